/* Per-call cost of fl_estimator_estimate called from C through libfrictionless.so (hot loop, one
 * thread). Driven by capi/benches/overhead.rs, which compiles it; prints `c_api_estimate_ns p50 p10 p90`.
 * usage: bench MODEL.fwt BATCHES CALLS_PER_BATCH */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <frictionless.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

static int cmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: %s MODEL.fwt BATCHES CALLS_PER_BATCH\n", argv[0]);
        return 2;
    }
    int batches = atoi(argv[2]), calls = atoi(argv[3]);
    fl_model *m = NULL;
    fl_estimator *e = NULL;
    if (fl_model_open(argv[1], &m) != FL_STATUS_OK ||
        fl_estimator_create(m, FL_WARMUP_ZERO_PAD, &e) != FL_STATUS_OK) {
        fprintf(stderr, "%s\n", fl_last_error());
        return 1;
    }
    fl_model_info info;
    fl_model_describe(m, &info);
    double *per_call = malloc((size_t)batches * sizeof *per_call);
    double sink = 0.0;
    long k = 0;
    for (int b = 0; b < batches + 10; b++) { /* 10 warm-up batches */
        double t0 = now_ns();
        for (int i = 0; i < calls; i++, k++) {
            double t = (double)k * 1e-3;
            fl_joint_sample s = {0.2 * sin(3.0 * t), 0.6 * cos(3.0 * t),
                                 info.gear_ratio * 0.2 * sin(3.0 * t) + 0.01 * sin(7.0 * t),
                                 info.gear_ratio * 0.6 * cos(3.0 * t), 35.0};
            double y;
            fl_estimator_estimate(e, &s, &y);
            sink += y;
        }
        if (b >= 10) per_call[b - 10] = (now_ns() - t0) / calls;
    }
    qsort(per_call, (size_t)batches, sizeof *per_call, cmp);
    printf("c_api_estimate_ns %.1f %.1f %.1f (sink %g)\n", per_call[batches / 2],
           per_call[batches / 10], per_call[batches * 9 / 10], sink);
    free(per_call);
    fl_estimator_free(e);
    fl_model_free(m);
    return 0;
}
