"""F-18/HARV lateral-directional MIMO model, five effectors (seed section 4.6).

Low-speed, high angle-of-attack condition, Eq 4.16; failed plant Eq 4.17
(``A_fail = 2 A, B_fail = 0.75 B``); Table 4-3 actuators; roll reference model
Eq 4.18; ganging Eq 4.19; manifolds Eq 4.20-4.21 (``p: K_rho = 500, K0 = 1,
K_-1 = 50``; ``beta: 3000, 1, 5``; ``eps = 1``); observers and hedges as
tabulated in section 4.6 (poles -10, -11, -12 per channel; hedge gains
``p_s 1.0, beta 2.0``).  Channels in Eq 4.19 column order: ``beta``, ``ps``.
All of it is alloc/data/vehicles/harv.toml's; this module names it for the simulator and
adds the Failure #2 scenario (where it flies: :mod:`sim.seed_flight`).

Derived (ours, from the model): the states are body axes -- the
``beta``-dot row of Eq 4.16 holds ``sin(alpha0) = 0.4959`` and ``-cos(alpha0) =
-0.8703`` -- so ``alpha0 = 29.7 deg`` and ``ps = cos(alpha0) p + sin(alpha0) r``;
bank angle ``phi = int(p + tan(alpha0) r)`` (level flight, theta0 = alpha0).

Substitutions (ours): the beta reference model is not printed (beta_c = 0),
the roll model is reused; the pilot (Fig 4-41, an image) is a crossover-model
pilot ``p_c = 2 (phi_c - phi)`` delayed 0.2 s (or the crossover pilot, :mod:`sim.pilot`).
Failure #2 with filtered bank-angle steps (the form of Fig 4-81) is the scenario
``harv_latdir_failure2``; its step times and sizes are ours (the figure is an image).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from alloc.vehicles import bundled

from sim.file_scenario import file_scenario, loop_of, filtered_steps as _filtered_steps
from sim.model import Failure, LoopShapedDesign, PlantModel, SMCDesign
from sim.scenarios.mimo import mimo_scenario, run_mimo
from sim.result import SimResult
from sim.scenarios.registry import register_scenario
from sim.seed_flight import HARV_LATDIR_ALTITUDE as ALTITUDE, HARV_LATDIR_SPEED as SPEED  # noqa: F401  # this scenario's names
from sim.seed_flight import harv_latdir as flight_condition  # noqa: F401

__all__ = ["A", "B", "SEED_BK", "vehicle", "allocation_problem", "failure", "run"]

#: The seed's HARV lat-dir as data: alloc/data/vehicles/harv.toml carries the model (Eq 4.16),
#: the actuators (Table 4-3), the ganging (Eq 4.19), the controller (Eq 4.18, 4.20-4.21, the
#: section 4.6 tables), the failures (Eq 4.17, section 4.6) and the Failure #2 input.
_FILE = bundled("harv")
_LOOP = file_scenario(_FILE)
_MODEL, _SIM = loop_of(_FILE)

#: the seed's effector labels, in the file's order (diff_tail is DT, ...)
EFFECTORS = ("dt", "ai", "ru", "rtv", "ytv")
A, B, C, _D = _MODEL.arrays()  # seed Eq 4.16, states beta, p, r
ALPHA0 = float(np.arctan2(A[0, 1], -A[0, 2]))  # body-axis beta-dot row: sin(alpha0), -cos(alpha0)
OUTPUTS = tuple(_MODEL.outputs)  # beta, p, r and ps = cos(alpha0) p + sin(alpha0) r
SEED_BK = np.array(_SIM.allocation.static, dtype=float)  # seed Eq 4.19 (beta, p)
REFERENCES = _LOOP.references  # seed Eq 4.18, the roll model, reused for beta
ROLL_MODEL = REFERENCES[1]
OUTPUT_BOUND = _LOOP.output_bound  # |beta| deg, |ps| deg/s


def vehicle() -> PlantModel:
    """Nominal HARV lat-dir model (harv.toml); allocation rows: beta-dot and ps-dot effectiveness."""
    return dataclasses.replace(_LOOP.vehicle(), name="harv_latdir")


def allocation_problem() -> Any:
    from sim.allocation import allocation_problem as _problem

    return _problem(vehicle())


FAILURES = {name: spec.description for name, spec in _SIM.failures.items()}


def failure(name: str, time: float | None = None) -> Failure:
    """The seed's failures of section 4.6 (harv.toml ``failures``): ``plant`` (Eq 4.17), ``failure1``, ``failure2``."""
    if name not in FAILURES:
        raise KeyError(f"unknown HARV lat-dir failure {name!r}; known: {sorted(FAILURES)}")
    return _LOOP.failure(name, time)


def smc_design(*, observer: bool = True, hedge: bool = True, cross_hedge: bool = True) -> SMCDesign:
    """Channels (beta, ps): seed Eq 4.21 gains, section 4.6 observer/hedge table (harv.toml)."""
    return _LOOP.smc_design(observer=observer, hedge=hedge, cross_hedge=cross_hedge)


def loop_shaped_design() -> LoopShapedDesign:
    """seed section 4.6: G_beta = 63 (s^2+0.9s+0.2)/(s^2+20s), G_ps = 5 (s^2+3s+2.25)/(s^2+0.5s) (harv.toml)."""
    return _LOOP.loop_shaped_design()


#: seed section 4.6, Failure #2 input: "a series of steps filtered by
#: (100/(s^2+20s+100)) (1/(s^2+2s+1))".  Step times and sizes are in Fig 4-81 (an image):
#: ours, bank-angle steps (deg) of a roll-reversal sequence.
_STEPS = dict(_SIM.pilot.commands)["filtered_steps"]  # type: ignore[union-attr]  # harv.toml has a pilot
STEP_TIMES, STEP_LEVELS, STEP_FILTER = _STEPS.times, _STEPS.levels, _STEPS.filter.pair()


def filtered_steps(t: np.ndarray) -> np.ndarray:
    """The Failure #2 bank-angle command: :data:`STEP_LEVELS` at :data:`STEP_TIMES`, through :data:`STEP_FILTER`."""
    return _filtered_steps(t, STEP_TIMES, STEP_LEVELS, STEP_FILTER)


# What the roll pilot flies, stick to bank angle: the ps reference model, then
# phi = int(p + tan(alpha0) r) = int(ps) / cos(alpha0) for a velocity-vector roll (beta = 0).
PILOT_ELEMENT = _LOOP.pilot_element


# the file's loop; the roll pilot's phi_command is "sines" (xi = 6) or "filtered_steps" (Failure #2)
SCENARIO = dataclasses.replace(
    _LOOP, vehicle=vehicle, failure=failure, smc_design=smc_design, catalogue_vehicle="harv",
    catalogue_effectors=("aileron", "rudder"), failure_time=25.0,
)


@mimo_scenario(SCENARIO,
               description="F-18/HARV lat-dir MIMO SMC, ps and beta tracking, five effectors (seed 4.6)")
def run(**options: Any) -> SimResult:
    """Run the HARV lat-dir scenario: :func:`sim.scenarios.mimo.run_mimo` options, plus ``observer``,
    ``hedge``, ``cross_hedge`` and ``phi_command`` (``"sines"``, the seed's xi = 6 sum of sines, or
    ``"filtered_steps"``, the Failure #2 input)."""
    return run_mimo(SCENARIO, **options)


@register_scenario(
    "harv_latdir_failure2",
    description="F-18/HARV lat-dir, Failure #2 at t = 0 (yaw thrust vector 10 %, +-3 deg, 6 deg/s) with the "
    "filtered bank-angle steps of seed 4.6, Fig 4-81 (their times and sizes are ours)",
    failures={"failure2": FAILURES["failure2"]},
    default_duration=40.0,
    default_method="ganging",
    default_failure="failure2",
)
def run_failure2(*, failure: str | None = "failure2", duration: float | None = None, **options: Any) -> SimResult:
    """HARV lat-dir with Failure #2 and the filtered-step input (``failure=None``: nominal, same input).

    ``failure`` defaults to ``"failure2"``, declared as the scenario's ``default_failure`` so
    that callers who name no failure (``alloc sim harv_latdir_failure2``) get it too."""
    return run_mimo(SCENARIO, failure=failure, duration=40.0 if duration is None else duration,
                    phi_command="filtered_steps", **options)
