"""F-16 pitch-rate tracking with a postfilter SMC (seed section 3.2.1, after Shtessel).

Plant (seed Eq 3.5), short-period approximation at Mach 0.7, 10,000 ft::

    [alpha, q]' = (A_n + dA 1(t - 5)) [alpha, q] + (B_n + dB 1(t - 5)) delta_e
    delta_e'    = a (delta_c - delta_e)            a = 20 rad/s

with the "failure" at 5 s a 50 % loss of horizontal tail area.  The open-loop
short period is statically unstable (eigenvalues 0.72 and -3.13 rad/s
nominal, 1.24 and -3.19 after the failure), so an elevator held at a position
limit loses the aircraft.

Reference model (seed section 3.2.1, ``A_r``, ``B_r``) driven by the pilot
command ``u_p``: pulses of 1 s at 0, 3, 6 and 9 s with polarities -, +, -, +
and amplitude 0.1 (Figs 3-7..3-9) or 0.2 (Figs 3-10..3-13); the pitch-rate
reference ``q_r`` is its second state.

SMC law (seed section 3.2.1) with ``e = q_r - q``::

    sigma   = e' + 5 e + 25 int(e)
    v       = -10 sat(sigma / eps)           (pseudo-command: elevator rate)
    delta_c = delta + v / a_design            (postfilter, a_design = 20)

``eps = 0.1`` for the static boundary layer; the dynamic boundary layer
(seed Eqs 3.6-3.8, :class:`sim.boundary_layer.DynamicBoundaryLayer`) widens it
to keep ``v`` within the limits ``delta_max = 0.37`` rad and
``rate_max = 10`` rad/s.  ``e'`` uses the measured pitch acceleration
``q' = A[1] x + B[1] delta`` (the postfilter needs the actuator position
anyway, seed section 3.2).

:data:`SEED_CASES` maps each of the seed's figures to the keyword arguments
reproducing it.  The ``method`` argument of the registry is ignored: one
elevator, nothing to allocate.  The loop is flown by
:func:`sim.scenarios.classic.run_classic`.
"""

from __future__ import annotations

import numpy as np

from sim.boundary_layer import DynamicBoundaryLayer, static_boundary_layer
from sim.result import SimResult
from sim.scenarios.classic import classic_scenario, run_classic

__all__ = ["A_N", "B_N", "DELTA_A", "DELTA_B", "A_REF", "B_REF", "SEED_CASES", "pilot_command", "run"]

# seed section 3.2.1 (Shtessel's model), Eq 3.5
A_N = np.array([[-1.1500, 0.9937], [3.7240, -1.2600]])
DELTA_A = np.array([[0.0400, 0.0031], [1.8560, 0.4200]])
B_N = np.array([-0.1770, -19.5000])
DELTA_B = np.array([0.0885, 9.7500])
# seed section 3.2.1, reference model
A_REF = np.array([[-1.2693, 0.9531], [-9.4176, -5.7307]])
B_REF = np.array([-0.1770, -19.5000])

ACTUATOR_BANDWIDTH = 20.0  # seed Eq 3.5, rad/s
DELTA_MAX = 0.37  # seed section 3.2.1, rad
RATE_MAX = 10.0  # seed section 3.2.1, rad/s
RHO = -10.0  # seed section 3.2.1, switching gain
EPSILON = 0.1  # seed section 3.2.1, static boundary layer
C_PROPORTIONAL = 5.0  # seed section 3.2.1, sigma coefficient of e
C_INTEGRAL = 25.0  # seed section 3.2.1, sigma coefficient of int(e)
PULSE_TIMES = (0.0, 3.0, 6.0, 9.0)  # seed section 3.2.1, s
PULSE_SIGNS = (-1.0, 1.0, -1.0, 1.0)
PULSE_WIDTH = 1.0
FAILURE_TIME = 5.0  # seed Eq 3.5, 1(t - 5)

FAILURES = {"tail_loss": "50 % loss of horizontal tail area at 5 s: A += dA, B += dB (seed Eq 3.5)"}

# |q| beyond 10 rad/s (570 deg/s) is far outside the envelope: diverged.
OUTPUT_BOUND = 10.0

#: The seed's figures (section 3.2.1) as keyword arguments of :func:`run`.
SEED_CASES: dict[str, dict[str, object]] = {
    "fig_3_7": dict(failure=None, limits=False, pulse_amplitude=0.1, boundary_layer="static"),
    "fig_3_8": dict(failure="tail_loss", limits=False, pulse_amplitude=0.1, boundary_layer="static"),
    "fig_3_9": dict(failure="tail_loss", limits=True, pulse_amplitude=0.1, boundary_layer="static"),
    "fig_3_10": dict(failure="tail_loss", limits=True, pulse_amplitude=0.2, boundary_layer="static"),
    "fig_3_11": dict(failure="tail_loss", limits=True, pulse_amplitude=0.2, boundary_layer="dynamic"),
    "fig_3_12": dict(
        failure="tail_loss", limits=True, pulse_amplitude=0.2, boundary_layer="dynamic", actuator_bandwidth=10.0, design_bandwidth=10.0
    ),
    "fig_3_13": dict(
        failure="tail_loss", limits=True, pulse_amplitude=0.2, boundary_layer="dynamic", actuator_bandwidth=10.0, design_bandwidth=20.0
    ),
}


def pilot_command(t: float, amplitude: float) -> float:
    """Pilot pitch-rate pulses of seed section 3.2.1 (1 s long, polarities -, +, -, +)."""
    for t0, s in zip(PULSE_TIMES, PULSE_SIGNS):
        if t0 <= t < t0 + PULSE_WIDTH:
            return s * amplitude
    return 0.0


@classic_scenario("f16", failures=FAILURES, default_duration=12.0, description="F-16 short-period pitch-rate "
                  "tracking, postfilter SMC with static or dynamic boundary layer (seed section 3.2.1, Figs 3-7..3-13 "
                  "via SEED_CASES)")
def run(
    *, failure: str | None, duration: float, dt: float, seed: int,
    pulse_amplitude: float = 0.1,
    limits: bool = True,
    boundary_layer: str = "static",
    actuator_bandwidth: float = ACTUATOR_BANDWIDTH,
    design_bandwidth: float = ACTUATOR_BANDWIDTH,
) -> SimResult:
    """Simulate F-16 pitch-rate tracking.

    The registry arguments ``method``, ``allocator_knows_failure`` and
    ``progress`` are accepted and ignored (one elevator, nothing to allocate;
    see :func:`sim.scenarios.classic.classic_scenario`).

    Parameters
    ----------
    failure : {None, "tail_loss"}
        Seed Eq 3.5 failure at 5 s.
    duration : float
        Seconds; the registry's default is 12 (the last pulse ends at 10 s).
    dt : float
        Fixed Heun (ODE2) step, seed default 0.0005 s.
    seed : int
        Ignored: the scenario has no noise.
    pulse_amplitude : float
        Pilot pulse amplitude, rad/s (seed: 0.1, or 0.2 to hit the limits).
    limits : bool
        Model the actuator position (0.37 rad) and rate (10 rad/s) limits.
    boundary_layer : {"static", "dynamic"}
        Static ``eps = 0.1`` or Shtessel's dynamic layer (Eqs 3.6-3.8).
    actuator_bandwidth : float
        True actuator bandwidth ``a``, rad/s (seed: 20; 10 in Figs 3-12, 3-13).
    design_bandwidth : float
        ``a_delta`` of the postfilter and of Eq 3.7 (seed: 20; 10 in Fig 3-12).

    Returns
    -------
    SimResult
        Channel ``q``: ``reference`` is ``q_r``, ``command`` the pilot pulses,
        ``pseudo`` the rate demand ``v``, ``effectors`` the elevator.  ``extra``
        holds ``sigma``, ``epsilon`` (boundary-layer thickness), ``alpha`` and
        ``delta_c``.
    """
    del seed  # no noise
    if boundary_layer not in ("static", "dynamic"):
        raise ValueError(f"boundary_layer must be 'static' or 'dynamic', got {boundary_layer!r}")
    if actuator_bandwidth <= 0 or design_bandwidth <= 0:
        raise ValueError(f"bandwidths must be positive, got actuator_bandwidth={actuator_bandwidth!r}, design_bandwidth={design_bandwidth!r}")
    delta_max = DELTA_MAX if limits else np.inf
    rate_max = RATE_MAX if limits else np.inf
    dynamic = (
        DynamicBoundaryLayer(rho=RHO, eps_min=EPSILON, a_delta=design_bandwidth, delta_max=DELTA_MAX, rate_max=RATE_MAX)
        if boundary_layer == "dynamic"
        else None
    )
    plants = {False: (A_N, B_N), True: (A_N + DELTA_A, B_N + DELTA_B)}

    # State X = [alpha, q, delta, alpha_r, q_r, int(e)]; signals u_p, v, sigma, eps, delta_c.
    def derivative(t: float, X: np.ndarray, failed: bool) -> tuple[np.ndarray, tuple[float, float, float, float, float]]:
        A, B = plants[failed]
        x, delta, xr = X[:2], X[2], X[3:5]
        u_p = pilot_command(t, pulse_amplitude)
        x_dot = A @ x + B * delta
        xr_dot = A_REF @ xr + B_REF * u_p
        e = xr[1] - x[1]
        sigma = (xr_dot[1] - x_dot[1]) + C_PROPORTIONAL * e + C_INTEGRAL * X[5]
        if dynamic is None:
            v, eps = float(static_boundary_layer(sigma, RHO, EPSILON)), EPSILON
        else:
            v_arr, eps_arr = dynamic.command(sigma, delta)
            v, eps = float(v_arr[0]), float(eps_arr[0])
        delta_c = delta + v / design_bandwidth
        rate = min(max(actuator_bandwidth * (delta_c - delta), -rate_max), rate_max)
        if (delta >= delta_max and rate > 0.0) or (delta <= -delta_max and rate < 0.0):
            rate = 0.0
        X_dot = np.array([x_dot[0], x_dot[1], rate, xr_dot[0], xr_dot[1], e])
        return X_dot, (u_p, v, sigma, eps, delta_c)

    def clamp_elevator(X: np.ndarray) -> None:
        """The position limit is an integrator clamp, re-applied after each step."""
        X[2] = min(max(X[2], -delta_max), delta_max)

    flown = run_classic(
        derivative, np.zeros(6), duration=duration, dt=dt, n_signals=5, outputs=slice(1, 2),
        output_bound=OUTPUT_BOUND, hold=lambda t: failure == "tail_loss" and t >= FAILURE_TIME,
        after_step=clamp_elevator,
    )
    X, signal = flown.states, flown.signals
    return flown.result(
        "f16", failure, FAILURE_TIME,
        channels=["q"],
        reference=X[:, 4:5],
        output=X[:, 1:2],
        command=signal[:, 0:1],
        pseudo=signal[:, 1:2],
        effectors=X[:, 2:3],
        effector_rates=flown.rates[:, 2:3],
        effector_names=["elevator"],
        effector_limits=(np.array([-delta_max]), np.array([delta_max])) if limits else None,
        rate_limits=(np.array([-rate_max]), np.array([rate_max])) if limits else None,
        extra={"sigma": signal[:, 2], "epsilon": signal[:, 3], "alpha": X[:, 0], "delta_c": signal[:, 4]},
    )
