"""The control allocation problem, validated once and immutable.

Glossary (seed section 1.3.4): the seed's desired moment ``m_d`` is called
``v`` here (the demand, or the SMC pseudo-command); its control power matrix
``B`` (Eq 1.14) keeps its name; ``u_pref`` is ``up``; ``W_u``/``W_d`` are
``Wu``/``Wv``.  Weights are quadratic-form matrices as in Eqs 1.20-1.23: the
preference cost is ``(u - up)' Wu (u - up)`` and the moment-error cost is
``(B u - v)' Wv (B u - v)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._kernels import all_finite, rate_window
from .exceptions import DemandError, ProblemError

__all__ = ["Problem"]

FloatArray = NDArray[np.float64]


def _as_array(name: str, value: ArrayLike, shape: tuple[int, ...], *, allow_inf: bool = False) -> FloatArray:
    """Return ``value`` as a read-only float array of ``shape`` or raise ProblemError."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{name}: not a numeric array ({exc})") from exc
    if arr.shape != shape:
        raise ProblemError(f"{name}: expected shape {shape}, got {arr.shape}")
    bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        what = "NaN" if allow_inf else "non-finite"
        raise ProblemError(f"{name}: {what} value at index {idx if len(idx) > 1 else idx[0]}")
    arr.setflags(write=False)
    return arr


def _as_weight(name: str, value: ArrayLike | None, n: int) -> FloatArray:
    """A symmetric positive definite ``n x n`` weight; a 1-D input is a diagonal."""
    if value is None:
        w = np.eye(n)
        w.setflags(write=False)
        return w
    arr = np.array(value, dtype=float) if not isinstance(value, np.ndarray) else value.astype(float)
    if arr.ndim == 1:
        arr = _as_array(name, arr, (n,))
        if (arr <= 0).any():
            i = int(np.argmax(arr <= 0))
            raise ProblemError(f"{name}: diagonal weight {name}[{i}] = {arr[i]:g} is not positive")
        out = np.diag(arr)
        out.setflags(write=False)
        return out
    arr = _as_array(name, arr, (n, n))
    scale = max(1.0, float(np.abs(arr).max()))
    if not np.allclose(arr, arr.T, rtol=0.0, atol=1e-12 * scale):
        raise ProblemError(f"{name}: weight matrix is not symmetric")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError as exc:
        raise ProblemError(f"{name}: weight matrix is not positive definite") from exc
    return arr


class Problem:
    """A linear control allocation problem ``B u = v`` with limits (seed Eq 1.14).

    Parameters
    ----------
    B : array_like, shape (k, m)
        Control effectiveness matrix: ``k`` virtual controls (axes), ``m`` effectors.
    umin, umax : array_like, shape (m,)
        Position limits, ``umin <= umax``.  ``umin[i] == umax[i]`` is a jammed effector.
    up : array_like, shape (m,), optional
        Preferred position ``u_pref`` (Eqs 1.19, 1.21-1.23), within the limits.
        Default: zero clipped into the limits.
    Wu : array_like, shape (m, m) or (m,), optional
        Symmetric positive definite preference weight (a vector is a diagonal).
    Wv : array_like, shape (k, k) or (k,), optional
        Symmetric positive definite moment-error weight.
    rate_min, rate_max : array_like, shape (m,), optional
        Rate limits in units per second, ``rate_min <= 0 <= rate_max``; ``inf`` allowed.
        Used with ``u_prev`` and ``dt`` (Eq 1.28).
    names : sequence of str, optional
        Effector names, unique; default ``u0 .. u{m-1}``.
    axes : sequence of str, optional
        Virtual-control axis names, unique; default ``v0 .. v{k-1}``.

    Raises
    ------
    ProblemError
        (a ``ValueError``) naming the field and the reason.

    Examples
    --------
    >>> import alloc
    >>> p = alloc.Problem([[1.0, 1.0, 0.5]], [-1, -1, -1], [1, 1, 1])
    >>> p.k, p.m
    (1, 3)
    """

    __slots__ = (
        "B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max",
        "names", "axes", "k", "m", "has_rate_limits", "_frozen",
    )

    def __init__(
        self,
        B: ArrayLike,
        umin: ArrayLike,
        umax: ArrayLike,
        *,
        up: ArrayLike | None = None,
        Wu: ArrayLike | None = None,
        Wv: ArrayLike | None = None,
        rate_min: ArrayLike | None = None,
        rate_max: ArrayLike | None = None,
        names: Sequence[str] | None = None,
        axes: Sequence[str] | None = None,
    ) -> None:
        try:
            B_arr = np.array(B, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ProblemError(f"B: not a numeric matrix ({exc})") from exc
        if B_arr.ndim == 1:
            B_arr = B_arr[np.newaxis, :]
        if B_arr.ndim != 2 or B_arr.shape[0] < 1 or B_arr.shape[1] < 1:
            raise ProblemError(f"B: expected a 2-D matrix (k x m), got shape {B_arr.shape}")
        k, m = B_arr.shape
        B_arr = _as_array("B", B_arr, (k, m))
        lo = _as_array("umin", umin, (m,))
        hi = _as_array("umax", umax, (m,))
        if (lo > hi).any():
            i = int(np.argmax(lo > hi))
            raise ProblemError(f"umin/umax: umin[{i}] = {lo[i]:g} > umax[{i}] = {hi[i]:g}")
        if up is None:
            up_arr = np.minimum(np.maximum(0.0, lo), hi)
            up_arr.setflags(write=False)
        else:
            up_arr = _as_array("up", up, (m,))
            out = (up_arr < lo) | (up_arr > hi)
            if out.any():
                i = int(np.argmax(out))
                raise ProblemError(
                    f"up: up[{i}] = {up_arr[i]:g} outside the limits [{lo[i]:g}, {hi[i]:g}]"
                )
        rmin = _as_array("rate_min", np.full(m, -np.inf) if rate_min is None else rate_min, (m,), allow_inf=True)
        rmax = _as_array("rate_max", np.full(m, np.inf) if rate_max is None else rate_max, (m,), allow_inf=True)
        if (rmin > 0).any():
            i = int(np.argmax(rmin > 0))
            raise ProblemError(f"rate_min: rate_min[{i}] = {rmin[i]:g} must be <= 0")
        if (rmax < 0).any():
            i = int(np.argmax(rmax < 0))
            raise ProblemError(f"rate_max: rate_max[{i}] = {rmax[i]:g} must be >= 0")
        names_t = self._labels("names", names, m, "u")
        axes_t = self._labels("axes", axes, k, "v")
        setter = object.__setattr__
        setter(self, "_frozen", False)
        for attr, val in (
            ("B", B_arr), ("umin", lo), ("umax", hi), ("up", up_arr),
            ("Wu", _as_weight("Wu", Wu, m)), ("Wv", _as_weight("Wv", Wv, k)),
            ("rate_min", rmin), ("rate_max", rmax), ("names", names_t), ("axes", axes_t),
            ("k", k), ("m", m),
            ("has_rate_limits", bool(np.isfinite(rmin).any() or np.isfinite(rmax).any())),
        ):
            setter(self, attr, val)
        setter(self, "_frozen", True)

    @staticmethod
    def _labels(field: str, labels: Sequence[str] | None, n: int, prefix: str) -> tuple[str, ...]:
        if labels is None:
            return tuple(f"{prefix}{i}" for i in range(n))
        if isinstance(labels, str):
            raise ProblemError(f"{field}: expected a sequence of {n} strings, got a string")
        out = tuple(str(s) for s in labels)
        if len(out) != n:
            raise ProblemError(f"{field}: expected {n} names, got {len(out)}")
        if len(set(out)) != n:
            raise ProblemError(f"{field}: names must be unique")
        return out

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"Problem is immutable; use Problem.replace(...) to change {name!r}")

    def __repr__(self) -> str:
        return f"Problem(k={self.k}, m={self.m}, rate_limits={self.has_rate_limits})"

    # ------------------------------------------------------------------ derived
    @property
    def jammed(self) -> NDArray[np.bool_]:
        """Effectors with ``umin == umax`` (held at that position)."""
        return self.umin == self.umax

    def replace(self, **changes: Any) -> Problem:
        """Return a new validated Problem with some fields changed."""
        fields = dict(
            B=self.B, umin=self.umin, umax=self.umax, up=self.up, Wu=self.Wu, Wv=self.Wv,
            rate_min=self.rate_min, rate_max=self.rate_max, names=self.names, axes=self.axes,
        )
        unknown = set(changes) - set(fields)
        if unknown:
            raise TypeError(f"Problem.replace: unknown field(s) {sorted(unknown)}")
        if ("umin" in changes or "umax" in changes) and "up" not in changes:
            lo = np.asarray(changes.get("umin", self.umin), dtype=float)
            hi = np.asarray(changes.get("umax", self.umax), dtype=float)
            if lo.shape == self.up.shape and hi.shape == self.up.shape:
                fields["up"] = np.minimum(np.maximum(self.up, lo), hi)
        fields.update(changes)
        return Problem(**fields)

    def index(self, effector: int | str) -> int:
        """Index of an effector given by position or name."""
        if isinstance(effector, str):
            try:
                return self.names.index(effector)
            except ValueError:
                raise ProblemError(f"effector: unknown name {effector!r}; known: {list(self.names)}") from None
        i = int(effector)
        if not 0 <= i < self.m:
            raise ProblemError(f"effector: index {i} out of range 0..{self.m - 1}")
        return i

    def with_jam(self, effector: int | str, position: float) -> Problem:
        """Effector held at ``position`` (``umin = umax = position``): a jam or hard-over."""
        i = self.index(effector)
        pos = float(position)
        if not (np.isfinite(pos) and self.umin[i] <= pos <= self.umax[i]):
            raise ProblemError(
                f"position: jam position {position!r} of effector {self.names[i]!r} outside its "
                f"limits [{self.umin[i]:g}, {self.umax[i]:g}]"
            )
        lo, hi = self.umin.copy(), self.umax.copy()
        lo[i] = hi[i] = pos
        return self.replace(umin=lo, umax=hi)

    def with_effectiveness(self, effector: int | str, fraction: float) -> Problem:
        """Scale an effector's column of ``B`` by ``fraction`` in [0, 1] (loss of effectiveness)."""
        i = self.index(effector)
        f = float(fraction)
        if not (np.isfinite(f) and 0.0 <= f <= 1.0):
            raise ProblemError(f"fraction: effectiveness {fraction!r} must be in [0, 1]")
        B = self.B.copy()
        B[:, i] *= f
        return self.replace(B=B)

    def with_limits(self, effector: int | str, lo: float, hi: float) -> Problem:
        """Reduced position limits ``[lo, hi]`` for one effector (must lie within the old ones)."""
        i = self.index(effector)
        lo_f, hi_f = float(lo), float(hi)
        if not (np.isfinite(lo_f) and np.isfinite(hi_f) and lo_f <= hi_f):
            raise ProblemError(f"limits: [{lo!r}, {hi!r}] is not an ordered finite interval")
        umin, umax = self.umin.copy(), self.umax.copy()
        umin[i], umax[i] = lo_f, hi_f
        return self.replace(umin=umin, umax=umax)

    def with_health(self, health: Any) -> Problem:
        """The problem with effector failures applied: ``{effector: alloc.health.EffectorHealth}``.

        See :mod:`alloc.health` for the failure kinds and their one meaning each.
        """
        from .health import apply_health

        return apply_health(self, health)

    # ------------------------------------------------------------ rate limits
    def check_demand(self, v: ArrayLike) -> FloatArray:
        """Validate a demand vector; return it as a float array of shape (k,)."""
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DemandError(f"v: not a numeric vector ({exc})") from exc
        if arr.shape != (self.k,):
            if arr.size == self.k and arr.ndim <= 2:
                arr = arr.reshape(self.k)
            else:
                raise DemandError(f"v: expected shape ({self.k},), got {arr.shape}")
        if not np.isfinite(arr).all():
            raise DemandError(f"v: non-finite value at index {int(np.argmax(~np.isfinite(arr)))}")
        return arr

    def effective_bounds(self, u_prev: ArrayLike | None = None, dt: float | None = None) -> tuple[FloatArray, FloatArray]:
        """Position and rate limits combined over one time step (seed Eq 1.28).

        ``lo = max(umin, u_prev + rate_min dt)`` and ``hi = min(umax, u_prev + rate_max dt)``.
        The seed prints the rate terms of Eq 1.28 loosely (``max[u_dot_max dt, ...]``); this is
        what its text means: an effector can move at most ``rate * dt`` in one step and never
        leave its position limits.  When ``u_prev`` lies so far outside the position limits
        that the two intervals do not meet (e.g. right after limits were reduced), position
        limits win: the effector is commanded to the nearest limit.

        Without ``u_prev`` and ``dt`` the bounds are the position limits.
        """
        if u_prev is None and dt is None:
            return self.umin, self.umax
        if u_prev is None or dt is None:
            raise DemandError("u_prev/dt: rate limits need both u_prev and dt (or neither)")
        try:
            dt_f = float(dt)
        except (TypeError, ValueError) as exc:
            raise DemandError(f"dt: not a number ({dt!r})") from exc
        if not math.isfinite(dt_f) or dt_f <= 0.0:
            raise DemandError(f"dt: time step must be positive and finite, got {dt!r}")
        try:
            up = np.asarray(u_prev, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DemandError(f"u_prev: not a numeric vector ({exc})") from exc
        if up.shape != (self.m,):
            raise DemandError(f"u_prev: expected shape ({self.m},), got {up.shape}")
        if not all_finite(up):
            raise DemandError(f"u_prev: non-finite value at index {int(np.argmax(~np.isfinite(up)))}")
        return rate_window(self.umin, self.umax, self.rate_min, self.rate_max, up, dt_f)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description (lists of floats; infinite rates as None)."""
        def fin(a: FloatArray) -> list[float | None]:
            return [float(x) if np.isfinite(x) else None for x in a]

        return {
            "B": self.B.tolist(), "umin": self.umin.tolist(), "umax": self.umax.tolist(),
            "up": self.up.tolist(), "Wu": self.Wu.tolist(), "Wv": self.Wv.tolist(),
            "rate_min": fin(self.rate_min), "rate_max": fin(self.rate_max),
            "names": list(self.names), "axes": list(self.axes),
        }
