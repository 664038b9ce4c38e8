"""The closed loop on any :class:`sim.plant.Plant`, in Python: :func:`fly_plant`.

The compiled engine (:mod:`sim.engine`) integrates the linear model inside its step; this loop asks a
plant object instead, so a third-party simulator (RotorPy, :mod:`sim.plants.rotorpy`) flies the same
controller, allocator and failure injection.  Per integration step ``dt`` (the plant's ``step``)::

    z = y (+ the run's sensor noise)                   divergence check on the controlled outputs
    frame?        -> a detector's belief due: the allocator rebuilt on it (detected)
                     v = controller.demand(...); u_cmd, v_achieved = allocator(v, u_prev, T);
                     controller.update(u_cmd, v_achieved)
    record; y = plant.step(u_cmd, dt)
    failure due next step?  -> plant.fail(...) for each actuator failure; told: the allocator is rebuilt
                     on the failure as the plant executed it (defaults filled in)
    detector sample due?    -> detector and do-no-harm monitor on plant.sensed() (detected)

The order is the engine's (:func:`sim.engine.simulate`): a :class:`sim.plant.LinearPlant` with the
engine's controller (:class:`sim.plant_control.EngineController`) reproduces the engine's run
(``tests/sim/test_plant_loop.py`` states the tolerance).  Health modes: ``blind``, ``told`` and
``detected``: the engine's in-loop detector and do-no-harm monitor (:mod:`sim.detection`, :mod:`sim.harm`)
sample the plant's :meth:`~sim.plant.Plant.sensed` response, in the engine's order, so ``detected`` on a
LinearPlant reproduces the engine's detections too.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from sim.allocation import LoopAllocator, build_allocator
from sim.model import Failure, PlantModel
from sim.result import SimResult
from sim.settings import SettingError

__all__ = ["fly_plant", "PLANT_HEALTH_MODES"]

#: health modes this loop flies
PLANT_HEALTH_MODES = ("blind", "told", "detected")


def fly_plant(
    plant: Any, controller: Any, vehicle: PlantModel, *, method: str, method_options: dict[str, Any] | None = None,
    duration: float, dt: float, frame_steps: int = 1, failure: Failure | None = None, health: str = "blind",
    noise: np.ndarray | None = None, output_bound: float | np.ndarray = 1.0e3, record_every: int = 1,
    alloc_options: dict[str, Any] | None = None, u_prev_source: str = "command", seed: int = 0,
    record_state: tuple[str, ...] = (), scenario: str | None = None, timing: dict[str, float] | None = None,
    output_limits: np.ndarray | None = None, detection: dict[str, Any] | None = None,
    vehicle_at: Any = None,
) -> SimResult:
    """Fly ``controller`` + the allocator of ``method`` against ``plant`` for ``duration`` seconds.

    Parameters
    ----------
    plant : sim.plant.Plant
        Reset with ``seed`` first; stepped ``dt`` at a time.
    controller
        ``channels``, ``reset()``, ``demand(step, z, plant) -> v`` and ``update(u_cmd, v_achieved)``;
        after ``demand`` its ``reference``, ``command`` and ``pseudo`` (length k) are recorded.
    vehicle : sim.model.PlantModel
        The loop's vehicle: the allocator's problem (``B_alloc``, limits as deviations), the
        controlled outputs (``controlled``), the names.
    noise : ndarray (n_steps + 1, ny) or None
        Sensor noise added to the outputs the controller sees.
    output_bound : float or ndarray
        Divergence bound on ``|controlled output|`` (:mod:`sim.result`).
    output_limits : ndarray (ny,) or None
        A further divergence bound on every plant output (a multirotor past 90 deg of bank has lost
        control whatever its rates); None: none.
    record_state : tuple of str
        Keys of ``plant.state()`` recorded into ``result.extra`` at every recorded sample.
    detection : dict or None
        ``health = "detected"``: ``noise_scale``, ``long_window`` (s or None) and ``preferred`` (the
        rule) of the in-loop detector (:class:`sim.detection.InLoopDetector`), which samples the
        plant's :meth:`~sim.plant.Plant.sensed` state derivative.
    timing : dict or None
        Filled with ``wall_s`` (the loop's wall time) and ``plant_s`` (inside ``plant.step``).
    vehicle_at : callable or None
        ``t -> PlantModel``: the allocator is rebuilt every frame on the vehicle at the frame's time (a
        scheduled effectiveness, :mod:`sim.plants.scheduled`), told of the failure as executed when
        ``health`` is ``told``; None: one allocator, rebuilt only at a failure or a belief.
    """
    if vehicle_at is not None and health == "detected":
        raise SettingError("health: a loop whose vehicle moves (vehicle_at) flies blind or told", field="health")
    if health not in PLANT_HEALTH_MODES:
        raise SettingError(f"health: {health!r}; the plant loop flies {', '.join(PLANT_HEALTH_MODES)}",
                           field="health")
    n_steps = int(round(duration / dt))
    frame = int(frame_steps)
    tframe = frame * dt
    t_grid = np.arange(n_steps + 1) * dt
    fail_step = n_steps + 1
    if failure is not None:
        due = np.nonzero(t_grid >= failure.time - 0.5 * dt)[0]
        fail_step = int(due[0]) if due.size else n_steps + 1
        if failure.A is not None or failure.B is not None or failure.D is not None or failure.delay is not None:
            raise SettingError(f"failure: {failure.name!r} changes the model's matrices or delay; a plant takes "
                               "actuator failures only", field="failure")
    options = dict(method_options or {})
    alloc_kw = {"frame_period": tframe, **(alloc_options or {})}
    allocator: LoopAllocator = build_allocator(vehicle, method, options, **alloc_kw)
    k, m = len(vehicle.controlled), len(vehicle.actuators)
    controlled = np.asarray(vehicle.controlled)
    bound = np.broadcast_to(np.asarray(output_bound, dtype=float), (k,))
    n_rec = n_steps // record_every + 1
    rec = {name: np.full((n_rec, width), np.nan) for name, width in
           (("ref", k), ("out", k), ("cmd", k), ("pseudo", k), ("unalloc", k), ("eff", m), ("lo", m), ("hi", m))}
    outputs_rec = np.full((n_rec, len(plant.outputs)), np.nan)
    state_rec = {key: np.full(n_rec, np.nan) for key in record_state}
    call_status = np.full(n_steps // frame + 1, -1, dtype=np.int8)
    y = plant.reset(seed=seed)
    controller.reset()
    u_cmd = np.zeros(m)
    v = np.zeros(k)
    v_achieved = np.zeros(k)
    n_done = n_steps + 1
    plant_time = 0.0
    clock = time.perf_counter
    start = clock()
    watch = None if health != "detected" else _Watch(plant, vehicle, dt, n_steps, noise, alloc_kw, detection)
    told: Failure | None = None  # the failure as executed, once a told allocator has heard of it
    if fail_step == 0:
        allocator, told = _inject(plant, failure, vehicle, method, options, alloc_kw, health, allocator, first_call=0)
    for step in range(n_steps + 1):
        z = y if noise is None else y + noise[step]
        yc = y[controlled]
        if not (np.all(np.isfinite(y)) and np.all(np.abs(yc) <= bound)) or (
                output_limits is not None and np.any(np.abs(y) > output_limits)):
            n_done = step
            break
        if step % frame == 0:
            if watch is not None and watch.due(step):
                allocator = watch.rebuild(step, u_cmd, method, options, first_call=step // frame)
            if vehicle_at is not None:
                allocator = build_allocator(vehicle_at(step * dt), method, options, failure=told,
                                            first_call=step // frame, **alloc_kw)
            v = controller.demand(step, z, plant)
            u_prev = plant.positions() if u_prev_source == "position" else u_cmd
            u_cmd, v_achieved, call_status[step // frame] = allocator(v, u_prev, tframe)
            controller.update(u_cmd, v_achieved)
        if step % record_every == 0:
            row = step // record_every
            rec["ref"][row], rec["out"][row], rec["cmd"][row] = controller.reference, yc, controller.command
            rec["pseudo"][row], rec["unalloc"][row] = controller.pseudo, v - v_achieved
            rec["eff"][row] = plant.positions()
            rec["lo"][row], rec["hi"][row] = plant.limits()
            outputs_rec[row] = y
            if state_rec:
                st = plant.state()
                for key in state_rec:
                    state_rec[key][row] = st[key]
        if step == n_steps:
            break
        t0 = clock()
        y = plant.step(u_cmd, dt)
        plant_time += clock() - t0
        if watch is not None:
            watch.detector.step_model(u_cmd)
        if step == fail_step - 1:  # the engine's order: injected before the next step's outputs are read
            allocator, told = _inject(plant, failure, vehicle, method, options, alloc_kw, health, allocator,
                                      first_call=-(-fail_step // frame))
        if watch is not None and watch.detector.due(step + 1):
            z_next = y if noise is None else y + noise[step + 1]
            watch.sample(step + 1, frame, controller.reference - z_next[controlled],
                         None if failure is None else failure.time)
    if timing is not None:
        timing.update(wall_s=clock() - start, plant_s=plant_time, simulated_s=min(n_done, n_steps) * dt)
    n = (n_done + record_every - 1) // record_every
    t = np.arange(n) * record_every * dt
    effectors = rec["eff"][:n]
    rates = np.zeros_like(effectors)
    if n > 1:
        rates[1:] = np.diff(effectors, axis=0) / (record_every * dt)
    extra = {name: outputs_rec[:n, i].copy() for i, name in enumerate(plant.outputs)}
    extra.update({key: arr[:n].copy() for key, arr in state_rec.items()})
    rmax = np.array([a.rate for a in vehicle.actuators])
    n_calls = (n_done + frame - 1) // frame
    result = SimResult(
        scenario=scenario or vehicle.name, method=method, failure=None if failure is None else failure.name, t=t,
        channels=vehicle.channels, reference=rec["ref"][:n], output=rec["out"][:n], command=rec["cmd"][:n],
        pseudo=rec["pseudo"][:n], effectors=effectors, effector_rates=rates, effector_names=vehicle.effector_names,
        effector_limits=(rec["lo"][:n], rec["hi"][:n]), rate_limits=(-rmax, rmax),
        failure_time=None if failure is None else failure.time, diverged=n_done <= n_steps,
        unallocated=rec["unalloc"][:n], extra=extra,
        allocator_t=np.arange(n_calls) * tframe, allocator_status=call_status[:n_calls].copy(),
    )
    if watch is not None:
        result.detections, result.withdrawals = watch.detections, watch.harm.withdrawals
        result.detector = {**watch.detector.describe(), "do_no_harm": watch.harm.describe()}
    result.settings = {"plant": plant.describe(), "control_law": controller.describe(), "health": health,
                       "allocator_knows_failure": health == "told", "dt": dt, "frame_period": tframe,
                       "method": method, "method_options": options, "seed": seed}
    return result


def _inject(plant: Any, failure: Failure, vehicle: PlantModel, method: str, options: dict[str, Any],
            alloc_kw: dict[str, Any], health: str, allocator: LoopAllocator, *, first_call: int,
            ) -> tuple[LoopAllocator, Failure | None]:
    """Fail the plant's actuators; a told allocator is rebuilt on the failure as the plant executed it
    (returned too: what the allocator was told)."""
    before = len(plant.executed())
    for f in failure.actuators:
        plant.fail(f.index, f.kind, dict(f.params))
    if health != "told":
        return allocator, None
    injected = replace(failure, actuators=tuple(plant.executed()[before:]))
    return build_allocator(vehicle, method, options, failure=injected, first_call=first_call, **alloc_kw), injected


class _Watch:
    """``--health detected`` in the plant loop: the engine's detector and do-no-harm monitor
    (:mod:`sim.detection`, :mod:`sim.harm`), sampling the plant's sensed state derivative."""

    def __init__(self, plant: Any, vehicle: PlantModel, dt: float, n_steps: int, noise: np.ndarray | None,
                 alloc_kw: dict[str, Any], detection: dict[str, Any] | None) -> None:
        from sim.allocation import preferred_positions
        from sim.detection import InLoopDetector, design_with
        from sim.harm import InLoopHarm

        opts = {"noise_scale": 1.0, "long_window": None, **(detection or {})}
        ny = len(vehicle.output_names)
        full = np.zeros((n_steps + 1, ny)) if noise is None else noise
        self.plant, self.vehicle, self.dt, self.alloc_kw = plant, vehicle, dt, alloc_kw
        self.detector = InLoopDetector(vehicle, dt, full, noise_scale=opts["noise_scale"], actuators=True,
                                       preferred=preferred_positions(vehicle, alloc_kw.get("preferred", "mid")),
                                       design=design_with(opts["long_window"]))
        self.harm = InLoopHarm(vehicle, self.detector)
        self.pending: list[tuple[int, dict[str, Any]]] = []
        self.detections: list[dict[str, Any]] = []

    def due(self, step: int) -> bool:
        return bool(self.pending) and step >= self.pending[0][0]

    def rebuild(self, step: int, u_cmd: np.ndarray, method: str, options: dict[str, Any], *,
                first_call: int) -> LoopAllocator:
        """The allocator on the latest belief due by ``step`` (the engine's rebuild)."""
        from sim.allocation import hold_commands

        belief = self.pending[0][1]
        while self.pending and step >= self.pending[0][0]:
            belief = self.pending.pop(0)[1]
        self.harm.apply(belief, u_cmd, step * self.dt)
        return hold_commands(build_allocator(self.vehicle, method, options, health=self.harm.belief,
                                             first_call=first_call, **self.alloc_kw), self.harm.held)

    def sample(self, step: int, frame: int, tracking_error: np.ndarray, failure_time: float | None) -> None:
        """One detector sample at ``step`` and the monitor's verdicts, as the engine takes them."""
        from sim.detection import detection_record

        det, harm = self.detector, self.harm
        at = step + det.delay_steps
        applied = -(-at // frame) * frame * self.dt
        found = det.sample_response(step, self.plant.sensed())
        harm.observe(step * self.dt, tracking_error, det.last_y, det.pos)
        for detection in found:
            self.detections.append(detection_record(detection, applied, failure_time))
            self.detections[-1]["applied"] = harm.detected(self.detections[-1])
            if self.detections[-1]["applied"]:
                self.pending.append((at, det.health))
        withdrawn = harm.verdicts(step * self.dt)
        for w in withdrawn:
            w["applied_time"] = applied
        if withdrawn or harm.released:
            self.pending.append((at, det.health))
