"""Failure injection: a :class:`sim.model.Failure` applied to the plant, the actuators and the delay.

Called by :func:`sim.engine.simulate` at the failure step, between two compiled steps; it
writes the changed arrays through the packed buffer's views (:class:`sim.packed.Packed`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.blocks import ActuatorBank, DelayLine, ScheduledPlant
from sim.model import Failure
from sim.packed import FloatSlot, IntSlot, Packed

__all__ = ["inject_failure"]


def inject_failure(
    failure: Failure, plant: ScheduledPlant, bank: ActuatorBank, delay: DelayLine, packed: Packed,
    u_last: np.ndarray,
) -> Failure:
    """Apply a failure to the plant, the actuators and the actuator delay (``u_last``: last command pushed).

    The bank executes each actuator failure's effects (its kind's row of :data:`alloc.health.FAILURE_KINDS`);
    returned is the failure as injected, every default filled in (a jam without a position holds
    the one it has now), which is what a told allocator is told.
    """
    actuators = tuple(bank.apply_failure(f) for f in failure.actuators)  # a jam writes pos/rate into the packed buffer
    plant.fail(effectiveness=bank.effectiveness)
    packed.view(FloatSlot.AD)[:] = plant.Ad
    packed.view(FloatSlot.BD)[:] = plant.Bd
    packed.view(FloatSlot.D)[:] = plant.D
    for slot, a in ((FloatSlot.WN2, bank.wn2), (FloatSlot.C1, bank.c1), (FloatSlot.LO, bank.lo), (FloatSlot.HI, bank.hi),
                    (FloatSlot.RMAX, bank.rmax), (FloatSlot.JAM_POS, bank.jam_pos), (FloatSlot.HARD_POS, bank.hard_pos),
                    (IntSlot.FIRST, bank.first), (IntSlot.JAMMED, bank.jammed), (IntSlot.HARDOVER, bank.hardover)):
        packed.view(slot)[:] = a
    if failure.delay is not None:
        # DelayLine.set_delay: the ring restarts, pre-filled with the last command pushed.
        delay.set_delay(failure.delay)
        length = int(delay.n.max()) + 1
        packed.view(IntSlot.DN)[:] = delay.n
        packed.view(IntSlot.DSTATE)[:] = 0, length
        packed.view(FloatSlot.DBUF)[:length] = u_last
    return replace(failure, actuators=actuators)
