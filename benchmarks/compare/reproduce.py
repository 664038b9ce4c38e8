"""Re-run committed closed-loop sweep rows and compare them with the committed CSVs.

``python -m benchmarks.compare.reproduce --sample N --seed S [--json]`` draws ``N`` closed-loop
specs of a sweep folder (default ``benchmarks/reference/full``) with a seeded generator, re-runs
each with the current code (:func:`benchmarks.compare.closedloop.run_closed`, no stored history)
and prints, per row, ``same`` (every column bit for bit), ``within`` (every discrete column bit for
bit, every continuous column within ``--rtol``) or ``differs``, then the largest relative
difference per column over the sample.  Exit status 0 when no row differs, 1 otherwise.

Two kinds of column, because they fail differently:

* **discrete** (:data:`DISCRETE`: the spec's own fields, ``diverged``, ``simulated``,
  ``recover_s``, the saturation times and the unattainable/fallback fractions) are counts,
  flags or thresholds crossed; they must agree exactly.
* **continuous** (``<channel>_rms|max_before|after``, ``effort_after``) are sums over a
  trajectory.  The committed rows were computed on another machine and dependency build than
  the one a reader has; OpenBLAS chooses its kernels per CPU, and the runs' first BLAS-bound
  step (the zero-order-hold discretisation, ``scipy.linalg.expm``) then differs in the last
  bit of a few entries; the closed loop carries that (measured: most rows move by 1e-14 to
  1e-12 relative; swapping the OpenBLAS kernel on one machine moves them by as much), so these
  are compared to :data:`DEFAULT_RTOL` (1e-9: over a thousand times the largest seen outside
  the setting below, 4e-13, and a million times below the smallest model change a sweep is
  meant to show).

A diverged run is compared up to its divergence only: once the state grows without bound, the
round-off difference grows with it (measured: an ICE ``daisy`` run that diverges 5 s after its
failure diverges 35 ms later and its post-failure RMS moves by 3 %), so the columns computed over
the diverging stretch (:func:`unjudged_columns`) are reported in ``unjudged`` and do not decide
the verdict; ``diverged`` itself must still agree.

One setting amplifies round-off far more: HARV lat-dir at 100 Hz (``frame_period`` set; the
sampled-data loop near its stability boundary, where most of HARV's divergences are).  There the
same rows move by up to 1e-6 relative before the failure, and after it, where the loop rides its
position and rate limits, a last-bit difference flips a saturation and the trajectories part
(measured: a ``daisy`` row's post-failure roll-rate peak moves by 33 %, its saturation times by
0.3 s, under the committing commit's code as under main's).  Its rows (:func:`is_sensitive`) are
judged on ``diverged`` and the spec exactly and on the columns before the failure within
:data:`SENSITIVE_RTOL`; the columns after the failure are reported in ``unjudged``.

Elsewhere a run can ride its limits after the failure too (measured: a HARV lat-dir 0.5 ms
``da_facet`` hard-over row, pilot gain 2, whose post-failure roll-rate peak moves by 1.3 %).
``--control KERNEL`` finds such columns by measurement instead of by setting: it runs each row
again under another OpenBLAS kernel (``OPENBLAS_CORETYPE``) and leaves unjudged the columns that
perturbation moves beyond the tolerance (:func:`sensitive_columns`); ``diverged`` is always
judged.

A column in the CSV that the current code no longer writes (or the reverse) is listed in the
row's ``missing`` / ``new``; it does not make the row differ.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from alloc.exceptions import AllocError

__all__ = [
    "DEFAULT_REFERENCE", "DEFAULT_RTOL", "SENSITIVE_RTOL", "DISCRETE", "ReproduceError", "RowComparison",
    "load_reference", "sample_ids", "is_sensitive", "unjudged_columns", "sensitive_columns", "control_rows",
    "compare_row", "reproduce", "summarise", "main",
]

DEFAULT_REFERENCE = Path(__file__).resolve().parents[1] / "reference" / "full"
DEFAULT_RTOL = 1e-9
#: before-failure tolerance of the round-off-sensitive setting (:func:`is_sensitive`): 13x the
#: largest difference measured there (16 rows: 1.6e-7 committed against here, 7.6e-7 between two
#: OpenBLAS kernels on one machine, both on a ``daisy`` row that rides its rate limits)
SENSITIVE_RTOL = 1e-5
#: columns that are counts, flags, thresholds crossed or the spec itself: compared exactly
DISCRETE = frozenset({
    "id", "scenario", "setting", "failure", "method", "told", "health", "seed", "duration", "failure_time",
    "noise", "diverged", "simulated", "recover_s", "unattainable_after", "fallback_after",
    "time_in_position_saturation", "time_in_rate_saturation",
    "verdict_pass", "verdict_broken", "back_in_band_s",  # the engineering verdict (sim.criteria)
})


#: columns computed over the stretch after the failure (diverging, when the run diverged)
_AFTER = frozenset({"simulated", "recover_s", "effort_after", "unattainable_after", "fallback_after",
                    "time_in_position_saturation", "time_in_rate_saturation",
                    "verdict_pass", "verdict_broken", "back_in_band_s"})


class ReproduceError(AllocError, ValueError):
    """A reproduction request names a folder, row or number that cannot be used."""


@dataclass(frozen=True)
class RowComparison:
    """One re-run row against its committed row.

    ``verdict`` is ``"same"`` (bit for bit), ``"within"`` (discrete columns exact, continuous
    within ``rtol``) or ``"differs"``; ``rel_diff`` maps every continuous column to
    ``|new - committed| / max(|committed|, tiny)`` (0 when equal, ``inf`` when one side is
    non-finite and the other is not); ``discrete_diffs`` maps each differing discrete column
    to ``(committed text, new text)``.
    """

    id: str
    verdict: str
    rel_diff: dict[str, float]
    discrete_diffs: dict[str, tuple[str, str]]
    unjudged: dict[str, tuple[str, str]] = field(default_factory=dict)
    missing: tuple[str, ...] = ()
    new: tuple[str, ...] = ()
    wall_s: float = 0.0
    rtol: float = DEFAULT_RTOL


def load_reference(folder: Path = DEFAULT_REFERENCE) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, str]]]:
    """Closed-loop specs (by id) of a sweep folder and their committed rows (by id, as text).

    Read once per folder and shared (40,020 rows take seconds to parse): treat as read-only.
    """
    return _load_reference(Path(folder).resolve())


@functools.lru_cache(maxsize=4)
def _load_reference(folder: Path) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, str]]]:
    specs_path = folder / "specs.json"
    if not specs_path.is_file():
        raise ReproduceError(f"reference: {folder} has no specs.json (not a sweep folder)")
    specs = {s["id"]: s for s in json.loads(specs_path.read_text()) if s.get("kind") == "closed"}
    rows: dict[str, dict[str, str]] = {}
    for path in sorted(folder.glob("closed_*.csv")):
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            if "id" not in (reader.fieldnames or []) or "diverged" not in (reader.fieldnames or []):
                continue  # the cells, timings and told/blind tables beside the row tables
            for r in reader:
                rows[r["id"]] = r
    specs = {k: v for k, v in specs.items() if k in rows}
    if not specs:
        raise ReproduceError(f"reference: {folder} has no closed-loop rows with a spec")
    return specs, rows


def sample_ids(specs: dict[str, dict[str, Any]], n: int, seed: int, *, exclude_methods: Sequence[str] = ()) -> list[str]:
    """``n`` spec ids drawn without replacement by ``numpy.random.default_rng(seed)`` (sorted ids first)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ReproduceError(f"sample: {n!r} is not a positive whole number")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ReproduceError(f"seed: {seed!r} is not a whole number >= 0")
    pool = sorted(i for i, s in specs.items() if s["method"] not in set(exclude_methods))
    if n > len(pool):
        raise ReproduceError(f"sample: {n} is more than the {len(pool)} rows that can be drawn")
    picked = np.random.default_rng(seed).choice(len(pool), size=n, replace=False)
    return [pool[int(i)] for i in picked]


def _text(value: Any) -> str:
    """A value as the sweep's CSV writer stores it (``csv`` writes ``str``; ``None`` as empty)."""
    return "" if value is None else str(value)


def _number(text: str) -> float:
    return math.nan if text == "" else float(text)


def _relative(committed: float, new: float) -> float:
    if committed == new or (math.isnan(committed) and math.isnan(new)):
        return 0.0
    if not (math.isfinite(committed) and math.isfinite(new)):
        return math.inf
    return abs(new - committed) / max(abs(committed), sys.float_info.min)


def is_sensitive(committed: dict[str, str]) -> bool:
    """Whether a row is of the setting that amplifies round-off most (HARV lat-dir at 100 Hz)."""
    return committed.get("scenario") == "harv_latdir" and "frame_period=" in committed.get("setting", "")


def unjudged_columns(committed: dict[str, str], columns: Sequence[str]) -> set[str]:
    """Columns of a committed row that are reported but do not decide its verdict.

    A run that did not diverge, outside the sensitive setting: none.  After the failure when
    the run diverged after its failure, or is of the sensitive setting; every trajectory column
    when it diverged before its failure (``simulated <= failure_time``).
    """
    diverged = committed.get("diverged") == "True"
    if not diverged and not is_sensitive(committed):
        return set()
    after = {c for c in columns if c.endswith("_after") or c in _AFTER}
    if not diverged:
        return after
    try:
        before_failure = float(committed["simulated"]) <= float(committed["failure_time"])
    except (KeyError, ValueError):
        before_failure = True
    if before_failure:
        after |= {c for c in columns if c.endswith("_before")}
    return after


def sensitive_columns(row: dict[str, Any], control: dict[str, Any], rtol: float = DEFAULT_RTOL) -> set[str]:
    """Columns that the same run under another BLAS kernel (``control``) moves beyond ``rtol``.

    Those are the row's own round-off-sensitive columns: no machine but the one that wrote them
    can be expected to give them again.  Discrete columns count when they change at all.
    """
    out = set()
    for name, value in row.items():
        if name not in control:
            continue
        a, b = _text(value), _text(control[name])
        if name in DISCRETE:
            if a != b:
                out.add(name)
        elif _relative(_number(a), _number(b)) > rtol:
            out.add(name)
    return out


def compare_row(committed: dict[str, str], row: dict[str, Any], *, rtol: float = DEFAULT_RTOL,
                wall_s: float = 0.0, control: dict[str, Any] | None = None) -> RowComparison:
    """Compare a freshly computed row with its committed text row (see the module docstring).

    ``control`` is the same run under another BLAS kernel (:func:`control_rows`); the columns it
    moves (:func:`sensitive_columns`) are reported in ``unjudged`` instead of judged.
    """
    if not (isinstance(rtol, (int, float)) and not isinstance(rtol, bool) and math.isfinite(rtol) and rtol >= 0):
        raise ReproduceError(f"rtol: {rtol!r} is not a finite number >= 0")
    rel: dict[str, float] = {}
    discrete: dict[str, tuple[str, str]] = {}
    unjudged: dict[str, tuple[str, str]] = {}
    skip = unjudged_columns(committed, list(row))
    if control is not None:
        skip |= sensitive_columns(row, control, rtol) - {"id", "diverged"}
    for name, value in row.items():
        if name not in committed:
            continue
        old, new = committed[name], _text(value)
        if name in skip:
            if old != new:
                unjudged[name] = (old, new)
        elif name in DISCRETE:
            if old != new:
                discrete[name] = (old, new)
        else:
            rel[name] = _relative(_number(old), _number(new))
    if is_sensitive(committed):
        rtol = max(rtol, SENSITIVE_RTOL)
    if discrete or any(r > rtol for r in rel.values()):
        verdict = "differs"
    elif unjudged or any(r > 0 for r in rel.values()):
        verdict = "within"
    else:
        verdict = "same"
    return RowComparison(
        id=str(row.get("id", committed.get("id", ""))), verdict=verdict, rel_diff=rel, discrete_diffs=discrete,
        unjudged=unjudged,
        missing=tuple(k for k in committed if k not in row), new=tuple(k for k in row if k not in committed),
        wall_s=wall_s, rtol=float(rtol),
    )


_CONTROL_SCRIPT = """
import json, sys
from pathlib import Path
from benchmarks.compare.closedloop import run_closed
from benchmarks.compare.reproduce import load_reference
ask = json.load(sys.stdin)
specs, _ = load_reference(Path(ask["reference"]))
rows = {i: run_closed(dict(specs[i], history=False))[0] for i in ask["ids"]}
json.dump(rows, sys.stdout, default=str)
"""


def control_rows(ids: Sequence[str], *, reference: Path = DEFAULT_REFERENCE,
                 kernel: str = "Prescott") -> dict[str, dict[str, Any]]:
    """The rows ``ids`` run again in a fresh interpreter with ``OPENBLAS_CORETYPE=kernel``.

    OpenBLAS built with ``DYNAMIC_ARCH`` (numpy's and scipy's wheels) then uses that kernel in
    place of the one it picks for this CPU: a controlled last-bit perturbation of the same
    computation, the kind another machine makes.  ``Prescott`` (SSE3) runs on every x86-64.
    """
    if not isinstance(kernel, str) or not kernel.isidentifier():
        raise ReproduceError(f"control: {kernel!r} is not an OpenBLAS kernel name (e.g. Prescott, Sandybridge)")
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel)
    done = subprocess.run([sys.executable, "-c", _CONTROL_SCRIPT], input=json.dumps(
        {"reference": str(reference), "ids": list(ids)}), env=env, capture_output=True, text=True,
        cwd=Path(__file__).resolve().parents[2])
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
        raise ReproduceError(f"control: the run under OPENBLAS_CORETYPE={kernel} failed: {tail[0]}")
    return json.loads(done.stdout)


def reproduce(ids: Sequence[str], *, reference: Path = DEFAULT_REFERENCE, rtol: float = DEFAULT_RTOL,
              progress: Any = None, control: str | None = None) -> list[RowComparison]:
    """Re-run the committed rows ``ids`` of ``reference`` and compare each (in the order given).

    ``control`` names an OpenBLAS kernel: each row is also run under it (:func:`control_rows`)
    and the columns that moves are not judged.
    """
    from .closedloop import run_closed

    specs, rows = load_reference(reference)
    unknown = [i for i in ids if i not in specs]
    if unknown:
        raise ReproduceError(f"id: {unknown[0]!r} is not a closed-loop row of {reference}")
    controls = control_rows(ids, reference=reference, kernel=control) if control is not None else {}
    out = []
    for rid in ids:
        t0 = time.perf_counter()
        row, _, _ = run_closed(dict(specs[rid], history=False))
        result = compare_row(rows[rid], row, rtol=rtol, wall_s=time.perf_counter() - t0,
                             control=controls.get(rid))
        out.append(result)
        if progress is not None:
            progress(result)
    return out


def summarise(results: Sequence[RowComparison]) -> dict[str, Any]:
    """Counts per verdict and, per continuous column, the largest relative difference and its row."""
    worst: dict[str, tuple[float, str]] = {}
    for r in results:
        for name, d in r.rel_diff.items():
            if name not in worst or d > worst[name][0]:
                worst[name] = (d, r.id)
    discrete = sorted({name for r in results for name in r.discrete_diffs})
    return {
        "rows": len(results),
        "verdicts": {v: sum(r.verdict == v for r in results) for v in ("same", "within", "differs")},
        "max_rel_diff": {k: {"value": v, "row": i} for k, (v, i) in sorted(worst.items())},
        "discrete_columns_differing": discrete,
        "rows_with_unjudged_columns": sum(bool(r.unjudged) for r in results),
    }


def _line(r: RowComparison) -> str:
    worst = max(r.rel_diff.items(), key=lambda kv: kv[1], default=("-", 0.0))
    text = f"{r.verdict:7s} {r.id}  max rel {worst[1]:.1e} ({worst[0]})  {r.wall_s:.1f} s"
    if r.discrete_diffs:
        text += "  " + ", ".join(f"{k}: {a!r} -> {b!r}" for k, (a, b) in sorted(r.discrete_diffs.items()))
    if r.unjudged:
        text += f"  (differ, not judged: {', '.join(sorted(r.unjudged))})"
    return text


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit status (2 for a bad argument, one stderr line)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m benchmarks.compare.reproduce",
                                     description="Re-run committed sweep rows and compare them column by column.")
    parser.add_argument("--sample", type=int, default=5, help="rows to draw (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draw (default 0)")
    parser.add_argument("--id", action="append", default=[], metavar="ID",
                        help="re-run this row (repeatable; replaces the draw)")
    parser.add_argument("--reference", type=Path, default=DEFAULT_REFERENCE, help="sweep folder")
    parser.add_argument("--rtol", type=float, default=DEFAULT_RTOL,
                        help=f"relative tolerance of continuous columns (default {DEFAULT_RTOL:g})")
    parser.add_argument("--exclude-method", action="append", default=[], metavar="METHOD",
                        help="leave this method out of the draw (repeatable)")
    parser.add_argument("--control", metavar="KERNEL", default=None,
                        help="also run each row under this OpenBLAS kernel (e.g. Prescott) and leave the "
                             "columns that moves unjudged (about twice the time)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of lines")
    args = parser.parse_args(argv)
    try:
        specs, _ = load_reference(args.reference)
        ids = list(args.id) or sample_ids(specs, args.sample, args.seed, exclude_methods=args.exclude_method)
        results = reproduce(ids, reference=args.reference, rtol=args.rtol, control=args.control,
                            progress=None if args.json else (lambda r: print(_line(r), flush=True)))
    except ReproduceError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    summary = summarise(results)
    if args.json:
        json.dump({"reference": str(args.reference), "rtol": args.rtol, "summary": summary,
                   "rows": [asdict(r) for r in results]}, sys.stdout, indent=1, default=str)
        print()
    else:
        print(f"{summary['rows']} rows: " + ", ".join(f"{v} {k}" for k, v in summary["verdicts"].items()))
        for name, w in summary["max_rel_diff"].items():
            print(f"  {name:32s} max rel diff {w['value']:.2e}  ({w['row']})")
        if summary["rows_with_unjudged_columns"]:
            print(f"  rows with columns not judged (diverged, 100 Hz HARV after the failure, or moved by the "
                  f"control): {summary['rows_with_unjudged_columns']}")
        if summary["discrete_columns_differing"]:
            print("  discrete columns differing: " + ", ".join(summary["discrete_columns_differing"]))
    return 1 if summary["verdicts"]["differs"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
