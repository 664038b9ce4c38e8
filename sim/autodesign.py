"""The seed's design procedure (section 4.3, steps 1-10) applied to a new vehicle's linear model.

Given the rigid-body model ``x' = A x + B u``, ``y = C x + D u`` (actuators excluded, step 1),
the controlled outputs (one channel each, a square architecture, step 3), the allocation
effectiveness ``B_v`` (the vehicle's axes) and the actuators, :func:`auto_design` returns the
observer-based sliding-mode controller of seed sections 3.3 and 4.3 and a linear baseline,
with every choice and the rule behind it in :attr:`AutoDesign.report`.

Pseudo-commands (step 3).  The controller's virtual control ``u_c`` of channel ``i`` is the
rate of its controlled output that the effectors are asked for: the model's input matrix is
fitted as ``B ~ M B_v`` (least squares; the residual is reported) and ``G = C_ctl M`` maps an
axis demand ``v`` to controlled-output rates, so ``v = G^-1 u_c`` (the loop's ``demand_map``)
makes ``y_ctl' = C_ctl A x + u_c`` whatever the units of the axes.  The plant seen by each
channel is then ``1/s`` at high frequency, and the loop-shaping of step 4 reads in rad/s.

Where the seed gives no number, the choice below is this module's (each is overridable by
name, :data:`DESIGN_OPTIONS`):

* limit frequency (step 1): the median of the actuators' first corner frequencies.  ICE's
  Table 4-5 gives 40 rad/s (eight of eleven surfaces at 40; LEF 17.8, nozzles 37).
* reference model (step 2): ``wn^2 / (s^2 + 2 zeta wn s + wn^2)`` with ``wn = 0.25`` x the
  limit frequency and ``zeta = 1``: on ICE that is seed Eq 4.22's alpha and roll models
  (``100 / (s^2 + 20 s + 100)``) exactly.
* sliding function (step 4): relative order one only, ``sigma = e + K_-1 int(e)`` (Eq 4.7 with
  ``K0 = 1``), ``K_-1`` = the reference bandwidth (ICE: 10 on alpha and beta).
* ``K_rho = rho / eps`` (step 4b, Eq 4.8), the crossover frequency of the loop without
  parasitic dynamics: 20 x the limit frequency ("very high crossover frequencies may result
  ... well beyond the limit frequency"; ICE's design crosses near 880-970 rad/s with 40 rad/s
  actuators), capped at ``0.5 / T`` so the per-frame gain of the boundary layer stays the
  seed's 0.5 (:func:`sim.settings.boundary_layer_at`), then lowered by factors of 2 until the
  step-10 check passes.
* ``rho`` (step 5): the largest pseudo-command the effectors can produce along the channel
  from trim (the attainable set's reach, an LP), so the control saturates where the effectors
  do; ``eps = rho / K_rho`` (step 6: the seed's constant ``rho / eps = K_rho``).  Steps 5 and 6
  by simulation are replaced by this rule.
* observers (step 8): one full-order observer per channel (seed section 3.3.2) with poles
  ``-(w_o + 0.1 j)``, ``j = 0..n-1``, ``w_o`` = the reference bandwidth (ICE's alpha observer:
  ``-10 - 0.1 j``).
* hedge (step 9, "if desired"): none; its filters are tuned per channel in the seed.
* check (step 10): the linear closed loop (plant, actuators, observers, the SMC in its
  boundary layer, a weighted pseudo-inverse standing in for the allocator, actuator delays
  and the hedge left out) must have every eigenvalue left of ``-stability_margin``.
* baseline: the linear equivalent of the same law without observer (Eq 4.3,
  ``K (1 + K_-1 / s)`` on the measured error), with the largest crossover from the same
  ladder that passes the same check with every closed-loop mode damped at least 0.3 (a
  classical margin; the SMC is held to none, its observers carry its robustness).  None when
  no gain passes (the tailless example: no PI on the measured error stabilises it).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize

from alloc.exceptions import OptionError, ProblemError
from sim.blocks import DEFAULT_DT, ActuatorSpec, observer_gain
from sim.model import TF, LoopShapedDesign, SMCDesign

__all__ = ["DESIGN_OPTIONS", "AutoDesign", "auto_design", "design_options", "relative_order", "pseudo_command_map",
           "channel_reach", "limit_frequency", "closed_loop_poles", "weighted_pinv"]

#: Overridable design choices: name -> (default, meaning).  ``None``: computed by the rule.
DESIGN_OPTIONS: dict[str, tuple[Any, str]] = {
    "limit_frequency": (None, "rad/s; default: median of the actuators' first corner frequencies (step 1)"),
    "reference_ratio": (0.25, "reference-model natural frequency / limit frequency (step 2)"),
    "reference_damping": (1.0, "reference-model damping ratio (step 2)"),
    "crossover_ratio": (20.0, "first K_rho tried, x the limit frequency (step 4b)"),
    "crossover": (None, "rad/s; K_rho = rho / eps of every channel, skips the ladder (step 4b)"),
    "frame_gain": (0.5, "cap of K_rho T, the per-frame gain of the boundary layer (step 6)"),
    "integral": (None, "K_-1 of the sliding function; default: the reference bandwidth (step 4a)"),
    "rho_scale": (1.0, "rho = rho_scale x the channel's reach from trim (step 5)"),
    "observer_bandwidth": (None, "rad/s; default: the reference bandwidth (step 8)"),
    "observer": (True, "observers on (false: feed back the measured outputs, seed Fig 4-95)"),
    "baseline_damping": (0.3, "least damping ratio of the baseline's closed loop (a classical loop-shaping margin)"),
    "stability_margin": (0.01, "1/s; every closed-loop eigenvalue but the neutral ones left of -margin (step 10)"),
    "command_fraction": (0.05, "peak pseudo-command of the sum-of-sines commands / rho"),
    "noise_fraction": (0.02, "sensor-noise gain on a controlled output / its command peak"),
    "static_bandwidth": (1000.0, "rad/s; first-order lag standing in for an effector without dynamics"),
}

#: Halvings of K_rho tried by the step-10 check before giving up.
MAX_HALVINGS = 12
#: A closed-loop eigenvalue this close to 0 (relative to the largest) is a free integrator, an
#: uncontrolled variable's neutral mode; every other one must be left of ``-stability_margin``.
NEUTRAL_TOL = 1e-9
#: Observer bandwidths tried, x the reference bandwidth (ICE: alpha 1, beta 0.1 of its 10 rad/s).
OBSERVER_LADDER = (1.0, 0.3, 0.1, 0.03)


@dataclass(frozen=True)
class AutoDesign:
    """What :func:`auto_design` returns: the controller, its baseline and the report.

    Attributes
    ----------
    smc : SMCDesign
    references : tuple of TF
        Reference model per channel (step 2).
    baseline : LoopShapedDesign or None
        Linear PI on the measured error, same sliding-function zero; None when no gain of
        the ladder passes the step-10 check (the report says so).
    demand_map : ndarray (k, k)
        ``v = demand_map u_c``: pseudo-commands (controlled-output rates) to axis demands.
    report : dict
        Every choice (value and rule), the checks' numbers; JSON-ready.
    """

    smc: SMCDesign
    references: tuple[TF, ...]
    baseline: LoopShapedDesign | None
    demand_map: np.ndarray
    report: dict[str, Any] = field(default_factory=dict)


def design_options(overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Every design choice: :data:`DESIGN_OPTIONS`' defaults with ``overrides`` checked and applied."""
    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(DESIGN_OPTIONS))
    if unknown:
        raise OptionError(f"design: unknown option(s) {unknown}; known: {sorted(DESIGN_OPTIONS)}", field="design")
    out = {name: default for name, (default, _) in DESIGN_OPTIONS.items()}
    for name, value in overrides.items():
        if name == "observer":
            if not isinstance(value, bool):
                raise ProblemError(f"design.observer: expected true or false, got {value!r}", field="design.observer")
        elif value is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
                raise ProblemError(f"design.{name}: expected a positive finite number, got {value!r}",
                                   field=f"design.{name}")
            value = float(value)
        out[name] = value
    return out


def relative_order(A: np.ndarray, B: np.ndarray, c: np.ndarray, d: np.ndarray, *, rtol: float = 1e-9) -> int:
    """Times output ``y = c x + d u`` is differentiated before ``u`` appears (step 4a's ``p``)."""
    scale = max(1.0, float(np.abs(B).max()) * float(np.abs(c).max()))
    if np.abs(d).max(initial=0.0) > rtol * scale:
        return 0
    row = np.asarray(c, dtype=float)
    for p in range(1, A.shape[0] + 1):
        if np.abs(row @ B).max() > rtol * scale:
            return p
        row = row @ A
    return A.shape[0] + 1  # no input reaches this output


def pseudo_command_map(B: np.ndarray, C_ctl: np.ndarray, B_axes: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """``demand_map = (C_ctl M)^-1`` with ``B ~ M B_axes`` (least squares): ``v`` per unit output rate.

    Raises ProblemError (field ``model.controlled``) when the controlled outputs are not as many
    as the axes or their rates cannot be set independently by the axes.
    """
    k = B_axes.shape[0]
    if C_ctl.shape[0] != k:
        raise ProblemError(f"model.controlled: {C_ctl.shape[0]} controlled outputs for {k} axes; the seed's "
                           "design is square (one channel per axis, section 4.3 step 3)", field="model.controlled")
    M = np.linalg.lstsq(B_axes.T, B.T, rcond=None)[0].T  # B ~ M B_axes
    residual = float(np.linalg.norm(B - M @ B_axes) / max(np.linalg.norm(B), np.finfo(float).tiny))
    G = C_ctl @ M
    cond = float(np.linalg.cond(G))
    if not cond < 1e8:
        raise ProblemError(f"model.controlled: the axes cannot set the controlled outputs' rates independently "
                           f"(cond(C_ctl M) = {cond:.3g})", field="model.controlled")
    return np.linalg.inv(G), {"fit_residual": residual, "cond": cond, "M": M.tolist()}


def channel_reach(B_axes: np.ndarray, umin: np.ndarray, umax: np.ndarray, direction: np.ndarray) -> float:
    """Largest ``t`` with ``t direction`` and ``-t direction`` both attainable from ``u = 0`` (an LP each way)."""
    m = B_axes.shape[1]
    reach = []
    for sign in (1.0, -1.0):
        # variables [u, t]: maximise t subject to B u = t sign d, umin <= u <= umax
        A_eq = np.hstack([B_axes, -sign * direction[:, None]])
        res = scipy.optimize.linprog(np.r_[np.zeros(m), -1.0], A_eq=A_eq, b_eq=np.zeros(B_axes.shape[0]),
                                     bounds=[*zip(umin, umax, strict=True), (0.0, None)], method="highs")
        reach.append(float(res.x[-1]) if res.status == 0 else 0.0)
    return min(reach)


def limit_frequency(actuators: Sequence[ActuatorSpec]) -> float:
    """Median first corner frequency (rad/s): ``a`` of ``a/(s+a)``; the lower real pole or ``wn`` of second order."""
    corners = []
    for a in actuators:
        if a.order == 1:
            corners.append(a.c1)
        else:
            disc = a.c1 * a.c1 - 4.0 * a.wn2
            corners.append(0.5 * (a.c1 - np.sqrt(disc)) if disc >= 0.0 else np.sqrt(a.wn2))
    return float(np.median(corners))


def _actuator_ss(actuators: Sequence[ActuatorSpec]) -> tuple[np.ndarray, ...]:
    """Block-diagonal state space of the (linear, unlimited) actuators: u_cmd -> u_act."""
    blocks = []
    for a in actuators:
        if a.order == 1:
            blocks.append((np.array([[-a.c1]]), np.array([[a.c1]]), np.array([[1.0]])))
        else:
            blocks.append((np.array([[0.0, 1.0], [-a.wn2, -a.c1]]), np.array([[0.0], [a.wn2]]), np.array([[1.0, 0.0]])))
    Aa = scipy.linalg.block_diag(*[b[0] for b in blocks])
    Ba = scipy.linalg.block_diag(*[b[1] for b in blocks])
    Ca = scipy.linalg.block_diag(*[b[2] for b in blocks])
    return Aa, Ba, Ca


def closed_loop_poles(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, controlled: Sequence[int], measured: Sequence[int],
    actuators: Sequence[ActuatorSpec], allocation: np.ndarray, demand_map: np.ndarray, k_rho: np.ndarray,
    integral: np.ndarray, observer_poles: Sequence[Sequence[float]] | None,
    observer_gains: Sequence[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of the linear closed loop of step 10 (reference inputs zero) and which are the channels'.

    ``u_c = K_rho (e + K_-1 xi)``, ``xi' = e``, ``e = -y_hat`` (observers) or ``-y`` (none, the
    baseline); ``u_cmd = allocation demand_map u_c``; actuators linear; plant ``(A, B, C, D)``.
    Each observer: ``xh' = A xh + B u_cmd + G (z - Cz xh - Dz u_cmd)`` (seed section 3.3).
    The second array is False for the neutral modes at the origin (:data:`NEUTRAL_TOL`): free
    integrators of uncontrolled variables.
    """
    n, k = A.shape[0], len(controlled)
    Aa, Ba, Ca = _actuator_ss(actuators)
    na = Aa.shape[0]
    Cz, Dz = C[list(measured)], D[list(measured)]
    K = allocation @ demand_map @ np.diag(k_rho)  # u_cmd = K (e + K_-1 xi)
    Ki = K @ np.diag(integral)
    obs = observer_poles is not None
    n_obs = k * n if obs else 0
    N = n + na + n_obs + k
    Acl = np.zeros((N, N))
    # the observers' rows, n + na .. n + na + n_obs, are filled block by block below
    ix, ia, ii = slice(0, n), slice(n, n + na), slice(n + na + n_obs, N)
    # e = -E z_state: rows selecting the feedback signal of each channel
    E = np.zeros((k, N))
    if obs:
        for i, c in enumerate(controlled):
            E[i, n + na + i * n: n + na + (i + 1) * n] = C[c]
    else:
        E[:, ix] = C[list(controlled)]
        E[:, ia] = D[list(controlled)] @ Ca
    ucmd = -K @ E
    ucmd[:, ii] += Ki
    Acl[ix, ix] = A
    Acl[ix, ia] = B @ Ca
    Acl[ia, :] = Ba @ ucmd
    Acl[ia, ia] += Aa
    Acl[ii, :] = -E
    if obs:
        for i, poles in enumerate(observer_poles):
            G = observer_gain(A, Cz, poles) if observer_gains is None else observer_gains[i]
            rows = slice(n + na + i * n, n + na + (i + 1) * n)
            Acl[rows, :] = (B - G @ Dz) @ ucmd
            Acl[rows, ix] += G @ Cz
            Acl[rows, ia] += G @ Dz @ Ca
            Acl[rows, rows] += A - G @ Cz
    eig = np.linalg.eigvals(Acl)
    # A mode at the origin is an uncontrolled variable's: a free integrator that no channel
    # regulates (a hovering hexacopter's attitude angles integrate the regulated rates; a
    # tailless aircraft holding alpha, p_s and beta leaves its bank angle free).  Step 3 asks
    # that those "remain stable": neutral is the most they may be.
    neutral = np.abs(eig) <= NEUTRAL_TOL * max(1.0, float(np.abs(eig).max()))
    return eig, ~neutral


def _placed_gain(A: np.ndarray, Cz: np.ndarray, poles: Sequence[float]) -> np.ndarray:
    """Observer gain with ``eig(A - G Cz) = poles``, checked: scipy's robust placement may stop short of its
    conditioning goal (a warning) while placing the poles exactly, which is all the observer needs."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Convergence was not reached", UserWarning)
        G = observer_gain(A, Cz, poles)
    got = np.sort_complex(np.linalg.eigvals(A - G @ Cz))
    want = np.sort_complex(np.asarray(poles, dtype=complex))
    if not np.allclose(got, want, rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(want).max()))):
        raise ProblemError(f"model.C: the observer poles {list(poles)} could not be placed (got {got.tolist()})",
                           field="model.C")
    return G


def _check_observable(A: np.ndarray, Cz: np.ndarray) -> None:
    """ProblemError (field ``model.C``) unless ``(A, Cz)`` is observable: seed section 3.3's observers need it."""
    n = A.shape[0]
    blocks, row = [], Cz
    for _ in range(n):
        blocks.append(row)
        row = row @ A
    sv = np.linalg.svd(np.vstack(blocks), compute_uv=False)
    rank = int(np.count_nonzero(sv > max(sv.max(initial=0.0), 1.0) * n * np.finfo(float).eps * 1e3))
    if rank < n:
        raise ProblemError(f"model.C: the measured outputs do not observe the state (observability rank {rank} of "
                           f"{n}); the observers of seed section 3.3 need it: fly without them (design "
                           "observer=false) or measure more outputs", field="model.C")


def weighted_pinv(B_axes: np.ndarray, Wu: np.ndarray | None) -> np.ndarray:
    """``Wu^-1 B^T (B Wu^-1 B^T)^-1``: the linear allocator standing in for the method in the step-10 check."""
    W_inv = np.diag(1.0 / (np.ones(B_axes.shape[1]) if Wu is None else np.asarray(Wu, dtype=float)))
    return W_inv @ B_axes.T @ np.linalg.inv(B_axes @ W_inv @ B_axes.T)


def auto_design(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, *, controlled: Sequence[int],
    measured: Sequence[int], output_names: Sequence[str], B_axes: np.ndarray, umin: np.ndarray, umax: np.ndarray,
    actuators: Sequence[ActuatorSpec], Wu: np.ndarray | None = None, frame_period: float = DEFAULT_DT,
    options: Mapping[str, Any] | None = None,
) -> AutoDesign:
    """Seed section 4.3 on ``(A, B, C, D)``: reference models, sliding functions, boundary layers, observers.

    ``umin``/``umax`` are the effector limits around trim (``u = 0`` is trim); ``options``
    overrides :data:`DESIGN_OPTIONS` by name.  See the module docstring for every rule.

    Raises
    ------
    ProblemError
        ``model.controlled`` when a controlled output is not of relative order one, the
        architecture is not square, or no crossover of the ladder passes the step-10 check.
    OptionError
        an unknown design option (a ``TypeError``); a malformed value is a ProblemError.
    """
    opt = design_options(options)
    controlled, measured = tuple(controlled), tuple(measured)
    k = len(controlled)
    report: dict[str, Any] = {"procedure": "seed section 4.3", "channels": [output_names[c] for c in controlled]}

    # step 3: square architecture, relative order, pseudo-command map
    orders = [relative_order(A, B, C[c], D[c]) for c in controlled]
    for i, p in enumerate(orders):
        if p > A.shape[0]:
            raise ProblemError(f"model.controlled[{i}]: no effector reaches output {output_names[controlled[i]]!r} "
                               "(C A^j B = 0 for every j)", field=f"model.controlled[{i}]")
        if p != 1:
            raise ProblemError(f"model.controlled[{i}]: output {output_names[controlled[i]]!r} has relative order "
                               f"{p}; the loop's sliding function sigma = K0 e + K_-1 int(e) (seed Eq 4.7) needs 1",
                               field=f"model.controlled[{i}]")
    demand_map, fit = pseudo_command_map(B, C[list(controlled)], B_axes)
    report["pseudo_commands"] = {
        "meaning": "u_c[i] = commanded rate of controlled output i; v = demand_map u_c (step 3)",
        "demand_map": demand_map.tolist(), "model_fit_residual": fit["fit_residual"], "cond": fit["cond"],
        "relative_order": orders,
    }

    # step 1: limit frequency from the actuators (excluded from the nominal plant)
    w_lim = opt["limit_frequency"] or limit_frequency(actuators)
    report["limit_frequency"] = {"value": w_lim, "unit": "rad/s",
                                 "rule": "given" if opt["limit_frequency"] else
                                 "median of the actuators' first corner frequencies"}

    # step 2: reference models
    wn, zeta = opt["reference_ratio"] * w_lim, opt["reference_damping"]
    references = tuple(((wn * wn,), (1.0, 2.0 * zeta * wn, wn * wn)) for _ in controlled)
    report["reference_model"] = {"wn": wn, "zeta": zeta, "tf": f"{wn * wn:.6g} / (s^2 + {2 * zeta * wn:.6g} s + "
                                 f"{wn * wn:.6g})", "rule": f"wn = {opt['reference_ratio']:g} x limit frequency"}

    # step 4a: sliding function sigma = e + K_-1 int(e)
    integral = np.full(k, opt["integral"] or wn)
    # step 5-6: rho from the attainable reach, eps = rho / K_rho
    reach = np.array([channel_reach(B_axes, umin, umax, demand_map[:, i]) for i in range(k)])
    if not np.all(reach > 0.0):
        bad = int(np.argmin(reach))
        raise ProblemError(f"model.controlled[{bad}]: the effectors cannot move output "
                           f"{output_names[controlled[bad]]!r} both ways from trim (reach 0)",
                           field=f"model.controlled[{bad}]")
    rho = opt["rho_scale"] * reach

    # step 4b, 8 and 10: K_rho from the ladder, the observers' bandwidth from theirs, checked on
    # the linear closed loop with the actuators
    n = A.shape[0]
    allocation = weighted_pinv(B_axes, Wu)
    cap = opt["frame_gain"] / frame_period

    def observers(w_obs: float) -> tuple[tuple[float, ...], ...]:
        return tuple(tuple(-(w_obs + 0.1 * j) for j in range(n)) for _ in controlled)

    placed: dict[Any, list[np.ndarray]] = {}  # one placement per observer set, not per K_rho

    def check(k_rho: float, poles: Any) -> dict[str, float]:
        if poles is not None and poles not in placed:
            placed[poles] = [_placed_gain(A, C[list(measured)], p) for p in poles]
        eig, visible = closed_loop_poles(A, B, C, D, controlled, measured, actuators, allocation, demand_map,
                                         np.full(k, k_rho), integral, poles, None if poles is None else placed[poles])
        live = eig[visible]
        damping = -live.real / np.abs(live)
        worst = int(np.argmin(damping))
        return {"K_rho": k_rho, "max_real_eig": float(live.real.max()), "neutral_modes": int(np.count_nonzero(~visible)),
                "min_damping": float(damping[worst]), "least_damped": [float(live[worst].real), float(abs(live[worst].imag))]}

    def passes(row: dict[str, float], damping: float = 0.0) -> bool:
        return row["max_real_eig"] < -opt["stability_margin"] and row["min_damping"] >= damping

    start = opt["crossover"] or min(opt["crossover_ratio"] * w_lim, cap)
    gains = [start] if opt["crossover"] else [start * 0.5**j for j in range(MAX_HALVINGS + 1)]
    if not opt["observer"]:
        bandwidths: list[float | None] = [None]
    elif opt["observer_bandwidth"]:
        bandwidths = [opt["observer_bandwidth"]]
    else:
        bandwidths = [wn * f for f in OBSERVER_LADDER]

    def search(bws: Sequence[float | None], damping: float = 0.0
               ) -> tuple[dict[str, float] | None, float | None, list[dict[str, float]]]:
        tried = []
        for w_obs in bws:
            for k_rho in gains:
                row = {**check(k_rho, None if w_obs is None else observers(w_obs)), "observer_bandwidth": w_obs}
                tried.append(row)
                if passes(row, damping):
                    return row, w_obs, tried
        return None, None, tried

    if opt["observer"]:
        _check_observable(A, C[list(measured)])
    try:
        found, w_obs, tried = search(bandwidths)
    except (ValueError, np.linalg.LinAlgError) as exc:  # place_poles on a nearly unobservable pair
        raise ProblemError(f"model.C: the observers' poles cannot be placed ({exc}); fly without observers "
                           "(design observer=false) or measure more outputs", field="model.C") from exc
    if found is None:
        worst = min(tried, key=lambda r: r["max_real_eig"])
        raise ProblemError(f"model.controlled: no K_rho from {start:g} rad/s down to {gains[-1]:g} and no observer "
                           f"bandwidth of {[b for b in bandwidths]} passes the step-10 check (closed-loop eigenvalues "
                           f"left of -{opt['stability_margin']:g}); best max Re = {worst['max_real_eig']:.3g} at "
                           f"K_rho {worst['K_rho']:g}; override design options", field="model.controlled")
    k_rho = found["K_rho"]
    observer_poles = None if w_obs is None else observers(w_obs)
    eps = rho / k_rho
    smc = SMCDesign(rho=rho, eps=eps, K0=np.ones(k), Km1=integral, observer_poles=observer_poles)
    report["sliding_function"] = {"sigma": "e + K_-1 int(e)", "K0": 1.0, "K_-1": integral.tolist(),
                                  "rule": "K_-1 = reference bandwidth" if opt["integral"] is None else "given"}
    report["switching"] = {
        "K_rho": k_rho, "rho": rho.tolist(), "eps": eps.tolist(), "reach": reach.tolist(),
        "rule": (f"K_rho: first of {start:g} rad/s (min({opt['crossover_ratio']:g} x limit frequency, "
                 f"{opt['frame_gain']:g} / T)) halved until step 10 passes" if not opt["crossover"] else "K_rho given")
        + f"; rho = {opt['rho_scale']:g} x reach from trim (LP); eps = rho / K_rho",
    }
    report["observers"] = None if w_obs is None else {
        "poles": f"-({w_obs:g} + 0.1 j), j = 0..{n - 1}, every channel", "bandwidth": w_obs,
        "rule": "given" if opt["observer_bandwidth"] else
        f"first of reference bandwidth x {list(OBSERVER_LADDER)} passing step 10"}
    report["hedge"] = None
    report["check"] = {**found, "margin": opt["stability_margin"], "tried": tried,
                       "model": "plant + linear actuators + observers + SMC in its boundary layer; weighted "
                                "pseudo-inverse for the allocator; delays and hedge excluded"}

    # baseline: the same PI law on the measured error (no observer), checked the same way
    base, _, tried_base = search([None], opt["baseline_damping"])
    baseline = None if base is None else LoopShapedDesign(compensators=tuple(
        ((base["K_rho"], base["K_rho"] * integral[i]), (1.0, 0.0)) for i in range(k)))
    report["baseline"] = {"law": "u_c = K (1 + K_-1 / s) (r - y_measured) (seed Eq 4.3, no observer)",
                          "rule": f"first K of the same ladder passing step 10 with every mode's damping >= "
                                  f"{opt['baseline_damping']:g}",
                          "K": None if base is None else base["K_rho"], "found": base is not None,
                          "check": base, "tried": len(tried_base),
                          "best_max_real_eig": min(r["max_real_eig"] for r in tried_base)}
    report["options"] = opt
    return AutoDesign(smc=smc, references=references, baseline=baseline, demand_map=demand_map, report=report)
