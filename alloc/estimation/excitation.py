"""Identifiable allocation: decorrelating excitation for any registry allocator (seed 1.3.2.5).

Allocators make the effectors' commands functions of the demand, so the regressor of an
estimator of ``B`` has (nearly) collinear columns and the columns of ``B`` cannot be told
apart (seed section 1.3.2.5).  Two remedies, both wrappers of an
:class:`alloc.Allocator` of any method:

:class:`NullSpaceExcitation`
    adds ``e`` with ``B e = 0`` to every command, so the moments ``B u`` are unchanged
    (to round-off: ``|B e| <= ~m eps |B| |e|``).  Per call: a signal ``z`` of independent,
    seeded channels, one per effector, each of amplitude ``a_j`` (``prbs``: ``+-a_j``,
    switching at random on a clock of ``1 / (2 f_hi)`` seconds with probability one half --
    a flat spectrum up to about ``f_hi``; ``multisine``: per effector, a sum of sines on
    distinct frequencies spread over the band with random phases, peak ``a_j``).  ``z`` is
    projected on the null space of ``B`` restricted to the *free* effectors (those with at
    least ``a_j / 2`` of room on both sides of the command within its position limits), in the metric that keeps each effector's
    share of its own amplitude: ``e_F = D N N^T D^-1 z_F``, ``N`` an orthonormal basis of
    ``null(B_F D)``, ``D = diag(a_F)``; the other effectors get none.  Then ``e`` is scaled by the
    largest ``tau <= 1`` that keeps ``u + tau e`` within this call's bounds (position and rate
    limits of Eq 1.28 combined) -- one common factor, so ``B e = 0`` is kept and admissibility
    holds exactly (a final clip moves nothing beyond round-off); where an effector binds
    ``tau`` below a half it leaves the free set and ``e`` is recomputed (at most four rounds;
    the largest excitation found is kept).  The PRBS jumps by ``2 a_j``: against rate limits
    of ``rate dt`` per call it is mostly scaled away, so ``multisine`` (the default) suits
    rate-limited effectors.  The status is recomputed by the library's own certified test
    (``exact`` iff ``|B u - v|`` within :data:`alloc.EXACT_RTOL`), a fallback stays a fallback.

:class:`RandomWeightAllocator`
    the seed's variant for weighted methods (Eq 1.22's ``W``, "randomly vary the weighting
    matrix"): a bank of allocators built with ``Wu`` scaled by seeded random diagonal factors
    (log-uniform in ``[1/spread, spread]``), switched at random every ``dwell`` calls.  Each
    call is an ordinary allocation of the chosen method (its status its own); a method whose
    answer does not depend on ``Wu`` is not decorrelated by it (measured in
    ``benchmarks/bench_estimation.py``).

:func:`regressor_condition` measures what either buys: the condition number of the
column-scaled regressor over a window.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..api import Allocator, make_allocator
from ..domain import MAX_MAGNITUDE, as_float_array, check_magnitude, short_repr
from ..exceptions import OptionError
from ..problem import Problem
from ..result import EXACT_RTOL, Result, Status
from ._checks import MAX_COUNT, setting_int, setting_real, setting_vector

__all__ = ["NullSpaceExcitation", "RandomWeightAllocator", "regressor_condition", "SIGNALS"]

#: the excitation signals
SIGNALS = ("prbs", "multisine")
#: sines per effector in a multisine
_TONES = 4
#: rounds of dropping a binding effector from the free set
_ROUNDS = 4
#: null-space bases kept (one per set of free effectors met)
_CACHE = 256


def regressor_condition(U: Any, scale: Any = None) -> float:
    """2-norm condition number of the regressor ``U`` (N samples x m effectors), columns
    centred and divided by ``scale`` (default: each column's own RMS);
    ``inf`` when a column never moves or columns are collinear."""
    X = as_float_array("U", U, OptionError)
    if X.ndim != 2 or X.shape[0] < 2 or X.shape[1] < 1:
        raise OptionError(f"U: expected a finite (N >= 2, m >= 1) array, got shape {X.shape}")
    check_magnitude("U", X, OptionError)  # |U| <= 1e50: the squares below stay finite
    X = X - X.mean(axis=0)
    s = np.sqrt((X ** 2).mean(axis=0)) if scale is None else setting_vector("scale", scale, X.shape[1], positive=True)
    if (s <= 0).any():
        return float("inf")
    with np.errstate(over="ignore"):
        Xs = X / s
    if not np.abs(Xs).max() <= MAX_MAGNITUDE:  # a subnormal scale; never hand LAPACK an inf
        raise OptionError(f"scale: U / scale exceeds {MAX_MAGNITUDE:g} (scale too small for U)")
    sv = np.linalg.svd(Xs, compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


class NullSpaceExcitation:
    """``u + tau e`` with ``B e = 0``: the allocation's moments, with identifiable commands.

    Parameters
    ----------
    allocator : Allocator
        Any allocator from :func:`alloc.make_allocator` (every registry method).
    sample_time : float
        Seconds between calls (the signal's clock).
    amplitude : float or array (m,)
        Per-effector amplitude ``a_j`` of the signal, in effector units.
    signal : "prbs" or "multisine"
    band : (float, float)
        Hz: the multisine's frequencies; the PRBS's clock is ``1 / (2 band[1])``.
    seed : int
        The signal's random generator.

    The wrapper keeps the signal's state: one per control loop (not for sharing between
    threads, unlike the allocator it wraps).
    """

    def __init__(self, allocator: Allocator, sample_time: float, *, amplitude: Any = 1.0, signal: str = "multisine",
                 band: tuple[float, float] = (0.1, 1.5), seed: int = 0) -> None:
        if not isinstance(allocator, Allocator):
            raise OptionError(f"allocator: expected an alloc.Allocator, got {type(allocator).__name__}")
        if not isinstance(signal, str) or signal not in SIGNALS:
            raise OptionError(f"signal: expected one of {', '.join(SIGNALS)}, got {short_repr(signal)}")
        self.allocator = allocator
        self.problem: Problem = allocator.problem
        m = self.problem.m
        self.dt = setting_real("sample_time", sample_time, 0.0, 3600.0, lo_open=True)
        self.amplitude = setting_vector("amplitude", amplitude, m)
        if (self.amplitude < 0).any():
            raise OptionError("amplitude: must be >= 0")
        if not (isinstance(band, (tuple, list)) and len(band) == 2):
            raise OptionError(f"band: expected (low, high) in Hz, got {short_repr(band)}")
        f_lo = setting_real("band", band[0], 0.0, 0.5 / self.dt, lo_open=True)
        f_hi = setting_real("band", band[1], f_lo, 0.5 / self.dt)
        self.band = (f_lo, f_hi)
        self.signal = signal
        self.seed = setting_int("seed", seed, 0, 2 ** 63 - 1)
        self._rng = np.random.default_rng(self.seed)
        # calls per PRBS switch; a band far below the call rate gives a clock beyond any run (a
        # subnormal band gave inf, which int() cannot convert): held at MAX_COUNT calls
        per_call = 2.0 * f_hi * self.dt  # may underflow to 0
        self._clock = max(1, int(round(1.0 / per_call)) if per_call * MAX_COUNT > 1.0 else MAX_COUNT)
        self._prbs = np.where(self._rng.random(m) < 0.5, -1.0, 1.0)
        freqs = np.linspace(f_lo, f_hi, _TONES * m)
        self._freqs = self._rng.permutation(freqs).reshape(m, _TONES)  # distinct tones per effector
        self._phases = self._rng.uniform(0.0, 2.0 * np.pi, (m, _TONES))
        self._bases: dict[bytes, np.ndarray] = {}
        self.calls = 0
        #: the last call's excitation factor ``tau`` (0: none was possible) and added command
        self.last_scale = 0.0
        self.last_excitation = np.zeros(m)

    def signal_at(self, n: int) -> np.ndarray:
        """The raw signal ``z`` (m,) of call ``n`` (PRBS: advanced by the calls themselves)."""
        if self.signal == "prbs":
            return self.amplitude * self._prbs
        t = n * self.dt
        return self.amplitude * np.sin(2 * np.pi * self._freqs * t + self._phases).sum(axis=1) / _TONES

    def _basis(self, free: np.ndarray) -> np.ndarray:
        """``D N`` for the free set (cached): the weighted null-space directions."""
        key = free.tobytes()
        basis = self._bases.get(key)
        if basis is None:
            D = self.amplitude[free]
            BD = self.problem.B[:, free] * D
            _, sv, Vt = np.linalg.svd(BD, full_matrices=True)
            rank = int((sv > 1e-12 * (sv[0] if sv.size else 1.0)).sum())
            N = Vt[rank:].T  # orthonormal basis of null(B_F D)
            basis = (D[:, None] * N, N / np.where(D > 0, D, 1.0)[:, None])
            if len(self._bases) >= _CACHE:
                self._bases.clear()
            self._bases[key] = basis
        return basis

    def _excitation(self, z: np.ndarray, u0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                    free: np.ndarray) -> tuple[np.ndarray, float, int]:
        """``(e, tau, binding)``: the projected signal on ``free``, the largest factor within the
        bounds, and the effector that binds it (-1 when none does)."""
        e = np.zeros(self.problem.m)
        if free.any():
            DN, NinvD = self._basis(free)
            if DN.shape[1] > 0:
                e[free] = DN @ (NinvD.T @ z[free])
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a room / e beyond range: no limit
            limit = np.where(e > 0, (hi - u0) / e, np.where(e < 0, (lo - u0) / e, np.inf))
        binding = int(np.argmin(limit))
        tau = float(limit[binding])
        if tau >= 1.0:
            return e, 1.0, -1
        return e, max(tau, 0.0), binding

    def __call__(self, v: Any, u_prev: Any = None, dt: Any = None) -> Result:
        """The allocator's answer with the excitation added (see the module docstring)."""
        n = self.calls
        self.calls += 1
        return self.excite(self.allocator(v, u_prev=u_prev, dt=dt), n, u_prev, dt)

    def excite(self, r: Result, n: int, u_prev: Any = None, dt: Any = None) -> Result:
        """``r`` (an answer of this problem for the same ``u_prev``, ``dt``) with call ``n``'s
        excitation added: for a loop that counts its own calls, or that rebuilds the wrapped
        allocator (a health change) and must keep the signal's phase.  The multisine is a
        function of ``n`` alone; the PRBS advances with the calls made."""
        if not isinstance(r, Result):
            raise OptionError(f"r: expected an alloc.Result, got {type(r).__name__}")
        n = setting_int("n", n, 0, MAX_COUNT)  # n dt stays exact and finite
        p = self.problem
        lo, hi = p.effective_bounds(u_prev, dt) if (u_prev is not None or dt is not None) else (p.umin, p.umax)
        if self.signal == "prbs" and n % self._clock == 0:
            flip = self._rng.random(p.m) < 0.5
            self._prbs[flip] *= -1.0
        z = self.signal_at(n)
        u0 = np.asarray(r.u)
        room = np.minimum(u0 - p.umin, p.umax - u0)
        free = (room >= 0.5 * self.amplitude) & (self.amplitude > 0)
        best_e, best_tau, best_size = np.zeros(p.m), 0.0, 0.0
        for _ in range(_ROUNDS):  # an effector that binds the factor below a half leaves the free set
            e, tau, binding = self._excitation(z, u0, lo, hi, free)
            size = tau * float(np.abs(e).max(initial=0.0))
            if size > best_size:
                best_e, best_tau, best_size = e, tau, size
            if tau >= 0.5 or binding < 0:
                break
            free[binding] = False
        u = np.minimum(np.maximum(u0 + best_tau * best_e, lo), hi)
        self.last_scale = best_tau if best_size > 0 else 0.0
        self.last_excitation = u - u0
        return _result(p, u, lo, hi, r)


def _result(p: Problem, u: np.ndarray, lo: np.ndarray, hi: np.ndarray, r: Result) -> Result:
    """The Result of admissible command ``u`` for ``r``'s demand, its status recomputed by the
    library's certified test (``fallback`` kept)."""
    from .._engine._kernels import finish_owned

    c = np.ascontiguousarray
    out, code = finish_owned(p.B, c(u, dtype=float), c(lo, dtype=float), c(hi, dtype=float),
                             c(r.v, dtype=float), EXACT_RTOL)
    m, k = p.m, p.k
    status = r.status if r.status is Status.FALLBACK else (Status.EXACT if code == 0 else Status.UNATTAINABLE)
    out.setflags(write=False)
    return Result(out[:m], out[m + k:m + 2 * k], out[m:m + k], status, r.method, r.iterations, r.solve_time,
                  r.message, out[m + 2 * k:])


class RandomWeightAllocator:
    """The seed's random-weight decorrelation (1.3.2.5): a bank of ``method`` allocators with
    seeded random diagonal rescalings of ``Wu``, switched at random every ``dwell`` calls.

    Parameters
    ----------
    problem : Problem
    method : str
        Any registry method; ``**options`` its options.
    spread : float
        Each effector's weight factor is log-uniform in ``[1/spread, spread]`` (> 1).
    n_weights : int
        Allocators in the bank (built once).
    dwell : int
        Calls between switches.
    seed : int
    """

    def __init__(self, problem: Problem, method: str, *, spread: float = 4.0, n_weights: int = 8, dwell: int = 10,
                 seed: int = 0, **options: Any) -> None:
        if not isinstance(problem, Problem):
            raise OptionError(f"problem: expected an alloc.Problem, got {type(problem).__name__}")
        self.spread = setting_real("spread", spread, 1.0, 1e6, lo_open=True)
        self.n_weights = setting_int("n_weights", n_weights, 1, 64)
        self.dwell = setting_int("dwell", dwell, 1, 10 ** 9)
        self.seed = setting_int("seed", seed, 0, 2 ** 63 - 1)
        rng = np.random.default_rng(self.seed)
        m = problem.m
        self.problem = problem
        self.factors = np.exp(rng.uniform(-np.log(self.spread), np.log(self.spread), (self.n_weights, m)))
        Wu = problem.Wu
        self.bank = []
        for f in self.factors:
            s = np.sqrt(f)
            W = s[:, None] * Wu * s[None, :] if Wu.ndim == 2 else f * Wu  # congruence keeps it SPD
            self.bank.append(make_allocator(problem.replace(Wu=W), method, **options))
        self._rng = rng
        self.calls = 0
        self.current = 0

    def __call__(self, v: Any, u_prev: Any = None, dt: Any = None) -> Result:
        if self.calls % self.dwell == 0:
            self.current = int(self._rng.integers(self.n_weights))
        self.calls += 1
        return self.bank[self.current](v, u_prev=u_prev, dt=dt)
