"""The scenario registry: :func:`register_scenario` and what it stores.

Below every scenario module (each registers itself here when imported) and below the
package's :func:`sim.scenarios.get_scenario`, which imports a scenario's module on first
use; the arrows point one way.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from sim.result import SimResult

__all__ = ["Scenario", "register_scenario", "registered", "registered_names"]


class Scenario(Protocol):
    """What :func:`get_scenario` returns."""

    name: str
    description: str
    failures: dict[str, str]
    default_duration: float
    default_method: str | None
    default_failure: str | None

    def __call__(self, **kwargs: Any) -> SimResult: ...


_REGISTRY: dict[str, Scenario] = {}


def register_scenario(
    name: str,
    *,
    description: str | None = None,
    failures: dict[str, str] | None = None,
    default_duration: float | None = None,
    default_method: str | None = None,
    default_failure: str | None = None,
) -> Callable[[Callable[..., SimResult]], Scenario]:
    """Register ``run`` under ``name`` and attach its metadata.

    Metadata not given here is taken from attributes already set on ``run``
    (``description`` falls back to the first docstring line,
    ``default_duration`` to 10 s, ``failures`` to none).

    Examples
    --------
    >>> @register_scenario("demo", description="...", default_duration=10.0)
    ... def run(*, method="pinv", failure=None, duration=None, **kw): ...
    """

    def decorate(run: Callable[..., SimResult]) -> Scenario:
        if name in _REGISTRY and _REGISTRY[name] is not run:
            raise ValueError(f"scenario {name!r} is already registered")
        doc = (run.__doc__ or "").strip().splitlines()
        run.name = name  # type: ignore[attr-defined]
        run.description = (  # type: ignore[attr-defined]
            description or getattr(run, "description", None) or (doc[0] if doc else name)
        )
        run.failures = dict(failures or getattr(run, "failures", {}) or {})  # type: ignore[attr-defined]
        run.default_duration = float(  # type: ignore[attr-defined]
            default_duration or getattr(run, "default_duration", 10.0)
        )
        run.default_method = default_method or getattr(run, "default_method", None)  # type: ignore[attr-defined]
        run.default_failure = default_failure or getattr(run, "default_failure", None)  # type: ignore[attr-defined]
        if run.default_failure is not None and run.default_failure not in run.failures:  # type: ignore[attr-defined]
            raise ValueError(f"scenario {name!r}: default failure {run.default_failure!r} is not one of its failures")
        _REGISTRY[name] = run  # type: ignore[assignment]
        return run  # type: ignore[return-value]

    return decorate


def registered(name: str) -> Scenario | None:
    """The scenario registered as ``name`` (None when its module has not registered it yet)."""
    return _REGISTRY.get(name)


def registered_names() -> set[str]:
    """The names registered so far."""
    return set(_REGISTRY)
