"""Start-up cost: ``import alloc``, first use of the allocator, ``alloc --help``; and a cold start
after a fresh install (``--fresh``).

Checkout table (default): each case is a fresh interpreter (``python -c ...``) run ``--repeat``
times, interleaved with a floor (``python -c pass``) measured in the same run; the table gives
medians, the 90th percentile, the ratio of medians to the floor, and how many modules the case
loaded.  ``--root`` points ``PYTHONPATH`` at another checkout (e.g. the tree before a change).

Fresh install (``--fresh``): a new venv with ``pip install '.[service]'`` from a copy of the
checkout (or ``--venv`` to reuse one made so).  Each sample is a fresh interpreter with a fresh
per-user cache (its own empty ``TMPDIR``, ``HOME=/nonexistent``): the first allocation on ICE
(process CPU seconds, and the import, ``make_allocator`` and call steps in CPU and wall seconds,
kernels compiled), as the installer (root: the package's own cache) and, where this runs as root,
as the user ``nobody`` (the package read-only: its cache copied to a private directory on first
use); ``pinv`` and ``qp`` ``--repeat`` times, every other method once.  Then the service's
start-up (as ``--service`` prints it).  ``--compile-baseline`` adds one sample each of pinv and qp
with an empty cache (what the first allocation cost before the wheel carried the kernels).

Service start-up (``--service``, the checkout ``--root`` with this Python; also part of
``--fresh``): ``python -m service.main`` started; ready is its first 200 on ``/v1/health``
(polled every 20 ms), in wall seconds and the server process's CPU seconds; then the latency
of one ``da`` request sent at that moment (its kernels are usually still loading on the
warm-up thread), and the time until ``/v1/ready`` reports every method's kernels loaded.

    python -m benchmarks.bench_startup --repeat 15
    python -m benchmarks.bench_startup --service --repeat 5
    python -m benchmarks.bench_startup --root /path/to/old/checkout
    python -m benchmarks.bench_startup --fresh --repeat 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import pwd
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

HELP = ("import sys\nsys.argv = ['alloc', '--help']\nfrom alloc.cli import app\n"
        "try:\n    app()\nexcept SystemExit:\n    pass\n")
CASES = {
    "python -c pass (floor)": "pass",
    "import alloc": "import alloc",
    "import alloc; alloc.Allocator": "import alloc\nalloc.Allocator",
    "first allocation (pinv)": "import alloc\nalloc.allocate(alloc.Problem([[1.0, 2.0]], [-1, -1], [1, 1]), [0.5], 'pinv')",
    "alloc --help": HELP,
}
DEFAULT_METHODS = ("pinv", "qp")
#: one fresh interpreter: import, build and first call on ICE; CPU and wall seconds of each step
FIRST_ALLOCATION = """
import json, sys, time
c0, w0 = time.process_time(), time.perf_counter()
import numpy as np
import alloc
from alloc import vehicles
p = vehicles.problem("ice")
c1, w1 = time.process_time(), time.perf_counter()
options = {"groups": vehicles.daisy_groups("ice")} if sys.argv[1] == "daisy" else {}
allocator = alloc.make_allocator(p, sys.argv[1], **options)
c2, w2 = time.process_time(), time.perf_counter()
r = allocator(np.array([2.0, 30.0, 0.5]))
c3, w3 = time.process_time(), time.perf_counter()
from alloc._engine import _jit_cache
print(json.dumps({"status": r.status.value, "compiles": _jit_cache.notice.compiles,
                  "import_cpu": c1 - c0, "make_cpu": c2 - c1, "call_cpu": c3 - c2,
                  "import_wall": w1 - w0, "make_wall": w2 - w1, "call_wall": w3 - w2,
                  "cache": [c for _, c, _ in _jit_cache.where()][0]}))
"""


def first_allocation(method: str, python: str = sys.executable, env: dict[str, str] | None = None,
                     as_user: list[str] | None = None) -> dict[str, Any]:
    """:data:`FIRST_ALLOCATION` in a fresh interpreter (``as_user``: a command prefix such as
    ``setpriv --reuid ...``); adds the whole process's CPU seconds and wall seconds, and its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([*(as_user or []), python, "-c", FIRST_ALLOCATION, method], capture_output=True, text=True,
                         env=env, cwd="/")
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise RuntimeError(f"first {method} allocation failed:\n{out.stderr[-3000:]}")
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row["process_cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    row["process_wall"] = wall
    row["stderr"] = out.stderr
    return row


def _run(code: str, env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, cwd=env["PYTHONPATH"])
    return time.perf_counter() - t0


def _modules(code: str, env: dict[str, str]) -> int:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint(len(sys.modules))"], env=env,
                         check=True, capture_output=True, text=True, cwd=env["PYTHONPATH"])
    return int(out.stdout.split()[-1])


def checkout_table(root: Path, repeat: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(root.resolve()), "COLUMNS": "80"}
    for code in CASES.values():  # warm the file cache and numba's on-disk cache
        _run(code, env)
    times: dict[str, list[float]] = {name: [] for name in CASES}
    for _ in range(repeat):
        for name, code in CASES.items():
            times[name].append(_run(code, env))
    floor = float(np.median(times["python -c pass (floor)"]))
    where = subprocess.run([sys.executable, "-c", "import alloc; print(alloc.__file__)"], env=env, check=True,
                           capture_output=True, text=True, cwd=env["PYTHONPATH"]).stdout.strip()
    print(f"alloc from {where}, {repeat} runs each, interleaved; machine load varies (shared)")
    print("| case | median s | p90 s | median / floor | modules |")
    print("|---|---|---|---|---|")
    for name, code in CASES.items():
        t = np.array(times[name])
        print(f"| {name} | {np.median(t):.3f} | {np.percentile(t, 90):.3f} | {np.median(t) / floor:.1f} "
              f"| {_modules(code, env)} |")


# ----------------------------------------------------------------------------- fresh install


def machine_state() -> str:
    model = ""
    try:
        model = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"{model or platform.processor()}, {os.cpu_count()} CPUs, load average {load}"


def build_fresh_venv(root: Path, where: Path) -> tuple[Path, float]:
    """A new venv with ``pip install '<copy of root>[service]'``; its python and the install's wall seconds."""
    python = _world_runnable_python()
    subprocess.run([python, "-m", "venv", str(where / "venv")], check=True)
    pip = where / "venv" / "bin" / "pip"
    subprocess.run([str(pip), "install", "--quiet", "--upgrade", "pip"], check=True)
    src = where / "src"
    src.mkdir()
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=root, check=True,
                           capture_output=True, text=True).stdout.split("\n")
    for name in filter(None, files):
        if (root / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(root / name, src / name)
    t0 = time.perf_counter()
    subprocess.run([str(pip), "install", "--quiet", f"{src}[service]"], check=True)
    return where / "venv" / "bin" / "python", time.perf_counter() - t0


def _other_user() -> list[str] | None:
    """A command prefix that runs as ``nobody`` (root only), or None."""
    if os.getuid() != 0 or shutil.which("setpriv") is None:
        return None
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        return None
    return ["setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups"]


def _world_runnable_python() -> str:
    """This Python, or one of the same version that ``nobody`` can run (a pyenv build under /root
    cannot be), so the same venv serves both users."""
    prefix = _other_user()
    if prefix is None:
        return sys.executable
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    for python in (sys.executable, f"/usr/local/bin/python{version}", f"/usr/bin/python{version}"):
        if os.path.exists(python) and subprocess.run([*prefix, "sh", "-c", '"$1" -c pass', "_", python],
                                                     capture_output=True).returncode == 0:
            return python
    return sys.executable


def _fresh_user_env(scratch: Path, owner: int | None) -> dict[str, str]:
    tmp = Path(tempfile.mkdtemp(dir=scratch))
    tmp.chmod(0o700)
    if owner is not None:
        os.chown(tmp, owner, -1)
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_CACHE_HOME", "NUMBA_CACHE_DIR", "PYTHONPATH")}
    return {**env, "HOME": "/nonexistent", "TMPDIR": str(tmp)}


def _row(name: str, user: str, rows: list[dict[str, Any]]) -> str:
    def med(key: str) -> float:
        return float(np.median([r[key] for r in rows]))

    compiled = sorted({r["compiles"] for r in rows})
    return (f"| {name} | {user} | {len(rows)} | {med('process_cpu'):.2f} | {med('import_cpu'):.2f} | "
            f"{med('make_cpu'):.2f} | {med('call_cpu'):.3f} | {med('process_wall'):.2f} | "
            f"{med('import_wall'):.2f} | {med('make_wall'):.2f} | {','.join(map(str, compiled))} |")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _process_cpu(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


#: the first request after the service answers: a method other than the default (its kernels
#: are then usually still loading on the warm-up thread)
FIRST_REQUEST = json.dumps({"B": [[1.0, 0.5, 0.2], [0.1, 1.0, 0.3]], "umin": [-1, -1, -1], "umax": [1, 1, 1],
                            "v": [0.3, 0.2], "method": "da"}).encode()


def _get(port: int, path: str, timeout: float = 1.0) -> tuple[int, dict[str, Any]]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=timeout) as answer:
        return answer.status, json.loads(answer.read())


def service_ready(python: Path, scratch: Path, timeout: float = 300.0,
                  pythonpath: Path | None = None, data: Path | None = None) -> dict[str, float]:
    """One start of ``python -m service.main``: seconds (wall) and the server process's CPU
    seconds to its first 200 on ``/v1/health`` (``ready``); the latency of a first ``da``
    request sent right then (``first_request_s``); and the seconds and CPU until ``/v1/ready``
    says every method's kernels are loaded (``warm``).  ``pythonpath``: a checkout to run;
    ``data``: the data directory (default: a new one, so the start creates the database)."""
    port = _free_port()
    data = Path(tempfile.mkdtemp(dir=scratch)) if data is None else data
    env = {k: v for k, v in os.environ.items() if not k.startswith("ALLOC_")}
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    errors = open(data / "stderr.txt", "w+")  # a file: a pipe nobody reads can fill and stall the server
    t0 = time.perf_counter()
    server = subprocess.Popen([str(python), "-m", "service.main", "--port", str(port), "--data-dir", str(data),
                               "--log-level", "warning"], env=env, cwd=str(pythonpath or scratch),
                              stdout=subprocess.DEVNULL, stderr=errors)
    row: dict[str, float] = {}
    try:
        def alive() -> None:
            if server.poll() is not None:
                errors.seek(0)
                raise RuntimeError(f"the service exited {server.returncode}: {errors.read()[-2000:]!r}")

        while "ready_wall" not in row:
            alive()
            if time.perf_counter() - t0 > timeout:
                raise RuntimeError(f"the service did not answer /v1/health within {timeout} s")
            try:
                if _get(port, "/v1/health")[0] == 200:
                    row.update(ready_wall=time.perf_counter() - t0, ready_cpu=_process_cpu(server.pid))
            except OSError:
                time.sleep(0.02)
        t1 = time.perf_counter()
        request = urllib.request.Request(f"http://127.0.0.1:{port}/v1/allocate", data=FIRST_REQUEST,
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=timeout) as answer:
            assert answer.status == 200 and json.loads(answer.read())["status"] == "exact"
        row["first_request_s"] = time.perf_counter() - t1
        while "warm_wall" not in row:
            alive()
            if time.perf_counter() - t0 > timeout:
                raise RuntimeError(f"the service's kernels were not warm within {timeout} s")
            try:
                status, body = _get(port, "/v1/ready")
                if status == 200 and body.get("warmed"):
                    row.update(warm_wall=time.perf_counter() - t0, warm_cpu=_process_cpu(server.pid))
            except OSError:
                pass
            time.sleep(0.02)
        return row
    finally:
        server.terminate()
        try:
            server.wait(10)
        except subprocess.TimeoutExpired:
            server.kill()
        errors.close()


def print_service_ready(ready: list[dict[str, float]], restart: list[dict[str, float]] | None = None) -> None:
    """The table: a row for starts on a new database (``ready``) and, given, on an existing one."""
    def cell(rows: list[dict[str, float]], key: str) -> str:
        x = [r[key] for r in rows]
        return f"{np.median(x):.2f} ({min(x):.2f}-{max(x):.2f})"

    print(f"\nService start-up (`python -m service.main`), {len(ready)} starts each; medians (range)")
    print("| database | ready: first 200 on /v1/health, wall s | ready, server CPU s | first `da` request then, s "
          "| all kernels warm (/v1/ready warmed), wall s | warm, server CPU s |")
    print("|---|---|---|---|---|---|")
    for name, rows in (("new", ready), ("existing (restart)", restart or [])):
        if rows:
            print(f"| {name} | {cell(rows, 'ready_wall')} | {cell(rows, 'ready_cpu')} | "
                  f"{cell(rows, 'first_request_s')} | {cell(rows, 'warm_wall')} | {cell(rows, 'warm_cpu')} |")


def service_report(args: argparse.Namespace) -> None:
    """The service start-up of the checkout ``--root`` with this Python (no fresh install)."""
    scratch = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    try:
        print(f"machine before: {machine_state()}")
        root = args.root.resolve()
        existing = Path(tempfile.mkdtemp(dir=scratch))
        service_ready(Path(sys.executable), scratch, pythonpath=root, data=existing)  # creates its database
        ready: list[dict[str, float]] = []
        restart: list[dict[str, float]] = []
        for _ in range(args.repeat):  # interleaved, so a change in the machine's load hits both rows
            ready.append(service_ready(Path(sys.executable), scratch, pythonpath=root))
            restart.append(service_ready(Path(sys.executable), scratch, pythonpath=root, data=existing))
        print(f"machine after: {machine_state()}")
        print(f"service from {root}")
        print_service_ready(ready, restart)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def fresh_report(args: argparse.Namespace) -> None:
    scratch = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    scratch.chmod(0o755)
    try:
        print(f"machine before: {machine_state()}")
        built = ""
        if args.venv is None:
            python, seconds = build_fresh_venv(args.root, scratch)
            built = f"; `pip install '.[service]'` took {seconds:.0f} s wall (it compiles every kernel)"
        else:
            python = args.venv / "bin" / "python"
        versions = subprocess.run([str(python), "-c", "import sys, numba, alloc; print(sys.version.split()[0], "
                                   "numba.__version__, alloc.__file__)"], capture_output=True, text=True,
                                  check=True, cwd="/").stdout.split()
        print(f"fresh venv {python} (Python {versions[0]}, numba {versions[1]}, alloc from {versions[2]}){built}")
        listed = subprocess.run([str(python), "-c", "import alloc; print(' '.join(alloc.methods()))"],
                                capture_output=True, text=True, check=True, cwd="/").stdout.split()
        others = [m for m in listed if m not in DEFAULT_METHODS]
        nobody = _other_user()
        owner = pwd.getpwnam("nobody").pw_uid if nobody else None
        users: list[tuple[str, list[str] | None, int | None]] = [("installer", None, None)]
        if nobody is not None:
            subprocess.run(["chmod", "-R", "a+rX", str(scratch)], check=True)
            users.append(("nobody (read-only package, no home)", nobody, owner))
        samples: dict[tuple[str, str], list[dict[str, Any]]] = {}
        for _ in range(args.repeat):  # interleaved, so each row sees the same spread of machine states
            for method in DEFAULT_METHODS:
                for user, prefix, uid in users:
                    samples.setdefault((method, user), []).append(
                        first_allocation(method, str(python), _fresh_user_env(scratch, uid), prefix))
        for method in others:
            samples[(method, "installer")] = [first_allocation(method, str(python), _fresh_user_env(scratch, None))]
        if args.compile_baseline:
            for method in DEFAULT_METHODS:
                env = _fresh_user_env(scratch, None)
                env["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(dir=scratch)  # empty: every kernel compiles
                samples[(method, "installer, empty cache")] = [first_allocation(method, str(python), env)]
        ready = [service_ready(python, scratch) for _ in range(args.repeat)]
        print(f"machine after: {machine_state()}")
        print("\nFirst allocation on ICE in a fresh interpreter with a fresh per-user cache (medians; CPU and wall s)")
        print("| method | user | n | process CPU | import CPU | make_allocator CPU | call CPU | process wall "
              "| import wall | make_allocator wall | kernels compiled |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for (method, user), rows in samples.items():
            print(_row(method, user, rows))
        print_service_ready(ready)
    finally:
        subprocess.run(["rm", "-rf", str(scratch)], check=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=11)
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1],
                        help="checkout to import alloc from (default: this one)")
    parser.add_argument("--fresh", action="store_true", help="cold start after a fresh install (see above)")
    parser.add_argument("--venv", type=Path, default=None, help="with --fresh: a venv made by `pip install '.[service]'`")
    parser.add_argument("--compile-baseline", action="store_true", help="with --fresh: also an empty-cache sample")
    parser.add_argument("--service", action="store_true",
                        help="only the service start-up of --root (ready, first request, warm), --repeat starts")
    args = parser.parse_args()
    if args.service:
        service_report(args)
    elif args.fresh:
        fresh_report(args)
    else:
        checkout_table(args.root, args.repeat)


if __name__ == "__main__":
    main()
