"""The standing adversarial suite: seeded hostile problems against the allocation contract.

The generator lives in :mod:`hostile_cases`, the contract check in :mod:`hostile_checks`;
this module keeps their API (``case``, ``case_classes``, ``decode``, ``check``) with the
watchdog, the shrinker, the driver and the command line.

``case(seed)`` draws one hostile case (pure data, reproducible from its seed); ``check(case)``
returns its contract violations.

``run(seeds, workers)`` runs cases in watchdog subprocesses (a hang that holds the GIL
cannot be interrupted from a thread): a case that does not answer within its budget is a
hang, the worker is killed and restarted.  ``shrink(case)`` reduces a failing case to a
minimal one (fewer calls, effectors, axes, options; simpler numbers) that still fails.

Command line (the large run recorded in the docs; seeds ``S .. S + N - 1``)::

    python tests/hostile.py --cases 100000 --workers 2 [--seed 0] [--json report.json]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import re
import sys
import time
from collections import Counter
from typing import Any

import numpy as np

import hostile_checks
from hostile_cases import NON_REAL, case, case_classes, decode
from hostile_checks import check

__all__ = ["NON_REAL", "case", "case_classes", "check", "decode", "markdown_rows", "run", "shrink"]

DEADLINE: float | None = None  # epoch seconds: the command line's --minutes stops taking cases


# ----------------------------------------------------------------------------- watchdog
def _worker(conn: Any) -> None:  # pragma: no cover - runs in a subprocess
    import os
    import warnings

    import alloc

    null = os.open(os.devnull, os.O_WRONLY)  # solver banners and C-level warnings
    os.dup2(null, 1)
    os.dup2(null, 2)
    warnings.simplefilter("ignore")

    from alloc.solvers import backends

    B = [[1.0, 0.5, -0.3], [0.2, 1.0, 0.7], [0.1, -0.4, 1.0]]
    W = [[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]]
    problems = [alloc.Problem(B, [-1] * 3, [1] * 3),
                alloc.Problem(B, [-1] * 3, [1] * 3, Wu=W, Wv=W, rate_min=[-1] * 3, rate_max=[1] * 3)]
    # a flat attainable set (k = 4 > m = 3): the facet searches' flat-set kernel
    flat = alloc.Problem([[1.0, 0.5, -0.3], [0.2, 1.0, 0.7], [0.1, -0.4, 1.0], [0.3, 0.15, -0.09]], [-1] * 3, [1] * 3,
                         rate_min=[-1] * 3, rate_max=[1] * 3)
    pairs = [(p, name) for p in problems for name in alloc.methods()]
    pairs += [(flat, name) for name in alloc.methods() if alloc.method_info(name)["capabilities"]["needs_ams"] or name == "da"]
    for p, name in pairs:  # load the compiled kernels and solvers before the clock starts
        opts = [{}] + ([{"backend": b} for b in backends()] if "backend" in alloc.method_info(name)["options"]
                       and name not in ("da", "lp") else [{"backend": b} for b in backends(lp=True)]
                       if name in ("da", "lp") else [])
        extra = {"incremental": True, "priorities": [1, 2, 2]}
        opts += [{x: extra[x]} for x in extra if x in alloc.method_info(name)["options"]]
        for o in opts:
            try:
                f = alloc.make_allocator(p, name, **o)
            except alloc.AllocError:
                continue  # a backend this method does not take
            v = np.array([0.1, 0.2, 0.3, 0.06][:p.k])
            f(v)
            f(v, u_prev=np.zeros(3), dt=0.01)
            f.batch(v[None, :])
            f(v.tolist(), u_prev=[0.0, 0.1, 0.2], dt=0.01)
    from alloc._engine._jit_warm import warm

    warm()  # every kernel signature an install compiles, loaded (the rest would compile in a call: a failure)
    conn.send("ready")
    while True:
        c = conn.recv()
        if c is None:
            return
        try:
            res = check(c)
        except Exception as exc:  # noqa: BLE001 - a checker bug is reported, not hidden
            res = {"fail": [f"checker error: {type(exc).__name__}: {exc}"], "status": Counter(), "refused": ""}
        conn.send(res)


class Watchdog:
    """A worker subprocess with a deadline per case; a hang kills and restarts it."""

    def __init__(self) -> None:
        self._ctx = mp.get_context("fork" if sys.platform != "win32" else "spawn")
        self._start()

    def _start(self) -> None:
        self.conn, child = self._ctx.Pipe()
        self.proc = self._ctx.Process(target=_worker, args=(child,), daemon=True)
        self.proc.start()
        t0 = time.time()
        while not self.conn.poll(1.0):
            if not self.proc.is_alive() or time.time() - t0 > 300:
                raise RuntimeError("hostile worker did not start")
        assert self.conn.recv() == "ready"

    def run(self, c: dict[str, Any]) -> dict[str, Any]:
        budget = hostile_checks.BUILD_WALL_LIMIT + hostile_checks.CALL_WALL_LIMIT * (5 + 3 * len(c["calls"]))
        self.conn.send(c)
        if self.conn.poll(budget):
            return self.conn.recv()
        self.proc.kill()
        self.proc.join()
        self._start()
        return {"fail": [f"hang: no answer within {budget:.0f} s"], "status": Counter(), "refused": ""}

    def close(self) -> None:
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()


# ----------------------------------------------------------------------------- shrinking
def _variants(c: dict[str, Any]):
    """Smaller versions of case ``c``, most aggressive first."""
    f, calls, opts = c["fields"], c["calls"], c["options"]
    for i in range(len(calls)):
        if len(calls) > 1:
            yield {**c, "calls": calls[:i] + calls[i + 1:]}
    for name in list(opts):
        yield {**c, "options": {k: v for k, v in opts.items() if k != name}}
    for name in ("up", "Wu", "Wv", "rate_min", "rate_max"):
        if name in f:
            yield {**c, "fields": {k: v for k, v in f.items() if k not in (name, "rate_min", "rate_max")
                                   or (name not in ("rate_min", "rate_max") and k != name)}}
    for i, call in enumerate(calls):
        if "u_prev" in call:
            yield {**c, "calls": calls[:i] + [{"v": call["v"]}] + calls[i + 1:]}
    try:
        B = np.array(f["B"], dtype=float)
    except (TypeError, ValueError, OverflowError):
        return
    k, m = B.shape if B.ndim == 2 else (0, 0)
    for j in range(m if m > 1 else 0):  # drop effector j
        def drop(x: Any, j: int = j) -> Any:
            return x[:j] + x[j + 1:] if isinstance(x, list) and len(x) == m else x
        nf = {}
        for key, val in f.items():
            if key == "B":
                nf[key] = [drop(list(r)) for r in val]
            elif key == "Wu" and isinstance(val, list) and val and isinstance(val[0], list):
                nf[key] = [drop(list(r)) for r in drop(val)]
            else:
                nf[key] = drop(val)
        ncalls = [{**cl, **({"u_prev": drop(cl["u_prev"])} if "u_prev" in cl else {})} for cl in calls]
        yield {**c, "fields": nf, "calls": ncalls, "options": {}}
    for i in range(k if k > 1 else 0):  # drop axis i
        nf = dict(f)
        nf["B"] = [list(r) for q, r in enumerate(f["B"]) if q != i]
        if isinstance(f.get("Wv"), list):
            Wv = f["Wv"]
            nf["Wv"] = ([[x for q, x in enumerate(r) if q != i] for p_, r in enumerate(Wv) if p_ != i]
                        if Wv and isinstance(Wv[0], list) else [x for q, x in enumerate(Wv) if q != i])
        ncalls = [{**cl, "v": [x for q, x in enumerate(cl["v"]) if q != i]}
                  for cl in calls if isinstance(cl["v"], list) and len(cl["v"]) == k]
        if ncalls:
            yield {**c, "fields": nf, "calls": ncalls, "options": {}}


def shrink(c: dict[str, Any], fails, dog: Watchdog | None = None, budget: int = 300) -> dict[str, Any]:
    """Greedy reduction of a failing case: keep any smaller variant with the same kind of failure."""
    def kind(res: dict[str, Any]) -> set[str]:
        return {s.split(":")[0] for s in res["fail"]}

    want = {s.split(":")[0] for s in fails}
    tries = 0
    improved = True
    while improved and tries < budget:
        improved = False
        for cand in _variants(c):
            tries += 1
            res = dog.run(cand) if dog is not None else check(cand)
            if want & kind(res):
                c, improved = cand, True
                break
            if tries >= budget:
                break
    return c


# ----------------------------------------------------------------------------- driver
def run(seeds: range, workers: int = 1, shrink_failures: bool = True, log: Any = None) -> dict[str, Any]:
    """Run the cases ``seeds``; totals, per-method status counts and (shrunk) failures."""
    import alloc

    report: dict[str, Any] = {"cases": 0, "refused": Counter(), "classes": Counter(), "fail": [], "by_method": {},
                              "fallback_reasons": {}}
    for name in alloc.methods():
        report["by_method"][name] = Counter()
        report["fallback_reasons"][name] = Counter()
    if workers <= 1:
        _run_chunk(list(seeds), report, shrink_failures, log)
        return report
    from concurrent.futures import ThreadPoolExecutor

    chunks = [list(seeds)[i::workers] for i in range(workers)]
    with ThreadPoolExecutor(workers) as pool:  # each thread drives its own watchdog subprocess
        parts = list(pool.map(lambda ch: _run_part(ch, shrink_failures, log), chunks))
    for part in parts:
        _merge(report, part)
    return report


def _run_part(seeds: list[int], shrink_failures: bool, log: Any = None) -> dict[str, Any]:
    import alloc

    rep: dict[str, Any] = {"cases": 0, "refused": Counter(), "classes": Counter(), "fail": [], "by_method": {},
                           "fallback_reasons": {}}
    for name in alloc.methods():
        rep["by_method"][name] = Counter()
        rep["fallback_reasons"][name] = Counter()
    _run_chunk(seeds, rep, shrink_failures, log)
    return rep


def _merge(report: dict[str, Any], part: dict[str, Any]) -> None:
    report["cases"] += part["cases"]
    report["stopped_at_deadline"] = report.get("stopped_at_deadline", False) or part.get("stopped_at_deadline", False)
    report["refused"].update(part["refused"])
    report["classes"].update(part["classes"])
    report["fail"].extend(part["fail"])
    for name, cnt in part["by_method"].items():
        report["by_method"][name].update(cnt)
    for name, cnt in part["fallback_reasons"].items():
        report["fallback_reasons"][name].update(cnt)


def _run_chunk(seeds: list[int], report: dict[str, Any], shrink_failures: bool, log: Any) -> None:
    dog = Watchdog()
    try:
        for n, seed in enumerate(seeds):
            if DEADLINE is not None and time.time() > DEADLINE:
                report["stopped_at_deadline"] = True
                break
            c = case(seed)
            res = dog.run(c)
            report["cases"] += 1
            if res["refused"]:
                report["refused"][res["refused"]] += 1
            report["classes"].update(case_classes(c))
            report["by_method"][c["method"]].update(res["status"])
            for msg in res.get("messages", []):
                report["fallback_reasons"][c["method"]][re.sub(r"[-+]?\d[\d.e+-]*", "#", msg)[:80]] += 1
            if res["fail"]:
                slow_only = all(s.startswith("slow call") for s in res["fail"])
                small = shrink(c, res["fail"], dog) if shrink_failures and not slow_only else c
                report["fail"].append({"seed": seed, "fail": res["fail"][:3], "minimal": small})
                if log is not None:
                    print("FAIL " + json.dumps(report["fail"][-1], default=str), file=log, flush=True)
            if log is not None and n % 1000 == 999:
                print(f"{n + 1} cases, {len(report['fail'])} failing", file=log, flush=True)
    finally:
        dog.close()


def markdown_rows(report: dict[str, Any], note: str = "") -> str:
    """The docs' hostile-run table rows for a ``--json`` report: the run (cases, seeds, breaks,
    rate) and its calls and fallbacks by method, generated rather than typed."""
    seeds = report.get("seeds") or [None, None]
    fails = report["fail"]
    kinds = Counter(f["fail"][0].split(":")[0] for f in fails)
    breaks = f"{len(fails)}" + (" (" + ", ".join(f"{n} {k}" for k, n in kinds.most_common()) + ")" if fails else "")
    rate = report["cases"] / report["seconds"] if report.get("seconds") else 0.0
    stopped = " (stopped at its time limit)" if report.get("stopped_at_deadline") else ""
    run = (f"| {report['cases']:,}{stopped} | {seeds[0]:,}-{seeds[0] + report['cases'] - 1:,} | {breaks} | "
           f"{report.get('seconds', 0):,.0f} s ({rate:.1f} cases/s){note} |")
    lines = [run, "", "| method | calls | exact | unattainable | fallback |", "|---|---:|---:|---:|---:|"]
    for name, cnt in sorted(report["by_method"].items()):
        total = sum(cnt.values())
        lines.append(f"| `{name}` | {total:,} | {cnt.get('exact', 0):,} | {cnt.get('unattainable', 0):,} | "
                     f"{cnt.get('fallback', 0):,} |")
    return "\n".join(lines)


def main() -> None:  # pragma: no cover - command line
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the report here")
    ap.add_argument("--minutes", type=float, help="stop taking new cases after this long (report what ran)")
    ap.add_argument("--table", metavar="JSON", help="print the docs' table rows for a --json report and exit")
    a = ap.parse_args()
    if a.table:
        with open(a.table) as fh:
            print(markdown_rows(json.load(fh)))
        return
    t0 = time.time()
    global DEADLINE
    DEADLINE = None if a.minutes is None else t0 + 60 * a.minutes
    rep = run(range(a.seed, a.seed + a.cases), a.workers, log=sys.stderr)
    rep["seconds"] = round(time.time() - t0, 1)
    calls = {m: dict(c) for m, c in rep["by_method"].items()}
    rate = rep["cases"] / rep["seconds"] if rep["seconds"] else 0.0
    print(json.dumps({"cases": rep["cases"], "seeds": [a.seed, a.seed + a.cases - 1], "seconds": rep["seconds"],
                      "cases_per_second": round(rate, 1),
                      "stopped_at_deadline": rep.get("stopped_at_deadline", False), "refused": dict(rep["refused"]),
                      "classes": dict(rep["classes"]), "failures": len(rep["fail"]), "calls_by_method": calls},
                     indent=1))
    for f in rep["fail"][:20]:
        print(json.dumps(f, default=str)[:2000])
    for m, cnt in rep["fallback_reasons"].items():
        for msg, n in cnt.most_common(5):
            print(f"fallback {m}: {n} x {msg}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({**rep, "seeds": [a.seed, a.seed + a.cases - 1], "refused": dict(rep["refused"]),
                       "classes": dict(rep["classes"]),
                       "by_method": calls, "fallback_reasons": {m: dict(c) for m, c in rep["fallback_reasons"].items()}},
                      fh, indent=1, default=str)


if __name__ == "__main__":
    main()
