"""A closed-loop run's settings, defined once: :class:`RunSettings`, and :class:`LoopSpec`.

Every setting is one field of a frozen dataclass with its type, its default and a
:class:`Setting` (help text, unit, allowed values or range, command-line flag, and whether it
is a verdict-driving choice).  Everything else is derived from these fields:

* the ``alloc sim`` options, their help and the reproducible command line (:mod:`sim.cli`);
* validation: a bad value raises :class:`SettingError` naming the field;
* the keyword arguments of :func:`sim.scenarios.mimo.run_mimo` (its signature) and what it
  forwards to the engine (the :class:`LoopSettings` part of :class:`LoopSpec`);
* the recorded ``SimResult.settings`` (:meth:`LoopSettings.record`), from which
  :meth:`RunSettings.from_record` rebuilds the run's settings.

:class:`LoopSettings` holds what the engine itself reads; :class:`RunSettings` adds what a
scenario runner resolves into objects (method, failure, duration, controller, pilot);
:class:`LoopSpec` adds the objects themselves.  The rules of the SMC at a frame period
(:func:`anti_windup_on`, :func:`boundary_layer_at`) live here with the names they accept.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import cache
from typing import Any, Union, get_args, get_origin, get_type_hints

import numpy as np

from alloc.exceptions import AllocError
from sim.allocation import PREFERRED_POSITIONS, RATE_HORIZONS, RATE_WINDOWS
from sim.blocks import DEFAULT_DT
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.pilot import PILOT_MODELS
from sim.world import MAX_MODEL_ERROR, TURBULENCE_LEVELS, parse_noise

#: ``--detector-model`` choices (sim.detection)
DETECTOR_MODELS = ("exact", "learnt")

__all__ = ["Setting", "SettingError", "SettingTypeError", "LoopSettings", "RunSettings", "LoopSpec",
           "setting_of", "value_types", "check_setting", "U_PREV_SOURCES", "BOUNDARY_LAYER_RULES", "ANTI_WINDUP_RULES",
           "CONTROLLERS", "HEALTH_MODES", "MAX_EXCITATION", "MAX_NOISE_SCALE", "SEED_FRAME_PERIOD", "MAX_DURATION", "MAX_PILOT_DELAY", "MAX_DT", "MAX_RECORD_EVERY",
           "anti_windup_on", "boundary_layer_at"]

#: ``u_prev`` the allocator may be told (see :class:`LoopSettings`).
U_PREV_SOURCES = ("command", "position")
#: Where the allocator's effector health comes from: never told (blind), told each failure as
#: it is injected (told, the oracle), or only from the in-loop detector (:mod:`sim.detection`).
HEALTH_MODES = ("blind", "told", "detected")
#: Largest sensor-noise scale (50 times the seed's).
MAX_NOISE_SCALE = 50.0
#: s: the longest second detector window a run may ask for (its buffers hold twice it)
MAX_LONG_WINDOW = 60.0
#: deg: the largest null-space excitation a run may add (a tenth of a 180 deg range would already be flight-visible)
MAX_EXCITATION = 20.0
#: Rules for the SMC boundary layer at a frame period ``T`` (see :func:`boundary_layer_at`).
BOUNDARY_LAYER_RULES = ("frame", "fixed")
#: Rules for the SMC's integral term when the allocator falls short (see :func:`anti_windup_on`).
ANTI_WINDUP_RULES = ("auto", "on", "off")
#: Controllers of the MIMO scenarios: the seed's observer-based SMC, or its loop-shaped baseline.
CONTROLLERS = ("smc", "loopshape")
#: Longest run (simulated seconds): 90 times the seed's longest; the 2 kHz loop records 200 rows/s.
MAX_DURATION = 3600.0
#: Longest pilot time delay (s), far beyond the seed's 0.2-0.3 s.
MAX_PILOT_DELAY = 10.0
#: Longest integration step (s), 10 times the seed's.  Measured (nominal, no noise, 10 s): ICE and
#: both HARV scenarios stay bounded at 5 ms, lat-dir's tracking error twice the seed step's.
MAX_DT = 0.005
#: Sparsest recording: one sample in this many integration steps.
MAX_RECORD_EVERY = 100_000
#: The metadata key of a field's :class:`Setting`.
SETTING = "setting"


class SettingError(AllocError, ValueError):
    """A run setting has a value outside its allowed values or range (``.field`` names it)."""


class SettingTypeError(SettingError, TypeError):
    """A run setting has a value of the wrong type (``.field`` names it)."""


@dataclass(frozen=True)
class Setting:
    """What one run setting is, besides its type and default (the field's own).

    Attributes
    ----------
    help : str
        One line for ``alloc sim --help`` and the docs' settings table.
    unit : str
        Unit of the value (``"s"``), empty for none.
    choices : tuple of str
        The allowed values of a text setting (empty: any text, checked where it is used).
    low, high, low_open, high_open
        The allowed range of a number (None: unbounded), open at an end on request.
    flag : str
        The ``alloc sim`` option; ``"--on/--off"`` for a bool.
    aliases : tuple of str
        Further names of the option.
    per_second : bool
        The option takes ``1 / value`` (a rate in Hz for a period in s).
    verdict : bool
        A verdict-driving choice: a choice of the experiment that can change whether a run
        stays bounded or which method does better, so a comparison holds it fixed or names it.
        False for bookkeeping (how often to record) and for the noise seed (a sample; results
        are compared over seeds).
    none_means : str
        What ``None`` stands for, in words (``"the scenario's"``).
    """

    help: str
    unit: str = ""
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    flag: str = ""
    aliases: tuple[str, ...] = ()
    per_second: bool = False
    verdict: bool = True
    none_means: str = ""

    def range_text(self) -> str:
        """The range in words (``"> 0 and <= 3600 s"``), empty when unbounded."""
        lo = "" if self.low is None else f"{'>' if self.low_open else '>='} {_number(self.low)}"
        hi = "" if self.high is None else f"{'<' if self.high_open else '<='} {_number(self.high)}"
        text = " and ".join(filter(None, [lo, hi]))
        return f"{text} {self.unit}".rstrip() if text else ""


def _number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) >= 1e6 else f"{x:g}"


def _setting(default: Any, help: str, **meta: Any) -> Any:
    return field(default=default, metadata={SETTING: Setting(help=help, **meta)})


def _kind(hint: Any) -> tuple[tuple[type, ...], bool]:
    """The value types a type hint allows (bool, int, float, str, Mapping, Failure) and whether None is one."""
    args = get_args(hint) if get_origin(hint) in (Union, type(int | None)) else (hint,)
    optional = type(None) in args
    kinds = tuple(get_origin(a) or a for a in args if a is not type(None))
    return tuple(Mapping if k is dict else k for k in kinds), optional


def _checked(name: str, value: Any, kinds: tuple[type, ...], optional: bool, spec: Setting) -> Any:
    """``value`` as the setting holds it (a bool, an int, a float ...), or :class:`SettingError`."""
    if value is None:
        if optional:
            return None
        raise SettingTypeError(f"{name}: None; expected {' or '.join(k.__name__ for k in kinds)}", field=name)
    if bool in kinds:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
    elif int in kinds and float not in kinds:
        if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
            return _in_range(name, int(value), spec)
    elif float in kinds:
        if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_)):
            if not math.isfinite(value):
                raise SettingError(f"{name}: {value!r} is not a finite number", field=name)
            return _in_range(name, float(value), spec)
    elif str in kinds and isinstance(value, str):
        if spec.choices and value not in spec.choices:
            raise SettingError(f"{name}: {value!r}; expected one of {spec.choices}", field=name)
        return value
    elif any(isinstance(value, k) for k in kinds):
        return value
    expected = " or ".join(k.__name__ for k in kinds) + (" or None" if optional else "")
    raise SettingTypeError(f"{name}: {value!r} ({type(value).__name__}); expected {expected}", field=name)


def _in_range(name: str, value: float, spec: Setting) -> Any:
    below = spec.low is not None and (value <= spec.low if spec.low_open else value < spec.low)
    above = spec.high is not None and (value >= spec.high if spec.high_open else value > spec.high)
    if below or above:
        raise SettingError(f"{name}: {value!r} is out of range; it must be {spec.range_text()}", field=name)
    return value


@dataclass(frozen=True, kw_only=True)
class LoopSettings:
    """The settings the engine (:func:`sim.engine.simulate`) reads, each with its :class:`Setting`.

    Constructing one checks every field (:class:`SettingError` names the first bad one) and
    that ``frame_period`` is a multiple of ``dt``.
    """

    dt: float = _setting(DEFAULT_DT, "integration step of plant and actuators (the seed's 0.5 ms)", unit="s",
                         low=0.0, low_open=True, high=MAX_DT, flag="--dt")
    seed: int = _setting(0, "noise seed", low=0, high=2**32 - 1, flag="--seed", verdict=False)
    noise: bool = _setting(True, "band-limited sensor noise on the measured outputs (seed gains)",
                           flag="--noise/--no-noise")
    noise_scale: float = _setting(1.0, "sensor noise as a multiple of the seed's (its gains times this)", low=0.0,
                                  high=MAX_NOISE_SCALE, flag="--noise-scale")
    actuators: bool = _setting(True, "actuator dynamics; off: ideal effectors (command = position, limits kept; "
                               "the seed's SMC without parasitic dynamics)", flag="--actuators/--ideal-actuators")
    frame_period: float | None = _setting(
        None, "period T of the flight-control computer (pilot sampling, controller, allocator), a multiple of dt",
        unit="s", low=0.0, low_open=True, flag="--frame-rate", per_second=True,
        none_means="dt (2000 Hz, the seed's single-rate loop)")
    detector_long_window: float | None = _setting(
        None, "the in-loop detector's second stage-1 window (--health detected), for small, lasting "
        "changes such as a loss of a quarter of an effector's effectiveness; it shares the false-alarm "
        "budget (sim.detection.DetectionDesign); 0: none, the 0.4 s window alone", unit="s", low=0.0,
        high=MAX_LONG_WINDOW, flag="--detector-long-window",
        none_means="the design's (sim.detection.DEFAULT_DESIGN.long_window)")
    detector_model: str = _setting(
        "exact", "what the in-loop detector (--health detected) judges residuals against: the stated model and "
        "noise taken as exact, or a nominal model learnt in flight from a stated 20 % model uncertainty, with a "
        "learnt noise scale and correlation and Huber-clipped residuals (alloc.estimation.robust; far fewer "
        "false detections under model error, turbulence and heavy tails, weaker in the first seconds of flight)",
        choices=DETECTOR_MODELS, flag="--detector-model")
    excitation: float = _setting(0.0, "null-space excitation added to every command (seed 1.3.2.5): each "
                                 "effector's multisine peak, B e = 0, within position and rate limits "
                                 "(sim.allocation.EXCITATION_BAND); 0: none", unit="deg", low=0.0,
                                 high=MAX_EXCITATION, flag="--excitation")
    rate_aware: bool = _setting(True, "the allocator gets u_prev and dt = T (seed Eq 1.28)",
                                flag="--rate-aware/--rate-blind")
    rate_window: str = _setting("binding", "when the allocator is given the Eq 1.28 box: only where its answer "
                                "breaks a rate limit, or always", choices=RATE_WINDOWS, flag="--rate-window")
    rate_horizon: str = _setting("actuator", "horizon of the Eq 1.28 rate box: the actuator's lag or one frame",
                                 choices=RATE_HORIZONS, flag="--rate-horizon")
    u_prev_source: str = _setting("command", "what the allocator is told as u_prev: its own previous command "
                                  "(the seed's) or the measured actuator positions", choices=U_PREV_SOURCES,
                                  flag="--u-prev")
    preferred: str = _setting("mid", "preferred position of one-sided effectors: mid-range, or zero (seed up = 0)",
                              choices=PREFERRED_POSITIONS, flag="--preferred")
    anti_windup: str = _setting("auto", "hold the SMC integral in frames the allocator falls short: on, off, or "
                                "auto (on slower than the seed's 2 kHz)", choices=ANTI_WINDUP_RULES,
                                flag="--anti-windup")
    boundary_layer: str = _setting("frame", "SMC boundary layer at the frame rate: eps * max(1, T / 0.5 ms), or "
                                   "the seed's eps fixed", choices=BOUNDARY_LAYER_RULES, flag="--boundary-layer")
    allocator_knows_failure: bool = _setting(False, "tell the allocator the failed effectors' new limits (told) "
                                             "or not (blind)", flag="--told/--blind",
                                             aliases=("--allocator-knows-failure",))
    health: str | None = _setting(None, "where the allocator's effector health comes from: blind (never told), "
                                  "told (each failure as injected: the oracle) or detected (only the in-loop "
                                  "detector on the simulated sensors, sim.detection); --told/--blind are its "
                                  "aliases", choices=HEALTH_MODES, flag="--health",
                                  none_means="told with --told, else blind")
    method_options: dict[str, Any] | None = _setting(
        None, "method options key=value (value parsed as JSON, else text; see `alloc methods`), over the "
        "vehicle file's methods.METHOD defaults; repeatable", flag="--option", aliases=("-o",),
        none_means="the vehicle's defaults")
    model_error: float = _setting(
        0.0, "plant not the model (sim.world): each effector's B and D columns (a failure's too) times a seeded "
        "U[1-F, 1+F] factor, each actuator's bandwidth times another; controller, allocator and detector keep the "
        "nominal model; 0: the plant is the model", low=0.0, high=MAX_MODEL_ERROR, flag="--model-error")
    noise_model: str = _setting(
        "gaussian", "sensor-noise families, '+'-combined, family[:parameter] (sim.world): gaussian (the seed's); "
        "student-t[:NU=4] (same spectrum and std, Student-t marginals through a Gaussian copula, Grigoriu 1984); "
        "coloured[:TAU=0.5 s] (Gauss-Markov driver, same std; also colored); bias[:B=1] (constant N(0, (B s)^2) "
        "plus a random walk of B s per minute); quantised[:Q=0.5] (measured outputs rounded to Q s); s: the "
        "output's noise std; the detector is told the seed's noise", flag="--noise-model")
    turbulence: str = _setting(
        "none", "Dryden turbulence and one 1-cosine gust at 10 s, MIL-F-8785C 3.7.1-3.7.2 at the scenario's flight "
        "condition (low altitude: sigma_w = 0.1 W20, W20 = 15/30/45 kn; above 2000 ft: the 1e-2/1e-3/1e-5 "
        "exceedance sigma, L = 1750 ft); the air-relative states see it (sim.world)",
        choices=TURBULENCE_LEVELS, flag="--turbulence")
    record_every: int = _setting(10, "record every n-th integration step", low=1, high=MAX_RECORD_EVERY,
                                 flag="--record-every", verdict=False)

    def __post_init__(self) -> None:
        for f in fields(LoopSettings):
            object.__setattr__(self, f.name, check_setting(f.name, getattr(self, f.name)))
        self._resolve_health()
        self.frame_steps()
        self.noise_terms()

    def noise_terms(self) -> tuple[Any, ...]:
        """The families of ``noise_model`` (:func:`sim.world.parse_noise`; SettingError naming it if bad)."""
        try:
            return parse_noise(self.noise_model)
        except ValueError as exc:
            raise SettingError(f"noise_model: {exc}", field="noise_model") from None

    @property
    def worldly(self) -> bool:
        """Whether any world setting differs from its default (the plant is not the model)."""
        return bool(self.model_error) or self.turbulence != "none" or \
            any(t.family != "gaussian" for t in self.noise_terms())

    def _resolve_health(self) -> None:
        """``health`` and ``allocator_knows_failure`` are one choice: either may be given, they must agree."""
        if self.allocator_knows_failure and self.health not in (None, "told"):
            raise SettingError(f"health: {self.health!r} contradicts allocator_knows_failure = True (--told); "
                               "give one of them", field="health")

    @property
    def health_mode(self) -> str:
        """``health`` as flown: the field, else ``told`` with ``allocator_knows_failure``, else ``blind``."""
        if self.health is not None:
            return self.health
        return "told" if self.allocator_knows_failure else "blind"

    def frame_steps(self) -> int:
        """Integration steps per flight-control frame (``T / dt``, an integer >= 1)."""
        if self.frame_period is None:
            return 1
        ratio = self.frame_period / self.dt
        n = int(round(ratio))
        if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
            raise SettingError(f"frame_period: {self.frame_period!r} s is not a positive multiple of "
                               f"dt = {self.dt!r} s", field="frame_period")
        return n

    def loop_settings(self) -> dict[str, Any]:
        """The :class:`LoopSettings` fields by name (what a runner forwards to :class:`LoopSpec`)."""
        return {f.name: getattr(self, f.name) for f in fields(LoopSettings)}

    def record(self) -> dict[str, Any]:
        """This run's settings, JSON-ready, as ``SimResult.settings`` records them.

        ``frame_period`` is recorded as the period flown (``dt`` when None);
        ``health`` and ``allocator_knows_failure`` are recorded as flown (:attr:`health_mode`).
        """
        out = {name: _jsonable(getattr(self, name)) for name in self._recorded()}
        if "frame_period" in out:
            out["frame_period"] = self.frame_steps() * self.dt
        out["health"] = self.health_mode
        out["allocator_knows_failure"] = self.health_mode == "told"
        return out

    def _recorded(self) -> list[str]:
        return [f.name for f in fields(LoopSettings)]


@dataclass(frozen=True, kw_only=True)
class RunSettings(LoopSettings):
    """Every setting of a MIMO scenario run (:func:`sim.scenarios.mimo.run_mimo`).

    The :class:`LoopSettings` fields plus what the runner resolves into objects: the method
    (None: the scenario's), the failure by name (or a :class:`sim.model.Failure`), its time,
    the duration, the controller and the pilot model.
    """

    method: str | None = _setting(None, "allocation method (see `alloc methods`) or 'static', the seed's printed "
                                  "distribution", flag="--method",
                                  none_means="the scenario's (the seed's: pinv for ice, ganging for the HARV)")
    failure: str | Failure | None = _setting(None, "failure injected: the scenario's own (seed, failure1), a catalogue "
                                             "name (jam1, effectiveness2, ...) or kind:effector@values text "
                                             "(jam:elevon_l@5, several joined by '+'), see --list; 'none' on the "
                                             "command line for a nominal run", flag="--failure", none_means="the scenario's own "
                                             "(harv_latdir_failure2: failure2), else none")
    failure_time: float | None = _setting(None, "failure time, before the end of the run", unit="s", low=0.0,
                                          flag="--failure-time", none_means="the seed's")
    duration: float | None = _setting(None, "simulated seconds", unit="s", low=0.0, low_open=True,
                                      high=MAX_DURATION, flag="--duration",
                                      none_means="the scenario's (ice 40 s)")
    controller: str = _setting("smc", "the seed's observer-based SMC with hedging, or its loop-shaped baseline "
                               "(the pendulum scenario takes 'smc' or 'lqr')", choices=CONTROLLERS,
                               flag="--controller")
    pilot: str = _setting("standin", "pilot model (sim.pilot): the stand-in gain and delay, McRuer's crossover "
                          "rule at a 45 deg phase margin, or crossover_wc (crossover at a stated frequency)", choices=PILOT_MODELS, flag="--pilot")
    pilot_gain: float | None = _setting(None, "the pilot's gain, over the model's", low=0.0, flag="--pilot-gain",
                                        none_means="the pilot model's")
    pilot_delay: float | None = _setting(None, "the pilot's time delay, over the model's", unit="s", low=0.0,
                                         high=MAX_PILOT_DELAY, flag="--pilot-delay", none_means="the pilot model's")

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in _own_fields():
            object.__setattr__(self, name, check_setting(name, getattr(self, name)))

    def _recorded(self) -> list[str]:
        return [f.name for f in fields(RunSettings)]

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> RunSettings:
        """The settings a recorded ``SimResult.settings`` was flown with (keys of no field are ignored)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in record.items() if k in names})

    @classmethod
    def split(cls, options: Mapping[str, Any]) -> tuple[RunSettings, dict[str, Any]]:
        """``(RunSettings of the setting keywords, the other keywords)``."""
        names = {f.name for f in fields(cls)}
        return (cls(**{k: v for k, v in options.items() if k in names}),
                {k: v for k, v in options.items() if k not in names})


@cache
def _own_fields() -> tuple[str, ...]:
    loop = {f.name for f in fields(LoopSettings)}
    return tuple(f.name for f in fields(RunSettings) if f.name not in loop)


@cache
def _hints() -> dict[str, tuple[tuple[type, ...], bool]]:
    return {name: _kind(hint) for name, hint in get_type_hints(RunSettings).items()}


def value_types(name: str) -> tuple[tuple[type, ...], bool]:
    """The value types setting ``name`` takes (bool, int, float, str, Mapping, Failure) and whether None is one."""
    return _hints()[name]


def setting_of(name: str) -> Setting:
    """The :class:`Setting` of the :class:`RunSettings` field ``name`` (KeyError: no such setting)."""
    return {f.name: f.metadata[SETTING] for f in fields(RunSettings)}[name]


def check_setting(name: str, value: Any) -> Any:
    """``value`` checked against setting ``name``'s type, choices and range (:class:`SettingError` if not)."""
    kinds, optional = _hints()[name]
    return _checked(name, value, kinds, optional, setting_of(name))


def _jsonable(value: Any) -> Any:
    if isinstance(value, Failure):
        return value.name
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass(frozen=True, kw_only=True)
class LoopSpec(LoopSettings):
    """Everything one closed-loop run needs (the argument of :func:`sim.engine.simulate`).

    The :class:`LoopSettings` fields (checked on construction) plus:

    Attributes
    ----------
    scenario : str
        Name recorded in the result.
    vehicle, references, controller, pilots, failure
        The vehicle, the reference models (one transfer function per channel),
        the SMC or loop-shaped design, the pilot models and the failure (or None).
    commands : ndarray (N, k)
        Direct commands into the reference models for channels without a
        pilot (precomputed on the integration grid); pilot channels overwrite
        their column.
    method : str
        Allocation method (any registry method, or ``static``).
    duration : float
        Simulated seconds (the range of :attr:`RunSettings.duration`).
    output_bound : float or ndarray
        Divergence bound on ``|controlled output|`` (see :mod:`sim.result`).
    """

    scenario: str
    vehicle: PlantModel
    references: Sequence[TF]
    controller: SMCDesign | LoopShapedDesign
    commands: np.ndarray
    failure: Failure | None
    method: str
    duration: float
    pilots: Sequence[Pilot] = ()
    output_bound: float | np.ndarray = 1.0e3

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "duration", check_setting("duration", self.duration))


#: Frame period the seed's boundary layers were chosen at: its Simulink step (seed section 4.5,
#: "fixed time step of dt = 0.0005 sec"; section 4.3 step 6 picks eps in that simulation).
SEED_FRAME_PERIOD = DEFAULT_DT


def anti_windup_on(rule: str, frame_period: float) -> bool:
    """Whether the SMC integrates its error in a frame where the allocator fell short of ``v``.

    ``sigma = K0 e + K_-1 int(e)`` (seed Eq 4.7) integrates the tracking error of
    the observer, which is driven by the command actually allocated.  When the
    allocator cannot meet the demand (Eq 1.28's rate box binding, position
    limits), ``e`` persists, ``int(e)`` winds up and ``u_c`` rails at ``rho``:
    the seed's hedging is driven by ``u_c`` (Eqs 3.17-3.18), not by the
    allocator's shortfall, so nothing in the seed's loop unwinds it.  ``"on"``
    is conditional integration, the textbook anti-windup: ``int(e)`` is held in
    every frame whose allocation was not exact (``alloc``'s test,
    ``max|v - B u| <= 1e-6 max(1, max|v|)``).  ``"off"`` is the seed's law.
    ``"auto"`` (default): on when the frame period is longer than the seed's
    0.5 ms, off at the seed's rate (seed runs bit-identical).
    """
    check_setting("anti_windup", rule)
    if rule == "auto":
        return frame_period > SEED_FRAME_PERIOD * (1.0 + 1e-9)
    return rule == "on"


def boundary_layer_at(eps: np.ndarray, frame_period: float, rule: str = "frame") -> np.ndarray:
    """Boundary-layer thickness of the SMC at frame period ``T``.

    Sampled at ``T`` and held, the linear region of ``u_c = rho sat(sigma / eps)``
    is a discrete loop ``sigma_{j+1} ~ (1 - T g rho / eps) sigma_j`` (``g``: the
    sliding variable's rate per unit ``u_c``); quasi-sliding is stable only for
    ``T g rho / eps < 2``.  The seed chose ``eps`` at ``T_seed = 0.5 ms``
    (section 4.3 step 6, section 4.5), where that per-frame gain is 0.45-0.51
    on ICE; at 100 Hz it is 9-10 and the loop chatters and diverges.

    ``"frame"`` (default) keeps the seed's per-frame gain:
    ``eps_T = eps * max(1, T / T_seed)`` (``rho`` unchanged, so the
    continuous-time equivalent gain ``rho / eps`` falls as ``1 / T``);
    ``"fixed"`` keeps the seed's ``eps`` at every rate.  At ``T <= T_seed``
    both return ``eps`` itself (seed runs bit-identical).
    """
    check_setting("boundary_layer", rule)
    ratio = frame_period / SEED_FRAME_PERIOD
    if rule == "fixed" or ratio <= 1.0 + 1e-9:
        return eps
    return eps * ratio
