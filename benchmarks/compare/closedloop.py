"""Closed-loop measures of one method in one scenario with one failure (one CSV row per spec).

Runs :func:`sim.scenarios.get_scenario` (``scenario``) with the spec's failure (by name, or a
catalogue failure from :mod:`.failures`), failure time, duration, noise seed and simulator
setting (``spec["sim"]``, passed through by keyword), the allocator blind to the failure, told
of it (``allocator_knows_failure``) or learning of it from the in-loop detector (``health``
``detected``; the row's ``health`` names the arm).  Row columns:

* ``<channel>_rms_before|after``, ``<channel>_max_before|after`` -- tracking error
  (reference - output) before and after the failure (:meth:`sim.result.SimResult.summary`).
* ``diverged``, ``simulated`` (s actually simulated; shorter when diverged).
* ``recover_s`` -- time from the failure until the 1 s windowed RMS tracking error of every
  channel stays within :data:`RECOVERY_FACTOR` x its pre-failure RMS to the end of the run
  (``inf``: never, or diverged; empty: no pre-failure interval).
* ``effort_after`` -- mean over post-failure samples and effectors of ``|u_i| / max(|lo_i|, |hi_i|)``
  (nominal limits): 0 = at rest, 1 = every effector at full deflection all the time.
* ``unattainable_after`` -- fraction of post-failure samples where the allocator did not meet its
  demand by its own model (``|v - v_achieved| > 1e-6 (1 + |v|)``, from the simulator's
  ``unallocated``: clipping counts, so ``pinv`` on ICE, whose one-sided effectors it drives
  negative, scores near 1 even before a failure), unless the simulator reports its own
  ``unattainable_fraction``.
* ``fallback_after`` -- fraction of allocator calls with status ``fallback``, when the simulator
  reports it (``fallback_fraction`` in the summary); empty otherwise.
* ``time_in_position_saturation``, ``time_in_rate_saturation`` (s).
* ``verdict_pass``, ``verdict_broken`` -- the run judged by its scenario's engineering criteria
  (:mod:`sim.criteria`): passed or not, and the broken criteria's names joined by ``;`` (empty
  when it passed); the criteria's metrics not already among the columns above follow under their
  own names (``<channel>_excursion_before|after``, ``position_saturation_before|after``,
  ``rate_saturation_before|after`` as fractions of the phase, ``back_in_band_s``).  A scenario
  with no criteria table leaves ``verdict_pass`` empty.

Runs with ``spec["history"]`` also return their time history (written by the runner to
``histories/``) so the report draws time histories from stored runs, never re-simulating.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from sim.result import SimResult
from sim.scenarios import get_scenario

from .failures import is_catalogue, make_failure
from .openloop import method_options
from .sweep import STATIC, Spec, setting_tag

__all__ = ["simulate_spec", "run_closed", "METRICS", "RECOVERY_FACTOR", "recovery_time", "history_of", "verdict_columns"]

#: per-channel columns, named ``<channel>_<metric>``
METRICS = ("rms_before", "rms_after", "max_before", "max_after")
RECOVERY_FACTOR = 2.0
RECOVERY_WINDOW_S = 1.0


def simulate_spec(spec: Spec) -> SimResult:
    """The closed-loop simulation a spec describes.

    A spec with a ``vehicle`` (a vehicle file or catalogue name with a ``[model]``) flies that
    model with the seed's section 4.3 auto-design (:func:`sim.user_vehicle.fly`, which merges
    the vehicle's method defaults); its failure is a name of :data:`sim.user_vehicle.FAILURE_SYNTAX`.
    A spec with a ``plant`` other than ``linear`` flies :func:`sim.plants.fly_on_plant` (no sensor noise:
    the plant loop's own).
    """
    if spec.get("plant") not in (None, "linear"):  # a third-party plant (sim.plants), its own loop and commands
        from sim.plants import fly_on_plant

        return fly_on_plant(spec.get("vehicle"), spec["plant"], method=spec["method"], failure=spec["failure"],
                            failure_time=spec["failure_time"], duration=spec["duration"], seed=spec["seed"],
                            health=spec.get("health", "told" if spec["told"] else "blind"))
    if spec.get("vehicle") is not None:
        from sim.user_vehicle import fly

        return fly(spec["vehicle"], method=spec["method"], failure=spec["failure"], failure_time=spec["failure_time"],
                   duration=spec["duration"], seed=spec["seed"], allocator_knows_failure=spec["told"],
                   noise=spec["noise"], **spec["sim"])
    scenario = spec["scenario"]
    run = get_scenario(scenario)
    options = None if spec["method"] == STATIC else (method_options(scenario, spec["method"]) or None)
    kwargs = dict(method=spec["method"], duration=spec["duration"], seed=spec["seed"],
                  allocator_knows_failure=spec["told"], failure_time=spec["failure_time"], noise=spec["noise"],
                  method_options=options, **spec["sim"])
    if spec.get("health") == "detected":
        kwargs["health"] = "detected"
    if not is_catalogue(spec["failure"]):
        return run(failure=spec["failure"], **kwargs)
    failure = make_failure(scenario, spec["failure"], spec["failure_time"])
    if not getattr(run, "accepts_failure_objects", False):
        raise ValueError(f"failure {spec['failure']!r}: scenario {scenario!r} does not take catalogue failures")
    return run(failure=failure, **kwargs)


def recovery_time(t: np.ndarray, err: np.ndarray, failure_time: float, rms_before: np.ndarray) -> float:
    """See ``recover_s`` in the module docstring."""
    if not np.all(np.isfinite(rms_before)) or failure_time <= t[0]:
        return math.nan
    after = t >= failure_time
    ta, ea = t[after], err[after]
    if ta.size == 0:
        return math.nan
    # full windows only: samples past the last full window join it (a lone end sample is no window)
    n_windows = max(1, int(np.floor((ta[-1] - failure_time) / RECOVERY_WINDOW_S + 1e-9)))
    window = np.minimum(np.floor((ta - failure_time) / RECOVERY_WINDOW_S).astype(int), n_windows - 1)
    last_bad = -1
    for w in range(n_windows):
        sel = window == w
        if not np.any(sel):
            continue
        rms = np.sqrt(np.mean(ea[sel] ** 2, axis=0))
        if np.any(rms > RECOVERY_FACTOR * rms_before):
            last_bad = w
    if last_bad == n_windows - 1:
        return math.inf
    return float((last_bad + 1) * RECOVERY_WINDOW_S)


def verdict_columns(verdict: dict[str, Any] | None, row: dict[str, Any]) -> dict[str, Any]:
    """A summary's ``verdict`` as row columns (module docstring); metrics already in ``row`` are not repeated."""
    if verdict is None:
        return {"verdict_pass": None, "verdict_broken": None}
    out: dict[str, Any] = {"verdict_pass": verdict["pass"], "verdict_broken": ";".join(verdict["broken"])}
    for name, value in verdict["metrics"].items():
        if name not in row:
            out[name] = math.inf if value == "inf" else value
    return out


def history_of(spec: Spec, res: SimResult) -> dict[str, np.ndarray]:
    """The arrays kept for a stored run (float32 signals; names as string arrays)."""
    return {
        "id": np.array(spec["id"]), "t": res.t.astype(np.float32),
        "channels": np.array(res.channels), "reference": res.reference.astype(np.float32),
        "output": res.output.astype(np.float32),
        "effector_names": np.array(res.effector_names),
        "effectors": (res.effectors if res.effectors is not None else np.zeros((res.t.size, 0))).astype(np.float32),
        "failure_time": np.array(np.nan if res.failure_time is None else res.failure_time),
        "diverged": np.array(bool(res.diverged)),
    }


def run_closed(spec: Spec) -> tuple[dict[str, Any], dict[str, Any], dict[str, np.ndarray] | None]:
    """Row, timings and (for ``history`` specs) the time history of one closed-loop spec."""
    t0 = time.perf_counter()
    res = simulate_spec(spec)
    wall = time.perf_counter() - t0
    summary = res.summary()
    row: dict[str, Any] = {
        "id": spec["id"], "scenario": spec["scenario"], "setting": setting_tag(spec["sim"]),
        "failure": spec["failure"], "method": spec["method"], "told": spec["told"],
        "health": spec.get("health", "told" if spec["told"] else "blind"), "seed": spec["seed"],
        "duration": spec["duration"], "failure_time": spec["failure_time"], "noise": spec["noise"],
        "diverged": summary["diverged"], "simulated": summary["duration"],
    }
    rms_before = []
    for channel, metrics in summary["channels"].items():
        for metric in METRICS:
            row[f"{channel}_{metric}"] = metrics[metric]
        rms_before.append(math.nan if metrics["rms_before"] is None else metrics["rms_before"])
    after = res.t >= spec["failure_time"]
    if res.diverged:
        row["recover_s"] = math.inf
    else:
        row["recover_s"] = recovery_time(res.t, res.error, spec["failure_time"], np.array(rms_before))
    if res.effectors is not None and np.any(after):
        scale = np.maximum(np.abs(res.effector_limits[0]), np.abs(res.effector_limits[1]))
        scale = scale[0] if scale.ndim == 2 else scale  # nominal limits (first sample)
        row["effort_after"] = float(np.mean(np.abs(res.effectors[after]) / np.where(scale > 0, scale, 1.0)))
    else:
        row["effort_after"] = math.nan
    if "unattainable_fraction" in summary:
        row["unattainable_after"] = summary["unattainable_fraction"]
    elif res.unallocated is not None and res.pseudo is not None and np.any(after):
        gap = np.linalg.norm(res.unallocated[after], axis=1)
        row["unattainable_after"] = float(np.mean(gap > 1e-6 * (1.0 + np.linalg.norm(res.pseudo[after], axis=1))))
    else:
        row["unattainable_after"] = math.nan
    row["fallback_after"] = summary.get("fallback_fraction")
    row["time_in_position_saturation"] = summary["time_in_position_saturation"]
    row["time_in_rate_saturation"] = summary["time_in_rate_saturation"]
    row.update(verdict_columns(summary["verdict"], row))
    timing = {"id": spec["id"], "wall_s": wall, "simulated_per_wall_s": summary["duration"] / wall}
    return row, timing, history_of(spec, res) if spec.get("history") else None
