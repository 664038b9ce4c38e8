"""Run the service as a separate uvicorn process on a free loopback port.

Used by the HTTP tests and ``benchmarks/bench_service.py``: the real server, a real
socket, a process that can be killed with SIGKILL and started again on the same data.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

__all__ = ["ServiceProcess", "free_port"]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class ServiceProcess:
    """``python -m service.main`` on 127.0.0.1 with ``ALLOC_*`` settings from ``env``."""

    def __init__(self, data_dir: str | Path, *, api_key: str | None = None, port: int | None = None,
                 env: dict[str, str] | None = None, log_level: str = "warning", nice: int = 0,
                 database_url: str | None = None, workers: int = 1) -> None:
        self.data_dir = Path(data_dir)
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        inherited = {k: v for k, v in os.environ.items() if not k.startswith("ALLOC_")}
        self.env = {**inherited, "ALLOC_DATA_DIR": str(self.data_dir), **(env or {})}
        if api_key is not None:
            self.env["ALLOC_API_KEY"] = api_key
        if database_url is not None:
            self.env["ALLOC_DATABASE_URL"] = database_url
        self.workers = workers
        self.log_level = log_level
        self.nice = nice  # scheduling priority increment of the server process (negative: root only)
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 90.0) -> ServiceProcess:
        root = Path(__file__).resolve().parent.parent
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.data_dir / "service.log"
        log = open(self.log_path, "ab")  # a file, not a pipe: a full pipe would stall the server
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "service.main", "--host", "127.0.0.1", "--port", str(self.port),
             "--log-level", self.log_level, "--workers", str(self.workers)],
            cwd=root, env=self.env, stdout=subprocess.DEVNULL, stderr=log,
            preexec_fn=(lambda: os.nice(self.nice)) if self.nice else None,
        )
        log.close()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = self.log_path.read_text(errors="replace")
                raise RuntimeError(f"service exited with {self.proc.returncode}: {err[-2000:]}")
            try:
                with urllib.request.urlopen(f"{self.url}/v1/health", timeout=1.0) as reply:
                    if reply.status == 200:
                        return self
            except (urllib.error.URLError, ConnectionError, TimeoutError):
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"service did not answer on {self.url} within {timeout} s")

    def build_processes(self, timeout: float = 120.0) -> list[int]:
        """Pids of the service's build processes (:mod:`service.builds`), once started."""
        assert self.proc is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = []
            for task in Path(f"/proc/{self.proc.pid}/task").iterdir():
                for child in (task / "children").read_text().split():
                    cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
                    if b"spawn_main" in cmdline and b"resource_tracker" not in cmdline:
                        found.append(int(child))
            if found:
                return found
            time.sleep(0.1)
        raise RuntimeError(f"no build process started within {timeout} s")

    def rss(self) -> int:
        """Resident memory (bytes) of the service process and its build processes together."""
        assert self.proc is not None
        total = 0
        for pid in [self.proc.pid, *self.build_processes()]:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
        return total

    def kill(self) -> None:
        """SIGKILL: no shutdown handlers, no flushing; what is on disk is what survives."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.kill()

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
