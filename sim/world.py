"""A world that is not the model: plant error, sensor-noise families, Dryden turbulence.

Three run settings (:class:`sim.settings.LoopSettings` ``model_error``, ``noise_model``,
``turbulence``) make the simulated world differ from the model the controller, the allocator
and the in-loop detector were designed on.  Each draw comes from its own stream,
``np.random.default_rng([seed, TAG])``, so the seed's own noise stream (``default_rng(seed)``)
is untouched and, with every world setting at its default, a run is bit-identical to one
without this module.  ``docs/world.md`` tabulates every free parameter and its source.

Model error (``model_error = F``)
    The plant's control-derivative columns ``B[:, j]``, ``D[:, j]`` (and a failure's) are
    scaled by ``s_j ~ U[1 - F, 1 + F]``, each actuator's bandwidth (first order: its pole;
    second order: ``wn``, damping kept) by another factor ``U[1 - F, 1 + F]``.  Only the
    plant and the actuator bank see them; ``spec.vehicle`` stays nominal.

Noise families (``noise_model``, ``+``-combinable, ``family[:parameter]``)
    ``gaussian``: the seed's band-limited noise (:func:`sim.blocks.band_limited_noise`).
    ``student-t[:NU]``: the same filtered Gaussian process mapped through a Gaussian copula to
    Student-t marginals of the same standard deviation, ``n -> s sqrt((NU - 2) / NU)
    t_NU^-1(Phi(n / s))`` -- a translation process (Grigoriu, "Crossings of non-Gaussian
    translation processes", J. Eng. Mech. 110(4), 1984): the spectrum is nearly the filter's,
    the marginal heavy-tailed.  Replacing the white driver instead would not do: the filter
    averages some 20 held samples and the CLT makes its output Gaussian again.
    ``coloured[:TAU]``: the white driver replaced by a first-order Gauss-Markov sequence of
    correlation time ``TAU`` s (at the driver's 10 ms hold), rescaled so the filtered output
    has the seed's standard deviation.  ``bias[:B]``: per output a constant ``N(0, (B s)^2)``
    plus a random walk whose standard deviation grows by ``B s`` per minute.  ``quantised[:Q]``:
    the measured output rounded to multiples of ``Q s`` (the flight computer reads a quantised
    sensor; done in the compiled step, :mod:`sim.packed`).  ``s`` is the output's noise std
    (the seed's gain, ``noise_scale`` included).  The in-loop detector is told the seed's
    noise level and correlation whatever the family (a designer who never characterised it).

Turbulence (``turbulence = none | light | moderate | severe``)
    Dryden gusts, MIL-F-8785C section 3.7.1 forms (as MIL-HDBK-1797 and the MathWorks Aerospace
    Blockset's "Dryden Wind Turbulence Model" document them): translational ``u_g, v_g, w_g``
    and rotational ``p_g, q_g, r_g``, each a shaping filter driven by white noise, discretised
    exactly at the integration step (Van Loan: the sampled process has the continuous one's
    covariance), started in its stationary distribution; plus one MIL-F-8785C 3.7.2 1-cosine
    vertical gust.  Into the linear plant the gust enters as the air-relative motion: the
    aerodynamic entries of ``A`` see ``x - x_gust``, so ``x' = A x + B u - A_aero x_gust``
    (:func:`gust_matrix`); the term is held over a step and discretised exactly like ``u``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit
from scipy import linalg, signal, stats

from alloc.exceptions import AllocError
from sim.blocks import ActuatorSpec, band_limited_noise
from sim.model import FlightCondition

__all__ = ["NOISE_FAMILIES", "NoiseTerm", "parse_noise", "TURBULENCE_LEVELS", "MAX_MODEL_ERROR",
           "model_error_factors", "scaled_actuator", "measurement_noise", "quantisation_steps", "Dryden",
           "dryden", "gust_matrix", "gust_series", "one_minus_cosine", "continuous_covariance", "GUST_COMPONENTS", "FEET",
           "HOVER_HEAVE_DAMPING", "HOVER_RATE_DAMPING", "HOVER_ALTITUDE", "HOVER_SPAN", "RATE_UNITS", "SPEED_UNITS"]

# independent streams of the run's seed (any fixed integers distinct from each other)
_TAG_MODEL, _TAG_NOISE, _TAG_TURBULENCE = 0x3D0E, 0x401E, 0x7B0C
#: the largest model error (a factor may fall to 0.1, never to zero or below)
MAX_MODEL_ERROR = 0.9
#: m per ft
FEET = 0.3048
#: the gust vector's components, in order (ft/s, ft/s, ft/s, rad/s, rad/s, rad/s)
GUST_COMPONENTS = ("u", "v", "w", "p", "q", "r")

# ----------------------------------------------------------------------------- noise families
#: family -> (default parameter, its meaning); ``colored`` is accepted for ``coloured``
NOISE_FAMILIES: dict[str, tuple[float | None, str]] = {
    "gaussian": (None, "the seed's band-limited Gaussian noise"),
    "student-t": (4.0, "degrees of freedom NU (> 2: a finite variance)"),
    "coloured": (0.5, "correlation time TAU of the driver, s (> 0)"),
    "bias": (1.0, "bias std and drift per minute, in noise stds (>= 0)"),
    "quantised": (0.5, "quantisation step, in noise stds (> 0)"),
}
_ALIASES = {"colored": "coloured", "quantized": "quantised"}
_LOWER = {"student-t": (2.0, True), "coloured": (0.0, True), "bias": (0.0, False), "quantised": (0.0, True)}


class _NoiseError(AllocError, ValueError):
    """Raised by :func:`parse_noise`; :mod:`sim.settings` turns it into a SettingError naming the field."""


@dataclass(frozen=True)
class NoiseTerm:
    """One family of a ``noise_model`` with its parameter (None: the family has none)."""

    family: str
    parameter: float | None


def parse_noise(text: str) -> tuple[NoiseTerm, ...]:
    """The families of ``family[:p]+family[:p]...`` (ValueError naming the bad part)."""
    if not isinstance(text, str) or not text.strip():
        raise _NoiseError(f"{text!r}: expected family[:parameter][+family...] with families "
                          f"{', '.join(NOISE_FAMILIES)}")
    terms: dict[str, NoiseTerm] = {}
    for part in text.strip().lower().split("+"):
        name, _, value = part.strip().partition(":")
        name = _ALIASES.get(name.strip(), name.strip())
        if name not in NOISE_FAMILIES:
            raise _NoiseError(f"{part!r}: unknown family; expected one of {', '.join(NOISE_FAMILIES)} (or colored)")
        if name in terms:
            raise _NoiseError(f"{part!r}: family {name} given twice")
        default, meaning = NOISE_FAMILIES[name]
        if value.strip() and default is None:
            raise _NoiseError(f"{part!r}: {name} takes no parameter")
        p = default
        if value.strip():
            try:
                p = float(value)
            except ValueError:
                raise _NoiseError(f"{part!r}: parameter {value!r} is not a number ({meaning})") from None
            low, open_ = _LOWER[name]
            if not math.isfinite(p) or (p <= low if open_ else p < low):
                raise _NoiseError(f"{part!r}: parameter {p:g} out of range ({meaning})")
        terms[name] = NoiseTerm(name, p)
    return tuple(terms.values())


def _term(terms: tuple[NoiseTerm, ...], name: str) -> NoiseTerm | None:
    return next((t for t in terms if t.family == name), None)


# the seed's driver (sim.blocks.band_limited_noise's defaults) and a long seeded sample to measure on
_POWER, _HOLD = 0.1, 0.01
_CALIBRATION_SECONDS, _CALIBRATION_SEED = 3600.0, 20261205


@cache
def seed_noise_std(dt: float) -> float:
    """The std of the seed's noise at unit gain (one seeded hour; about 0.4 % standard error)."""
    n = int(round(_CALIBRATION_SECONDS / dt))
    return float(band_limited_noise(n, dt, np.ones(1), np.random.default_rng(_CALIBRATION_SEED))[:, 0].std())


def _coloured_noise(n_steps: int, dt: float, tau: float, width: int, rng: np.random.Generator) -> np.ndarray:
    """The seed's filter driven by a unit Gauss-Markov sequence (correlation time ``tau``) held 10 ms."""
    hold = max(1, int(round(_HOLD / dt)))
    n_samples = n_steps // hold + 2
    a = math.exp(-hold * dt / tau)
    e = rng.standard_normal((n_samples, width))
    e[1:] *= math.sqrt(1.0 - a * a)  # the first sample is drawn stationary
    driver = signal.lfilter([1.0], [1.0, -a], e, axis=0) * math.sqrt(_POWER / _HOLD)
    held = np.repeat(driver, hold, axis=0)[:n_steps]
    num, den, _ = signal.cont2discrete(([100.0], [1.0, 20.0, 100.0]), dt, method="zoh")
    return signal.lfilter(np.ravel(num), den, held, axis=0)


@cache
def coloured_gain(dt: float, tau: float) -> float:
    """Factor that gives the coloured-driver noise the seed's std (both measured on one seeded hour)."""
    n = int(round(_CALIBRATION_SECONDS / dt))
    c = _coloured_noise(n, dt, tau, 1, np.random.default_rng(_CALIBRATION_SEED))[:, 0]
    return seed_noise_std(dt) / float(c.std())


def measurement_noise(terms: tuple[NoiseTerm, ...], n: int, dt: float, gains: np.ndarray, seed: int
                      ) -> tuple[np.ndarray, dict[str, Any]]:
    """Noise (n, len(gains)) of the non-default families and what was drawn (JSON-ready).

    ``gains``: the seed's gains times ``noise_scale``.  The base process is the seed's band-limited
    Gaussian one, drawn from the run's own noise stream (``default_rng(seed)``: the very sample a
    ``gaussian`` run gets, so ``student-t`` maps that sample path's marginals and ``bias`` adds to
    it) or, with ``coloured``, the Gauss-Markov-driven one; ``coloured`` and ``bias`` draw from the
    world's stream ``default_rng([seed, tag])``.
    """
    rng = np.random.default_rng([seed, _TAG_NOISE])
    gains = np.asarray(gains, dtype=float)
    s0 = seed_noise_std(dt)
    drawn: dict[str, Any] = {"unit_std": s0}
    coloured, t_term, bias = _term(terms, "coloured"), _term(terms, "student-t"), _term(terms, "bias")
    if coloured is not None:
        g = coloured_gain(dt, coloured.parameter)
        base = _coloured_noise(n, dt, coloured.parameter, gains.size, rng) * g
        drawn["coloured_gain"] = g
    else:
        base = band_limited_noise(n, dt, np.ones(gains.size), np.random.default_rng(seed))
    if t_term is not None:
        nu = t_term.parameter
        # Gaussian copula: exact Student-t marginal of the same std (Grigoriu 1984)
        base = s0 * math.sqrt((nu - 2.0) / nu) * stats.t.ppf(stats.norm.cdf(base / s0), nu)
    noise = base * gains
    if bias is not None:
        sigma = s0 * gains  # per output noise std
        b = bias.parameter
        offset = rng.standard_normal(gains.size) * b * sigma
        # random walk: std b * sigma after 60 s
        steps = rng.standard_normal((n, gains.size)) * b * sigma * math.sqrt(dt / 60.0)
        steps[0] = 0.0
        noise = noise + offset + np.cumsum(steps, axis=0)
        drawn["bias"] = offset.tolist()
    return noise, drawn


def quantisation_steps(terms: tuple[NoiseTerm, ...], dt: float, gains: np.ndarray) -> np.ndarray:
    """Per output: the quantisation step ``Q s`` (0: not quantised, also where the noise std is 0)."""
    q = _term(terms, "quantised")
    gains = np.asarray(gains, dtype=float)
    if q is None:
        return np.zeros(gains.size)
    return q.parameter * seed_noise_std(dt) * np.abs(gains)


# ------------------------------------------------------------------------------ model error
def model_error_factors(error: float, m: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(effectiveness factors, bandwidth factors)``, each of ``m`` draws from ``U[1 - F, 1 + F]``."""
    rng = np.random.default_rng([seed, _TAG_MODEL])
    s = rng.uniform(1.0 - error, 1.0 + error, m)
    w = rng.uniform(1.0 - error, 1.0 + error, m)
    return s, w


def scaled_actuator(spec: ActuatorSpec, factor: float) -> ActuatorSpec:
    """``spec`` with its bandwidth times ``factor`` (first order: the pole; second order: ``wn``, same damping)."""
    return spec.with_bandwidth(spec.wn * factor)


# -------------------------------------------------------------------------------- turbulence
#: intensity levels; W20 (wind at 20 ft, knots) for low altitude, MIL-F-8785C 3.7.1.3 / Fig 8:
#: light 15, moderate 30, severe 45 knots
TURBULENCE_LEVELS = ("none", "light", "moderate", "severe")
_W20_KNOTS = {"light": 15.0, "moderate": 30.0, "severe": 45.0}
_KNOT = 1.6878098571  # ft/s per knot
#: medium/high altitude (MIL-F-8785C 3.7.1.3, Fig 7): sigma (ft/s) at the probability of exceedance
#: 1e-2 (light), 1e-3 (moderate), 1e-5 (severe) by altitude (ft); the digitised figure as the
#: open JSBSim FGWinds.cpp tabulates it (its POE rows 3, 4 and 6)
_POE_ALTITUDES = (500.0, 1750.0, 3750.0, 7500.0, 15000.0, 25000.0, 35000.0, 45000.0, 55000.0, 65000.0, 75000.0,
                  80000.0)
_POE_SIGMA = {
    "light": (6.6, 6.9, 7.4, 6.7, 4.6, 2.7, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0),
    "moderate": (8.6, 9.6, 10.6, 10.1, 8.0, 6.6, 5.0, 4.2, 2.7, 0.0, 0.0, 0.0),
    "severe": (15.6, 17.6, 23.0, 23.6, 22.1, 20.0, 16.0, 15.1, 12.1, 7.9, 6.2, 5.1),
}
#: the 1-cosine gust (MIL-F-8785C 3.7.2 shape): vertical, starting at this time (s), amplitude
#: v_m = GUST_SIGMAS x sigma_w, half-length d_m = V x GUST_RISE (ours: the spec leaves both to the
#: analysis; a 2-sigma gust rising over one second, inside the loops' bandwidth)
GUST_TIME, GUST_SIGMAS, GUST_RISE = 10.0, 2.0, 1.0
#: white-noise intensity of the Dryden forms as MIL-F-8785C writes them (their spectra integrate
#: to sigma^2 with E[eta(t) eta(t + s)] = pi delta(s))
_ETA = math.pi


@dataclass(frozen=True)
class Dryden:
    """Intensities (ft/s), scale lengths (ft), airspeed (ft/s) and span (ft) of one turbulence level."""

    level: str
    altitude: float
    speed: float
    span: float
    sigma_u: float
    sigma_v: float
    sigma_w: float
    L_u: float
    L_v: float
    L_w: float

    def record(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def dryden(level: str, flight: FlightCondition) -> Dryden:
    """MIL-F-8785C 3.7.1.3 intensities and scale lengths at the flight condition.

    Low altitude (h <= 1000 ft): ``sigma_w = 0.1 W20``, ``sigma_u = sigma_v = sigma_w / (0.177 +
    0.000823 h)^0.4``, ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``; medium/high
    (h >= 2000 ft): every sigma from the probability-of-exceedance figure, every L 1750 ft;
    in between, linear in altitude (MIL-HDBK-1797's rule).  A hovering vehicle (``speed`` 0) is
    passed by the mean wind: Taylor's hypothesis with ``V = W20`` (ours).
    """
    h = float(flight.altitude)
    w20 = _W20_KNOTS[level] * _KNOT

    def low(hh: float) -> tuple[float, ...]:
        hh = max(hh, 10.0)  # the low-altitude forms hold from 10 ft (MIL-F-8785C 3.7.1.3)
        k = 0.177 + 0.000823 * hh
        sw = 0.1 * w20
        su = sw / k**0.4
        return su, su, sw, hh / k**1.2, hh / k**1.2, hh

    def high(hh: float) -> tuple[float, ...]:
        s = float(np.interp(hh, _POE_ALTITUDES, _POE_SIGMA[level]))
        return s, s, s, 1750.0, 1750.0, 1750.0

    if h <= 1000.0:
        values = low(h)
    elif h >= 2000.0:
        values = high(h)
    else:
        f = (h - 1000.0) / 1000.0
        values = tuple((1 - f) * a + f * b for a, b in zip(low(1000.0), high(2000.0), strict=True))
    speed = flight.speed if flight.speed > 0 else w20
    return Dryden(level, h, speed, flight.span, *values)


def _filters(d: Dryden) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous ``(A, B, C)`` of the six Dryden filters, noise ``[eta_u, eta_v, eta_w, eta_p]``.

    MIL-F-8785C 3.7.1 (MathWorks "Dryden Wind Turbulence Model (Continuous)" table):
    ``H_u = s_u sqrt(2 L_u / (pi V)) / (1 + L_u s / V)``; ``H_v, H_w = s sqrt(L / (pi V)) (1 + sqrt(3) L s / V)
    / (1 + L s / V)^2``; ``H_p = s_w sqrt(0.8 / V) (pi / (4 b))^(1/6) / (L_w^(1/3) (1 + 4 b s / (pi V)))``;
    ``q_g = (s / V) / (1 + 4 b s / (pi V)) w_g`` and ``r_g = -(s / V) / (1 + 3 b s / (pi V)) v_g``
    (``q_g = dw_g/dx``, ``r_g = -dv_g/dx``, the spec's definitions, frozen field passed at V).
    """
    V, b = d.speed, d.span
    tu, tv, tw = d.L_u / V, d.L_v / V, d.L_w / V
    ku = d.sigma_u * math.sqrt(2.0 * d.L_u / (math.pi * V))
    kv = d.sigma_v * math.sqrt(d.L_v / (math.pi * V))
    kw = d.sigma_w * math.sqrt(d.L_w / (math.pi * V))
    kp = d.sigma_w * math.sqrt(0.8 / V) * (math.pi / (4.0 * b)) ** (1.0 / 6.0) / d.L_w ** (1.0 / 3.0)
    hv = ([kv * math.sqrt(3.0) * tv, kv], [tv * tv, 2.0 * tv, 1.0])
    hw = ([kw * math.sqrt(3.0) * tw, kw], [tw * tw, 2.0 * tw, 1.0])
    tq, tr = 4.0 * b / (math.pi * V), 3.0 * b / (math.pi * V)
    systems = [  # (num, den, noise input, output component)
        ([ku], [tu, 1.0], 0, 0),
        (*hv, 1, 1),
        (*hw, 2, 2),
        ([kp], [4.0 * b / (math.pi * V), 1.0], 3, 3),
        (np.polymul([1.0 / V, 0.0], hw[0]), np.polymul([tq, 1.0], hw[1]), 2, 4),
        (np.polymul([-1.0 / V, 0.0], hv[0]), np.polymul([tr, 1.0], hv[1]), 1, 5),
    ]
    blocks = [signal.tf2ss(num, den) for num, den, _, _ in systems]
    n = sum(a.shape[0] for a, *_ in blocks)
    A, B, C = np.zeros((n, n)), np.zeros((n, 4)), np.zeros((6, n))
    i = 0
    for (a, bb, c, dd), (_, _, inp, out) in zip(blocks, systems, strict=True):
        k = a.shape[0]
        A[i:i + k, i:i + k] = a
        B[i:i + k, inp] = bb[:, 0]
        C[out, i:i + k] = c[0]
        if np.any(dd):
            raise AssertionError("Dryden filters are strictly proper")
        i += k
    return A, B, C


def _van_loan(A: np.ndarray, Q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Q_d)``: the exact discrete equivalent of ``x' = A x + w``, ``E w w' = Q delta`` (Van Loan 1978)."""
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -A, Q, A.T
    E = linalg.expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def _sqrt_psd(Q: np.ndarray) -> np.ndarray:
    """A square root ``L L' = Q`` of a positive semi-definite matrix (the Dryden states share their noises)."""
    w, v = np.linalg.eigh(Q)
    return np.ascontiguousarray(v * np.sqrt(np.clip(w, 0.0, None)))


@njit(cache=True)
def _recursion(Phi: np.ndarray, L: np.ndarray, x0: np.ndarray, e: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Outputs ``C x_k`` of ``x_{k+1} = Phi x_k + L e_k`` from ``x_0``."""
    n = e.shape[0]
    out = np.empty((n, C.shape[0]))
    x = x0.copy()
    for k in range(n):
        out[k] = C @ x
        x = Phi @ x + L @ e[k]
    return out


def continuous_covariance(d: Dryden) -> np.ndarray:
    """Stationary covariance (6 x 6) of ``[u, v, w, p, q, r]`` gusts of the continuous filters."""
    A, B, C = _filters(d)
    P = linalg.solve_continuous_lyapunov(A, -_ETA * B @ B.T)
    return C @ P @ C.T


def one_minus_cosine(t: np.ndarray, d: Dryden, start: float = GUST_TIME) -> np.ndarray:
    """MIL-F-8785C 3.7.2: ``v = v_m / 2 (1 - cos(pi x / d_m))`` for ``0 <= x <= 2 d_m`` (x = V (t - start)), else 0."""
    vm, dm = GUST_SIGMAS * d.sigma_w, d.speed * GUST_RISE
    x = d.speed * (np.asarray(t, dtype=float) - start)
    inside = (x >= 0.0) & (x <= 2.0 * dm)
    return np.where(inside, 0.5 * vm * (1.0 - np.cos(np.pi * x / dm)), 0.0)


def gust_series(d: Dryden, n: int, dt: float, seed: int, *, gust: bool = True) -> np.ndarray:
    """Gusts (n, 6) ``[u, v, w (ft/s), p, q, r (rad/s)]`` at ``t = k dt``: Dryden plus the 1-cosine on ``w``."""
    rng = np.random.default_rng([seed, _TAG_TURBULENCE])
    A, B, C = _filters(d)
    Phi, Qd = _van_loan(A, _ETA * B @ B.T, dt)
    P = linalg.solve_discrete_lyapunov(Phi, Qd)
    x0 = _sqrt_psd(0.5 * (P + P.T)) @ rng.standard_normal(A.shape[0])
    e = rng.standard_normal((n, A.shape[0]))
    out = _recursion(np.ascontiguousarray(Phi), _sqrt_psd(Qd), x0, e, np.ascontiguousarray(C))
    if gust:
        out[:, 2] += one_minus_cosine(np.arange(n) * dt, d)
    return out


def gust_matrix(A: np.ndarray, flight: FlightCondition) -> np.ndarray:
    """``E`` (nx x 6): the state derivative a gust vector adds, ``x' = A x + B u + E g``.

    ``E[:, c] = -sum over the states of component c of A_aero[:, i] scale_i`` (the aerodynamic
    entries of ``A`` see ``x - x_gust``), plus the ``hover`` entries of a model without
    aerodynamic damping.
    """
    A = np.asarray(A, dtype=float)
    nx = A.shape[0]
    if flight.aero is not None:
        mask = np.asarray(flight.aero, dtype=bool)
    else:
        mask = np.ones((nx, nx), dtype=bool)
        rate_rows = [i for i, c, _ in flight.gust_states if c in "pqr"]
        for i, c, _ in flight.gust_states:
            if c in "pqr":  # a rotational gust is aerodynamic: the moment equations' rows only
                mask[:, i] = False
                mask[rate_rows, i] = True
    E = np.zeros((nx, 6))
    for i, c, scale in flight.gust_states:
        E[:, GUST_COMPONENTS.index(c)] -= np.where(mask[:, i], A[:, i], 0.0) * scale
    for row, c, gain in flight.hover:
        E[row, GUST_COMPONENTS.index(c)] += gain
    return E


# ------------------------------------------------------------------------- vehicle files' air
#: a hovering multirotor's linear model has no aerodynamic damping to carry a gust (hexa-x: A's
#: rate and heave columns are zero), so the gust enters through stated damping (ours, docs/world.md):
#: heave ``w' += HOVER_HEAVE_DAMPING (w_g)`` and ``p' += HOVER_RATE_DAMPING p_g``, ``q'`` likewise.
#: 0.7 1/s is the momentum-theory heave damping ``Z_w ~ -0.37 g / v_h`` of a hovering rotor with
#: v_h ~ 5 m/s (2 kg on six 10-inch rotors); 2.2 1/s is what that gives through hexa-x's rotor
#: arms, ``(Z_w m / n) sum(y_j^2) / I_xx`` (0.75 m^2, 0.08 kg m^2).  Yaw: none (rotor drag torque).
HOVER_HEAVE_DAMPING, HOVER_RATE_DAMPING = 0.7, 2.2
#: ft: a hovering vehicle's altitude (ours: 50 ft, low-altitude turbulence) and span (the 1 m rotor circle)
HOVER_ALTITUDE, HOVER_SPAN = 50.0, 1.0 / FEET
#: a rate state's units per rad/s, a speed state's per ft/s
RATE_UNITS = {"rad/s": 1.0, "deg/s": 180.0 / math.pi}
SPEED_UNITS = {"m/s": FEET, "ft/s": 1.0}
