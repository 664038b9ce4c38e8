/*
 * The timing and reporting shared by the native drivers of benchmarks/bench_export.py
 * (driver.c: a generated kernel; daqp_driver.c: DAQP's C): each call timed on its own with
 * clock_gettime, and one line of JSON with the same fields for every driver.
 */
#ifndef BENCH_TIMING_H
#define BENCH_TIMING_H

#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static int cmp_int(const void *a, const void *b) { return *(const int *)a - *(const int *)b; }

/* count doubles from path (exit 2 when the file is shorter) */
static double *load_doubles(const char *path, size_t count)
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

/*
 * Prints the JSON line: per-call times in ns (median, p99, max over the passes x n calls in t,
 * sorted here), the worst demand (the largest over demands of each demand's fastest pass: a
 * preempted call does not count), the timer's own floor (floor_t: an empty timed region), the
 * iterations of the first pass (median, max), the calls by outcome (counts: 0 exact, 1
 * unattainable, 2 fallback or solver failure) and a checksum of the commands.
 */
static void report(double *t, double *floor_t, int *its, size_t n, size_t passes, const size_t counts[3],
                   double check)
{
    size_t total = n * passes, i, p;
    double worst = 0;
    for (i = 0; i < n; ++i) {
        double best = t[i];
        for (p = 1; p < passes; ++p) {
            if (t[p * n + i] < best) best = t[p * n + i];
        }
        if (best > worst) worst = best;
    }
    qsort(t, total, sizeof(double), cmp_double);
    qsort(floor_t, total, sizeof(double), cmp_double);
    qsort(its, n, sizeof(int), cmp_int);
    printf("{\"calls\": %zu, \"median_ns\": %.1f, \"p99_ns\": %.1f, \"max_ns\": %.1f, \"worst_demand_ns\": %.1f, "
           "\"floor_median_ns\": %.1f, \"floor_p99_ns\": %.1f, \"iterations_median\": %d, "
           "\"iterations_max\": %d, \"exact\": %zu, \"unattainable\": %zu, \"fallback\": %zu, "
           "\"checksum\": %.17g}\n",
           total, t[total / 2], t[(size_t)(0.99 * (double)(total - 1))], t[total - 1], worst, floor_t[total / 2],
           floor_t[(size_t)(0.99 * (double)(total - 1))], its[n / 2], its[n - 1], counts[0], counts[1],
           counts[2], check);
}

#endif /* BENCH_TIMING_H */
