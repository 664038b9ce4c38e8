"""The plants ``alloc sim --plant NAME`` flies, and the runner of a vehicle file on one of them.

``linear`` (the default) is the vehicle's linear model in the compiled engine (:mod:`sim.engine`;
:class:`sim.plant.LinearPlant` is its reference implementation of the contract).  ``rotorpy`` is RotorPy's
nonlinear multirotor (:mod:`sim.plants.rotorpy`, the ``[plants]`` extra), flown by
:func:`sim.plant_loop.fly_plant` with the multirotor cascade (:class:`sim.plant_control.CascadeController`)
holding a level hover at the trim.

A RotorPy run (:func:`fly_on_plant`):

- the flight-control frame is ``frame_period`` (default :data:`ROTORPY_FRAME`, 250 Hz) and the plant
  steps once per frame (RotorPy's RK45 adapts inside the step); ``dt`` is not used;
- the references are a level hover at heading 0 and the trim altitude (no sum-of-sines commands: those are
  the seed's auto-design's, sized for the linear model);
- no sensor noise (the cascade reads RotorPy's state; the engine's noise gains are sized to the sum of
  sines); ``--turbulence light|moderate|severe`` is the world's Dryden turbulence and 1-cosine gust
  (:mod:`sim.world` at the vehicle's flight condition) as RotorPy's wind, translational components only;
- health ``blind``, ``told`` or ``detected`` (the engine's in-loop detector and do-no-harm monitor on
  RotorPy's own state derivative, noise-free, designed for the seed's noise level times ``noise_scale``);
- every frame is recorded; ``result.settings`` records ``dt``, ``record_every`` and ``noise`` as flown
  (the engine's ``dt``, ``record_every``, ``noise`` and ``noise_scale`` do not apply), and the settings
  a plant run cannot fly (``model_error``, ``excitation``, a noise family, the pilot and
  the seed's controllers) are refused naming the setting.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from alloc.exceptions import ProblemError
from sim.plants.rotorpy import DEFAULT_STEP  # rotorpy itself is imported when a plant is built
from sim.result import SimResult
from sim.settings import RunSettings, SettingError

__all__ = ["PLANTS", "DEFAULT_PLANT", "ROTORPY_FRAME", "PlantSpec", "register_plant", "plant_spec", "check_plant",
           "fly_on_plant", "fly_multirotor", "flown_settings", "rotorpy_plant"]

#: ``fly(source, settings, options, *, progress, forward_speed) -> SimResult``: a plant's runner
PlantRunner = Callable[..., SimResult]


@dataclass(frozen=True)
class PlantSpec:
    """A plant ``alloc sim --plant NAME`` flies, with what it can do (read by the CLI, the
    closed-loop benchmark and :func:`fly_on_plant`; nothing branches on a plant's name).

    ``fly`` runs a vehicle on it; ``flies_scenarios``: the seed's scenarios (not only vehicle
    files) fly on it; ``velocity_loop``: it takes ``forward_speed``; ``follows_schedule``: it
    follows a scheduled ``B`` (``--schedule``); ``own_vehicle``: the vehicle file it flies when
    none is named (a third-party aircraft's own linearisation), else None; ``design_options``: the
    section 4.3 design options its aircraft's loop is designed with, else None."""

    name: str
    description: str
    fly: PlantRunner
    flies_scenarios: bool = False
    velocity_loop: bool = False
    follows_schedule: bool = False
    own_vehicle: Callable[[], str] | None = None
    design_options: Callable[[], Any] | None = None


_SPECS: dict[str, PlantSpec] = {}
#: the plants by ``--plant`` name, with what each is (kept by :func:`register_plant`)
PLANTS: dict[str, str] = {}


def register_plant(spec: PlantSpec) -> PlantSpec:
    """Make ``spec`` a plant of ``--plant`` (its name is taken once; ValueError otherwise)."""
    if not isinstance(spec, PlantSpec) or not spec.name or spec.name in _SPECS:
        raise ValueError(f"plant: {getattr(spec, 'name', spec)!r} is not a new PlantSpec")
    _SPECS[spec.name] = spec
    PLANTS[spec.name] = spec.description
    return spec


#: entry-point group of plants a package publishes: loading one registers its plants
ENTRY_POINTS = "alloc.plants"
_plugins_loaded = False


def _load_plugins() -> None:
    """Import the ``alloc.plants`` entry points once (a plant another package registers)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        try:
            ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plug-in is named, the built-in plants still fly
            import warnings

            warnings.warn(f"plant entry point {ep.name!r} ({ep.value}) failed to load: {exc}", stacklevel=2)


def plant_spec(name: Any) -> PlantSpec:
    """The registered plant ``name`` (built in, registered, or published under the
    ``alloc.plants`` entry-point group); SettingError naming ``plant`` and the plants otherwise."""
    if isinstance(name, str) and name not in _SPECS:
        _load_plugins()
    if not isinstance(name, str) or name not in _SPECS:
        raise SettingError(f"plant: unknown plant {name!r}; plants: {', '.join(_SPECS)}", field="plant")
    return _SPECS[name]


DEFAULT_PLANT = "linear"
#: s: the flight-control frame (and plant step) of a RotorPy run unless --frame-rate says otherwise
ROTORPY_FRAME = DEFAULT_STEP
#: divergence bounds on the hover model's outputs (phi, theta, psi, p, q, r, w): past 90 deg of bank or pitch,
#: 20 rad/s of roll or pitch rate, 60 rad/s of yaw rate or 20 m/s of heave the vehicle has lost control
HOVER_LIMITS = {"phi": np.pi / 2, "theta": np.pi / 2, "psi": np.inf, "p": 20.0, "q": 20.0, "r": 60.0,
                "u": np.inf, "v": np.inf, "w": 20.0}

def check_plant(name: Any) -> str:
    """``name`` if it is a plant (:data:`PLANTS`); SettingError naming ``plant`` otherwise."""
    return plant_spec(name).name


def rotorpy_plant(fm: Any, *, dt_step: float, wind: np.ndarray | None = None) -> Any:
    """The :class:`sim.plants.rotorpy.RotorPyPlant` of a flight model; SettingError naming ``plant`` when the
    package is missing, ProblemError naming the vehicle's field it cannot fly."""
    from sim.plants.rotorpy import RotorPyPlant

    try:
        import rotorpy  # noqa: F401 (the [plants] extra)
    except ImportError as exc:
        raise SettingError(f"plant: rotorpy is not installed ({exc}); pip install 'alloc-toolkit[plants]'",
                           field="plant") from None
    return RotorPyPlant(fm.source, fm.vehicle, fm.trim_u, dt_step=dt_step, wind=wind)


def fly_on_plant(source: Any, plant: str, settings: RunSettings | None = None, *, progress: bool = False,
                 forward_speed: float | None = None, **options: Any) -> SimResult:
    """Fly vehicle ``source`` (a file, a catalogue name or a vehicle) on ``plant`` (module docstring).

    ``forward_speed`` (plants with a velocity loop, RotorPy's): m/s due north, held by the cascade's
    velocity loop (:class:`sim.plant_control.VelocityHold`, its ramp and gains) from the hover on; 0 holds
    the hover's zero ground speed; None (default) flies the cascade without a velocity loop (a level hover
    that drifts).  ``plant = "jsbsim:AIRCRAFT"`` flies :func:`sim.plants.jsbsim_run.fly_jsbsim`; ``source``
    None is then the aircraft's own vehicle file.

    ``settings`` / ``options``: :class:`sim.settings.RunSettings` (method, failure, failure_time, duration,
    health, frame_period, turbulence, seed ...).  ``result.settings["plant"]`` is the plant's ``describe()``.
    """
    spec = plant_spec(plant)
    if forward_speed is not None and not spec.velocity_loop:
        takes = ", ".join(f"--plant {n}" for n, s in _SPECS.items() if s.velocity_loop)
        raise SettingError(f"forward_speed: --plant {plant} flies no velocity loop; --forward-speed is for "
                           f"{takes}", field="forward_speed")
    return spec.fly(source, settings, options, progress=progress, forward_speed=forward_speed)


def _fly_linear(source: Any, settings: RunSettings | None, options: dict[str, Any], *, progress: bool = False,
                forward_speed: float | None = None) -> SimResult:
    from sim.user_vehicle import fly

    result = fly(source, settings, progress=progress, **options)
    result.settings["plant"] = {"name": "linear", "source": PLANTS["linear"]}
    return result


def _fly_jsbsim_f22(source: Any, settings: RunSettings | None, options: dict[str, Any], *, progress: bool = False,
                    forward_speed: float | None = None) -> SimResult:
    from sim.plants.jsbsim_run import fly_jsbsim

    return fly_jsbsim(source, "jsbsim:f22", flown_settings(settings, options, "--plant jsbsim:f22"),
                      progress=progress)


def _f22_design() -> Any:
    from sim.plants.jsbsim_loop import DESIGN_OPTIONS

    return DESIGN_OPTIONS


def _f22_file() -> str:
    from sim.plants.jsbsim_run import JSBSIM_AIRCRAFT

    return str(JSBSIM_AIRCRAFT["f22"])


def fly_multirotor(name: str, make_plant: Callable[..., Any]) -> PlantRunner:
    """The runner of a multirotor plant: ``make_plant(fm, dt_step=, wind=)`` builds the
    :class:`sim.plant.Plant` of a flight model (its ``motor_time_constant``, s, sets the cascade's
    gains; its ``recorded_state``, names of :meth:`~sim.plant.Plant.state`, go into ``result.extra``), flown by :func:`sim.plant_loop.fly_plant` with the multirotor cascade holding a level
    hover at the trim (module docstring; RotorPy's runner, and any other multirotor physics')."""

    def fly(source: Any, settings: RunSettings | None, options: dict[str, Any], *, progress: bool = False,
            forward_speed: float | None = None) -> SimResult:
        return _fly_multirotor(name, make_plant, source, settings, options, progress=progress,
                               forward_speed=forward_speed)

    return fly


def _fly_multirotor(plant: str, make_plant: Callable[..., Any], source: Any, settings: RunSettings | None,
                    options: dict[str, Any], *, progress: bool = False,
                    forward_speed: float | None = None) -> SimResult:
    from alloc import vehicles
    from alloc.registry import DEFAULT_METHOD
    from sim.plant_control import CascadeController, CascadeGains, VelocityHold
    from sim.plant_loop import fly_plant
    from sim.user_vehicle import DEFAULT_DURATION, DEFAULT_FAILURE_TIME, flight_model

    flown = flown_settings(settings, options, f"--plant {plant}")
    fv = vehicles.get_vehicle(source)
    if fv.simulation is not None:
        raise SettingError(f"plant: {fv.name!r} flies its own [simulation] design on its linear model; "
                           f"--plant {plant} flies multirotors with a [body]", field="plant")
    if fv.model is None:
        raise SettingError(f"plant: {fv.name!r} has no [model] and no [body]; --plant {plant} needs a [body]",
                           field="plant")
    _refuse_unflown(flown)
    fm = flight_model(fv)
    frame = ROTORPY_FRAME if flown.frame_period is None else float(flown.frame_period)
    duration = DEFAULT_DURATION if flown.duration is None else float(flown.duration)
    method = DEFAULT_METHOD if flown.method is None else flown.method
    method_options = vehicles.method_options(fm.source, method, flown.method_options)
    failure = flown.failure
    if isinstance(failure, str):
        failure = fm.failure(failure, DEFAULT_FAILURE_TIME if flown.failure_time is None else flown.failure_time)
    n_steps = int(round(duration / frame))
    wind, world = _wind(fm, flown, n_steps + 1, frame)
    the_plant = make_plant(fm, dt_step=frame, wind=wind)
    tau = float(the_plant.motor_time_constant)
    velocity = None if forward_speed is None else VelocityHold(speed=_speed(forward_speed))
    controller = CascadeController(fv, fm.vehicle, CascadeGains.for_motor_lag(tau), frame, velocity=velocity)
    limits = np.array([HOVER_LIMITS.get(o, np.inf) for o in fm.vehicle.output_names])
    bound = np.array([HOVER_LIMITS[c] for c in fm.vehicle.channels])
    timing: dict[str, float] = {}
    result = fly_plant(
        the_plant, controller, fm.vehicle, method=method, method_options=method_options, duration=duration,
        dt=frame, frame_steps=1, failure=failure, health=flown.health_mode, output_bound=bound,
        output_limits=limits, record_every=1, seed=flown.seed, record_state=tuple(getattr(the_plant, "recorded_state", ())), timing=timing,
        alloc_options=dict(rate_aware=flown.rate_aware, preferred=flown.preferred, rate_horizon=flown.rate_horizon,
                           rate_window=flown.rate_window),
        u_prev_source=flown.u_prev_source, scenario=fv.name,
        detection=dict(noise_scale=flown.noise_scale, long_window=flown.detector_long_window))
    setpoints = np.array(controller.setpoints[:len(result.t)]).reshape(-1, 3)
    result.extra.update(phi_setpoint=setpoints[:, 0], theta_setpoint=setpoints[:, 1], v_north_ref=setpoints[:, 2])
    record = {**flown.record(), **result.settings}
    record.update(duration=duration, method=method, failure=None if failure is None else failure.name,
                  failure_time=None if failure is None else failure.time, frame_period=frame, dt=frame,
                  noise=False, record_every=1, controller="cascade", forward_speed=forward_speed, units=_units(fm), trim_u=fm.trim_u.tolist(),
                  real_time_factor=timing["simulated_s"] / max(timing["wall_s"], 1e-9), timing=timing)
    if world is not None:
        record["world"] = world
    result.settings = record
    return result


#: m/s: the largest --forward-speed (a multirotor past it needs a tilt the velocity loop does not ask for)
MAX_FORWARD_SPEED = 20.0


def _speed(value: Any) -> float:
    """``--forward-speed`` checked: a finite number of m/s within +-:data:`MAX_FORWARD_SPEED`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_FORWARD_SPEED:
        raise SettingError(f"forward_speed: expected m/s within +-{MAX_FORWARD_SPEED:g}, got {value!r}",
                           field="forward_speed")
    return float(value)


def flown_settings(settings: RunSettings | None, options: dict[str, Any], run: str) -> RunSettings:
    """The run settings of a ``run`` (``"--plant rotorpy"``) from ``settings`` and keyword ``options``;
    TypeError naming a stray option."""
    given, extra = RunSettings.split(options)
    if extra:
        raise TypeError(f"{min(extra)}: not a run setting of a {run} run")
    return given if settings is None else replace(settings, **options)


def _refuse_unflown(flown: RunSettings) -> None:
    """Settings a plant run does not fly: refused by name rather than ignored."""
    for name, default in (("model_error", 0.0), ("excitation", 0.0), ("noise_model", "gaussian")):
        if getattr(flown, name) != default:
            raise SettingError(f"{name}: a --plant other than linear does not fly it (the plant is not the model "
                               "already; no excitation or noise families in the plant loop)", field=name)
    if flown.controller != "smc" or flown.pilot != "standin" or flown.pilot_gain is not None or \
            flown.pilot_delay is not None:
        raise SettingError("controller: a --plant other than linear flies the multirotor cascade "
                           "(sim.plant_control), no pilot", field="controller")


def _wind(fm: Any, flown: RunSettings, n: int, dt: float) -> tuple[np.ndarray | None, dict[str, Any] | None]:
    """World wind (n, 3), m/s north-east-down, of ``--turbulence`` at the vehicle's flight condition."""
    if flown.turbulence == "none":
        return None, None
    from sim.world import FEET, dryden, gust_series

    flight = fm.vehicle.flight
    if flight is None:
        raise ProblemError(f"turbulence: vehicle {fm.vehicle.name!r} states no flight condition", field="turbulence")
    d = dryden(flown.turbulence, flight)
    g = gust_series(d, n, dt, flown.seed)
    wind = g[:, :3] * FEET  # u along north (the mean wind's direction), v east, w down
    return wind, {"turbulence": d.record(), "components": ["north", "east", "down"], "unit": "m/s",
                  "std": wind.std(axis=0).tolist(), "rotational_gusts": "not applied (RotorPy's wind is a velocity)"}


def _units(fm: Any) -> dict[str, Any]:
    from sim.user_vehicle import file_units

    return file_units(fm.source)


register_plant(PlantSpec("linear", "the vehicle's linear model in the compiled engine (sim.engine)", _fly_linear,
                         flies_scenarios=True, follows_schedule=True))
register_plant(PlantSpec("rotorpy", "RotorPy's nonlinear multirotor (rotorpy 3.0.0, the [plants] extra), any rotor "
                         "count", fly_multirotor("rotorpy", rotorpy_plant), velocity_loop=True))
register_plant(PlantSpec("jsbsim:f22", "JSBSim's F-22 (jsbsim 1.3.3, the [plants] extra), pass-through flight "
                         "control, M0.7 at 20,000 ft", _fly_jsbsim_f22, own_vehicle=_f22_file,
                         design_options=_f22_design))
