"""Effector failure catalogue of the comparison sweep, and how a failure reaches a scenario.

A failure in a sweep spec is a name.  Either the scenario knows it (the seed's composite
failures: ICE ``seed``, HARV lat-dir ``plant``/``failure1``/``failure2``, passed by name), or
it is ``<kind><n>`` from this catalogue: ``n`` = 1 (single) or 2 (double) effector failures
of one kind, effector-only (the plant, delays and bandwidths stay nominal), so the
comparison isolates what an allocator can do about a failed effector.

====================  ==================================================================
kind                  effect on each failed effector (range ``[lo, hi]``, rate ``r``)
====================  ==================================================================
``jam``               stuck at half its upper deflection (``hi / 2``; mid-range if one-sided)
``hardover``          command stuck at ``hi``, reached at the rate limit
``float``             zero effectiveness (the surface trails and produces no moment)
``loe``               loss of effectiveness: 25 % of its control power left
``limits``            reduced position and rate limits: ``[lo/4, hi/4]`` (a quarter of the
                      range around mid-range if one-sided) and ``r / 5``
====================  ==================================================================

Failed effectors (:data:`FAILED_EFFECTORS`): ICE -- single: left elevon; double: left
elevon and left leading-edge flap (the two surfaces the seed's ICE failure degrades).
HARV lat-dir -- single: aileron; double: aileron and rudder.

A *told* allocator is given the same failure as a changed :class:`alloc.Problem`
(:func:`sim.allocation.allocation_problem`); a *blind* one keeps the nominal problem.

A catalogue failure is a :class:`sim.loop.Failure`, handed to scenarios that take failure
objects (attribute ``accepts_failure_objects``: the MIMO scenarios of ``sim.scenarios.mimo``).
"""

from __future__ import annotations

import importlib
import re
from typing import Any

import numpy as np

__all__ = ["KINDS", "FAILED_EFFECTORS", "catalogue_names", "is_catalogue", "make_failure"]

#: failure kinds of the catalogue, in report order
KINDS = ("jam", "hardover", "float", "loe", "limits")

#: scenario -> effector indices failed by a single (first) and a double (both) failure
FAILED_EFFECTORS: dict[str, tuple[int, int]] = {
    "ice": (0, 7),          # elevon_l, lef_l (alloc.vehicles.ICE_EFFECTORS order)
    "harv_latdir": (1, 2),  # aileron, rudder (alloc.vehicles.HARV_LATDIR_EFFECTORS order)
}

_NAME = re.compile(r"^(?P<kind>[a-z]+)(?P<n>[12])$")
LOE_FRACTION = 0.25
LIMIT_FRACTION = 0.25
RATE_FRACTION = 0.2


def catalogue_names() -> list[str]:
    """``jam1, jam2, hardover1, ...`` in report order."""
    return [f"{k}{n}" for k in KINDS for n in (1, 2)]


def is_catalogue(name: str | None) -> bool:
    """Whether ``name`` is a catalogue failure (not one the scenario defines)."""
    m = _NAME.match(name or "")
    return bool(m) and m["kind"] in KINDS


def _vehicle(scenario: str) -> Any:
    module = importlib.import_module(f"sim.scenarios.{scenario}")
    return module.vehicle()


def make_failure(scenario: str, name: str, time: float) -> Any:
    """The :class:`sim.loop.Failure` named ``name`` (``<kind><1|2>``) for ``scenario`` at ``time``."""
    from sim.blocks import ActuatorFailure
    from sim.loop import Failure

    m = _NAME.match(name)
    if not m or m["kind"] not in KINDS:
        raise ValueError(f"failure: {name!r} is not a catalogue failure; expected <kind><1|2> with kind in {KINDS}")
    if scenario not in FAILED_EFFECTORS:
        raise ValueError(f"failure: no catalogue effectors for scenario {scenario!r}; known: {sorted(FAILED_EFFECTORS)}")
    vehicle = _vehicle(scenario)
    lo, hi, rate = vehicle.umin, vehicle.umax, vehicle.rate_max
    kind, count = m["kind"], int(m["n"])
    failures = []
    for i in FAILED_EFFECTORS[scenario][:count]:
        one_sided = lo[i] >= 0.0
        mid = 0.5 * (lo[i] + hi[i])
        if kind == "jam":
            failures.append(ActuatorFailure(i, "jam", position=mid if one_sided else 0.5 * hi[i]))
        elif kind == "hardover":
            failures.append(ActuatorFailure(i, "hardover", position=float(hi[i])))
        elif kind == "float":
            failures.append(ActuatorFailure(i, "float"))
        elif kind == "loe":
            failures.append(ActuatorFailure(i, "effectiveness", fraction=LOE_FRACTION))
        else:  # limits
            half = 0.5 * LIMIT_FRACTION * (hi[i] - lo[i])
            new_lo, new_hi = (mid - half, mid + half) if one_sided else (LIMIT_FRACTION * lo[i], LIMIT_FRACTION * hi[i])
            failures.append(ActuatorFailure(i, "limits", lo=float(new_lo), hi=float(new_hi),
                                            rate=float(RATE_FRACTION * rate[i])))
    names = ", ".join(vehicle.effector_names[i] for i in FAILED_EFFECTORS[scenario][:count])
    return Failure(name=name, time=float(time), description=f"{kind} of {names} at t = {time:g} s",
                   actuators=tuple(failures))


def failure_effectors(scenario: str, name: str) -> np.ndarray:
    """Indices of the effectors a catalogue failure affects (for the report's captions)."""
    m = _NAME.match(name)
    return np.array(FAILED_EFFECTORS[scenario][: int(m["n"])]) if m else np.array([], dtype=int)
