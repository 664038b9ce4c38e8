"""C99 template of the active set's factorisation of a free set (:mod:`alloc.export`): the
table lookup, or at run time the Cholesky factor of ``Wu[F, F]`` and the one-sided Jacobi SVDs
of alloc/_engine/_lsq_factor.py (``_jacobi``, ``_factor``) in the same order of operations."""

FACTOR = r"""#if TABLE
static void lookup(struct work *w, int key)
{
    unsigned long bits = 0;
    int j;
    for (j = 0; j < M; ++j) {
        if (w->freeset[j]) bits |= 1UL << j;
    }
    w->L = w->S->tab_l[key][bits];
    w->Yc = w->S->tab_yc[key][bits];
    w->Vc = w->S->tab_vc[key][bits];
    w->sc = w->S->tab_sc[key][bits];
    w->Ya = w->S->tab_ya[key][bits];
    w->Va = w->S->tab_va[key][bits];
    w->sa = w->S->tab_sa[key][bits];
}
#else

/* one-sided Jacobi SVD of X[:n, :p] (row stride ld) in place: columns U diag(sig), V p x p */
static void jacobi(real *X, int ld, int n, int p, real *V, real *sig, real ref)
{
    int i, j, r, sweep;
    real tol, small = 0, smax = 0;
    for (i = 0; i < p; ++i) {
        for (j = 0; j < p; ++j) V[i * ld + j] = 0;
        V[i * ld + i] = 1;
    }
    tol = rmax(JACOBI_TOL_FLOOR, (real)n * JACOBI_EPS);
    for (j = 0; j < p; ++j) {
        for (r = 0; r < n; ++r) small += X[r * ld + j] * X[r * ld + j];
    }
    small *= JACOBI_SMALL;
    for (sweep = 0; sweep < 40; ++sweep) {
        int rotated = 0;
        for (i = 0; i < p - 1; ++i) {
            for (j = i + 1; j < p; ++j) {
                real a = 0, b = 0, c = 0, zeta, t, cs, sn;
                for (r = 0; r < n; ++r) {
                    real xi = X[r * ld + i], xj = X[r * ld + j];
                    a += xi * xi;
                    b += xj * xj;
                    c += xi * xj;
                }
                if (c == 0 || a <= small || b <= small || ABS(c) <= tol * SQRT(a * b)) continue;
                rotated = 1;
                zeta = (b - a) / (2 * c);
                t = (zeta >= 0 ? (real)1 : (real)-1) / (ABS(zeta) + SQRT(1 + zeta * zeta));
                cs = 1 / SQRT(1 + t * t);
                sn = cs * t;
                for (r = 0; r < n; ++r) {
                    real xi = X[r * ld + i], xj = X[r * ld + j];
                    X[r * ld + i] = cs * xi - sn * xj;
                    X[r * ld + j] = sn * xi + cs * xj;
                }
                for (r = 0; r < p; ++r) {
                    real vi = V[r * ld + i], vj = V[r * ld + j];
                    V[r * ld + i] = cs * vi - sn * vj;
                    V[r * ld + j] = sn * vi + cs * vj;
                }
            }
        }
        if (!rotated) break;
    }
    for (j = 0; j < p; ++j) {
        real s = 0;
        for (r = 0; r < n; ++r) s += X[r * ld + j] * X[r * ld + j];
        s = SQRT(s);
        sig[j] = s;
        if (s > smax) smax = s;
    }
    smax = rmax(smax, ref);
    for (j = 0; j < p; ++j) {
        if (sig[j] > SIGMA_RTOL * smax && sig[j] > SIGMA_TINY) {
            real inv = 1 / sig[j];
            for (r = 0; r < n; ++r) X[r * ld + j] *= inv;
        } else {
            sig[j] = 0;
        }
    }
}

/* X[:n, c] = L^-1 X[:n, c] (row stride ld) */
static void lsolve_col(const struct work *w, int n, real *X, int ld, int c)
{
    int q, s;
    for (q = 0; q < n; ++q) {
        real acc = X[q * ld + c];
        if (!w->S->diag) {
            for (s = 0; s < q; ++s) acc -= LQ(w, q, s) * X[s * ld + c];
        }
        X[q * ld + c] = acc / LQ(w, q, q);
    }
}

/* the current factorisation is f */
static void use(struct work *w, const struct factors *f)
{
    w->L = f->L;
    w->Yc = f->Yc;
    w->Vc = f->Vc;
    w->sc = f->sc;
    w->Ya = f->Ya;
    w->Va = f->Va;
    w->sa = f->sa;
}

/* factorise the free set fidx[:nf] of the level with rows A[r0:r1] (equalities A[:r0]) into f */
static void factor(struct work *w, int r0, int r1, int nf, struct factors *f)
{
    int nl = r1 - r0, nc = r0, q, s, t, c, i, twice;
    const int *F = w->fidx;
    real ref = 0, *L = f->L, *Yc = f->Yc, *Vc = f->Vc, *sc = f->sc, *Ya = f->Ya, *Va = f->Va;
    use(w, f);
    for (q = 0; q < nf; ++q) {
        if (w->S->diag) {
            L[q * ML] = SQRT(w->S->wu[F[q]][F[q]]);
        } else {
            for (s = 0; s <= q; ++s) {
                real acc = w->S->wu[F[q]][F[s]];
                for (t = 0; t < s; ++t) acc -= LQ(w, q, t) * LQ(w, s, t);
                if (q == s) {
                    L[q * ML + (w->S->diag ? 0 : q)] = SQRT(rmax(acc, CHOL_TINY));
                } else {
                    L[q * ML + (w->S->diag ? 0 : s)] = acc / LQ(w, s, s);
                }
            }
        }
    }
    for (c = 0; c < nc; ++c) {
        for (q = 0; q < nf; ++q) Yc[q * NCW + c] = A[c][F[q]];
        lsolve_col(w, nf, Yc, NCW, c);
    }
    if (nc > 0) jacobi(Yc, NCW, nf, nc, Vc, sc, 0);
    for (i = 0; i < nl; ++i) {
        for (q = 0; q < nf; ++q) Ya[q * NLW + i] = A[r0 + i][F[q]];
        lsolve_col(w, nf, Ya, NLW, i);
        for (q = 0; q < nf; ++q) ref = rmax(ref, ABS(Ya[q * NLW + i]));
        for (twice = 0; twice < 2; ++twice) {
            for (c = 0; c < nc; ++c) {
                if (sc[c] > 0) {
                    real acc = 0;
                    for (q = 0; q < nf; ++q) acc += Yc[q * NCW + c] * Ya[q * NLW + i];
                    for (q = 0; q < nf; ++q) Ya[q * NLW + i] -= acc * Yc[q * NCW + c];
                }
            }
        }
    }
    if (nl > 0) jacobi(Ya, NLW, nf, nl, Va, f->sa, ref);
}

#if CACHE
/* direct-mapped: slot hash(instance, key, free set) % CACHE, overwritten on a miss */
struct slot {
    int used, inst, key, nf;
    int fidx[M];
    struct factors f;
};
static struct slot cache[CACHE];

/* the factorisation of the free set fidx[:nf] under level key `key`, from the cache or fresh */
static void factorise(struct work *w, int key, int r0, int r1, int nf)
{
    int inst = (int)(w->S - INSTANCES), q, same;
    unsigned long h = (unsigned long)(key * NINST + inst);
    struct slot *s;
    for (q = 0; q < nf; ++q) h = (h * 31UL + (unsigned long)w->fidx[q] + 1UL) & 0xffffffffUL;
    s = &cache[((h * 2654435761UL) & 0xffffffffUL) % CACHE];
    same = s->used && s->inst == inst && s->key == key && s->nf == nf;
    for (q = 0; same && q < nf; ++q) same = s->fidx[q] == w->fidx[q];
    if (same) {
        use(w, &s->f);
        return;
    }
    factor(w, r0, r1, nf, &s->f);
    s->used = 1;
    s->inst = inst;
    s->key = key;
    s->nf = nf;
    for (q = 0; q < nf; ++q) s->fidx[q] = w->fidx[q];
}
#else
static void factorise(struct work *w, int key, int r0, int r1, int nf)
{
    (void)key;
    factor(w, r0, r1, nf, &w->own);
}
#endif
#endif

"""
