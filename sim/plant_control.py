"""Flight-control laws of :func:`sim.plant_loop.fly_plant`: the engine's, and a multirotor cascade.

Each controller has ``channels`` (the controlled outputs), ``reset()``, ``demand(step, z, plant) -> v``
(once per frame; it sets ``reference``, ``command`` and ``pseudo`` for the record),
``update(u_cmd, v_achieved)`` (after the allocator) and ``describe()``.

:class:`EngineController` is the engine's SMC or loop-shaped law (:mod:`sim.packed` ``observe`` and
``advance``) in numpy, on the same discretised systems (:func:`sim.engine._controller_slots`), so the
Python loop can be checked against the compiled one.

:class:`CascadeController` is the cascade PX4 and ArduPilot fly on a multirotor: P on attitude, PI on body
rate, PI on vertical speed with P on altitude, giving the allocator the demand ``v = [L, M, N, dFz]``
(N m, N m, N m, N: deviation from the trim thrust).  Gains (:class:`CascadeGains`) are angular or
vertical accelerations per unit error, turned into moments and forces by the ``[body]``'s inertia and
mass; where each number comes from is stated at its field.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from alloc.exceptions import ProblemError
from alloc.result import EXACT_RTOL
from sim.settings import LoopSpec, anti_windup_on

__all__ = ["EngineController", "CascadeController", "CascadeGains", "VelocityHold", "GRAVITY"]

GRAVITY = 9.81


class EngineController:
    """The engine's flight-control computer (SMC or loop-shaped), in numpy, fed by a plant's outputs.

    Built from the :class:`sim.settings.LoopSpec` the engine would fly (no pilots: a pilot model
    closes its loop inside the compiled step).
    """

    def __init__(self, spec: LoopSpec) -> None:
        from sim.engine import _controller_slots
        from sim.model import SMCDesign
        from sim.packed import FloatSlot as S

        if spec.pilots:
            raise ProblemError("pilots: the plant loop flies direct commands only", field="pilots")
        self.spec = spec
        v = spec.vehicle
        self.channels = tuple(v.channels)
        tframe = spec.frame_steps() * spec.dt
        self.tframe = tframe
        self.smc = isinstance(spec.controller, SMCDesign)
        slots = _controller_slots(v, spec.controller, spec.references, tframe, spec.boundary_layer)
        self._m = {name: np.array(slots[getattr(S, name)], dtype=float) for name in
                   ("XC", "ADC", "BDC", "CC", "XK", "AK", "BK", "CK", "DK", "K0", "KM1", "RHO", "EPS")}
        self.observed = self.smc and spec.controller.observer_poles is not None
        self.sign = self.smc and spec.controller.eps is None
        self.anti_windup = self.smc and anti_windup_on(spec.anti_windup, tframe)
        self.ctrl = np.asarray(v.controlled)
        self.meas = np.asarray(v.measured)
        self.demand_map = np.asarray(v.demand_map, dtype=float)
        self.commands = np.asarray(spec.commands, dtype=float)
        self.reset()

    def reset(self) -> None:
        k = len(self.ctrl)
        self.xc = self._m["XC"].copy()
        self.xk = self._m["XK"].copy()
        self.integ = np.zeros(k)
        self.reference = np.zeros(k)
        self.command = np.zeros(k)
        self.pseudo = np.zeros(k)
        self.e = np.zeros(k)
        self.v = np.zeros(k)
        self.z = np.zeros(len(self.spec.vehicle.output_names))

    def demand(self, step: int, z: np.ndarray, plant: Any) -> np.ndarray:
        """``observe``'s controller part: reference, error, pseudo-command ``u_c`` and ``v = demand_map u_c``."""
        M, k = self._m, len(self.ctrl)
        self.z = z
        self.command = self.commands[step, :k].copy()
        if self.smc:
            o = M["CC"] @ self.xc
            y_fb = o[k:2 * k] if self.observed else z[self.ctrl]
            r = o[:k]
            e = r - (y_fb + o[2 * k:3 * k])
            sigma = M["K0"] * e + M["KM1"] * self.integ
            uc = M["RHO"] * (np.sign(sigma) if self.sign else np.clip(sigma / M["EPS"], -1.0, 1.0))
        else:
            r = M["CC"] @ self.xc
            e = r - z[self.ctrl]
            uc = M["CK"] @ self.xk + M["DK"] @ e
            self.xk = M["AK"] @ self.xk + M["BK"] @ e
            self.xc = M["ADC"] @ self.xc + M["BDC"] @ self.command
        self.reference, self.e, self.pseudo = r.copy(), e, uc
        self.v = self.demand_map @ uc
        return self.v

    def update(self, u_cmd: np.ndarray, v_achieved: np.ndarray) -> None:
        """``advance``'s controller part: the SMC system's input ``[command, u_cmd, z, u_c]`` and the integral."""
        if not self.smc:
            return
        M = self._m
        w = np.concatenate([self.command, u_cmd, self.z[self.meas], self.pseudo])
        self.xc = M["ADC"] @ self.xc + M["BDC"] @ w
        short = not np.max(np.abs(v_achieved - self.v), initial=0.0) <= EXACT_RTOL * max(1.0, np.max(np.abs(self.v)))
        if not (self.anti_windup and short):
            self.integ = self.integ + self.tframe * self.e

    def describe(self) -> dict[str, Any]:
        return {"name": "smc" if self.smc else "loopshape", "source": "sim.engine's law (sim.plant_control.EngineController)"}


@dataclass(frozen=True)
class CascadeGains:
    """Gains of :class:`CascadeController` (per unit error, as accelerations: inertia and mass scale them).

    The rate loop is designed on the motor lag ``tau`` the plant states (``[body]`` or the effectors'
    dynamics): crossover ``rate_p = 1 / (2.5 tau)`` (12 rad/s at hexa-x's 1/30 s, about 70 deg of
    phase margin against the lag alone), integral zero at ``rate_i / rate_p = 1.5`` rad/s, no D (the
    lag leaves no room for it).  Attitude P is half the rate crossover (6 /s, PX4's ``MC_ROLL_P`` is
    6.5).  Yaw: heading P 2.8 /s (PX4 ``MC_YAW_P``), yaw-rate P 4 /s, no integral (a multirotor that
    lost a rotor gives yaw up; an integral would only wind).  Vertical: PX4's ``MPC_Z_P`` 1 /s,
    ``MPC_Z_VEL_P_ACC`` 4 /s, ``MPC_Z_VEL_I_ACC`` 2 /s^2.
    """

    attitude_p: float = 6.0      #: 1/s, roll and pitch: rate command per attitude error
    rate_p: float = 12.0         #: 1/s, roll and pitch: angular acceleration per rate error
    rate_i: float = 18.0         #: 1/s^2
    yaw_p: float = 2.8           #: 1/s, heading
    yaw_rate_p: float = 4.0      #: 1/s
    altitude_p: float = 1.0      #: 1/s, vertical speed command per altitude error
    climb_p: float = 4.0         #: 1/s, vertical acceleration per vertical-speed error
    climb_i: float = 2.0         #: 1/s^2

    @classmethod
    def for_motor_lag(cls, tau: float) -> CascadeGains:
        """The rate loop at ``1 / (2.5 tau)``, attitude at half of it, the rest as stated."""
        rate_p = 1.0 / (2.5 * tau)
        return cls(attitude_p=0.5 * rate_p, rate_p=rate_p, rate_i=1.5 * rate_p)


@dataclass(frozen=True)
class VelocityHold:
    """A horizontal velocity loop above the cascade's attitude loop (PX4's velocity PI, no position loop).

    The reference is a ground speed ``speed`` m/s due north, reached from the hover on a ramp of ``accel``
    m/s^2, and zero east.  The loop's acceleration ``a = p e + i int(e) + the ramp's acceleration`` (NED) is
    turned into the heading frame by the measured heading (yaw may be given up) and into attitude
    set-points ``theta_d = -atan(a_x / g)``, ``phi_d = atan(a_y cos(theta_d) / g)``, the tilt held to
    ``tilt_max_deg``.  Gains are PX4's ``MPC_XY_VEL_P_ACC`` 1.8 /s and ``MPC_XY_VEL_I_ACC`` 0.4 /s^2; the ramp
    (PX4's ``MPC_ACC_HOR`` is 3 m/s^2) and the tilt limit (PX4's ``MPC_TILTMAX_AIR`` is 45 deg) are this
    loop's own choices, gentler than PX4's.  The speed comes from the plant's state (``v_north_mps``,
    ``v_east_mps``), as a navigation filter's would, without noise; with this loop the altitude and
    vertical-speed loops read the down speed (``climb_mps``) instead of body ``w``.
    """

    speed: float = 0.0          #: m/s, ground speed held due north after the ramp (0: hold the hover)
    accel: float = 1.0          #: m/s^2, the ramp from the hover to ``speed``
    p: float = 1.8              #: 1/s, acceleration per velocity error
    i: float = 0.4              #: 1/s^2
    tilt_max_deg: float = 35.0  #: deg, the largest tilt the loop asks for

    def reference(self, t: float) -> tuple[float, float]:
        """``(v_north, a_north)`` of the ramp at ``t`` s."""
        if self.accel <= 0 or abs(self.speed) <= self.accel * t:
            return self.speed, 0.0
        return float(np.sign(self.speed)) * self.accel * t, float(np.sign(self.speed)) * self.accel


#: the outputs the cascade reads, by name
CASCADE_OUTPUTS = ("phi", "theta", "psi", "p", "q", "r", "w")
#: the wrench components of the four axes it commands, in the order of ``v``
CASCADE_AXES = ("roll", "pitch", "yaw", "fz")


class CascadeController:
    """Attitude P / rate PI / vertical PI cascade for a hovering multirotor (module docstring).

    Parameters
    ----------
    fv : alloc.vehicle_file.Vehicle
        The vehicle file: its ``[body]`` (inertia, mass) and the axes' wrench components.
    vehicle : sim.model.PlantModel
        The loop's vehicle: output names and the controlled channels.
    gains : CascadeGains
    dt : float
        The frame period (s): the integrators' step.
    """

    def __init__(self, fv: Any, vehicle: Any, gains: CascadeGains, dt: float,
                 velocity: VelocityHold | None = None) -> None:
        if fv.body is None:
            raise ProblemError(f"body: the cascade controller scales its gains by the [body]'s inertia and mass; "
                               f"{fv.name!r} has no [body]", field="body")
        names = tuple(vehicle.output_names)
        missing = [o for o in CASCADE_OUTPUTS if o not in names]
        if missing:
            raise ProblemError(f"model.outputs: the cascade reads {', '.join(CASCADE_OUTPUTS)}; missing "
                               f"{', '.join(missing)}", field="model.outputs")
        comps = [a.component for a in fv.axes]
        if sorted(c or "" for c in comps) != sorted(CASCADE_AXES):
            raise ProblemError(f"axes: the cascade commands the axes roll, pitch, yaw, fz; the vehicle's are "
                               f"{comps}", field="axes")
        self.order = np.array([CASCADE_AXES.index(c) for c in comps])  # v[i] = wrench[order[i]]
        self.idx = {o: names.index(o) for o in CASCADE_OUTPUTS}
        self.channels = tuple(vehicle.channels)
        self.J = fv.body.J
        self.mass = fv.body.mass
        self.gains = gains
        self.dt = float(dt)
        self.velocity = velocity
        self.reset()

    def reset(self) -> None:
        self.velocity_integral = np.zeros(2)
        #: per frame: roll and pitch set-points (rad) and the north speed reference (m/s); zeros without a
        #: velocity loop (the level hover)
        self.setpoints: list[tuple[float, float, float]] = []
        self.rate_integral = np.zeros(2)
        self.climb_integral = 0.0
        self.altitude = 0.0  # the controller's own estimate: minus the integral of w (level hover)
        self.reference = np.zeros(len(self.channels))
        self.command = np.zeros(len(self.channels))
        self.pseudo = np.zeros(len(self.channels))
        self._rate_error = np.zeros(2)
        self._climb_error = 0.0
        self._v = np.zeros(4)

    def demand(self, step: int, z: np.ndarray, plant: Any) -> np.ndarray:
        g, i = self.gains, self.idx
        phi, theta, psi = z[i["phi"]], z[i["theta"]], z[i["psi"]]
        rates = np.array([z[i["p"]], z[i["q"]], z[i["r"]]])
        w = z[i["w"]]
        phi_d, theta_d, v_ref = 0.0, 0.0, 0.0
        if self.velocity is not None:
            phi_d, theta_d, v_ref = self._attitude_setpoint(step, psi, plant)
            # in forward flight body w carries the forward speed through the pitch: the vertical loops take
            # the navigation's down speed instead (in a level hover the two are the same)
            w = -plant.state()["climb_mps"]
        self.setpoints.append((phi_d, theta_d, v_ref))
        # attitude P (references: level or the velocity loop's, heading 0) -> body-rate commands
        rate_cmd = np.array([g.attitude_p * (phi_d - phi), g.attitude_p * (theta_d - theta), g.yaw_p * -_wrap(psi)])
        err = rate_cmd - rates
        self._rate_error = err[:2]
        alpha = np.array([g.rate_p * err[0] + g.rate_i * self.rate_integral[0],
                          g.rate_p * err[1] + g.rate_i * self.rate_integral[1],
                          g.yaw_rate_p * err[2]])
        moments = self.J @ alpha + np.cross(rates, self.J @ rates)  # Euler's gyroscopic term
        # altitude P -> vertical-speed command (w: body z, down positive) -> PI -> body z force deviation
        w_cmd = g.altitude_p * (-(0.0 - self.altitude))
        self._climb_error = w_cmd - w
        accel = g.climb_p * self._climb_error + g.climb_i * self.climb_integral
        tilt = max(np.cos(phi) * np.cos(theta), 0.5)  # hold the vertical thrust through a tilt (to 60 deg)
        dfz = self.mass * accel - self.mass * GRAVITY * (1.0 / tilt - 1.0)
        wrench = np.array([*moments, dfz])
        self._v = wrench[self.order]
        self.reference = np.array([*rate_cmd, w_cmd])[self._channel_order()]
        self.command = np.zeros(len(self.channels))
        self.pseudo = self._v.copy()
        self.altitude -= w * self.dt
        return self._v

    def _attitude_setpoint(self, step: int, psi: float, plant: Any) -> tuple[float, float, float]:
        """The velocity loop (:class:`VelocityHold`): roll and pitch set-points (rad) and the speed reference."""
        hold = self.velocity
        st = plant.state()
        v_ref, a_ref = hold.reference(step * self.dt)
        err = np.array([v_ref - st["v_north_mps"], -st["v_east_mps"]])
        a_ned = hold.p * err + hold.i * self.velocity_integral + np.array([a_ref, 0.0])
        c, s = np.cos(psi), np.sin(psi)
        a_x, a_y = c * a_ned[0] + s * a_ned[1], -s * a_ned[0] + c * a_ned[1]
        a_max = GRAVITY * np.tan(np.radians(hold.tilt_max_deg))
        norm = np.hypot(a_x, a_y)
        if norm > a_max:  # the tilt limit; the integral stops while it binds
            a_x, a_y = a_x * a_max / norm, a_y * a_max / norm
        else:
            self.velocity_integral += self.dt * err
        theta_d = -np.arctan(a_x / GRAVITY)
        phi_d = np.arctan(a_y * np.cos(theta_d) / GRAVITY)
        return float(phi_d), float(theta_d), float(v_ref)

    def _channel_order(self) -> np.ndarray:
        names = ("p", "q", "r", "w")
        return np.array([names.index(c) for c in self.channels])

    def update(self, u_cmd: np.ndarray, v_achieved: np.ndarray) -> None:
        """Integrate each loop's error unless the allocator fell short on its axis (conditional integration)."""
        short = np.abs(v_achieved - self._v) > 1e-6 * np.maximum(1.0, np.abs(self._v))
        by_axis = dict(zip((CASCADE_AXES[j] for j in self.order), short, strict=True))
        for j, axis in enumerate(("roll", "pitch")):
            if not by_axis[axis]:
                self.rate_integral[j] += self.dt * self._rate_error[j]
        if not by_axis["fz"]:
            self.climb_integral += self.dt * self._climb_error

    def describe(self) -> dict[str, Any]:
        return {"name": "cascade", "gains": asdict(self.gains), "mass": self.mass, "inertia": self.J.tolist(),
                "velocity": None if self.velocity is None else asdict(self.velocity),
                "source": "sim.plant_control.CascadeController: attitude P, rate PI, vertical-speed PI, altitude P"
                          + ("" if self.velocity is None else ", velocity PI (VelocityHold)")}


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2.0 * np.pi) - np.pi)
