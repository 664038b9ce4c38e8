"""Closed-loop measures of one method in one scenario with one failure (one CSV row per spec).

Runs :func:`sim.scenarios.get_scenario` (``scenario``) with the spec's failure, failure
time, duration and noise seed, the allocator blind to the failure or told of it
(``allocator_knows_failure``), and writes :meth:`sim.result.SimResult.summary`: per
channel the RMS and max of the tracking error (reference - output) before and after the
failure, the time any effector sits at a position / rate limit, and divergence.
"""

from __future__ import annotations

import time
from typing import Any

from sim.result import SimResult
from sim.scenarios import get_scenario

from .openloop import method_options
from .sweep import STATIC, Spec

__all__ = ["simulate_spec", "run_closed", "METRICS"]

#: per-channel columns, named ``<channel>_<metric>``
METRICS = ("rms_before", "rms_after", "max_before", "max_after")


def simulate_spec(spec: Spec) -> SimResult:
    """The closed-loop simulation a spec describes (also used to redraw time histories)."""
    run = get_scenario(spec["scenario"])
    options = None if spec["method"] == STATIC else (method_options(spec["scenario"], spec["method"]) or None)
    extra = {} if spec.get("pilot_gain") is None else {"pilot_gain": spec["pilot_gain"]}
    return run(
        method=spec["method"], failure=spec["failure"], duration=spec["duration"], seed=spec["seed"],
        allocator_knows_failure=spec["told"], failure_time=spec["failure_time"], noise=spec["noise"],
        method_options=options, **extra,
    )


def run_closed(spec: Spec) -> tuple[dict[str, Any], dict[str, Any]]:
    """Row and timings of one closed-loop spec."""
    t0 = time.perf_counter()
    summary = simulate_spec(spec).summary()
    wall = time.perf_counter() - t0
    row: dict[str, Any] = {
        "id": spec["id"], "scenario": spec["scenario"], "failure": spec["failure"],
        "method": spec["method"], "told": spec["told"], "seed": spec["seed"],
        "duration": spec["duration"], "failure_time": spec["failure_time"], "noise": spec["noise"],
        "pilot_gain": spec.get("pilot_gain"),
        "diverged": summary["diverged"], "simulated": summary["duration"],
    }
    for channel, metrics in summary["channels"].items():
        for metric in METRICS:
            row[f"{channel}_{metric}"] = metrics[metric]
    row["time_in_position_saturation"] = summary["time_in_position_saturation"]
    row["time_in_rate_saturation"] = summary["time_in_rate_saturation"]
    return row, {"id": spec["id"], "wall_s": wall, "simulated_per_wall_s": summary["duration"] / wall}
