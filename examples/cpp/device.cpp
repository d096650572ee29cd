// A device-style loop on the frictionless C API: N joints at 1 kHz, each with its own friction
// estimator (a PINN from a shared .fwt model, or CV when no model is given) and its own control law,
// like a YARP device's run(). The "robot" here is a made-up sinusoidal motion so the example runs
// anywhere; replace read_state() and write_current() with the real interfaces.
//
// usage: device [MODEL.fwt] [--ticks N] [--joints N]
#include <frictionless.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

// Throws with the library's message when a call fails (setup only: the loop checks codes).
void ok(fl_status st, const char *what) {
    if (st != FL_STATUS_OK) {
        throw std::runtime_error(std::string(what) + ": " + fl_status_name(st) + ": " + fl_last_error());
    }
}

struct ModelDeleter {
    void operator()(fl_model *m) const { fl_model_free(m); }
};
struct EstimatorDeleter {
    void operator()(fl_estimator *e) const { fl_estimator_free(e); }
};
struct LawDeleter {
    void operator()(fl_law *l) const { fl_law_free(l); }
};

struct Joint {
    std::unique_ptr<fl_estimator, EstimatorDeleter> estimator;
    std::unique_ptr<fl_law, LawDeleter> law;
    double gear_ratio;
    bool enabled = false;
};

// The made-up robot: joint j follows a sinusoid; the motor angle adds a small wind-up.
fl_joint_sample read_state(std::size_t j, long tick, double r) {
    const double t = static_cast<double>(tick) * 1e-3, w = 3.0 + static_cast<double>(j);
    fl_joint_sample s;
    s.s_rad = 0.2 * std::sin(w * t);
    s.sdot_rad_s = 0.2 * w * std::cos(w * t);
    s.theta_motor_rad = r * s.s_rad + 0.05 * std::sin(2.0 * w * t);
    s.omega_motor_rad_s = r * s.sdot_rad_s + 0.1 * w * std::cos(2.0 * w * t);
    s.temperature_c = 35.0;
    return s;
}

}  // namespace

int main(int argc, char **argv) {
    const char *model_path = nullptr;
    long ticks = 1000;
    std::size_t n_joints = 3;
    const char *trace_path = nullptr;  // diagnostics: one line per joint per tick (a test compares it)
    for (int i = 1; i < argc; i++) {
        if (!std::strcmp(argv[i], "--ticks") && i + 1 < argc) {
            ticks = std::atol(argv[++i]);
        } else if (!std::strcmp(argv[i], "--joints") && i + 1 < argc) {
            n_joints = static_cast<std::size_t>(std::atol(argv[++i]));
        } else if (!std::strcmp(argv[i], "--trace") && i + 1 < argc) {
            trace_path = argv[++i];
        } else {
            model_path = argv[i];
        }
    }
    try {
        // Setup (allocates): one shared model, per joint an estimator and a law.
        std::unique_ptr<fl_model, ModelDeleter> model;
        fl_model_info info{};
        if (model_path) {
            fl_model *m = nullptr;
            ok(fl_model_open(model_path, &m), model_path);
            model.reset(m);
            ok(fl_model_describe(model.get(), &info), "describe");
            std::printf("model %s: joint %s, %s, H=%u, %u inputs, r=%g, kt=%g Nm/A\n", model_path,
                        info.joint_name, info.feature_set, info.history, info.n_inputs,
                        info.gear_ratio, info.kt_nm_per_a);
            for (uint32_t b = 0; b < info.n_blocks; b++) {
                fl_feature_block blk;
                ok(fl_model_feature_block(model.get(), b, &blk), "block");
                std::printf("  block %u: %s [%s] x %u\n", b, blk.name, blk.unit, info.history);
            }
        }
        std::vector<Joint> joints(n_joints);
        for (auto &j : joints) {
            fl_estimator *e = nullptr;
            if (model) {
                ok(fl_estimator_create(model.get(), FL_WARMUP_HOLD_ZERO, &e), "estimator");
                j.gear_ratio = info.gear_ratio;
            } else {
                fl_cv_params cv{1.2, 10.53, 0.24};  // kc, ka, kv (paper, ankle roll)
                ok(fl_estimator_create_cv(&cv, &e), "estimator");
                j.gear_ratio = -160.0;
            }
            j.estimator.reset(e);
            fl_law_params p{};
            p.kt_nm_per_a = model ? info.kt_nm_per_a : 0.0665;
            p.gear_ratio = j.gear_ratio;
            p.kfc = 0.85;
            p.max_curr_a = 3.0;
            p.max_output_friction_nm = 8.0;
            p.dt_s = 1e-3;
            p.bwfilter_enabled = true;
            p.bwfilter_order = 2;
            p.bwfilter_cutoff_hz = 20.0;
            fl_law *l = nullptr;
            ok(fl_law_create(&p, &l), "law");
            j.law.reset(l);
        }
        model.reset();  // estimators keep what they need
        // Diagnostics only (a real device would not write a file in its loop): joint, sample, tau_F.
        std::FILE *trace = trace_path ? std::fopen(trace_path, "w") : nullptr;
        if (trace_path && !trace) {
            throw std::runtime_error(std::string("cannot write ") + trace_path);
        }

        // The 1 kHz loop: no allocation, no exception, status codes checked.
        auto next = std::chrono::steady_clock::now();
        long failures = 0, overruns = 0;
        double max_abs_i = 0.0;
        for (long tick = 0; tick < ticks; tick++) {
            for (std::size_t k = 0; k < joints.size(); k++) {
                Joint &j = joints[k];
                const fl_joint_sample s = read_state(k, tick, j.gear_ratio);
                if (!j.enabled) {  // bumpless enable: estimator and law reset at this sample
                    failures += fl_estimator_reset(j.estimator.get(), &s) != FL_STATUS_OK;
                    failures += fl_law_reset(j.law.get()) != FL_STATUS_OK;
                    j.enabled = true;
                }
                double f = 0.0;
                failures += fl_estimator_estimate(j.estimator.get(), &s, &f) != FL_STATUS_OK;
                if (trace) {
                    std::fprintf(trace, "%zu,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", k, s.s_rad,
                                 s.sdot_rad_s, s.theta_motor_rad, s.omega_motor_rad_s,
                                 s.temperature_c, f);
                }
                fl_law_input in{};
                in.tau_des_nm = 1.0 * std::sin(1e-3 * static_cast<double>(tick));
                in.friction_nm = f;
                in.sdot_rad_s = s.sdot_rad_s;
                fl_law_output out{};
                failures += fl_law_step(j.law.get(), &in, &out) != FL_STATUS_OK;
                // write_current(k, out.i_a);
                max_abs_i = std::fmax(max_abs_i, std::fabs(out.i_a));
            }
            next += std::chrono::milliseconds(1);
            if (std::chrono::steady_clock::now() > next) {
                overruns++;
            }
            std::this_thread::sleep_until(next);
        }
        if (trace) {
            std::fclose(trace);
        }
        std::printf("ticks %ld joints %zu failures %ld overruns %ld max_abs_i_a %.6g\n", ticks,
                    joints.size(), failures, overruns, max_abs_i);
        return failures == 0 ? 0 : 1;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "device: %s\n", e.what());
        return 1;
    }
}
