"""DC-8 bank-angle tracking with a three-loop SMC (seed section 3.2.2, after Shtessel).

Plant: linear lateral-directional model, flight condition 8003 of McRuer,
Ashkenas and Graham, as printed in seed section 3.2.2; states
``[v, p, r, phi]`` (ft/s, rad/s, rad/s, rad), inputs ``[delta_a, delta_r]``
(rad).  Both actuators ``20 / (s + 20)``.

The printed input matrix is transcribed as printed, columns labelled
``[delta_a, delta_r]``.  Physically the first column (side force -18.33,
yaw 1.164) looks like a rudder and the second (roll 2.110) like an aileron,
but the seed's switching-gain signs (``rho_da = -50`` on the roll-rate
surface, ``rho_dr = 25`` on the yaw-rate surface) match the printed labels:
``L_da = -0.549 < 0`` needs a negative gain, ``N_dr = 0.0652 > 0`` a positive
one.  With the printed labels the roll/yaw pairing is not diagonally
dominant; the high-gain inner loop still converges (the matrix
``[[L_da, L_dr], [N_da, N_dr]] diag(rho)`` has eigenvalues 14.5 +- 54j).

Loops (seed section 3.2.2):

* Outer loop, bank angle: ``p_c = G_c(s) (phi_c - phi)`` with
  ``G_c(s) = 1778 (s + 2)^2 / (s + 20)^3``, designed against the roll-rate
  reference model ``p_r / p_c = 4 / (s^2 + 2 (0.8) 2 s + 2^2)``.  The yaw-rate
  reference is ``r_r = 0``.
* Inner loop, rates: ``eta = [p_r - p, r_r - r]``,
  ``sigma = eta' + C2 eta + C3 int(eta)`` (Eq 3.9) with ``C2 = 5``, ``C3 = 25``,
  and the postfilter ``delta_ci = delta_i + (1/a_delta) rho_i sat(sigma_i / eps)``
  (Eq 3.10), ``a_delta = 20``, ``eps = 1``, ``rho = (-50, 25)``.
* Actuator loop: ``sigma_di = (delta_ci - delta_i) + 10 int(delta_ci - delta_i)``,
  actuator input ``u_di = 10 sat(sigma_di / 1)``.

Failure (seed section 3.2.2, at 40 s): rows v, p, r of ``A`` halved, the
aileron column of ``B`` times 0.2, the aileron actuator bandwidth times 0.2.

The bank-angle command is not printed in the seed; this scenario uses a
square wave of amplitude ``command_amplitude`` (default 0.2 rad) and period
``command_period`` (default 20 s).  No actuator limits are modelled (the seed
states that with limits this design fails, without showing it).  The
``method`` argument of the registry is ignored: the design is a square,
decentralised SMC with no allocation.  The loop is flown by
:func:`sim.scenarios.classic.run_classic`.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from sim.boundary_layer import static_boundary_layer
from sim.result import SimResult
from sim.scenarios.classic import classic_scenario, run_classic

__all__ = ["A", "B", "run", "bank_command", "outer_loop_compensator"]

# seed section 3.2.2, flight condition 8003 (McRuer, Ashkenas & Graham)
A = np.array(
    [
        [-0.0868, 0.0, -824.2, 32.174],
        [-0.0054, -1.1810, 0.3340, 0.0],
        [0.0026, -0.0204, -0.2280, 0.0],
        [0.0, 1.0, 0.0, 0.0],
    ]
)
B = np.array([[-18.3300, 0.0], [-0.5490, 2.110], [1.1640, 0.0652], [0.0, 0.0]])

ACTUATOR_BANDWIDTH = 20.0  # seed section 3.2.2, both actuators 20/(s+20)
A_DELTA = 20.0  # seed Eq 3.10, postfilter design bandwidth
C2, C3 = 5.0, 25.0  # seed section 3.2.2, C2 = diag{5}, C3 = diag{25}
EPSILON = 1.0  # seed section 3.2.2
RHO = np.array([-50.0, 25.0])  # seed section 3.2.2, rho_da, rho_dr
ACT_INTEGRAL = 10.0  # seed section 3.2.2, actuator-loop sigma: e + 10 int(e)
ACT_RHO, ACT_EPSILON = 10.0, 1.0  # seed section 3.2.2, u = 10 sat(sigma/1)
REF_WN, REF_ZETA = 2.0, 0.8  # seed section 3.2.2, p/p_c = 4/(s^2 + 2(0.8)2 s + 2^2)
FAILURE_TIME = 40.0  # seed section 3.2.2, Fig 3-18
FAIL_A_ROWS, FAIL_AILERON_POWER, FAIL_AILERON_BANDWIDTH = 0.5, 0.2, 0.2  # seed section 3.2.2

FAILURES = {
    "aileron_and_stability": "at 40 s: rows v, p, r of A halved, aileron power x0.2, "
    "aileron actuator bandwidth x0.2 (seed section 3.2.2)",
}

# |phi| beyond pi rad or |r| beyond 10 rad/s: diverged.
OUTPUT_BOUND = np.array([np.pi, 10.0])


def outer_loop_compensator() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """State space of ``G_c(s) = 1778 (s + 2)^2 / (s + 20)^3`` (seed section 3.2.2)."""
    num = 1778.0 * np.polymul([1.0, 2.0], [1.0, 2.0])
    den = np.polymul(np.polymul([1.0, 20.0], [1.0, 20.0]), [1.0, 20.0])
    return signal.tf2ss(num, den)


def bank_command(t: float, amplitude: float, period: float) -> float:
    """Square-wave bank-angle command (not printed in the seed; chosen here)."""
    return amplitude if (t % period) < period / 2 else -amplitude


@classic_scenario("dc8", failures=FAILURES, default_duration=80.0, description="DC-8 bank-angle tracking: "
                  "loop-shaped outer loop, postfilter rate SMC, actuator-loop SMC (seed section 3.2.2)")
def run(*, failure: str | None, duration: float, dt: float, seed: int, command_amplitude: float = 0.2,
        command_period: float = 20.0, failure_time: float = FAILURE_TIME) -> SimResult:
    """Simulate DC-8 bank-angle tracking.

    The registry arguments ``method``, ``allocator_knows_failure`` and
    ``progress`` are accepted and ignored (square decentralised design,
    nothing to allocate; see :func:`sim.scenarios.classic.classic_scenario`).

    Parameters
    ----------
    failure : {None, "aileron_and_stability"}
    duration : float
        Seconds; the registry's default is 80.
    dt : float
        Fixed Heun (ODE2) step, seed default 0.0005 s.
    seed : int
        Ignored: the scenario has no noise.
    command_amplitude, command_period : float
        Square-wave bank command (rad, s).
    failure_time : float
        Seed: 40 s.

    Returns
    -------
    SimResult
        Channels ``phi`` (reference: the bank command) and ``r`` (reference
        0); ``pseudo`` holds the postfilter commands ``delta_c``,
        ``effectors`` the surfaces, ``extra`` the actuator inputs
        (``u_delta_a``, ``u_delta_r``), ``p``, ``p_r`` and the rate surfaces.
    """
    del seed  # no noise
    Ag, Bg, Cg, Dg = outer_loop_compensator()
    Cg, Dg = Cg[0], float(Dg[0, 0])
    A_fail = A.copy()
    A_fail[:3] *= FAIL_A_ROWS
    B_fail = B.copy()
    B_fail[:, 0] *= FAIL_AILERON_POWER
    healthy = (A, B, np.array([ACTUATOR_BANDWIDTH, ACTUATOR_BANDWIDTH]))
    failed = (A_fail, B_fail, np.array([ACTUATOR_BANDWIDTH * FAIL_AILERON_BANDWIDTH, ACTUATOR_BANDWIDTH]))
    ng = Ag.shape[0]
    # State X = [x(4), delta(2), int(delta_c - delta)(2), int(eta)(2), p_r, p_r', x_g(3)]
    i_x, i_d, i_ai, i_ei, i_g = slice(0, 4), slice(4, 6), slice(6, 8), slice(8, 10), slice(12, 12 + ng)

    # Signals: phi_c, delta_c(2), u_act(2), sigma(2).
    def derivative(t: float, X: np.ndarray, plant: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        Ap, Bp, bw = plant
        x, delta = X[i_x], X[i_d]
        x_dot = Ap @ x + Bp @ delta
        # outer loop: p_c = G_c (phi_c - phi); roll-rate reference model
        phi_c = bank_command(t, command_amplitude, command_period)
        e_phi = phi_c - x[3]
        xg = X[i_g]
        p_c = float(Cg @ xg) + Dg * e_phi
        pr, pr_dot = X[10], X[11]
        pr_ddot = REF_WN**2 * (p_c - pr) - 2 * REF_ZETA * REF_WN * pr_dot
        # inner loop (Eqs 3.9, 3.10); r_r = 0
        eta = np.array([pr - x[1], -x[2]])
        eta_dot = np.array([pr_dot - x_dot[1], -x_dot[2]])
        sigma = eta_dot + C2 * eta + C3 * X[i_ei]
        delta_c = delta + static_boundary_layer(sigma, RHO, EPSILON) / A_DELTA
        # actuator loop
        e_act = delta_c - delta
        u_act = static_boundary_layer(e_act + ACT_INTEGRAL * X[i_ai], ACT_RHO, ACT_EPSILON)
        delta_dot = bw * (u_act - delta)
        X_dot = np.concatenate([x_dot, delta_dot, e_act, eta, [pr_dot, pr_ddot], Ag @ xg + Bg[:, 0] * e_phi])
        return X_dot, np.concatenate([[phi_c], delta_c, u_act, sigma])

    flown = run_classic(
        derivative, np.zeros(12 + ng), duration=duration, dt=dt, n_signals=7, outputs=[3, 2],
        output_bound=OUTPUT_BOUND, hold=lambda t: failed if (failure is not None and t >= failure_time) else healthy,
    )
    X, signal = flown.states, flown.signals
    ref = np.column_stack([signal[:, 0], np.zeros(flown.t.size)])
    return flown.result(
        "dc8", failure, failure_time,
        channels=["phi", "r"],
        reference=ref,
        output=X[:, [3, 2]],
        command=ref.copy(),
        pseudo=signal[:, 1:3],
        effectors=X[:, i_d],
        effector_rates=flown.rates[:, i_d],
        effector_names=["aileron", "rudder"],
        extra={
            "p": X[:, 1],
            "p_r": X[:, 10],
            "u_delta_a": signal[:, 3],
            "u_delta_r": signal[:, 4],
            "sigma_p": signal[:, 5],
            "sigma_r": signal[:, 6],
        },
    )
