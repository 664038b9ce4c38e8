"""ICE tailless fighter, 6-DOF linear model, eleven effectors (seed section 4.7).

Flight condition: 1 g, wings level, M = 0.3, h = 15,000 ft.  Controlled
variables (channels, in the order of the seed's Eq 4.24 columns): angle of
attack ``alphaw``, stability-axis roll rate ``ps`` and sideslip ``betaw``.

Transcription checks (tests/sim/test_ice.py): the weighted pseudo-inverse of
:data:`B_DESIGN` with ``Wu = diag(2, 2, 1, ...)`` reproduces the printed
Eq 4.24; the actuator natural frequencies sqrt(40*100) = 63 and
sqrt(37.168*41.3) = 39 rad/s are the ones quoted in the failure list.

Substitutions (ours, not the seed's): the pilot models of Fig 4-86 are images
not recoverable from the scan.  The roll channel is flown by the run's pilot
model (:mod:`sim.pilot`; the stand-in ``p_c = 2.0 (phi_c - phi)`` delayed 0.2 s
by default).  The seed's Fig 4-85 also closes a pilot loop on angle of attack
("a pilot closes an outer loop to control the angle of attack and Euler roll
angle", section 4.7); by default the alpha sum-of-sines is fed straight into the
alpha reference model instead, and ``alpha_pilot=True`` closes that loop with
:func:`alpha_loop_pilot` (a crossover-model pilot with a lag: its numbers are ours).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from alloc.vehicles import ICE_B_FULL, ICE_BK_SEED, ICE_EFFECTORS

from sim.blocks import ActuatorFailure, ActuatorSpec, HedgeTerm, sum_of_sines
from sim.model import Failure, FlightCondition, LoopShapedDesign, Pilot, SMCDesign, Vehicle
from sim.pilot import CROSSOVER_DELAY, CROSSOVER_NEUROMUSCULAR, crossover_gain
from sim.scenarios.mimo import MimoScenario, mimo_scenario, run_mimo
from sim.result import SimResult

__all__ = [
    "A", "B", "C", "D", "B_DESIGN", "SEED_BK", "WU", "EFFECTORS", "OUTPUTS",
    "vehicle", "allocation_problem", "failure", "smc_design", "loop_shaped_design", "alpha_loop_pilot", "run",
]

STATES = ("u", "w", "qb", "theta", "v", "pb", "rb", "phi")
OUTPUTS = ("vel", "alphaw", "qb", "theta", "betaw", "ps", "rs", "phi", "axcg", "aycg", "azcg")
EFFECTORS = ("de3", "de13", "de4", "de5", "de15", "de9", "de19", "de2", "de12", "de10", "de20")

# seed section 4.7, A matrix (OCR "-0001257882" read as -0.001257882, etc.)
A = np.array([
    [0.005957049, 0.03198734, -1.330975822, -0.545071629, -0.001257882, 0, 0, 0],
    [-0.063377426, -0.586254141, 5.373673826, -0.135005804, -0.001903204, 0.000232091, 5.74854e-05, 0],
    [-0.052181448, 0.081703751, -0.594369479, 0, 0.011258699, 0.001753944, 0.000434425, 0],
    [0, 0, 1, 0, 0, 0, 0, 0],
    [3.32155e-07, 8.215e-08, 0, 0, 0.011094111, 1.331849864, -5.373457339, 0.54507129],
    [8.50045e-06, 2.10115e-06, 0, 0, -1.220701747, -0.607006478, 0.395148765, 0],
    [-2.90151e-06, -7.15713e-07, 0, 0, -0.126260979, 0.002970324, 0.02064623, 0],
    [0, 0, 0, 0, 0, 1, 0.247684519, 0],
])

# seed section 4.7, B (8 states x 11 effectors, order EFFECTORS): one transcription, in
# alloc.vehicles, shared with the allocation problem.
B = ICE_B_FULL.copy()

# seed section 4.7, C matrix (outputs OUTPUTS)
C = np.zeros((11, 8))
C[0, :2] = [0.970669032, 0.240419692]
C[1, :2] = [-0.043428009, 0.17533598]
C[2, 2] = 1.0
C[3, 3] = 1.0
C[4, 4] = 0.180634155
C[5, 5:7] = [0.970669034, 0.240419689]
C[6, 5:7] = [-0.240419689, 0.970669034]
C[7, 7] = 1.0
C[8, [0, 1, 4]] = [0.000185151, 0.000994198, -3.90962e-05]
C[9, [0, 1, 4, 5, 6]] = [1.03237e-08, 2.55331e-09, 0.000344816, 2.71661e-05, 6.72862e-06]
C[10, [0, 1, 4, 5, 6]] = [0.001969834, 0.018221363, 5.91535e-05, -7.21362e-06, -1.7867e-06]

# seed section 4.7, D^T: only the three acceleration outputs depend on the effectors
_D_ACC = np.array([
    [-0.000185532, -0.00028357, 0.008328726],
    [-0.000185532, 0.00028357, 0.008328726],
    [-0.000126984, 0, 0.007166854],
    [-0.000440534, -7.72328e-06, 0.002612026],
    [-0.000440534, 7.72328e-06, 0.002612026],
    [-0.000784435, 0.000681697, -0.003456716],
    [-0.000784435, -0.000681697, -0.003456716],
    [0.000357429, -0.000898262, -0.003016188],
    [0.000357429, 0.000898262, -0.003016188],
    [-3.669e-07, 0, 0.003852384],
    [0, 0.003852384, 0],
])
D = np.zeros((11, 11))
D[8:11, :] = _D_ACC.T

CONTROLLED = (OUTPUTS.index("alphaw"), OUTPUTS.index("ps"), OUTPUTS.index("betaw"))

# The design effectiveness behind Eq 4.24 is the state-derivative rows (w, pb, v)
# of B -- recovered from the printed B_k as (B_k' Wu B_k)^-1 B_k' Wu, which matches
# those rows to the printed digits -- with the spoiler-slot deflectors removed
# from the pitch (w) row ("spoilers artificially removed from the pitch channel").
B_DESIGN = B[[STATES.index("w"), STATES.index("pb"), STATES.index("v")]].copy()
B_DESIGN[0, [EFFECTORS.index("de9"), EFFECTORS.index("de19")]] = 0.0

# seed Eq 4.23 weights: Wu = diag[2, 2, 1, ...] (elevons weighted 2; the scan shows ten entries)
WU = np.array([2.0, 2.0] + [1.0] * 9)

# seed Eq 4.24 as printed (columns: alpha, p, beta pseudo-commands)
SEED_BK = ICE_BK_SEED.copy()


def _actuators() -> tuple[ActuatorSpec, ...]:
    """seed Table 4-5 (pitch/yaw nozzle pole printed once as 37.186, once as 37.168: 37.168 used)."""
    elevon = dict(a=40.0, b=100.0, lo=-30.0, hi=30.0, rate=150.0)
    spf = dict(a=40.0, b=100.0, lo=-30.0, hi=30.0, rate=50.0)
    tip = dict(a=40.0, b=100.0, lo=0.0, hi=60.0, rate=150.0)
    ssd = dict(a=40.0, b=100.0, lo=0.0, hi=60.0, rate=150.0)
    lef = dict(a=17.828, b=100.0, lo=-40.0, hi=40.0, rate=40.0)
    tv = dict(a=37.168, b=41.3, lo=-15.0, hi=15.0, rate=60.0)
    table = (elevon, elevon, spf, tip, tip, ssd, ssd, lef, lef, tv, tv)
    return tuple(ActuatorSpec.two_real_poles(n, **p) for n, p in zip(EFFECTORS, table, strict=True))


def flight_condition() -> FlightCondition:
    """Where ICE flies and what the air moves (``--turbulence``, :mod:`sim.world`).

    seed section 4.7 ("1g, wings-level, M = 0.3, h = 15,000 ft", line 3258 of the OCR'd seed):
    15,000 ft and M 0.3 with the standard atmosphere's 1057.4 ft/s there, V = 317.2 ft/s -- the
    model agrees: the inertial terms of A are U0 pi/180 = 5.3737 and W0 pi/180 = 1.3310, so
    sqrt(U0^2 + W0^2) = 317.2 ft/s.  States u, w, v in ft/s and qb, pb, rb in deg/s (seed
    section 4.7 state list); the aerodynamic entries of A are those the plant failure doubles
    (not :data:`_KINEMATIC`).  Span 37.5 ft: ours (the seed gives none; a fighter's, the F/A-18's).
    """
    deg = 180.0 / np.pi
    s = STATES.index
    return FlightCondition(
        altitude=15000.0, speed=317.2, span=37.5,
        gust_states=((s("u"), "u", 1.0), (s("w"), "w", 1.0), (s("v"), "v", 1.0), (s("pb"), "p", deg),
                     (s("qb"), "q", deg), (s("rb"), "r", deg)),
        aero=~_KINEMATIC, source="seed section 4.7: M 0.3, 15,000 ft; span ours")


def vehicle() -> Vehicle:
    """The nominal ICE model with its allocation data."""
    gains = np.full(len(OUTPUTS), 0.1414)  # seed section 4.7 noise gains
    gains[[OUTPUTS.index("alphaw"), OUTPUTS.index("betaw")]] = 0.0707
    return Vehicle(
        name="ice", A=A, B=B, C=C, D=D, output_names=OUTPUTS, actuators=_actuators(),
        controlled=CONTROLLED, measured=tuple(range(len(OUTPUTS))), noise_gains=gains,
        B_alloc=B_DESIGN, Bk_seed=SEED_BK, demand_map=np.eye(3), Wu=WU, names=ICE_EFFECTORS,
        flight=flight_condition(),
    )


def allocation_problem() -> Any:
    """The ICE :class:`alloc.Problem` (B_DESIGN, Table 4-5 limits and rates, Eq 4.23 weights)."""
    from sim.allocation import allocation_problem as _problem

    return _problem(vehicle())


# Kinematic elements of A kept at their nominal value by the plant failure ("A-matrix
# is multiplied by 2 -- with the exception of the elements describing kinematic
# relationships", seed section 4.7): the theta and phi rows, the gravity terms
# (theta column in u', w'; phi column in v') and the inertial U0, W0 terms
# (q in u', w'; p, r in v'), identified by value (U0 pi/180 = 5.374, g pi/180 cos(theta0) = 0.545).
_KINEMATIC = np.zeros_like(A, dtype=bool)
_KINEMATIC[[3, 7], :] = True
_KINEMATIC[[0, 1], 3] = True
_KINEMATIC[4, 7] = True
_KINEMATIC[[0, 1], 2] = True
_KINEMATIC[4, [5, 6]] = True


def failure(time: float = 20.0) -> Failure:
    """The seed's ICE vehicle failure at t = 20 s (section 4.7, bullet list)."""
    i = EFFECTORS.index
    return Failure(
        name="seed",
        time=time,
        description="plant (2A except kinematics, 0.75B), 50 ms delay, left elevon 10 deg/s +-15 deg, "
        "pitch flap and nozzles 10 rad/s, left LEF jammed at +5 deg (seed section 4.7)",
        A=np.where(_KINEMATIC, A, 2.0 * A),
        B=0.75 * B,
        D=0.75 * D,
        actuators=(
            ActuatorFailure(i("de3"), "limits", lo=-15.0, hi=15.0),
            ActuatorFailure(i("de3"), "rate_limits", rate_min=-10.0, rate_max=10.0),
            ActuatorFailure(i("de4"), "bandwidth", wn=10.0),
            ActuatorFailure(i("de2"), "jam", position=5.0),
            ActuatorFailure(i("de10"), "bandwidth", wn=10.0),
            ActuatorFailure(i("de20"), "bandwidth", wn=10.0),
        ),
        delay=0.05,
    )


# seed Eq 4.22 reference models (alpha, p, beta)
REFERENCES = (
    ([100.0], [1.0, 20.0, 100.0]),
    ([100.0], [1.0, 20.0, 100.0]),
    ([100.0], [1.0, 25.0, 100.0]),
)


def smc_design(*, observer: bool = True, hedge: bool = True) -> SMCDesign:
    """seed Eq 4.27 manifolds, eps = 1 (so rho = K_rho), Table 4-6 observers and hedges."""
    poles = (
        tuple(-10.0 - 0.1 * j for j in range(8)),  # alpha
        tuple(-40.0 - 0.1 * j for j in range(8)),  # ps
        tuple(-1.0 - 0.1 * j for j in range(8)),  # beta
    )
    terms = (
        HedgeTerm(0, 0, a_f=10.0, a_h=4.0, b_h=4.0),
        HedgeTerm(1, 1, a_f=50.0, a_h=4.0, b_h=4.0),
        HedgeTerm(2, 2, a_f=5.0, a_h=3.0, b_h=2.0),
        HedgeTerm(0, 2, a_f=10.0, a_h=4.0, b_h=4.0, gain=0.0001),
        HedgeTerm(1, 2, a_f=50.0, a_h=16.0, b_h=64.0, gain=-0.2),
        HedgeTerm(2, 1, a_f=5.0, a_h=2.0, b_h=1.0, gain=0.02),
    )
    return SMCDesign(
        rho=np.array([5000.0, 1000.0, 5000.0]),
        eps=np.ones(3),
        K0=np.ones(3),
        Km1=np.array([10.0, 20.0, 10.0]),
        observer_poles=poles if observer else None,
        hedge_terms=terms if hedge else (),
        hedge_gain=np.array([1.0, 2.0, 10.0]),
    )


def loop_shaped_design() -> LoopShapedDesign:
    """seed Eq 4.28 classic loop-shaped baseline (alpha, p, beta)."""
    return LoopShapedDesign(compensators=(
        (np.polymul([56.0], [1.0, 1.7, 0.52]), [1.0, 32.0, 0.0]),
        (np.polymul([10.0], [1.0, 0.4, 0.04]), [1.0, 0.0, 0.0]),
        (np.polymul([50.0], [1.0, 2.0, 1.0]), [1.0, 50.0, 0.0]),
    ))


#: Divergence bound on |alpha| (deg), |ps| (deg/s), |beta| (deg): far outside the
#: validity of a model linearised at 1 g, wings level (see sim.result).
OUTPUT_BOUND = np.array([45.0, 200.0, 30.0])

FAILURES = {"seed": "t = 20 s: " + failure().description}


# What the roll pilot flies, stick to bank angle: the p reference model, then phi = int(ps)
# (wings level, small alpha).  Sets the crossover pilot's gain (sim.pilot).
PILOT_ELEMENT = ([100.0], [1.0, 20.0, 100.0, 0.0])


def _commands(t: np.ndarray) -> np.ndarray:
    """Direct commands: the alpha sum-of-sines into the alpha reference model (seed section 4.7, xi = 5)."""
    commands = np.zeros((t.size, 3))
    commands[:, 0] = sum_of_sines(t, 5.0)
    return commands


# What the alpha pilot flies, stick to alpha: the alpha reference model (seed Eq 4.22), a
# K-like element (unit gain to 10 rad/s), for which the crossover model calls for a lag.
ALPHA_PILOT_ELEMENT = REFERENCES[0]
#: The alpha pilot's lag T_I (s), ours: long beside 1 / w_c, so that Y_p Y_c ~ w_c e^{-tau s} / s
#: around crossover (the crossover model's form for a K element).
ALPHA_PILOT_LAG = 5.0


def alpha_loop_pilot() -> Pilot:
    """The pilot of the alpha loop (seed Fig 4-85, option ``alpha_pilot``): the sum-of-sines (xi = 5) as
    alpha command, the crossover rule of :mod:`sim.pilot` (its delay, neuromuscular lag and 45 deg phase
    margin) with the lag :data:`ALPHA_PILOT_LAG` on :data:`ALPHA_PILOT_ELEMENT`."""
    gain, _ = crossover_gain(*ALPHA_PILOT_ELEMENT, lag=ALPHA_PILOT_LAG)
    row = np.zeros(len(OUTPUTS))
    row[OUTPUTS.index("alphaw")] = 1.0
    return Pilot(channel=0, row=row, name="alpha", gain=gain, delay=CROSSOVER_DELAY, lag=ALPHA_PILOT_LAG,
                 neuromuscular=CROSSOVER_NEUROMUSCULAR, model="crossover",
                 attitude_command=lambda tt: sum_of_sines(tt, 5.0))


def _pilots(params: dict[str, Any], alpha_pilot: bool = False) -> Pilot | tuple[Pilot, Pilot]:
    row = np.zeros(len(OUTPUTS))
    row[OUTPUTS.index("phi")] = 1.0
    roll = Pilot(
        channel=1, row=row, name="phi", **params,
        attitude_command=lambda tt: sum_of_sines(tt, 10.0, phase_step=np.pi / 4),  # xi = 10, i*pi/4
    )
    if not isinstance(alpha_pilot, (bool, np.bool_)):
        raise TypeError(f"alpha_pilot: {alpha_pilot!r}; expected True or False")
    return (roll, alpha_loop_pilot()) if alpha_pilot else roll


SCENARIO = MimoScenario(
    name="ice", vehicle=vehicle, references=REFERENCES, smc_design=smc_design,
    loop_shaped_design=loop_shaped_design, failure=lambda name, time: _failure_by_name(name, time),
    pilot=_pilots, pilot_element=PILOT_ELEMENT, commands=_commands, output_bound=OUTPUT_BOUND,
    default_duration=40.0, default_method="pinv", catalogue_vehicle="ice", input_options=("alpha_pilot",),
    # the catalogue fails the two surfaces the seed's ICE failure degrades; at the seed's failure time
    failures=FAILURES, catalogue_effectors=("elevon_l", "lef_l"), failure_time=20.0,
)


@mimo_scenario(SCENARIO,
               description="ICE 6-DOF, 11 effectors, observer-based SMC with hedging, alpha/ps/beta tracking (seed 4.7)")
def run(**options: Any) -> SimResult:
    """Run the ICE scenario: :func:`sim.scenarios.mimo.run_mimo` options, plus ``observer``, ``hedge``
    and ``alpha_pilot`` (close the seed's Fig 4-85 alpha pilot loop; default False, see the module docstring).

    ``controller`` is ``"smc"`` (Eq 4.27 with Table 4-6 observers/hedges,
    switchable off with ``observer``/``hedge``) or ``"loopshape"`` (Eq 4.28).
    """
    return run_mimo(SCENARIO, **options)


def _failure_by_name(name: str, time: float | None) -> Failure:
    if name == "seed":
        return failure(20.0 if time is None else time)
    raise KeyError(f"unknown ICE failure {name!r}; known: {sorted(FAILURES)}")
