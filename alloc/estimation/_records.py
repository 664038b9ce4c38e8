"""Detections and withdrawals read back from a stored detector state (:meth:`FailureDetector.from_dict`):
every number finite, every field named in the error."""

from __future__ import annotations

from typing import Any

from ..health import FailureEvent, health_from_dict
from ..problem import as_real, short_repr
from ._checks import StateError, state_count
from .isolation import Detection, Withdrawal

_OPTIONAL_NUMBERS = ("parameter", "parameter_std", "end_position", "improvement")




def detection_from_dict(d: Any) -> Detection:
    if not isinstance(d, dict) or "event" not in d:
        raise StateError("detections: expected mappings with an event")
    try:
        ev = dict(d["event"])
        event = FailureEvent(ev.pop("effector"), ev.pop("kind"), **ev)
        rest = {k: v for k, v in d.items() if k != "event"}
        for name, value in rest.items():  # every number recorded is finite (an unknown name: Detection's TypeError)
            if name == "samples":
                rest[name] = state_count("detections", value)
            elif value is not None or name not in _OPTIONAL_NUMBERS:
                rest[name] = as_real("detections", value, StateError)
        return Detection(event=event, **rest)
    except (TypeError, ValueError, KeyError) as exc:
        raise StateError(f"detections: {exc}") from None


def withdrawal_from_dict(d: Any) -> Withdrawal:
    if not isinstance(d, dict) or set(d) != {f for f in Withdrawal.__dataclass_fields__}:
        raise StateError(f"withdrawals: expected mappings with {sorted(Withdrawal.__dataclass_fields__)}")
    if not (isinstance(d["effector"], str) and isinstance(d["kind"], str) and isinstance(d["reason"], str)):
        raise StateError("withdrawals: effector, kind and reason must be strings")
    return Withdrawal(effector=d["effector"], kind=d["kind"], time=as_real("withdrawals", d["time"], StateError),
                      detection_time=as_real("withdrawals", d["detection_time"], StateError),
                      statistic=None if d["statistic"] is None else as_real("withdrawals", d["statistic"], StateError),
                      reason=d["reason"][:200])


def active_from_dict(d: Any, det: Any) -> dict[str, dict[str, Any]]:
    """The standing detections' records (``active``), each on an effector the health lists."""
    if not isinstance(d, dict):
        raise StateError("active: expected a mapping of effector name to its standing detection")
    out = {}
    for name, a in d.items():
        if name not in det.problem.names or not isinstance(a, dict) or set(a) != {"before", "time", "kind"}:
            raise StateError(f"active: expected effector names of the problem with before, time, kind; got {short_repr(name)}")
        if not isinstance(a["kind"], str):
            raise StateError("active: kind must be a string")
        try:
            before = None if a["before"] is None else health_from_dict({name: a["before"]})[name]
        except (TypeError, ValueError) as exc:
            raise StateError(f"active: {exc}") from None
        out[name] = {"before": before, "time": as_real("active", a["time"], StateError), "kind": a["kind"]}
    return out
