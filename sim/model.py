"""The closed loop's data: the plant model, its failure, the controller designs and the pilot.

Frozen dataclasses and nothing else: the scenarios (:mod:`sim.scenarios`) build them, the
engine (:mod:`sim.engine`) flies them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.blocks import ActuatorFailure, ActuatorSpec, HedgeTerm

__all__ = ["TF", "FlightCondition", "PlantModel", "Failure", "SMCDesign", "LoopShapedDesign", "Pilot"]

def __getattr__(name: str) -> Any:
    if name == "Vehicle":  # the old name; a vehicle is alloc.vehicle_file.Vehicle
        import warnings

        warnings.warn("sim.model.Vehicle is renamed sim.model.PlantModel", DeprecationWarning, stacklevel=2)
        return PlantModel
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: A transfer function ``(numerator, denominator)``, coefficients in descending powers of ``s``.
TF = tuple[Sequence[float], Sequence[float]]


@dataclass(frozen=True)
class FlightCondition:
    """Where a vehicle flies and which of its states the air moves (``--turbulence``, :mod:`sim.world`).

    Attributes
    ----------
    altitude : float
        ft above ground (MIL-F-8785C's turbulence intensities and scale lengths depend on it).
    speed : float
        ft/s, the true airspeed that carries the frozen turbulence field past the vehicle
        (Taylor's hypothesis, MIL-F-8785C 3.7.1); for a hovering vehicle the mean wind's.
    span : float
        ft, the wing span ``b`` of the rotational gust filters (MIL-F-8785C 3.7.1).
    gust_states : tuple of (state index, component, scale)
        The air-relative states: component one of ``u v w p q r`` (gust velocities in ft/s,
        gust rates in rad/s), ``scale`` the state's units per gust unit (``180 / pi / V`` for an
        angle in deg driven by a velocity, ``180 / pi`` for a rate in deg/s).
    aero : ndarray (nx, nx) of bool or None
        The entries of ``A`` that are aerodynamic (they see the air-relative state); None: every
        entry of a translational column, and the rows of the rate states in a rotational column.
    hover : tuple of (state row, component, gain)
        Direct disturbance ``x'[row] += gain * scale * gust`` for a model with no aerodynamic
        damping to carry the gust (a hovering multirotor's linear model, :mod:`sim.world`).
    source : str
        Where the numbers come from.
    """

    altitude: float
    speed: float
    span: float
    gust_states: tuple[tuple[int, str, float], ...]
    source: str
    aero: np.ndarray | None = None
    hover: tuple[tuple[int, str, float], ...] = ()


@dataclass(frozen=True)
class PlantModel:
    """A linear plant as the loop flies it: the model, its actuators and sensors, its allocation data.

    What :class:`sim.plant.LinearPlant` and the compiled engine integrate (``x' = A x + B u``,
    ``y = C x + D u``, deviations from trim), not a vehicle: a vehicle is a vehicle file
    (:class:`alloc.vehicle_file.Vehicle`), whose ``[model]`` and ``[simulation]`` sections a
    scenario turns into one of these (:func:`sim.file_scenario.file_scenario`).

    ``controlled`` are the output indices of the controlled variables (the
    channels, in the order of the pseudo-commands); ``measured`` the output
    indices fed to the observers.  ``B_alloc`` (k x m) is the effectiveness
    the allocator is given, ``demand_map`` (k x k) turns the SMC's pseudo-
    commands into allocator demands ``v``, ``Bk_seed`` is the seed's printed
    control distribution (for comparison and the ``static`` method).
    """

    name: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    output_names: tuple[str, ...]
    actuators: tuple[ActuatorSpec, ...]
    controlled: tuple[int, ...]
    measured: tuple[int, ...]
    noise_gains: np.ndarray
    B_alloc: np.ndarray
    Bk_seed: np.ndarray
    demand_map: np.ndarray
    Wu: np.ndarray | None = None
    #: effector names as the library names them (``alloc.vehicles``); default the actuator names
    names: tuple[str, ...] | None = None
    #: flight condition and air-relative states (None: ``--turbulence`` is refused for this vehicle)
    flight: FlightCondition | None = None

    @property
    def channels(self) -> list[str]:
        return [self.output_names[i] for i in self.controlled]

    @property
    def effector_names(self) -> list[str]:
        return list(self.names) if self.names is not None else [a.name for a in self.actuators]

    @property
    def umin(self) -> np.ndarray:
        return np.array([a.lo for a in self.actuators])

    @property
    def umax(self) -> np.ndarray:
        return np.array([a.hi for a in self.actuators])

    @property
    def rate_max(self) -> np.ndarray:
        return np.array([a.rate for a in self.actuators])


@dataclass(frozen=True)
class Failure:
    """Failure injected at ``time``: plant (A, B) change, actuator failures, added delay."""

    name: str
    time: float
    description: str
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    D: np.ndarray | None = None
    actuators: tuple[ActuatorFailure, ...] = ()
    #: actuator time delay after the failure (s): scalar or one per effector
    delay: float | np.ndarray | None = None


@dataclass(frozen=True)
class SMCDesign:
    """Observer-based SMC with simplified hedging, one channel per controlled variable.

    ``observer_poles[i]`` are the poles of channel ``i``'s full-order
    observer (seed section 3.3.2: one observer per channel), ``None`` to feed
    back the measured output instead (no observer, seed Fig 4-95).
    """

    rho: np.ndarray
    eps: np.ndarray | None
    K0: np.ndarray
    Km1: np.ndarray
    observer_poles: tuple[tuple[float, ...], ...] | None = None
    hedge_terms: tuple[HedgeTerm, ...] = ()
    hedge_gain: np.ndarray | None = None


@dataclass(frozen=True)
class LoopShapedDesign:
    """Diagonal linear compensators ``u_c[i] = G_i(s) (r[i] - y_meas[i])`` (seed Eq 4.28)."""

    compensators: tuple[TF, ...]


@dataclass(frozen=True)
class Pilot:
    """Compensatory pilot on one channel (the seed's pilot models, Figs 4-6, 4-41, 4-86, are images).

    McRuer's precision model of the human operator::

        command[channel] = gain (lead s + 1) / ((lag s + 1)(neuromuscular s + 1)) e^{-delay s} error
        error = att_cmd - att,  att = row @ y_measured  (integrated if ``integrate``)

    With ``lead = lag = neuromuscular = 0`` this is the project's original
    stand-in, ``gain (att_cmd - att)`` delayed (gain 2, 0.2 s by default).
    :mod:`sim.pilot` sets the parameters by the crossover-model rule.  The
    pilot is sampled by the flight-control computer once per frame.
    """

    channel: int
    row: np.ndarray
    attitude_command: Callable[[np.ndarray], np.ndarray]
    name: str
    gain: float = 2.0
    delay: float = 0.2
    integrate: bool = False
    lead: float = 0.0
    lag: float = 0.0
    neuromuscular: float = 0.0
    #: label of the rule that set the parameters ("standin", "crossover", ...)
    model: str = "standin"

    @property
    def filtered(self) -> bool:
        """True when the pilot has lead, lag or neuromuscular dynamics (not a pure gain)."""
        return bool(self.lead or self.lag or self.neuromuscular)

    def transfer_function(self) -> TF:
        """``(lead s + 1) / ((lag s + 1)(neuromuscular s + 1))`` (gain and delay excluded)."""
        return [self.lead, 1.0] if self.lead else [1.0], np.polymul([self.lag, 1.0], [self.neuromuscular, 1.0])

    def describe(self) -> dict[str, Any]:
        """Parameters as JSON-ready numbers."""
        return {"name": self.name, "model": self.model, "gain": float(self.gain), "delay": float(self.delay),
                "lead": float(self.lead), "lag": float(self.lag), "neuromuscular": float(self.neuromuscular)}
