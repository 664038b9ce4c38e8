"""Per-request phase timings, reported in the ``Server-Timing`` response header.

:class:`service.main.ServerTiming` opens a :class:`Timeline` per request; code on the
request's path (on the event loop, or a thread the request waits on) marks the end of
named phases with :func:`mark`.  The header then reads, in ms,
``app;dur=3.1, route;dur=0.4, write-queue;dur=0.02, write;dur=2.5, resume;dur=0.1``:
each phase lasts from the previous mark (or the request reaching the application), so a
client can tell where a slow request spent its time.
"""

from __future__ import annotations

import time
from contextvars import ContextVar

__all__ = ["Timeline", "current", "mark", "start"]


class Timeline:
    """Named consecutive phases of one request (seconds)."""

    __slots__ = ("last", "phases")

    def __init__(self) -> None:
        self.last = time.perf_counter()
        self.phases: list[tuple[str, float]] = []

    def mark(self, name: str) -> None:
        """End phase ``name`` now (it began at the previous mark)."""
        now = time.perf_counter()
        self.phases.append((name, now - self.last))
        self.last = now

    def header(self) -> str:
        return ", ".join(f"{name};dur={s * 1e3:.3f}" for name, s in self.phases)


_current: ContextVar[Timeline | None] = ContextVar("alloc_timeline", default=None)


def start() -> Timeline:
    """Open the timeline of the current request (called by the middleware)."""
    timeline = Timeline()
    _current.set(timeline)
    return timeline


def current() -> Timeline | None:
    """The current request's timeline (``None`` outside a request); pass it to threads."""
    return _current.get()


def mark(name: str) -> None:
    """End phase ``name`` of the current request, if any."""
    timeline = _current.get()
    if timeline is not None:
        timeline.mark(name)
