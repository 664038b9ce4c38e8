"""The control allocation problem, validated once and immutable.

Glossary (seed section 1.3.4): the seed's desired moment ``m_d`` is called
``v`` here (the demand, or the SMC pseudo-command); its control power matrix
``B`` (Eq 1.14) keeps its name; ``u_pref`` is ``up``; ``W_u``/``W_d`` are
``Wu``/``Wv``.  Weights are quadratic-form matrices as in Eqs 1.20-1.23: the
preference cost is ``(u - up)' Wu (u - up)`` and the moment-error cost is
``(B u - v)' Wv (B u - v)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .domain import (  # re-exported: the problem's checks, imported from here by many
    MAX_AXES,
    MAX_EFFECTORS,
    MAX_MAGNITUDE,
    MIN_WEIGHT,
    as_float_array,
    as_real,
    check_magnitude,
    short_repr,
    singular_within_round_off,
)
from .effector_health import EffectorHealth, _checked_health
from .exceptions import DemandError, ProblemError

__all__ = ["Problem"]

FloatArray = NDArray[np.float64]


def _as_array(name: str, value: ArrayLike, shape: tuple[int, ...], *, allow_inf: bool = False,
              none_as: float | None = None) -> FloatArray:
    """Return ``value`` as a read-only float array of ``shape`` or raise ProblemError."""
    arr = as_float_array(name, value, none_as=none_as)
    if arr.shape != shape:
        raise ProblemError(f"{name}: expected shape {shape}, got {arr.shape}")
    check_magnitude(name, arr, allow_inf=allow_inf)
    arr.setflags(write=False)
    return arr


def _as_weight(name: str, value: ArrayLike | None, n: int) -> FloatArray:
    """A symmetric positive definite ``n x n`` weight; a 1-D input is a diagonal.

    Eigenvalues must lie in ``[MIN_WEIGHT, MAX_MAGNITUDE]`` (the valid input domain).
    """
    if value is None:
        w = np.eye(n)
        w.setflags(write=False)
        return w
    arr = as_float_array(name, value)
    if arr.ndim == 1:
        arr = _as_array(name, arr, (n,))
        if (arr < MIN_WEIGHT).any():
            i = int(np.argmax(arr < MIN_WEIGHT))
            why = "is not positive" if arr[i] <= 0 else f"is below the smallest weight {MIN_WEIGHT:g}"
            raise ProblemError(f"{name}: diagonal weight {name}[{i}] = {arr[i]:g} {why}")
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
    # Entries within MAX_MAGNITUDE still allow an eigenvalue up to n times larger (all
    # entries 1e50 at n = 512: 5e52), so both ends of the spectrum are bounded; the
    # condition number is then at most MAX_MAGNITUDE / MIN_WEIGHT.
    lam = np.linalg.eigvalsh((arr + arr.T) / 2.0)
    if singular_within_round_off(arr, float(lam[0]), float(lam[-1])):
        raise ProblemError(f"{name}: weight matrix is not positive definite within round-off (eigenvalues "
                           f"[{lam[0]:.3g}, {lam[-1]:.3g}], ratio below {n} x machine epsilon)")
    if lam[0] < MIN_WEIGHT:
        raise ProblemError(f"{name}: weight matrix's smallest eigenvalue {lam[0]:g} is below {MIN_WEIGHT:g} "
                           "(not positive definite within the valid domain)")
    if lam[-1] > MAX_MAGNITUDE:
        raise ProblemError(f"{name}: weight matrix's largest eigenvalue {lam[-1]:g} is above {MAX_MAGNITUDE:g} "
                           "(outside the valid domain)")
    return arr


def _rate_window(*args: Any) -> tuple[np.ndarray, np.ndarray]:
    # The compiled kernel is imported at the first rate-limited call, not with this module:
    # importing numba costs 0.2-0.3 s of CPU, which every ``import alloc`` (and the service's
    # start) would pay before anything is allocated.  The first call rebinds the name, so
    # later calls reach the kernel directly.
    global _rate_window
    from ._engine._kernels import rate_window
    _rate_window = rate_window
    return rate_window(*args)


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
    # set once in __init__ through object.__setattr__ (the class is immutable); declared here for
    # readers and type checkers
    B: NDArray[np.float64]
    umin: NDArray[np.float64]
    umax: NDArray[np.float64]
    up: NDArray[np.float64]
    Wu: NDArray[np.float64]
    Wv: NDArray[np.float64]
    rate_min: NDArray[np.float64]
    rate_max: NDArray[np.float64]
    names: tuple[str, ...]
    axes: tuple[str, ...]
    k: int
    m: int
    has_rate_limits: bool
    _frozen: bool

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
        B_arr = as_float_array("B", B)
        if B_arr.ndim == 1:
            B_arr = B_arr[np.newaxis, :]
        if B_arr.ndim != 2 or B_arr.shape[0] < 1 or B_arr.shape[1] < 1:
            raise ProblemError(f"B: expected a 2-D matrix (k x m), got shape {B_arr.shape}")
        k, m = B_arr.shape
        if k > MAX_AXES or m > MAX_EFFECTORS:
            raise ProblemError(f"B: {k} x {m} exceeds the size caps (k <= {MAX_AXES}, m <= {MAX_EFFECTORS})")
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
        rmin = _as_array("rate_min", np.full(m, -np.inf) if rate_min is None else rate_min, (m,),
                         allow_inf=True, none_as=-np.inf)
        rmax = _as_array("rate_max", np.full(m, np.inf) if rate_max is None else rate_max, (m,),
                         allow_inf=True, none_as=np.inf)
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
        try:
            out = tuple(labels)
        except TypeError:
            raise ProblemError(f"{field}: expected a sequence of {n} strings, got {short_repr(labels)}") from None
        for s in out:
            if not isinstance(s, str):  # 1 and "1" would be one name in JSON, two here
                raise ProblemError(f"{field}: names must be strings, got {type(s).__name__} {short_repr(s)}")
        out = tuple(str(s) for s in out)  # a numpy str_ as a plain str
        if len(out) != n:
            raise ProblemError(f"{field}: expected {n} names, got {len(out)}")
        if len(set(out)) != n:
            raise ProblemError(f"{field}: names must be unique")
        return out

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"Problem is immutable; use Problem.replace(...) to change {name!r}")

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickle, ``copy`` and ``deepcopy`` rebuild through the constructor.

        So an unpickled problem is validated like any other input (a pickle comes from
        outside), its arrays are read-only again, and its values are bit for bit the
        original's (the constructor copies floats without arithmetic).
        """
        return _problem_from_fields, (self.B, self.umin, self.umax, self.up, self.Wu, self.Wv,
                                      self.rate_min, self.rate_max, self.names, self.axes)

    def __repr__(self) -> str:
        return f"Problem(k={self.k}, m={self.m}, rate_limits={self.has_rate_limits})"

    # ------------------------------------------------------------------ derived
    @property
    def jammed(self) -> NDArray[np.bool_]:
        """Effectors with ``umin == umax`` (held at that position)."""
        return self.umin == self.umax

    def replace(self, **changes: Any) -> Problem:
        """Return a new validated Problem with some fields changed."""
        fields: dict[str, Any] = dict(
            B=self.B, umin=self.umin, umax=self.umax, up=self.up, Wu=self.Wu, Wv=self.Wv,
            rate_min=self.rate_min, rate_max=self.rate_max, names=self.names, axes=self.axes,
        )
        unknown = set(changes) - set(fields)
        if unknown:
            raise TypeError(f"Problem.replace: unknown field(s) {sorted(unknown)}")
        if ("umin" in changes or "umax" in changes) and "up" not in changes:
            try:
                lo = as_float_array("umin", changes.get("umin", self.umin))
                hi = as_float_array("umax", changes.get("umax", self.umax))
            except ProblemError:
                pass  # the constructor below reports the bad limits, naming them
            else:
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
                raise ProblemError(f"effector: unknown name {short_repr(effector)}; known: {short_repr(list(self.names), 200)}") from None
        if isinstance(effector, (bool, np.bool_)):
            raise ProblemError(f"effector: expected an index or a name, got {short_repr(effector)}")
        if isinstance(effector, (int, np.integer)):
            i = int(effector)
        elif isinstance(effector, (float, np.floating)) and float(effector).is_integer():
            i = int(effector)  # 2.0 from JSON; 1.7 is an error, never truncated
        else:
            raise ProblemError(f"effector: {short_repr(effector)} is not an integer index or a name")
        if not 0 <= i < self.m:
            raise ProblemError(f"effector: index {short_repr(i)} out of range 0..{self.m - 1}")
        return i

    def with_jam(self, effector: int | str, position: float) -> Problem:
        """Effector held at ``position`` (``umin = umax = position``): a jam or hard-over."""
        i = self.index(effector)
        pos = as_real("position", position)
        if not self.umin[i] <= pos <= self.umax[i]:
            raise ProblemError(
                f"position: jam position {pos:g} of effector {self.names[i]!r} outside its "
                f"limits [{self.umin[i]:g}, {self.umax[i]:g}]"
            )
        lo, hi = self.umin.copy(), self.umax.copy()
        lo[i] = hi[i] = pos
        return self.replace(umin=lo, umax=hi)

    def with_effectiveness(self, effector: int | str, fraction: float) -> Problem:
        """Scale an effector's column of ``B`` by ``fraction`` in [0, 1] (loss of effectiveness)."""
        i = self.index(effector)
        f = as_real("fraction", fraction)
        if not 0.0 <= f <= 1.0:
            raise ProblemError(f"fraction: effectiveness {f:g} must be in [0, 1]")
        B = self.B.copy()
        B[:, i] *= f
        return self.replace(B=B)

    def with_limits(self, effector: int | str, lo: float, hi: float) -> Problem:
        """Reduced position limits ``[lo, hi]`` for one effector, within its current limits.

        Widening is refused: a failure never gives an effector more travel (use
        :meth:`replace` to change the nominal limits).
        """
        i = self.index(effector)
        lo_f, hi_f = as_real("lo", lo), as_real("hi", hi)
        if lo_f > hi_f:
            raise ProblemError(f"limits: [{lo_f:g}, {hi_f:g}] is not an ordered interval")
        if lo_f < self.umin[i] or hi_f > self.umax[i]:
            raise ProblemError(f"limits: [{lo_f:g}, {hi_f:g}] of effector {self.names[i]!r} must lie within its "
                               f"limits [{self.umin[i]:g}, {self.umax[i]:g}]")
        umin, umax = self.umin.copy(), self.umax.copy()
        umin[i], umax[i] = lo_f, hi_f
        return self.replace(umin=umin, umax=umax)

    def with_health(self, health: Mapping[int | str, EffectorHealth]) -> Problem:
        """The problem with effector failures applied: ``{effector: alloc.health.EffectorHealth}``
        (``self`` when all are healthy).

        Keys are effector names or indices.  See :mod:`alloc.health` for the failure kinds and
        their one meaning each.  Reduced position and rate limits act within the nominal ones
        (their intersection: a failure never widens a limit); reduced limits that do not meet
        the nominal ones, or a jam outside them, raise ProblemError.
        """
        p = self
        rate_min, rate_max = self.rate_min.copy(), self.rate_max.copy()
        for key, h in _checked_health(health).items():
            i = self.index(key)
            if h.effectiveness != 1.0 or h.floating:
                p = p.with_effectiveness(i, 0.0 if h.floating else h.effectiveness)
            if h.floating:
                p = p.with_jam(i, float(self.up[i]))
            elif h.jam_position is not None:
                p = p.with_jam(i, h.jam_position)
            elif h.limits is not None:
                lo0, hi0 = float(self.umin[i]), float(self.umax[i])
                lo, hi = max(h.limits[0], lo0), min(h.limits[1], hi0)
                if lo > hi:
                    raise ProblemError(f"limits: reduced limits [{h.limits[0]:g}, {h.limits[1]:g}] of "
                                       f"{self.names[i]!r} do not meet its nominal limits [{lo0:g}, {hi0:g}]")
                p = p.with_limits(i, lo, hi)
            if h.rate_limits is not None:  # rate_min <= 0 <= rate_max on both sides: never empty
                rate_min[i] = max(h.rate_limits[0], self.rate_min[i])
                rate_max[i] = min(h.rate_limits[1], self.rate_max[i])
        if not (np.array_equal(rate_min, p.rate_min) and np.array_equal(rate_max, p.rate_max)):
            p = p.replace(rate_min=rate_min, rate_max=rate_max)
        return p

    # ------------------------------------------------------------ rate limits
    def check_demand(self, v: ArrayLike) -> FloatArray:
        """Validate a demand vector; return it as a float array of shape (k,)."""
        arr = as_float_array("v", v, DemandError)
        if arr.shape != (self.k,):
            if arr.size == self.k and arr.ndim <= 2:
                arr = arr.reshape(self.k)
            else:
                raise DemandError(f"v: expected shape ({self.k},), got {arr.shape}")
        check_magnitude("v", arr, DemandError)
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
        return _rate_window(self.umin, self.umax, self.rate_min, self.rate_max,
                           self.check_u_prev(u_prev), self.check_dt(dt))

    @staticmethod
    def check_dt(dt: Any) -> float:
        """Validate a time step: a real number in ``(0, MAX_MAGNITUDE]``."""
        dt_f = as_real("dt", dt, DemandError)
        if not dt_f > 0.0:
            raise DemandError(f"dt: time step must be positive, finite and <= {MAX_MAGNITUDE:g}, got {dt_f!r}")
        return dt_f

    def check_u_prev(self, u_prev: ArrayLike) -> FloatArray:
        """Validate the previous command: shape (m,), finite, within the domain (not the limits)."""
        up = as_float_array("u_prev", u_prev, DemandError)
        if up.shape != (self.m,):
            raise DemandError(f"u_prev: expected shape ({self.m},), got {up.shape}")
        check_magnitude("u_prev", up, DemandError)
        return up

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


_ARRAY_FIELDS = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max")


def _problem_from_fields(B: Any, umin: Any, umax: Any, up: Any, Wu: Any, Wv: Any, rate_min: Any, rate_max: Any,
                         names: Any, axes: Any) -> Problem:
    """:meth:`Problem.__reduce__`'s rebuild (module level, so pickle can name it).

    Validated by the constructor; then the problem keeps the very arrays it was handed
    where they equal the validated ones (float64, same shape and values), made read-only.
    Other objects of the same pickle or deep copy (an allocator's bounds) refer to those
    arrays, and methods recognise the problem's own limits by identity (``lo is
    problem.umin``): a copy of the constructor's would take the general path and could
    round differently.
    """
    given = (B, umin, umax, up, Wu, Wv, rate_min, rate_max)
    p = Problem(B, umin, umax, up=up, Wu=Wu, Wv=Wv, rate_min=rate_min, rate_max=rate_max, names=names, axes=axes)
    for name, arr in zip(_ARRAY_FIELDS, given):
        own = getattr(p, name)
        if (type(arr) is np.ndarray and arr.dtype == own.dtype and arr.shape == own.shape
                and arr.tobytes() == own.tobytes()):
            arr.setflags(write=False)
            object.__setattr__(p, name, arr)
    return p
