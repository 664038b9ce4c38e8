"""C99 template of the active-set kernels (:mod:`alloc.export`): ``wls``, ``qp`` (with
``priorities``) and ``dynamic``; filled as :mod:`.templates` describes."""

import re

from .templates import SET_LIMITS
from .templates_factor import FACTOR

# the constants, the solver instances, the work arrays and the triangular solves
_DATA = r"""
/* levels: rows STARTS[l]..STARTS[l+1] of A = T B[PERM] (T: the upper square roots of the
   level blocks of Wv), weight GAM[l]; FINAL adds min (u-up)'Wu(u-up) with every row held */
#define N @N@
#define NLEV @NLEV@
#define FINAL @FINAL@
#define MAXIT PFX_MAXIT
#define NCW @NCW@
#define NLW @NLW@
#define ML @ML@
/* 1: the factorisation of every free set is a constant table (looked up, never computed) */
#define TABLE @TABLE@
/* without the table: slots of the static cache of the free sets' factorisations met last
   (0: none); a factorisation depends on the instance, the level and the free set alone, so a
   cached one has the bits of a fresh one: the cache changes the time, never the answer */
#define CACHE @CACHE@
/* singular values below SIGMA_RTOL of the largest are round-off; the Jacobi SVD's unit
   round-off; multipliers are tested against MU_EPS times the round-off of their computation */
#define SIGMA_RTOL @SIGMA_RTOL@
#define JACOBI_EPS @JACOBI_EPS@
#define JACOBI_TOL_FLOOR @JACOBI_TOL_FLOOR@
#define JACOBI_SMALL @JACOBI_SMALL@
#define SIGMA_TINY @SIGMA_TINY@
#define CHOL_TINY @CHOL_TINY@
#define MU_EPS @MU_EPS@

static const real UMIN0[M] = @UMIN@;
static const real UMAX0[M] = @UMAX@;
static const real A[N][M] = @A@;
static const real T[N][N] = @T@;
static const int PERM[N] = @PERM@;
static const int STARTS[NLEV + 1] = @STARTS@;
static const real GAM[NLEV] = @GAM@;
/* 1 (qp, wls) or 2 solver instances (dynamic: without and with u_prev), each with its own
   preference weight WU, cold start P0 (Eq 1.23 in the WU metric: up + P0 (v - B up) clipped)
   and preference point: UPT, or with KV (and KU) the call's UPT + KV v (+ KU u_prev) */
#define NINST @NINST@

struct instance {
    int diag;
    const real (*wu)[M];
    const real (*p0)[K];
    const real *upt;
    const real (*kv)[K];
    const real (*ku)[M];
#if TABLE
    const real (*tab_l)[1 << M][M * ML];
    const real (*tab_yc)[1 << M][M * NCW];
    const real (*tab_vc)[1 << M][NCW * NCW];
    const real (*tab_sc)[1 << M][NCW];
    const real (*tab_ya)[1 << M][M * NLW];
    const real (*tab_va)[1 << M][NLW * NLW];
    const real (*tab_sa)[1 << M][NLW];
#endif
};

@INSTANCES@

#if !TABLE
/* the factorisation of one free set: L L' = Wu[F, F] (a diagonal L as a column), Yc/Vc/sc the
   SVD of the held rows, Ya/Va/sa that of the level's rows, projected */
struct factors {
    real L[M * ML], Yc[M * NCW], Vc[NCW * NCW], sc[NCW], Ya[M * NLW], Va[NLW * NLW], sa[NLW];
};
#endif

struct work {
    const struct instance *S;
    real u[M], e[N], bv[N], tmp[M], h[M], y[M], g[M], scale[M], lam[N];
    int freeset[M], fidx[M], tabu[M], pinned[M];
    /* the factorisation of the current free set (a table row, a cache slot or own) */
    const real *L, *Yc, *Vc, *sc, *Ya, *Va, *sa;
#if !TABLE && !CACHE
    struct factors own;
#endif
};

/* L[q, s] of the current factorisation (a diagonal L is stored as its column of pivots) */
#define LQ(w, q, s) ((w)->L[(q) * ML + ((w)->S->diag ? 0 : (s))])

/* x = L^-1 x */
static void lsolve(const struct work *w, int n, real *x)
{
    int q, t;
    for (q = 0; q < n; ++q) {
        real acc = x[q];
        if (!w->S->diag) {
            for (t = 0; t < q; ++t) acc -= LQ(w, q, t) * x[t];
        }
        x[q] = acc / LQ(w, q, q);
    }
}

/* x = L^-T x */
static void ltsolve(const struct work *w, int n, real *x)
{
    int q, t;
    for (q = n - 1; q >= 0; --q) {
        real acc = x[q];
        if (!w->S->diag) {
            for (t = q + 1; t < n; ++t) acc -= LQ(w, t, q) * x[t];
        }
        x[q] = acc / LQ(w, q, q);
    }
}

"""

# one level of the lexicographic problem (alloc._engine._active_set._level)
_LEVEL = r"""/* one level on w->u (feasible on entry) and w->freeset, at most cap iterations: iterations,
   or -1 at the cap */
static int level(struct work *w, int r0, int r1, int lev, real gam, const real *up, const real *lo,
                 const real *hi, int cap@LEVEL_ARGS@)
{
    int nl = r1 - r0, nc = r0, it, i, j, q, s, c, r, last = -1;
    /* a one-level problem's final level holds level 0's rows: its factors are level 0's, and
       their level blocks are read as its held blocks */
    int share = nl == 0 && lev == 1 && NLEV == 1 && STARTS[0] == 0;
    int wc = share ? NLW : NCW;
    real gam2 = gam * gam;
    const real *Yc, *Vc, *sc, *Ya, *Va, *sa;
    real *u = w->u, *e = w->e, *tmp = w->tmp, *h = w->h, *y = w->y, *g = w->g, *scale = w->scale;
    real *lam = w->lam;
    int *freeset = w->freeset, *fidx = w->fidx, *tabu = w->tabu, *pinned = w->pinned;
    for (j = 0; j < M; ++j) tabu[j] = 0;
@LEVEL_INIT@
    for (it = 0; it < cap; ++it) {
        int zero = nl > 0 && gam2 == 0, nf = 0, block = -1, worst = -1, unique = 1;
        real alpha = 1, wv = 0;
@SKIP_RESIDUAL@
        /* residual e = b - A u; a pure least-squares level at zero residual is optimal */
        for (i = 0; i < nl; ++i) {
            real acc = w->bv[r0 + i], mag = ABS(w->bv[r0 + i]);
            for (j = 0; j < M; ++j) {
                real t = A[r0 + i][j] * u[j];
                acc -= t;
                mag += ABS(t);
            }
            e[i] = acc;
            if (ABS(acc) > MU_EPS * mag) zero = 0;
        }
        if (zero) return it + 1;
@FREE_SET_LABEL@
        for (j = 0; j < M; ++j) {
            if (freeset[j]) fidx[nf++] = j;
        }
@LOOKUP_OPEN@
#if TABLE
        lookup(w, share ? 0 : lev);
#else
        factorise(w, share ? 0 : lev, share ? 0 : r0, share ? r0 : r1, nf);
#endif
@LOOKUP_CLOSE@
        Yc = share ? w->Ya : w->Yc;
        Vc = share ? w->Va : w->Vc;
        sc = share ? w->sa : w->sc;
        Ya = w->Ya;
        Va = w->Va;
        sa = w->sa;
@SKIP_STEP@
        /* h = L^-1 (Wu (u - up))_F */
        for (j = 0; j < M; ++j) tmp[j] = u[j] - up[j];
        for (q = 0; q < nf; ++q) {
            real acc = 0;
            j = fidx[q];
            if (w->S->diag) {
                acc = w->S->wu[j][j] * tmp[j];
            } else {
                for (s = 0; s < M; ++s) acc += w->S->wu[j][s] * tmp[s];
            }
            h[q] = acc;
        }
        lsolve(w, nf, h);
        /* step y = -P h + Ua z */
        for (q = 0; q < nf; ++q) y[q] = -h[q];
        for (c = 0; c < nc; ++c) {
            if (sc[c] > 0) {
                real acc = 0;
                for (q = 0; q < nf; ++q) acc += Yc[q * wc + c] * h[q];
                for (q = 0; q < nf; ++q) y[q] += acc * Yc[q * wc + c];
            }
        }
        for (i = 0; i < nl; ++i) {
            if (sa[i] > 0) {
                real uh = 0, ve = 0, z;
                for (q = 0; q < nf; ++q) uh += Ya[q * NLW + i] * h[q];
                for (r = 0; r < nl; ++r) ve += Va[r * NLW + i] * e[r];
                z = (sa[i] * ve - gam2 * uh) / (sa[i] * sa[i] + gam2);
                for (q = 0; q < nf; ++q) y[q] += (uh + z) * Ya[q * NLW + i];
            }
        }
        for (c = 0; c < nc; ++c) { /* y in the null space of the held rows */
            if (sc[c] > 0) {
                real acc = 0;
                for (q = 0; q < nf; ++q) acc += Yc[q * wc + c] * y[q];
                for (q = 0; q < nf; ++q) y[q] -= acc * Yc[q * wc + c];
            }
        }
        ltsolve(w, nf, y);
        /* ratio test */
        for (q = 0; q < nf; ++q) {
            real d = y[q], room;
            j = fidx[q];
            if (d > 0) {
                room = hi[j] - u[j];
                if (room < alpha * d) {
                    alpha = rmax(room, 0) / d;
                    block = q;
                }
            } else if (d < 0) {
                room = lo[j] - u[j];
                if (room > alpha * d) {
                    alpha = rmin(room, 0) / d;
                    block = q;
                }
            }
        }
        for (q = 0; q < nf; ++q) u[fidx[q]] += alpha * y[q];
        if (block >= 0) {
            j = fidx[block];
            u[j] = y[block] > 0 ? hi[j] : lo[j];
            freeset[j] = 0;
            if (alpha > 0) {
                for (s = 0; s < M; ++s) tabu[s] = 0;
            } else if (j == last) {
                tabu[j] = 1;
            }
            continue;
        }
@AFTER_STEP@
@MULTIPLIERS_LABEL@
        /* full step: multipliers of the bounds held, mu = g + A[:r0]' lam */
        for (j = 0; j < M; ++j) tmp[j] = u[j] - up[j];
        for (j = 0; j < M; ++j) {
            real acc = 0;
            if (gam2 > 0) {
                if (w->S->diag) {
                    acc = gam2 * w->S->wu[j][j] * tmp[j];
                } else {
                    for (s = 0; s < M; ++s) acc += w->S->wu[j][s] * tmp[s];
                    acc *= gam2;
                }
            }
            g[j] = acc;
        }
        for (j = 0; j < M; ++j) scale[j] = 0;
        for (i = 0; i < nl; ++i) {
            real acc = -w->bv[r0 + i], mag = ABS(w->bv[r0 + i]);
            for (j = 0; j < M; ++j) {
                real t = A[r0 + i][j] * u[j];
                acc += t;
                mag += ABS(t);
            }
            for (j = 0; j < M; ++j) {
                g[j] += A[r0 + i][j] * acc;
                scale[j] += ABS(A[r0 + i][j]) * mag;
            }
        }
        if (gam2 > 0) {
            for (j = 0; j < M; ++j) {
                real acc;
                if (w->S->diag) {
                    acc = ABS(w->S->wu[j][j]) * (ABS(u[j]) + ABS(up[j]));
                } else {
                    acc = 0;
                    for (s = 0; s < M; ++s) acc += ABS(w->S->wu[j][s]) * (ABS(u[s]) + ABS(up[s]));
                }
                scale[j] += gam2 * acc;
            }
        }
        if (nc > 0) {
            for (q = 0; q < nf; ++q) h[q] = g[fidx[q]];
            lsolve(w, nf, h);
            for (c = 0; c < nc; ++c) lam[c] = 0;
            for (c = 0; c < nc; ++c) {
                if (sc[c] > 0) {
                    real acc = 0;
                    for (q = 0; q < nf; ++q) acc += Yc[q * wc + c] * h[q];
                    acc /= sc[c];
                    for (r = 0; r < nc; ++r) lam[r] -= Vc[r * wc + c] * acc;
                }
            }
            for (c = 0; c < nc; ++c) {
                for (j = 0; j < M; ++j) {
                    real t = A[c][j] * lam[c];
                    g[j] += t;
                    scale[j] += ABS(t);
                }
            }
        }
        for (c = 0; c < nc; ++c) {
            if (sc[c] == 0) unique = 0;
        }
        for (j = 0; j < M; ++j) {
            real viol, tol;
            if (freeset[j] || lo[j] == hi[j] || pinned[j] || tabu[j]) continue;
            viol = u[j] <= lo[j] ? -g[j] : g[j];
            tol = MU_EPS * scale[j];
            if (viol > tol && viol - tol > wv) {
                wv = viol - tol;
                worst = j;
            }
        }
        if (worst < 0) {
            if (unique && nl > 0) {
                for (j = 0; j < M; ++j) {
                    if (!freeset[j] && lo[j] < hi[j]) {
                        real mu = u[j] <= lo[j] ? -g[j] : g[j];
                        if (mu < (-100 * MU_EPS) * scale[j]) pinned[j] = 1;
                    }
                }
            }
@STEPPED@
            return it + 1;
        }
        freeset[worst] = 1;
        last = worst;
    }
    return -1;
}

"""

# all levels from the cold start, the preference point and the entry points
_ENTRY = r"""/* all levels for one demand into w->u within budget iterations (and MAXIT a level): total
   iterations, and *ok = 0 when a level reaches its cap or the budget is spent */
static int run(struct work *w, const real *v, const real *lo, const real *hi, const real *up, int budget,
               int *ok)
{
    int i, j, q, l, total = 0@RUN_DECL@;
    real r[K];
    for (i = 0; i < N; ++i) {
        real acc = 0;
        for (q = 0; q < N; ++q) acc += T[i][q] * v[PERM[q]];
        w->bv[i] = acc;
    }
    /* cold start: the Eq 1.23 answer clipped, the clipped effectors held */
    for (i = 0; i < K; ++i) {
        real acc = v[i];
        for (j = 0; j < M; ++j) acc -= BM[i][j] * up[j];
        r[i] = acc;
    }
    for (j = 0; j < M; ++j) {
        real x = up[j];
        for (i = 0; i < K; ++i) x += w->S->p0[j][i] * r[i];
        x = rmin(rmax(x, lo[j]), hi[j]);
        w->u[j] = x;
        w->freeset[j] = lo[j] < x && x < hi[j];
        w->pinned[j] = 0;
    }
@WARM_PICK@    *ok = 1;
    for (l = 0; l < NLEV + FINAL; ++l) {
        int it, cap = budget - total < MAXIT ? budget - total : MAXIT;
        if (cap <= 0) {
            *ok = 0;
            break;
        }
        if (l < NLEV) {
            it = level(w, STARTS[l], STARTS[l + 1], l, GAM[l], up, lo, hi, cap@LEVEL_CALL@);
        } else {
            it = level(w, N, N, l, 1, up, lo, hi, cap@FINAL_CALL@);
        }
        if (it < 0) {
            total += cap;
            *ok = 0;
            break;
        }
        total += it;
    }
    return total;
}

/* the call's preference point (alloc._engine._active_set._target): UPT, or UPT + KV v (+ KU u_prev);
   0 when it is not finite */
static int target(const struct instance *S, const real *v, const real *u_prev, real *upc)
{
    int i, j, s, good = 1;
    for (j = 0; j < M; ++j) {
        real acc = S->upt[j];
        for (i = 0; i < K; ++i) acc += S->kv[j][i] * v[i];
        if (u_prev != NULL) {
            for (s = 0; s < M; ++s) acc += S->ku[j][s] * u_prev[s];
        }
        upc[j] = acc;
        if (!FINITE(acc)) good = 0;
    }
    return good;
}

"""

# the entry point up to the run, shared by the cold and the warm kernels (@DECL@: the warm
# one's extra local)
_ALLOCATE_HEAD = r"""/* 1 while the limits in force are the nominal ones (PREFIX_set_limits) */
static int limits_nominal = 1;

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    struct work w;
    real lo[M], hi[M], upc[M];
    const real *up;
    int j, ok, code@DECL@;
    last_iterations = 0;
    if (bounds(v, u_prev, dt, lo, hi, u)) return 2;
    /* dynamic: the instance with u_prev when there is a rate window */
    w.S = &INSTANCES[NINST > 1 && u_prev != NULL ? 1 : 0];
    up = w.S->upt;
    if (w.S->kv != NULL) {
        if (!target(w.S, v, u_prev, upc)) {
            safe_answer(v, lo, hi, u);
            return 2;
        }
        up = upc;
    }
"""

_COLD_RUN = r"""    /* the certified budget covers the nominal limits without a rate window (see the header) */
    last_iterations = run(&w, v, lo, hi, up, u_prev == NULL && limits_nominal ? PFX_ITERATION_BOUND : PFX_MAXIT_TOTAL,
                          &ok);
    if (!ok) {
        safe_answer(v, lo, hi, u);
        return 2;
    }
    for (j = 0; j < M; ++j) u[j] = w.u[j];
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}

"""

# The warm start of a kernel exported with warm_start=True (the library's opt-in warm_start,
# alloc/_engine/_active_set.py: _warm_pick, _warm_keep).  Placed before run(), which calls warm_pick
# where the cold start is made.
_WARM = r"""/*
 * Warm start: each instance keeps its last answer and that answer's working set (each effector
 * free, or held at its lower or its upper bound).  A call then starts from that working set on
 * its own bounds (the free effectors' last values clipped, the held ones at the same side's
 * bound) instead of the cold start when the first level's objective is not larger there; a run
 * from it that reaches the budget is redone from the cold start.  Any start is feasible and the
 * levels end at the same optimum, so the answer is the cold one up to round-off where the
 * optimum is unique.  Where level 0 ends on its own step, the final level starts at its
 * multiplier test (its first step would be zero to round-off).  The library's allocator with
 * warm_start=True follows the same rule in the same order: its answers bit for bit.
 */
static int warm_valid[NINST];
static real warm_u[NINST][M];
static signed char warm_side[NINST][M]; /* 0 free, -1 held at the lower bound, 1 at the upper */
/* set by PREFIX_allocate: 1 lets run() take the warm start, which makes it 2 */
static int warm_try;

/* the first level's objective at x: ||A_0 x - b_0||^2 + GAM[0]^2 (x - up)' Wu (x - up) */
static real first_objective(const struct work *w, const real *x, const real *up)
{
    int i, j, s, r1 = NLEV > 0 ? STARTS[1] : 0;
    real gam = NLEV > 0 ? GAM[0] : 1, acc = 0, q = 0;
    for (i = 0; i < r1; ++i) {
        real e = w->bv[i];
        for (j = 0; j < M; ++j) e -= A[i][j] * x[j];
        acc += e * e;
    }
    if (gam != 0) {
        for (j = 0; j < M; ++j) {
            real d = 0;
            if (w->S->diag) {
                d = w->S->wu[j][j] * (x[j] - up[j]);
            } else {
                for (s = 0; s < M; ++s) d += w->S->wu[j][s] * (x[s] - up[s]);
            }
            q += (x[j] - up[j]) * d;
        }
        acc += gam * gam * q;
    }
    return acc;
}

/* w->u, w->freeset: the warm start in place of the cold start when it is kept and not worse;
   1 when taken */
static int warm_pick(struct work *w, const real *lo, const real *hi, const real *up)
{
    int inst = (int)(w->S - INSTANCES), j;
    real x[M];
    if (!warm_valid[inst]) return 0;
    for (j = 0; j < M; ++j) {
        int side = warm_side[inst][j];
        x[j] = side < 0 ? lo[j] : side > 0 ? hi[j] : rmin(rmax(warm_u[inst][j], lo[j]), hi[j]);
    }
    if (first_objective(w, x, up) > first_objective(w, w->u, up)) return 0;
    for (j = 0; j < M; ++j) {
        w->u[j] = x[j];
        w->freeset[j] = lo[j] < x[j] && x[j] < hi[j];
    }
    return 1;
}

/* keep the answer of a finished run as the instance's warm start */
static void warm_keep(const struct work *w, const real *hi)
{
    int inst = (int)(w->S - INSTANCES), j;
    for (j = 0; j < M; ++j) {
        warm_u[inst][j] = w->u[j];
        warm_side[inst][j] = (signed char)(w->freeset[j] ? 0 : w->u[j] >= hi[j] ? 1 : -1);
    }
    warm_valid[inst] = 1;
}

void PREFIX_warm_reset(void)
{
    int i;
    for (i = 0; i < NINST; ++i) warm_valid[i] = 0;
}

"""

_PICK = "    if (warm_try && warm_pick(w, lo, hi, up)) warm_try = 2; /* the warm start is taken */\n"

_WARM_RUN = r"""    /* the certified budget covers the nominal limits without a rate window, from the cold start
       (see the header); a warm run that reaches it is redone cold under the same budget */
    budget = u_prev == NULL && limits_nominal ? PFX_ITERATION_BOUND : PFX_MAXIT_TOTAL;
    warm_try = 1;
    ok = 0;
    last_iterations = run(&w, v, lo, hi, up, budget, &ok);
    if (!ok && warm_try == 2) {
        warm_try = 0;
        last_iterations += run(&w, v, lo, hi, up, budget, &ok);
    }
    if (!ok) {
        warm_valid[w.S - INSTANCES] = 0;
        safe_answer(v, lo, hi, u);
        return 2;
    }
    warm_keep(&w, hi);
    for (j = 0; j < M; ++j) u[j] = w.u[j];
    code = finish(u, lo, hi, v);
    if (code == 2) {
        warm_valid[w.S - INSTANCES] = 0;
        safe_answer(v, lo, hi, u);
    }
    return code;
}

"""

# What the warm kernel adds to the level and the run (alloc._engine._active_set._level, _levels: the
# same rule, the same order of operations); the cold kernel's text has none of it
_WARM_LEVEL = {
    "@LEVEL_ARGS@": ", int warm, int at_step, int *stepped",
    "@LEVEL_INIT@": "    *stepped = 0; /* 1 when the level ends on its own step */\n",
    "@SKIP_RESIDUAL@": ("        /* u already is this level's step on the free set (run): the first step would be zero\n"
                        "           to round-off, so the first iteration tests the multipliers only */\n"
                        "        if (it == 0 && at_step) goto free_set;\n"),
    "@FREE_SET_LABEL@": "    free_set:\n",
    # at the step, level 0's factors of this free set are the current ones (w->L, ...)
    "@LOOKUP_OPEN@": "        if (!(it == 0 && at_step)) {\n",
    "@LOOKUP_CLOSE@": "        }\n",
    "@SKIP_STEP@": "        if (it == 0 && at_step) goto multipliers;\n",
    "@AFTER_STEP@": r"""        if (warm && nc == 0 && nl > 0 && gam2 == 0) {
            /* warm: a pure least-squares level at zero residual after its step is at its global
               minimum; the test below would find every multiplier zero to round-off */
            int flat = 1;
            for (i = 0; flat && i < nl; ++i) {
                real acc = w->bv[r0 + i], mag = ABS(w->bv[r0 + i]);
                for (j = 0; j < M; ++j) {
                    real t = A[r0 + i][j] * u[j];
                    acc -= t;
                    mag += ABS(t);
                }
                if (ABS(acc) > MU_EPS * mag) flat = 0;
            }
            if (flat) {
                *stepped = 1;
                return it + 1;
            }
        }
""",
    "@MULTIPLIERS_LABEL@": "    multipliers:\n",
    "@STEPPED@": "            *stepped = 1;\n",
    "@RUN_DECL@": ", stepped = 0",
    "@LEVEL_CALL@": ", warm_try == 2, 0, &stepped",
    # the final level of a one-level problem reads level 0's factors: entered at level 0's step
    "@FINAL_CALL@": ",\n                       warm_try == 2, warm_try == 2 && stepped && NLEV == 1 && STARTS[0] == 0, &stepped",
}


def _fill_warm(text: str, warm: bool) -> str:
    """``text`` with the warm kernel's additions, or without them (a placeholder alone on its
    line goes with the line: the cold kernel's text is what it was before they existed)."""
    for key, value in _WARM_LEVEL.items():
        if warm:
            text = text.replace(key + "\n", value) if value.endswith("\n") else text.replace(key, value)
        else:
            text = text.replace(f"\n{key}\n", "\n").replace(key, "")
    return text


# qp, wls (and their priorities): the lexicographic least-squares active set of
# alloc/_engine/_active_set.py (_level, _start, _run, _call_into) with the factorisation of
# alloc/_engine/_lsq_factor.py (_jacobi, _factor), with a fixed-size static cache of factorisations
# in the library's place (both change the cost, never the answer).  The library starts cold
# by default, so the default kernel does too; ACTIVE_SET_WARM adds the warm start (export_c's
# warm_start), the library's warm_start=True bit for bit and its cold answers to round-off.
_ALLOCATE = _ALLOCATE_HEAD.replace("@DECL@", "") + _COLD_RUN
_ALLOCATE_WARM = _ALLOCATE_HEAD.replace("@DECL@", ", budget") + _WARM_RUN
ACTIVE_SET = _fill_warm(_DATA + FACTOR + _LEVEL + _ENTRY.replace("@WARM_PICK@", ""), False) + _ALLOCATE + SET_LIMITS
ACTIVE_SET_WARM = (_fill_warm(_DATA + FACTOR + _LEVEL + _WARM + _ENTRY.replace("@WARM_PICK@", _PICK), True)
                   + _ALLOCATE_WARM
                   + re.sub(r"( +)limits_nominal = 1;\n", r"\1PREFIX_warm_reset();\n\1limits_nominal = 1;\n", SET_LIMITS))
