"""Start-up cost: ``import alloc``, first use of the allocator, ``alloc --help``.

Each case is a fresh interpreter (``python -c ...``) run ``--repeat`` times, interleaved with a
floor (``python -c pass``) measured in the same run; the table gives medians, the 90th
percentile, the ratio of medians to the floor, and how many modules the case loaded.  ``--root``
points ``PYTHONPATH`` at another checkout (e.g. the tree before a change) for comparison.

    python -m benchmarks.bench_startup --repeat 15
    python -m benchmarks.bench_startup --root /path/to/old/checkout
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

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


def _run(code: str, env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, cwd=env["PYTHONPATH"])
    return time.perf_counter() - t0


def _modules(code: str, env: dict[str, str]) -> int:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint(len(sys.modules))"], env=env,
                         check=True, capture_output=True, text=True, cwd=env["PYTHONPATH"])
    return int(out.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=11)
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1],
                        help="checkout to import alloc from (default: this one)")
    args = parser.parse_args()
    env = {**os.environ, "PYTHONPATH": str(args.root.resolve()), "COLUMNS": "80"}
    for code in CASES.values():  # warm the file cache and numba's on-disk cache
        _run(code, env)
    times: dict[str, list[float]] = {name: [] for name in CASES}
    for _ in range(args.repeat):
        for name, code in CASES.items():
            times[name].append(_run(code, env))
    floor = float(np.median(times["python -c pass (floor)"]))
    where = subprocess.run([sys.executable, "-c", "import alloc; print(alloc.__file__)"], env=env, check=True,
                           capture_output=True, text=True, cwd=env["PYTHONPATH"]).stdout.strip()
    print(f"alloc from {where}, {args.repeat} runs each, interleaved; machine load varies (shared)")
    print("| case | median s | p90 s | median / floor | modules |")
    print("|---|---|---|---|---|")
    for name, code in CASES.items():
        t = np.array(times[name])
        print(f"| {name} | {np.median(t):.3f} | {np.percentile(t, 90):.3f} | {np.median(t) / floor:.1f} "
              f"| {_modules(code, env)} |")


if __name__ == "__main__":
    main()
