//! Per-call cost of the C API's estimator step against the core called directly (results in
//! docs/performance.md; no timing asserts). One thread, hot loop, the same model and samples for every variant:
//!
//! - `rust_core`: `frictionless::model::JointModel::estimate` (what frictiond calls);
//! - `c_entry_from_rust`: `fl_estimator_estimate` called in-process (null checks, `catch_unwind`,
//!   conversions);
//! - `c_api_from_c`: `fl_estimator_estimate` from a C program through `libfrictionless.so`
//!   (`benches/c/bench.c`, compiled with the system `cc`; skipped when `cc` or the `.so` is absent).
//!
//! Models: the paper-size PINN (40 → 268 → 215 → 1, Δθ/ṡ, H = 20, f32) and a small one (H = 4,
//! 8 → 16 → 8 → 1) where the boundary's fixed cost is visible. Each figure is the median (p10, p90) of
//! per-call times over batches of calls; the two in-process variants alternate batch by batch. `cargo bench -p frictionless-capi --bench overhead`; under
//! `cargo test` it runs a few batches as a smoke test.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use fl_core::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use fl_core::mlp::StorageDtype;
use fl_core::model::{FrictionModel, JointModel, PinnEstimator};
use fl_core::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use fl_core::units::GearRatio;
use fl_core::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless::{
    FL_WARMUP_ZERO_PAD, fl_estimator_create, fl_estimator_estimate, fl_estimator_free,
    fl_joint_sample, fl_model_free, fl_model_open, fl_status,
};

fn sample(k: usize, r: f64) -> JointSample {
    let t = k as f64 * 1e-3;
    JointSample {
        s_rad: 0.2 * (3.0 * t).sin(),
        sdot_rad_s: 0.6 * (3.0 * t).cos(),
        theta_motor_rad: r * 0.2 * (3.0 * t).sin() + 0.01 * (7.0 * t).sin(),
        omega_motor_rad_s: r * 0.6 * (3.0 * t).cos(),
        temperature_c: 35.0,
    }
}

fn write_model(path: &Path, history: usize, hidden: &[usize]) -> ModelFile {
    let spec = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history,
        temperature: false,
    };
    let mut sizes = vec![spec.n_inputs()];
    sizes.extend_from_slice(hidden);
    sizes.push(1);
    let mlp = seeded_mlp(
        &RandomMlpSpec {
            sizes,
            weights: WeightInit::HeUniform,
            bias: -0.1..0.3,
            norm: NormInit::Uniform {
                mean: -0.5..0.5,
                scale: 0.5..2.0,
            },
        },
        7,
    )
    .expect("bench net");
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: "bench".into(),
            gear_ratio: GearRatio::new(-160.0).expect("ratio"),
            kt_nm_per_a: 0.0665,
            features: spec,
            scv: None,
            training: TrainingMeta::unknown("capi bench", 0),
        },
        dtype: StorageDtype::F32,
        mlp,
    };
    fl_core::weights::write_file(path, &file).expect("write bench model");
    file
}

/// Median, p10, p90 of per-call ns over `batches` batches of `calls` calls of `f(k)`.
type Stats = (f64, f64, f64);

fn quantiles(mut per_call: Vec<f64>) -> Stats {
    per_call.sort_by(f64::total_cmp);
    let q = |x: f64| per_call[((per_call.len() - 1) as f64 * x).round() as usize];
    (q(0.5), q(0.1), q(0.9))
}

/// Per-call ns of `a` and `b`, timed in alternating batches of `calls` calls (so a load change on
/// the shared machine hits both alike): median, p10, p90 over `batches` batches each.
fn time_pair(
    batches: usize,
    calls: usize,
    mut a: impl FnMut(usize) -> f64,
    mut b: impl FnMut(usize) -> f64,
) -> (Stats, Stats) {
    let (mut ta, mut tb) = (Vec::with_capacity(batches), Vec::with_capacity(batches));
    let mut sink = 0.0;
    let mut k = 0usize;
    for round in 0..batches + 10 {
        for (f, out) in [
            (&mut a as &mut dyn FnMut(usize) -> f64, &mut ta),
            (&mut b, &mut tb),
        ] {
            let t0 = Instant::now();
            for i in 0..calls {
                sink += f(k + i);
            }
            if round >= 10 {
                out.push(t0.elapsed().as_nanos() as f64 / calls as f64);
            }
        }
        k += calls;
    }
    black_box(sink);
    (quantiles(ta), quantiles(tb))
}

/// `target/<profile>/` holding `libfrictionless.so`, if built.
fn lib_dir() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let deps = exe.parent()?;
    [deps.parent()?, deps]
        .into_iter()
        .find(|d| d.join("libfrictionless.so").exists())
        .map(Path::to_path_buf)
}

fn c_bench(model: &Path, out_dir: &Path, batches: usize, calls: usize) -> Option<String> {
    let lib = lib_dir()?;
    let exe = out_dir.join("capi-bench");
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let ok = Command::new("cc")
        .args(["-std=c11", "-O2", "-I"])
        .arg(crate_dir.join("include"))
        .arg(crate_dir.join("benches/c/bench.c"))
        .arg("-L")
        .arg(&lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .args(["-lfrictionless", "-lm", "-o"])
        .arg(&exe)
        .status()
        .ok()?
        .success();
    if !ok {
        return None;
    }
    let out = Command::new(&exe)
        .arg(model)
        .arg(batches.to_string())
        .arg(calls.to_string())
        .output()
        .ok()?;
    Some(String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

fn main() {
    let bench = std::env::args().any(|a| a == "--bench");
    let (batches, calls) = if bench { (400, 2000) } else { (3, 10) };
    let dir = std::env::temp_dir().join(format!("capi-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("bench dir");
    for (name, history, hidden) in [
        ("paper 40-268-215-1", 20usize, &[268usize, 215][..]),
        ("small 8-16-8-1", 4, &[16, 8][..]),
    ] {
        let path = dir.join(format!("h{history}.fwt"));
        let file = write_model(&path, history, hidden);
        let r = file.meta.gear_ratio.get();
        let mut core = JointModel::from(
            PinnEstimator::from_model_file(&file, WarmupPolicy::ZeroPad).expect("estimator"),
        );
        let cpath = std::ffi::CString::new(path.to_str().expect("utf-8 path")).expect("path");
        let mut m = std::ptr::null_mut();
        let mut e = std::ptr::null_mut();
        // SAFETY: valid NUL-terminated path and out-pointers; handles freed below.
        unsafe {
            assert_eq!(fl_model_open(cpath.as_ptr(), &mut m), fl_status::Ok);
            assert_eq!(
                fl_estimator_create(m, FL_WARMUP_ZERO_PAD, &mut e),
                fl_status::Ok
            );
        }
        let (a, b) = time_pair(
            batches,
            calls,
            |k| core.estimate(&sample(k, r)),
            |k| {
                let s = sample(k, r);
                let cs = fl_joint_sample {
                    s_rad: s.s_rad,
                    sdot_rad_s: s.sdot_rad_s,
                    theta_motor_rad: s.theta_motor_rad,
                    omega_motor_rad_s: s.omega_motor_rad_s,
                    temperature_c: s.temperature_c,
                };
                let mut y = 0.0;
                // SAFETY: live estimator, valid sample and output pointers.
                unsafe { fl_estimator_estimate(e, &cs, &mut y) };
                y
            },
        );
        // SAFETY: handles from above, freed once.
        unsafe {
            fl_estimator_free(e);
            fl_model_free(m);
        }
        println!(
            "{name}: rust_core          p50 {:8.1} ns  (p10 {:.1}, p90 {:.1})",
            a.0, a.1, a.2
        );
        println!(
            "{name}: c_entry_from_rust  p50 {:8.1} ns  (p10 {:.1}, p90 {:.1})",
            b.0, b.1, b.2
        );
        println!("{name}: overhead (p50 difference) {:+.1} ns", b.0 - a.0);
        match c_bench(&path, &dir, batches, calls) {
            Some(line) => println!("{name}: c_api_from_c       {line}"),
            None => println!("{name}: c_api_from_c       skipped (no cc or no libfrictionless.so)"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
