/* The C API exercised from C: the Rust test (capi/tests/c_program.rs) compiles this file against
 * libfrictionless.so and libfrictionless.a, runs it, and checks what it prints against the core.
 *
 * usage: check MODEL.fwt SAMPLES.csv ROWS.csv [CODE:BAD_PATH ...]
 *   SAMPLES.csv: one joint sample per line: s_rad,sdot_rad_s,theta_motor_rad,omega_motor_rad_s,temperature_c
 *   ROWS.csv:    one raw input vector per line (n_inputs floats)
 *   CODE:PATH:   fl_model_open(PATH) must return status CODE
 * Prints `tag index value...` lines; exits non-zero (with a message on stderr) on any failed check. */
#include <frictionless.h>

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHECK(call)                                                                              \
    do {                                                                                         \
        fl_status st_ = (call);                                                                  \
        if (st_ != FL_STATUS_OK) {                                                               \
            fprintf(stderr, "%s:%d: %s -> %s: %s\n", __FILE__, __LINE__, #call,                  \
                    fl_status_name(st_), fl_last_error());                                       \
            exit(1);                                                                             \
        }                                                                                        \
    } while (0)

#define EXPECT(cond)                                                                             \
    do {                                                                                         \
        if (!(cond)) {                                                                           \
            fprintf(stderr, "%s:%d: expected %s (last error: %s)\n", __FILE__, __LINE__, #cond,  \
                    fl_last_error());                                                            \
            exit(1);                                                                             \
        }                                                                                        \
    } while (0)

/* Reads a CSV of `cols` numbers per line into a new array; *rows receives the line count. */
static double *read_csv(const char *path, size_t cols, size_t *rows) {
    FILE *f = fopen(path, "r");
    EXPECT(f != NULL);
    size_t cap = 1024, n = 0;
    double *v = malloc(cap * sizeof *v);
    char line[65536];
    while (fgets(line, sizeof line, f)) {
        char *p = line;
        for (size_t c = 0; c < cols; c++) {
            char *end;
            double x = strtod(p, &end);
            EXPECT(end != p);
            if (n == cap) {
                cap *= 2;
                v = realloc(v, cap * sizeof *v);
            }
            v[n++] = x;
            p = end;
            if (*p == ',') p++;
        }
    }
    fclose(f);
    EXPECT(n % cols == 0);
    *rows = n / cols;
    return v;
}

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    EXPECT(f != NULL);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc((size_t)n);
    EXPECT(fread(b, 1, (size_t)n, f) == (size_t)n);
    fclose(f);
    *len = (size_t)n;
    return b;
}

static fl_joint_sample sample_at(const double *s, size_t k) {
    fl_joint_sample js = {s[5 * k], s[5 * k + 1], s[5 * k + 2], s[5 * k + 3], s[5 * k + 4]};
    return js;
}

/* The estimator loop on one model: reset at the first sample, one estimate per sample. */
static void run_estimator(const fl_model *m, fl_warmup warmup, const double *s, size_t n, double *out) {
    fl_estimator *e = NULL;
    CHECK(fl_estimator_create(m, warmup, &e));
    fl_joint_sample first = sample_at(s, 0);
    CHECK(fl_estimator_reset(e, &first));
    for (size_t k = 0; k < n; k++) {
        fl_joint_sample js = sample_at(s, k);
        CHECK(fl_estimator_estimate(e, &js, &out[k]));
    }
    fl_estimator_free(e);
}

struct thread_job {
    const fl_model *model;
    const double *samples;
    size_t n;
    double *out;
};

static void *thread_main(void *arg) {
    struct thread_job *j = arg;
    run_estimator(j->model, FL_WARMUP_ZERO_PAD, j->samples, j->n, j->out);
    return NULL;
}

static void check_nulls(void) {
    fl_model *m = NULL;
    EXPECT(fl_model_open(NULL, &m) == FL_STATUS_NULL_POINTER && m == NULL);
    EXPECT(strstr(fl_last_error(), "path") != NULL);
    EXPECT(fl_model_open("x.fwt", NULL) == FL_STATUS_NULL_POINTER);
    EXPECT(fl_model_from_bytes(NULL, 10, &m) == FL_STATUS_NULL_POINTER);
    double y = 0.0;
    fl_joint_sample js = {0};
    EXPECT(fl_estimator_estimate(NULL, &js, &y) == FL_STATUS_NULL_POINTER);
    EXPECT(fl_estimator_reset(NULL, &js) == FL_STATUS_NULL_POINTER);
    EXPECT(fl_model_describe(NULL, NULL) == FL_STATUS_NULL_POINTER);
    EXPECT(fl_law_step(NULL, NULL, NULL) == FL_STATUS_NULL_POINTER);
    EXPECT(strcmp(fl_status_name(FL_STATUS_FORMAT), "FL_STATUS_FORMAT") == 0);
    EXPECT(strlen(fl_version()) > 0);
    fl_model_free(NULL);
    fl_estimator_free(NULL);
    fl_law_free(NULL);
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: %s MODEL.fwt SAMPLES.csv ROWS.csv [CODE:BAD_PATH ...]\n", argv[0]);
        return 2;
    }
    check_nulls();

    /* Open and describe. */
    fl_model *m = NULL;
    CHECK(fl_model_open(argv[1], &m));
    fl_model_info info;
    CHECK(fl_model_describe(m, &info));
    printf("info joint_name %s\n", info.joint_name);
    printf("info feature_set %s\n", info.feature_set);
    printf("info n_blocks %u\ninfo history %u\ninfo temperature %d\ninfo n_inputs %u\n",
           info.n_blocks, info.history, (int)info.temperature, info.n_inputs);
    printf("info uses_delta_theta %d\n", (int)info.uses_delta_theta);
    printf("info gear_ratio %.17g\ninfo kt_nm_per_a %.17g\ninfo dtype %u\n", info.gear_ratio,
           info.kt_nm_per_a, info.dtype);
    printf("info layers");
    for (uint32_t i = 0; i < info.n_layer_sizes; i++) printf(" %u", info.layer_sizes[i]);
    printf("\ninfo scv_prior %d %.17g %.17g\n", (int)info.has_scv_prior, info.scv_prior.ks,
           info.scv_prior.alpha);
    for (uint32_t b = 0; b < info.n_blocks; b++) {
        fl_feature_block blk;
        CHECK(fl_model_feature_block(m, b, &blk));
        printf("block %u %s|%s\n", b, blk.name, blk.unit);
    }
    fl_feature_block none;
    EXPECT(fl_model_feature_block(m, info.n_blocks, &none) == FL_STATUS_INVALID_ARGUMENT);

    /* The same model from a byte buffer, freed before use. */
    size_t len = 0;
    unsigned char *bytes = read_all(argv[1], &len);
    fl_model *mb = NULL;
    CHECK(fl_model_from_bytes(bytes, len, &mb));
    EXPECT(fl_model_from_bytes(bytes, len / 2, &m) == FL_STATUS_FORMAT);
    free(bytes);
    fl_model_info ib;
    CHECK(fl_model_describe(mb, &ib));
    EXPECT(ib.n_inputs == info.n_inputs && ib.gear_ratio == info.gear_ratio);
    EXPECT(strcmp(ib.joint_name, info.joint_name) == 0);

    /* Estimator loop (zero-pad warm-up). */
    size_t n = 0;
    double *s = read_csv(argv[2], 5, &n);
    EXPECT(n > info.history);
    double *est = calloc(n, sizeof *est);
    run_estimator(m, FL_WARMUP_ZERO_PAD, s, n, est);
    for (size_t k = 0; k < n; k++) printf("est %zu %.17g\n", k, est[k]);

    /* Hold-zero warm-up: 0 and not ready for H-1 ticks, then the zero-pad values. */
    fl_estimator *hz = NULL;
    CHECK(fl_estimator_create(m, FL_WARMUP_HOLD_ZERO, &hz));
    EXPECT(fl_estimator_create(m, 7, &hz) == FL_STATUS_INVALID_ARGUMENT);
    for (int round = 0; round < 2; round++) {
        fl_joint_sample first = sample_at(s, 0);
        CHECK(fl_estimator_reset(hz, &first));
        for (size_t k = 0; k < info.history; k++) {
            bool ready = true;
            CHECK(fl_estimator_is_ready(hz, &ready));
            EXPECT(!ready);
            double y = -1.0;
            fl_joint_sample js = sample_at(s, k);
            CHECK(fl_estimator_estimate(hz, &js, &y));
            EXPECT(k + 1 < info.history ? y == 0.0 : y == est[k]);
        }
        bool ready = false;
        CHECK(fl_estimator_is_ready(hz, &ready));
        EXPECT(ready);
    }
    fl_estimator_free(hz);

    /* The model shared by four threads, each with its own estimator: identical outputs. */
    pthread_t th[4];
    struct thread_job jobs[4];
    for (int t = 0; t < 4; t++) {
        jobs[t] = (struct thread_job){mb, s, n, calloc(n, sizeof(double))};
        EXPECT(pthread_create(&th[t], NULL, thread_main, &jobs[t]) == 0);
    }
    for (int t = 0; t < 4; t++) {
        pthread_join(th[t], NULL);
        EXPECT(memcmp(jobs[t].out, est, n * sizeof(double)) == 0);
        free(jobs[t].out);
    }

    /* Batch predict on the given rows. */
    size_t nr = 0;
    double *rows_d = read_csv(argv[3], info.n_inputs, &nr);
    float *rows = malloc(nr * info.n_inputs * sizeof *rows);
    for (size_t i = 0; i < nr * info.n_inputs; i++) rows[i] = (float)rows_d[i];
    float *pred = malloc(nr * sizeof *pred);
    CHECK(fl_model_predict(m, rows, nr, info.n_inputs, pred));
    for (size_t k = 0; k < nr; k++) printf("pred %zu %.9g\n", k, (double)pred[k]);
    EXPECT(fl_model_predict(m, rows, nr, info.n_inputs + 1, pred) == FL_STATUS_INVALID_ARGUMENT);
    EXPECT(fl_model_predict(m, NULL, nr, info.n_inputs, pred) == FL_STATUS_NULL_POINTER);
    EXPECT(fl_model_predict(m, NULL, 0, info.n_inputs, NULL) == FL_STATUS_OK);

    /* Static models with the BLF parameter names (paper Table I, ankle roll). */
    fl_cv_params cv = {.kc = 1.2, .ka = 10.53, .kv = 0.24};
    fl_scv_params scv = {.kc = 1.0005, .ka = 2.78, .kv = 0.29, .ks = 6.0, .vs = 0.13, .alpha = 0.6};
    const double v[] = {-2.0, -0.1, 0.0, 0.003, 0.13, 1.5};
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) {
        double a, b;
        CHECK(fl_cv_friction_nm(&cv, v[i], &a));
        CHECK(fl_scv_friction_nm(&scv, v[i], &b));
        printf("static %.17g %.17g %.17g\n", v[i], a, b);
    }
    fl_cv_params bad_cv = {.kc = -1.0, .ka = 1.0, .kv = 0.0};
    double unused;
    EXPECT(fl_cv_friction_nm(&bad_cv, 0.1, &unused) == FL_STATUS_INVALID_ARGUMENT);
    EXPECT(strstr(fl_last_error(), "kc") != NULL);
    fl_estimator *ecv = NULL;
    EXPECT(fl_estimator_create_cv(&bad_cv, &ecv) == FL_STATUS_INVALID_ARGUMENT && ecv == NULL);
    CHECK(fl_estimator_create_scv(&scv, &ecv));
    fl_joint_sample js1 = sample_at(s, 1);
    double y1, w1;
    CHECK(fl_estimator_estimate(ecv, &js1, &y1));
    CHECK(fl_scv_friction_nm(&scv, js1.sdot_rad_s, &w1));
    EXPECT(y1 == w1);
    fl_estimator_free(ecv);

    /* The law, fed with the estimator's output. */
    fl_law_params lp = {.kt_nm_per_a = info.kt_nm_per_a,
                        .gear_ratio = info.gear_ratio,
                        .kfc = 0.85,
                        .kp = 0.0,
                        .ki = 0.0,
                        .max_curr_a = 3.0,
                        .max_output_friction_nm = 8.0,
                        .joint_velocity_threshold_rad_s = 0.0,
                        .dt_s = 1e-3,
                        .bwfilter_enabled = true,
                        .bwfilter_order = 2,
                        .bwfilter_cutoff_hz = 20.0};
    fl_law *law = NULL;
    CHECK(fl_law_create(&lp, &law));
    for (size_t k = 0; k < n; k++) {
        fl_law_input in = {.tau_des_nm = 2.0 * sin(0.01 * (double)k),
                           .friction_nm = est[k],
                           .sdot_rad_s = s[5 * k + 1],
                           .tau_meas_nm = 0.0};
        fl_law_output o;
        CHECK(fl_law_step(law, &in, &o));
        printf("law %zu %.17g %.17g %u\n", k, o.i_a, o.tau_f_hat_nm, o.flags);
    }
    fl_law_input nan_in = {.tau_des_nm = NAN, .friction_nm = 0.0, .sdot_rad_s = 0.0, .tau_meas_nm = 0.0};
    fl_law_output o;
    CHECK(fl_law_step(law, &nan_in, &o));
    EXPECT(o.i_a == 0.0 && (o.flags & FL_LAW_NON_FINITE));
    CHECK(fl_law_reset(law));
    fl_law_free(law);
    fl_law_params bad = lp;
    bad.kt_nm_per_a = 0.0;
    EXPECT(fl_law_create(&bad, &law) == FL_STATUS_INVALID_ARGUMENT);
    EXPECT(strstr(fl_last_error(), "kt_nm_per_a") != NULL);
    bad = lp;
    bad.bwfilter_cutoff_hz = 600.0;
    EXPECT(fl_law_create(&bad, &law) == FL_STATUS_INVALID_ARGUMENT);

    /* The speed-dependent current limit: 0.5 * 3 A up to 100 rad/s at the motor, 0 A at 300;
     * half-way down the slope (200 rad/s) a large request gets 0.75 A. */
    fl_law_params sl = lp;
    sl.bwfilter_enabled = false;
    sl.speed_limit_enabled = true;
    sl.rated_motor_speed_rad_s = 100.0;
    sl.no_load_motor_speed_rad_s = 300.0;
    sl.current_safety_factor = 0.5;
    CHECK(fl_law_create(&sl, &law));
    fl_law_input fast = {.tau_des_nm = 100.0 * info.gear_ratio,
                         .friction_nm = 0.0,
                         .sdot_rad_s = 200.0 / fabs(info.gear_ratio),
                         .tau_meas_nm = 0.0};
    CHECK(fl_law_step(law, &fast, &o));
    EXPECT(fabs(o.i_a - 0.75) < 1e-9 && (o.flags & FL_LAW_CURRENT_SATURATED));
    fast.sdot_rad_s = 0.0;
    CHECK(fl_law_step(law, &fast, &o));
    EXPECT(fabs(o.i_a - 1.5) < 1e-12);
    fl_law_free(law);
    law = NULL;
    bad = sl;
    bad.current_safety_factor = 1.5;
    EXPECT(fl_law_create(&bad, &law) == FL_STATUS_INVALID_ARGUMENT && law == NULL);
    EXPECT(strstr(fl_last_error(), "current_safety_factor") != NULL);
    bad = sl;
    bad.no_load_motor_speed_rad_s = 50.0;
    EXPECT(fl_law_create(&bad, &law) == FL_STATUS_INVALID_ARGUMENT);
    EXPECT(strstr(fl_last_error(), "no_load_motor_speed_rad_s") != NULL);

    /* Bad files. */
    for (int i = 4; i < argc; i++) {
        char *colon = strchr(argv[i], ':');
        EXPECT(colon != NULL);
        int want = atoi(argv[i]);
        fl_model *bm = NULL;
        fl_status st = fl_model_open(colon + 1, &bm);
        printf("bad %d %d %s\n", want, (int)st, fl_last_error());
        EXPECT(st == want && bm == NULL && strlen(fl_last_error()) > 0);
    }

    free(s);
    free(est);
    free(rows_d);
    free(rows);
    free(pred);
    fl_model_free(m);
    fl_model_free(mb);
    printf("done\n");
    return 0;
}
