"""A failure by name for a simulated vehicle: its scenario's own, the catalogue's, or the library's grammar.

A scenario's ``--failure NAME`` is one of three things, tried in this order:

1. a failure the scenario defines (the seed's composite failures: ICE ``seed``, HARV
   ``failure1``; plant matrices and delays included);
2. a *catalogue* name ``<kind><1|2>`` (``jam1``, ``effectiveness2``): one or two effector
   failures of one kind, effector-only, on the effectors the scenario names for it
   (``catalogue_effectors``: the first for ``1``, both for ``2``).  Each name stands for a
   text of the grammar (:func:`catalogue`), so ``jam1`` on ICE *is* ``jam:elevon_l@15``;
3. any text of the library's grammar (:data:`alloc.failure_grammar.GRAMMAR`) naming the
   vehicle's effectors: ``jam:elevon_l@5+float:lef_l``.

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

The catalogue's ``limits`` also reduces the rate limits (the seed's failure list has "reduced
position and rate limits", section 4.7): ``rate_limits`` rides with ``limits``
(:data:`RIDES_WITH`) and has no catalogue name of its own.  The comparison sweep
(``benchmarks/compare``) flies this catalogue; ``alloc sim ice --failure jam1`` flies the same.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence

from alloc.exceptions import ProblemError
from alloc.failure_grammar import EffectorFailure, format_failure, parse_failure
from alloc.health import Effect, FailureKind
from sim.blocks import ActuatorFailure
from sim.model import Failure, PlantModel

__all__ = [
    "LIMIT_FRACTION",
    "LOE_FRACTION",
    "RATE_FRACTION",
    "RIDES_WITH",
    "SEVERITY",
    "catalogue",
    "catalogue_kind",
    "catalogue_kinds",
    "catalogue_names",
    "check",
    "failure_help",
    "failure_of_text",
    "resolve",
]

LOE_FRACTION = 0.25
LIMIT_FRACTION = 0.25
RATE_FRACTION = 0.2

#: kind -> the kind whose catalogue failure it joins (and so has no catalogue name of its own)
RIDES_WITH = {"rate_limits": "limits"}

_NAME = re.compile(r"^(?P<kind>[a-z_]+?)(?P<n>[12])$")


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

# Every effect a told kind can have sets its parameters here: a new effect without a severity
# fails at import, not in the middle of a sweep.
if missing := set(Effect) - set(SEVERITY) - {Effect.REPAIR, Effect.BANDWIDTH, Effect.DELAY}:
    raise ImportError(f"sim.failure_catalogue: no catalogue severity for {sorted(e.name for e in missing)}")


def catalogue_kinds() -> tuple[str, ...]:
    """The catalogue's kinds: the table's, in its order, without ``repair`` and the riders."""
    return tuple(k.value for k in FailureKind if Effect.REPAIR not in k.spec.effects and k not in RIDES_WITH)


def catalogue_names() -> list[str]:
    """``jam1, jam2, hardover1, ...`` in report order."""
    return [f"{k}{n}" for k in catalogue_kinds() for n in (1, 2)]


def catalogue_kind(name: object) -> tuple[str, int] | None:
    """``(kind, n)`` of a catalogue name, else None."""
    m = _NAME.match(name) if isinstance(name, str) else None
    return (m["kind"], int(m["n"])) if m and m["kind"] in catalogue_kinds() else None


def _effector_failures(kind: str, effector: str, lo: float, hi: float, rate: float) -> list[EffectorFailure]:
    """The failures of ``kind`` (and the kinds riding with it) on one effector, at the catalogue's severity."""
    out = []
    for k in (kind, *(rider for rider, host in RIDES_WITH.items() if host == kind and rider in FailureKind)):
        spec = FailureKind(k).spec
        params: dict[str, float] = {}
        for effect in spec.effects:
            params.update(SEVERITY[effect](lo, hi, rate))
        out.append(EffectorFailure(k, effector, {p: params[p] for p in spec.params if p in params}))
    return out


def catalogue(vehicle: PlantModel, effectors: Sequence[str]) -> dict[str, str]:
    """Catalogue name -> its grammar text on ``vehicle``, failing ``effectors`` (by name; first, then both).

    Empty when the scenario names no catalogue effectors.  ProblemError (field ``failure``)
    for a name that is not one of the vehicle's effectors.
    """
    names = vehicle.effector_names
    unknown = [e for e in effectors if e not in names]
    if unknown:
        raise ProblemError(f"failure: catalogue effectors {unknown} are not effectors of {vehicle.name}: "
                           f"{', '.join(names)}", field="failure")
    lo, hi, rate = vehicle.umin, vehicle.umax, vehicle.rate_max
    out = {}
    for kind in catalogue_kinds():
        for n in (1, 2):
            if len(effectors) < n:
                continue
            parts = [f for e in effectors[:n] for f in _effector_failures(
                kind, e, float(lo[names.index(e)]), float(hi[names.index(e)]), float(rate[names.index(e)]))]
            out[f"{kind}{n}"] = format_failure(parts)
    return out


def failure_of_text(vehicle: PlantModel, text: str, time: float, *, name: str | None = None,
                    description: str | None = None) -> Failure:
    """The :class:`sim.model.Failure` a grammar text names on ``vehicle`` at ``time`` (effector failures only).

    Positions are checked against each actuator's limits, reduced rate limits against its rate.
    """
    names = vehicle.effector_names
    parts = parse_failure(text, names, limits=list(zip(vehicle.umin, vehicle.umax, strict=True)),
                          rate_limits=[(-r, r) for r in vehicle.rate_max])
    actuators = []
    for part in parts:
        try:
            actuators.append(ActuatorFailure(names.index(part.effector), part.kind, **part.params))
        except ProblemError as exc:
            raise ProblemError(f"failure: {part.text()!r}: {exc}", field="failure") from None
    return Failure(name=name or text, time=float(time), description=description or f"{text} at t = {time:g} s",
                   actuators=tuple(actuators))


def failure_help(named: Mapping[str, str], catalogued: Mapping[str, str], effectors: Sequence[str] | None) -> str:
    """What ``--failure`` takes for one scenario, for its messages: names, catalogue names, the grammar."""
    words = [f"its failures: {', '.join(named) or '(none)'}"]
    if catalogued:
        words.append(f"catalogue: {', '.join(catalogued)}")
    if effectors is not None:
        words.append(f"or text <kind>:<effector>[@<value>...] with effectors {', '.join(effectors)}")
    return "; ".join(words)


def resolve(text: str, time: float | None, *, named: Callable[[str, float | None], Failure],
            own: Mapping[str, str], vehicle: PlantModel, catalogued: Mapping[str, str],
            default_time: float) -> Failure:
    """A failure by name: the scenario's own (``named``), a catalogue name, or grammar text (module docstring)."""
    if text in own:
        return named(text, time)
    at = default_time if time is None else time
    if text in catalogued:
        kind = text[:-1]
        failed = ", ".join(dict.fromkeys(f.effector for f in parse_failure(catalogued[text])))
        return failure_of_text(vehicle, catalogued[text], at, name=text,
                               description=f"{kind} of {failed} at t = {at:g} s")
    if catalogue_kind(text) is not None:
        raise ProblemError(f"failure: {text!r}: {vehicle.name} names no catalogue effectors; "
                           f"{failure_help(own, catalogued, vehicle.effector_names)}", field="failure")
    return failure_of_text(vehicle, text, at)


def check(text: object, *, own: Mapping[str, str], vehicle: PlantModel, catalogued: Mapping[str, str]) -> None:
    """ProblemError (field ``failure``) unless ``text`` names a failure :func:`resolve` can build; says what is taken."""
    if isinstance(text, str) and (text in own or text in catalogued):
        return
    if catalogue_kind(text) is not None:
        raise ProblemError(f"failure: {text!r}: {vehicle.name} names no catalogue effectors; "
                           f"{failure_help(own, catalogued, vehicle.effector_names)}", field="failure")
    try:
        failure_of_text(vehicle, text, 0.0)  # type: ignore[arg-type]
    except ProblemError as exc:
        raise ProblemError(f"{exc}; {failure_help(own, catalogued, vehicle.effector_names)}",
                           field="failure") from None
