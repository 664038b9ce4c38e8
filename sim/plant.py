"""What a plant of the closed loop is: effector commands in, measured outputs out.

The loop's controller, allocator, detector and excitation see a plant only through
:class:`Plant`, so the same loop flies the project's linear models (``--plant linear``, the
default, integrated in the compiled engine :mod:`sim.engine`) and third-party nonlinear
simulators (``--plant rotorpy``, ``--plant jsbsim:AIRCRAFT``, the optional ``[plants]`` extra).

Conventions every plant keeps
-----------------------------
- Commands, positions and outputs are in the vehicle model's units and order, as *deviations
  from the trim* the vehicle file states (the linear model's variables); a nonlinear plant adds
  its trim inside and reports deviations back.  The allocator's ``B`` is then the model's, and
  the plant's true effectiveness is whatever its physics gives -- they differ as on an aircraft.
- ``step`` advances exactly ``dt`` seconds with the command held; the plant applies its own
  actuator dynamics, position and rate limits and injected failures to that command.
- A failure uses the library's failure kinds (:data:`alloc.health.FAILURE_KINDS` names them and their parameters):
  :meth:`Plant.fail` takes an effector index, a kind and its parameters, and the plant applies
  it from the next step on.
- Outputs are noise-free; measurement noise and turbulence belong to the world (:mod:`sim.world`)
  unless the plant models its own wind, which it then states in :attr:`Plant.source`.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Plant", "LinearPlant", "command_of"]


@runtime_checkable
class Plant(Protocol):
    """A plant of the closed loop (see the module's conventions)."""

    #: the ``--plant`` name that built it, e.g. ``"linear"``, ``"rotorpy"``, ``"jsbsim:f22"``
    name: str
    #: effector names in the vehicle file's order (the allocator's columns)
    effectors: tuple[str, ...]
    #: measured output names in the vehicle model's order (the controller's channels)
    outputs: tuple[str, ...]
    #: where the physics comes from (package and version, model file, trim), for results and docs
    source: str

    def reset(self, *, seed: int) -> np.ndarray:
        """Return to the trim; seed every draw the plant makes; return the outputs at ``t = 0``."""
        ...

    def step(self, u_cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` s holding the effector commands ``u_cmd``; return the outputs after it."""
        ...

    def positions(self) -> np.ndarray:
        """Effector positions now, after actuator dynamics, saturation and failures."""
        ...

    def state(self) -> dict[str, float]:
        """Named physical state with units in the names (``"altitude_m"``, ``"airspeed_mps"``)."""
        ...

    def fail(self, effector: int, kind: str, params: dict[str, float] | None = None) -> None:
        """Inject the failure ``kind`` on ``effector`` from the next step on."""
        ...

    def describe(self) -> dict[str, Any]:
        """JSON-ready description for ``result.settings["plant"]``: name, source, trim, step."""
        ...

    # Added for the plant loop (sim.plant_loop): what a told allocator is told, and what is recorded.
    def executed(self) -> list[Any]:
        """Every failure injected so far as the plant executed it, defaults filled in (a jam without a
        position holds the one it had), as :class:`sim.blocks.ActuatorFailure`: what a told allocator hears."""
        ...

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Effector position limits now (deviations from trim; failures change them)."""
        ...

    def sensed(self) -> np.ndarray:
        """``x' - A x``: the model's states' derivative as the plant's physics gives it now (gyros and
        accelerometers, noise-free), less the nominal model's free response ``A x``: the effectors' (and
        the world's) share, which the in-loop detector (``--health detected``) samples."""
        ...


class LinearPlant:
    """The project's linear model as a :class:`Plant`: ``x' = A x + B u_pos``, ``y = C x + D u_pos``.

    The reference implementation of the contract (the compiled engine, :mod:`sim.engine`, stays the
    fast path of ``--plant linear``).  Every integration step of ``dt_step`` does what the engine's
    compiled step does, in the same order: the state advances by the exact ZOH of the positions
    held over the step (:class:`sim.blocks.DiscreteLTI`), then the actuators take the command
    (:class:`sim.blocks.ActuatorBank`, Heun-stepped, position and rate limited; ``actuators=False``:
    position = command clipped to the limits).  A failure runs its kind's effects on the bank and
    scales the plant's ``B`` and ``D`` columns by the effectiveness left, as the engine's injection
    does (:func:`sim.injection.inject_failure`).

    Parameters
    ----------
    vehicle : sim.model.PlantModel
        The linear model, its actuators and names (deviations from trim).
    dt_step : float
        The plant's own integration step (s); :meth:`step` takes a whole number of them.
    actuators : bool
        Actuator dynamics on (the engine's ``--actuators``) or ideal.
    """

    def __init__(self, vehicle: Any, dt_step: float, *, actuators: bool = True) -> None:
        from sim.blocks import ActuatorBank, ScheduledPlant

        self.name = "linear"
        self.vehicle = vehicle
        self.effectors = tuple(vehicle.effector_names)
        self.outputs = tuple(vehicle.output_names)
        self.source = f"linear model of {vehicle.name} (sim.plant.LinearPlant, exact ZOH at {dt_step:g} s)"
        self.dt_step = float(dt_step)
        self.actuators = bool(actuators)
        self._make_plant = lambda: ScheduledPlant(vehicle.A, vehicle.B, vehicle.C, vehicle.D, self.dt_step)
        self._make_bank = lambda: ActuatorBank(vehicle.actuators, self.dt_step)
        self.reset(seed=0)

    def reset(self, *, seed: int) -> np.ndarray:
        """Back to the trim (``x = 0``, positions 0); the linear plant draws nothing, ``seed`` is unused."""
        self._plant = self._make_plant()
        self._bank = self._make_bank()
        self._failures: list[dict[str, Any]] = []
        return self._outputs()

    def _outputs(self) -> np.ndarray:
        p = self._plant
        return p.C @ p.x + p.D @ self._bank.pos

    def step(self, u_cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` (a whole number of ``dt_step``) holding ``u_cmd``; the outputs after it."""
        u = command_of(u_cmd, len(self.effectors))
        n = _whole_steps(dt, self.dt_step)
        p, bank = self._plant, self._bank
        for _ in range(n):
            cur = p._cur
            p.x = cur.Ad @ p.x + cur.Bd @ bank.pos
            if self.actuators:
                bank.step(u)
            else:
                bank.pos = np.clip(np.where(bank.jammed, bank.jam_pos, u), bank.lo, bank.hi)
        return self._outputs()

    def positions(self) -> np.ndarray:
        return self._bank.pos.copy()

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self._bank.lo.copy(), self._bank.hi.copy()

    def sensed(self) -> np.ndarray:
        """``(A_now - A) x + B_now u_pos`` (the engine's expression; ``A_now``, ``B_now``: the model as it is now)."""
        p = self._plant
        return (p._cur.A - self.vehicle.A) @ p.x + p._cur.B @ self._bank.pos

    def state(self) -> dict[str, float]:
        return {f"{name}": float(x) for name, x in zip(self.outputs, self._outputs(), strict=True)}

    def fail(self, effector: int, kind: str, params: dict[str, float] | None = None) -> None:
        """Run ``kind``'s effects on the actuator (:meth:`sim.blocks.ActuatorBank.apply_failure`) and
        scale the plant's columns by the effectiveness left; the failure as executed is recorded."""
        from sim.blocks import ActuatorFailure

        executed = self._bank.apply_failure(ActuatorFailure(int(effector), kind, **(params or {})))
        self._plant.fail(effectiveness=self._bank.effectiveness)
        self._failures.append({"effector": self.effectors[executed.index], "kind": executed.kind,
                               "params": dict(executed.params)})

    def executed(self) -> list[Any]:
        """The failures as executed (defaults filled in), as :class:`sim.blocks.ActuatorFailure`."""
        from sim.blocks import ActuatorFailure

        return [ActuatorFailure(self.effectors.index(f["effector"]), f["kind"], **f["params"]) for f in self._failures]

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "source": self.source, "step": self.dt_step, "actuators": self.actuators,
                "trim": "the model's operating point (deviations are zero there)", "failures": list(self._failures)}


def command_of(u_cmd: Any, m: int) -> np.ndarray:
    """``u_cmd`` as m finite floats (ProblemError naming ``u_cmd`` otherwise): a plant's input boundary."""
    from alloc.exceptions import ProblemError

    u = np.asarray(u_cmd, dtype=float)
    if u.shape != (m,) or not np.all(np.isfinite(u)):
        raise ProblemError(f"u_cmd: expected {m} finite effector commands, got shape {u.shape}"
                           f"{'' if u.shape != (m,) else ' with a non-finite entry'}", field="u_cmd")
    return u


def _whole_steps(dt: float, dt_step: float) -> int:
    """``dt / dt_step`` as a whole number >= 1 (AllocError naming ``dt`` otherwise)."""
    from alloc.exceptions import ProblemError

    ratio = float(dt) / dt_step
    n = int(round(ratio))
    if not np.isfinite(ratio) or n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
        raise ProblemError(f"dt: {dt!r} s is not a positive multiple of the plant's step {dt_step!r} s", field="dt")
    return n
