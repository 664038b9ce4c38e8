"""``alloc sim --plant jsbsim:AIRCRAFT``: a JSBSim aircraft flown by :func:`sim.plant_loop.fly_plant`.

The control law is :class:`sim.plants.jsbsim_loop.SMCLoop` (seed section 4.3 on the aircraft's
linearisation, ``stability_margin`` 0.005 1/s, the observers fed the allocator's command as in the
seed), its commands the 1 s + 1 s doublets of :func:`sim.plants.jsbsim_loop.doublets`, one frame per
JSBSim step.  The allocator, the failure injection and the health modes (``blind``, ``told``, ``detected``) are the
plant loop's, the same a RotorPy run flies, so the run returns a :class:`sim.result.SimResult` with the
JSON summary every ``alloc sim`` prints.  ``--health detected`` runs the engine's detector and do-no-harm
monitor on the plant's sensed response (:meth:`sim.plants.jsbsim.JSBSimPlant.sensed`), noise-free.  The vehicle is the aircraft's own file
(:data:`JSBSIM_AIRCRAFT`) unless ``--vehicle`` names another linearisation of the same aircraft.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sim.result import SimResult
from sim.settings import RunSettings, SettingError

__all__ = ["JSBSIM_AIRCRAFT", "SMCController", "aircraft_of", "fly_jsbsim"]

#: the aircraft ``--plant jsbsim:AIRCRAFT`` knows, each with the vehicle file its controller is designed on
JSBSIM_AIRCRAFT = {"f22": Path(__file__).with_name("data") / "f22_jsbsim.toml"}


def aircraft_of(plant: str) -> str:
    """``"f22"`` of ``"jsbsim:f22"``; SettingError naming ``plant`` and the known aircraft otherwise."""
    prefix, _, aircraft = plant.partition(":")
    if prefix != "jsbsim" or aircraft not in JSBSIM_AIRCRAFT:
        known = ", ".join(f"jsbsim:{a}" for a in JSBSIM_AIRCRAFT)
        raise SettingError(f"plant: unknown JSBSim aircraft {plant!r}; known: {known}", field="plant")
    return aircraft


class SMCController:
    """:class:`~sim.plants.jsbsim_loop.SMCLoop`'s law as a controller of :func:`sim.plant_loop.fly_plant`.

    ``commands`` (n_steps + 1, k): the channels' commands per step, in the loop vehicle's channel order.
    """

    def __init__(self, loop: Any, commands: np.ndarray, channels: tuple[str, ...]) -> None:
        self.loop = loop
        self.commands = np.asarray(commands, dtype=float)
        self.channels = tuple(channels)
        self.reset()

    def reset(self) -> None:
        self.loop.reset()
        k = len(self.channels)
        self.reference, self.command, self.pseudo = np.zeros(k), np.zeros(k), np.zeros(k)
        self._y: np.ndarray | None = None
        self._positions: np.ndarray | None = None

    def demand(self, step: int, z: np.ndarray, plant: Any) -> np.ndarray:
        self.command = self.commands[step].copy()
        self._y = z
        self._positions = plant.positions() if self.loop.observer_input == "position" else None
        v = self.loop.demand(z, self.command)
        self.reference, self.pseudo = self.loop.r.copy(), self.loop.u_c.copy()
        return v

    def update(self, u_cmd: np.ndarray, v_achieved: np.ndarray) -> None:
        self.loop.observe(np.asarray(u_cmd, dtype=float), self._y, self._positions)

    def describe(self) -> dict[str, Any]:
        return {"name": "smc", "commands": "doublets (sim.plants.jsbsim_loop.doublets)",
                "observer_input": self.loop.observer_input,
                "source": "sim.plants.jsbsim_loop.SMCLoop: seed section 4.3 on the aircraft's linearisation"}


def fly_jsbsim(source: Any, plant: str, flown: RunSettings, *, progress: bool = False) -> SimResult:
    """Fly ``plant`` (``"jsbsim:f22"``) with the vehicle ``source`` (None: the aircraft's own file)."""
    from alloc import vehicles
    from alloc.registry import DEFAULT_METHOD
    from sim.plant_loop import fly_plant
    from sim.plants.jsbsim_linear import CONTROLLED
    from sim.plants.jsbsim_loop import DESIGN_OPTIONS, OUTPUT_BOUND, SMCLoop, doublets
    from sim.user_vehicle import DEFAULT_DURATION, DEFAULT_FAILURE_TIME, file_units

    aircraft = aircraft_of(plant)
    try:
        from sim.plants.jsbsim import JSBSimPlant
        from sim.plants.jsbsim_model import JSBSIM_DT
    except ImportError as exc:
        raise SettingError(f"plant: jsbsim is not installed ({exc}); pip install 'alloc-toolkit[plants]'",
                           field="plant") from None
    if flown.turbulence != "none":
        raise SettingError("turbulence: --plant jsbsim flies JSBSim's still standard atmosphere (no world wind "
                           "wired into it)", field="turbulence")
    if flown.noise and flown.noise_scale != 1.0:
        raise SettingError("noise_scale: --plant jsbsim flies without sensor noise", field="noise_scale")
    frame = JSBSIM_DT if flown.frame_period is None else float(flown.frame_period)
    the_plant = JSBSimPlant(jsbsim_dt=frame)
    vehicle_source = JSBSIM_AIRCRAFT[aircraft] if source is None else source
    loop = SMCLoop(vehicle_source, T=frame, method=DEFAULT_METHOD if flown.method is None else flown.method)
    fm = loop.fm
    model = loop.fv.model
    assert model is not None  # the F-22 file carries its linear model (SMCLoop designs on it)
    the_plant.free_response = np.asarray(model.arrays()[0], dtype=float)  # the design's model, for sensed()
    duration = DEFAULT_DURATION if flown.duration is None else float(flown.duration)
    method = loop.method
    method_options = vehicles.method_options(fm.source, method, flown.method_options)
    failure = flown.failure
    if isinstance(failure, str):
        failure = fm.failure(failure, DEFAULT_FAILURE_TIME if flown.failure_time is None else flown.failure_time)
    n_steps = round(duration / frame)
    channels = tuple(fm.vehicle.channels)
    t = np.arange(n_steps + 1) * frame
    commands = doublets(t)[:, [CONTROLLED.index(c) for c in channels]]  # doublets are q, p, r
    controller = SMCController(loop, commands, channels)
    outputs = tuple(fm.vehicle.output_names)
    limits = np.array([OUTPUT_BOUND[the_plant.outputs.index(o)] for o in outputs])
    bound = np.array([limits[outputs.index(c)] for c in channels])
    timing: dict[str, float] = {}
    result = fly_plant(
        the_plant, controller, fm.vehicle, method=method, method_options=method_options, duration=duration,
        dt=frame, frame_steps=1, failure=failure, health=flown.health_mode, output_bound=bound,
        output_limits=limits, record_every=1, seed=flown.seed, record_state=("altitude_m", "mach", "qbar_pa", "nz_g"),
        timing=timing, scenario=fm.source.name,
        alloc_options={"rate_aware": flown.rate_aware, "preferred": flown.preferred,
                       "rate_horizon": flown.rate_horizon, "rate_window": flown.rate_window},
        u_prev_source=flown.u_prev_source,
        detection={"noise_scale": flown.noise_scale, "long_window": flown.detector_long_window})
    record = {**flown.record(), **result.settings}
    record.update(duration=duration, method=method, failure=None if failure is None else failure.name,
                  failure_time=None if failure is None else failure.time, frame_period=frame, dt=frame,
                  noise=False, record_every=1, controller="smc", design_options=dict(DESIGN_OPTIONS),
                  units=file_units(fm.source), real_time_factor=timing["simulated_s"] / max(timing["wall_s"], 1e-9),
                  timing=timing)
    result.settings = record
    return result
