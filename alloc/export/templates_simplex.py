"""C99 template of the ``lp`` kernel (:mod:`alloc.export`): the library's compiled lexicographic
simplex (:mod:`alloc._engine._simplex`, seed Eqs 1.18-1.19), filled as :mod:`.templates` describes.

Transcribes ``_eliminate``, ``_refactor``, ``_reduced_costs``, ``_step_to_bound``, ``_iterate``
and ``solve_lexicographic`` line for line and in the same order of operations (numba's
``max(a, b)`` and ``min(a, b)`` are ``rmax``/``rmin`` of the common part: the second argument
when it compares greater, resp. smaller, else the first).  The scaled tableau ``F``, the
half-widths ``D``, the row scales ``rho`` and the stages' normalised costs are the library's
own arrays (:class:`alloc._engine._simplex.LexicographicL1`), printed as constants; everything that
depends on the call's limits (the centre ``c``, the variables' upper bounds, the right-hand
side) is computed per call, so ``set_limits`` needs no new export.  One guard is added, the
per-call pivot budget ``PFX_ITERATION_BOUND``: a pivot beyond it is not taken (the call returns
the safe answer).  It does not move the refactorisation points, which follow the library's cap
``PFX_MAXIT``, so every call within the budget takes the library's path, bit for bit.
"""

from .templates import SET_LIMITS

SIMPLEX = r"""
/* the tableau of alloc/_engine/_simplex.py: A (p - n) - e+ + e- = b, u = c + D (p - n), columns
   [p (M), n (M), e+ (K), e- (K)]; F = [A, -A, -I, I] with A = diag(1/rho) B D */
#define NV @NV@
#define NSTAGE @NSTAGE@
#define MAXIT PFX_MAXIT
/* consecutive degenerate pivots before Bland's rule; pivots between refactorisations */
#define BLAND_AFTER 8
#define REFACTOR_EVERY 32
/* the library's tolerances (costs normalised to a largest entry of 1, columns O(1)) */
#define DUAL_TOL @DUAL_TOL@
#define PIVOT_TOL @PIVOT_TOL@
#define TIE_RTOL @TIE_RTOL@
#define DEGENERATE_TOL @DEGENERATE_TOL@
#define SINGULAR_TOL @SINGULAR_TOL@
#define FEASIBLE_RTOL @FEASIBLE_RTOL@
#define B_CLAMP @B_CLAMP@
#define INF @INF@
#define BASIC 0
#define LOWER 1
#define UPPER 2
/* solve codes (alloc._engine._simplex): OPTIMAL, ITERATION_LIMIT, NUMERICAL */
#define LP_OPTIMAL 0
#define LP_LIMIT 1
#define LP_NUMERICAL 2

static const real UMIN0[M] = @UMIN@;
static const real UMAX0[M] = @UMAX@;
static const real F[K][NV] = @F@;
static const real RHO[K] = @RHO@;
static const real D[M] = @D@;
/* one row per stage: the priority levels' moment errors (Eq 1.18), the distance to the
   preference (Eq 1.19), the generic tie-break sum_j t_j u_j / D_j */
static const real COSTS[NSTAGE][NV] = @COSTS@;

struct lp {
    real T[K][NV], x[NV], lb[NV], ub[NV], d[NV], b[K], c[M];
    int status[NV], frozen[NV], basis[K];
    /* pivots of the call so far, the budget of the call, and 1 once a pivot was refused */
    int spent, limit, capped;
};

/* Gauss-Jordan step on the rows of t (K rows of n): t[r][q] = 1, column q cleared elsewhere */
static void eliminate(real *t, int n, int r, int q)
{
    int i, j;
    real piv = t[r * n + q];
    for (j = 0; j < n; ++j) t[r * n + j] /= piv;
    for (i = 0; i < K; ++i) {
        if (i != r) {
            real f = t[i * n + q];
            if (f != 0) {
                for (j = 0; j < n; ++j) t[i * n + j] -= f * t[r * n + j];
            }
        }
    }
}

static void reduced_costs(struct lp *s, const real *cost)
{
    int j, r;
    for (j = 0; j < NV; ++j) {
        real acc = cost[j];
        for (r = 0; r < K; ++r) acc -= cost[s->basis[r]] * s->T[r][j];
        s->d[j] = acc;
    }
    for (r = 0; r < K; ++r) s->d[s->basis[r]] = 0;
}

/* tableau, basic values and reduced costs from the basis (Gauss-Jordan on W = [M | F | b - N x_N],
   partial pivoting); 0 when the basis matrix is numerically singular or a value not finite */
static int refactor(struct lp *s, const real *cost)
{
    int i, j, r, c;
    real W[K][K + NV + 1]; /* local: the compiler then copies its rows into T with memcpy */
    for (i = 0; i < K; ++i) {
        real acc = s->b[i];
        for (r = 0; r < K; ++r) W[i][r] = F[i][s->basis[r]];
        for (j = 0; j < NV; ++j) {
            W[i][K + j] = F[i][j];
            if (s->status[j] != BASIC && s->x[j] != 0) acc -= F[i][j] * s->x[j];
        }
        W[i][K + NV] = acc;
    }
    for (c = 0; c < K; ++c) {
        int piv = c;
        real best = ABS(W[c][c]);
        for (i = c + 1; i < K; ++i) {
            if (ABS(W[i][c]) > best) {
                piv = i;
                best = ABS(W[i][c]);
            }
        }
        if (!(best > SINGULAR_TOL)) return 0;
        if (piv != c) {
            for (j = 0; j < K + NV + 1; ++j) {
                real t = W[c][j];
                W[c][j] = W[piv][j];
                W[piv][j] = t;
            }
        }
        eliminate(&W[0][0], K + NV + 1, c, c);
    }
    for (r = 0; r < K; ++r) s->x[s->basis[r]] = W[r][K + NV];
    for (r = 0; r < K; ++r) {
        for (j = 0; j < NV; ++j) s->T[r][j] = W[r][K + j];
    }
    for (r = 0; r < K; ++r) {
        for (i = 0; i < K; ++i) s->T[i][s->basis[r]] = i == r ? 1 : 0;
    }
    reduced_costs(s, cost);
    for (j = 0; j < NV; ++j) {
        if (!FINITE(s->T[0][j]) || !FINITE(s->d[j])) return 0;
    }
    return 1;
}

/* step of the entering variable at which a basic variable moving at rate -a meets a bound */
static real step_to_bound(real a, real xj, real lbj, real ubj)
{
    if (a > PIVOT_TOL) return rmax((xj - lbj) / a, 0);
    if (a < -PIVOT_TOL && ubj < INF) return rmax((ubj - xj) / -a, 0);
    return INF;
}

/* primal simplex pivots, at most budget: pivots taken, *done = 1 when optimal (0 also when
   unbounded, or when the call's budget refused a pivot: s->capped) */
static int iterate(struct lp *s, int budget, int *done)
{
    int it, degenerate = 0, i, j, r;
    for (it = 0; it < budget; ++it) {
        int bland = degenerate >= BLAND_AFTER, q = -1, row = -1, leave;
        real best = 0, delta, t_min = INF, flip, tie, big = 0, a, f;
        for (j = 0; j < NV; ++j) {
            real dj, score;
            if (s->status[j] == BASIC || s->frozen[j] || !(s->ub[j] > s->lb[j])) continue;
            dj = s->d[j];
            score = s->status[j] == LOWER ? -dj : dj;
            if (score > DUAL_TOL && score > best) {
                q = j;
                best = score;
                if (bland) break;
            }
        }
        if (q < 0) {
            *done = 1;
            return it;
        }
        /* the call's pivot budget (not in the library, whose cap is MAXIT): refuse the pivot */
        if (s->spent + it >= s->limit) {
            s->capped = 1;
            *done = 0;
            return it;
        }
        delta = s->status[q] == LOWER ? 1 : -1;
        /* ratio test: the smallest step, ties to the largest pivot (Bland: smallest index) */
        for (r = 0; r < K; ++r) {
            j = s->basis[r];
            t_min = rmin(t_min, step_to_bound(delta * s->T[r][q], s->x[j], s->lb[j], s->ub[j]));
        }
        flip = s->ub[q] - s->lb[q];
        if (flip <= t_min) {
            if (!(flip < INF)) {
                *done = 0; /* unbounded: impossible for these stages (costs bounded below) */
                return it;
            }
            for (r = 0; r < K; ++r) s->x[s->basis[r]] -= flip * delta * s->T[r][q];
            if (s->status[q] == LOWER) {
                s->status[q] = UPPER;
                s->x[q] = s->ub[q];
            } else {
                s->status[q] = LOWER;
                s->x[q] = s->lb[q];
            }
            degenerate = 0;
            continue;
        }
        tie = t_min + TIE_RTOL * (1 + t_min);
        for (r = 0; r < K; ++r) {
            a = delta * s->T[r][q];
            j = s->basis[r];
            if (step_to_bound(a, s->x[j], s->lb[j], s->ub[j]) <= tie) {
                if (bland) {
                    if (row < 0 || s->basis[r] < s->basis[row]) row = r;
                } else if (ABS(a) > big) {
                    row = r;
                    big = ABS(a);
                }
            }
        }
        if (row < 0) { /* unreachable: the row of t_min (finite here) is within the tie */
            *done = 0;
            return it;
        }
        r = row;
        a = delta * s->T[r][q];
        for (i = 0; i < K; ++i) s->x[s->basis[i]] -= t_min * delta * s->T[i][q];
        leave = s->basis[r];
        if (a > 0) {
            s->status[leave] = LOWER;
            s->x[leave] = s->lb[leave];
        } else {
            s->status[leave] = UPPER;
            s->x[leave] = s->ub[leave];
        }
        s->x[q] = (delta > 0 ? s->lb[q] : s->ub[q]) + delta * t_min;
        s->basis[r] = q;
        s->status[q] = BASIC;
        eliminate(&s->T[0][0], NV, r, q);
        f = s->d[q];
        for (j = 0; j < NV; ++j) s->d[j] -= f * s->T[r][j];
        for (i = 0; i < K; ++i) s->T[i][q] = 0;
        s->T[r][q] = 1;
        s->d[q] = 0;
        degenerate = t_min <= DEGENERATE_TOL ? degenerate + 1 : 0;
    }
    *done = 0;
    return budget;
}

/* 1 while no nonbasic, unfrozen, movable variable prices in (the fresh reduced costs) */
static int priced_out(const struct lp *s)
{
    int j;
    for (j = 0; j < NV; ++j) {
        if (s->status[j] != BASIC && !s->frozen[j] && s->ub[j] > s->lb[j]) {
            real sc = s->status[j] == LOWER ? -s->d[j] : s->d[j];
            if (sc > DUAL_TOL) return 0;
        }
    }
    return 1;
}

/* every stage in order from the canonical basis (alloc._engine._simplex.solve_lexicographic): u, and
   the solve code; s->spent the pivots taken */
static int lp_solve(struct lp *s, const real *v, const real *lo, const real *hi, real *u)
{
    int i, j, st;
    for (j = 0; j < M; ++j) {
        real cj = rmin(rmax(UP[j], lo[j]), hi[j]);
        s->c[j] = cj;
        if (D[j] > 0) {
            s->ub[j] = rmax((hi[j] - cj) / D[j], 0);
            s->ub[M + j] = rmax((cj - lo[j]) / D[j], 0);
        } else {
            s->ub[j] = 0;
            s->ub[M + j] = 0;
        }
    }
    for (j = 0; j < NV; ++j) {
        s->lb[j] = 0;
        s->x[j] = 0;
        s->status[j] = LOWER;
        s->frozen[j] = 0;
    }
    for (i = 0; i < K; ++i) {
        real acc = v[i], bi, sgn;
        s->ub[2 * M + i] = INF;
        s->ub[2 * M + K + i] = INF;
        for (j = 0; j < M; ++j) acc -= BM[i][j] * s->c[j];
        bi = acc / RHO[i];
        /* beyond the reach of any column the sign alone matters */
        if (!(bi <= B_CLAMP)) bi = !(bi < 0) ? B_CLAMP : -B_CLAMP;
        if (bi < -B_CLAMP) bi = -B_CLAMP;
        s->b[i] = bi;
        /* canonical start: the slack whose sign matches b_i is basic (e- for b_i >= 0) */
        j = bi >= 0 ? 2 * M + K + i : 2 * M + i;
        s->basis[i] = j;
        s->status[j] = BASIC;
        s->x[j] = ABS(bi);
        sgn = bi >= 0 ? 1 : -1;
        for (j = 0; j < NV; ++j) s->T[i][j] = sgn * F[i][j];
    }
    s->spent = 0;
    s->capped = 0;
    for (st = 0; st < NSTAGE; ++st) {
        const real *cost = COSTS[st];
        int since = 0;
        reduced_costs(s, cost);
        for (;;) {
            int done, n, budget = MAXIT - s->spent < REFACTOR_EVERY ? MAXIT - s->spent : REFACTOR_EVERY;
            n = iterate(s, budget, &done);
            s->spent += n;
            since += n;
            if (s->capped) return LP_LIMIT;
            if (since > 0 || !done) {
                if (!refactor(s, cost)) return LP_NUMERICAL;
                since = 0;
                if (!done) {
                    if (s->spent >= MAXIT) return LP_LIMIT;
                    continue;
                }
                /* optimal before the refactorisation: confirm on the fresh reduced costs */
                if (!priced_out(s)) {
                    if (s->spent >= MAXIT) return LP_LIMIT;
                    continue;
                }
            }
            break;
        }
        /* the next stages stay on this stage's optimal face */
        for (j = 0; j < NV; ++j) {
            if (s->status[j] == LOWER && s->d[j] > DUAL_TOL) {
                s->frozen[j] = 1;
            } else if (s->status[j] == UPPER && s->d[j] < -DUAL_TOL) {
                s->frozen[j] = 1;
            }
        }
    }
    for (j = 0; j < NV; ++j) {
        real tol;
        if (!FINITE(s->x[j])) return LP_NUMERICAL;
        tol = FEASIBLE_RTOL * (1 + ABS(s->x[j]));
        if (s->x[j] < s->lb[j] - tol || s->x[j] > s->ub[j] + tol) return LP_NUMERICAL;
    }
    for (j = 0; j < M; ++j) u[j] = rmin(rmax(s->c[j] + D[j] * (s->x[j] - s->x[M + j]), lo[j]), hi[j]);
    return LP_OPTIMAL;
}

/* 1 while the limits in force are the nominal ones (PREFIX_set_limits) */
static int limits_nominal = 1;

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    struct lp s;
    real lo[M], hi[M];
    int code;
    last_iterations = 0;
    if (bounds(v, u_prev, dt, lo, hi, u)) return 2;
    /* the certified budget covers the nominal limits without a rate window (see the header);
       elsewhere the library's cap: a call succeeds within MAXIT - 1 pivots */
    s.limit = u_prev == NULL && limits_nominal ? PFX_ITERATION_BOUND : PFX_MAXIT - 1;
    code = lp_solve(&s, v, lo, hi, u);
    last_iterations = s.spent;
    if (code != LP_OPTIMAL) {
        safe_answer(v, lo, hi, u);
        return 2;
    }
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}

""" + SET_LIMITS
