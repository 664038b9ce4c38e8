"""F-18/HARV longitudinal pitch-rate tracking, two effectors (seed section 4.5).

Flight condition M = 0.6, h = 30,000 ft; short-period model Eq 4.9, failed
plant Eq 4.10 (50 % stabilator area), Table 4-1 actuators, reference model
Eq 4.11, ganging Eq 4.12, SMC ``K_rho = -30, K0 = 1, K_-1 = 20`` with
``eps = 0.1`` (``rho = -30``: |rho| must cover the 30 deg limit, seed 4.5).

Designs (observer poles and hedge, seed 4.5):
``slow``: -7, -8, no hedge; ``fast``: -50, -51, hedge ``-5 s/(s+100) 100/(s^2+20s+100)``;
``modified`` (default, used for Failure #2): -40, -41, hedge
``-100 s/(s+100) 4/(s^2+4s+4)``.  Loop-shaped baseline
``G_c = -2.5 (s^2 + 0.8 s + 1.2)/(s (s + 0.3))``.

Substitutions (ours): pitch attitude ``theta = int(q)`` (level flight); the
pilot (Fig 4-6, an image) is a crossover-model pilot ``q_c = K (theta_c - theta)``
delayed 0.2 s, ``K = 2``; noise gain 1.0 on alpha and q gives the printed
RMS of about 0.5 deg/s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.blocks import ActuatorFailure, ActuatorSpec, HedgeTerm, sum_of_sines
from sim.model import Failure, FlightCondition, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.scenarios.mimo import MimoScenario, mimo_scenario, run_mimo
from sim.result import SimResult

__all__ = ["A", "B", "A_FAIL", "B_FAIL", "SEED_BK", "vehicle", "allocation_problem", "failure", "run"]

OUTPUTS = ("alpha", "q")
EFFECTORS = ("stab", "ptv")
A = np.array([[-0.5088, 0.9940], [-1.1310, -0.2804]])  # seed Eq 4.9
B = np.array([[-0.9277, -0.01787], [-6.575, -1.525]])  # seed Eq 4.9
A_FAIL = np.array([[-0.48, 0.997], [-0.39, -0.182]])  # seed Eq 4.10
B_FAIL = np.array([[-0.4639, -0.01787], [-3.2875, -1.525]])  # seed Eq 4.10 ("-3 2875" = 6.575/2)
SEED_BK = np.array([[1.0], [1.0]])  # seed Eq 4.12
REFERENCES = (([100.0], [1.0, 25.0, 100.0]),)  # seed Eq 4.11: 100/((s+5)(s+20))
OUTPUT_BOUND = np.array([200.0])  # |q| deg/s, far outside the short-period model's validity


def _actuators(tv_wn: float = 20.0) -> tuple[ActuatorSpec, ...]:
    """seed Table 4-1."""
    return (
        ActuatorSpec.second_order("stab", 30.0, 0.707, -30.0, 30.0, 60.0),
        ActuatorSpec.second_order("ptv", tv_wn, 0.6, -30.0, 30.0, 60.0),
    )


#: ft/s: M 0.6 at 30,000 ft (seed section 4.5, line 2619 of the OCR'd seed), standard atmosphere a = 994.8 ft/s
SPEED = 0.6 * 994.8


def flight_condition() -> FlightCondition:
    """seed section 4.5's condition; angle of attack (deg) sees ``w_g / V``, pitch rate (deg/s) ``q_g``;
    span 37.5 ft (the F/A-18's, ours)."""
    deg = 180.0 / np.pi
    return FlightCondition(altitude=30000.0, speed=SPEED, span=37.5,
                           gust_states=((0, "w", deg / SPEED), (1, "q", deg)),
                           source="seed section 4.5: M 0.6, 30,000 ft; span ours")


def vehicle() -> PlantModel:
    """Nominal HARV longitudinal model; allocation rows: q-dot effectiveness."""
    B_alloc = B[[1]]
    return PlantModel(
        name="harv_lon", A=A, B=B, C=np.eye(2), D=np.zeros((2, 2)), output_names=OUTPUTS,
        actuators=_actuators(), controlled=(1,), measured=(0, 1), noise_gains=np.array([1.0, 1.0]),
        B_alloc=B_alloc, Bk_seed=SEED_BK, demand_map=B_alloc @ SEED_BK, flight=flight_condition(),
    )


def allocation_problem() -> Any:
    from sim.allocation import allocation_problem as _problem

    return _problem(vehicle())


FAILURES = {
    "plant": "t = 10 s: failed plant, Eq 4.10 (50 % stabilator area)",
    "failure1": "t = 10 s: failed plant + thrust-vector hard-over at -3 deg (seed 4.5)",
    "failure2": "t = 10 s: failed plant, stabilator rate 30 deg/s, thrust vector rate 6 deg/s "
    "and bandwidth 10 rad/s, 50 ms delay in both actuators (seed 4.5, Failure #2)",
}


def failure(name: str, time: float = 10.0) -> Failure:
    if name == "plant":
        return Failure("plant", time, FAILURES[name], A=A_FAIL, B=B_FAIL)
    if name == "failure1":
        return Failure(
            "failure1", time, FAILURES[name], A=A_FAIL, B=B_FAIL,
            actuators=(ActuatorFailure(1, "hardover", position=-3.0),),
        )
    if name == "failure2":
        return Failure(
            "failure2", time, FAILURES[name], A=A_FAIL, B=B_FAIL,
            actuators=(
                ActuatorFailure(0, "rate_limits", rate_min=-30.0, rate_max=30.0),
                ActuatorFailure(1, "rate_limits", rate_min=-6.0, rate_max=6.0),
                ActuatorFailure(1, "bandwidth", wn=10.0),
            ),
            delay=0.05,
        )
    raise KeyError(f"unknown HARV longitudinal failure {name!r}; known: {sorted(FAILURES)}")


DESIGNS = {
    "slow": ((-7.0, -8.0), None),
    "fast": ((-50.0, -51.0), (-5.0, 100.0, 20.0, 100.0)),
    "modified": ((-40.0, -41.0), (-100.0, 100.0, 4.0, 4.0)),
}


def smc_design(design: str = "modified", *, observer: bool = True, hedge: bool = True) -> SMCDesign:
    poles, h = DESIGNS[design]
    terms: tuple[HedgeTerm, ...] = ()
    gain = np.array([1.0])
    if h is not None and hedge:
        gain = np.array([h[0]])
        terms = (HedgeTerm(0, 0, a_f=h[1], a_h=h[2], b_h=h[3]),)
    return SMCDesign(
        rho=np.array([-30.0]), eps=np.array([0.1]), K0=np.array([1.0]), Km1=np.array([20.0]),
        observer_poles=(poles,) if observer else None, hedge_terms=terms, hedge_gain=gain,
    )


def loop_shaped_design() -> LoopShapedDesign:
    """seed section 4.5: G_c = -2.5 (s^2 + 0.8 s + 1.2) / (s (s + 0.3))."""
    return LoopShapedDesign(compensators=((np.polymul([-2.5], [1.0, 0.8, 1.2]), [1.0, 0.3, 0.0]),))


# What the pitch pilot flies, stick to pitch attitude: the q reference model, then theta = int(q).
PILOT_ELEMENT = ([100.0], [1.0, 25.0, 100.0, 0.0])


def _pitch_pilot(params: dict[str, Any]) -> Pilot:
    return Pilot(
        channel=0, row=np.array([0.0, 1.0]), integrate=True, name="theta", **params,
        attitude_command=lambda tt: sum_of_sines(tt, 5.0),  # seed Eq 4.13, xi = 5
    )


SCENARIO = MimoScenario(
    name="harv_lon", vehicle=vehicle, references=REFERENCES, smc_design=smc_design,
    loop_shaped_design=loop_shaped_design,
    failure=lambda name, time: failure(name, 10.0 if time is None else time),
    pilot=_pitch_pilot, pilot_element=PILOT_ELEMENT, commands=lambda t: np.zeros((t.size, 1)),
    output_bound=OUTPUT_BOUND, default_duration=30.0, default_method="ganging",
    design_options=("design", "observer", "hedge"), failures=FAILURES, failure_time=10.0,
)


@mimo_scenario(SCENARIO,
               description="F-18/HARV longitudinal pitch-rate SMC, stabilator + pitch thrust vector (seed 4.5)")
def run(**options: Any) -> SimResult:
    """Run the HARV longitudinal scenario: :func:`sim.scenarios.mimo.run_mimo` options, plus
    ``design`` (``"slow"``, ``"fast"``, ``"modified"``), ``observer`` and ``hedge``."""
    return run_mimo(SCENARIO, **options)
