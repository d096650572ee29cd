//! `frictl demo --robot leg`: the method on the coupled six-joint ergoCub left leg, end to end.
//!
//! 1. **Acquire** two simultaneous runs of every leg joint on the coupled plant
//!    (`frictionless_acquire::leg`, in process, as `frictl acquire --preset leg` runs them): the
//!    training protocol (seed S) and an unseen variant of it (other sine frequencies and amplitudes,
//!    ramp slopes, step levels and starting poses; seed S + 100).
//! 2. **Label** every joint of both runs from the whole leg's state (`label_leg`: one RNEA of the
//!    nominal URDF per sample over every joint's logged position) and, for comparison, from the
//!    single-joint view (the other joints held at their mean positions). Each joint's label error
//!    against the plant's truth is the report's `label_error_nm`.
//! 3. **Fit** CV, SCV and LuGre, **train** the PINN (SCV prior) and **evaluate** every model on the
//!    unseen run, per joint, through the real `frictl fit|train|eval` stages (the PINN as it is
//!    after step 5).
//! 4. **One frictiond config for the six joints** per compensation (`models/frictiond.toml` with the
//!    PINNs, `frictiond_scv.toml`, `frictiond_cv.toml`), each read back through `frictiond-config`.
//! 5. **On-policy rounds** (`--onpolicy-rounds`, default 1; DAgger as in the two-joint demo): the
//!    PINNs' minimum K_p on the knee and the ankle roll, closed-loop runs around it with them
//!    compensating, the tested joint's rows labelled from the whole leg's state and its training
//!    continued on the union (`--init`).
//! 6. **Closed loop** (`frictionless_experiment::leg::run_leg_suite`): one frictiond with six
//!    models against the leg in lockstep under the whole-leg computed-torque controller; minimum K_p
//!    and a disturbance trial on the knee and the ankle roll while the rest of the leg holds, for
//!    none, CV, SCV, PINN and the oracle.
//!
//! `report.json` (`frictionless-demo-leg-v1`) keeps the default demo's per-joint keys
//! (`joints.<name>.models.<model>.eval.rmse_true_all`, `….min_kp.kp`) and adds
//! `joints.<name>.label_error_nm = {"full_state", "single_joint_view"}` of the training label (matched,
//! with the wave generator's ripple step: `label_config`) and the same two with the authors'
//! separate filters, `separate_full_state` and `separate_single_joint_view`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use frictionless_acquire::leg::{
    LegJointLabels, SHORT_PROTOCOL, label_config, label_leg, leg_protocols, run_leg_offline_rows,
};
use frictionless_eval::{Metrics, Report as EvalReport};
use frictionless_experiment::leg::{
    LegCell, LegModel, LegSuiteConfig, LegTestJoint, run_leg_suite,
};
use frictionless_experiment::rig::LegSetup;
use frictionless_experiment::search::MinKp;
use frictionless_experiment::session::{
    Binaries, DaemonJoint, FrictionModel, ORACLE_LABEL, daemon_joint,
};
use frictionless_sim::LegParams;

use super::{
    Args, Dirs, EVAL_MODELS, JointFiles, Runner, Sizes, Stage, eval_table, evaluate, fit, s,
    train_args,
};
use frictionless_dataset::fit_file::FittedModel;
use frictionless_ident::dataset_file::{Provenance, write_dataset};

/// The unseen run of `--quick`: the same length, other frequency, slope, levels and starting pose.
const QUICK_TEST: &[&str] = &[
    "protocol.n_starts=1",
    "protocol.recentre_s=1.0",
    "protocol.current_scale=0.4",
    "protocol.start_shrink_deg=14",
    "protocol.sines.amplitude_to_a=0.7",
    "protocol.sines.frequencies_hz=[1.1]",
    "protocol.ramps.slopes_a_per_s=[0.3]",
    "protocol.steps.levels_a=[1.0, -1.0]",
];

/// The unseen run of the default and `--full` flavours: one start at other poses, other sine
/// frequencies and amplitudes, ramp slopes and step levels than the training protocol.
const TEST: &[&str] = &[
    "protocol.n_starts=1",
    "protocol.start_shrink_deg=14",
    "protocol.sines.frequencies_hz=[1.2, 0.6]",
    "protocol.sines.amplitude_from_a=0.8",
    "protocol.sines.amplitude_to_a=1.6",
    "protocol.sines.amplitude_step_a=0.4",
    "protocol.ramps.slopes_a_per_s=[0.19, 0.35]",
    "protocol.steps.levels_a=[0.8, -0.8, 1.2, -1.2]",
];

/// `report.json` of the leg demo.
#[derive(serde::Serialize)]
struct LegReport<'a> {
    format: &'static str,
    producer: String,
    settings: &'static str,
    seed: u64,
    network: super::Network,
    /// Samples per joint of the training and the unseen run.
    samples: [usize; 2],
    joints: &'a BTreeMap<String, LegJointEntry>,
    /// The closed-loop suite's own report (`None` with `--no-experiments`).
    closed_loop: Option<&'a frictionless_experiment::leg::LegSuiteReport>,
    /// The on-policy rounds (`--onpolicy-rounds`; none with `--no-experiments`).
    onpolicy_rounds: &'a [LegRound],
    stages: &'a [Stage],
    total_seconds: f64,
}

/// `report.json` `joints.JOINT`.
#[derive(serde::Serialize)]
struct LegJointEntry {
    /// label − truth RMS on the training run's valid, active, sliding rows [Nm].
    label_error_nm: LabelError,
    /// Model label (`none`, `CV`, `SCV`, `LuGre`, `PINN`, the oracle's) → results.
    models: BTreeMap<String, LegModelEntry>,
    files: super::JointFilesEntry,
}

/// Both label errors of one joint [Nm]: the training labels' (matched, with the ripple step:
/// `label_config`) and the authors' separate filters' (`separate_label_config`).
#[derive(serde::Serialize)]
struct LabelError {
    full_state: Option<f64>,
    single_joint_view: Option<f64>,
    separate_full_state: Option<f64>,
    separate_single_joint_view: Option<f64>,
}

/// `report.json` `joints.JOINT.models.LABEL`.
#[derive(serde::Serialize, Default)]
struct LegModelEntry {
    #[serde(skip_serializing_if = "Option::is_none")]
    eval: Option<Option<Metrics>>,
    #[serde(flatten)]
    closed_loop: Option<LegClosedLoop>,
}

/// The closed-loop results of a tested joint and model.
#[derive(serde::Serialize)]
struct LegClosedLoop {
    min_kp: MinKp,
    /// RMSE of τ̂_F/kfc against the true friction while tracking at the minimum K_p [Nm].
    closed_loop_tau_f_rmse_nm: Option<f64>,
    tracking_rmse_at_min_kp_rad: Option<f64>,
    disturbance_kp: f64,
    disturbance_rmse_rad: f64,
}

impl From<&LegCell> for LegClosedLoop {
    fn from(c: &LegCell) -> Self {
        Self {
            min_kp: c.min_kp,
            closed_loop_tau_f_rmse_nm: c
                .track_at_min_kp
                .and_then(|t| t.friction_estimate_rmse_nm()),
            tracking_rmse_at_min_kp_rad: c.track_at_min_kp.map(|t| t.rmse_rad),
            disturbance_kp: c.disturbance_kp_per_s2,
            disturbance_rmse_rad: c.disturbance.rmse_after_release_rad,
        }
    }
}

/// Runs `frictl demo --robot leg`.
pub(super) fn run(
    args: &Args,
    r: &mut Runner,
    dirs: &Dirs,
    started: Instant,
) -> anyhow::Result<()> {
    let sizes = Sizes::for_args(args);
    let setup = LegSetup::load(&[])?;
    let leg = &setup.params;
    let (train_sets, test_sets): (Vec<String>, Vec<String>) = if args.quick {
        (strings(&SHORT_PROTOCOL), strings(QUICK_TEST))
    } else {
        let starts = if args.full { sizes.n_starts } else { 1 };
        (vec![format!("protocol.n_starts={starts}")], strings(TEST))
    };

    let train = acquire_and_label(r, leg, &setup.robot, &train_sets, args.seed, "train")?;
    let test = acquire_and_label(r, leg, &setup.robot, &test_sets, args.seed + 100, "test")?;
    let samples = [
        train.first().map_or(0, |l| l.full_state.len()),
        test.first().map_or(0, |l| l.full_state.len()),
    ];

    let mut files = fit_and_train(r, args, &sizes, dirs, leg, [&train, &test])?;
    let rounds = if args.no_experiments {
        0
    } else {
        args.onpolicy_rounds.unwrap_or(sizes.onpolicy_rounds)
    };
    let mut onpolicy = Vec::with_capacity(rounds as usize);
    for k in 1..=rounds {
        onpolicy.push(onpolicy_round(
            r, args, &sizes, dirs, &setup, &mut files, k,
        )?);
    }

    let (mut joints, eval_md) = evaluate_joints(r, dirs, leg, &files, &train)?;

    let configs = write_daemon_configs(&setup, &files, &dirs.models)?;
    write_robot_file(args, &sizes, &setup, &configs.joints, &files)?;
    let suite = if args.no_experiments {
        None
    } else {
        Some(closed_loop(r, args, &setup, &configs.paths, &mut joints)?)
    };
    if let Some(s) = &suite {
        std::fs::create_dir_all(&dirs.experiments)?;
        frictionless::output_file::write(
            dirs.experiments.join("leg-report.json"),
            serde_json::to_string_pretty(s)?,
        )?;
    }

    let total = started.elapsed().as_secs_f64();
    let report = LegReport {
        format: "frictionless-demo-leg-v1",
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        settings: super::settings_name(args),
        seed: args.seed,
        network: super::Network {
            hidden: sizes.hidden,
            history: sizes.history,
            epochs: sizes.epochs,
            batch: sizes.batch,
        },
        samples,
        joints: &joints,
        closed_loop: suite.as_ref(),
        onpolicy_rounds: &onpolicy,
        stages: &r.stages,
        total_seconds: total,
    };
    let out = &args.out;
    frictionless::output_file::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    let md = report_md(&report, &eval_md, suite.as_ref());
    frictionless::output_file::write(out.join("report.md"), &md)?;
    println!("{md}");
    eprintln!(
        "frictl demo --robot leg: done in {total:.0} s → {}/report.md",
        out.display()
    );
    Ok(())
}

/// Per joint: its two datasets written from the leg's labels, the CV/SCV/LuGre fits and the PINN
/// trained; returns each joint's files, in the leg's joint order.
fn fit_and_train(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    dirs: &Dirs,
    leg: &LegParams,
    [train, test]: [&[LegJointLabels]; 2],
) -> anyhow::Result<Vec<JointFiles>> {
    let mut files = Vec::with_capacity(leg.joints.len());
    for ((p, tr), te) in leg.joints.iter().zip(train).zip(test) {
        let f = JointFiles::new(dirs, &p.joint);
        let t0 = Instant::now();
        for (labels, path, seed) in [
            (tr, &f.train_ds, args.seed),
            (te, &f.test_ds, args.seed + 100),
        ] {
            write_joint_dataset(p, labels, path, seed)?;
        }
        r.stages.push(Stage {
            name: format!("write datasets {}", p.joint),
            seconds: t0.elapsed().as_secs_f64(),
        });
        fit(r, &p.joint, &f)?;
        let a = train_args(
            sizes,
            args.seed,
            &p.joint,
            &[&f.train_ds],
            [&f.scv, &f.fwt, &f.train_report],
            sizes.epochs,
        )?;
        r.stage(&format!("train {}", p.joint), &["train"], &a)?;
        files.push(f);
    }
    Ok(files)
}

/// Per joint: the offline evaluation on the unseen run (a failure is a warning: the closed loop
/// does not need it) and the joint's report entry; returns the entries and the evaluation tables.
fn evaluate_joints(
    r: &mut Runner,
    dirs: &Dirs,
    leg: &LegParams,
    files: &[JointFiles],
    train: &[LegJointLabels],
) -> anyhow::Result<(BTreeMap<String, LegJointEntry>, String)> {
    let mut joints: BTreeMap<String, LegJointEntry> = BTreeMap::new();
    let mut eval_md = String::new();
    for ((p, f), labels) in leg.joints.iter().zip(files).zip(train) {
        let ev: Option<EvalReport> = match evaluate(r, dirs, &p.joint, &p.joint, f) {
            Ok(()) => Some(super::read_typed(&f.eval_json)?),
            Err(e) => {
                eprintln!("warning: {e:#}");
                None
            }
        };
        if let Some(ev) = &ev {
            eval_md += &eval_table(&p.joint, "unseen run", ev);
        }
        let models = EVAL_MODELS
            .iter()
            .map(|(key, label)| {
                let eval = Some(ev.as_ref().and_then(|e| e.models.get(*key)).copied());
                let entry = LegModelEntry {
                    eval,
                    closed_loop: None,
                };
                ((*label).to_owned(), entry)
            })
            .collect();
        joints.insert(
            p.joint.clone(),
            LegJointEntry {
                label_error_nm: LabelError {
                    full_state: labels.error_full_state_nm,
                    single_joint_view: labels.error_single_joint_view_nm,
                    separate_full_state: labels.error_separate_nm.0,
                    separate_single_joint_view: labels.error_separate_nm.1,
                },
                models,
                files: super::JointFilesEntry {
                    cv: s(&f.cv),
                    scv: s(&f.scv),
                    lugre: s(&f.lugre),
                    pinn: s(&f.fwt),
                    eval: s(&f.eval_json),
                },
            },
        );
    }

    Ok((joints, eval_md))
}

/// The closed-loop suite's settings for `models`: the paper's (the knee and the ankle roll, the
/// rest holding), the demo's seed, two trials at once; `--quick`: the faster, smaller sines.
fn suite_config(r: &Runner, args: &Args, models: Vec<LegModel>) -> anyhow::Result<LegSuiteConfig> {
    let bins = match &r.frictiond {
        Some(d) => Binaries {
            frictl: r.exe.clone(),
            frictiond: d.clone(),
        },
        None => Binaries::locate()?,
    };
    let mut cfg = LegSuiteConfig::paper(bins, models);
    cfg.seed = args.seed;
    cfg.jobs = 2;
    if args.quick {
        cfg.joints = LegTestJoint::fast_pair();
        cfg.after_release_s = 1.0;
    }
    Ok(cfg)
}

/// `report.json` `onpolicy_rounds[]`: one on-policy round on the leg.
#[derive(serde::Serialize)]
struct LegRound {
    /// 1 = the first round (its PINNs are the protocol's).
    round: u32,
    /// Tested joint → what the round measured and added.
    joints: BTreeMap<String, LegRoundJoint>,
}

/// `report.json` `onpolicy_rounds[].joints.JOINT`.
#[derive(serde::Serialize)]
struct LegRoundJoint {
    /// The round's PINN (before its data): minimum K_p of the PINN-only search.
    min_kp: Option<MinKp>,
    /// RMSE of τ̂_F/kfc against the true friction while tracking at that K_p [Nm].
    closed_loop_tau_f_rmse_nm: Option<f64>,
    /// Closed-loop runs recorded around that K_p.
    runs: usize,
    /// Valid rows of the recorded runs' dataset.
    valid_rows: usize,
    /// Its label − truth RMS on valid sliding rows [Nm].
    label_error_nm: Option<f64>,
    /// The dataset.
    dataset: String,
}

/// One on-policy round on the leg (DAgger, as the two-joint demo's): the current PINNs' minimum
/// K_p on the knee and the ankle roll, closed-loop runs around it with those PINNs compensating
/// on every joint (the rest of the leg holding), the tested joint's rows labelled from the whole
/// leg's state (`label_config`), added to its datasets, and its training continued from them
/// (`--init`). Replaces the tested joints' `fwt` and `train_report`.
fn onpolicy_round(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    dirs: &Dirs,
    setup: &LegSetup,
    files: &mut [JointFiles],
    k: u32,
) -> anyhow::Result<LegRound> {
    // The round's configs (the final ones replace them once the rounds are done).
    let configs = write_daemon_configs(setup, files, &dirs.models)?;
    let (_, pinn) = configs
        .paths
        .iter()
        .find(|(l, _)| *l == "PINN")
        .context("the PINN config")?;
    let model = LegModel::from_daemon_config("PINN", pinn, setup)?;
    let mut cfg = suite_config(r, args, vec![model])?;
    r.n += 1;
    eprintln!(
        "[{:>2}] on-policy round {k}: min K_p of the round-{} PINNs …",
        r.n,
        k - 1
    );
    let t0 = Instant::now();
    let search = run_leg_suite(&cfg)?;
    let mut plans = vec![];
    let mut cells = vec![];
    for (j, tj) in cfg.joints.iter().enumerate() {
        let cell = search
            .joints
            .get(&tj.name)
            .and_then(|jr| jr.models.get("PINN"))
            .with_context(|| format!("no PINN result on {}", tj.name))?;
        plans.extend(frictionless_experiment::leg::leg_record_plans(
            &cfg,
            j,
            cell.min_kp.kp_for_runs(),
            sizes.onpolicy_runs as usize,
            sizes.periods,
        ));
        cells.push(cell.clone());
    }
    cfg.seed = args.seed + 1000 * u64::from(k);
    let traces = frictionless_experiment::leg::record_leg(&cfg, 0, &plans)?;
    r.stages.push(Stage {
        name: format!("on-policy round {k}: search and record (leg)"),
        seconds: t0.elapsed().as_secs_f64(),
    });
    let whole =
        frictionless_ident::preprocess::WholeBody::new(setup.robot.clone(), BTreeMap::new())?;
    let mut joints = BTreeMap::new();
    for ((j, tj), cell) in cfg.joints.iter().enumerate().zip(&cells) {
        let index = setup.index(&tj.name)?;
        let p = &setup.params.joints[index];
        let runs: Vec<&[frictionless_experiment::run::JointTrace]> = plans
            .iter()
            .zip(&traces)
            .filter(|(plan, _)| plan.joint == j)
            .map(|(_, t)| t.as_slice())
            .collect();
        let (path, ds) = write_onpolicy_dataset(setup, &whole, index, &runs, dirs, k, cfg.seed)?;
        let f = &mut files[index];
        f.datasets.push(path.clone());
        super::onpolicy::continue_training(r, args, sizes, dirs, f, &p.joint, &p.joint, k)?;
        joints.insert(
            tj.name.clone(),
            LegRoundJoint {
                min_kp: Some(cell.min_kp),
                closed_loop_tau_f_rmse_nm: cell
                    .track_at_min_kp
                    .and_then(|t| t.friction_estimate_rmse_nm()),
                runs: runs.len(),
                valid_rows: ds.valid.iter().filter(|v| **v).count(),
                label_error_nm: frictionless_acquire::leg::label_error_rms_nm(&ds),
                dataset: s(&path),
            },
        );
    }
    Ok(LegRound { round: k, joints })
}

/// Labels the on-policy closed-loop runs `runs` of payload joint `index` (round `k`, recorded with
/// `seed`) with the whole leg's state and writes them as a dataset; returns its path and the
/// dataset.
fn write_onpolicy_dataset(
    setup: &LegSetup,
    whole: &frictionless_ident::preprocess::WholeBody,
    index: usize,
    runs: &[&[frictionless_experiment::run::JointTrace]],
    dirs: &Dirs,
    k: u32,
    seed: u64,
) -> anyhow::Result<(PathBuf, frictionless_dataset::Dataset)> {
    let p = &setup.params.joints[index];
    let names: Vec<String> = setup
        .params
        .joints
        .iter()
        .map(|p| p.joint.clone())
        .collect();
    let (log, state) = traces_log(runs, index, &names)?;
    let mut meta = frictionless_acquire::log_meta(p);
    meta.plant_link = None;
    let cfg_label = label_config(p);
    let (ds, summary) = frictionless_ident::preprocess::preprocess_whole_body(
        &log, &meta, whole, &state, &cfg_label,
    )
    .with_context(|| format!("labelling the on-policy runs of {}", p.joint))?;
    let path = dirs.data.join(format!("{}_onpolicy{k}_ds.csv", p.joint));
    write_dataset(
        &path,
        &ds,
        &summary,
        &Provenance {
            input_log: format!(
                "frictl demo --robot leg: on-policy round {k}, {} closed-loop runs, seed {}",
                runs.len(),
                seed
            ),
            input_sha256: String::new(),
            meta: &meta,
            fs_hz: cfg_label.fs_hz,
            settings: serde_json::to_value(&cfg_label)?,
            dynamics: format!(
                "URDF {} (nominal leg), the whole leg's logged state, fixed base",
                frictionless_sim::leg::ERGOCUB_URDF_PATH
            ),
        },
    )?;
    Ok((path, ds))
}

/// Seconds between the runs of an on-policy log (a chunk each).
const RUN_GAP_S: f64 = 5.0;

/// The acquisition log of payload joint `index` over `runs` (each every leg joint's trace of one
/// closed-loop run; a chunk per run, [`RUN_GAP_S`] apart, split where a disturbance pulse acts,
/// whose rows are left out as in the two-joint rounds) and the whole leg's positions on its clock
/// (`names` in payload order).
fn traces_log(
    runs: &[&[frictionless_experiment::run::JointTrace]],
    index: usize,
    names: &[String],
) -> anyhow::Result<(
    frictionless_ident::preprocess::RawLog,
    frictionless_ident::preprocess::JointStates,
)> {
    let mut log = frictionless_ident::preprocess::RawLog {
        tau_f_true_nm: Some(vec![]),
        phi_ddot_rad_s2: Some(vec![]),
        ..Default::default()
    };
    let mut q: Vec<Vec<f64>> = vec![vec![]; names.len()];
    let mut t0 = 0.0;
    let mut chunk = 0u32;
    for run in runs {
        let tr = run
            .iter()
            .find(|t| t.index == index)
            .with_context(|| format!("an on-policy run without joint {index}"))?;
        let n = tr.t_s.len();
        let at = |v: &[f64], k: usize| v.get(k).copied().unwrap_or(f64::NAN);
        // The rows near a disturbance pulse are left out (the label would count the external
        // torque as friction); a chunk ends there.
        let keep = frictionless_experiment::onpolicy::unlabelled_mask(&tr.tau_ext_nm, n);
        let mut kept = vec![];
        for (k, &keep_k) in keep.iter().enumerate() {
            if !keep_k {
                if kept.last().is_some_and(|&last: &usize| last + 1 == k) {
                    chunk += 1;
                }
                continue;
            }
            kept.push(k);
            log.time_s.push(t0 + tr.t_s[k]);
            log.chunk.push(chunk);
            log.active.push(true);
            log.s_rad.push(tr.s_rad[k]);
            log.theta_motor_rad.push(at(&tr.theta_motor_rad, k));
            log.omega_motor_rad_s.push(at(&tr.omega_motor_rad_s, k));
            log.i_meas_a.push(at(&tr.i_meas_a, k));
            log.temperature_c.push(at(&tr.temperature_c, k));
            if let Some(t) = &mut log.tau_f_true_nm {
                t.push(at(&tr.tau_f_true_nm, k));
            }
            if let Some(a) = &mut log.phi_ddot_rad_s2 {
                a.push(at(&tr.phi_ddot_rad_s2, k));
            }
        }
        for (i, qi) in q.iter_mut().enumerate() {
            let other = run
                .iter()
                .find(|t| t.index == i)
                .with_context(|| format!("an on-policy run without joint {i}"))?;
            anyhow::ensure!(
                other.s_rad.len() == n,
                "on-policy run: joints {index} and {i} have {n} and {} rows",
                other.s_rad.len()
            );
            qi.extend(kept.iter().map(|&k| other.s_rad[k]));
        }
        chunk += 1;
        t0 += tr.t_s.last().copied().unwrap_or(0.0) + RUN_GAP_S;
    }
    let state = frictionless_ident::preprocess::JointStates {
        names: names.to_vec(),
        q,
        qdot: vec![None; names.len()],
        qddot: vec![None; names.len()],
        base_quat_xyzw: None,
        base_frame: None,
        wrenches: Vec::new(),
    };
    Ok((log, state))
}

fn strings(sets: &[&str]) -> Vec<String> {
    sets.iter().map(|s| (*s).to_owned()).collect()
}

/// One simultaneous acquisition of the leg (`sets` on every joint's protocol, plant `seed`),
/// labelled from both views; one stage record each.
fn acquire_and_label(
    r: &mut Runner,
    leg: &LegParams,
    robot: &frictionless_dynamics::Robot,
    sets: &[String],
    seed: u64,
    what: &str,
) -> anyhow::Result<Vec<LegJointLabels>> {
    r.n += 1;
    eprintln!("[{:>2}] acquire leg ({what}, seed {seed}) …", r.n);
    let t0 = Instant::now();
    let protocols = leg_protocols(leg, sets)?;
    let (rows, _) = run_leg_offline_rows(leg, &protocols, seed)?;
    let secs = t0.elapsed().as_secs_f64();
    eprintln!(
        "     {} samples per joint in {secs:.1} s",
        rows.first().map_or(0, Vec::len)
    );
    r.stages.push(Stage {
        name: format!("acquire leg ({what})"),
        seconds: secs,
    });
    r.n += 1;
    eprintln!(
        "[{:>2}] label leg ({what}): whole state and single-joint view …",
        r.n
    );
    let t0 = Instant::now();
    let labels =
        label_leg(leg, robot, &rows).with_context(|| format!("labelling the leg's {what} run"))?;
    drop(rows);
    for l in &labels {
        eprintln!(
            "     {:<14} label error {} Nm (whole state), {} Nm (single-joint view); separate filters: {} / {} Nm",
            l.joint,
            opt(l.error_full_state_nm),
            opt(l.error_single_joint_view_nm),
            opt(l.error_separate_nm.0),
            opt(l.error_separate_nm.1)
        );
    }
    r.stages.push(Stage {
        name: format!("label leg ({what})"),
        seconds: t0.elapsed().as_secs_f64(),
    });
    Ok(labels)
}

fn opt(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| format!("{x:.3}"))
}

/// Writes joint `p`'s whole-state dataset of one run and its sidecar.
fn write_joint_dataset(
    p: &frictionless_sim::PlantParams,
    labels: &LegJointLabels,
    path: &Path,
    seed: u64,
) -> anyhow::Result<()> {
    let cfg = label_config(p);
    let meta = frictionless_acquire::log_meta(p);
    write_dataset(
        path,
        &labels.full_state,
        &labels.summary,
        &Provenance {
            input_log: format!(
                "frictl demo --robot leg: simultaneous leg acquisition, seed {seed}"
            ),
            input_sha256: String::new(),
            meta: &meta,
            fs_hz: cfg.fs_hz,
            settings: serde_json::to_value(&cfg)?,
            dynamics: format!(
                "URDF {} (nominal leg), the whole leg's logged state, fixed base",
                frictionless_sim::leg::ERGOCUB_URDF_PATH
            ),
        },
    )?;
    Ok(())
}

/// A joint's model in one of the configs, from its files.
type ModelOf = fn(&JointFiles) -> anyhow::Result<FrictionModel>;

/// The configs [`write_daemon_configs`] wrote.
struct DaemonConfigs {
    /// (label, path) of the PINN's (`frictiond.toml`), the SCV's and the CV's.
    paths: Vec<(&'static str, PathBuf)>,
    /// The PINN config's joints.
    joints: Vec<frictiond_config::JointConfig>,
}

/// The six-joint frictiond configs: the PINN's (`frictiond.toml`), the SCV's and the CV's. Each
/// joint gets the shipped law of its drive (`daemon_joint`), its fitted model and, for the PINN,
/// the Δθ offset its training latched; model paths are relative to `models`.
fn write_daemon_configs(
    setup: &LegSetup,
    files: &[JointFiles],
    models: &Path,
) -> anyhow::Result<DaemonConfigs> {
    let kinds: [(&str, &str, ModelOf); 3] = [
        ("PINN", "frictiond.toml", |f| {
            Ok(FrictionModel::Pinn(f.fwt.clone()))
        }),
        ("SCV", "frictiond_scv.toml", |f| {
            Ok(FrictionModel::Scv(FittedModel::read_scv(&f.scv)?))
        }),
        ("CV", "frictiond_cv.toml", |f| {
            Ok(FrictionModel::Cv(FittedModel::read_cv(&f.cv)?))
        }),
    ];
    let mut out = vec![];
    let mut pinn_joints = vec![];
    for (label, name, model) in kinds {
        let mut joints = vec![];
        for (index, (p, f)) in setup.params.joints.iter().zip(files).enumerate() {
            let offset = if label == "PINN" {
                let report: frictionless_train::pipeline::TrainReport =
                    super::read_typed(&f.train_report)?;
                report
                    .deployed_offset_rad()
                    .map_err(|e| anyhow::anyhow!("{}: {e}", s(&f.train_report)))?
            } else {
                None
            };
            let mut j = daemon_joint(
                &DaemonJoint {
                    name: p.joint.clone(),
                    index,
                    gear_ratio: p.gear_ratio_signed,
                    kt_nm_per_a: p.kt_nm_per_a,
                    model: model(f)?,
                    delta_theta_offset_motor_rad: offset,
                    kfc: None,
                    lpf: None,
                },
                false,
            )?;
            // Beside the config: the directory moves as a whole.
            if let Some(m) = &mut j.model {
                *m = PathBuf::from(m.file_name().context("a PINN file name")?);
            }
            joints.push(j);
        }
        let cfg = frictiond_config::RawConfig::shm(joints);
        if label == "PINN" {
            pinn_joints = cfg.joint.clone();
        }
        let path = models.join(name);
        frictionless::output_file::write(
            &path,
            format!(
                "# The coupled ergoCub left leg, {label} on every joint (frictl demo --robot leg).\n{}",
                toml::to_string(&cfg)?
            ),
        )?;
        // Read back as frictiond would (model files, their inputs against each joint).
        frictiond_config::load(&path)
            .with_context(|| format!("{} as frictiond reads it", path.display()))?;
        out.push((label, path));
    }
    Ok(DaemonConfigs {
        paths: out,
        joints: pinn_joints,
    })
}

/// `robot.toml` beside the report: the six leg joints for `frictl robot run` (and the Ray driver),
/// each on the demo's whole-state datasets (paths relative to the file) with its drive's constants,
/// the PINN's feature set, the law of `joints` (the PINN config's), and the demo's network trained
/// once (`[search] trials = 0`).
fn write_robot_file(
    args: &Args,
    sizes: &Sizes,
    setup: &LegSetup,
    joints: &[frictiond_config::JointConfig],
    files: &[JointFiles],
) -> anyhow::Result<()> {
    use crate::robot::{
        JointSection, LpfSection, RobotFile, RobotSection, SearchSection, TrainSection,
    };
    let rel = |p: &Path| -> anyhow::Result<PathBuf> {
        Ok(p.strip_prefix(&args.out)
            .with_context(|| format!("{} is not under {}", p.display(), args.out.display()))?
            .to_path_buf())
    };
    let mut joint = Vec::with_capacity(joints.len());
    for ((p, j), f) in setup.params.joints.iter().zip(joints).zip(files) {
        joint.push(JointSection {
            name: p.joint.clone(),
            preset: None,
            logs: vec![],
            test_logs: vec![],
            datasets: vec![rel(&f.train_ds)?],
            test_datasets: vec![rel(&f.test_ds)?],
            gear_ratio: p.gear_ratio_signed,
            kt_nm_per_a: p.kt_nm_per_a,
            features: super::feature_set(&p.joint),
            temperature: false,
            motor_encoder: frictiond_config::MotorEncoder::Absolute,
            max_curr_a: j.max_curr,
            kfc: j.kfc,
            max_output_friction_nm: j
                .max_output_friction
                .is_finite()
                .then_some(j.max_output_friction),
            lpf: j.lpf.map(|l| LpfSection {
                order: l.order,
                cutoff_hz: l.cutoff_hz,
            }),
            preprocess_args: vec![],
            import: None,
        });
    }
    let robot = RobotFile {
        robot: RobotSection {
            name: "ergoCub left leg (frictl demo --robot leg)".into(),
            seed: args.seed,
            ..RobotSection::default()
        },
        acquire: Default::default(),
        import: None,
        search: SearchSection {
            trials: 0,
            ..SearchSection::default()
        },
        train: TrainSection {
            hidden: super::hidden_widths(sizes.hidden)?,
            history: sizes.history as usize,
            epochs: sizes.epochs as usize,
            batch: sizes.batch as usize,
            ..TrainSection::default()
        },
        joint,
    };
    let path = args.out.join("robot.toml");
    let text = format!(
        "# The coupled ergoCub left leg on the datasets of `frictl demo --robot leg`:\n# frictl robot run robot.toml --out robot-out\n{}",
        toml::to_string(&robot)?
    );
    // Read back as `frictl robot` reads it.
    crate::robot::parse(&path, &text)?;
    frictionless::output_file::write(&path, text)?;
    Ok(())
}

/// The closed-loop suite on the knee and the ankle roll: none, the configs' CV / SCV / PINN, the
/// oracle. Adds each tested joint's results to `joints`.
fn closed_loop(
    r: &mut Runner,
    args: &Args,
    setup: &LegSetup,
    configs: &[(&'static str, PathBuf)],
    joints: &mut BTreeMap<String, LegJointEntry>,
) -> anyhow::Result<frictionless_experiment::leg::LegSuiteReport> {
    let n = setup.dof();
    let mut models = vec![LegModel::uniform(FrictionModel::None, n)];
    for label in ["CV", "SCV", "PINN"] {
        let (_, path) = configs
            .iter()
            .find(|(l, _)| *l == label)
            .context("a config per model")?;
        models.push(LegModel::from_daemon_config(label, path, setup)?);
    }
    models.push(LegModel::uniform(FrictionModel::Oracle, n));
    let cfg = suite_config(r, args, models)?;
    r.n += 1;
    eprintln!(
        "[{:>2}] closed loop on the leg: {} models × {} tested joints …",
        r.n,
        cfg.models.len(),
        cfg.joints.len()
    );
    let t0 = Instant::now();
    let report = run_leg_suite(&cfg)?;
    let secs = t0.elapsed().as_secs_f64();
    eprintln!("     {} trials in {secs:.1} s", report.trials);
    r.stages.push(Stage {
        name: "closed loop (leg)".into(),
        seconds: secs,
    });
    for (joint, jr) in &report.joints {
        let Some(entry) = joints.get_mut(joint) else {
            continue;
        };
        for (label, cell) in &jr.models {
            entry.models.entry(label.clone()).or_default().closed_loop =
                Some(LegClosedLoop::from(cell));
        }
    }
    debug_assert!(
        report
            .joints
            .values()
            .all(|j| j.models.contains_key(ORACLE_LABEL))
    );
    Ok(report)
}

/// `report.md`: the label errors, each joint's offline table and the closed-loop table.
fn report_md(
    report: &LegReport<'_>,
    eval_md: &str,
    suite: Option<&frictionless_experiment::leg::LegSuiteReport>,
) -> String {
    let mut md = format!(
        "# frictl demo --robot leg ({} settings, seed {})\n\nThe coupled ergoCub left leg, every joint excited at once ({} samples per joint for training, {} in the unseen run); network {} H {}, {} epochs. Total {:.0} s.\n\n",
        report.settings,
        report.seed,
        report.samples[0],
        report.samples[1],
        report.network.hidden,
        report.network.history,
        report.network.epochs,
        report.total_seconds
    );
    md += "**Label error against the plant's truth [Nm RMS]** (training run, valid sliding rows; the models train on the first two columns' labels: matched, with the wave generator's ripple; the last two are the authors' separate filters)\n\n| joint | whole state | single-joint view | separate, whole state | separate, single-joint view |\n|---|---|---|---|---|\n";
    for (joint, e) in report.joints {
        let l = &e.label_error_nm;
        md += &format!(
            "| {joint} | {} | {} | {} | {} |\n",
            opt(l.full_state),
            opt(l.single_joint_view),
            opt(l.separate_full_state),
            opt(l.separate_single_joint_view)
        );
    }
    md += "\n**Offline: friction RMSE against the truth on the unseen run [Nm]**\n\n| joint | none | CV | SCV | LuGre | PINN |\n|---|---|---|---|---|---|\n";
    for (joint, e) in report.joints {
        let cell = |label: &str| {
            opt(e
                .models
                .get(label)
                .and_then(|m| m.eval.flatten())
                .and_then(|m| m.rmse_true_all))
        };
        md += &format!(
            "| {joint} | {} | {} | {} | {} | {} |\n",
            cell("none"),
            cell("CV"),
            cell("SCV"),
            cell("LuGre"),
            cell("PINN")
        );
    }
    md += eval_md;
    if let Some(s) = suite {
        md += "\n## Closed loop\n\n";
        md += &s.markdown();
    }
    if !report.onpolicy_rounds.is_empty() {
        md += "\n## On-policy rounds (DAgger)\n\nEach round searches the current PINNs' minimum K_p, records closed-loop runs around it with them compensating (the rest of the leg holding), labels the tested joint's rows from the whole leg's state and continues its training on the union; the closed-loop table above is the last round's PINNs'.\n\n| round | joint | min K_p before [1/s²] | closed-loop τ̂_F error before [Nm] | runs | valid rows | label error [Nm] |\n|---|---|---|---|---|---|---|\n";
        for round in report.onpolicy_rounds {
            for (joint, j) in &round.joints {
                md += &format!(
                    "| {} | {joint} | {} | {} | {} | {} | {} |\n",
                    round.round,
                    j.min_kp.map_or("–".into(), |m| m.display()),
                    opt(j.closed_loop_tau_f_rmse_nm),
                    j.runs,
                    j.valid_rows,
                    opt(j.label_error_nm)
                );
            }
        }
    }
    md
}
