/*
 * Native timing driver of DAQP's C (the sources of the daqp package on PyPI, which
 * benchmarks/bench_export.py downloads and compiles in its own step) on the wls problem
 *
 *     min (B u - v)' Wv (B u - v) + gamma^2 (u - up)' Wu (u - up)   over umin <= u <= umax,
 *
 * as H = B' Wv B + gamma^2 Wu, f = -B' Wv v - gamma^2 Wu up and m simple bounds: the model set
 * up once (H factorised once), per call f updated and the QP solved ("cold": every bound's state
 * reset each call, as the generated kernels start cold; "warm": the last working set kept, DAQP's
 * default between solves).
 *
 * usage: daqp_driver PROBLEM.bin DEMANDS.bin N PASSES cold|warm GAMMA
 *   PROBLEM.bin: k, m, B (k x m, row-major), sqrt(diag Wv), sqrt(diag Wu), umin, umax, up as
 *   doubles (the file bench_export.py writes for wls-alloc).
 * Prints the JSON line of timing.h; "exact" counts exit flags > 0, "fallback" the others.
 */
#include "timing.h" /* first: it defines _POSIX_C_SOURCE */
#include <string.h>
#include "api.h"
#include "utils.h" /* daqp_update_ldp */

int main(int argc, char **argv)
{
    DAQPProblem qp;
    DAQPWorkspace work;
    DAQPResult res;
    double *P, *V, *B, *wv, *wu, *umin, *umax, *up, *H, *BW, *f0, *f, *x, *lam, *t, *floor_t;
    double gamma, check = 0, head[2];
    int *sense, *its, k, m, i, j, q, warm;
    size_t n, passes, p, c, counts[3] = {0, 0, 0};
    FILE *fp;
    if (argc < 7) {
        fprintf(stderr, "usage: daqp_driver PROBLEM.bin DEMANDS.bin N PASSES cold|warm GAMMA\n");
        return 2;
    }
    fp = fopen(argv[1], "rb");
    if (!fp || fread(head, sizeof(double), 2, fp) != 2) {
        fprintf(stderr, "daqp_driver: cannot read %s\n", argv[1]);
        return 2;
    }
    fclose(fp);
    k = (int)head[0];
    m = (int)head[1];
    P = load_doubles(argv[1], 2 + (size_t)(k * m + k + 4 * m));
    B = P + 2;
    wv = B + k * m;
    wu = wv + k;
    umin = wu + m;
    umax = umin + m;
    up = umax + m;
    n = (size_t)atol(argv[3]);
    passes = (size_t)atol(argv[4]);
    warm = strcmp(argv[5], "warm") == 0;
    gamma = atof(argv[6]);
    V = load_doubles(argv[2], n * (size_t)k);

    H = calloc((size_t)(m * m), sizeof(double));
    BW = calloc((size_t)(m * k), sizeof(double));
    f0 = calloc((size_t)m, sizeof(double));
    f = calloc((size_t)m, sizeof(double));
    x = calloc((size_t)m, sizeof(double));
    lam = calloc((size_t)m, sizeof(double));
    sense = calloc((size_t)m, sizeof(int));
    for (i = 0; i < m; ++i) {
        for (j = 0; j < m; ++j) {
            double s = 0;
            for (q = 0; q < k; ++q) s += B[q * m + i] * wv[q] * wv[q] * B[q * m + j];
            H[i * m + j] = s + (i == j ? gamma * gamma * wu[i] * wu[i] : 0);
        }
        for (q = 0; q < k; ++q) BW[i * k + q] = B[q * m + i] * wv[q] * wv[q];
        f0[i] = -gamma * gamma * wu[i] * wu[i] * up[i];
        f[i] = f0[i];
    }
    memset(&qp, 0, sizeof qp);
    memset(&work, 0, sizeof work);
    memset(&res, 0, sizeof res);
    qp.n = m;
    qp.m = m;
    qp.ms = m;
    qp.H = H;
    qp.f = f;
    qp.A = NULL;
    qp.bupper = umax;
    qp.blower = umin;
    qp.sense = sense;
    if (setup_daqp(&qp, &work, NULL) < 0) {
        fprintf(stderr, "daqp_driver: setup failed\n");
        return 2;
    }
    res.x = x;
    res.lam = lam;
    t = malloc(n * passes * sizeof(double));
    floor_t = malloc(n * passes * sizeof(double));
    its = malloc(n * sizeof(int));
    for (p = 0; p < passes; ++p) {
        for (c = 0; c < n; ++c) {
            const double *v = V + c * (size_t)k;
            double t0, t1, t2;
            int mask = DAQP_UPDATE_v;
            t0 = now_ns();
            t1 = now_ns();
            for (i = 0; i < m; ++i) {
                double s = f0[i];
                for (q = 0; q < k; ++q) s -= BW[i * k + q] * v[q];
                f[i] = s;
            }
            if (!warm) {
                for (i = 0; i < m; ++i) sense[i] = 0;
                mask |= DAQP_UPDATE_sense;
            }
            daqp_update_ldp(mask, &work, &qp);
            daqp_solve(&res, &work);
            t2 = now_ns();
            floor_t[p * n + c] = t1 - t0;
            t[p * n + c] = t2 - t1;
            if (p == 0) {
                its[c] = res.iter;
                counts[res.exitflag > 0 ? 0 : 2] += 1;
                for (i = 0; i < m; ++i) check += x[i];
            }
        }
    }
    report(t, floor_t, its, n, passes, counts, check);
    return 0;
}
