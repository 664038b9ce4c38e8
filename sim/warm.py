"""Compile (or load) the simulator's numba kernels, as ``make install`` does after the library's.

``python -m alloc._engine._jit_warm warm`` compiles the library's kernels; the library knows nothing of
the simulator, so the simulator's own (``sim.packed``, ``sim.blocks``, ``sim.allocation``,
``sim.world``) are warmed here, by flying what a first ``alloc sim`` flies: one second of the ICE
scenario with its default failure, and a moment of it in turbulence (the Dryden recursion).  They
land in the same kernel cache (:mod:`alloc._engine._jit_cache` places them).

``python -m sim.warm [--quiet]``: one line (the seconds and kernels compiled), or nothing.
"""

from __future__ import annotations

import sys
import time

__all__ = ["warm"]


def warm() -> int:
    """Fly the runs above; the number of our kernels compiled (0 when the cache had them all)."""
    from alloc._engine._jit_cache import notice
    from sim.scenarios import get_scenario

    before = notice.compiles
    run = get_scenario("ice")
    run(duration=1.0, failure=run.default_failure)
    run(duration=0.2, failure=None, turbulence="light")
    return notice.compiles - before


def _main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m sim.warm", description=__doc__.split("\n")[0])
    parser.add_argument("--quiet", action="store_true", help="print nothing")
    args = parser.parse_args(argv)
    from alloc._engine._jit_cache import notice

    notice.silent = True  # this is the compile that was asked for: no per-kernel notice
    t0, c0 = time.perf_counter(), time.process_time()
    compiled = warm()
    if not args.quiet:
        print(f"warmed the simulator in {time.perf_counter() - t0:.1f} s "
              f"({time.process_time() - c0:.1f} s CPU; {compiled} kernels compiled)")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
