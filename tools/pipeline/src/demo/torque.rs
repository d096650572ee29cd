//! `frictl demo --sensor torque`: the method on a torque-sensed arm's logs, every stage through the
//! CLI, evaluated on a held-out run.
//!
//! The virtual knee logged as a torque-sensed arm would (`frictl acquire --sensor torque`: q, dq,
//! current and a joint torque sensor, no motor encoder, a 500 Hz log with jittered timestamps) at three
//! speeds, one file each (`slow`, `mid`, `fast`: closed-loop sine tracking at increasing frequencies) →
//! `frictl import csv` of the three files into one dataset with three runs, label `torque-sensor`
//! (r·k_t·i − τ_joint: no link model), and again with label `given` from the simulator's true friction
//! (for scoring against the truth) → `frictl fit cv|scv` on the slow and fast runs → `frictl train
//! --features joint-pos-joint-vel --test-run mid` (the feature set that needs no motor encoder) →
//! `frictl eval --test-run mid` on both datasets: RMSE per run and per |ṡ| band, with the training
//! range of the slow and fast runs.
//!
//! Writes to `--out`: `report.json` (format `frictionless-demo-torque-v1`, keys below), `report.md`,
//! `data/`, `models/`, `eval/` (both eval reports and figures) and `logs/`.
//!
//! ```text
//! format, producer, settings ("quick" | "default" | "full"), seed, joint, features, held_out_run,
//! training_runs[], network {hidden, history, epochs, batch}, runs {NAME: {file, peak_abs_sdot_rad_s}},
//! held_out {label: {MODEL: RunMetrics}, truth: {MODEL: RunMetrics}, extrapolated_share},
//! stages[] {name, seconds}, total_seconds
//! ```
//!
//! What it is not: the closed-loop experiments (they need a model frictiond runs on the motor-encoder
//! joint; the default `frictl demo` does those).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use frictionless_eval::Report as EvalReport;
use frictionless_eval::runs::RunMetrics;

use frictionless::features::FeatureSet;
use frictionless::model::ModelKind;

use super::{Args, Runner, Stage, read_json, read_typed, s, settings_name};
use crate::{Host, ImportCsv, ImportLabel};
use frictl_cli::{acquire, eval, fit, stage, train};

/// The preset logged as a torque-sensed joint.
const PRESET: &str = "knee";
/// Tracking centre, amplitudes and the frequencies of each speed run (peak |ṡ| = A·2πf).
const SPEEDS: [(&str, &str); 3] = [
    ("slow", "[0.1, 0.15]"),
    ("mid", "[0.25, 0.35]"),
    ("fast", "[0.5, 0.7]"),
];
/// The run held out for testing: the middle speed (inside the range of the other two).
const HELD_OUT: &str = "mid";
/// The feature set: joint position and velocity history (no motor encoder on this joint).
const FEATURES: FeatureSet = FeatureSet::JointPosJointVel;

/// Sizes of one flavour.
struct Sizes {
    amplitudes: &'static str,
    cycles: f64,
    hidden: &'static str,
    history: u32,
    epochs: u32,
    batch: u32,
}

impl Sizes {
    fn for_args(args: &Args) -> Self {
        if args.quick {
            Self {
                amplitudes: "[0.3]",
                cycles: 1.0,
                hidden: "16,16",
                history: 10,
                epochs: 2,
                batch: 2048,
            }
        } else if args.full {
            Self {
                amplitudes: "[0.2, 0.4, 0.6]",
                cycles: 3.0,
                hidden: "268,215",
                history: 20,
                epochs: 100,
                batch: 4316,
            }
        } else {
            Self {
                amplitudes: "[0.2, 0.4, 0.6]",
                cycles: 3.0,
                hidden: "128,128",
                history: 30,
                epochs: 10,
                batch: 512,
            }
        }
    }
}

/// `report.json`.
#[derive(serde::Serialize)]
struct TorqueReport<'a> {
    format: &'static str,
    producer: String,
    settings: &'static str,
    seed: u64,
    joint: String,
    features: &'static str,
    held_out_run: &'static str,
    training_runs: Vec<&'static str>,
    network: super::Network,
    runs: BTreeMap<String, RunEntry>,
    held_out: HeldOut,
    stages: &'a [Stage],
    total_seconds: f64,
}

/// `report.json` `runs.NAME`.
#[derive(serde::Serialize)]
struct RunEntry {
    file: String,
    peak_abs_sdot_rad_s: f64,
}

/// `report.json` `held_out`: the held-out run's numbers per model.
#[derive(serde::Serialize)]
struct HeldOut {
    label: BTreeMap<String, RunMetrics>,
    truth: BTreeMap<String, RunMetrics>,
    extrapolated_share: Option<f64>,
}

/// The 99.5 % quantile of |dq| of an arm log (the speed of the run, robust to single spikes).
fn peak_abs_dq(csv: &Path) -> anyhow::Result<f64> {
    let cols = frictionless_dataset::read_columns(csv)?;
    let dq = cols
        .get("dq_rad_s")
        .with_context(|| format!("{}: no dq_rad_s column", csv.display()))?;
    let mut v: Vec<f64> = dq
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.abs())
        .collect();
    v.sort_by(f64::total_cmp);
    Ok(v.get((v.len() as f64 * 0.995) as usize)
        .copied()
        .unwrap_or(0.0))
}

/// The held-out run's entry of an eval report.
fn held_out_models(ev: &EvalReport) -> anyhow::Result<(BTreeMap<String, RunMetrics>, Option<f64>)> {
    let run = ev
        .per_run
        .iter()
        .find(|r| r.run == HELD_OUT)
        .context("the eval report has no entry for the held-out run")?;
    Ok((run.models.clone(), run.extrapolated_share))
}

/// Runs `frictl demo --sensor torque`.
pub fn run(args: &Args, host: &dyn Host) -> anyhow::Result<()> {
    super::install_signal_flag()?;
    let started = Instant::now();
    let sizes = Sizes::for_args(args);
    let out = &args.out;
    let dirs = Dirs {
        data: out.join("data"),
        models: out.join("models"),
        eval: out.join("eval"),
    };
    let logs = out.join("logs");
    for d in [&dirs.data, &dirs.models, &dirs.eval, &logs] {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    let mut r = Runner {
        exe: host.frictl()?,
        frictiond: None,
        logs,
        stages: vec![],
        n: 0,
    };
    eprintln!(
        "frictl demo --sensor torque → {} ({} settings; logs in {}/logs)",
        out.display(),
        settings_name(args),
        out.display()
    );
    let (logs_csv, runs) = acquire_runs(&mut r, args, &sizes, &dirs.data)?;
    let facts = joint_facts(&logs_csv[0])?;
    let [ds, ds_truth] = import_labels(&mut r, host, &logs_csv, &facts, &dirs.data)?;
    let [cv, scv] = fit_static(&mut r, &ds, &dirs.models)?;
    let [fwt, train_report] = train_pinn(&mut r, args, &sizes, &ds, &scv, &dirs.models)?;
    let ((label, extrapolated_share), truth) = evaluate_held_out(
        &mut r,
        [&ds, &ds_truth],
        [&cv, &scv, &fwt, &train_report],
        &dirs.eval,
    )?;
    let total = started.elapsed().as_secs_f64();
    let report = TorqueReport {
        format: "frictionless-demo-torque-v1",
        producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
        settings: settings_name(args),
        seed: args.seed,
        joint: facts.joint,
        features: FEATURES.name(),
        held_out_run: HELD_OUT,
        training_runs: SPEEDS
            .iter()
            .map(|(n, _)| *n)
            .filter(|n| *n != HELD_OUT)
            .collect(),
        network: super::Network {
            hidden: sizes.hidden,
            history: sizes.history,
            epochs: sizes.epochs,
            batch: sizes.batch,
        },
        runs,
        held_out: HeldOut {
            label,
            truth,
            extrapolated_share,
        },
        stages: &r.stages,
        total_seconds: total,
    };
    frictionless::output_file::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    let md = report_md(&report);
    frictionless::output_file::write(out.join("report.md"), &md)?;
    println!("{md}");
    eprintln!(
        "frictl demo --sensor torque: done in {total:.0} s → {}/report.md",
        out.display()
    );
    Ok(())
}

/// The demo's directories.
struct Dirs {
    data: PathBuf,
    models: PathBuf,
    eval: PathBuf,
}

/// The joint's facts from the acquisition sidecar (what a user reads off the robot's datasheet).
struct JointFacts {
    joint: String,
    r_signed: f64,
    kt_nm_per_a: f64,
}

/// Stage 1, acquire: one torque-sensed log per speed; returns the logs and their peak speeds.
fn acquire_runs(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    data: &Path,
) -> anyhow::Result<(Vec<PathBuf>, BTreeMap<String, RunEntry>)> {
    let mut logs_csv: Vec<PathBuf> = Vec::new();
    let mut runs = BTreeMap::new();
    for (k, (name, freqs)) in SPEEDS.iter().enumerate() {
        let seed = args.seed + k as u64;
        r.stage(
            &format!("acquire {PRESET} torque-sensed ({name}, seed {seed})"),
            &["acquire"],
            &acquire::Args {
                preset: PRESET.into(),
                seed,
                out: data.to_owned(),
                name: Some((*name).into()),
                sensor: acquire::Sensor::Torque,
                log_period_ms: 2.0,
                jitter_ms: 0.2,
                sets: vec![
                    "protocol.n_starts=1".into(),
                    // start at the tracking centre: no fast re-centring move in the log
                    "plant.initial_s_rad=-0.8".into(),
                    "protocol.sines.enabled=false".into(),
                    "protocol.ramps.enabled=false".into(),
                    "protocol.steps.enabled=false".into(),
                    format!(
                        "protocol.tracking.train.amplitudes_rad={}",
                        sizes.amplitudes
                    ),
                    format!("protocol.tracking.train.frequencies_hz={freqs}"),
                    format!("protocol.tracking.train.cycles={}", sizes.cycles),
                ],
                ..stage::defaults()?
            },
        )?;
        let csv = data.join(format!("{name}.csv"));
        runs.insert(
            (*name).to_owned(),
            RunEntry {
                file: s(&csv),
                peak_abs_sdot_rad_s: peak_abs_dq(&csv)?,
            },
        );
        logs_csv.push(csv);
    }
    Ok((logs_csv, runs))
}

/// The joint's name, signed gear ratio and k_t from the sidecar of the acquisition log `log`.
fn joint_facts(log: &Path) -> anyhow::Result<JointFacts> {
    let side = read_json(&log.with_extension("json"))?;
    let joint = side["joint"].as_str().unwrap_or_default().to_owned();
    let r_signed = side["gear_ratio_signed"]
        .as_f64()
        .context("acquisition sidecar: gear_ratio_signed")?;
    let kt = side["kt_nm_per_a"]
        .as_f64()
        .context("acquisition sidecar: kt_nm_per_a")?;

    Ok(JointFacts {
        joint,
        r_signed,
        kt_nm_per_a: kt,
    })
}

/// Stage 2, import: the torque-sensor label, and the truth as a `given` label for scoring; returns both
/// datasets.
fn import_labels(
    r: &mut Runner,
    host: &dyn Host,
    logs_csv: &[PathBuf],
    facts: &JointFacts,
    data: &Path,
) -> anyhow::Result<[PathBuf; 2]> {
    let ds = data.join("arm.csv");
    let ds_truth = data.join("arm_truth.csv");
    for (dst, label, truth_column) in [
        (&ds, ImportLabel::TorqueSensor, None),
        (&ds_truth, ImportLabel::Given, Some("tau_f=tau_f_true_nm")),
    ] {
        let mut columns: Vec<String> = [
            "time=time_s",
            "s=q_rad",
            "sdot=dq_rad_s",
            "current=current_a",
            "tau_joint=tau_joint_nm",
        ]
        .map(String::from)
        .into();
        columns.extend(truth_column.map(String::from));
        let argv = host.import_csv_argv(&ImportCsv {
            files: logs_csv,
            joint: &facts.joint,
            columns: &columns,
            out: dst,
            label,
            gear_ratio_signed: facts.r_signed,
            kt_nm_per_a: facts.kt_nm_per_a,
        })?;
        r.frictl(
            &format!(
                "import csv ({} label)",
                match label {
                    ImportLabel::TorqueSensor => "torque-sensor",
                    ImportLabel::Given => "given",
                }
            ),
            &argv,
        )?;
    }

    Ok([ds, ds_truth])
}

/// Stage 3, fit CV and SCV on the training runs; returns their files.
fn fit_static(r: &mut Runner, ds: &Path, models: &Path) -> anyhow::Result<[PathBuf; 2]> {
    let cv = models.join("cv.json");
    let scv = models.join("scv.json");
    for (m, f) in [(ModelKind::Cv, &cv), (ModelKind::Scv, &scv)] {
        r.stage(
            &format!("fit {} (training runs)", m.name()),
            &["fit"],
            &fit::Args {
                model: fit::FitModel(m),
                dataset: ds.to_owned(),
                test_runs: vec![HELD_OUT.into()],
                json: Some(f.clone()),
                ..stage::defaults()?
            },
        )?;
    }

    Ok([cv, scv])
}

/// Stage 4, train on slow + fast, the middle speed held out (validation would take a whole run: none);
/// returns the model and its train report.
fn train_pinn(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    ds: &Path,
    scv: &Path,
    models: &Path,
) -> anyhow::Result<[PathBuf; 2]> {
    let fwt = models.join("pinn.fwt");
    let train_report = models.join("pinn_train.json");
    let mut train_args = train::Args {
        datasets: vec![ds.to_owned()],
        val_frac: 0.0,
        features: train::Features(FEATURES),
        scv: scv.to_owned(),
        out: fwt.clone(),
        report: Some(train_report.clone()),
        hidden: sizes
            .hidden
            .split(',')
            .map(str::parse)
            .collect::<Result<_, _>>()
            .context("the demo's hidden widths")?,
        history: sizes.history as usize,
        epochs: sizes.epochs as usize,
        batch: sizes.batch as usize,
        seed: args.seed,
        ..stage::defaults()?
    };
    train_args.held_out.test_runs = vec![HELD_OUT.into()];
    r.stage("train (held-out run: mid)", &["train"], &train_args)?;

    Ok([fwt, train_report])
}

/// The held-out run's metrics per model and its extrapolated share (vs the label), and its metrics
/// vs the truth.
type HeldOutMetrics = (
    (BTreeMap<String, RunMetrics>, Option<f64>),
    BTreeMap<String, RunMetrics>,
);

/// Stage 5, evaluate on the held-out run, against the label and against the truth.
fn evaluate_held_out(
    r: &mut Runner,
    [ds, ds_truth]: [&Path; 2],
    [cv, scv, fwt, train_report]: [&Path; 4],
    eval_dir: &Path,
) -> anyhow::Result<HeldOutMetrics> {
    let mut held = Vec::new();
    for (d, tag) in [(ds, "label"), (ds_truth, "truth")] {
        let json = eval_dir.join(format!("{tag}.json"));
        r.stage(
            &format!("eval held-out run (vs {tag})"),
            &["eval"],
            &eval::Args {
                datasets: vec![d.to_owned()],
                test_runs: vec![HELD_OUT.into()],
                cv: Some(cv.to_owned()),
                scv: Some(scv.to_owned()),
                pinns: vec![fwt.to_owned()],
                train_report: Some(train_report.to_owned()),
                out: Some(eval_dir.join(tag)),
                json: Some(json.clone()),
                ..stage::defaults()?
            },
        )?;
        let ev: EvalReport = read_typed(&json)?;
        held.push(held_out_models(&ev)?);
    }
    let (truth, _) = held.pop().context("two evaluations")?;
    let (label, extrapolated_share) = held.pop().context("two evaluations")?;

    Ok(((label, extrapolated_share), truth))
}

fn report_md(r: &TorqueReport) -> String {
    let f = |v: Option<f64>| v.map_or_else(|| "-".into(), |x| format!("{x:.3}"));
    let mut md = format!(
        "# frictionless demo: a torque-sensed joint\n\nThe virtual {} logged with a joint torque sensor and no motor encoder, three speed runs \
         (peak |ṡ|: {}), label r·k_t·i − τ_joint, PINN [{}] (hidden {}, H {}, {} epochs) trained on {} and tested on the \
         held-out run `{}` ({} settings, seed {}, {:.0} s).\n\n",
        r.joint,
        r.runs
            .iter()
            .map(|(n, e)| format!("{n} {:.2} rad/s", e.peak_abs_sdot_rad_s))
            .collect::<Vec<_>>()
            .join(", "),
        r.features,
        r.network.hidden,
        r.network.history,
        r.network.epochs,
        r.training_runs.join(" + "),
        r.held_out_run,
        r.settings,
        r.seed,
        r.total_seconds
    );
    md += &format!(
        "Friction RMSE on the held-out run [Nm]; {} of its samples lie outside the training runs' range of s and ṡ.\n\n\
         | model | vs label: all | sliding | stick | vs truth: all | sliding | stick |\n|---|---|---|---|---|---|---|\n",
        r.held_out
            .extrapolated_share
            .map_or_else(|| "-".into(), |x| format!("{:.1} %", 100.0 * x))
    );
    for (key, name) in super::EVAL_MODELS {
        let (l, t) = (r.held_out.label.get(key), r.held_out.truth.get(key));
        md += &format!(
            "| {name} | {} | {} | {} | {} | {} | {} |\n",
            f(l.and_then(|m| m.rmse_all)),
            f(l.and_then(|m| m.rmse_sliding)),
            f(l.and_then(|m| m.rmse_stick)),
            f(t.and_then(|m| m.rmse_all)),
            f(t.and_then(|m| m.rmse_sliding)),
            f(t.and_then(|m| m.rmse_stick)),
        );
    }
    md
}
