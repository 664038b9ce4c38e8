"""C99 template of ``cgi`` with priority levels (:mod:`alloc.export`); filled as
:mod:`.templates` describes.  Transcribes
``alloc.methods.cascade.CascadedGeneralizedInverse._solve_by_level`` (and
:func:`alloc._engine._linalg.max_scale`, :func:`alloc._engine._kernels.matvec`) in the same order of
operations, over constant tables of every level's prioritised pseudo-inverse of every free set
computed by the library's own ``_level_pinv``."""

from .templates_closed_form import _clipped_preference

CASCADE_LEVELS = r"""
/* priority levels, most important first: level l holds the axes LEVEL_AXES[LEVEL_START[l] ..
   LEVEL_START[l + 1]]; TAB_l[bits] is rows q < nf of the nf x K_l block of level l's
   prioritised pseudo-inverse over the free set (Wv of the levels so far, the earlier levels'
   moments held), K_l values a row, as the library computes it */
#define NL @NL@
static const int LEVEL_START[NL + 1] = @LEVEL_START@;
static const int LEVEL_AXES[K] = @LEVEL_AXES@;
/* a level is met when its residual is within CGI_RTOL max(1, |v|_inf); an effector is
   saturated when the step's room left for it is within CGI_REACH */
#define CGI_RTOL @CGI_RTOL@
#define CGI_REACH @CGI_REACH@
@TABLES@

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    real lo[M], hi[M], base[M], r[K], du[M], vmag = 0, tol;
    int F[M], freeset[M], i, j, q, l, step, nf, steps = 0, code;
""" + _clipped_preference("        u[j] = y;\n"
                          "        freeset[j] = lo[j] < hi[j];\n") + r"""    for (i = 0; i < K; ++i) {
        if (ABS(v[i]) > vmag) vmag = ABS(v[i]);
    }
    tol = CGI_RTOL * rmax(1, vmag);
    for (l = 0; l < NL; ++l) {
        int a0 = LEVEL_START[l], kl = LEVEL_START[l + 1] - a0;
        /* each step saturates at least one effector or ends the level: at most M + 1 */
        for (step = 0; step < M + 1; ++step) {
            unsigned long bits = 0;
            const real *P;
            real worst = 0, s = 1;
            int hit = 0;
            for (i = 0; i < kl; ++i) {
                int a = LEVEL_AXES[a0 + i];
                real acc = 0;
                for (j = 0; j < M; ++j) acc += BM[a][j] * u[j];
                r[i] = v[a] - acc;
                if (ABS(r[i]) > worst) worst = ABS(r[i]);
            }
            nf = 0;
            for (j = 0; j < M; ++j) {
                if (freeset[j]) {
                    F[nf++] = j;
                    bits |= 1UL << j;
                }
            }
            if (nf == 0 || worst <= tol) break;
            P = TAB[l] + bits * (unsigned long)(M * kl);
            for (q = 0; q < nf; ++q) {
                real acc = 0;
                for (i = 0; i < kl; ++i) acc += P[q * kl + i] * r[i];
                du[q] = acc;
            }
            /* the largest s in [0, 1] that keeps u + s du within the bounds */
            for (q = 0; q < nf; ++q) {
                real t;
                j = F[q];
                if (du[q] > 0) {
                    t = (hi[j] - u[j]) / du[q];
                    if (t < s) s = t;
                } else if (du[q] < 0) {
                    t = (lo[j] - u[j]) / du[q];
                    if (t < s) s = t;
                }
            }
            if (!(s > 0)) s = 0;
            for (q = 0; q < nf; ++q) {
                real y;
                j = F[q];
                y = u[j] + s * du[q];
                if (y < lo[j]) y = lo[j];
                if (y > hi[j]) y = hi[j];
                u[j] = y;
            }
            steps += 1;
            if (s >= 1) break;
            /* the effectors the step took to a bound leave the free set */
            for (q = 0; q < nf; ++q) {
                real reach;
                j = F[q];
                if (du[q] > 0) {
                    reach = (hi[j] - u[j]) / du[q];
                } else if (du[q] < 0) {
                    reach = (lo[j] - u[j]) / du[q];
                } else {
                    continue;
                }
                if (reach <= CGI_REACH) {
                    freeset[j] = 0;
                    hit = 1;
                }
            }
            if (!hit) break;
        }
    }
    (void)base;
    last_iterations = steps;
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}
"""
