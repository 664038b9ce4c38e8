"""Closed-loop engine shared by the MIMO scenarios (ICE, F-18/HARV): :func:`simulate`.

Multi-rate: plant, actuators and delay integrate every step ``dt`` (the
seed's 0.5 ms); the flight-control computer -- pilot sampling, reference
models, observers, SMC, hedges and the allocator -- runs once per frame
``T = LoopSpec.frame_period`` (a multiple of ``dt``), its outputs held in
between.  ``T = dt`` is the seed's single-rate loop, bit for bit.

Signal flow per frame (seed Figs 3-26, 3-32, 4-85)::

    pilot -> command -> reference models -> r
    plant outputs + noise -> z -> observers (+ hedge) -> y_hat_h
    e = r - y_hat_h,  sigma = K0 e + K_-1 int(e),  u_c = rho sat(sigma/eps)
    v = demand_map u_c  ->  allocator  ->  u_cmd  ->  delay -> actuators -> plant

Linear controller dynamics (reference models, observers, hedge) are stacked
into one continuous system and discretised exactly once, so a step costs a
handful of small matrix-vector products plus the allocator call.  The loop-
shaped baseline replaces the SMC, observers and hedge by one linear
compensator per channel acting on ``r - y_measured``.

Speed: everything but the allocator runs in the two numba-compiled functions
of :mod:`sim.packed` on packed state.  The Python loop is ``allocator(v)`` then
one :func:`sim.packed.advance` call per step; failure injection
(:mod:`sim.injection`) and allocator rebuilds stay in Python.

``health = "detected"`` (:mod:`sim.detection`): the injected failure reaches the plant and
actuators only; a detector samples the simulated sensors every 0.1 s, and each detection
rebuilds the allocator on the detector's belief at the first frame after its processing delay.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from tqdm import tqdm

from sim.allocation import LoopAllocator, build_allocator, hold_commands, preferred_positions
from sim.blocks import (
    ActuatorBank,
    DelayLine,
    DiscreteLTI,
    ScheduledPlant,
    band_limited_noise,
    hedge_system,
    observer_gain,
    stack_lti,
    tf_to_ss,
)
from sim.detection import InLoopDetector, design_with, detection_record
from sim.harm import InLoopHarm
from sim.injection import inject_failure
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.packed import DIVERGED, N_MISC, FloatSlot, IntSlot, Misc, Packed, advance, observe, record_columns
from sim.result import SimResult
from sim.settings import LoopSpec, SettingError, anti_windup_on, boundary_layer_at
from sim.world import (GUST_COMPONENTS, GUST_RISE, GUST_SIGMAS, GUST_TIME, dryden, gust_matrix, gust_series,
                       measurement_noise, model_error_factors, quantisation_steps, scaled_actuator)

__all__ = ["simulate"]


def simulate(
    spec: LoopSpec | None = None,
    *,
    progress: bool = False,
    step_times: list[np.ndarray] | None = None,
    **fields: Any,
) -> SimResult:
    """Run one closed loop.

    Multi-rate (seed 0.5 ms plant, frame ``T`` flight-control computer): at
    each frame the compiled :func:`sim.packed.observe` samples the pilot and the noisy
    outputs, advances the SMC and produces the demand ``v``; the allocator (a
    plug-in, called from Python) turns it into ``u_cmd`` with ``u_prev`` and
    ``dt = T`` (seed Eq 1.28); one compiled :func:`sim.packed.advance` per integration
    step records, integrates the controller (at frames), plant, delay and
    actuators with ``u_cmd`` held.  With ``T = dt`` this is the seed's single-
    rate loop, bit for bit.

    Parameters
    ----------
    spec : LoopSpec
        The run; alternatively its fields as keywords (``simulate(**fields)``).
    progress : bool
        Show a progress bar.
    step_times : list or None
        When given, one array is appended: the wall time (s) of every
        integration step (allocator call, when due, plus the compiled step);
        set-up and failure injection are not included.
    """
    if spec is None:
        spec = LoopSpec(**fields)
    elif fields:
        raise TypeError(f"simulate: give a LoopSpec or keywords, not both (got {sorted(fields)})")
    frame = spec.frame_steps()
    vehicle, failure, method, pilots = spec.vehicle, spec.failure, spec.method, spec.pilots
    dt, record_every = spec.dt, spec.record_every
    tframe = frame * dt
    k = len(vehicle.controlled)
    m = len(vehicle.actuators)
    n_steps = int(round(spec.duration / dt))
    t_grid = np.arange(n_steps + 1) * dt
    # Failure step: the first with t >= t_fail - dt/2 (never: n_steps + 1).
    fail_step = n_steps + 1
    if failure is not None:
        due = np.nonzero(t_grid >= failure.time - 0.5 * dt)[0]
        fail_step = int(due[0]) if due.size else n_steps + 1
    world: dict[str, Any] = {}
    inputs = _inputs(spec, t_grid, world)
    plant, bank = _world_plant(spec, world)
    gust, disturbance = _turbulence(spec, t_grid, fail_step, world)
    if gust is not None:
        inputs = np.hstack([inputs, gust])
    delay = DelayLine(m, dt, 0.0)
    alloc_options = dict(rate_aware=spec.rate_aware, preferred=spec.preferred, frame_period=tframe,
                         rate_horizon=spec.rate_horizon, rate_window=spec.rate_window,
                         excitation=spec.excitation, excitation_seed=spec.seed)
    method_options = spec.method_options or {}
    allocator: LoopAllocator = build_allocator(vehicle, method, method_options, **alloc_options)
    position_feedback = spec.u_prev_source == "position"
    packed = _pack(spec, plant, bank, delay, frame, n_steps, fail_step, quantisation=world.get("quantisation"),
                   gust_column=0 if gust is None else inputs.shape[1] - gust.shape[1])
    # The bank's position and rate live in the packed buffer (failures write there).
    bank.pos, bank.rate = packed.view(FloatSlot.POS), packed.view(FloatSlot.RATE)
    F, I = packed.F, packed.I
    v = packed.view(FloatSlot.V)

    cols = record_columns(k, m, len(pilots))
    rec = np.zeros((n_steps // record_every + 1, cols["extra"].stop))
    u_cmd = np.zeros(m)
    v_achieved = np.zeros(k)
    positions = packed.view(FloatSlot.UACT)
    # allocator status of every frame (STATUS_NAMES codes; -1: not reached)
    call_status = np.full(n_steps // frame + 1, -1, dtype=np.int8)
    n_done = n_steps + 1

    def fail_now(u_last: np.ndarray) -> LoopAllocator:
        injected = inject_failure(failure, plant, bank, delay, packed, u_last)  # defaults filled in: what is told
        if spec.actuators:
            packed.view(FloatSlot.UACT)[:] = bank.pos  # a jammed surface is at its jam position at once
        if spec.health_mode == "told":
            # its first call is the next frame's (the excitation's signal goes on)
            return build_allocator(vehicle, method, method_options, failure=injected,
                                   first_call=-(-fail_step // frame), **alloc_options)
        return allocator  # blind and detected: the failure itself tells the allocator nothing

    if fail_step == 0:
        allocator = fail_now(u_cmd)
    status = observe(0, F, I, inputs)
    iterator = range(n_steps + 1)
    if progress:
        iterator = tqdm(iterator, total=n_steps + 1, unit="step", mininterval=0.5, desc=spec.scenario)
    timed = step_times is not None
    times = np.full(n_steps + 1, np.nan) if timed else None
    clock = time.perf_counter
    last_before_failure = fail_step - 1 if failure is not None else -1
    step_once, diverged = advance, DIVERGED  # locals: the loop body is the per-step Python cost
    # --health detected: the detector on the simulated sensors (never the failure), and the
    # beliefs waiting for their processing delay: (step the allocator gets it, belief)
    detector = _detector(spec, inputs) if spec.health_mode == "detected" else None
    harm = InLoopHarm(vehicle, detector) if detector is not None else None
    pending: list[tuple[int, dict[str, Any]]] = []
    detections: list[dict[str, Any]] = []
    x = packed.view(FloatSlot.X)
    z, r = packed.view(FloatSlot.Z), packed.view(FloatSlot.R)
    controlled = np.asarray(vehicle.controlled)
    for step in iterator:
        if status == diverged:
            n_done = step
            break
        if timed:
            t0 = clock()
        if step % frame == 0:
            if pending and step >= pending[0][0]:
                harm.apply(_due(pending, step), u_cmd, step * dt)
                allocator = hold_commands(build_allocator(vehicle, method, method_options, health=harm.belief,
                                                          first_call=step // frame, **alloc_options), harm.held)
            u_prev = positions.copy() if position_feedback else u_cmd
            u_cmd, v_achieved, call_status[step // frame] = allocator(v, u_prev, tframe)
        status = step_once(step, u_cmd, v_achieved, F, I, inputs, rec)
        if detector is not None:
            detector.step_model(u_cmd)
        if timed:
            times[step] = clock() - t0
        if step == last_before_failure:
            allocator = fail_now(u_cmd)
            status = observe(step + 1, F, I, inputs)
        if detector is not None and detector.due(step + 1) and step < n_steps:
            # the sensors measure the plant's physics as it is now (plant._cur: the failed model after injection)
            at = step + 1 + detector.delay_steps
            applied = -(-at // frame) * frame * dt
            # and the gust's state derivative where there is turbulence (the sensors measure it too)
            gust_now = {} if disturbance is None else {"disturbance": disturbance[step + 1]}
            found = detector.sample(step + 1, x, positions, plant._cur.A, plant._cur.B, **gust_now)
            # the loop's tracking as the flight computer measures it (r - z, the last frame's)
            harm.observe((step + 1) * dt, r - z[controlled], detector.last_y, detector.pos)
            for detection in found:
                detections.append(detection_record(detection, applied, None if failure is None else failure.time))
                detections[-1]["applied"] = harm.detected(detections[-1])  # False: refused (sim.harm)
                if detections[-1]["applied"]:
                    pending.append((at, detector.health))
            withdrawn = harm.verdicts((step + 1) * dt)
            for w in withdrawn:
                w["applied_time"] = applied
            if withdrawn or harm.released:  # a belief back, or a hold released (a probation passed)
                pending.append((at, detector.health))
    if timed:
        step_times.append(times[:n_done])
    n = (n_done + record_every - 1) // record_every  # samples recorded before step n_done
    n_calls = (n_done + frame - 1) // frame
    result = _result(rec[:n], cols, spec.scenario, method, vehicle, failure, pilots, diverged=n_done <= n_steps)
    result.allocator_t = np.arange(n_calls) * tframe
    result.allocator_status = call_status[:n_calls].copy()
    result.settings = {**spec.record(), "pilots": [p.describe() for p in pilots]}
    if spec.worldly:  # the drawn world; absent at the defaults (the record as it always was)
        result.settings["world"] = _jsonable_world(world)
    if detector is not None:
        result.detections = detections
        result.withdrawals = harm.withdrawals
        result.detector = {**detector.describe(), "do_no_harm": harm.describe()}
    return result


def _detector(spec: LoopSpec, inputs: np.ndarray) -> InLoopDetector:
    """The in-loop detector of a ``detected`` run, on the run's own sensor noise (``inputs``' noise columns)."""
    vehicle = spec.vehicle
    k, ny = len(vehicle.controlled), vehicle.C.shape[0]
    design = design_with(spec.detector_long_window, spec.detector_model)
    return InLoopDetector(vehicle, spec.dt, inputs[:, k:k + ny], noise_scale=spec.noise_scale,
                          actuators=spec.actuators, preferred=preferred_positions(vehicle, spec.preferred),
                          design=design)


def _due(pending: list[tuple[int, dict[str, Any]]], step: int) -> dict[str, Any]:
    """The latest belief due by ``step``, removed with every earlier one from ``pending``."""
    belief = pending[0][1]
    while pending and step >= pending[0][0]:
        belief = pending.pop(0)[1]
    return belief


def _inputs(spec: LoopSpec, t_grid: np.ndarray, world: dict[str, Any] | None = None) -> np.ndarray:
    """Per integration step: direct commands (k), measurement noise (ny), pilots' attitude commands.

    Noise is on the measured outputs only, precomputed (vectorised filtering) from ``spec.seed``,
    the seed's gains times ``spec.noise_scale``; a ``noise_model`` other than ``gaussian`` draws
    its families by :func:`sim.world.measurement_noise` and records them in ``world``.
    """
    vehicle, n = spec.vehicle, t_grid.size
    noise = np.zeros((n, vehicle.C.shape[0]))
    terms = spec.noise_terms()
    measured = np.asarray(vehicle.measured)
    gains = vehicle.noise_gains * spec.noise_scale
    if spec.noise and all(t.family == "gaussian" for t in terms):
        rng = np.random.default_rng(spec.seed)
        noise[:, measured] = band_limited_noise(n, spec.dt, gains, rng)
    elif spec.noise:
        noise[:, measured], drawn = measurement_noise(terms, n, spec.dt, gains, spec.seed)
        steps = np.zeros(vehicle.C.shape[0])
        steps[measured] = quantisation_steps(terms, spec.dt, gains)
        if world is not None:
            world["noise"] = {"families": [t.family for t in terms], "parameters": [t.parameter for t in terms],
                              "output_std": dict(zip([vehicle.output_names[i] for i in measured],
                                                     (drawn["unit_std"] * np.abs(gains)).tolist(), strict=True)),
                              **drawn, "quantisation": steps.tolist()}
            if np.any(steps):
                world["quantisation"] = steps
    return np.hstack([
        np.asarray(spec.commands, dtype=float)[:n],
        noise,
        np.column_stack([p.attitude_command(t_grid) for p in spec.pilots]) if spec.pilots else np.zeros((n, 0)),
    ])


def _world_plant(spec: LoopSpec, world: dict[str, Any]) -> tuple[ScheduledPlant, ActuatorBank]:
    """The plant and the actuator bank as the world has them (``model_error``: scaled, the draws in ``world``).

    The nominal model (``spec.vehicle``) is left to the controller, the allocator and the detector.
    """
    vehicle, failure, dt = spec.vehicle, spec.failure, spec.dt
    A_fail = None if failure is None else failure.A
    B_fail = None if failure is None else failure.B
    D_fail = None if failure is None else failure.D
    if not spec.model_error:
        plant = ScheduledPlant(vehicle.A, vehicle.B, vehicle.C, vehicle.D, dt, A_fail=A_fail, B_fail=B_fail,
                               D_fail=D_fail)
        return plant, ActuatorBank(vehicle.actuators, dt)
    s, w = model_error_factors(spec.model_error, len(vehicle.actuators), spec.seed)

    def scaled(M: np.ndarray | None) -> np.ndarray | None:  # column j is effector j's
        return None if M is None else np.asarray(M, dtype=float) * s

    plant = ScheduledPlant(vehicle.A, scaled(vehicle.B), vehicle.C, scaled(vehicle.D), dt, A_fail=A_fail,
                           B_fail=scaled(B_fail), D_fail=scaled(D_fail))
    world["model_error"] = {"error": spec.model_error, "effectors": vehicle.effector_names,
                            "effectiveness": s.tolist(), "bandwidth": w.tolist()}
    return plant, ActuatorBank([scaled_actuator(a, f) for a, f in zip(vehicle.actuators, w, strict=True)], dt)


def _turbulence(spec: LoopSpec, t_grid: np.ndarray, fail_step: int, world: dict[str, Any]
                ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(per-step plant-state increments (n, nx), state-derivative disturbance (n, nx))``, or Nones.

    The disturbance is ``E g`` (:func:`sim.world.gust_matrix`) of the Dryden gusts ``g``; it is held
    over a step, so its exact increment is ``Gamma E g`` with ``Gamma = int_0^dt e^(A s) ds``, the
    same ZOH as ``u``.  At the failure step both switch to the failed ``A``.
    """
    if spec.turbulence == "none":
        return None, None
    vehicle, failure, dt = spec.vehicle, spec.failure, spec.dt
    flight = vehicle.flight
    if flight is None:
        raise SettingError(f"turbulence: vehicle {vehicle.name!r} states no flight condition and no air-relative "
                           "states (sim.model.FlightCondition); fly it with --turbulence none", field="turbulence")
    d = dryden(spec.turbulence, flight)
    g = gust_series(d, t_grid.size, dt, spec.seed)
    nx = vehicle.A.shape[0]
    disturbance = np.empty((t_grid.size, nx))
    increment = np.empty((t_grid.size, nx))
    A_after = vehicle.A if failure is None or failure.A is None else failure.A
    for A, rows in ((vehicle.A, slice(0, fail_step)), (A_after, slice(fail_step, None))):
        E = gust_matrix(A, flight)
        Gamma = DiscreteLTI(A, np.eye(nx), np.zeros((1, nx)), np.zeros((1, nx)), dt).Bd
        disturbance[rows] = g[rows] @ E.T
        increment[rows] = disturbance[rows] @ Gamma.T
    world["turbulence"] = {**d.record(), "flight_source": flight.source, "gust_time": GUST_TIME,
                           "gust_amplitude": GUST_SIGMAS * d.sigma_w, "gust_half_length": d.speed * GUST_RISE,
                           "gust_matrix": gust_matrix(vehicle.A, flight).tolist(),
                           "components": list(GUST_COMPONENTS), "std": g.std(axis=0).tolist()}
    return increment, disturbance


def _jsonable_world(world: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in world.items() if k != "quantisation"}


def _pack(
    spec: LoopSpec, plant: ScheduledPlant, bank: ActuatorBank, delay: DelayLine, frame: int, n_steps: int,
    fail_step: int, *, quantisation: np.ndarray | None = None, gust_column: int = 0,
) -> Packed:
    """The packed buffers of the run: plant, controller, actuators, delay ring, pilots, signals, constants.

    ``quantisation``: per output, the step of the quantised sensor (None: none); ``gust_column``:
    the first ``inputs`` column of the gust's per-step state increments (0: no turbulence).
    """
    vehicle, controller, failure, pilots, dt = spec.vehicle, spec.controller, spec.failure, spec.pilots, spec.dt
    tframe = frame * dt
    k, m, ny = len(vehicle.controlled), len(vehicle.actuators), vehicle.C.shape[0]
    smc = isinstance(controller, SMCDesign)
    controller_slots = _controller_slots(vehicle, controller, spec.references, tframe, spec.boundary_layer)
    pilot_floats, pilot_ints = _pilot_slots(pilots, ny, tframe)
    # The actuator delay ring holds the longest delay of the run.
    ring = 1
    if failure is not None and failure.delay is not None:
        ring = int(DelayLine(m, dt, failure.delay).n.max()) + 1
    misc = np.zeros(N_MISC, dtype=np.int64)
    misc[[Misc.N_STEPS, Misc.RECORD_EVERY, Misc.FAIL_STEP]] = n_steps, spec.record_every, fail_step
    misc[Misc.SMC] = smc
    misc[Misc.OBSERVED] = smc and controller.observer_poles is not None
    misc[Misc.SIGN] = smc and controller.eps is None
    misc[Misc.ACTUATORS] = spec.actuators
    misc[Misc.FRAME] = frame
    misc[Misc.PFILTER] = any(p.filtered for p in pilots)
    misc[Misc.ANTI_WINDUP] = smc and anti_windup_on(spec.anti_windup, tframe)
    misc[Misc.QUANT] = quantisation is not None
    misc[Misc.GUST] = gust_column
    nx, nc, nk = vehicle.A.shape[0], controller_slots[FloatSlot.ADC].shape[0], controller_slots[FloatSlot.AK].shape[0]
    return Packed(
        floats={
            FloatSlot.X: np.zeros(nx), FloatSlot.AD: plant.Ad, FloatSlot.BD: plant.Bd, FloatSlot.C: plant.C, FloatSlot.D: plant.D, FloatSlot.UACT: bank.pos,
            **controller_slots,
            FloatSlot.INTEG: np.zeros(k), FloatSlot.DEMAND: vehicle.demand_map, FloatSlot.BOUND: np.broadcast_to(spec.output_bound, (k,)),
            FloatSlot.DT: np.array(dt), FloatSlot.TFRAME: np.array(tframe),
            FloatSlot.POS: bank.pos, FloatSlot.RATE: bank.rate, FloatSlot.RATE_OUT: np.zeros(m), FloatSlot.WN2: bank.wn2, FloatSlot.C1: bank.c1,
            FloatSlot.LO: bank.lo, FloatSlot.HI: bank.hi, FloatSlot.RMAX: bank.rmax, FloatSlot.JAM_POS: bank.jam_pos,
            FloatSlot.HARD_POS: bank.hard_pos, FloatSlot.DBUF: np.zeros((ring, m)),
            **pilot_floats,
            FloatSlot.Y: np.zeros(ny), FloatSlot.Z: np.zeros(ny), FloatSlot.CMD: np.zeros(k), FloatSlot.R: np.zeros(k),
            FloatSlot.E: np.zeros(k), FloatSlot.UC: np.zeros(k), FloatSlot.V: np.zeros(k), FloatSlot.UDEL: np.zeros(m), FloatSlot.O: np.zeros(3 * k),
            FloatSlot.SCRATCH: np.zeros((2, max(nx, ny, nc, nk, k, *pilot_floats[FloatSlot.PAF].shape, len(pilots)))),
            FloatSlot.QSTEP: np.zeros(ny) if quantisation is None else quantisation,
        },
        ints={
            IntSlot.FIRST: bank.first, IntSlot.JAMMED: bank.jammed, IntSlot.HARDOVER: bank.hardover,
            IntSlot.DN: delay.n, IntSlot.DSTATE: np.array([0, 1]), **pilot_ints,
            IntSlot.MEAS: np.asarray(vehicle.measured), IntSlot.CTRL: np.asarray(vehicle.controlled), IntSlot.MISC: misc,
        },
    )


def _result(
    rec: np.ndarray, cols: dict[str, slice], scenario: str, method: str, vehicle: PlantModel,
    failure: Failure | None, pilots: Sequence[Pilot], *, diverged: bool,
) -> SimResult:
    """SimResult from the record matrix (contiguous copies of its columns)."""

    def column(name: str) -> np.ndarray:
        return np.ascontiguousarray(rec[:, cols[name]])

    extra = {}
    for j, p in enumerate(pilots):
        extra[f"{p.name}_command"] = rec[:, cols["extra"].start + 2 * j].copy()
        extra[f"{p.name}"] = rec[:, cols["extra"].start + 2 * j + 1].copy()
    return SimResult(
        scenario=scenario,
        method=method,
        failure=None if failure is None else failure.name,
        t=rec[:, 0].copy(),
        channels=vehicle.channels,
        reference=column("ref"),
        output=column("out"),
        command=column("cmd"),
        pseudo=column("pseudo"),
        effectors=column("eff"),
        effector_rates=column("rate"),
        effector_names=vehicle.effector_names,
        # Limits as they were at each sample (failures change them).
        effector_limits=(column("lo"), column("hi")),
        rate_limits=(-column("rmax"), column("rmax")),
        failure_time=None if failure is None else failure.time,
        diverged=diverged,
        unallocated=column("unalloc"),
        extra=extra,
    )


def _controller_slots(
    vehicle: PlantModel, controller: SMCDesign | LoopShapedDesign, references: Sequence[TF], dt: float,
    boundary_layer: str = "frame",
) -> dict[int, np.ndarray]:
    """Packed arrays of the controller: the SMC system and gains, or reference models and compensators.

    ``dt`` is the frame period; ``boundary_layer`` the rule of :func:`boundary_layer_at`.
    """
    k = len(vehicle.controlled)
    if isinstance(controller, SMCDesign):
        ctl, n_in = _controller_system(vehicle, controller, references, dt)
        # unused with sign (eps None)
        eps = np.ones(k) if controller.eps is None else boundary_layer_at(controller.eps, dt, boundary_layer)
        return {
            FloatSlot.XC: ctl.x, FloatSlot.ADC: ctl.Ad, FloatSlot.BDC: ctl.Bd, FloatSlot.CC: ctl.C, FloatSlot.W: np.zeros(n_in),
            FloatSlot.XK: np.zeros(0), FloatSlot.AK: np.zeros((0, 0)), FloatSlot.BK: np.zeros((0, k)), FloatSlot.CK: np.zeros((k, 0)),
            FloatSlot.DK: np.zeros((k, k)),
            FloatSlot.K0: controller.K0, FloatSlot.KM1: controller.Km1, FloatSlot.RHO: controller.rho, FloatSlot.EPS: eps,
        }
    ref = DiscreteLTI(*_diagonal_system(references, k), dt=dt)
    comp = DiscreteLTI(*_diagonal_system(controller.compensators, k), dt=dt)
    return {
        FloatSlot.XC: ref.x, FloatSlot.ADC: ref.Ad, FloatSlot.BDC: ref.Bd, FloatSlot.CC: ref.C, FloatSlot.W: np.zeros(0),
        FloatSlot.XK: comp.x, FloatSlot.AK: comp.Ad, FloatSlot.BK: comp.Bd, FloatSlot.CK: comp.C, FloatSlot.DK: comp.D,
        FloatSlot.K0: np.zeros(k), FloatSlot.KM1: np.zeros(k), FloatSlot.RHO: np.zeros(k), FloatSlot.EPS: np.zeros(k),
    }


def _pilot_slots(pilots: Sequence[Pilot], ny: int, dt: float) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Packed arrays of the pilots (float slots, int slots) at the frame period ``dt``.

    Each delay is a DelayLine ring of its own; lead-lag / neuromuscular
    filters are stacked block-diagonally and discretised once (ZOH).
    """
    n = len(pilots)
    length = np.array([int(DelayLine(1, dt, p.delay).n[0]) + 1 for p in pilots], dtype=np.int64)
    if any(p.filtered for p in pilots):
        filt = DiscreteLTI(*_diagonal_system([p.transfer_function() for p in pilots], n), dt=dt)
        pf = (filt.x, filt.Ad, filt.Bd, filt.C, filt.D)
    else:
        pf = (np.zeros(0), np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n)))
    floats = {
        FloatSlot.PROW: np.array([p.row for p in pilots], dtype=float).reshape(n, ny),
        FloatSlot.PGAIN: np.array([p.gain for p in pilots], dtype=float),
        FloatSlot.PATT: np.zeros(n),
        FloatSlot.PBUF: np.zeros((int(length.max(initial=1)), n)),
        FloatSlot.PXF: pf[0], FloatSlot.PAF: pf[1], FloatSlot.PBF: pf[2], FloatSlot.PCF: pf[3],
        FloatSlot.PDF: pf[4], FloatSlot.PERR: np.zeros(2 * n),
    }
    ints = {
        IntSlot.PN: length - 1, IntSlot.PLEN: length, IntSlot.PIDX: np.zeros(n),
        IntSlot.PCHAN: np.array([p.channel for p in pilots]), IntSlot.PINT: np.array([p.integrate for p in pilots]),
    }
    return floats, ints


def _diagonal_system(tfs: Sequence[TF], k: int) -> tuple[np.ndarray, ...]:
    """Stack of SISO transfer functions, ``y[i] = G_i(s) u[i]``."""
    return stack_lti(
        [tf_to_ss(n, d) for n, d in tfs],
        [np.eye(k)[[i]] for i in range(k)],
        [np.eye(k)[:, [i]] for i in range(k)],
        k, k,
    )


def _controller_system(
    vehicle: PlantModel, design: SMCDesign, references: Sequence[TF], dt: float
) -> tuple[DiscreteLTI, int]:
    """Stack reference models, observers and hedge into one discrete LTI.

    Input ``w = [command (k), u_cmd (m), z (nz), u_c (k)]``; output
    ``[r (k), y_hat (k), y_f (k)]``, all strictly proper.
    """
    k = len(vehicle.controlled)
    m = len(vehicle.actuators)
    nz = len(vehicle.measured)
    n_in = k + m + nz + k
    n_out = 3 * k
    systems, ins, outs = [], [], []
    for i, (num, den) in enumerate(references):
        S = np.zeros((1, n_in))
        S[0, i] = 1.0
        P = np.zeros((n_out, 1))
        P[i, 0] = 1.0
        systems.append(tf_to_ss(num, den))
        ins.append(S)
        outs.append(P)
    if design.observer_poles is not None:
        Cz = vehicle.C[list(vehicle.measured)]
        Dz = vehicle.D[list(vehicle.measured)]
        for i, poles in enumerate(design.observer_poles):
            G = observer_gain(vehicle.A, Cz, poles)  # seed section 3.3.2, one observer per channel
            a = vehicle.A - G @ Cz
            b = np.hstack([vehicle.B - G @ Dz, G])
            c = vehicle.C[[vehicle.controlled[i]]]
            S = np.zeros((m + nz, n_in))
            S[:, k : k + m + nz] = np.eye(m + nz)
            P = np.zeros((n_out, 1))
            P[k + i, 0] = 1.0
            systems.append((a, b, c, np.zeros((1, m + nz))))
            ins.append(S)
            outs.append(P)
    if design.hedge_terms:
        a, b, c, d = hedge_system(design.hedge_terms, k, design.hedge_gain)
        S = np.zeros((k, n_in))
        S[:, k + m + nz :] = np.eye(k)
        P = np.zeros((n_out, k))
        P[2 * k :, :] = np.eye(k)
        systems.append((a, b, c, d))
        ins.append(S)
        outs.append(P)
    A, B, C, D = stack_lti(systems, ins, outs, n_in, n_out)
    return DiscreteLTI(A, B, C, D, dt), n_in
