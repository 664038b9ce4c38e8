"""F-18/HARV lateral-directional MIMO model, five effectors (seed section 4.6).

Low-speed, high angle-of-attack condition, Eq 4.16; failed plant Eq 4.17
(``A_fail = 2 A, B_fail = 0.75 B``); Table 4-3 actuators; roll reference model
Eq 4.18; ganging Eq 4.19; manifolds Eq 4.20-4.21 (``p: K_rho = 500, K0 = 1,
K_-1 = 50``; ``beta: 3000, 1, 5``; ``eps = 1``); observers and hedges as
tabulated in section 4.6 (poles -10, -11, -12 per channel; hedge gains
``p_s 1.0, beta 2.0``).  Channels in Eq 4.19 column order: ``beta``, ``ps``.

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

from typing import Any

import numpy as np

from alloc.vehicles import HARV_LATDIR_EFFECTORS

from sim.blocks import ActuatorFailure, ActuatorSpec, HedgeTerm, sum_of_sines
from sim.model import Failure, FlightCondition, LoopShapedDesign, Pilot, SMCDesign, Vehicle
from sim.scenarios.mimo import MimoScenario, mimo_scenario, run_mimo
from sim.result import SimResult
from sim.scenarios.registry import register_scenario

__all__ = ["A", "B", "SEED_BK", "vehicle", "allocation_problem", "failure", "run"]

EFFECTORS = ("dt", "ai", "ru", "rtv", "ytv")
A = np.array([  # seed Eq 4.16, states beta, p, r
    [-0.05904, 0.4959, -0.8703],
    [-5.513, -0.9391, 0.6655],
    [0.06838, 0.02632, -0.1038],
])
B = np.array([  # seed Eq 4.16
    [0.005629, 0.005764, 0.003685, 0.0, 0.0904],
    [1.879, 1.328, 0.02922, 0.6754, 0.217],
    [-0.1092, -0.09645, -0.08404, 0.006811, -2.974],
])
ALPHA0 = float(np.arctan2(A[0, 1], -A[0, 2]))  # body-axis beta-dot row: sin(alpha0), -cos(alpha0)
OUTPUTS = ("beta", "p", "r", "ps")
C = np.array([
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, np.cos(ALPHA0), np.sin(ALPHA0)],
])
SEED_BK = np.array([[0, 0.6], [0, 1], [1, 0], [0, 0.6], [0.6, 0]], dtype=float)  # seed Eq 4.19 (beta, p)
ROLL_MODEL = ([1000.0], np.polymul([1.0, 4.1], [1.0, 2 * 0.829 * 15.6, 15.6**2]))  # seed Eq 4.18
REFERENCES = (ROLL_MODEL, ROLL_MODEL)
OUTPUT_BOUND = np.array([30.0, 300.0])  # |beta| deg, |ps| deg/s


def _actuators() -> tuple[ActuatorSpec, ...]:
    """seed Table 4-3."""
    return (
        ActuatorSpec.second_order("dt", 30.0, 0.707, -17.5, 17.5, 60.0),
        ActuatorSpec.second_order("ai", 75.0, 0.6, -27.5, 27.5, 100.0),
        ActuatorSpec.second_order("ru", 72.0, 0.69, -30.0, 30.0, 100.0),
        ActuatorSpec.second_order("rtv", 20.0, 0.6, -30.0, 30.0, 60.0),
        ActuatorSpec.second_order("ytv", 20.0, 0.6, -30.0, 30.0, 60.0),
    )


#: ft, ft/s: the seed gives no altitude or speed for Eq 4.16 ("this low speed, high angle of attack,
#: flight condition", section 4.6, line 2912 of the OCR'd seed); ours: 25,000 ft and 250 ft/s
#: (about M 0.25), a HARV high-alpha test point's order of magnitude at alpha0 = 29.7 deg
ALTITUDE, SPEED = 25000.0, 250.0


def flight_condition() -> FlightCondition:
    """Where the HARV lat-dir model flies (ours, :data:`ALTITUDE`, :data:`SPEED`) and what the air moves:
    sideslip (deg) sees ``v_g / V``, the body rates (deg/s) ``p_g, r_g``; span 37.5 ft (the F/A-18's)."""
    deg = 180.0 / np.pi
    return FlightCondition(altitude=ALTITUDE, speed=SPEED, span=37.5,
                           gust_states=((0, "v", deg / SPEED), (1, "p", deg), (2, "r", deg)),
                           source="ours: the seed gives no altitude or speed for Eq 4.16")


def vehicle() -> Vehicle:
    """Nominal HARV lat-dir model; allocation rows: beta-dot and ps-dot effectiveness."""
    B_alloc = C[[0, 3]] @ B
    return Vehicle(
        name="harv_latdir", A=A, B=B, C=C, D=np.zeros((4, 5)), output_names=OUTPUTS,
        actuators=_actuators(), controlled=(0, 3), measured=(0, 1, 2),
        noise_gains=np.array([0.0707, 0.1414, 0.1414]),  # seed section 4.6
        B_alloc=B_alloc, Bk_seed=SEED_BK, demand_map=B_alloc @ SEED_BK, names=HARV_LATDIR_EFFECTORS,
        flight=flight_condition(),
    )


def allocation_problem() -> Any:
    from sim.allocation import allocation_problem as _problem

    return _problem(vehicle())


FAILURES = {
    "plant": "t = 25 s: failed plant, Eq 4.17 (2A, 0.75B)",
    "failure1": "t = 25 s: failed plant; roll and yaw thrust vectors +-15 deg, 30 deg/s, 50 ms delay (seed 4.6)",
    "failure2": "t = 0 s: nominal plant; yaw thrust vector effectiveness 0.1, +-3 deg, 6 deg/s (seed 4.6)",
}


def failure(name: str, time: float | None = None) -> Failure:
    if name == "plant":
        return Failure("plant", 25.0 if time is None else time, FAILURES[name], A=2.0 * A, B=0.75 * B)
    if name == "failure1":
        delay = np.array([0.0, 0.0, 0.0, 0.05, 0.05])
        return Failure(
            "failure1", 25.0 if time is None else time, FAILURES[name], A=2.0 * A, B=0.75 * B,
            actuators=(
                ActuatorFailure(3, "limits", lo=-15.0, hi=15.0),
                ActuatorFailure(3, "rate_limits", rate_min=-30.0, rate_max=30.0),
                ActuatorFailure(4, "limits", lo=-15.0, hi=15.0),
                ActuatorFailure(4, "rate_limits", rate_min=-30.0, rate_max=30.0),
            ),
            delay=delay,
        )
    if name == "failure2":
        return Failure(
            "failure2", 0.0 if time is None else time, FAILURES[name],
            actuators=(
                ActuatorFailure(4, "effectiveness", fraction=0.1),
                ActuatorFailure(4, "limits", lo=-3.0, hi=3.0),
                ActuatorFailure(4, "rate_limits", rate_min=-6.0, rate_max=6.0),
            ),
        )
    raise KeyError(f"unknown HARV lat-dir failure {name!r}; known: {sorted(FAILURES)}")


def smc_design(*, observer: bool = True, hedge: bool = True, cross_hedge: bool = True) -> SMCDesign:
    """Channels (beta, ps): seed Eq 4.21 gains, section 4.6 observer/hedge table."""
    terms = [
        HedgeTerm(1, 1, a_f=50.0, a_h=20.0, b_h=100.0),  # p_h/u_cp
        HedgeTerm(0, 0, a_f=20.0, a_h=2.0, b_h=1.0),  # beta_h/u_cbeta
    ]
    if cross_hedge:
        terms += [
            HedgeTerm(1, 0, a_f=50.0, a_h=2.0, b_h=1.0, gain=-20.0),  # p_h/u_cbeta
            HedgeTerm(0, 1, a_f=20.0, a_h=2.0, b_h=1.0, gain=0.8),  # beta_h/u_cp
        ]
    poles = ((-10.0, -11.0, -12.0), (-10.0, -11.0, -12.0))
    return SMCDesign(
        rho=np.array([3000.0, 500.0]), eps=np.ones(2), K0=np.ones(2), Km1=np.array([5.0, 50.0]),
        observer_poles=poles if observer else None, hedge_terms=tuple(terms) if hedge else (),
        hedge_gain=np.array([2.0, 1.0]),
    )


def loop_shaped_design() -> LoopShapedDesign:
    """seed section 4.6: G_beta = 63 (s^2+0.9s+0.2)/(s^2+20s), G_ps = 5 (s^2+3s+2.25)/(s^2+0.5s)."""
    return LoopShapedDesign(compensators=(
        (np.polymul([63.0], [1.0, 0.9, 0.2]), [1.0, 20.0, 0.0]),
        (np.polymul([5.0], [1.0, 3.0, 2.25]), [1.0, 0.5, 0.0]),
    ))


#: seed section 4.6, Failure #2 input: "a series of steps filtered by
#: (100/(s^2+20s+100)) (1/(s^2+2s+1))".  Step times and sizes are in Fig 4-81 (an image):
#: ours, bank-angle steps (deg) of a roll-reversal sequence.
STEP_TIMES = (1.0, 11.0, 21.0, 31.0)
STEP_LEVELS = (20.0, -20.0, 10.0, 0.0)
STEP_FILTER = ([100.0], np.polymul([1.0, 20.0, 100.0], [1.0, 2.0, 1.0]))


def filtered_steps(t: np.ndarray) -> np.ndarray:
    """The Failure #2 bank-angle command: :data:`STEP_LEVELS` at :data:`STEP_TIMES`, through :data:`STEP_FILTER`."""
    from scipy import signal

    t = np.asarray(t, dtype=float)
    steps = np.zeros_like(t)
    for when, level in zip(STEP_TIMES, STEP_LEVELS, strict=True):
        steps[t >= when] = level
    if t.size < 2:
        return np.zeros_like(t)
    _, y, _ = signal.lsim(signal.lti(*STEP_FILTER), steps, t)
    return np.asarray(y, dtype=float)


def _phi_command(kind: str):
    if kind == "sines":
        return lambda tt: sum_of_sines(tt, 6.0)  # seed section 4.6: xi = 6
    if kind == "filtered_steps":
        return filtered_steps
    raise ValueError(f"phi_command: {kind!r}; expected 'sines' or 'filtered_steps'")


# What the roll pilot flies, stick to bank angle: the ps reference model, then
# phi = int(p + tan(alpha0) r) = int(ps) / cos(alpha0) for a velocity-vector roll (beta = 0).
PILOT_ELEMENT = (list(np.array(ROLL_MODEL[0]) / np.cos(ALPHA0)), list(np.polymul(ROLL_MODEL[1], [1.0, 0.0])))


def _roll_pilot(params: dict[str, Any], phi_command: str = "sines") -> Pilot:
    return Pilot(
        channel=1, row=np.array([0.0, 1.0, np.tan(ALPHA0), 0.0]), integrate=True, name="phi", **params,
        attitude_command=_phi_command(phi_command),
    )


SCENARIO = MimoScenario(
    name="harv_latdir", vehicle=vehicle, references=REFERENCES, smc_design=smc_design,
    loop_shaped_design=loop_shaped_design, failure=failure, pilot=_roll_pilot, pilot_element=PILOT_ELEMENT,
    commands=lambda t: np.zeros((t.size, 2)), output_bound=OUTPUT_BOUND, default_duration=50.0,
    default_method="ganging", design_options=("observer", "hedge", "cross_hedge"), input_options=("phi_command",),
    catalogue_vehicle="harv", failures=FAILURES, catalogue_effectors=("aileron", "rudder"), failure_time=25.0,
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
