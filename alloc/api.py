"""Public entry points: allocate, make_allocator, allocate_batch."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._engine._kernels import finish_batch, finish_owned, fused_affine, owned_demand
from ._engine._threads import split_rows, threads_for
from .exceptions import AllocError, DemandError, MethodTypeError, ProblemTypeError, SolverError
from .export_data import ExportData
from .problem import MAX_MAGNITUDE, Problem, as_float_array, check_magnitude
from .registry import DEFAULT_METHOD, FloatArray, Method, build
from .result import EXACT_RTOL, BatchResult, Result, Status

__all__ = ["Allocator", "make_allocator", "allocate", "allocate_batch", "has_c_call_path"]

_EXACT, _UNATT, _FALLBACK = Status.EXACT, Status.UNATTAINABLE, Status.FALLBACK
_F64 = np.dtype(np.float64)
_clock = time.perf_counter
_new_result = tuple.__new__  # Result is a tuple: built in one C call on the fast paths
_STATUS = (Status.EXACT, Status.UNATTAINABLE)  # by the kernels' code

class _PyCallBase:
    """The allocator's lock where ``alloc._engine._fastcall`` is not built: a re-entrant lock made with
    the object (also by ``__new__`` alone, as unpickling and copying do)."""

    __slots__ = ("_rlock",)

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        self = super().__new__(cls)
        self._rlock = threading.RLock()
        return self

    def _acquire(self) -> None:
        self._rlock.acquire()

    def _release(self) -> None:
        self._rlock.release()


try:  # the call path in C (alloc/_engine/_fastcall.c, built at install); without it the same path in Python
    from ._engine._fastcall import FastCall as _CallBase
except ImportError:  # pragma: no cover - a build without a C compiler
    _CallBase = _PyCallBase


def has_c_call_path() -> bool:
    """Whether an allocator's call runs in C: ``alloc._engine._fastcall`` was built at install (it
    needs a C compiler; without it the same path runs in Python, with the same answers).
    A fact of the installation, read from :class:`Allocator`'s base class; not a switch."""
    return _CallBase is not _PyCallBase

#: dtype kinds converted to float64 at the boundary (others go to the problem's checks)
_REAL_KINDS = frozenset("fiu")


def _compiled_layout(a: Any) -> Any:
    """``a`` in the layout the kernels are compiled for, when it is a real numeric array.

    numba compiles one machine-code version per argument type, and an array's type includes
    its dtype, layout (C-contiguous or not) and writeability: a strided, reversed,
    transposed, unaligned, byte-swapped, read-only, float32 or integer array met for the
    first time would compile a new kernel inside the call (seconds).  A copy into a new
    C-contiguous, aligned, native float64 array costs well under a microsecond and gives the
    same values, so the same bits.  Anything else (lists, complex, objects) is returned
    unchanged for the problem's checks to convert or refuse."""
    if type(a) is np.ndarray and a.dtype.kind in _REAL_KINDS:
        f = a.flags
        if not (a.dtype == _F64 and f.c_contiguous and f.aligned and f.writeable):
            return np.array(a, dtype=np.float64, order="C")
    return a


def _describe(value: Any) -> str:
    """What was passed, for an error message: its type, and its shape or a short repr."""
    if isinstance(value, np.ndarray):
        return f"numpy.ndarray of shape {value.shape}"
    text = repr(value)
    return f"{type(value).__name__} {text[:60] + '...' if len(text) > 60 else text}"


def _check_arguments(problem: Any, method: Any) -> None:
    """Raise the named TypeError for a first argument that is not a Problem or a method that
    is not a name."""
    if not isinstance(problem, Problem):
        hint = {dict: "; build one with alloc.Problem(**d)",
                str: "; a named vehicle is alloc.vehicles.problem(name)"}.get(type(problem), "")
        raise ProblemTypeError(f"problem: expected an alloc.Problem, got {_describe(problem)}{hint}")
    if not isinstance(method, str):
        raise MethodTypeError(f"method: expected a method name (str), got {_describe(method)}")


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _entry_point(kernel: Any, args: tuple[Any, ...]) -> Any:
    """The compiled entry of numba dispatcher ``kernel`` for exactly the types of ``args``.

    Calling it skips the dispatcher's type resolution (0.2-0.6 us a call); the C call path
    uses it only for arguments of exactly these types (1-D float64 arrays, C-contiguous,
    aligned, native byte order; a Python float).  Anything else -- or a kernel that is not a
    dispatcher -- keeps the dispatcher itself."""
    try:
        from numba import typeof

        sig = tuple(typeof(a) for a in args)
        overload = kernel.overloads.get(sig)
        if overload is None:
            kernel.compile(sig)  # what the first call would do (from numba's cache when it has it)
            overload = kernel.overloads[sig]
        return overload.entry_point
    except Exception:  # noqa: BLE001 - not a numba dispatcher, or a type numba cannot name
        return kernel


def _reason(exc: BaseException) -> str:
    """A fallback's message: the backend's own words, or the exception's type and text."""
    return str(exc) if isinstance(exc, SolverError) else f"{type(exc).__name__}: {exc}"


class Allocator(_CallBase):
    """A method built once for a problem; call it with demands.

    ``allocator(v, u_prev=None, dt=None) -> Result``.  With ``u_prev`` and ``dt`` the
    command also respects the rate limits over that step (Eq 1.28).  The output is always
    finite and within the bounds.  Inside the valid input domain (README, :mod:`alloc.problem`)
    neither the build nor a call raises: invalid input raises an :class:`~alloc.exceptions.AllocError`
    naming the field (``OptionError``, a TypeError, for options), and anything else a method's
    backend raises -- at build or at call -- becomes the safe answer of
    :class:`~alloc.methods.pseudo_inverse.SafeCommand` with status ``fallback`` and the reason.

    The call is :meth:`_call_py`; where ``alloc._engine._fastcall`` is built (:func:`has_c_call_path`), its fast
    paths run in C (the same compiled kernel with the same arguments, so the same bits) and
    every other case goes to :meth:`_call_py`.

    Thread safety: an allocator is safe to call from several threads at once, and each
    answer is what the same call on this allocator alone would return.  Every call and every
    :meth:`batch` holds the allocator's own re-entrant lock while it touches the method's
    mutable state (factorisation caches, warm starts, backend models, none of which are
    re-entrant) -- on the C path and on the Python path alike.  The one path that takes no
    lock is the fused affine kernel ``u = clip(c + P v)`` without rate limits, which only
    reads its matrix.  Batches that run on internal threads (:mod:`alloc._engine._threads`) hold the
    lock in the calling thread and give each worker thread private solver state.  Different
    allocators share no mutable state and do not wait for each other.

    Inputs are normalised at the boundary: a demand, ``u_prev`` or batch ``V`` that is not a
    C-contiguous, aligned, native-order, writeable float64 array is copied into one, so no
    call ever compiles a kernel for a new argument layout.
    """

    __slots__ = ("problem", "method", "impl", "build_error", "_safe", "_B", "_lo", "_hi", "_kshape", "_mshape",
                 "_W", "_packed", "_packed_rate", "_zm", "_su", "_sv", "_sa", "_sr")

    def __init__(self, problem: Problem, method: str, **options: Any) -> None:
        _check_arguments(problem, method)
        self.problem = problem
        self.method = method
        #: why the method could not be built (every call is then a fallback), or ""
        self.build_error = ""
        try:
            self.impl: Method | None = build(problem, method, options)
        except SolverError as exc:
            self.impl, self.build_error = None, _reason(exc)
        except AllocError:
            raise  # bad problem, option or method name: the caller's error, naming the field
        except Exception as exc:  # noqa: BLE001 - a backend failing on a valid problem
            self.impl, self.build_error = None, _reason(exc)
        from .methods.pseudo_inverse import SafeCommand  # loaded with the registry's methods, not with alloc

        self._safe = SafeCommand(problem)
        self._B = problem.B
        self._lo, self._hi = problem.umin, problem.umax
        m, k = problem.m, problem.k
        self._kshape, self._mshape = (k,), (m,)
        # the fast paths' packed output (alloc._engine._kernels.packed_out): u, B u, v, v - B u
        self._su, self._sa, self._sv, self._sr = (slice(0, m), slice(m, m + k), slice(m + k, m + 2 * k),
                                                  slice(m + 2 * k, m + 3 * k))
        self._zm = np.zeros(m)  # the u_prev argument of a call without rate limits (unused)
        self._W = None
        impl = self.impl
        fused = None if impl is None else impl.fused
        if fused is not None:  # closed-form u = clip(c + P v): one packed compiled call
            c, P = fused
            W = np.column_stack([c, P, problem.B.T, problem.umin, problem.umax])
            if np.isfinite(W).all():
                self._W = np.ascontiguousarray(W, dtype=float)
        self._packed = None if impl is None else impl.packed
        self._packed_rate = None if impl is None else impl.packed_rate
        self._wire()

    def _wire(self) -> None:
        """Hand the C call path (``alloc._engine._fastcall``) the kernels of :meth:`_call_py`'s fast paths."""
        if _CallBase is _PyCallBase:
            return
        k, m = self.problem.k, self.problem.m
        if self._W is not None:
            kernel, pre, post = fused_affine, (self._W,), (EXACT_RTOL, MAX_MAGNITUDE)
        elif self._packed is not None:
            kernel, pre, post = self._packed[0], tuple(self._packed[1]), (self._zm, 0.0)
        else:
            kernel, pre, post = None, (), ()
        if kernel is not None:
            kernel = _entry_point(kernel, (*pre, np.zeros(k), *post))
        rkernel, rpre = (None, ()) if self._packed_rate is None else (self._packed_rate[0], tuple(self._packed_rate[1]))
        if rkernel is not None:
            rkernel = _entry_point(rkernel, (*rpre, np.zeros(k), np.zeros(m), 1.0))
        # only the fused affine kernel is stateless (it reads W); every other kernel is locked
        self._fast_setup(kernel, pre, post, rkernel, rpre, self.method, _STATUS, Result, k, m, MAX_MAGNITUDE,
                         self._W is None, True)

    def __getstate__(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in Allocator.__slots__ if hasattr(self, name)}

    def __copy__(self) -> Allocator:
        """A deep copy: a copy has its own lock, so it must not share the method's mutable
        state (caches, backend models) with the original."""
        import copy

        return copy.deepcopy(self)

    def __setstate__(self, state: dict[str, Any]) -> None:
        for name, value in state.items():
            setattr(self, name, value)
        self._wire()

    def __repr__(self) -> str:
        return f"Allocator(method={self.method!r}, {self.problem!r})"

    def export_data(self) -> ExportData | None:
        """What the C generator reads of this allocator (:mod:`alloc.export_data`): the method's
        kernel, of its declared kind (:attr:`alloc.method.Method.export`), and the safe answer;
        ``None`` where the method was not built or this instance has no exportable kernel."""
        kernel = None if self.impl is None else self.impl.export_data()
        if kernel is None:
            return None
        return ExportData(method=self.method, kernel=kernel, safe=self._safe.affine_map())

    def _call_py(self, v: ArrayLike, *, u_prev: ArrayLike | None = None, dt: float | None = None) -> Result:
        """``allocator(v, u_prev=None, dt=None)``: the call (in Python; see the class docstring)."""
        # Every input form is brought to the one the kernels are compiled for, so that every
        # form of the same values takes the same path (and the same compiled code).
        v = _compiled_layout(v)
        if not (type(v) is np.ndarray and v.shape == self._kshape and v.dtype == _F64):
            v = self.problem.check_demand(v)  # DemandError naming v, or a new float64 array (k,)
        if u_prev is not None and dt is not None:
            u_prev = _compiled_layout(u_prev)
            if not (type(u_prev) is np.ndarray and u_prev.shape == self._mshape and u_prev.dtype == _F64):
                u_prev = self.problem.check_u_prev(u_prev)
            if type(dt) is not float:
                dt = self.problem.check_dt(dt)
        # fast paths: one compiled call checks v (and u_prev), allocates, computes B u, the
        # residual and the status code into one new array; the Result holds read-only views
        res = None
        if u_prev is None and dt is None:
            if self._W is not None:
                t0 = _clock()
                res = fused_affine(self._W, v, EXACT_RTOL, MAX_MAGNITUDE)
            elif self._packed is not None:
                kernel, state = self._packed
                self._acquire()
                try:
                    t0 = _clock()
                    res = kernel(*state, v, self._zm, 0.0)
                finally:
                    self._release()
        elif self._packed_rate is not None and type(dt) is float and 0.0 < dt <= MAX_MAGNITUDE and u_prev is not None:
            kernel, state = self._packed_rate
            self._acquire()
            try:
                t0 = _clock()
                res = kernel(*state, v, u_prev, dt)
            finally:
                self._release()
        if res is not None and res[1] < 2:
            out = res[0]
            out.setflags(write=False)
            return _new_result(Result, (out[self._su], out[self._sv], out[self._sa], _STATUS[res[1]], self.method,
                                        res[2], _clock() - t0, "", out[self._sr]))
        v, ok = owned_demand(v, MAX_MAGNITUDE)  # the result owns its demand: the caller may reuse the array
        if not ok:
            self.problem.check_demand(v)  # raises DemandError naming v
        self._acquire()
        try:
            return self._solve(v, u_prev, dt)
        finally:
            self._release()

    if _CallBase is _PyCallBase:  # pragma: no cover - the Python base has no __call__ of its own
        __call__ = _call_py

    def _solve(self, v: FloatArray, u_prev: ArrayLike | None, dt: float | None) -> Result:
        """Allocate a validated demand (owned copy) through the method, or the safe answer
        (the caller holds the allocator's lock)."""
        problem = self.problem
        if u_prev is None and dt is None:
            lo, hi, up = self._lo, self._hi, None
        else:
            lo, hi = problem.effective_bounds(u_prev, dt)
            up = problem.check_u_prev(u_prev)
        t0 = time.perf_counter()
        message = self.build_error
        if self.impl is not None:
            try:
                u_m, iterations = self.impl.solve(v, lo, hi, up)
                if not (type(u_m) is np.ndarray and u_m.dtype == _F64):
                    u_m = np.asarray(u_m, dtype=float)
                if u_m.shape != self._mshape:
                    raise SolverError(f"{self.method} returned a command of shape {u_m.shape}")
                # one compiled call: the result's arrays in one new buffer, as on the fast paths
                out, code = finish_owned(self._B, u_m, lo, hi, v, EXACT_RTOL)
                if code == 2:
                    raise SolverError(f"{self.method} produced non-finite commands")
                out.setflags(write=False)
                return _new_result(Result, (out[self._su], out[self._sv], out[self._sa], _STATUS[code],
                                            self.method, int(iterations), time.perf_counter() - t0, message,
                                            out[self._sr]))
            except Exception as exc:  # noqa: BLE001 - any backend failure becomes the safe answer
                message = _reason(exc)
        u, iterations, status = self._safe(v, lo, hi), 0, _FALLBACK
        v_ach = self._B @ u
        if not np.isfinite(v_ach).all():  # unreachable inside the valid domain; never report NaN
            u = np.minimum(np.maximum(problem.up, lo), hi)
            v_ach = self._B @ u
        return Result(_frozen(u), _frozen(v), _frozen(v_ach), status, self.method, iterations,
                      time.perf_counter() - t0, message)

    def batch(self, V: ArrayLike) -> BatchResult:
        """Allocate each row of ``V`` (N, k) without rate limits; vectorised where the method allows.

        Row ``i`` equals ``self(V[i])`` (status included).  Methods with a compiled
        solve-and-classify pass (:meth:`Method.batch_finished`: ``qp``, ``wls``, ``dynamic``)
        redo by the single call only the rows that pass could not finish (an iteration cap);
        elsewhere, where the vectorised path cannot vouch for that (non-finite output, an
        exception), the rows are allocated one by one.
        """
        problem = self.problem
        Varr = as_float_array("V", V, DemandError)
        if Varr.ndim != 2 or Varr.shape[1] != problem.k:
            raise DemandError(f"V: expected shape (N, {problem.k}), got {Varr.shape}")
        check_magnitude("V", Varr, DemandError)
        if not Varr.flags.c_contiguous:  # a Fortran-ordered or transposed V (the copy above kept its order)
            Varr = np.ascontiguousarray(Varr)
        Varr.setflags(write=False)
        self._acquire()
        try:
            return self._batch(Varr)
        finally:
            self._release()

    def _batch(self, Varr: FloatArray) -> BatchResult:
        """:meth:`batch` of a validated, read-only, C-contiguous ``V`` (the caller holds the lock)."""
        problem = self.problem
        t0 = time.perf_counter()
        U = None
        fused = None
        if self.impl is not None:
            try:  # solve and classify in one compiled pass, where the method has one
                fused = self.impl.batch_finished(Varr)
            except Exception:  # noqa: BLE001 - the per-row path below handles every failure
                fused = None
        if fused is not None:
            U, Vach, codes = fused
            status = np.where(codes == 0, _EXACT.value, _UNATT.value).astype("<U12")
            for i in np.flatnonzero(codes > 1):  # a level's cap, a non-finite answer: the single call
                r = self(Varr[i])
                U[i], Vach[i], status[i] = r.u, r.v_achieved, r.status.value
            return BatchResult(_frozen(U), Varr, _frozen(Vach), _frozen(status), self.method, time.perf_counter() - t0)
        if self.impl is not None:
            try:
                U = self.impl.solve_batch(Varr, self._lo, self._hi)
            except Exception:  # noqa: BLE001 - the per-row path below handles every failure
                U = None
        if U is not None and U.shape == (len(Varr), problem.m):
            U = np.array(U, dtype=float)  # own, contiguous: clipped in place by the kernel
            Vach = np.empty((len(Varr), problem.k))
            B, lo, hi = self._B, self._lo, self._hi
            codes = np.concatenate(split_rows(  # row by row, so any split gives the same bits
                lambda a, b: finish_batch(B, U[a:b], lo, hi, Varr[a:b], Vach[a:b], EXACT_RTOL),
                len(Varr), threads_for(len(Varr))))
            if not (codes == 2).any():  # the single call's kernel: same B u, same status
                status = np.where(codes == 0, _EXACT.value, _UNATT.value)
                return BatchResult(_frozen(U), Varr, _frozen(Vach), _frozen(status), self.method,
                                   time.perf_counter() - t0)
        results = [self(v) for v in Varr]  # the single call itself (its fast path where it has one)
        m = problem.m
        U = np.array([r.u for r in results]).reshape(len(results), m)
        Vach = np.array([r.v_achieved for r in results]).reshape(len(results), problem.k)
        status = np.array([r.status.value for r in results], dtype="<U12")
        return BatchResult(_frozen(U), Varr, _frozen(Vach), _frozen(status), self.method, time.perf_counter() - t0)


def make_allocator(problem: Problem, method: str = DEFAULT_METHOD, **options: Any) -> Allocator:
    """Build ``method`` for ``problem`` once; the returned callable allocates fast (and may be
    shared by threads: see :class:`Allocator`).

    Anything but a :class:`~alloc.problem.Problem` as ``problem`` raises
    :class:`~alloc.exceptions.ProblemTypeError`, a ``method`` that is not a str
    :class:`~alloc.exceptions.MethodTypeError` (both TypeErrors naming the field).

    Parameters
    ----------
    problem : Problem
    method : str
        A name from :func:`alloc.methods`.
    **options
        Method options (see ``alloc methods``); unknown options raise ``OptionError`` (a TypeError).

    Examples
    --------
    >>> import alloc
    >>> p = alloc.Problem([[1.0, 1.0, 0.5]], [-1, -1, -1], [1, 1, 1])
    >>> allocate = alloc.make_allocator(p, "qp")
    >>> r = allocate([1.5])
    >>> r.status.value, round(float(r.v_achieved[0]), 6)
    ('exact', 1.5)
    """
    return Allocator(problem, method, **options)


def allocate(
    problem: Problem,
    v: ArrayLike,
    method: str = DEFAULT_METHOD,
    *,
    u_prev: ArrayLike | None = None,
    dt: float | None = None,
    **options: Any,
) -> Result:
    """Allocate one demand ``v`` (builds the method each call: use :func:`make_allocator` in loops)."""
    return Allocator(problem, method, **options)(v, u_prev=u_prev, dt=dt)


def allocate_batch(problem: Problem, V: ArrayLike, method: str = DEFAULT_METHOD, **options: Any) -> BatchResult:
    """Allocate the rows of ``V`` (N, k); vectorised for the pseudo-inverse family and ganging."""
    return Allocator(problem, method, **options).batch(V)
