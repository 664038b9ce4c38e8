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
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include KERNEL_HEADER

#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
#define ALLOCATE CAT(PREFIX, _allocate)
#define ITERATIONS CAT(PREFIX, _iterations)
typedef CAT(PREFIX, _real) real;

static double now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static int cmpi(const void *a, const void *b) { return *(const int *)a - *(const int *)b; }

static double *load(const char *path, size_t count)
{
    FILE *f = fopen(path, "rb");
    double *x = malloc(count * sizeof(double));
    if (!f || !x || fread(x, sizeof(double), count, f) != count) {
        fprintf(stderr, "driver: cannot read %zu doubles from %s\n", count, path);
        exit(2);
    }
    fclose(f);
    return x;
}

int main(int argc, char **argv)
{
    size_t n, passes, i, p, j, total, counts[3] = {0, 0, 0};
    int k = CAT(CAT(PREFIX_UPPER, _), K), m = CAT(CAT(PREFIX_UPPER, _), M);
    double *V, *U = NULL, *t, *floor_t, dt = 0, check = 0, worst = 0;
    real *v, *uprev = NULL, u[CAT(CAT(PREFIX_UPPER, _), M)];
    int *its;
    if (argc < 4) {
        fprintf(stderr, "usage: driver DEMANDS.bin N PASSES [UPREV.bin DT]\n");
        return 2;
    }
    n = (size_t)atol(argv[2]);
    passes = (size_t)atol(argv[3]);
    V = load(argv[1], n * (size_t)k);
    if (argc >= 6) {
        U = load(argv[4], n * (size_t)m);
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
    for (i = 0; i < n; ++i) {
        double best = t[i];
        for (p = 1; p < passes; ++p) {
            if (t[p * n + i] < best) best = t[p * n + i];
        }
        if (best > worst) worst = best;
    }
    qsort(t, total, sizeof(double), cmp);
    qsort(floor_t, total, sizeof(double), cmp);
    qsort(its, n, sizeof(int), cmpi);
    printf("{\"calls\": %zu, \"median_ns\": %.1f, \"p99_ns\": %.1f, \"max_ns\": %.1f, \"worst_demand_ns\": %.1f, "
           "\"floor_median_ns\": %.1f, \"floor_p99_ns\": %.1f, \"iterations_median\": %d, "
           "\"iterations_max\": %d, \"exact\": %zu, \"unattainable\": %zu, \"fallback\": %zu, "
           "\"checksum\": %.17g}\n",
           total, t[total / 2], t[(size_t)(0.99 * (double)(total - 1))], t[total - 1], worst, floor_t[total / 2],
           floor_t[(size_t)(0.99 * (double)(total - 1))], its[n / 2], its[n - 1], counts[0], counts[1],
           counts[2], check);
    return 0;
}
