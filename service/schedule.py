"""A stored vehicle's problem at the scheduling variables of a request (``"at"``).

A vehicle created from a document with a ``[schedule]`` (format ``alloc-vehicle/1.2``: a
tiltrotor's tilt, the airspeed PX4 scales its surfaces with) has ``B`` as a function of named
variables.  An allocation or batch with ``"at": {"tilt": 45, "airspeed": 12}`` is answered for
``B`` at those values, with the vehicle's current health applied on top, as ``alloc allocate
--vehicle FILE --at tilt=45 --at airspeed=12`` does: the names and checks are the library's
(:meth:`alloc.vehicle_file.schedule.ScheduledEffectiveness.values`: each finite, within its
declared range; a variable not given takes its ``nominal``).  A refusal is 422 naming
``at.<name>``; ``at`` on a vehicle without a schedule is 422 naming ``at``.

The evaluators are held apart from the vehicle states, in :class:`Schedules`, an LRU of
:data:`SCHEDULE_ENTRIES` vehicles filled on a vehicle's first allocation at ``at``: an evaluator
keeps its terms (at the caps, 32 terms of 6 x 64: about 225 KB measured with ``tracemalloc``),
which in each of the 1,024 states a process holds would triple their memory bound.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

import alloc
from alloc.exceptions import ProblemError
from alloc.vehicle_file.schedule import ScheduledEffectiveness

from .errors import InvalidRequest
from .health import to_problem
from .vehicle_state import VehicleState

__all__ = ["SCHEDULE_ENTRIES", "Schedules", "at_values", "problem_at_values"]

#: vehicles whose schedule evaluator a process keeps (about 225 KB each at the caps: ~14 MB)
SCHEDULE_ENTRIES = 64


def _at_error(name: str | None, reason: str) -> InvalidRequest:
    loc: list[str] = ["body", "at"] if name is None else ["body", "at", name]
    pointer = "/" + "/".join(p.replace("~", "~0").replace("/", "~1") for p in loc[1:])
    where = "at" if name is None else f"at.{name[:40]}"
    return InvalidRequest(f"{where}: {reason}", [{"loc": loc, "pointer": pointer, "reason": reason}])


class Schedules:
    """The schedule evaluators of the vehicles allocated at ``at`` in this process, an LRU of
    :data:`SCHEDULE_ENTRIES` (thread-safe), each made from the stored document (read with
    ``document``) on a miss.  A vehicle's document never changes, so an entry never goes stale."""

    def __init__(self, document: Callable[[str], dict[str, Any] | None], entries: int = SCHEDULE_ENTRIES) -> None:
        self._document, self._entries = document, entries
        self._items: OrderedDict[str, ScheduledEffectiveness] = OrderedDict()
        self._lock = threading.Lock()

    def of(self, state: VehicleState) -> ScheduledEffectiveness:
        """The evaluator of ``state``'s vehicle; 422 naming ``at`` when it declares no schedule."""
        if not state.scheduled:
            raise _at_error(None, f"vehicle {state.name or state.id!r} declares no [schedule]; its B is constant")
        with self._lock:
            found = self._items.get(state.id)
            if found is not None:
                self._items.move_to_end(state.id)
                return found
        from alloc.vehicle_file.vehicle import vehicle_from_dict

        document = self._document(state.id)
        evaluator = vehicle_from_dict(document or {}).scheduled()  # validated when the vehicle was created
        with self._lock:
            self._items[state.id] = evaluator
            while len(self._items) > self._entries:
                self._items.popitem(last=False)
        return evaluator

    def forget(self, vehicle_id: str) -> None:
        with self._lock:
            self._items.pop(vehicle_id, None)


def at_values(evaluator: ScheduledEffectiveness, at: Mapping[str, float]) -> tuple[float, ...]:
    """Every scheduling variable's value, in declared order, for a request's ``at`` (those not
    given at their nominal values), checked by the library.

    Raises
    ------
    InvalidRequest
        naming ``at.<name>``: an unknown variable, a value out of its range.
    """
    declared = tuple(v.name for v in evaluator.schedule.variables)
    unknown = next((name for name in at if name not in declared), None)
    if unknown is not None:
        raise _at_error(unknown, f"unknown scheduling variable; declared: {', '.join(declared)}")
    try:
        return tuple(evaluator.values(at))
    except ProblemError as exc:
        name = exc.field if exc.field in declared else None
        raise _at_error(name, str(exc).removeprefix(f"{name}: ")) from None


def problem_at_values(state: VehicleState, evaluator: ScheduledEffectiveness | None,
                      values: tuple[float, ...] | None) -> alloc.Problem:
    """The effective problem of ``state`` with ``B`` at ``values`` (:func:`at_values`;
    ``state.problem`` for ``None``): the schedule evaluated into a new array (the evaluator is
    shared, no buffer is), then the vehicle's health applied as to its nominal problem."""
    if values is None or evaluator is None:
        return state.problem
    B = evaluator.evaluate(values, out=np.empty(evaluator.shape))
    return to_problem(state.nominal.replace(B=B), state.health)
