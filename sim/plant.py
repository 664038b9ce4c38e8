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

__all__ = ["Plant"]


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
