"""Compiled lexicographic least-squares active-set solver (``qp``, ``wls``, ``dynamic``).

One primal active-set method on the least-squares form (Härkegård 2002, "Efficient active
set algorithms for solving constrained least squares problems in aircraft control
allocation": sequential least squares), compiled with numba so that an allocation is one
compiled call.  It solves a short sequence of *levels*, each lexicographically below the
ones before it:

    level l:   minimise  ||A_l u - b_l||^2 + g_l^2 (u - up)' Wu (u - up)
               subject to  lo <= u <= hi  and  A_i u = A_i u*_i  for the levels i < l

where ``u*_i`` is the answer of level ``i`` (the moments ``A_i u`` an optimum reaches are
unique, so holding them keeps every earlier level optimal).  The two-stage ``qp`` is a
level ``A = Lv' B`` with ``g = 0`` (Eq 1.20) followed by a level with no rows and ``g = 1``
(Eq 1.21); ``priorities`` split the first level by axis; ``wls`` is one level with
``g = gamma``.

Why not the normal equations: stage 1 of ``qp`` has the singular Hessian ``B'WvB`` (rank
``k < m``, worse with collinear columns); a solver working on it needs a ridge and stops
short (moment errors of 1e-6 on unattainable rate-limited demands).  Here every step is
the minimum-norm least-squares solution on the free effectors, computed from a one-sided
Jacobi SVD of the small ``rows x free`` matrix in the ``Wu`` metric, so rank deficiency
is handled by dropping singular values at round-off level and the residual, the gradient
and the multipliers are recomputed from the data at every iterate (no drift).
Multipliers are tested against tolerances scaled to the round-off of their own
computation (``MU_EPS`` times the magnitudes that formed them): near-degenerate cases then
pick the right active set (SOLVER-NOTES, "Lessons").

Every loop is bounded; a level that hits its iteration cap returns ``ok = False`` and the
caller raises :class:`~alloc.exceptions.SolverError` (the allocator's safe fallback).

Speed (measured in ``benchmarks/bench_alloc.py``): the factorisation of a free set depends
on the level and the set alone, so it is cached per (level, free set) in the allocator's
packed state (bitwise equal to a recomputation: the cache changes the cost, never the
answer).  By default every call starts from the clipped Eq 1.23 answer, never from the previous
call's working set: an answer is then a function of the call's data bit for bit.  (Warm starts
made answers depend on call history where they are unique only to round-off: with ``Wv``
eigenvalues 7.7e29 and 3.4e13, in the domain, a long-lived allocator returned another point
than a fresh one; adversarial seed 10037684, moments 0.81 vs -0.39 on the weak axis.)  The
``warm_start`` option opts in to the C export's warm start (:func:`_warm_pick`, the single call
only), refused by :mod:`alloc._engine._warm` on problems like that one; its answers agree with the cold
ones to round-off (tests/alloc/test_warm_start.py).  A call that takes the warm start also skips
what it already knows: a least-squares level at zero residual after its step stops there, and the
final level of ``qp`` and ``dynamic`` starts at its multiplier test when level 0 ended on its own
step (:func:`_levels`; on ICE sines a call is then one step and two tests).  All work arrays
live in the packed state (no allocation per call but the result).  The entry points that
mutate that state hold the GIL (no ``nogil``): an allocator shared by threads stays safe.
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from ._threads import run_chunks, threads_for
from ._kernels import _FREE_BITS, close_out, copy_demand, finish, packed_out, rate_window_into
from ._active_set_layout import (CACHE_ENTRIES, CACHE_FLOATS, OVERFLOW_SLOTS, _A, _B, _BV, _CONST, _DIAG, _DYN, _E,
                                 _FIDX, _FINAL, _FREE, _G, _GAM, _H, _HEAD, _HI, _K, _KU, _KV, _LAM, _LO, _M,
                                 _MAXIT, _MISC, _N, _NCW, _NEXT_SLOT, _NLEV, _NLW, _P0, _PERM, _PINNED, _R, _RMAX,
                                 _RMIN, _SCALE, _STARTS, _T, _TABLE, _TABU, _TMP, _U, _UMAX, _UMIN, _UP, _UPC, _UW,
                                 _WARM, _WSIDE, _WU, _WVALID, _Y)
from ._lsq_factor import SIGMA_RTOL, _factors, _lsolve, _ltsolve, _slot_offsets

__all__ = ["pack", "lexico_call", "lexico_solve", "lexico_batch_finished", "SIGMA_RTOL", "MU_EPS"]

#: Multiplier tolerance in units of the round-off bound of the multiplier's computation.
MU_EPS = 1e3 * np.finfo(float).eps


@njit(cache=True, nogil=True, _nrt=False)
def _level(mats, vecs, ivecs, bankL, bank, r0, r1, lev, gam, diag, iup, ilo, ihi, maxit, m, warm, at_step,
           at_slot):  # pragma: no cover - compiled
    """Solve one level in place on ``u`` (feasible on entry) and ``free`` (working set).

    Rows ``A[r0:r1]`` are this level's least-squares rows, rows ``A[:r0]`` its equality
    constraints (held at their values on entry).  ``pinned`` effectors are never freed:
    an earlier level proved them at their bound on its whole optimal set (a strictly
    nonzero, unique multiplier); on return this level adds its own.  Without pinning, the
    stage-2 multipliers at a stage-1 vertex are not unique and a minimum-norm estimate
    frees effectors that cannot move.  An effector freed and then blocked by a zero step
    (a degenerate multiplier) is not freed again until the iterate moves.  Everything is
    addressed by row in the stacked arrays of :func:`pack` (``up``, ``lo``, ``hi`` are the
    rows ``iup``, ``ilo``, ``ihi`` of ``vecs``; the cache slot is indexed flat): no allocation.
    ``warm`` (a call started from the kept working set, :func:`_warm_pick`): a pure
    least-squares level at zero residual after a step returns there; ``at_step``: ``u`` is
    already this level's step on ``free`` (:func:`_levels`) from the factors in slot
    ``at_slot``, so the first iteration tests the multipliers only, on those factors.  Returns
    ``(iterations, stepped, slot)``: iterations -1 when the cap was hit, ``stepped`` when the
    level ended on its own step (the multiplier test passed after a step), from slot ``slot``.
    """
    nl = r1 - r0
    nc = r0
    # rows of the stacked state as views (free without reference counting); the arithmetic is
    # the same, in the same order, as indexing the stacks
    A, Wu = mats[_A], mats[_WU]
    u, e, bv, tmp, h, y, g, scale, lam = (vecs[_U], vecs[_E], vecs[_BV], vecs[_TMP], vecs[_H], vecs[_Y], vecs[_G],
                                          vecs[_SCALE], vecs[_LAM])
    up, lo, hi = vecs[iup], vecs[ilo], vecs[ihi]
    free, fidx, tabu, pinned = ivecs[_FREE], ivecs[_FIDX], ivecs[_TABU], ivecs[_PINNED]
    # the factors in a slot ``E = bank[slot]`` (:func:`_slot_offsets`), indexed flat: ``Yc``
    # row q, column c at ``oYc + q * wc + c``, ``Vc`` likewise from ``oVc``, ``sc`` from
    # ``osc``; ``Ya, Va, sa`` from ``oYa, oVa, osa`` with width ``nlw`` (2-d views made per
    # iteration cost more than they save: 14 % on an ICE batch row)
    ncw, nlw = ivecs[_HEAD, _NCW], ivecs[_HEAD, _NLW]
    oVc, osc, oYa, oVa, osa, _end = _slot_offsets(m, ncw, nlw)
    oYc, wc = 0, ncw
    # The final level of a one-level problem (stage 2 of ``qp`` and ``dynamic``) holds the
    # rows of level 0 as its equalities: its factorisation of a free set is level 0's (the
    # same matrix ``L^-1 A[:n, F]'``, the same Jacobi SVD), so it is looked up under level 0
    # and its ``Ya, Va, sa`` are read as this level's ``Yc, Vc, sc``.  Stage 2 starts on the
    # free set stage 1 ended on: that factorisation is always cached by then.
    share = nl == 0 and lev == 1 and ivecs[_HEAD, _NLEV] == 1 and ivecs[_STARTS, 0] == 0
    klev, kr0, kr1 = (0, 0, r0) if share else (lev, r0, r1)
    if share:  # the equalities' factors are level 0's own
        oYc, oVc, osc, wc = oYa, oVa, osa, nlw
    for j in range(m):
        tabu[j] = 0
    last = -1
    gam2 = gam * gam
    for it in range(maxit):
        # the first iteration of a level entered at its own step (``at_step``: :func:`_levels`)
        # would step by zero to round-off: it goes straight to the multiplier test
        stepping = it > 0 or not at_step
        # --- residual e = b - A u of this level's rows.  A pure least-squares level whose
        # residual is zero to round-off is at its global minimum (the objective is >= 0):
        # done, with zero multipliers (the common attainable case).
        zero = nl > 0 and gam2 == 0.0
        if stepping:
            for i in range(nl):
                acc = bv[r0 + i]
                mag = abs(bv[r0 + i])
                for j in range(m):
                    t = A[r0 + i, j] * u[j]
                    acc -= t
                    mag += abs(t)
                e[i] = acc
                if abs(acc) > MU_EPS * mag:
                    zero = False
            if zero:
                return it + 1, False, 0
        nf = 0
        for j in range(m):
            if free[j]:
                fidx[nf] = j
                nf += 1
        slot = _factors(mats, ivecs, bankL, bank, kr0, kr1, klev, diag, nf, m) if stepping else at_slot
        E = bank[slot]
        if stepping:
            # --- the preference gradient Wu (u - up)
            for j in range(m):
                tmp[j] = u[j] - up[j]
            for q in range(nf):
                j = fidx[q]
                acc = 0.0
                if diag:
                    acc = Wu[j, j] * tmp[j]
                else:
                    for s in range(m):
                        acc += Wu[j, s] * tmp[s]
                h[q] = acc
            _lsolve(bankL, slot, nf, diag, vecs, _H)  # h = L^-1 (Wu (u - up))_F
            # --- step y = -P h + Ua z   (P: projector onto null(Ct) and null(At)),
            #     z_i = (s_i (Va' e)_i - gam^2 (Ua' h)_i) / (s_i^2 + gam^2)
            for q in range(nf):
                y[q] = -h[q]
            for c in range(nc):
                if E[osc + c] > 0.0:
                    acc = 0.0
                    for q in range(nf):
                        acc += E[oYc + q * wc + c] * h[q]
                    for q in range(nf):
                        y[q] += acc * E[oYc + q * wc + c]
            for i in range(nl):
                if E[osa + i] > 0.0:
                    uh = 0.0
                    for q in range(nf):
                        uh += E[oYa + q * nlw + i] * h[q]
                    ve = 0.0
                    for r in range(nl):
                        ve += E[oVa + r * nlw + i] * e[r]
                    z = (E[osa + i] * ve - gam2 * uh) / (E[osa + i] * E[osa + i] + gam2)
                    for q in range(nf):
                        y[q] += (uh + z) * E[oYa + q * nlw + i]
            for c in range(nc):  # y in null(Ct) to round-off: the held moments do not drift
                if E[osc + c] > 0.0:
                    acc = 0.0
                    for q in range(nf):
                        acc += E[oYc + q * wc + c] * y[q]
                    for q in range(nf):
                        y[q] -= acc * E[oYc + q * wc + c]
            _ltsolve(bankL, slot, nf, diag, vecs, _Y)  # p_F = L^-T y
            # --- ratio test
            alpha = 1.0
            block = -1
            for q in range(nf):
                j = fidx[q]
                d = y[q]
                if d > 0.0:
                    room = hi[j] - u[j]
                    if room < alpha * d:
                        alpha = max(room, 0.0) / d
                        block = q
                elif d < 0.0:
                    room = lo[j] - u[j]
                    if room > alpha * d:
                        alpha = min(room, 0.0) / d
                        block = q
            for q in range(nf):
                u[fidx[q]] += alpha * y[q]
            if block >= 0:
                j = fidx[block]
                u[j] = hi[j] if y[block] > 0.0 else lo[j]
                free[j] = 0
                if alpha > 0.0:
                    for t in range(m):
                        tabu[t] = 0
                elif j == last:
                    tabu[j] = 1
                continue
            if warm and nc == 0 and nl > 0 and gam2 == 0.0:
                # warm: a pure least-squares level at zero residual after its step is at its
                # global minimum; the test below would find every multiplier zero to round-off
                flat = True
                for i in range(nl):
                    acc = bv[r0 + i]
                    mag = abs(bv[r0 + i])
                    for j in range(m):
                        t = A[r0 + i, j] * u[j]
                        acc -= t
                        mag += abs(t)
                    if abs(acc) > MU_EPS * mag:
                        flat = False
                        break
                if flat:
                    return it + 1, True, slot
        # --- full step: multipliers of the bounds held, mu = g + A[:r0]' lam
        for j in range(m):
            tmp[j] = u[j] - up[j]
        for j in range(m):
            acc = 0.0
            if gam2 > 0.0:
                if diag:
                    acc = gam2 * Wu[j, j] * tmp[j]
                else:
                    for s in range(m):
                        acc += Wu[j, s] * tmp[s]
                    acc *= gam2
            g[j] = acc
        for j in range(m):
            scale[j] = 0.0  # round-off bound of each g_j (and of A' lam below)
        for i in range(nl):
            acc = -bv[r0 + i]
            mag = abs(bv[r0 + i])
            for j in range(m):
                t = A[r0 + i, j] * u[j]
                acc += t
                mag += abs(t)
            for j in range(m):
                g[j] += A[r0 + i, j] * acc
                scale[j] += abs(A[r0 + i, j]) * mag
        if gam2 > 0.0:
            for j in range(m):
                if diag:
                    acc = abs(Wu[j, j]) * (abs(u[j]) + abs(up[j]))
                else:
                    acc = 0.0
                    for s in range(m):
                        acc += abs(Wu[j, s]) * (abs(u[s]) + abs(up[s]))
                scale[j] += gam2 * acc
        if nc > 0:
            # lam = -Vc diag(1/sc) Uc' L^-1 g_F
            for q in range(nf):
                h[q] = g[fidx[q]]
            _lsolve(bankL, slot, nf, diag, vecs, _H)
            for c in range(nc):
                lam[c] = 0.0
            for c in range(nc):
                if E[osc + c] > 0.0:
                    acc = 0.0
                    for q in range(nf):
                        acc += E[oYc + q * wc + c] * h[q]
                    acc /= E[osc + c]
                    for r in range(nc):
                        lam[r] -= E[oVc + r * wc + c] * acc
            for c in range(nc):
                for j in range(m):
                    t = A[c, j] * lam[c]
                    g[j] += t
                    scale[j] += abs(t)
        unique = True
        for c in range(nc):
            if E[osc + c] == 0.0:
                unique = False
        worst = -1
        wv = 0.0
        for j in range(m):
            if free[j] or lo[j] == hi[j] or pinned[j] or tabu[j]:
                continue
            viol = -g[j] if u[j] <= lo[j] else g[j]
            tol = MU_EPS * scale[j]
            if viol > tol and viol - tol > wv:
                wv = viol - tol
                worst = j
        if worst < 0:
            if unique and nl > 0:
                for j in range(m):
                    if not free[j] and lo[j] < hi[j]:
                        mu = -g[j] if u[j] <= lo[j] else g[j]
                        if mu < -100.0 * MU_EPS * scale[j]:
                            pinned[j] = 1
            return it + 1, True, slot
        free[worst] = 1
        last = worst
    return -1, False, 0


def pack(A, T, perm, starts, gammas, final, Wu, diag, up, B, P0, umin, umax, rate_min, rate_max, maxit,
         vmax, rtol, Kv=None, Ku=None, warm=False):
    """The solver's data and state: the argument tuple of :func:`lexico_call` before ``v``.

    ``up`` is the preference point, or with ``Kv`` (m x k) and ``Ku`` (m x m) its constant
    part: the call's preference point is ``up + Kv v (+ Ku u_prev with rate limits)``
    (``dynamic``).  ``vmax`` bounds the valid input domain, ``rtol`` is the ``exact``
    tolerance.  The cache holds up to ``CACHE_ENTRIES`` free sets within ``CACHE_FLOATS``.
    ``warm``: the single call (:func:`lexico_call`) keeps its answer's working set and starts
    the next from it (:func:`_warm_pick`); batches and :func:`lexico_solve` stay cold.
    """
    n, m = A.shape
    k = B.shape[0]
    nlev = len(starts) - 1
    words = m // _FREE_BITS + 2  # the free set's bits, then the level
    R = C = max(n, m, k)
    mats = np.zeros((7, R, C))
    for i, M in ((_A, A), (_T, T), (_WU, Wu), (_B, B), (_P0, P0)) + (((_KV, Kv), (_KU, Ku)) if Kv is not None else ()):
        M = np.asarray(M, dtype=float)
        mats[i, :M.shape[0], :M.shape[1]] = M
    vecs = np.zeros((_WSIDE + 1, max(m, n, k, nlev, 2)))
    for i, x in ((_UP, up), (_UMIN, umin), (_UMAX, umax), (_RMIN, rate_min), (_RMAX, rate_max), (_GAM, gammas),
                 (_CONST, [vmax, rtol])):
        x = np.asarray(x, dtype=float)
        vecs[i, :len(x)] = x
    # the widest equality block and level block any level factorises on its own (the final
    # level of a one-level problem reads level 0's: see _level); a slot holds exactly these
    share = nlev == 1 and int(starts[0]) == 0
    own = [(int(starts[lv]), int(starts[lv + 1]) - int(starts[lv])) for lv in range(nlev)]
    if final and not share:
        own.append((n, 0))
    ncw = max(1, max(nc for nc, _ in own))
    nlw = max(1, max(nl for _, nl in own))
    ivecs = np.zeros((_TABLE, max(m, n, nlev + 1, words + 1, _WVALID + 1)), dtype=np.int64)
    ivecs[_HEAD, :_WVALID + 1] = [n, m, k, nlev, int(final), int(diag), int(maxit), words, int(Kv is not None), ncw,
                                  nlw, int(bool(warm)), 0]
    ivecs[_PERM, :n] = perm
    ivecs[_STARTS, :nlev + 1] = starts
    ivecs[_MISC, _NEXT_SLOT] = OVERFLOW_SLOTS  # the next free cache slot (the overflow's come first)
    mL = 1 if diag else m  # a diagonal L is stored as its column of pivots
    slot = _slot_offsets(m, ncw, nlw)[5]
    cap = int(max(4, min(CACHE_ENTRIES, CACHE_FLOATS // (m * mL + slot) - OVERFLOW_SLOTS)))
    # written once here so that every page is resident: a first-seen free set's factorisation
    # then never takes a page fault on the call path (measured: 15-18 % off the first-pass p99
    # of random ICE demands; real-time code pre-faults its memory for the same reason)
    bankL = np.empty((cap + OVERFLOW_SLOTS, m, mL))
    bankL.fill(0.0)
    bank = np.empty((cap + OVERFLOW_SLOTS, slot))
    bank.fill(0.0)
    size = 1 << int(2 * cap - 1).bit_length()  # a power of two, at most half full
    table = np.zeros((size, ivecs.shape[1]), dtype=np.int64)
    table[:, 0] = -1
    return mats, vecs, np.vstack([ivecs, table]), bankL, bank


@njit(cache=True, nogil=True, inline="always")
def _start(mats, vecs, ivecs, v, ilo, ihi, iup, m, k):  # pragma: no cover - compiled
    """The first iterate and working set: the Eq 1.23 pseudo-inverse answer
    ``up + P0 (v - B up)`` clipped, the clipped effectors held."""
    for i in range(k):
        acc = v[i]
        for j in range(m):
            acc -= mats[_B, i, j] * vecs[iup, j]
        vecs[_R, i] = acc
    for j in range(m):
        x = vecs[iup, j]
        for i in range(k):
            x += mats[_P0, j, i] * vecs[_R, i]
        lo, hi = vecs[ilo, j], vecs[ihi, j]
        x = min(max(x, lo), hi)
        vecs[_U, j] = x
        ivecs[_FREE, j] = 1 if lo < x < hi else 0


@njit(cache=True, nogil=True, _nrt=False)
def _first_objective(mats, vecs, ivecs, x, iup, m):  # pragma: no cover - compiled
    """The first level's objective at ``x``: ``||A_0 x - b_0||^2 + g_0^2 (x - up)' Wu (x - up)``."""
    r1 = ivecs[_STARTS, 1]
    acc = 0.0
    for i in range(r1):
        e = vecs[_BV, i]
        for j in range(m):
            e -= mats[_A, i, j] * x[j]
        acc += e * e
    gam = vecs[_GAM, 0]
    if gam != 0.0:
        q = 0.0
        for j in range(m):
            d = 0.0
            if ivecs[_HEAD, _DIAG] != 0:
                d = mats[_WU, j, j] * (x[j] - vecs[iup, j])
            else:
                for s in range(m):
                    d += mats[_WU, j, s] * (x[s] - vecs[iup, s])
            q += (x[j] - vecs[iup, j]) * d
        acc += gam * gam * q
    return acc


@njit(cache=True, nogil=True, _nrt=False)
def _warm_pick(mats, vecs, ivecs, ilo, ihi, iup, m):  # pragma: no cover - compiled
    """Replace the cold start (``vecs[_U]``, ``ivecs[_FREE]``) by the kept working set on this
    call's bounds -- held effectors at the same side's bound, free ones at their last value
    clipped -- when the first level's objective is not larger there; True when taken.  The C
    export's ``warm_pick`` (alloc/export/templates_active_set.py), the same rule."""
    x = vecs[_TMP]  # scratch: the levels write it before they read it
    for j in range(m):
        side = vecs[_WSIDE, j]
        lo, hi = vecs[ilo, j], vecs[ihi, j]
        x[j] = lo if side < 0.0 else hi if side > 0.0 else min(max(vecs[_UW, j], lo), hi)
    if _first_objective(mats, vecs, ivecs, x, iup, m) > _first_objective(mats, vecs, ivecs, vecs[_U], iup, m):
        return False
    for j in range(m):
        vecs[_U, j] = x[j]
        ivecs[_FREE, j] = 1 if vecs[ilo, j] < x[j] < vecs[ihi, j] else 0
    return True


@njit(cache=True, nogil=True, _nrt=False)
def _warm_keep(vecs, ivecs, ihi, m):  # pragma: no cover - compiled
    """Keep the finished run's answer and working set (each effector free, or held at its
    lower or upper bound) for the next call."""
    for j in range(m):
        vecs[_UW, j] = vecs[_U, j]
        vecs[_WSIDE, j] = 0.0 if ivecs[_FREE, j] != 0 else (1.0 if vecs[_U, j] >= vecs[ihi, j] else -1.0)
    ivecs[_HEAD, _WVALID] = 1


@njit(cache=True, nogil=True, _nrt=False)
def _levels(mats, vecs, ivecs, bankL, bank, ilo, ihi, iup, warm):  # pragma: no cover - compiled
    """Every level from the start in ``vecs[_U]``, ``ivecs[_FREE]``; ``(iterations, ok)``.

    ``warm``: the start is the kept working set (:func:`_warm_pick`).  Then, where the final
    level reads level 0's factors (``qp``, ``dynamic``) and level 0 ended on its own step, the
    final level starts at its multiplier test, on level 0's factors of the same free set: that
    step already minimised ``(u - up)' Wu (u - up)`` over the free set with level 0's moments
    held (the same projection, from the same factorisation), so the final level's first step
    is zero to round-off.  On a smoothly
    moving demand the kept working set is usually the optimal one, and a call is then one step
    and two multiplier tests."""
    n, m, nlev = ivecs[_HEAD, _N], ivecs[_HEAD, _M], ivecs[_HEAD, _NLEV]
    maxit = ivecs[_HEAD, _MAXIT]
    diag = ivecs[_HEAD, _DIAG] != 0
    share = nlev == 1 and ivecs[_STARTS, 0] == 0
    for j in range(m):
        ivecs[_PINNED, j] = 0
    total = slot = 0
    stepped = False
    for l in range(nlev + (1 if ivecs[_HEAD, _FINAL] else 0)):
        if l < nlev:
            r0, r1, gam = ivecs[_STARTS, l], ivecs[_STARTS, l + 1], vecs[_GAM, l]
        else:
            r0, r1, gam = n, n, 1.0
        at_step = warm and stepped and share and l == nlev
        it, stepped, slot = _level(mats, vecs, ivecs, bankL, bank, r0, r1, l, gam, diag, iup, ilo, ihi, maxit, m,
                                   warm, at_step, slot)
        if it < 0:
            return total + maxit, False
        total += it
    return total, True


@njit(cache=True, nogil=True, _nrt=False)
def _run(mats, vecs, ivecs, bankL, bank, v, ilo, ihi, iup, warm):  # pragma: no cover - compiled
    """All levels for one demand, into ``vecs[_U]``; returns ``(iterations, ok)``.

    ``b = T v[perm]``; level ``l`` is rows ``A[starts[l]:starts[l+1]]`` with weight
    ``gammas[l]``; ``final`` adds the preference level holding every row (stage 2 of ``qp``).
    The bounds and the preference point are the rows ``ilo``, ``ihi``, ``iup`` of ``vecs``.
    ``warm``: start from the kept working set where :func:`_warm_pick` takes it; a run from it
    that hits the cap is redone from the cold start (a call then does at most twice the work).
    """
    n, m, k = ivecs[_HEAD, _N], ivecs[_HEAD, _M], ivecs[_HEAD, _K]
    for i in range(n):
        acc = 0.0
        for q in range(n):
            acc += mats[_T, i, q] * v[ivecs[_PERM, q]]
        vecs[_BV, i] = acc
    _start(mats, vecs, ivecs, v, ilo, ihi, iup, m, k)
    if not (warm and ivecs[_HEAD, _WVALID] != 0 and _warm_pick(mats, vecs, ivecs, ilo, ihi, iup, m)):
        return _levels(mats, vecs, ivecs, bankL, bank, ilo, ihi, iup, False)
    total, ok = _levels(mats, vecs, ivecs, bankL, bank, ilo, ihi, iup, True)
    if ok:
        return total, ok
    _start(mats, vecs, ivecs, v, ilo, ihi, iup, m, k)
    again, ok = _levels(mats, vecs, ivecs, bankL, bank, ilo, ihi, iup, False)
    return total + again, ok


@njit(cache=True, nogil=True, inline="always")
def _target(mats, vecs, ivecs, v, u_prev, rate):  # pragma: no cover - compiled
    """The row of ``vecs`` holding the call's preference point: ``up``, or (``dynamic``)
    ``up + Kv v (+ Ku u_prev)`` written into ``vecs[_UPC]``; -1 when that is not finite."""
    if ivecs[_HEAD, _DYN] == 0:
        return _UP
    m, k = ivecs[_HEAD, _M], ivecs[_HEAD, _K]
    good = True
    for j in range(m):
        acc = vecs[_UP, j]
        for i in range(k):
            acc += mats[_KV, j, i] * v[i]
        if rate:
            for s in range(m):
                acc += mats[_KU, j, s] * u_prev[s]
        vecs[_UPC, j] = acc
        if not np.isfinite(acc):
            good = False
    return _UPC if good else -1


@njit(cache=True)
def lexico_call(mats, vecs, ivecs, bankL, bank, v, u_prev, dt):  # pragma: no cover - compiled
    """One allocation in one compiled call, for the allocator's fast path.

    Checks the demand (and ``u_prev`` when ``dt > 0``) against the valid domain, forms the
    rate-limited bounds (Eq 1.28) when ``dt > 0``, solves, clips, and classifies like
    :func:`alloc._engine._kernels.finish`.  Returns ``(out, code, iterations)``: the
    :func:`alloc._engine._kernels.packed_out` array and the code, 0 exact, 1 unattainable,
    2 non-finite, 3 ``v`` outside the domain, 4 ``u_prev`` outside the domain, 5 the cap.
    """
    out = packed_out(ivecs[_HEAD, _M], ivecs[_HEAD, _K])
    code, it = _call_into(mats, vecs, ivecs, bankL, bank, v, u_prev, dt, out)
    return out, code, it


@njit(cache=True, nogil=True, _nrt=False)
def _call_into(mats, vecs, ivecs, bankL, bank, v, u_prev, dt, out):  # pragma: no cover - compiled
    """:func:`lexico_call`'s work into its ``out``: ``(code, iterations)``.  No reference
    counting (the caller owns every array), so the views below cost nothing."""
    m, k = ivecs[_HEAD, _M], ivecs[_HEAD, _K]
    vmax, rtol = vecs[_CONST, 0], vecs[_CONST, 1]
    if not copy_demand(v, out, m, vmax):
        return 3, 0
    rate = dt > 0.0
    ilo, ihi = _UMIN, _UMAX
    if rate:
        for j in range(m):
            if not abs(u_prev[j]) <= vmax:
                return 4, 0
        ilo, ihi = _LO, _HI
        rate_window_into(vecs[_UMIN, :m], vecs[_UMAX], vecs[_RMIN], vecs[_RMAX], u_prev, dt, vecs[_LO], vecs[_HI])
    iup = _target(mats, vecs, ivecs, v, u_prev, rate)
    if iup < 0:
        return 2, 0
    warm = ivecs[_HEAD, _WARM] != 0
    it, ok = _run(mats, vecs, ivecs, bankL, bank, v, ilo, ihi, iup, warm)
    if not ok:
        ivecs[_HEAD, _WVALID] = 0
        return 5, it
    if warm:
        _warm_keep(vecs, ivecs, ihi, m)
    for j in range(m):
        out[j] = vecs[_U, j]
    code = finish(mats[_B, :k, :m], out[:m], vecs[ilo], vecs[ihi], v, out[m:m + k], rtol)
    if code == 2:
        ivecs[_HEAD, _WVALID] = 0
    close_out(out, m, k)
    return code, it


@njit(cache=True)
def lexico_solve(mats, vecs, ivecs, bankL, bank, v, lo, hi, u_prev, rate):  # pragma: no cover - compiled
    """The method's ``solve``: ``(u, iterations, ok)`` within ``[lo, hi]`` (the caller's
    bounds, copied into the state); ``u_prev`` enters only the ``dynamic`` preference
    point, when ``rate``; ``iterations`` is -1 when that point is not finite."""
    m = ivecs[_HEAD, _M]
    for j in range(m):
        vecs[_LO, j] = lo[j]
        vecs[_HI, j] = hi[j]
    iup = _target(mats, vecs, ivecs, v, u_prev, rate)
    if iup < 0:
        return vecs[_UPC, :m].copy(), -1, False
    it, ok = _run(mats, vecs, ivecs, bankL, bank, v, _LO, _HI, iup, False)
    return vecs[_U, :m].copy(), it, ok


@njit(cache=True, nogil=True, _nrt=False)
def _finished_into(mats, vecs, ivecs, bankL, bank, V, U, Vach, codes, a, b):  # pragma: no cover - compiled
    """Rows ``a:b`` of the batch, each what :func:`_call_into` does for it without rate
    limits: solve, then :func:`alloc._engine._kernels.finish` (clip, ``B u``, the code) into ``U``,
    ``Vach``, ``codes``; code 5 where a level hit its cap, 2 where the preference point is
    not finite (the caller redoes such rows one by one)."""
    m, k = ivecs[_HEAD, _M], ivecs[_HEAD, _K]
    rtol = vecs[_CONST, 1]
    for i in range(a, b):
        iup = _target(mats, vecs, ivecs, V[i], V[i], False)
        if iup < 0:
            codes[i] = 2
            continue
        if not _run(mats, vecs, ivecs, bankL, bank, V[i], _UMIN, _UMAX, iup, False)[1]:
            codes[i] = 5
            continue
        for j in range(m):
            U[i, j] = vecs[_U, j]
        codes[i] = finish(mats[_B, :k, :m], U[i], vecs[_UMIN], vecs[_UMAX], V[i], Vach[i], rtol)


@njit(cache=True)
def _finished_gil(mats, vecs, ivecs, bankL, bank, V, U, Vach, codes, a, b):  # pragma: no cover - compiled
    """:func:`_finished_into` holding the GIL: on the allocator's own state."""
    _finished_into(mats, vecs, ivecs, bankL, bank, V, U, Vach, codes, a, b)


@njit(cache=True, nogil=True)
def _finished_nogil(mats, vecs, ivecs, bankL, bank, V, U, Vach, codes, a, b):  # pragma: no cover - compiled
    """:func:`_finished_into` without the GIL: on a thread's private copy of the state."""
    _finished_into(mats, vecs, ivecs, bankL, bank, V, U, Vach, codes, a, b)


def lexico_batch_finished(state: tuple, V: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(U, B U, codes)`` of the rows of ``V`` within the position limits: the solve and the
    single call's :func:`alloc._engine._kernels.finish` in one compiled pass per chunk of rows.

    Large batches run on :func:`alloc._engine._threads.threads_for` threads that pull chunks of rows
    from a shared counter (:func:`alloc._engine._threads.run_chunks`: a thread slowed by other load
    takes fewer), each on a private copy of the solver's state; the allocator's own state is
    used, under the GIL, only by a one-thread batch.  Rows are pure functions of the data (the
    factorisation cache changes the cost, never the answer), so every split gives the same
    bits as the single calls."""
    V = np.ascontiguousarray(V, dtype=float)
    n = len(V)
    m, k = int(state[2][_HEAD, _M]), int(state[2][_HEAD, _K])
    U = np.empty((n, m))
    Vach = np.empty((n, k))
    codes = np.empty(n, dtype=np.int64)
    threads = threads_for(n)
    if threads == 1:
        _finished_gil(*state, V, U, Vach, codes, 0, n)
        return U, Vach, codes

    def worker():
        own = tuple(x.copy() for x in state)
        return lambda a, b: _finished_nogil(*own, V, U, Vach, codes, a, b)

    run_chunks(worker, n, threads)
    return U, Vach, codes
