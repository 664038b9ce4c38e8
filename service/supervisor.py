"""Worker processes that are health-checked only once they are ready.

uvicorn's multiprocess supervisor pings every worker with a 5 s deadline
(``timeout_worker_healthcheck``) from the moment it is spawned.  A worker answers from a
thread that starts only after the worker has imported the application's modules, and it
is not serving until its start-up (imports, database migration) is done; the numba kernels
load afterwards on a thread (:mod:`service.warm`).  On a loaded machine start-up can take
longer than 5 s, and uvicorn's supervisor killed workers that were still starting (71 kills
and no worker up in about 400 s at load 13, issue 23).

:class:`ReadinessSupervisor` keeps uvicorn's supervisor and changes one thing: a worker
that is still starting is asked whether it is ready without waiting for the answer, and
is restarted only when it is not ready within ``ALLOC_STARTUP_TIMEOUT_S``; once ready, it
is health-checked as uvicorn does.  Start-up time then depends on the machine's load, and
the number of restarts does not.
"""

from __future__ import annotations

import logging
import time
from socket import socket

from uvicorn.config import STARTUP_FAILURE, Config
from uvicorn.supervisors.multiprocess import Multiprocess, Process

__all__ = ["ReadinessSupervisor"]

_log = logging.getLogger("uvicorn.error")


class _Starting:
    """A worker not yet ready: when it was spawned, and whether a readiness ping is unanswered."""

    __slots__ = ("since", "asked")

    def __init__(self) -> None:
        self.since = time.monotonic()
        self.asked = False


class ReadinessSupervisor(Multiprocess):
    """uvicorn's :class:`~uvicorn.supervisors.multiprocess.Multiprocess`, health checks after readiness."""

    def __init__(self, config: Config, sockets: list[socket], startup_timeout: float) -> None:
        super().__init__(config, sockets)
        self.startup_timeout = startup_timeout
        self._starting: dict[int, _Starting] = {}
        self.restarts = 0

    def init_processes(self) -> None:
        super().init_processes()
        for process in self.processes:
            self._starting[id(process)] = _Starting()

    def _ready_now(self, process: Process, state: _Starting) -> bool:
        """Ask without waiting: a ping is sent when none is unanswered, an answer read if there."""
        try:
            if not state.asked:
                process.parent_conn.send(b"ping")
                state.asked = True
            if process.parent_conn.poll(0):
                state.asked = False
                return bool(process.parent_conn.recv())
        except (OSError, EOFError):
            pass
        return False

    def _replace(self, idx: int, process: Process, why: str) -> None:
        self._starting.pop(id(process), None)
        process.kill()
        process.join()
        if process.exitcode == STARTUP_FAILURE:
            _log.error(f"Child process [{process.pid}] failed to start, stopping the parent process.")
            self.should_exit.set()
            return
        if self.should_exit.is_set():
            return
        _log.warning(f"Child process [{process.pid}] {why}; starting a new one")
        self.restarts += 1
        replacement = Process(self.config, self.sockets)
        replacement.start()
        self.processes[idx] = replacement
        self._starting[id(replacement)] = _Starting()

    def keep_subprocess_alive(self) -> None:
        if self.should_exit.is_set():
            return
        for idx, process in enumerate(self.processes):
            state = self._starting.get(id(process))
            if state is None:  # ready: uvicorn's health check
                if not process.is_alive(timeout=self.config.timeout_worker_healthcheck):
                    self._replace(idx, process, "did not answer its health check")
                continue
            if not process.process.is_alive():
                self._replace(idx, process, "exited while starting")
            elif self._ready_now(process, state):
                del self._starting[id(process)]
                _log.info(f"Child process [{process.pid}] ready after {time.monotonic() - state.since:.1f} s")
            elif time.monotonic() - state.since > self.startup_timeout:
                self._replace(idx, process, f"was not ready within ALLOC_STARTUP_TIMEOUT_S = {self.startup_timeout:g} s")
