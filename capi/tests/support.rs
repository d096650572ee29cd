//! Shared by the C and C++ tests: where the built libraries are, compiling and running programs,
//! test models and samples.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fl_core::features::{FeatureSet, FeatureSpec, JointSample};
use fl_core::mlp::StorageDtype;
use fl_core::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use fl_core::units::GearRatio;
use fl_core::weights::{ModelFile, ModelMeta, TrainingMeta};

/// The crate directory (`capi/`).
pub fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `target/<profile>/`: the directory holding `libfrictionless.so` and `.a` (Cargo builds this
/// package's cdylib and staticlib with the rlib the test links).
pub fn lib_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    let deps = exe.parent().expect("deps dir");
    for dir in [deps.parent().expect("profile dir"), deps] {
        if dir.join("libfrictionless.so").exists() && dir.join("libfrictionless.a").exists() {
            return dir.to_path_buf();
        }
    }
    panic!("libfrictionless.so/.a not found next to {}", exe.display());
}

/// `frictl` next to the test's `deps/` directory (`tests/run.sh` builds every binary first), if built.
pub fn frictl() -> Option<PathBuf> {
    let exe = std::env::current_exe().expect("current_exe");
    let p = exe.parent()?.parent()?.join("frictl");
    p.exists().then_some(p)
}

/// A fresh scratch directory for one test.
pub fn scratch(tag: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("capi-{tag}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs a command; panics with its output unless it exits 0.
pub fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}):\n--- stdout\n{}\n--- stderr\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Compiles the C program `source` into `exe` with the system `cc` (C11, all warnings as errors):
/// `static_link` links `libfrictionless.a` with the link line the header gives, else the `.so`
/// (with an rpath); `extra` adds compiler flags (sanitizers).
pub fn compile_c(source: &Path, exe: &Path, static_link: bool, extra: &[&str]) {
    let lib = lib_dir();
    let mut cmd = Command::new("cc");
    cmd.args(["-std=c11", "-O1", "-g", "-Wall", "-Wextra", "-Werror"])
        .args(extra)
        .arg("-I")
        .arg(crate_dir().join("include"))
        .arg(source)
        .arg("-o")
        .arg(exe);
    if static_link {
        // The link line the README and the header give for the static library.
        cmd.arg(lib.join("libfrictionless.a"))
            .args(["-lpthread", "-ldl", "-lm"]);
    } else {
        cmd.arg("-L")
            .arg(&lib)
            .arg(format!("-Wl,-rpath,{}", lib.display()))
            .args(["-lfrictionless", "-lpthread", "-lm"]);
    }
    run_ok(&mut cmd);
}

/// Whether `prog` is on PATH.
pub fn have(prog: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {prog} >/dev/null 2>&1")])
        .status()
        .is_ok_and(|s| s.success())
}

/// A random model of the given spec (seeded), written to `path`.
pub fn write_model(
    path: &Path,
    spec: FeatureSpec,
    ratio: f64,
    dtype: StorageDtype,
    seed: u64,
) -> ModelFile {
    let mlp = seeded_mlp(
        &RandomMlpSpec {
            sizes: vec![spec.n_inputs(), 16, 8, 1],
            weights: WeightInit::Uniform { amp: 0.5 },
            bias: -0.2..0.2,
            norm: NormInit::Uniform {
                mean: -0.5..0.5,
                scale: 0.5..3.0,
            },
        },
        seed,
    )
    .unwrap();
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: "l_ankle_roll".into(),
            gear_ratio: GearRatio::new(ratio).unwrap(),
            kt_nm_per_a: 0.0665,
            features: spec,
            scv: Some(fl_core::friction::paper::SCV_ANKLE_ROLL),
            training: TrainingMeta::unknown("capi test", 0),
        },
        dtype,
        mlp,
    };
    fl_core::weights::write_file(path, &file).unwrap();
    // What a reader sees (weights rounded to the dtype).
    fl_core::weights::read_file(path).unwrap()
}

/// The two test models: the paper's set with temperature (f32) and the motor-velocity set (f16).
pub fn specs() -> [(FeatureSpec, f64, StorageDtype); 2] {
    [
        (
            FeatureSpec {
                set: FeatureSet::DeltaThetaJointVel,
                history: 8,
                temperature: true,
            },
            -160.0,
            StorageDtype::F32,
        ),
        (
            FeatureSpec {
                set: FeatureSet::MotorVelJointVel,
                history: 5,
                temperature: false,
            },
            100.0,
            StorageDtype::F16,
        ),
    ]
}

/// Tick `k` of a smooth joint motion with wind-up (r = `ratio`).
pub fn sample(k: usize, ratio: f64) -> JointSample {
    let t = k as f64 * 1e-3;
    JointSample {
        s_rad: 0.3 * (4.0 * t).sin(),
        sdot_rad_s: 1.2 * (4.0 * t).cos(),
        theta_motor_rad: ratio * 0.3 * (4.0 * t).sin() + 3.0 + 0.2 * (9.0 * t).sin(),
        omega_motor_rad_s: ratio * 1.2 * (4.0 * t).cos() + 1.8 * (9.0 * t).cos(),
        temperature_c: 30.0 + 5.0 * t,
    }
}

/// Relative closeness `|a − b| ≤ tol·|b|` (equal values always pass, 0 included).
pub fn close(a: f64, b: f64, tol: f64) -> bool {
    a == b || (a - b).abs() <= tol * b.abs()
}
