"""Compile every kernel the registered methods use into the kernel cache (:mod:`alloc._engine._jit_cache`
places it): what a wheel's build and ``make install`` run, ``python -m alloc._engine._jit_warm warm``;
``python -m alloc._engine._jit_warm where`` says where each kernel file's cache is.

Kept apart from the cache's locator because warming reaches every method (the registry, the
vehicles), while the locator is imported by every kernel module before its kernels exist.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import alloc._engine._kernel_cache  # noqa: F401 - the caches placed before any kernel is compiled
from alloc._engine._jit_cache import notice, where

__all__ = ["warm", "where"]


def _warm_cases() -> list[tuple[Any, dict[str, dict[str, Any]]]]:
    """(problem, {method: options}) pairs whose calls reach every kernel signature in use."""
    import numpy as np

    # the modules themselves, not the package: the package imports this module
    from .. import vehicles
    from ..problem import Problem
    from ..registry import method_info, methods

    small = Problem(np.array([[1.0, -1.0, 0.5, 0.2], [0.3, 0.4, -1.0, 0.8], [0.2, 0.1, 0.3, -1.0]]),
                          [-1.0] * 4, [1.0] * 4, rate_min=[-5.0] * 4, rate_max=[5.0] * 4)
    # a flat attainable set (a fourth row dependent on the first): the facet searches' flat-set kernel
    flat = Problem(np.vstack([small.B, 0.3 * small.B[0]]), [-1.0] * 4, [1.0] * 4, rate_min=[-5.0] * 4,
                   rate_max=[5.0] * 4)
    cases = []
    for problem, groups in ((small, [[0, 1], [2, 3]]), (flat, [[0, 1], [2, 3]]),
                            (vehicles.problem("ice"), vehicles.daisy_groups("ice"))):
        options: dict[str, dict[str, Any]] = {}
        for name in methods():
            spec = method_info(name)["options"]
            opts: dict[str, Any] = {}
            if "groups" in spec:
                opts["groups"] = groups
            if "resolution" in spec:
                opts["resolution"] = 8
            options[name] = opts
            if "priorities" in spec:
                options[f"{name}:priorities"] = {**opts, "priorities": list(range(problem.k, 0, -1))}
            if "incremental" in spec:
                options[f"{name}:incremental"] = {**opts, "incremental": True}
            if "backend" in spec:  # an explicit solver backend: the LP/QP paths' own kernels
                options[f"{name}:daqp"] = {**opts, "backend": "daqp"}
                # da's compiled ray simplex (lp's own backend of that name is its default);
                # a method without such a backend refuses it and the variant is skipped
                options[f"{name}:simplex"] = {**opts, "backend": "simplex"}
        cases.append((problem, options))
    return cases


def warm(methods: list[str] | None = None, stream: Any = None) -> dict[str, float]:
    """Compile (or load) every kernel the registered methods use; CPU seconds per method.

    Each method (and its variants: ``priorities``, ``incremental``) is built on a small
    problem and on ICE and called the ways a user calls it: a demand; a demand with ``u_prev``
    and ``dt``; the same with strided (non-contiguous) vectors; a batch, C- and
    Fortran-ordered.
    """
    import numpy as np

    from ..api import make_allocator
    from ..exceptions import AllocError

    spent: dict[str, float] = {}
    for problem, options in _warm_cases():
        rng = np.random.default_rng(0)
        k = problem.k
        scale = np.abs(problem.B).sum(axis=1) * np.maximum(np.abs(problem.umin), np.abs(problem.umax)).max() / 3
        V = rng.uniform(-1.0, 1.0, (5, k)) * scale
        u_prev = 0.5 * (problem.umin + problem.umax)
        strided_v = np.repeat(V[0], 2)[::2]
        strided_u = np.repeat(u_prev, 2)[::2]
        for variant, opts in options.items():
            name = variant.split(":")[0]
            if methods is not None and name not in methods:
                continue
            t0 = time.process_time()
            try:
                allocator = make_allocator(problem, name, **opts)
            except AllocError:
                continue  # options this problem cannot give
            allocator(V[0])
            allocator(V[1], u_prev=u_prev, dt=0.01)
            allocator(strided_v)
            allocator(strided_v, u_prev=strided_u, dt=0.01)
            allocator.batch(V)
            allocator.batch(np.asfortranarray(V))
            # the method's own solve, nominal and rate-limited, as a call meets it when a
            # one-call fast path cannot finish (an iteration cap, a non-finite answer)
            allocator._solve(np.array(V[2]), None, None)
            allocator._solve(np.array(V[3]), u_prev, 0.01)
            spent[name] = spent.get(name, 0.0) + time.process_time() - t0
    if methods is None or "da" in methods:
        t0 = time.process_time()
        _warm_ray_fallback(np)
        spent["da"] = spent.get("da", 0.0) + time.process_time() - t0
    if stream is not None:
        for name, seconds in spent.items():
            print(f"{name:12s} {seconds:7.2f} s", file=stream)
    return spent


def _warm_ray_fallback(np: Any) -> None:
    """Compile ``da``'s primal ray simplex, the fallback its dual walk hands over to and which no
    ordinary warm case reaches (a first fallback in a user's call compiled it there: 1.3-2.8 CPU s
    in the adversarial suite's first-use run)."""
    from . import _ray_simplex

    k, m = 2, 3
    A = np.array([[1.0, 0.5, -0.2], [0.1, 1.0, 0.4]])
    F = _ray_simplex.ray_matrix(A)
    nw, ni = _ray_simplex.work_sizes(k, m)
    G = np.array(np.linalg.pinv(A @ A.T), order="C")
    _ray_simplex.solve_ray(F, np.array([0.3, 0.2]), np.zeros(m), -np.ones(m), np.ones(m), 10.0,
                           50, np.empty(nw), np.empty(ni, dtype=np.int64), np.empty(m), G,
                           np.linalg.norm(A, axis=0))


def _main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m alloc._engine._jit_warm", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    w = sub.add_parser("warm", help="compile every kernel into the cache (what the build does)")
    w.add_argument("methods", nargs="*", help="only these methods (default: all registered)")
    w.add_argument("--quiet", action="store_true", help="print nothing")
    w.add_argument("--summary", action="store_true", help="one line, not a line per method")
    sub.add_parser("where", help="where each kernel file's cache is")
    args = parser.parse_args(argv)
    if args.command == "warm":
        t0, c0 = time.perf_counter(), time.process_time()
        notice.silent = args.quiet or args.summary
        spent = warm(args.methods or None, stream=None if args.quiet or args.summary else sys.stdout)
        if not args.quiet:
            print(f"warmed {len(spent)} methods in {time.perf_counter() - t0:.1f} s "
                  f"({time.process_time() - c0:.1f} s CPU; {notice.compiles} kernels compiled)")
        return 0
    for file, cache, writable in where():
        print(f"{file}: {cache}{'' if writable else ' (read-only: loads only)'}")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
