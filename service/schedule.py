"""A stored vehicle's problem at the scheduling variables of a request (``"at"``).

A vehicle created from a document with a ``[schedule]`` (format ``alloc-vehicle/1.2``: a
tiltrotor's tilt, the airspeed PX4 scales its surfaces with) has ``B`` as a function of named
variables.  An allocation or batch with ``"at": {"tilt": 45, "airspeed": 12}`` is answered for
``B`` at those values, with the vehicle's current health applied on top, as ``alloc allocate
--vehicle FILE --at tilt=45 --at airspeed=12`` does: the names and checks are the library's
(:meth:`alloc.vehicle_file.schedule.ScheduledEffectiveness.values`: each finite, within its
declared range; a variable not given takes its ``nominal``).  A refusal is 422 naming
``at.<name>``; ``at`` on a vehicle without a schedule is 422 naming ``at``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

import alloc
from alloc.exceptions import ProblemError

from .errors import InvalidRequest
from .health import to_problem
from .vehicle_state import VehicleState

__all__ = ["at_values", "problem_at", "problem_at_values"]


def _at_error(name: str | None, reason: str) -> InvalidRequest:
    loc: list[str] = ["body", "at"] if name is None else ["body", "at", name]
    pointer = "/" + "/".join(p.replace("~", "~0").replace("/", "~1") for p in loc[1:])
    where = "at" if name is None else f"at.{name[:40]}"
    return InvalidRequest(f"{where}: {reason}", [{"loc": loc, "pointer": pointer, "reason": reason}])


def at_values(state: VehicleState, at: Mapping[str, float] | None) -> tuple[float, ...] | None:
    """Every scheduling variable's value, in declared order, for a request's ``at`` (those not
    given at their nominal values), checked by the library; ``None`` when ``at`` is absent or empty.

    Raises
    ------
    InvalidRequest
        naming ``at.<name>`` (unknown, out of its range) or ``at`` (the vehicle has no schedule).
    """
    if not at:
        return None
    if state.schedule is None:
        raise _at_error(None, f"vehicle {state.name or state.id!r} declares no [schedule]; its B is constant")
    declared = state.schedule.schedule.names
    unknown = next((name for name in at if name not in declared), None)
    if unknown is not None:
        raise _at_error(unknown, f"unknown scheduling variable; declared: {', '.join(declared)}")
    try:
        return tuple(state.schedule.values(at))
    except ProblemError as exc:
        name = exc.field if exc.field in declared else None
        raise _at_error(name, str(exc).removeprefix(f"{name}: ")) from None


def problem_at_values(state: VehicleState, values: tuple[float, ...] | None) -> alloc.Problem:
    """The effective problem of ``state`` with ``B`` at ``values`` (:func:`at_values`;
    ``state.problem`` for ``None``): the schedule evaluated into a new array (the evaluator is
    shared, no buffer is), then the vehicle's health applied as to its nominal problem."""
    if values is None or state.schedule is None:
        return state.problem
    B = state.schedule.evaluate(values, out=np.empty(state.schedule.shape))
    return to_problem(state.nominal.replace(B=B), state.health)


def problem_at(state: VehicleState, at: Mapping[str, float] | None) -> alloc.Problem:
    """:func:`problem_at_values` of :func:`at_values`: the problem at a request's ``at``."""
    return problem_at_values(state, at_values(state, at))
