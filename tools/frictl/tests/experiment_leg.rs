//! The whole-leg closed loop through real processes: `frictionless_experiment::leg::run_leg_suite`
//! runs, per tested joint (knee, ankle roll) and compensation, the minimum-K_p bisection and a
//! disturbance trial, each trial a lockstep run of `frictl sim serve --preset leg`, `frictiond` with
//! six joints and the whole-leg computed-torque controller (M(q), h(q, q̇) of the nominal URDF),
//! while the other joints hold their pose.
//!
//! Checks: the report has every (joint, model) key with a finished search and finite disturbance
//! metrics; on the knee and on the ankle roll, compensating with the plant's true friction (the
//! oracle) and with the drives' nominal SCV each needs a lower minimum K_p than no compensation;
//! with the rest of the leg moving on small sines, the oracle still needs a lower one than none.
//! Small sizes: 0.5 Hz sines, two periods, four halvings.
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::PathBuf;

use crate::util::s;

use frictionless::friction::{CvParams, ScvParams};
use frictionless_experiment::controller::Reference;
use frictionless_experiment::leg::{
    LegModel, LegSuiteConfig, LegSuiteReport, LegTestJoint, RestMotion, run_leg_suite,
};
use frictionless_experiment::rig::LegSetup;
use frictionless_experiment::session::{Binaries, FrictionModel, ORACLE_LABEL};
use frictionless_sim::PlantParams;

/// The nominal steady-state SCV of a drive (motor side + LuGre at 25 °C, no ripple, no load term).
fn nominal_scv(p: &PlantParams) -> ScvParams {
    ScvParams {
        kc: p.f_c0_nm + p.f_cm_nm,
        ka: 50.0,
        kv: p.sigma2m_nms_per_rad + p.sigma2j_nms_per_rad,
        ks: p.f_s0_nm + p.f_cm_nm,
        vs: p.v_s_rad_s,
        alpha: p.stribeck_exponent,
    }
}

/// The same drive's CV (Coulomb and viscous terms of [`nominal_scv`]).
fn nominal_cv(p: &PlantParams) -> CvParams {
    let s = nominal_scv(p);
    CvParams {
        kc: s.kc,
        ka: s.ka,
        kv: s.kv,
    }
}

fn kp(r: &LegSuiteReport, joint: &str, model: &str) -> f64 {
    r.joints[joint].models[model].min_kp.kp_for_runs()
}

#[test]
fn leg_oracle_and_scv_need_a_lower_min_kp_than_none_on_knee_and_ankle_roll() {
    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond next to frictl (cargo build --workspace --bins)");
    let leg = LegSetup::load(&[]).unwrap();
    let n = leg.dof();
    let per = |f: &dyn Fn(&PlantParams) -> FrictionModel| -> Vec<FrictionModel> {
        leg.params.joints.iter().map(f).collect()
    };
    let models = vec![
        LegModel::uniform(FrictionModel::None, n),
        LegModel::per_joint("CV", per(&|p| FrictionModel::Cv(nominal_cv(p)))),
        LegModel::per_joint("SCV", per(&|p| FrictionModel::Scv(nominal_scv(p)))),
        LegModel::uniform(FrictionModel::Oracle, n),
    ];
    let mut cfg = LegSuiteConfig::paper(bins, models);
    cfg.joints = LegTestJoint::fast_pair();
    cfg.iterations = 4;
    cfg.after_release_s = 1.0;
    cfg.jobs = 2;
    cfg.progress = true;
    let report = run_leg_suite(&cfg).expect("leg suite");
    eprintln!("{}", report.markdown());

    // every (joint, model) key, a finished search, finite disturbance metrics
    let json = serde_json::to_value(&report).unwrap();
    for joint in ["l_knee", "l_ankle_roll"] {
        for model in ["none", "CV", "SCV", ORACLE_LABEL] {
            let cell = &json["joints"][joint]["models"][model];
            assert!(
                cell["min_kp"]["outcome"].is_string(),
                "{joint}/{model}: {cell}"
            );
            let d = cell["disturbance"]["rmse_after_release_rad"].as_f64();
            assert!(d.is_some_and(f64::is_finite), "{joint}/{model}: {cell}");
            assert!(cell["disturbance"]["max_deflection_rad"].as_f64().unwrap() > 0.0);
        }
    }
    for joint in ["l_knee", "l_ankle_roll"] {
        let none = kp(&report, joint, "none");
        for model in [ORACLE_LABEL, "SCV"] {
            let m = kp(&report, joint, model);
            assert!(
                m < none,
                "{joint}: {model} needs K_p {m}, no compensation {none}\n{}",
                report.markdown()
            );
        }
    }

    // the variant where the rest of the leg moves on small sines: the oracle still needs less
    cfg.rest = RestMotion::Sines {
        amplitude_rad: 0.05,
        freq_hz: 0.3,
    };
    cfg.models = vec![
        LegModel::uniform(FrictionModel::None, n),
        LegModel::uniform(FrictionModel::Oracle, n),
    ];
    let moving = run_leg_suite(&cfg).expect("leg suite, rest moving");
    eprintln!("{}", moving.markdown());
    for joint in ["l_knee", "l_ankle_roll"] {
        let (none, oracle) = (kp(&moving, joint, "none"), kp(&moving, joint, ORACLE_LABEL));
        assert!(
            oracle < none,
            "{joint}, rest moving: oracle K_p {oracle}, none {none}\n{}",
            moving.markdown()
        );
    }
}

/// A PINN on the leg's knee and ankle roll in frictiond's six-joint config: with the raw friction
/// (kfc 1, no clip, no LPF), the daemon's τ̂_F of every recorded state equals offline inference of
/// the same network on the same states (Δθ offset latched at enable), while the whole-leg
/// controller tracks a sine on the knee and the rest holds.
#[test]
fn leg_pinn_joints_in_frictiond_equal_offline_inference() {
    use crate::experiment_online_offline::{model_file, replay};
    use frictionless_experiment::rig::Rig;
    use frictionless_experiment::run::{JointPlan, TrialOptions, TrialSpec, run_trial_on};
    use frictionless_experiment::session::Mode;

    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond next to frictl (cargo build --workspace --bins)");
    let leg = LegSetup::load(&[]).unwrap();
    let dir = crate::util::scratch("frictl_leg_pinn");
    std::fs::create_dir_all(&dir).unwrap();
    let knee = leg.index("l_knee").unwrap();
    let ankle = leg.index("l_ankle_roll").unwrap();
    let mut files = std::collections::BTreeMap::new();
    for (i, seed) in [(knee, 21u64), (ankle, 22)] {
        let p = &leg.params.joints[i];
        let f = model_file(&p.joint, p.gear_ratio_signed, p.kt_nm_per_a, seed);
        let path = dir.join(format!("{}.fwt", p.joint));
        frictionless::weights::write_file(&path, &f).unwrap();
        files.insert(i, (f, path));
    }
    let joints = (0..leg.dof())
        .map(|i| JointPlan {
            index: i,
            kp_per_s2: if i == knee { 2000.0 } else { 5000.0 },
            reference: if i == knee {
                Reference::Sine {
                    centre_rad: -0.8,
                    amplitude_rad: 0.3,
                    freq_hz: 0.5,
                }
            } else {
                Reference::Hold {
                    s_rad: leg.params.joints[i].initial_s_rad,
                }
            },
            pulse: None,
            model: files
                .get(&i)
                .map_or(FrictionModel::None, |(_, p)| FrictionModel::Pinn(p.clone())),
        })
        .collect();
    let spec = TrialSpec {
        mode: Mode::Lockstep,
        duration_s: 1.5,
        joints,
        seed: 3,
        sets: vec![],
        pinn_delta_theta_offset_motor_rad: vec![],
        raw_friction: true,
        kfc: vec![],
    };
    let trace =
        run_trial_on(&bins, &Rig::Leg(&leg), &spec, &TrialOptions::default()).expect("leg trial");
    let _ = std::fs::remove_dir_all(&dir);
    for (&i, (file, _)) in &files {
        let tr = &trace.joints[i];
        assert_eq!(tr.index, i);
        assert_eq!(tr.model, "PINN");
        let n = tr.t_s.len();
        assert!(n > 1000, "{}: only {n} ticks", tr.name);
        let (off, _) = replay(file, None, tr);
        let mut worst = 0.0f64;
        let mut spread = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 1..n {
            let online = tr.tau_f_hat_nm[k];
            assert!(online.is_finite(), "{} row {k}: no daemon output", tr.name);
            worst = worst.max((online - off[k - 1]).abs());
            spread = (spread.0.min(off[k - 1]), spread.1.max(off[k - 1]));
        }
        eprintln!(
            "{}: max |online − offline| {worst:.3e} Nm, offline in [{:.3}, {:.3}]",
            tr.name, spread.0, spread.1
        );
        assert!(
            worst <= 1e-5 * (1.0 + spread.0.abs().max(spread.1.abs())),
            "{}: daemon τ̂_F differs from offline inference by {worst:.3e} Nm",
            tr.name
        );
    }
    // the knee tracked its sine under the whole-leg controller
    let k = &trace.joints[knee];
    let err = (0..k.t_s.len())
        .map(|r| (k.s_des_rad[r] - k.s_rad[r]).abs())
        .fold(0.0, f64::max);
    assert!(err < 0.1, "knee max tracking error {err} rad");
}

/// `frictl experiment all --robot leg` refuses, before any trial, labels that would merge two
/// models' rows (`none`, `oracle`, repeated, empty), a config that names no leg joint, options of the
/// single joints and an unusable `--out` (before: merged rows, a silent run without compensation,
/// ignored options, and an `--out` found unusable after the whole run).
#[test]
fn leg_options_that_would_merge_rows_or_be_ignored_are_refused_before_any_trial() {
    let dir = crate::util::scratch("frictl-leg-options");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let config = |name: &str, joint: &str| {
        let p = dir.join(name);
        std::fs::write(
            &p,
            format!(
                "[backend]\nkind = \"shm\"\n[[joint]]\nname = \"{joint}\"\nindex = 0\n\
                 gear_ratio = -100.0\nkt = 0.157\nmax_curr = 5.0\nfriction_model = \"none\"\n"
            ),
        )
        .unwrap();
        p
    };
    let knee = config("knee.toml", "l_knee");
    let other = config("other.toml", "r_wrist");
    let out = dir.join("out");
    let leg = |extra: &[&str]| {
        let mut a = vec!["experiment", "all", "--robot", "leg", "--out", s(&out)];
        a.extend_from_slice(extra);
        crate::util::err_text(crate::util::frictl(&a), &format!("{extra:?}"))
    };
    let cfg = |label: &str, p: &std::path::Path| format!("{label}={}", p.display());
    for (extra, says) in [
        (vec![cfg("none", &knee)], "built-in row"),
        (vec![cfg("oracle", &knee)], "built-in row"),
        (vec![cfg("", &knee)], "non-empty label"),
        (
            vec![format!("{},{}", cfg("A", &knee), cfg("A", &knee))],
            "given twice",
        ),
        (vec![cfg("W", &other)], "none of its joints (r_wrist)"),
    ] {
        let mut a = vec!["--leg-config"];
        a.extend(extra.iter().map(String::as_str));
        let err = leg(&a);
        assert!(err.contains(says), "{extra:?}: {err}");
    }
    let err = leg(&["--joint", "knee"]);
    assert!(err.contains("--joint"), "{err}");
    let err = leg(&["--model", "scv"]);
    assert!(err.contains("--model scv"), "{err}");
    let err = crate::util::err_text(
        crate::util::frictl(&[
            "experiment",
            "all",
            "--leg-config",
            &cfg("A", &knee),
            "--out",
            s(&out),
        ]),
        "--leg-config without --robot leg",
    );
    assert!(err.contains("only with --robot leg"), "{err}");
    // An --out that is a file: refused up front.
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let err = crate::util::err_text(
        crate::util::frictl(&["experiment", "all", "--robot", "leg", "--out", s(&file)]),
        "--out over a file",
    );
    assert!(err.contains("--out") && err.contains("a-file"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
