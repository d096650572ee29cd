//! `tests/c/check.c` against `libfrictionless.so` and `libfrictionless.a`: the same numbers as the
//! core and `frictl predict`, the right status for each bad file, and no memory error or leak under
//! valgrind (ASan when valgrind is absent).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use fl_core::features::History;
use fl_core::filter::CausalButterworth;
use fl_core::friction::{StaticFriction, paper};
use fl_core::kernel::Mlp;
use fl_core::law::{Gains, JointLaw, LawInput};
use fl_core::weights::ModelFile;

use crate::support::{close, compile_c, crate_dir, frictl, have, run_ok, sample, scratch, specs};

const TICKS: usize = 300;

/// Compiles `check.c`: `static` links `libfrictionless.a`, else the `.so` (with an rpath);
/// `extra` adds compiler flags (sanitizers).
fn compile(out: &Path, static_link: bool, extra: &[&str]) -> PathBuf {
    let exe = out.join(match (static_link, extra.is_empty()) {
        (true, _) => "check_static",
        (false, true) => "check_shared",
        (false, false) => "check_sanitized",
    });
    compile_c(
        &crate_dir().join("tests/c/check.c"),
        &exe,
        static_link,
        extra,
    );
    exe
}

/// The program's `tag index values...` lines, by tag.
fn parse(stdout: &[u8]) -> BTreeMap<String, Vec<Vec<String>>> {
    let mut m: BTreeMap<String, Vec<Vec<String>>> = BTreeMap::new();
    for line in String::from_utf8_lossy(stdout).lines() {
        let mut it = line.splitn(2, ' ');
        let tag = it.next().unwrap_or("").to_owned();
        let rest = it.next().unwrap_or("").to_owned();
        m.entry(tag)
            .or_default()
            .push(rest.split(' ').map(str::to_owned).collect());
    }
    m
}

fn num(s: &str) -> f64 {
    s.parse()
        .unwrap_or_else(|_| panic!("`{s}` is not a number"))
}

/// The files the program reads, and the expected values computed by the core.
struct Case {
    model_path: PathBuf,
    file: ModelFile,
    samples_csv: PathBuf,
    rows_csv: PathBuf,
    rows: Vec<Vec<f32>>,
    bad: Vec<String>,
}

fn make_case(dir: &Path, k: usize) -> Case {
    let (spec, ratio, dtype) = specs()[k];
    let model_path = dir.join(format!("model{k}.fwt"));
    let file = crate::support::write_model(&model_path, spec, ratio, dtype, 40 + k as u64);
    // Samples, and the input rows the core's History builds from them (zero-pad, latched at the
    // first sample) — what frictiond feeds the kernel.
    let mut samples = String::new();
    let mut rows_txt = String::new();
    let mut rows = Vec::new();
    let mut h = History::new(spec, file.meta.gear_ratio).unwrap();
    h.reset(&sample(0, ratio));
    let mut x = vec![0.0f32; spec.n_inputs()];
    for t in 0..TICKS {
        let s = sample(t, ratio);
        writeln!(
            samples,
            "{:?},{:?},{:?},{:?},{:?}",
            s.s_rad, s.sdot_rad_s, s.theta_motor_rad, s.omega_motor_rad_s, s.temperature_c
        )
        .unwrap();
        h.push(&s);
        h.fill(&mut x).unwrap();
        let line: Vec<String> = x.iter().map(|v| format!("{v:?}")).collect();
        writeln!(rows_txt, "{}", line.join(",")).unwrap();
        rows.push(x.clone());
    }
    let samples_csv = dir.join(format!("samples{k}.csv"));
    let rows_csv = dir.join(format!("rows{k}.csv"));
    std::fs::write(&samples_csv, samples).unwrap();
    std::fs::write(&rows_csv, rows_txt).unwrap();

    // Bad files: status code : path.
    let good = std::fs::read(&model_path).unwrap();
    let put = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let truncated = put("truncated.fwt", &good[..good.len() / 3]);
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let garbage = put("garbage.fwt", &garbage);
    let empty = put("empty.fwt", b"");
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    let flipped = put("crc.fwt", &flipped);
    let fifo = dir.join("fifo.fwt");
    run_ok(Command::new("mkfifo").arg(&fifo));
    let missing = dir.join("missing.fwt");
    let code = |st: frictionless::fl_status, p: &Path| format!("{}:{}", st as i32, p.display());
    use frictionless::fl_status as S;
    let bad = vec![
        code(S::Io, &missing),
        code(S::NotRegularFile, &fifo),
        code(S::NotRegularFile, dir),
        code(S::Format, &truncated),
        code(S::Format, &garbage),
        code(S::Format, &empty),
        code(S::Format, &flipped),
    ];
    Case {
        model_path,
        file,
        samples_csv,
        rows_csv,
        rows,
        bad,
    }
}

fn run_program(exe: &Path, c: &Case, wrapper: &[&str]) -> Vec<u8> {
    let mut cmd = if let Some((first, rest)) = wrapper.split_first() {
        let mut cmd = Command::new(first);
        cmd.args(rest).arg(exe);
        cmd
    } else {
        Command::new(exe)
    };
    cmd.arg(&c.model_path)
        .arg(&c.samples_csv)
        .arg(&c.rows_csv)
        .args(&c.bad);
    run_ok(&mut cmd).stdout
}

/// What `frictl predict` prints for the rows: the real binary when built (`tests/run.sh` builds it
/// first), else the computation it runs (`Mlp::new(&file.mlp, file.dtype)` + `forward`).
fn frictl_predict(c: &Case) -> Vec<f64> {
    match frictl() {
        Some(bin) => {
            let out = run_ok(
                Command::new(bin)
                    .arg("predict")
                    .arg(&c.model_path)
                    .arg("--input")
                    .arg(&c.rows_csv),
            );
            String::from_utf8(out.stdout)
                .unwrap()
                .lines()
                .map(num)
                .collect()
        }
        None => {
            assert!(
                std::env::var_os("CI").is_none(),
                "frictl is not built (tests/run.sh builds every binary before the tests)"
            );
            eprintln!("note: frictl not built; comparing with its kernel call in-process");
            let mut mlp = Mlp::new(&c.file.mlp, c.file.dtype).unwrap();
            c.rows.iter().map(|r| f64::from(mlp.forward(r))).collect()
        }
    }
}

fn check_output(out: &BTreeMap<String, Vec<Vec<String>>>, c: &Case) {
    let meta = &c.file.meta;
    let spec = meta.features;
    let info: BTreeMap<&str, String> = out["info"]
        .iter()
        .map(|v| (v[0].as_str(), v[1..].join(" ")))
        .collect();
    assert_eq!(info["joint_name"], meta.joint_name);
    assert_eq!(info["feature_set"], spec.set.name());
    assert_eq!(info["n_blocks"], spec.set.n_blocks().to_string());
    assert_eq!(info["history"], spec.history.to_string());
    assert_eq!(info["temperature"], u8::from(spec.temperature).to_string());
    assert_eq!(info["n_inputs"], spec.n_inputs().to_string());
    assert_eq!(
        info["uses_delta_theta"],
        u8::from(spec.set.uses_delta_theta()).to_string()
    );
    assert_eq!(num(&info["gear_ratio"]), meta.gear_ratio.get());
    assert_eq!(num(&info["kt_nm_per_a"]), meta.kt_nm_per_a);
    let layers: Vec<String> = c.file.mlp.sizes().iter().map(|n| n.to_string()).collect();
    assert_eq!(info["layers"], layers.join(" "));
    let scv = paper::SCV_ANKLE_ROLL;
    let prior: Vec<f64> = info["scv_prior"].split(' ').map(num).collect();
    assert_eq!(prior, [1.0, scv.ks, scv.alpha]);
    let blocks: Vec<String> = out["block"].iter().map(|v| v[1..].join(" ")).collect();
    let want: Vec<String> = spec
        .set
        .blocks()
        .iter()
        .map(|b| format!("{}|{}", b.name(), b.unit()))
        .collect();
    assert_eq!(blocks, want);

    // Batch predict and the estimator loop agree with `frictl predict` on the same rows.
    let reference = frictl_predict(c);
    assert_eq!(reference.len(), TICKS);
    let pred: Vec<f64> = out["pred"].iter().map(|v| num(&v[1])).collect();
    let est: Vec<f64> = out["est"].iter().map(|v| num(&v[1])).collect();
    assert_eq!((pred.len(), est.len()), (TICKS, TICKS));
    let mut nonzero = 0;
    for t in 0..TICKS {
        assert!(
            close(pred[t], reference[t], 1e-6),
            "row {t}: C predict {} vs frictl {}",
            pred[t],
            reference[t]
        );
        assert!(
            close(est[t], reference[t], 1e-6),
            "tick {t}: C estimator {} vs frictl {}",
            est[t],
            reference[t]
        );
        nonzero += usize::from(est[t] != 0.0);
    }
    assert!(
        nonzero > TICKS / 2,
        "the random network gives non-zero outputs"
    );

    // Static models: the core's values.
    let cv = paper::CV_ANKLE_ROLL;
    for v in &out["static"] {
        let (x, a, b) = (num(&v[0]), num(&v[1]), num(&v[2]));
        assert_eq!(a, cv.torque_nm(x), "CV at {x}");
        assert_eq!(b, scv.torque_nm(x), "SCV at {x}");
    }

    // The law: the core's JointLaw on the same inputs, bit for bit.
    let mut law = JointLaw::new(
        Gains {
            kt_nm_per_a: meta.kt_nm_per_a,
            gear_ratio: meta.gear_ratio.get(),
            kfc: 0.85,
            kp: 0.0,
            ki: 0.0,
            max_curr_a: 3.0,
            max_output_friction_nm: 8.0,
            joint_velocity_threshold_rad_s: 0.0,
            dt_s: 1e-3,
            speed_limit: None,
        },
        Some(CausalButterworth::design(2, 20.0, 1e3).unwrap()),
    );
    let laws = &out["law"];
    assert_eq!(laws.len(), TICKS);
    for (t, v) in laws.iter().enumerate() {
        let o = law.step(&LawInput {
            tau_des_nm: 2.0 * (0.01 * t as f64).sin(),
            friction_nm: est[t],
            sdot_rad_s: sample(t, meta.gear_ratio.get()).sdot_rad_s,
            tau_meas_nm: 0.0,
        });
        assert!(
            close(num(&v[1]), o.i_a, 1e-12),
            "tick {t}: i {} vs {}",
            v[1],
            o.i_a
        );
        assert!(close(num(&v[2]), o.tau_f_hat_nm, 1e-12), "tick {t}: τ̂_F");
        let flags = u32::from(o.flags.friction_clipped)
            | u32::from(o.flags.current_saturated) << 1
            | u32::from(o.flags.non_finite) << 2;
        assert_eq!(num(&v[3]) as u32, flags, "tick {t}: flags");
    }

    // Every bad file was refused with its code (the program checks the code; here: all ran).
    assert_eq!(out["bad"].len(), c.bad.len());
    assert_eq!(out["done"].len(), 1);
}

#[test]
fn c_program_matches_core_and_frictl() {
    let dir = scratch("c");
    let shared = compile(&dir, false, &[]);
    let static_ = compile(&dir, true, &[]);
    for k in 0..specs().len() {
        let case_dir = dir.join(format!("case{k}"));
        std::fs::create_dir_all(&case_dir).unwrap();
        let c = make_case(&case_dir, k);
        let a = run_program(&shared, &c, &[]);
        check_output(&parse(&a), &c);
        let b = run_program(&static_, &c, &[]);
        assert!(a == b, "the .so and .a programs print the same");
    }
}

#[test]
fn c_program_is_clean_under_valgrind_or_asan() {
    let dir = scratch("memcheck");
    let case_dir = dir.join("case");
    std::fs::create_dir_all(&case_dir).unwrap();
    let c = make_case(&case_dir, 0);
    if have("valgrind") {
        let exe = compile(&dir, false, &[]);
        let out = run_program(
            &exe,
            &c,
            &["valgrind", "-q", "--leak-check=full", "--error-exitcode=1"],
        );
        assert!(String::from_utf8_lossy(&out).contains("done"));
    } else {
        eprintln!("note: valgrind not found; running under AddressSanitizer");
        let exe = compile(
            &dir,
            false,
            &["-fsanitize=address", "-fno-omit-frame-pointer"],
        );
        let out = run_program(&exe, &c, &[]);
        assert!(String::from_utf8_lossy(&out).contains("done"));
    }
}
