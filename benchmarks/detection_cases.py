"""The detection measurements' cases and their bookkeeping (a leaf: no benchmark imports here).

What :mod:`benchmarks.bench_detection` and :mod:`benchmarks.detection_evidence` share: the
scenarios, issue 26's goals, the detection cases and their failures, the ``delays`` section's
failure times, the first detection on a failed effector, the JSON-lines files and the
markdown tables.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.compare.failures import catalogue_kinds, make_failure
from sim.actuator_failure import ActuatorFailure

SCENARIOS = ("ice", "harv_latdir")
#: goals of issue 26 (seconds)
JAM_P95_GOAL = 0.5
LOE_GOAL = 2.0

#: detection cases: the catalogue's kinds (its loss of effectiveness leaves 25 %), losses of 50 %
#: and 25 % (fractions 0.5, 0.75), and the catalogue's reduced rate limits alone
EXTRA_CASES = {"loe50": ("effectiveness", {"fraction": 0.5}), "loe25": ("effectiveness", {"fraction": 0.75}),
               "rate_limits": ("rate_limits", None)}


def detection_cases() -> tuple[str, ...]:
    return (*catalogue_kinds(), *EXTRA_CASES)


def case_kind(case: str) -> str:
    """The failure kind of a detection case (what a right isolation names)."""
    return EXTRA_CASES[case][0] if case in EXTRA_CASES else case


def case_failure(scenario: str, case: str, time: float) -> Any:
    """The single-effector failure of ``case`` at ``time`` (the catalogue's, or a variant of it)."""
    if case not in EXTRA_CASES:
        return make_failure(scenario, f"{case}1", time)
    kind, params = EXTRA_CASES[case]
    base = make_failure(scenario, "effectiveness1" if kind == "effectiveness" else "limits1", time)
    if params is None:  # the rider alone (the catalogue's rate limits, without its position limits)
        acts = tuple(a for a in base.actuators if a.kind == kind)
    else:
        acts = tuple(ActuatorFailure(a.index, kind, **params) for a in base.actuators)
    return dataclasses.replace(base, name=case, description=f"{case}: {acts}", actuators=acts)


def write_row(out: Path, section: str, row: dict[str, Any]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with open(out / f"{section}.jsonl", "a") as fh:
        fh.write(json.dumps(row) + "\n")


def done_keys(out: Path, section: str) -> set[str]:
    path = out / f"{section}.jsonl"
    if not path.exists():
        return set()
    return {json.loads(line)["key"] for line in path.read_text().splitlines() if line.strip()}


def delay_failure_time(s: int, scenario: str, case: str) -> float:
    """The ``delays`` section's failure time of seed index ``s``: seeded, uniform in [2, 3] s, 10 ms grid."""
    rng = np.random.default_rng([s, SCENARIOS.index(scenario), detection_cases().index(case)])
    return float(np.round(rng.uniform(2.0, 3.0), 2))


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def first_on_failed(row: dict[str, Any]) -> dict[str, Any] | None:
    """The first detection at or after the failure naming a failed effector."""
    for d in row["detections"]:
        if d["delay"] is not None and d["effector"] in row["failed"]:
            return d
    return None
