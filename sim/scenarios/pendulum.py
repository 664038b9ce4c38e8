"""Inverted pendulum on a translating cart (seed sections 2.2 and 3.1).

State ``z = [x, theta, x_dot, theta_dot]`` (cart position in m, pendulum angle
from upright in rad), inputs ``[u, tau]`` (cart force in N, pendulum torque in
N m).  The single-input controllers use the force only (``tau = 0``).

Model
-----
Nonlinear equations of motion, seed Eq 2.49::

    (M + m) x'' + Fx x' + m L cos(theta) theta'' - m L theta'^2 sin(theta) = u
    J theta'' + Ftheta theta' - m L g sin(theta) + m L cos(theta) x''     = tau

and their linearisation about ``theta = 0`` (seed section 2.2, first state
equation).  Parameters are the seed's table in section 2.2.  Two numbers are
not printed and were recovered from the printed numeric ``A`` and ``B``:

* ``J = m L^2 = 0.08`` kg m^2 (point-mass pendulum): the printed
  ``B = [0, 0, 0.3333, -0.8333]`` is ``[J, -m L] / (J (M + m) - m^2 L^2)``,
  which gives ``m L / D = 0.8333`` and ``J / D = 0.3333``, i.e. ``D = 0.24``
  and ``J = 0.08``.
* ``g = 9.807`` m/s^2: the printed ``A[2,1] = -1.6345 = -g / 6`` and
  ``A[3,1] = 28.6037 = 2.91667 g``; ``g = 9.81`` would print ``-1.6350`` and
  ``28.6125``, ``g = 9.80665`` would print ``-1.6344`` and ``28.6027``.

Controllers (``controller=``)
-----------------------------
``"smc"``
    Regular-form SMC of seed section 2.2: ``sigma = S z`` with ``S`` from the
    LQ sliding-surface design (``Q = diag(10, 10, 1, 1)``) and
    ``u = [U_eq z] + rho * sat(sigma / epsilon)`` (``U_eq`` only when
    ``equivalent_control=True``).  Section 3.1 uses ``rho = 50``,
    ``epsilon = 0.1`` and no ``U_eq``: these are the defaults.
``"lqr"``
    ``u = -K z`` with the same ``Q`` and ``R = 0.01`` (seed section 2.2).

The seed's section 3.1 actuator-bandwidth demonstration is
``actuator_bandwidth=None`` (Fig 3-1), ``20.0`` (Fig 3-2) and ``13.0``
(Fig 3-3), a first-order actuator ``a / (s + a)`` between controller and cart;
:data:`ACTUATOR_CASES` names them.

The ``method`` argument of the scenario registry is accepted and ignored: a
single force input has no allocation problem (``SimResult.method`` is None).
The loop is flown by :func:`sim.scenarios.classic.run_classic`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.boundary_layer import static_boundary_layer
from sim.design import equivalent_control_gain, lq_sliding_surface, lqr_gain
from sim.result import SimResult
from sim.scenarios.classic import classic_scenario, run_classic

__all__ = [
    "PendulumParameters",
    "NOMINAL",
    "AFTER_FAILURE",
    "ACTUATOR_CASES",
    "Q_WEIGHT",
    "R_WEIGHT",
    "linear_model",
    "nonlinear_derivative",
    "SMCDesign",
    "smc_design",
    "run",
]


@dataclass(frozen=True)
class PendulumParameters:
    """Physical parameters of the cart and pendulum (seed section 2.2 table).

    Attributes
    ----------
    M : float
        Cart mass, kg.
    m : float
        Pendulum mass, kg.
    L : float
        Rod length, m.
    Fx : float
        Linear friction coefficient, kg/s.
    Ftheta : float
        Angular friction coefficient, kg m^2 (per s).
    g : float
        Gravity, m/s^2; 9.807 reproduces the seed's printed ``A`` (see module
        docstring).
    """

    M: float = 3.0  # seed section 2.2 table, nominal
    m: float = 0.50
    L: float = 0.4
    Fx: float = 6.0
    Ftheta: float = 0.005
    g: float = 9.807  # recovered from the printed A, see module docstring

    @property
    def J(self) -> float:
        """Pendulum inertia ``m L^2`` (not printed; reproduces the printed ``B``)."""
        return self.m * self.L**2


#: Seed section 2.2 table, "Nominal Value".
NOMINAL = PendulumParameters()
#: Seed section 2.2 table, "Value after 'Failure'".
AFTER_FAILURE = PendulumParameters(M=30.0, m=5.0, L=0.8, Fx=25.0, Ftheta=0.05)

#: Seed section 3.1, the three actuator cases (Figs 3-1, 3-2, 3-3), rad/s.
ACTUATOR_CASES: dict[str, float | None] = {"none": None, "actuator_20": 20.0, "actuator_13": 13.0}

#: Seed section 2.2, LQ weights for both the sliding surface and the LQR.
Q_WEIGHT = np.diag([10.0, 10.0, 1.0, 1.0])
R_WEIGHT = 0.01

FAILURES = {
    "plant_change": "masses, length and friction jump to the seed's 'after failure' values "
    "(section 2.2 table) at failure_time (default 3 s)",
}

# |x| beyond 100 m or |theta| beyond 90 deg (pendulum fallen) counts as diverged.
OUTPUT_BOUND = np.array([100.0, math.pi / 2])


def linear_model(p: PendulumParameters = NOMINAL) -> tuple[np.ndarray, np.ndarray]:
    """Linearisation of Eq 2.49 about ``theta = 0`` (seed section 2.2).

    Returns
    -------
    A : ndarray, shape (4, 4)
    B : ndarray, shape (4, 2)
        Columns for the force ``u`` and the torque ``tau``.
    """
    D = p.J * (p.M + p.m) - (p.m * p.L) ** 2
    mL = p.m * p.L
    A = np.array(
        [
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, -(mL**2) * p.g / D, -p.J * p.Fx / D, mL * p.Ftheta / D],
            [0.0, (p.M + p.m) * mL * p.g / D, mL * p.Fx / D, -(p.M + p.m) * p.Ftheta / D],
        ]
    )
    B = np.array([[0.0, 0.0], [0.0, 0.0], [p.J / D, -mL / D], [-mL / D, (p.M + p.m) / D]])
    return A, B


def nonlinear_derivative(p: PendulumParameters, z: np.ndarray, u: float, tau: float = 0.0) -> np.ndarray:
    """Right-hand side of the nonlinear equations of motion, seed Eq 2.49.

    The two accelerations solve the 2x2 mass-matrix system
    ``[[M+m, mL cos], [mL cos, J]] [x'', theta''] =
    [u - Fx x' + mL theta'^2 sin, tau - Ftheta theta' + mLg sin]``.
    """
    _, th, xd, thd = z
    s, c = math.sin(th), math.cos(th)
    mL = p.m * p.L
    a11, a12, a22 = p.M + p.m, mL * c, p.J
    r1 = u - p.Fx * xd + mL * thd * thd * s
    r2 = tau - p.Ftheta * thd + mL * p.g * s
    det = a11 * a22 - a12 * a12
    return np.array([xd, thd, (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det])


@dataclass(frozen=True)
class SMCDesign:
    """Single-input regular-form SMC design of seed section 2.2.

    Attributes
    ----------
    S : ndarray, shape (4,)
        Switching function ``sigma = S z``.
    K_eq : ndarray, shape (4,)
        Equivalent-control gain, ``U_eq = K_eq z`` (Eq 2.15).
    K_lqr : ndarray, shape (4,)
        LQR gain for ``u = -K_lqr z``.
    """

    S: np.ndarray
    K_eq: np.ndarray
    K_lqr: np.ndarray


def smc_design(p: PendulumParameters = NOMINAL) -> SMCDesign:
    """Design the force-input SMC and LQR of seed section 2.2 on the linear model."""
    A, B = linear_model(p)
    Bu = B[:, :1]
    S = lq_sliding_surface(A, Bu, Q_WEIGHT)
    return SMCDesign(
        S=S[0],
        K_eq=equivalent_control_gain(A, Bu, S)[0],
        K_lqr=lqr_gain(A, Bu, Q_WEIGHT, R_WEIGHT)[0],
    )


@classic_scenario("pendulum", failures=FAILURES, default_duration=10.0, description="Inverted pendulum on a "
                  "cart, single-input regular-form SMC or LQR (seed sections 2.2 and 3.1; actuator_bandwidth=None/20/13 "
                  "reproduces Figs 3-1..3-3)")
def run(
    *, failure: str | None, duration: float, dt: float, seed: int,
    controller: str = "smc",
    rho: float = 50.0,
    epsilon: float = 0.1,
    equivalent_control: bool = False,
    switching_until: float | None = None,
    actuator_bandwidth: float | None = None,
    model: str = "linear",
    x0: float = -1.0,
    theta0_deg: float = -10.0,
    noise_std: float = 0.0,
    disturbance_bias: float = 0.0,
    disturbance_time: float = 5.0,
    failure_time: float = 3.0,
) -> SimResult:
    """Simulate the cart-pendulum regulator.

    The registry arguments ``method``, ``allocator_knows_failure`` and
    ``progress`` are accepted and ignored (one input, nothing to allocate; see
    :func:`sim.scenarios.classic.classic_scenario`).

    Parameters
    ----------
    failure : {None, "plant_change"}
        ``"plant_change"`` switches the plant (not the controller) to
        :data:`AFTER_FAILURE` at ``failure_time``.
    duration : float
        Seconds; the registry's default is 10.
    dt : float
        Fixed Heun (ODE2) step, seed default 0.0005 s.
    seed : int
        Seed of the control-input noise generator.
    controller : {"smc", "lqr"}
    rho, epsilon : float
        Switching gain and boundary-layer thickness of
        ``rho * sat(sigma / epsilon)`` (seed section 3.1: 50 and 0.1).
    equivalent_control : bool
        Add ``U_eq z`` (seed Figs 2-15, 2-17, 2-18, 2-20).
    switching_until : float, optional
        Switch the ``rho`` term off at this time (seed Fig 2-15: 0.15 s, the
        "reaching phase only" case).
    actuator_bandwidth : float, optional
        First-order actuator ``a / (s + a)`` on the force; None means none
        (seed section 3.1 and :data:`ACTUATOR_CASES`).
    model : {"linear", "nonlinear"}
        Plant model: the linearisation or Eq 2.49.
    x0, theta0_deg : float
        Initial cart position (m) and angle (deg); seed section 3.1: -1, -10.
    noise_std : float
        Standard deviation of white Gaussian noise added to the force, one
        sample held per step (seed Figs 2-19/2-20; the level is not printed).
    disturbance_bias, disturbance_time : float
        Step bias added to the force from ``disturbance_time`` (seed Figs
        2-19/2-20: 10 at 5 s).
    failure_time : float
        Time of ``failure="plant_change"``.

    Returns
    -------
    SimResult
        Channels ``x`` and ``theta`` regulated to zero; ``pseudo`` is the
        commanded force, ``effectors`` the force reaching the cart (after the
        actuator, before the disturbance); ``extra`` holds ``sigma``,
        ``x_dot``, ``theta_dot`` and ``disturbance``.
    """
    if controller not in ("smc", "lqr"):
        raise ValueError(f"controller must be 'smc' or 'lqr', got {controller!r}")
    if model not in ("linear", "nonlinear"):
        raise ValueError(f"model must be 'linear' or 'nonlinear', got {model!r}")
    if actuator_bandwidth is not None and actuator_bandwidth <= 0:
        raise ValueError(f"actuator_bandwidth must be positive or None, got {actuator_bandwidth!r}")
    if epsilon <= 0:
        raise ValueError(f"epsilon must be positive, got {epsilon!r}")
    rng = np.random.default_rng(seed)

    design = smc_design(NOMINAL)
    plants = {NOMINAL: linear_model(NOMINAL), AFTER_FAILURE: linear_model(AFTER_FAILURE)}
    S, K_eq, K_lqr = design.S, design.K_eq, design.K_lqr

    def control(t: float, z: np.ndarray) -> tuple[float, float]:
        sigma = float(S @ z)
        if controller == "lqr":
            return -float(K_lqr @ z), sigma
        u = float(K_eq @ z) if equivalent_control else 0.0
        if switching_until is None or t < switching_until:
            u += float(static_boundary_layer(sigma, rho, epsilon))
        return u, sigma

    def hold(t: float) -> tuple[PendulumParameters, float]:
        """Plant and force disturbance over the step; one noise sample per step."""
        p = AFTER_FAILURE if (failure == "plant_change" and t >= failure_time) else NOMINAL
        d = (disturbance_bias if t >= disturbance_time else 0.0) + (noise_std * rng.standard_normal() if noise_std else 0.0)
        return p, d

    # State X = [x, theta, x_dot, theta_dot, delta] (delta: actuator output, 0 without actuator).
    def derivative(t: float, X: np.ndarray, held: tuple[PendulumParameters, float]) -> tuple[np.ndarray, tuple[float, float, float]]:
        p, d = held
        z, delta = X[:4], X[4]
        u_c, sigma = control(t, z)
        if actuator_bandwidth is None:
            force, delta_dot = u_c, 0.0
        else:
            force, delta_dot = delta, actuator_bandwidth * (u_c - delta)
        if model == "linear":
            A, B = plants[p]
            z_dot = A @ z + B[:, 0] * (force + d)
        else:
            z_dot = nonlinear_derivative(p, z, force + d)
        X_dot = np.empty(5)
        X_dot[:4], X_dot[4] = z_dot, delta_dot
        return X_dot, (u_c, sigma, d)

    flown = run_classic(
        derivative, np.array([x0, math.radians(theta0_deg), 0.0, 0.0, 0.0]), duration=duration, dt=dt,
        n_signals=3, outputs=slice(0, 2), output_bound=OUTPUT_BOUND, hold=hold,
    )
    X, u_c = flown.states, flown.signals[:, 0]
    zeros = np.zeros((flown.t.size, 2))
    return flown.result(
        "pendulum", failure, failure_time,
        channels=["x", "theta"],
        reference=zeros,
        output=X[:, :2],
        command=zeros.copy(),
        pseudo=u_c[:, None],
        effectors=(u_c if actuator_bandwidth is None else X[:, 4])[:, None],
        effector_rates=flown.rates[:, 4:5],
        effector_names=["force"],
        extra={"sigma": flown.signals[:, 1], "x_dot": X[:, 2], "theta_dot": X[:, 3], "disturbance": flown.signals[:, 2]},
    )
