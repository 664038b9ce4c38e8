/*
 * Native timing driver of one generated kernel (benchmarks/bench_export.py builds it once per
 * kernel with -DKERNEL_HEADER='"alloc_qp.h"' -DPREFIX=alloc_qp; no Python in the loop).
 *
 * usage: driver DEMANDS.bin N PASSES [UPREV.bin DT]
 *   DEMANDS.bin holds N x K doubles (row-major); with UPREV.bin (N x M doubles) each call gets
 *   the rate window of that row's previous command over DT.
 * Prints one line of JSON: per-call times in ns (median, p99, max over PASSES passes of the N
 * calls, each call timed on its own), the worst demand (the largest over demands of each
 * demand's fastest pass: a preempted call does not count), the timer's own floor (an empty timed
 * region), the iterations (median, max) and a checksum of the commands.
 */
#include "timing.h" /* first: it defines _POSIX_C_SOURCE */
#include KERNEL_HEADER

#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
#define ALLOCATE CAT(PREFIX, _allocate)
#define ITERATIONS CAT(PREFIX, _iterations)
typedef CAT(PREFIX, _real) real;

int main(int argc, char **argv)
{
    size_t n, passes, i, p, j, total, counts[3] = {0, 0, 0};
    int k = CAT(CAT(PREFIX_UPPER, _), K), m = CAT(CAT(PREFIX_UPPER, _), M);
    double *V, *U = NULL, *t, *floor_t, dt = 0, check = 0;
    real *v, *uprev = NULL, u[CAT(CAT(PREFIX_UPPER, _), M)];
    int *its;
    if (argc < 4) {
        fprintf(stderr, "usage: driver DEMANDS.bin N PASSES [UPREV.bin DT]\n");
        return 2;
    }
    n = (size_t)atol(argv[2]);
    passes = (size_t)atol(argv[3]);
    V = load_doubles(argv[1], n * (size_t)k);
    if (argc >= 6) {
        U = load_doubles(argv[4], n * (size_t)m);
        dt = atof(argv[5]);
    }
    v = malloc(n * (size_t)k * sizeof(real));
    for (i = 0; i < n * (size_t)k; ++i) v[i] = (real)V[i];
    if (U) {
        uprev = malloc(n * (size_t)m * sizeof(real));
        for (i = 0; i < n * (size_t)m; ++i) uprev[i] = (real)U[i];
    }
    total = n * passes;
    t = malloc(total * sizeof(double));
    floor_t = malloc(total * sizeof(double));
    its = malloc(n * sizeof(int));
    for (p = 0; p < passes; ++p) {
        for (i = 0; i < n; ++i) {
            double t0, t1, t2;
            int s;
            t0 = now_ns();
            t1 = now_ns();
            s = ALLOCATE(v + i * (size_t)k, uprev ? uprev + i * (size_t)m : NULL, (real)dt, u);
            t2 = now_ns();
            floor_t[p * n + i] = t1 - t0;
            t[p * n + i] = t2 - t1;
            if (p == 0) {
                its[i] = ITERATIONS();
                counts[s < 0 || s > 2 ? 2 : s] += 1;
                for (j = 0; j < (size_t)m; ++j) check += (double)u[j];
            }
        }
    }
    report(t, floor_t, its, n, passes, counts, check);
    return 0;
}
