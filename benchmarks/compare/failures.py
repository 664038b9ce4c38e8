"""Effector failure catalogue of the comparison sweep, and how a failure reaches a scenario.

A failure in a sweep spec is a name.  Either the scenario knows it (the seed's composite
failures: ICE ``seed``, HARV lat-dir ``plant``/``failure1``/``failure2``, passed by name), or
it is ``<kind><n>`` from this catalogue: ``n`` = 1 (single) or 2 (double) effector failures
of one kind, effector-only (the plant, delays and bandwidths stay nominal), so the
comparison isolates what an allocator can do about a failed effector.

The catalogue's kinds are the failure kinds of the library's table
(:data:`alloc.health.FAILURE_KINDS`, registered kinds included) except ``repair``, in table
order.  Each failed effector gets the parameters its kind's effects read, set by the effect
(:data:`SEVERITY`, the catalogue's own choice of how hard a failure is):

====================  ==================================================================
effect                parameters on each failed effector (range ``[lo, hi]``, rate ``r``)
====================  ==================================================================
``HOLD``              ``position``: half its upper deflection (``hi / 2``; mid-range if one-sided)
``RUN_TO_STOP``       ``position``: ``hi``, reached at the rate limit
``TRAIL``             none (zero effectiveness: the surface trails and produces no moment)
``SCALE``             ``fraction``: 25 % of its control power left
``LIMITS``            ``[lo/4, hi/4]`` (a quarter of the range around mid-range if one-sided)
``RATE_LIMITS``       ``[-r/5, r/5]``
====================  ==================================================================

So ``jam``, ``hardover``, ``float``, ``effectiveness`` and ``limits``.  The catalogue's
``limits`` also reduces the rate limits (the seed's failure list has "reduced position and rate
limits", section 4.7): ``rate_limits`` rides with ``limits`` (:data:`RIDES_WITH`) and has no
catalogue name of its own.

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
from collections.abc import Callable
from typing import Any

import numpy as np

from alloc.health import Effect, FailureKind
from sim import criteria as _criteria

__all__ = ["KINDS", "FAILED_EFFECTORS", "SEVERITY", "RIDES_WITH", "catalogue_kinds", "catalogue_names",
           "canonical_name", "is_catalogue", "make_failure"]

#: scenario -> effector indices failed by a single (first) and a double (both) failure
FAILED_EFFECTORS: dict[str, tuple[int, int]] = {
    "ice": (0, 7),          # elevon_l, lef_l (alloc.vehicles.ICE_EFFECTORS order)
    "harv_latdir": (1, 2),  # aileron, rudder (alloc.vehicles.HARV_LATDIR_EFFECTORS order)
}

_NAME = re.compile(r"^(?P<kind>[a-z_]+?)(?P<n>[12])$")
LOE_FRACTION = 0.25
LIMIT_FRACTION = 0.25
RATE_FRACTION = 0.2

#: kind -> the kind whose catalogue failure it joins (and so has no catalogue name of its own)
RIDES_WITH = {"rate_limits": "limits"}

#: Rows written before the failure kinds had one name (benchmarks/reference/, 2026-11) call loss of
#: effectiveness ``loe``; those CSVs are kept as run, so their names still read as today's.
_LEGACY_KINDS = {"loe": "effectiveness"}


def _hold(lo: float, hi: float, rate: float) -> dict[str, float]:
    return {"position": 0.5 * (lo + hi) if lo >= 0.0 else 0.5 * hi}


def _quarter_range(lo: float, hi: float, rate: float) -> dict[str, float]:
    if lo >= 0.0:  # one-sided: a quarter of the range around mid-range
        mid, half = 0.5 * (lo + hi), 0.5 * LIMIT_FRACTION * (hi - lo)
        return {"lo": float(mid - half), "hi": float(mid + half)}
    return {"lo": float(LIMIT_FRACTION * lo), "hi": float(LIMIT_FRACTION * hi)}


#: effect -> the parameters a catalogue failure sets, from the effector's range [lo, hi] and rate
SEVERITY: dict[Effect, Callable[[float, float, float], dict[str, float]]] = {
    Effect.HOLD: _hold,
    Effect.RUN_TO_STOP: lambda lo, hi, rate: {"position": float(hi)},
    Effect.TRAIL: lambda lo, hi, rate: {},
    Effect.SCALE: lambda lo, hi, rate: {"fraction": LOE_FRACTION},
    Effect.LIMITS: _quarter_range,
    Effect.RATE_LIMITS: lambda lo, hi, rate: {"rate_min": -float(RATE_FRACTION * rate),
                                              "rate_max": float(RATE_FRACTION * rate)},
}


def catalogue_kinds() -> tuple[str, ...]:
    """The catalogue's kinds: the table's, in its order, without ``repair`` and the riders."""
    return tuple(k.value for k in FailureKind if Effect.REPAIR not in k.spec.effects and k not in RIDES_WITH)


def __getattr__(name: str) -> Any:
    if name == "KINDS":  # read from the table when asked: a kind registered after import counts
        return catalogue_kinds()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def catalogue_names() -> list[str]:
    """``jam1, jam2, hardover1, ...`` in report order."""
    return [f"{k}{n}" for k in catalogue_kinds() for n in (1, 2)]


def _parse(name: str | None) -> tuple[str, int] | None:
    """``(kind, n)`` of a catalogue name (legacy kind names read as today's), else None."""
    m = _NAME.match(name or "")
    if not m:
        return None
    kind = _LEGACY_KINDS.get(m["kind"], m["kind"])
    return (kind, int(m["n"])) if kind in catalogue_kinds() else None


def canonical_name(name: str) -> str:
    """Today's name of a catalogue failure (``loe1`` -> ``effectiveness1``); others unchanged."""
    parsed = _parse(name)
    return f"{parsed[0]}{parsed[1]}" if parsed else name


def is_catalogue(name: str | None) -> bool:
    """Whether ``name`` is a catalogue failure (not one the scenario defines)."""
    return _parse(name) is not None


def _vehicle(scenario: str) -> Any:
    module = importlib.import_module(f"sim.scenarios.{scenario}")
    return module.vehicle()


def _effector_failures(kind: str, i: int, lo: float, hi: float, rate: float) -> list[Any]:
    """The actuator failures of ``kind`` (and the kinds riding with it) on effector ``i``."""
    from sim.blocks import ActuatorFailure

    out = []
    for k in (kind, *(rider for rider, host in RIDES_WITH.items() if host == kind and rider in FailureKind)):
        params: dict[str, float] = {}
        for effect in FailureKind(k).spec.effects:
            params.update(SEVERITY[effect](lo, hi, rate))
        out.append(ActuatorFailure(i, k, **params))
    return out


def make_failure(scenario: str, name: str, time: float) -> Any:
    """The :class:`sim.loop.Failure` named ``name`` (``<kind><1|2>``) for ``scenario`` at ``time``."""
    from sim.loop import Failure

    parsed = _parse(name)
    if parsed is None:
        raise ValueError(f"failure: {name!r} is not a catalogue failure; expected <kind><1|2> with kind in "
                         f"{catalogue_kinds()}")
    if scenario not in FAILED_EFFECTORS:
        raise ValueError(f"failure: no catalogue effectors for scenario {scenario!r}; known: {sorted(FAILED_EFFECTORS)}")
    vehicle = _vehicle(scenario)
    kind, count = parsed
    failed = FAILED_EFFECTORS[scenario][:count]
    failures = [f for i in failed
                for f in _effector_failures(kind, i, vehicle.umin[i], vehicle.umax[i], vehicle.rate_max[i])]
    names = ", ".join(vehicle.effector_names[i] for i in failed)
    return Failure(name=name, time=float(time), description=f"{kind} of {names} at t = {time:g} s",
                   actuators=tuple(failures))


def failure_effectors(scenario: str, name: str) -> np.ndarray:
    """Indices of the effectors a catalogue failure affects (for the report's captions)."""
    parsed = _parse(name)
    return np.array(FAILED_EFFECTORS[scenario][: parsed[1]]) if parsed else np.array([], dtype=int)


# Every effect a told kind can have sets its parameters here: a new effect without a severity
# fails at import, not in the middle of a sweep.
if missing := set(Effect) - set(SEVERITY) - {Effect.REPAIR, Effect.BANDWIDTH, Effect.DELAY}:
    raise ImportError(f"benchmarks.compare.failures: no catalogue severity for {sorted(e.name for e in missing)}")


def _criteria_source(scenario: str, name: str, time: float | None) -> Any:
    """A catalogue failure by name, for the criteria's saturation shares (None: not a catalogue one)."""
    return make_failure(scenario, name, time or 0.0) if is_catalogue(name) and scenario in FAILED_EFFECTORS else None


# The criteria leave a failure's out-of-command effectors out of the saturation shares; sim never
# imports the benchmarks, so the catalogue tells it its failures.
_criteria.register_failure_source(_criteria_source)
