"""``--plant jsbsim:f22``: JSBSim's F-22 as a plant of the closed loop (:class:`sim.plant.Plant`).

The nonlinear six-degree-of-freedom F-22 of ``jsbsim`` 1.3.3 (aerodynamics, mass, engines as
shipped; flight control replaced by pass-through channels, :mod:`sim.plants.jsbsim_model`),
trimmed at a :class:`~sim.plants.jsbsim_model.TrimCondition` (default M0.7, 20,000 ft).
Commands, positions and outputs are deviations from that trim in the units of the vehicle
file :data:`sim.plants.jsbsim_linear.VEHICLE_FILE`: effectors
:data:`~sim.plants.jsbsim_linear.EFFECTORS` in degrees, outputs
:data:`~sim.plants.jsbsim_model.STATES` (m/s, deg, deg/s).  Throttle and the leading- and
trailing-edge flaps stay at their trim.

Actuators (this module's, the stock file's have no lag): per effector a first-order lag of
bandwidth :data:`~sim.plants.jsbsim_linear.ACTUATOR_BANDWIDTH`, then its rate limit and its
position limits (the stock FCS's), stepped exactly (``exp(-w h)``) at JSBSim's own step
``h`` (:data:`~sim.plants.jsbsim_model.JSBSIM_DT`, 1/120 s unless given); ``step(u, dt)``
runs ``dt / h`` of those steps, so ``dt`` must be a multiple of ``h``.

Failures are the library's kinds (:data:`alloc.health.FAILURE_KINDS`), executed by their
effects, in the units of the commands (deviations from trim):

* ``HOLD`` (``jam``): held at ``position``, or where it is at the failure when none is given;
* ``RUN_TO_STOP`` (``hardover``): runs to ``position`` (default the upper limit) at its rate
  limit and stays;
* ``TRAIL`` (``float``): the model has no hinge moments to float on, so the surface goes to
  zero deflection (streamlined, absolute 0 deg) at its rate limit and no longer answers;
* ``SCALE`` (``effectiveness``): the aerodynamics sees ``trim + fraction (position - trim)``:
  the control power about the trim scaled, as the told allocator's column is;
* ``LIMITS`` / ``RATE_LIMITS``: reduced position / rate limits; ``REPAIR``: nominal again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from alloc.exceptions import AllocError, ProblemError
from alloc.health import Effect, FailureKind, check_parameters, resolve_defaults
from sim.plants.jsbsim_linear import ACTUATOR_BANDWIDTH, EFFECTORS
from sim.plants.jsbsim_model import JSBSIM_DT, SURFACES, STATES, STATE_UNITS, F22, FT, TrimCondition

__all__ = ["JSBSimPlant", "PLANT_NAME", "make_plant"]

PLANT_NAME = "jsbsim:f22"
_INDEX = [next(i for i, s in enumerate(SURFACES) if s.name == e) for e in EFFECTORS]
_UNIT = {"m/s": "mps", "deg": "deg", "deg/s": "deg_s"}


class JSBSimPlant:
    """JSBSim's F-22 behind the plant contract (module docstring); ``failures`` lists the injected ones."""

    name = PLANT_NAME
    effectors: tuple[str, ...] = EFFECTORS
    outputs: tuple[str, ...] = STATES

    def __init__(self, condition: TrimCondition | None = None, *, jsbsim_dt: float = JSBSIM_DT,
                 bandwidth: dict[str, float] | None = None) -> None:
        if isinstance(jsbsim_dt, bool) or not isinstance(jsbsim_dt, (int, float)) or not 1e-4 <= jsbsim_dt <= 0.05:
            raise AllocError(f"jsbsim_dt: expected a step in [1e-4, 0.05] s, got {jsbsim_dt!r}", field="jsbsim_dt")
        self.condition = condition or TrimCondition()
        self.h = float(jsbsim_dt)
        bw = dict(ACTUATOR_BANDWIDTH)
        for k, v in (bandwidth or {}).items():
            if k not in bw:
                raise AllocError(f"bandwidth: unknown effector {k!r}; effectors: {', '.join(EFFECTORS)}",
                                 field="bandwidth")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise AllocError(f"bandwidth: {k} must be a positive number of rad/s, got {v!r}", field="bandwidth")
            bw[k] = float(v)
        self.bandwidth = np.array([bw[e] for e in EFFECTORS])
        self.sim: F22 | None = None
        #: the linear model's A (states x states) whose free response :meth:`sensed` takes away; None: the
        #: vehicle file's, read when first needed
        self.free_response: np.ndarray | None = None
        self._new_sim()
        self.source = (f"jsbsim {self._version()} aircraft/f22/f22.xml, pass-through flight control; trimmed "
                       f"M{self.condition.mach:g} at {self.condition.altitude_ft:g} ft (sim.plants.jsbsim_model)")
        self.reset(seed=0)

    @staticmethod
    def _version() -> str:
        import jsbsim

        return str(getattr(jsbsim, "__version__", "unknown"))

    def _new_sim(self) -> None:
        # a fresh, re-trimmed instance is the exact trim (engine spool state included); 10 ms
        self.sim = F22(self.condition, dt=self.h)
        trim = self.sim.trim_positions
        self.trim_u = trim[_INDEX].copy()
        self.lo0 = np.array([SURFACES[i].lo for i in _INDEX]) - self.trim_u
        self.hi0 = np.array([SURFACES[i].hi for i in _INDEX]) - self.trim_u
        self.rate0 = np.array([SURFACES[i].rate for i in _INDEX])

    # ---------------------------------------------------------------- the contract
    def reset(self, *, seed: int) -> np.ndarray:
        """Back to the trim (a new trimmed JSBSim instance), every failure cleared.  The plant draws
        nothing at random: ``seed`` is recorded only."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise AllocError(f"seed: expected an integer, got {seed!r}", field="seed")
        if self.sim is None or self.sim.fdm.get_sim_time() > 0.0:
            self._new_sim()
        self.seed = int(seed)
        m = len(EFFECTORS)
        self.pos = np.zeros(m)
        self.lo, self.hi = self.lo0.copy(), self.hi0.copy()
        self.rate_lo, self.rate_hi = -self.rate0.copy(), self.rate0.copy()
        self.held = np.full(m, np.nan)  # jam / hard-over / float target, nan: free
        self.scale = np.ones(m)
        self.failures: list[dict[str, Any]] = []
        self.time = 0.0
        return self._outputs()

    def step(self, u_cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` s (a multiple of JSBSim's step) holding ``u_cmd`` (deg from trim)."""
        u = np.asarray(u_cmd, dtype=float)
        if u.shape != (len(EFFECTORS),) or not np.all(np.isfinite(u)):
            raise AllocError(f"u_cmd: expected {len(EFFECTORS)} finite commands ({', '.join(EFFECTORS)}), got "
                             f"shape {u.shape}", field="u_cmd")
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0:
            raise AllocError(f"dt: expected a positive step in s, got {dt!r}", field="dt")
        n = int(round(dt / self.h))
        if n < 1 or abs(n * self.h - dt) > 1e-9 * max(1.0, dt):
            raise AllocError(f"dt: {dt!r} s is not a multiple of JSBSim's step {self.h:g} s", field="dt")
        fdm = self.sim.fdm
        decay = np.exp(-self.bandwidth * self.h)
        held = ~np.isnan(self.held)
        for _ in range(n):
            target = np.where(held, self.held, u)
            lag = np.where(held, target, target + (self.pos - target) * decay)  # a held surface runs at its rate
            move = np.clip(lag - self.pos, self.rate_lo * self.h, self.rate_hi * self.h)
            self.pos = np.clip(self.pos + move, self.lo, self.hi)
            seen = self.trim_u + self.scale * self.pos
            for k, i in enumerate(_INDEX):
                fdm[SURFACES[i].prop] = float(seen[k])
            if not fdm.run():
                raise AllocError("dt: JSBSim stopped the run (a crash or a terminate condition)", field="dt")
        self.time += n * self.h
        return self._outputs()

    def positions(self) -> np.ndarray:
        """Effector positions (deg from trim) after actuator dynamics, limits and failures."""
        return self.pos.copy()

    def state(self) -> dict[str, float]:
        """Named physical state, units in the names."""
        f = self.sim.fdm
        x = self.sim.state()
        out = {f"{n}_{_UNIT[u]}": float(v) for n, v, u in zip(STATES, x, STATE_UNITS, strict=True)}
        out.update(altitude_m=float(f["position/h-sl-ft"]) * FT, mach=float(f["velocities/mach"]),
                   qbar_pa=float(f["aero/qbar-psf"]) * 47.880258889, nz_g=float(-f["accelerations/n-pilot-z-norm"]),
                   psi_deg=float(f["attitude/psi-deg"]), time_s=self.time)
        return out

    def fail(self, effector: int, kind: str, params: dict[str, float] | None = None) -> None:
        """Inject ``kind`` (a row of :data:`alloc.health.FAILURE_KINDS`) on ``effector`` from the next step on.

        Positions and limits are deviations from trim (deg), rates deg/s.  Raises ProblemError
        naming ``effector``, ``kind`` or the parameter for bad input.
        """
        m = len(EFFECTORS)
        if isinstance(effector, bool) or not isinstance(effector, (int, np.integer)) or not 0 <= effector < m:
            raise ProblemError(f"effector: expected an index in [0, {len(EFFECTORS) - 1}] ({', '.join(EFFECTORS)}), "
                               f"got {effector!r}", field="effector")
        if not (isinstance(kind, str) and kind in {k.value for k in FailureKind}):
            kinds = ", ".join(k.value for k in FailureKind)
            raise ProblemError(f"kind: unknown failure kind {kind!r}; expected one of {kinds}", field="kind")
        spec = FailureKind(kind).spec
        params = dict(params or {})
        for p in params:
            if p not in spec.params:
                raise ProblemError(f"{p}: a {kind!r} failure does not take it (it takes "
                                   f"{', '.join(spec.params) or 'no parameters'})", field=p)
        for p, default in spec.params.items():
            if default is None and p not in params:
                raise ProblemError(f"{p}: required for a {kind!r} failure", field=p)
        i = int(effector)
        limits = (float(self.lo0[i]), float(self.hi0[i]))
        params = resolve_defaults(spec, params, limits=limits, position=float(self.pos[i]))
        check_parameters(kind, params, effector=EFFECTORS[i], limits=limits,
                         rate_limits=(float(-self.rate0[i]), float(self.rate0[i])))
        for effect in spec.effects:
            self._execute(effect, i, params)
        self.failures.append({"time": self.time, "effector": EFFECTORS[i], "kind": kind, **params})

    def executed(self) -> list[Any]:
        """The failures as executed (defaults filled in), as :class:`sim.blocks.ActuatorFailure`."""
        from sim.blocks import ActuatorFailure

        return [ActuatorFailure(EFFECTORS.index(f["effector"]), f["kind"],
                                **{k: v for k, v in f.items() if k not in ("time", "effector", "kind")})
                for f in self.failures]

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Effector position limits now (deviations from trim, deg; failures change them)."""
        return self.lo.copy(), self.hi.copy()

    def sensed(self) -> np.ndarray:
        """``x' - A x`` in the vehicle file's states (:data:`~sim.plants.jsbsim_model.STATES`, deviations from
        trim): JSBSim's own body accelerations of its last pass turned into the states' rates
        (:func:`~sim.plants.jsbsim_model.state_rates`, what gyros, accelerometers and air data give), less the
        free response of the linear model's ``A`` (:attr:`free_response`; default: the vehicle file's)."""
        from sim.plants.jsbsim_model import state_rates

        if self.free_response is None:
            from alloc import vehicles
            from sim.plants.jsbsim_linear import VEHICLE_FILE

            self.free_response = np.asarray(vehicles.get_vehicle(VEHICLE_FILE).model.arrays()[0], dtype=float)
        x = self.sim.state()
        return state_rates(x, self.sim.accelerations()) - self.free_response @ (x - self.sim.trim_state)

    def _execute(self, effect: Effect, i: int, p: dict[str, float]) -> None:
        if effect in (Effect.HOLD, Effect.RUN_TO_STOP):
            # a jam stops where it is told (rate 0 from now: the target is reached at once when it is
            # the position at failure); a hard-over runs there at its rate limit
            self.held[i] = p["position"]
            if effect is Effect.HOLD:
                self.pos[i] = p["position"]
        elif effect is Effect.TRAIL:
            self.held[i] = -self.trim_u[i]  # absolute 0 deg: streamlined
        elif effect is Effect.SCALE:
            self.scale[i] = p["fraction"]
        elif effect is Effect.LIMITS:
            self.lo[i], self.hi[i] = p["lo"], p["hi"]
        elif effect is Effect.RATE_LIMITS:
            self.rate_lo[i], self.rate_hi[i] = p["rate_min"], p["rate_max"]
        elif effect is Effect.REPAIR:
            self.lo[i], self.hi[i] = self.lo0[i], self.hi0[i]
            self.rate_lo[i], self.rate_hi[i] = -self.rate0[i], self.rate0[i]
            self.held[i], self.scale[i] = np.nan, 1.0
        else:  # a kind registered later with an effect this plant cannot execute
            raise ProblemError(f"kind: effect {effect.name} is not executed by {PLANT_NAME}", field="kind")

    def describe(self) -> dict[str, Any]:
        """JSON-ready: name, source, trim, steps, actuators, failures."""
        c = self.condition
        return {
            "name": self.name, "source": self.source,
            "trim": {"mach": c.mach, "altitude_ft": c.altitude_ft, "gamma_deg": c.gamma_deg,
                     "state": dict(zip(STATES, self.sim.trim_state.tolist(), strict=True)),
                     "positions_deg": dict(zip([s.name for s in SURFACES], self.sim.trim_positions.tolist(),
                                               strict=True)),
                     "throttle": self.sim.throttle, "residual": self.sim.trim_residual},
            "jsbsim_dt": self.h, "effectors": list(EFFECTORS), "outputs": list(STATES), "units": list(STATE_UNITS),
            "actuators": {e: {"bandwidth_rad_s": float(b), "rate_deg_s": float(r), "lo_deg": float(lo),
                              "hi_deg": float(hi)}
                          for e, b, r, lo, hi in zip(EFFECTORS, self.bandwidth, self.rate0, self.lo0, self.hi0,
                                                     strict=True)},
            "failures": list(self.failures), "seed": self.seed,
        }

    # ---------------------------------------------------------------- helpers
    def _outputs(self) -> np.ndarray:
        return self.sim.state() - self.sim.trim_state


def make_plant(spec: str = PLANT_NAME, **options: Any) -> JSBSimPlant:
    """The plant named ``spec`` (``"jsbsim:f22"``, the only aircraft wired); AllocError naming ``plant`` else."""
    if spec != PLANT_NAME:
        raise AllocError(f"plant: {spec!r} is not available; JSBSim plants: {PLANT_NAME}", field="plant")
    return JSBSimPlant(**options)
