"""ICE tailless fighter, 6-DOF linear model, eleven effectors (seed section 4.7).

Flight condition: 1 g, wings level, M = 0.3, h = 15,000 ft.  Controlled
variables (channels, in the order of the seed's Eq 4.24 columns): angle of
attack ``alphaw``, stability-axis roll rate ``ps`` and sideslip ``betaw``.

The numbers are alloc/data/vehicles/ice.toml's (its ``[model]``, effectors and ``[simulation]``);
this module names them for the simulator and adds the alpha pilot (where it flies: :mod:`sim.seed_flight`).
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

import dataclasses
from typing import Any

import numpy as np

from alloc.vehicles import bundled

from sim.blocks import sum_of_sines
from sim.file_scenario import file_scenario, loop_of
from sim.seed_flight import ice as flight_condition  # noqa: F401  # this scenario's name for it
from sim.model import Failure, LoopShapedDesign, PlantModel, Pilot, SMCDesign
from sim.pilot import CROSSOVER_DELAY, CROSSOVER_NEUROMUSCULAR, crossover_gain
from sim.scenarios.mimo import mimo_scenario, run_mimo
from sim.result import SimResult

__all__ = [
    "A", "B", "C", "D", "B_DESIGN", "SEED_BK", "WU", "EFFECTORS", "OUTPUTS",
    "vehicle", "allocation_problem", "failure", "smc_design", "loop_shaped_design", "alpha_loop_pilot", "run",
]

#: The seed's ICE as data: alloc/data/vehicles/ice.toml carries the model (seed section 4.7 A,
#: B, C, D), the actuators (Table 4-5), the design allocation (Eq 4.23-4.24), the controller
#: (Eq 4.22, 4.27, 4.28, Table 4-6) and the failure; this module adds what is no file's.
_FILE = bundled("ice")
_LOOP = file_scenario(_FILE)
_MODEL, _SIM = loop_of(_FILE)

STATES = tuple(_MODEL.states)
OUTPUTS = tuple(_MODEL.outputs)
#: the seed's effector labels, in the file's order (elevon_l is de3, ...)
EFFECTORS = ("de3", "de13", "de4", "de5", "de15", "de9", "de19", "de2", "de12", "de10", "de20")
A, B, C, D = _MODEL.arrays()
CONTROLLED = tuple(OUTPUTS.index(c) for c in _MODEL.controlled)

# The design effectiveness behind Eq 4.24 is the state-derivative rows (w, pb, v)
# of B -- recovered from the printed B_k as (B_k' Wu B_k)^-1 B_k' Wu, which matches
# those rows to the printed digits -- with the spoiler-slot deflectors removed
# from the pitch (w) row ("spoilers artificially removed from the pitch channel").
B_DESIGN = np.array(_SIM.allocation.B, dtype=float)
# seed Eq 4.23 weights: Wu = diag[2, 2, 1, ...] (elevons weighted 2; the scan shows ten entries)
WU = np.array(_SIM.allocation.weights, dtype=float)
# seed Eq 4.24 as printed (columns: alpha, p, beta pseudo-commands)
SEED_BK = np.array(_SIM.allocation.static, dtype=float)


def vehicle() -> PlantModel:
    """The nominal ICE model with its allocation data (ice.toml; flight condition :func:`sim.seed_flight.ice`)."""
    return _LOOP.vehicle()


def allocation_problem() -> Any:
    """The ICE :class:`alloc.Problem` (B_DESIGN, Table 4-5 limits and rates, Eq 4.23 weights)."""
    from sim.allocation import allocation_problem as _problem

    return _problem(vehicle())


def failure(time: float = 20.0) -> Failure:
    """The seed's ICE vehicle failure at t = 20 s (section 4.7, bullet list; ice.toml ``failures.seed``)."""
    return _LOOP.failure("seed", time)


# seed Eq 4.22 reference models (alpha, p, beta)
REFERENCES = _LOOP.references


def smc_design(*, observer: bool = True, hedge: bool = True) -> SMCDesign:
    """seed Eq 4.27 manifolds, eps = 1 (so rho = K_rho), Table 4-6 observers and hedges (ice.toml)."""
    return _LOOP.smc_design(observer=observer, hedge=hedge)


def loop_shaped_design() -> LoopShapedDesign:
    """seed Eq 4.28 classic loop-shaped baseline (alpha, p, beta; ice.toml)."""
    return _LOOP.loop_shaped_design()


#: Divergence bound on |alpha| (deg), |ps| (deg/s), |beta| (deg): far outside the
#: validity of a model linearised at 1 g, wings level (see sim.result).
OUTPUT_BOUND = _LOOP.output_bound

FAILURES = {"seed": "t = 20 s: " + failure().description}


# What the roll pilot flies, stick to bank angle: the p reference model, then phi = int(ps)
# (wings level, small alpha).  Sets the crossover pilot's gain (sim.pilot).
PILOT_ELEMENT = _LOOP.pilot_element


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
    roll = _LOOP.pilot(params)  # phi, sum of sines xi = 10, phase i*pi/4 (ice.toml)
    if not isinstance(alpha_pilot, (bool, np.bool_)):
        raise TypeError(f"alpha_pilot: {alpha_pilot!r}; expected True or False")
    return (roll, alpha_loop_pilot()) if alpha_pilot else roll


SCENARIO = dataclasses.replace(
    _LOOP, vehicle=vehicle, smc_design=smc_design, failure=lambda name, time: _failure_by_name(name, time),
    pilot=_pilots, catalogue_vehicle="ice", input_options=("alpha_pilot",),  # commands: alpha sines, xi = 5
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
