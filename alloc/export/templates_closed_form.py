"""C99 templates of the closed-form kernels (:mod:`alloc.export`): ``pinv``, ``pinv_clip``,
``ganging``, ``pinv_scale`` and ``cgi``; filled as :mod:`.templates` describes."""


def _clipped_preference(also: str = "") -> str:
    """C statements that open a kernel working from ``base``: the call's bounds ``lo``, ``hi``
    (code 2 with the held answer when ``v``, ``u_prev`` or ``dt`` is invalid), then
    ``base[j]``, the preferred position ``UP[j]`` clipped onto them as ``y``; ``also`` holds
    further statements of that loop over ``j``."""
    return ("    last_iterations = 0;\n"
            "    if (bounds(v, u_prev, dt, lo, hi, u)) return 2;\n"
            "    for (j = 0; j < M; ++j) {\n"
            "        real y = UP[j];\n"
            "        if (y < lo[j]) y = lo[j];\n"
            "        if (y > hi[j]) y = hi[j];\n"
            "        base[j] = y;\n"
            + also +
            "    }\n")


# pinv, pinv_clip, ganging: u = clip(c + P v) (alloc._engine._kernels.fused_affine and, with rate
# limits, Method.solve + finish_owned: the same arithmetic).
AFFINE = r"""
/* the method's affine map u = C + P v before clipping */
static const real MAP_C[M] = @MAP_C@;
static const real MAP_P[M][K] = @MAP_P@;

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    real lo[M], hi[M];
    int i, j, code;
    last_iterations = 0;
    if (bounds(v, u_prev, dt, lo, hi, u)) return 2;
    for (j = 0; j < M; ++j) {
        real s = MAP_C[j];
        for (i = 0; i < K; ++i) s += MAP_P[j][i] * v[i];
        u[j] = s;
    }
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}
"""

# pinv_scale (alloc._engine._inverse_kernels.fused_scaled / scaled_increment): the increment from
# the clipped preferred position scaled by one factor into the box.
SCALED = r"""
static const real MAP_P[M][K] = @MAP_P@;

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    real lo[M], hi[M], base[M], r[K], du[M], s = 1;
    int i, j, code;
""" + _clipped_preference() + r"""    for (i = 0; i < K; ++i) {
        real acc = 0;
        for (j = 0; j < M; ++j) acc += BM[i][j] * base[j];
        r[i] = v[i] - acc;
    }
    for (j = 0; j < M; ++j) {
        real acc = 0;
        for (i = 0; i < K; ++i) acc += MAP_P[j][i] * r[i];
        du[j] = acc;
    }
    for (j = 0; j < M; ++j) {
        real t;
        if (du[j] > 0) {
            t = (hi[j] - base[j]) / du[j];
            if (t < s) s = t;
        } else if (du[j] < 0) {
            t = (lo[j] - base[j]) / du[j];
            if (t < s) s = t;
        }
    }
    s = rmax(0, s);
    for (j = 0; j < M; ++j) u[j] = base[j] + s * du[j];
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}
"""

# cgi (alloc._engine._inverse_kernels.cascade): the cascaded generalized inverse of section 1.3.4.6
# over the pseudo-inverses of every free set, precomputed by the library's own code.
CASCADE = r"""
/* the weighted pseudo-inverse of every free set (row: the free-set bits; rows q < nf of the
   nf x K inverse, K values each), as the library computes it */
static const real TAB_P[1 << M][M * K] = @TAB_P@;

int PREFIX_allocate(const real *v, const real *u_prev, real dt, real *u)
{
    real lo[M], hi[M], base[M], r[K], uF[M];
    int F[M], freeset[M], i, j, q, it, nf, code;
""" + _clipped_preference("        u[j] = y;\n"
                          "        freeset[j] = lo[j] < hi[j];\n") + r"""    for (it = 1; it < M + 2; ++it) {
        unsigned long bits = 0;
        const real *P;
        int hit = 0;
        nf = 0;
        for (j = 0; j < M; ++j) {
            if (freeset[j]) {
                F[nf++] = j;
                bits |= 1UL << j;
            }
        }
        if (nf == 0) { /* all saturated */
            it -= 1;
            break;
        }
        for (q = 0; q < nf; ++q) u[F[q]] = base[F[q]];
        for (i = 0; i < K; ++i) {
            real s = 0;
            for (j = 0; j < M; ++j) s += BM[i][j] * u[j];
            r[i] = v[i] - s;
        }
        P = TAB_P[bits];
        for (q = 0; q < nf; ++q) {
            real s = 0;
            for (i = 0; i < K; ++i) s += P[q * K + i] * r[i];
            uF[q] = base[F[q]] + s;
        }
        if (nf < K) { /* Eq 1.24, then clip */
            for (q = 0; q < nf; ++q) {
                real y = uF[q];
                j = F[q];
                if (y < lo[j]) y = lo[j];
                if (y > hi[j]) y = hi[j];
                u[j] = y;
            }
            break;
        }
        for (q = 0; q < nf; ++q) {
            j = F[q];
            if (uF[q] > hi[j] || uF[q] < lo[j]) hit = 1;
        }
        if (!hit) { /* no new saturation */
            for (q = 0; q < nf; ++q) u[F[q]] = uF[q];
            break;
        }
        for (q = 0; q < nf; ++q) {
            j = F[q];
            if (uF[q] > hi[j]) {
                u[j] = hi[j];
                freeset[j] = 0;
            } else if (uF[q] < lo[j]) {
                u[j] = lo[j];
                freeset[j] = 0;
            }
        }
    }
    last_iterations = it < M + 2 ? it : M + 1;
    code = finish(u, lo, hi, v);
    if (code == 2) {
        safe_answer(v, lo, hi, u);
    }
    return code;
}
"""
