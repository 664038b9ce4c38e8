"""RotorPy (``rotorpy`` 3.0.0, the ``[plants]`` extra) as a :class:`sim.plant.Plant` for multirotors of any rotor count.

What comes from the vehicle file
--------------------------------
- ``[body]``: mass, inertia; ``rotor_speed_max`` (or ``thrust_coefficient``) and ``motor_time_constant``
  (:mod:`alloc.vehicle_file.body`).  RotorPy's ``k_eta = ct / rotor_speed_max^2``, ``k_m = |km| k_eta``,
  ``tau_m`` the motor time constant (the effectors' first-order lag when ``[body]`` does not state one).
- each rotor effector's geometry: ``position`` (body FRD, m) and the sign of ``km`` (RotorPy's
  ``rotor_directions = -sign(km)``: a rotor whose reaction torque is negative about FRD z pushes
  positive about RotorPy's z-up body axis).  RotorPy thrusts along body z, so every rotor axis must be
  ``[0, 0, -1]``; its ``k_eta`` and ``k_m`` are scalars, so every rotor must share ``ct`` and ``|km|``.

Command to rotor speed
----------------------
An effector of unit ``1`` commands the rotor's thrust as a fraction of ``ct`` (the linear model's
effectiveness, ``thrust = ct u``).  The plant inverts RotorPy's ``thrust = k_eta w^2``: the commanded
speed is ``w = rotor_speed_max sqrt(u)`` with ``u = u0 + du`` (trim plus the loop's deviation), so
thrust is linear in ``u`` in steady state, as PX4's thrust-curve correction makes it.  Before the
square root the command goes through the effector's position limits and its ``rate_max`` as a slew
limit (PX4's motor slew); RotorPy then lags the speed with ``tau_m`` and clips it to
``[0, rotor_speed_max]``.  :meth:`RotorPyPlant.positions` reports ``(w / rotor_speed_max)^2 - u0``,
the thrust fraction the rotor makes now.

Failures (:data:`alloc.health.FAILURE_KINDS`, executed by :meth:`sim.blocks.ActuatorBank.apply_failure`
on the command stage): ``float`` (a rotor lost: commanded speed 0, it spins down through ``tau_m`` to
zero thrust), ``jam`` (the command held: a stuck speed), ``hardover`` (run to a position),
``effectiveness`` (fraction ``f`` of the thrust and torque: the speed times ``sqrt(f)``, a weak motor),
``limits``, ``rate_limits`` (a reduced slew), ``repair``.  ``bandwidth`` is refused: RotorPy has one
``tau_m`` for every rotor.

Two places of RotorPy 3.0.0 assume four rotors (its state packing is 20 numbers, its constructor inverts
a 4 x n mixer): the adapter builds the ``Multirotor`` on a four-rotor placeholder, then sets the real
geometry, and integrates RotorPy's own derivative (``Multirotor._s_dot_fn``) with RotorPy's integrator
(``scipy.integrate.solve_ivp``, RK45) on its own ``16 + n`` packing.  The mixer is not used: the plant
commands rotor speeds (``cmd_motor_speeds``).  RotorPy applies translational lift to a stopped rotor; the
adapter removes it from a rotor the plant has stopped (``float``).

Wind: the world's Dryden turbulence (:func:`sim.world.gust_series`, translational components; rotorpy.wind
is not imported: it imports torch), rotated into RotorPy's z-up world and set as the state's wind each step.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from alloc.exceptions import ProblemError
from sim.plant import _whole_steps, command_of

__all__ = ["RotorPyPlant", "rotorpy_parameters", "DEFAULT_DRAG", "DEFAULT_STEP"]

#: s: the plant's step, wind and command held over it (RK45 adapts inside it); 250 Hz, a multirotor
#: rate loop's frame (PX4 runs its rate loop at 250 Hz to 1 kHz)
DEFAULT_STEP = 0.004
#: RotorPy's drag coefficients for a vehicle that states none: its Hummingbird's (rotorpy.vehicles.hummingbird_params),
#: frame drag c_D (N/(m/s)^2), rotor drag k_d and induced inflow k_z (N/(rad/s)/(m/s)), translational lift k_h (N/(m/s)^2)
DEFAULT_DRAG = {"c_Dx": 0.5e-2, "c_Dy": 0.5e-2, "c_Dz": 1e-2, "k_d": 1.19e-4, "k_z": 2.32e-4, "k_h": 3.39e-3,
                "k_flap": 0.0}
#: RotorPy's gravity (m/s^2): the trim's thrust must hold mass x this
GRAVITY = 9.81
#: FRD <-> RotorPy's FLU (body) and NED <-> its z-up world: both flip y and z
_FLIP = np.diag([1.0, -1.0, -1.0])
#: how closely the axes' trim thrust must hold the body's weight (a file's decimals)
TRIM_RTOL = 1e-3


def _refuse(field: str, message: str) -> ProblemError:
    return ProblemError(f"{field}: --plant rotorpy {message}", field=field)


def rotorpy_parameters(fv: Any, trim_u: np.ndarray) -> tuple[dict[str, Any], np.ndarray]:
    """RotorPy's parameter dictionary of vehicle file ``fv`` and each rotor's full-command speed (rad/s).

    Raises ProblemError naming the field that keeps RotorPy from flying the vehicle.
    """
    body = fv.body
    if body is None:
        raise _refuse("body", f"needs the vehicle's [body] (mass, inertia, rotor_speed_max); {fv.name!r} has none")
    rotors = []
    for j, e in enumerate(fv.effectors):
        if e.rotor is None:
            raise _refuse(f"effectors[{j}].rotor", f"flies rotors only; {e.name!r} is not a rotor")
        axis = np.asarray(e.rotor.axis, dtype=float)
        if not np.allclose(axis / np.linalg.norm(axis), [0.0, 0.0, -1.0], atol=1e-9):
            raise _refuse(f"effectors[{j}].rotor.axis", f"thrusts along body z only; {e.name!r} has axis {list(e.rotor.axis)}")
        if not (0.0 <= e.min and e.max <= 1.0):
            raise _refuse(f"effectors[{j}].max", f"takes thrust fractions in [0, 1]; {e.name!r} spans [{e.min:g}, {e.max:g}]")
        rotors.append(e.rotor)
    ct, km = rotors[0].ct, abs(rotors[0].km)
    for j, r in enumerate(rotors):
        if not np.isclose(r.ct, ct, rtol=1e-9) or not np.isclose(abs(r.km), km, rtol=1e-9, atol=0.0):
            raise _refuse(f"effectors[{j}].rotor", "has one thrust and one torque coefficient for every rotor; "
                          f"rotor {j} has ct {r.ct:g}, km {r.km:g} against {ct:g}, {rotors[0].km:g}")
    w_max = body.rotor_speed_max_for(ct)
    if w_max is None:
        raise _refuse("body.rotor_speed_max", "needs a rotor's speed at full command (or thrust_coefficient)")
    tau = body.motor_time_constant if body.motor_time_constant is not None else _motor_lag(fv)
    weight = body.mass * GRAVITY
    thrust = ct * float(np.sum(trim_u))
    if not abs(thrust - weight) <= TRIM_RTOL * weight:
        raise _refuse("axes", f"hovers at the trim: the trim thrust {thrust:g} N must hold the body's weight "
                      f"{body.mass:g} kg x {GRAVITY} = {weight:g} N (axes[].trim)")
    k_eta = ct / (w_max * w_max)
    J = body.J
    params = {
        "mass": body.mass, "Ixx": J[0, 0], "Iyy": J[1, 1], "Izz": J[2, 2],
        # FRD -> FLU flips the sign of the products of inertia with one flipped axis (xy, xz)
        "Ixy": -J[0, 1], "Ixz": -J[0, 2], "Iyz": J[1, 2],
        "num_rotors": len(rotors),
        "rotor_pos": {f"r{j + 1}": _FLIP @ np.asarray(r.position, dtype=float) for j, r in enumerate(rotors)},
        "rotor_directions": np.array([-np.sign(r.km) for r in rotors]),
        "k_eta": k_eta, "k_m": km * k_eta, "tau_m": tau,
        "rotor_speed_min": 0.0, "rotor_speed_max": w_max, "motor_noise_std": 0.0,
        **DEFAULT_DRAG,
    }
    return params, np.full(len(rotors), w_max)


def _motor_lag(fv: Any) -> float:
    """The rotors' shared first-order time constant from their ``dynamics``."""
    taus = set()
    for j, e in enumerate(fv.effectors):
        d = e.dynamics
        if d is None or (d.time_constant is None and d.bandwidth is None):
            raise _refuse("body.motor_time_constant", f"needs the motors' time constant: [body] states none and "
                          f"effectors[{j}].dynamics has no first-order lag")
        taus.add(d.time_constant if d.time_constant is not None else 1.0 / d.bandwidth)
    if len(taus) > 1:
        raise _refuse("body.motor_time_constant", f"has one tau_m; the rotors' lags differ ({sorted(taus)})")
    return taus.pop()


class RotorPyPlant:
    """RotorPy's multirotor as a plant of the loop (see the module docstring).

    Parameters
    ----------
    fv : alloc.vehicle_file.Vehicle
        The vehicle file (``[body]``, rotor effectors).
    vehicle : sim.model.PlantModel
        The loop's vehicle (deviation limits, actuators, output names) of the same file.
    trim_u : ndarray
        ``u0``, the trim command (file units).
    dt_step : float
        The plant's step (s).
    wind : ndarray (n, 3) or None
        World wind (m/s, north-east-down) at ``k dt_step``; held past its end; None: still air.
    """

    name = "rotorpy"
    #: the state recorded into a run's ``result.extra`` (sim.plants.fly_multirotor)
    recorded_state = ("altitude_m", "north_m", "east_m", "v_north_mps", "v_east_mps", "wind_north_mps",
                      "wind_east_mps", "wind_down_mps")

    def __init__(self, fv: Any, vehicle: Any, trim_u: np.ndarray, *, dt_step: float = DEFAULT_STEP,
                 wind: np.ndarray | None = None) -> None:
        import rotorpy
        from rotorpy.vehicles.multirotor import Multirotor

        self.trim_u = np.asarray(trim_u, dtype=float)
        params, self.w_max = rotorpy_parameters(fv, self.trim_u)
        self.outputs = tuple(vehicle.output_names)
        unknown = [o for o in self.outputs if o not in _OUTPUTS]
        if unknown:
            i = self.outputs.index(unknown[0])
            raise _refuse(f"model.outputs[{i}]", f"measures {', '.join(_OUTPUTS)}; the model's output "
                          f"{unknown[0]!r} is none of them")
        self.effectors = tuple(vehicle.effector_names)
        self.vehicle = vehicle
        self.states = tuple(fv.model.states) if fv.model is not None else ()
        self.params = params
        self.dt_step = float(dt_step)
        self.wind = None if wind is None else np.asarray(wind, dtype=float)
        self.version = getattr(rotorpy, "__version__", None) or _version()
        self.source = (f"rotorpy {self.version} Multirotor ({params['num_rotors']} rotors, {fv.name}: mass "
                       f"{params['mass']:g} kg, k_eta {params['k_eta']:.4g}, k_m {params['k_m']:.4g}, tau_m "
                       f"{params['tau_m']:.4g} s, rotor_speed_max {params['rotor_speed_max']:g} rad/s), RK45 per "
                       f"{self.dt_step:g} s step")
        self._multirotor = _build(Multirotor, params)
        self.reset(seed=0)

    # ------------------------------------------------------------------ the contract
    @property
    def motor_time_constant(self) -> float:
        """s: the rotors' first-order speed lag ``tau_m`` (the multirotor cascade's gains follow it)."""
        return float(self.params["tau_m"])

    def reset(self, *, seed: int) -> np.ndarray:
        """Hover at the trim, at the origin, level, rotors at their trim speeds (RotorPy draws nothing here)."""
        from sim.blocks import ActuatorBank

        self._bank = ActuatorBank(self.vehicle.actuators, self.dt_step)  # the command stage's limits and failures
        self._stopped = np.zeros(len(self.effectors), dtype=bool)
        self._multirotor.stopped = self._stopped
        self._t = 0.0
        self._k = 0
        self._failures: list[dict[str, Any]] = []
        speeds = self.w_max * np.sqrt(np.clip(self.trim_u, 0.0, 1.0))
        self._speeds_cmd = speeds
        self._state = {"x": np.zeros(3), "v": np.zeros(3), "q": np.array([0.0, 0.0, 0.0, 1.0]), "w": np.zeros(3),
                       "wind": self._wind_at(0), "rotor_speeds": speeds}
        return self._outputs()

    def step(self, u_cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` (whole plant steps) holding the deviation command ``u_cmd``."""
        import scipy.integrate

        u = command_of(u_cmd, len(self.effectors))
        mr = self._multirotor
        for _ in range(_whole_steps(dt, self.dt_step)):
            speeds_cmd = self._speed_command(u)
            self._speeds_cmd = speeds_cmd
            self._state["wind"] = self._wind_at(self._k)
            s = _pack(self._state)
            # RotorPy's integrator (RK45, its tolerances); the first trial step is the whole step: scipy's
            # guess from |f(t0)| is 1e-6 s at an exact hover (f = 0) and costs a dozen steps to grow back
            sol = scipy.integrate.solve_ivp(lambda t, x: mr._s_dot_fn(t, x, speeds_cmd), (0.0, self.dt_step), s,
                                            first_step=self.dt_step, **mr.integrator_kwargs)
            s = sol["y"][:, -1]
            s[6:10] /= np.linalg.norm(s[6:10])
            s[16:] = np.clip(s[16:], mr.rotor_speed_min, mr.rotor_speed_max)
            self._state = _unpack(s)
            self._k += 1
            self._t += self.dt_step
        return self._outputs()

    def positions(self) -> np.ndarray:
        """The thrust fraction each rotor makes now, as a deviation from trim: ``(w / w_max)^2 - u0``."""
        return (self._state["rotor_speeds"] / self.w_max) ** 2 - self.trim_u

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The command stage's position limits now (deviations; failures change them)."""
        return self._bank.lo.copy(), self._bank.hi.copy()

    def state(self) -> dict[str, float]:
        st = self._state
        ned = _FLIP @ st["x"]
        v_ned = _FLIP @ st["v"]
        out = {"north_m": ned[0], "east_m": ned[1], "altitude_m": -ned[2], "v_north_mps": v_ned[0],
               "v_east_mps": v_ned[1], "climb_mps": -v_ned[2], "t_s": self._t}
        wind = _FLIP @ st["wind"]
        out.update({"wind_north_mps": wind[0], "wind_east_mps": wind[1], "wind_down_mps": wind[2]})
        out.update({f"{n}_rad_s": w for n, w in zip(self.effectors, st["rotor_speeds"], strict=True)})
        return {k: float(v) for k, v in out.items()}

    def sensed(self) -> np.ndarray:
        """The model's states' derivative from RotorPy's own (``Multirotor._s_dot_fn`` at the state now),
        less the nominal free response ``A x``: body rates' derivative, Euler-angle rates (ZYX kinematics)
        and body velocities' derivative ``R^T v_ned' - w x v_body``, in the project's frames."""
        missing = [i for i, n in enumerate(self.states) if n not in _OUTPUTS]
        if missing or not self.states:
            i = missing[0] if missing else 0
            raise _refuse(f"model.states[{i}]", f"senses {', '.join(_OUTPUTS)}; the model's states are {self.states}")
        st = self._state
        sdot = self._multirotor._s_dot_fn(0.0, _pack(st), self._speeds_cmd)
        now = _measure(st)
        phi, theta = now["phi"], now["theta"]
        w = np.array([now["p"], now["q"], now["r"]])
        from scipy.spatial.transform import Rotation

        R = _FLIP @ Rotation.from_quat(st["q"]).as_matrix() @ _FLIP
        v_body = np.array([now["u"], now["v"], now["w"]])
        v_body_dot = R.T @ (_FLIP @ sdot[3:6]) - np.cross(w, v_body)
        w_dot = _FLIP @ sdot[10:13]
        turn = w[1] * np.sin(phi) + w[2] * np.cos(phi)
        rates = {"phi": w[0] + np.tan(theta) * turn, "theta": w[1] * np.cos(phi) - w[2] * np.sin(phi),
                 "psi": turn / np.cos(theta), "p": w_dot[0], "q": w_dot[1], "r": w_dot[2],
                 "u": v_body_dot[0], "v": v_body_dot[1], "w": v_body_dot[2]}
        x = np.array([now[n] for n in self.states])
        xdot = np.array([rates[n] for n in self.states])
        return xdot - np.asarray(self.vehicle.A, dtype=float) @ x

    def fail(self, effector: int, kind: str, params: dict[str, float] | None = None) -> None:
        """Execute ``kind`` on rotor ``effector``'s command stage from the next step on (module docstring)."""
        from alloc.health import SIMULATOR_ONLY
        from sim.blocks import ActuatorFailure

        if kind in SIMULATOR_ONLY:
            raise ProblemError(f"kind: --plant rotorpy has one motor time constant for every rotor; {kind!r} "
                               "cannot change one rotor's", field="kind")
        bank = self._bank  # its position is the command stage's: a jam holds the command it has now
        executed = bank.apply_failure(ActuatorFailure(int(effector), kind, **(params or {})))
        self._stopped[:] = bank.effectiveness == 0.0
        self._failures.append({"effector": self.effectors[executed.index], "kind": executed.kind,
                               "params": dict(executed.params)})

    def executed(self) -> list[Any]:
        """The failures as executed (defaults filled in), as :class:`sim.blocks.ActuatorFailure`."""
        from sim.blocks import ActuatorFailure

        return [ActuatorFailure(self.effectors.index(f["effector"]), f["kind"], **f["params"]) for f in self._failures]

    def describe(self) -> dict[str, Any]:
        p = self.params
        return {"name": self.name, "source": self.source, "step": self.dt_step, "rotorpy": self.version,
                "parameters": {k: (v.tolist() if isinstance(v, np.ndarray) else
                                   {r: x.tolist() for r, x in v.items()} if isinstance(v, dict) else v)
                               for k, v in p.items()},
                "trim": {"u0": self.trim_u.tolist(), "rotor_speeds": (self.w_max * np.sqrt(self.trim_u)).tolist()},
                "command": "w = rotor_speed_max sqrt(u0 + du), after position limits and rate_max as a slew",
                "wind": None if self.wind is None else "sim.world Dryden gusts (u, v, w), north-east-down",
                "failures": list(self._failures)}

    # ------------------------------------------------------------------ inside
    def _speed_command(self, u: np.ndarray) -> np.ndarray:
        """The command stage of one step: hard-over target, limits, slew, jam; then ``w = w_max sqrt(f u)``."""
        b = self._bank
        target = np.where(b.hardover, b.hard_pos, u)
        target = np.clip(target, b.lo, b.hi)
        step = np.clip(target - b.pos, -b.rmax * self.dt_step, b.rmax * self.dt_step)
        b.pos = np.where(b.jammed, b.jam_pos, b.pos + step)
        fraction = np.clip(b.pos + self.trim_u, 0.0, 1.0) * b.effectiveness
        return self.w_max * np.sqrt(fraction)

    def _wind_at(self, k: int) -> np.ndarray:
        if self.wind is None or not len(self.wind):
            return np.zeros(3)
        return _FLIP @ self.wind[min(k, len(self.wind) - 1)]

    def _outputs(self) -> np.ndarray:
        values = _measure(self._state)
        return np.array([values[o] for o in self.outputs])


#: the outputs the plant measures (FRD body, NED world; deviations from a level hover at heading 0)
_OUTPUTS = ("phi", "theta", "psi", "p", "q", "r", "u", "v", "w")


def _measure(state: dict[str, np.ndarray]) -> dict[str, float]:
    """Euler angles (ZYX), body rates and body velocities in the project's FRD / NED frames."""
    from scipy.spatial.transform import Rotation

    R_flu = Rotation.from_quat(state["q"]).as_matrix()
    R = _FLIP @ R_flu @ _FLIP  # body FRD -> world NED
    psi, theta, phi = Rotation.from_matrix(R).as_euler("ZYX")
    rates = _FLIP @ state["w"]
    body_v = R.T @ (_FLIP @ state["v"])
    return {"phi": phi, "theta": theta, "psi": psi, "p": rates[0], "q": rates[1], "r": rates[2],
            "u": body_v[0], "v": body_v[1], "w": body_v[2]}


def _pack(state: dict[str, np.ndarray]) -> np.ndarray:
    """RotorPy's state vector, ``16 + n`` long (its own packing is 20 numbers: four rotors)."""
    return np.concatenate([state["x"], state["v"], state["q"], state["w"], state["wind"], state["rotor_speeds"]])


def _unpack(s: np.ndarray) -> dict[str, np.ndarray]:
    return {"x": s[0:3].copy(), "v": s[3:6].copy(), "q": s[6:10].copy(), "w": s[10:13].copy(),
            "wind": s[13:16].copy(), "rotor_speeds": s[16:].copy()}


def _version() -> str:
    from importlib.metadata import version

    return version("rotorpy")


def _build(Multirotor: type, params: dict[str, Any]) -> Any:
    """A ``Multirotor`` of ``params``' rotors: built on a four-rotor placeholder (RotorPy's constructor
    inverts a 4 x n mixer), then given the real geometry; stopped rotors lose translational lift."""

    class _Multirotor(Multirotor):
        stopped: np.ndarray

        def compute_body_wrench(self, body_rates, rotor_speeds, body_airspeed_vector):
            F, M = super().compute_body_wrench(body_rates, rotor_speeds, body_airspeed_vector)
            if self.aero and self.k_h and self.stopped.any():
                # RotorPy lifts every rotor by k_h |v_xy|^2 whatever its speed; a stopped rotor makes none
                local = body_airspeed_vector[:, None] + Multirotor.hat_map(body_rates) @ self.rotor_geometry.T
                lift = np.zeros((3, self.num_rotors))
                lift[2] = self.k_h * (local[0] ** 2 + local[1] ** 2) * self.stopped
                F = F - lift.sum(axis=1)
                M = M + np.einsum("ijk,ik->j", Multirotor.hat_map(self.rotor_geometry), lift)
            return F, M

    d = 0.1
    placeholder = {**params, "num_rotors": 4, "rotor_directions": np.array([1, -1, 1, -1]),
                   "rotor_pos": {f"r{i}": d * np.array(p) for i, p in
                                 enumerate(([1, 1, 0], [1, -1, 0], [-1, -1, 0], [-1, 1, 0]), 1)}}
    mr = _Multirotor(placeholder, control_abstraction="cmd_motor_speeds", aero=True)
    mr.num_rotors = params["num_rotors"]
    mr.rotor_pos = params["rotor_pos"]
    mr.rotor_dir = np.asarray(params["rotor_directions"], dtype=float)
    mr.extract_geometry()
    k = mr.k_m / mr.k_eta
    mr.f_to_TM = np.vstack((np.ones((1, mr.num_rotors)),
                            np.array([np.cross(r, [0.0, 0.0, 1.0])[:2] for r in mr.rotor_geometry]).T,
                            (k * mr.rotor_dir).reshape(1, -1)))
    mr.TM_to_f = np.linalg.pinv(mr.f_to_TM)  # unused with cmd_motor_speeds; kept consistent for a reader
    mr.stopped = np.zeros(mr.num_rotors, dtype=bool)
    return mr
