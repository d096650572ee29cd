//! The whole-log import: every run read into memory, each joint labelled in passes and written
//! with its sidecar; the argument checks and the readers' specs every import shares, and the choice
//! of the streamed import (`crate::stream`) when a window is asked for.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use crate::options::{CommonOptions, CsvOptions, MatOptions, McapOptions};
use anyhow::{Context, bail};
use frictionless_dataset::Dataset;
use frictionless_dataset::LabelSource;
use frictionless_ident::preprocess::{
    Dynamics, JointLabel, PreprocessConfig, RunJoints, SignalsLabel, SignalsSummary, WholeBody,
    preprocess_joints, required_signals,
};
use frictionless_logs::{ImportedRun, Role, csv_log, mcap_log};

use crate::check_outputs;
use crate::shared::{
    Inputs, JOINT, commit_pair, out_path, per_joint, per_joint_values, plausibility,
    state_plausibility,
};
use crate::urdf::{urdf_link, urdf_whole_body};

/// A progress bar on stderr when it is a terminal (hidden otherwise).
fn bar(path: &Path) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(0);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {bytes}/{total_bytes} {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb.set_message(path.display().to_string());
    pb
}

fn read_all(
    files: &[PathBuf],
    mut read: impl FnMut(
        &Path,
        frictionless_logs::Progress,
    ) -> Result<ImportedRun, frictionless_logs::LogsError>,
) -> anyhow::Result<Vec<ImportedRun>> {
    let mut runs = Vec::with_capacity(files.len());
    for f in files {
        let pb = bar(f);
        let mut progress = |done: u64, total: u64| {
            pb.set_length(total);
            pb.set_position(done);
        };
        let run = read(f, &mut progress);
        pb.finish_and_clear();
        runs.push(run?);
    }
    frictionless_logs::unique_run_names(&mut runs);
    Ok(runs)
}

/// The whole-body model when the current label may be asked for (`label` is `current`, or not
/// given and `default_current`), else `None`.
fn whole_body_for(
    common: &CommonOptions,
    default_current: bool,
) -> anyhow::Result<Option<WholeBody>> {
    let current = match common.label {
        Some(l) => l == LabelSource::Current,
        None => default_current,
    };
    if !current {
        return Ok(None);
    }
    let body = urdf_whole_body(
        common.urdf.as_deref(),
        &common.fixed_joints,
        crate::urdf::gravity_m_s2(common.gravity_m_s2),
    )?;
    Ok(Some(body.with_base_frame(common.base_frame.clone())?))
}

fn urdf_names(body: &Option<WholeBody>) -> Option<Vec<String>> {
    body.as_ref()
        .map(|b| b.robot().joint_names().map(str::to_string).collect())
}

/// `--wrench FRAME=SOURCE` texts as `(frame, source)`, each frame checked in the URDF when there is
/// one; `example` is shown when the `=` is missing.
fn frame_pairs(
    texts: &[String],
    body: Option<&WholeBody>,
    example: &str,
) -> anyhow::Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for w in texts {
        let Some((frame, source)) = w.split_once('=') else {
            bail!("--wrench {w:?}: expected FRAME=SOURCE (e.g. {example})");
        };
        if let Some(b) = body {
            b.robot()
                .frame_id(frame.trim())
                .map_err(|e| anyhow::anyhow!("--wrench {w:?}: {e}"))?;
        }
        out.push((frame.trim().to_string(), source.trim().to_string()));
    }
    Ok(out)
}

/// Runs `frictl import csv`.
pub fn run_csv(args: CsvOptions) -> anyhow::Result<()> {
    let mut spec = csv_log::CsvSpec::parse(&args.columns, &args.units, &args.common.negate)?;
    anyhow::ensure!(
        args.delimiter.is_ascii(),
        "--delimiter {:?}: must be one ASCII character",
        args.delimiter
    );
    spec.delimiter = args.delimiter as u8;
    spec.joints = args.joint.clone();
    spec.all_joints = args.common.all_joints;
    check(
        &args.files,
        &args.joint,
        &args.common,
        ("--base-quat", args.base_quat.is_some()),
    )?;
    let body = match &args.positions {
        Some(_) => {
            let reads = |r: Role| spec.columns.iter().any(|c| c.0 == r);
            whole_body_for(&args.common, !reads(Role::TauF) && !reads(Role::TauJoint))?
        }
        None => None,
    };
    if let (Some(positions), Some(names)) = (&args.positions, urdf_names(&body)) {
        let base_quat = match &args.base_quat {
            None => None,
            Some(t) => {
                let v: Vec<String> = t.split(',').map(|c| c.trim().to_string()).collect();
                let q: [String; 4] = v.try_into().map_err(|v: Vec<String>| {
                    anyhow::anyhow!(
                        "--base-quat {t:?}: expected 4 columns X,Y,Z,W, got {}",
                        v.len()
                    )
                })?;
                Some(q)
            }
        };
        let wrenches = frame_pairs(&args.wrenches, body.as_ref(), "l_foot=ft_l_foot_{c}")?;
        spec.state = Some(csv_log::CsvState {
            wrenches,
            positions: positions.clone(),
            velocities: args.velocities.clone(),
            accelerations: args.accelerations.clone(),
            joints: names,
            base_quat,
        });
    }
    anyhow::ensure!(
        !spec.all_joints || spec.state.is_some(),
        "--joints all labels the joints of --positions with the current label: pass --positions TEMPLATE"
    );
    if let Some(w) = args.window_samples {
        return crate::stream::run_csv(&args.files, &spec, &args.common, body.as_ref(), w);
    }
    let runs = read_all(&args.files, |p, pr| csv_log::read(p, &spec, pr))?;
    let units = spec.units.clone();
    finish(
        runs,
        &args.files,
        "csv",
        0.1,
        Some(&units),
        args.common,
        body,
    )
}

/// Runs `frictl import mcap`.
pub fn run_mcap(args: McapOptions) -> anyhow::Result<()> {
    let effort_role = mcap_log::parse_effort(&args.effort)
        .map_err(|e| anyhow::anyhow!("--effort {}: {e}", args.effort))?;
    let negate = args
        .common
        .negate
        .iter()
        .map(|n| Role::parse(n))
        .collect::<Result<Vec<_>, _>>()?;
    check(
        &args.files,
        &args.joint,
        &args.common,
        ("--base-orientation", args.base_orientation.is_some()),
    )?;
    let body = whole_body_for(
        &args.common,
        !matches!(effort_role, Some(Role::TauF | Role::TauJoint)),
    )?;
    let spec = mcap_log::McapSpec {
        topic: args.topic.clone(),
        joints: args.joint.clone(),
        all_joints: args.common.all_joints,
        state_joints: urdf_names(&body),
        effort_role,
        negate,
    };
    anyhow::ensure!(
        !spec.all_joints || spec.state_joints.is_some(),
        "--joints all labels the joints of the whole-body state, which only the current label reads"
    );
    let extra = mcap_log::McapState {
        base_orientation: args.base_orientation.clone(),
        wrenches: frame_pairs(
            &args.wrenches,
            body.as_ref(),
            "l_foot_rear_ft=/l_foot_rear_ft",
        )?,
    };
    if let Some(w) = args.window_samples {
        let default_label = match effort_role {
            Some(Role::TauF) => LabelSource::Given,
            Some(Role::TauJoint) => LabelSource::TorqueSensor,
            _ => LabelSource::Current,
        };
        return crate::stream::run_stream(
            &args.files,
            "mcap",
            default_label,
            &args.common,
            body.as_ref(),
            None,
            w,
            |f, stream| mcap_log::read_streamed(f, &spec, &extra, &mut |_, _| {}, stream),
        );
    }
    let runs = read_all(&args.files, |p, pr| {
        mcap_log::read_state(p, &spec, &extra, pr)
    })?;
    finish(runs, &args.files, "mcap", 0.1, None, args.common, body)
}

/// Runs `frictl import mat`.
#[cfg(feature = "mat")]
pub fn run_mat(args: MatOptions) -> anyhow::Result<()> {
    use frictionless_logs::mat_log;
    let negate = args
        .common
        .negate
        .iter()
        .map(|n| Role::parse(n))
        .collect::<Result<Vec<_>, _>>()?;
    check(
        &args.files,
        &args.joint,
        &args.common,
        ("--base-orientation", args.base_orientation.is_some()),
    )?;
    let body = whole_body_for(&args.common, true)?;
    let spec = mat_log::MatSpec {
        joints: args.joint.clone(),
        all_joints: args.common.all_joints,
        state_joints: urdf_names(&body),
        negate,
        desired_gap_s: args.common.gap_s.unwrap_or(1.0),
    };
    let extra = mat_log::MatState {
        base_orientation: args.base_orientation.clone(),
        logged_derivatives: args.logged_derivatives,
        wrenches: frame_pairs(
            &args.wrenches,
            body.as_ref(),
            "l_foot_rear_ft=FTs/l_foot_rear_ft",
        )?,
    };
    anyhow::ensure!(
        !spec.all_joints || spec.state_joints.is_some(),
        "--joints all labels the joints of the whole-body state, which only the current label reads"
    );
    if let Some(w) = args.window_samples {
        let mut common = args.common;
        common.gap_s = Some(spec.desired_gap_s);
        return crate::stream::run_stream(
            &args.files,
            "mat",
            LabelSource::Current,
            &common,
            body.as_ref(),
            None,
            w,
            |f, stream| mat_log::read_streamed(f, &spec, &extra, &mut |_, _| {}, stream),
        );
    }
    let runs = read_all(&args.files, |p, pr| {
        mat_log::read_state(p, &spec, &extra, pr)
    })?;
    finish(runs, &args.files, "mat", 1.0, None, args.common, body)
}

/// Runs `frictl import mat` (built without the `mat` feature: explains how to get it).
#[cfg(not(feature = "mat"))]
pub fn run_mat(args: MatOptions) -> anyhow::Result<()> {
    let _ = args;
    bail!(
        "this frictl was built without `.mat` support (cargo feature `mat`, which needs the system HDF5 \
         library): install it with `apt install libhdf5-dev`, then rebuild with \
         `cargo install --path tools/frictl --features mat`"
    )
}

/// Most joints labelled in one pass: their datasets are held in memory until written (about 150
/// bytes per joint and grid sample).
const JOINTS_PER_PASS: usize = 4;

/// Checks the options every format shares, before any work: the numbers, `--base-frame` only with
/// a logged base orientation (`base_option`: the format's option for it, and whether it is given;
/// alone it would change nothing, silently) and the outputs.
fn check(
    files: &[PathBuf],
    joints: &[String],
    common: &CommonOptions,
    base_option: (&str, bool),
) -> anyhow::Result<()> {
    for (k, j) in joints.iter().enumerate() {
        anyhow::ensure!(!joints[..k].contains(j), "--joint {j}: given twice");
    }
    let mut labelled: Vec<&str> = joints.iter().map(String::as_str).collect();
    labelled.extend(common.urdf_joint.as_deref());
    crate::urdf::check_not_held(&labelled, &common.fixed_joints)?;
    if let (Some(f), (option, false)) = (&common.base_frame, base_option) {
        bail!("--base-frame {f} names the frame of a logged base orientation: give {option}");
    }
    // Every number is checked, needed or not: each goes into the sidecar.
    for (v, r) in per_joint_values(&common.gear_ratio, "--gear-ratio")? {
        anyhow::ensure!(
            r.is_finite() && r != 0.0,
            "--gear-ratio {v}: must be finite and non-zero (signed)"
        );
    }
    for (v, k) in per_joint_values(&common.kt, "--kt")? {
        anyhow::ensure!(
            k.is_finite() && k > 0.0,
            "--kt {v}: must be finite and > 0 [Nm/A] (a current of the other sign convention: \
             --negate current)"
        );
    }
    if let Some(g) = common.gap_s {
        anyhow::ensure!(
            g.is_finite() && g > 0.0,
            "--gap-s {g}: must be finite and > 0 [s]"
        );
    }
    let inputs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    // The joints of `--joints all` are known after reading: the directory is checked here, each
    // output again before it is written.
    let out = out_path(&common.out, "x");
    let side = out.with_extension("json");
    check_outputs(&inputs, &[&out, &side])
}

/// Labels the runs read whole and writes each joint's dataset and sidecar.
fn finish(
    runs: Vec<ImportedRun>,
    files: &[PathBuf],
    format: &str,
    default_gap_s: f64,
    units: Option<&[(Role, frictionless_logs::Unit)]>,
    common: CommonOptions,
    body: Option<WholeBody>,
) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let joints = labelled_joints(&runs, &common)?;
    let label = label_of(&runs, &common)?;
    let whole = label == LabelSource::Current && runs.iter().all(|r| r.state.is_some());
    let body = body.filter(|_| whole);
    let mut warnings = Vec::new();
    let model = dynamics_of(&runs, &joints, label, &common, body.as_ref(), &mut warnings)?;
    let link = model
        .link
        .as_ref()
        .map(frictionless_sim::link::link_from_model)
        .transpose()?;
    let labels = joint_labels(&joints, &common, format, default_gap_s, label)?;
    let dyn_ = match (&body, &link) {
        (Some(b), _) => Dynamics::WholeBody(b),
        (None, Some(l)) => Dynamics::Link(l.as_ref()),
        (None, None) => Dynamics::None,
    };
    for r in &runs {
        warnings.extend(r.report.warning_lines());
    }
    // Units and rates: what a wrong declaration leaves in the numbers, before any work.
    let suspicious = plausibility(&runs, labels[0].cfg.gap_s, units)?;
    warnings.extend(suspicious.iter().cloned());
    if let Some(b) = &body {
        state_plausibility(&runs, b.robot())?;
    }
    let inputs = Inputs::hash(files)?;
    let import = WholeImport {
        inputs: &inputs,
        runs: &runs,
        format,
        label,
        joints: &joints,
        plan: &model.plan,
        gravity_m_s2: model.gravity_m_s2,
        dynamics: &model.text,
        warnings: &warnings,
        suspicious: &suspicious,
        out: &common.out,
    };
    let mut empty = Vec::new();
    let mut written = 0usize;
    // The datasets are held until written: joints are labelled in passes of at most
    // JOINTS_PER_PASS (one RNEA per sample and pass), each pass written before the next.
    let run_joints: Vec<RunJoints<'_>> = runs
        .iter()
        .map(|r| RunJoints {
            signals: r.joint_signals().collect(),
            state: r.state.as_ref(),
        })
        .collect();
    for (pass, batch) in labels.chunks(JOINTS_PER_PASS).enumerate() {
        let first = pass * JOINTS_PER_PASS;
        let subset: Vec<RunJoints<'_>> = run_joints
            .iter()
            .map(|r| RunJoints {
                signals: r.signals[first..first + batch.len()].to_vec(),
                state: r.state,
            })
            .collect();
        let results = preprocess_joints(&subset, batch, dyn_)
            .map_err(name_the_flag)
            .with_context(|| {
                format!(
                    "labelling {} ({label:?} label needs: {})",
                    files
                        .iter()
                        .map(|f| f.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    required_signals(label).join(", ")
                )
            })?;
        for (jl, (ds, sum)) in batch.iter().zip(results) {
            if ds.is_empty() {
                empty.push(jl.joint.clone());
            }
            import.write(jl, &ds, &sum)?;
            written += 1;
        }
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    for r in &runs {
        eprintln!(
            "  run {}: {} of {} rows used",
            r.name, r.report.rows_used, r.report.rows_read,
        );
    }
    if !empty.is_empty() {
        bail!("no samples for {}", empty.join(", "));
    }
    eprintln!(
        "frictl import {format}: {} runs, {written} joint(s), {}, in {:.2} s",
        runs.len(),
        model.text,
        started.elapsed().as_secs_f64(),
    );
    Ok(())
}

/// The labelled joints, the same in every run; several need `{joint}` in `-o`.
fn labelled_joints(runs: &[ImportedRun], common: &CommonOptions) -> anyhow::Result<Vec<String>> {
    let joints: Vec<String> = runs[0].joints.clone();
    for r in &runs[1..] {
        anyhow::ensure!(
            r.joints == joints,
            "{}: labels joints [{}], {} labels [{}]: every file of one import must have the same joints",
            r.report.source,
            r.joints.join(", "),
            runs[0].report.source,
            joints.join(", ")
        );
    }
    anyhow::ensure!(
        joints.len() == 1 || common.out.to_string_lossy().contains(JOINT),
        "{} joints are labelled ({}): -o must hold {JOINT} to name one dataset per joint (e.g. -o ds_{JOINT}.csv)",
        joints.len(),
        joints.join(", ")
    );
    Ok(joints)
}

/// The label: `--label`, else the log's friction column, torque sensor or current; refused when
/// the log lacks what it needs (with what the reader said), or the current label has no URDF.
fn label_of(runs: &[ImportedRun], common: &CommonOptions) -> anyhow::Result<LabelSource> {
    let first = &runs[0].signals;
    let label: LabelSource = match common.label {
        Some(l) => l,
        None if first.tau_f_nm.is_some() => LabelSource::Given,
        None if first.tau_joint_nm.is_some() => LabelSource::TorqueSensor,
        None => LabelSource::Current,
    };
    let has = |role: &str| match role {
        "time" => true,
        "s" => first.s_rad.is_some(),
        "sdot" => first.sdot_rad_s.is_some(),
        "current" => first.current_a.is_some(),
        "tau_joint" => first.tau_joint_nm.is_some(),
        "tau_motor" => first.tau_motor_nm.is_some(),
        "tau_f" => first.tau_f_nm.is_some(),
        _ => false,
    };
    let lacking: Vec<&str> = required_signals(label)
        .iter()
        .copied()
        .filter(|group| !group.split('|').any(has))
        .collect();
    if !lacking.is_empty() {
        let why: Vec<&str> = runs
            .iter()
            .flat_map(|r| &r.report.warnings)
            .map(String::as_str)
            .collect();
        bail!(
            "the {label:?} label needs {} but the log gives none of: {} (pick another --label or map the column){}",
            required_signals(label).join(", "),
            lacking.join(", "),
            if why.is_empty() {
                String::new()
            } else {
                format!("; the reader says: {}", why.join("; "))
            }
        );
    }
    // The simulator's virtual leg is the default of `frictl preprocess` (the simulator's own logs)
    // only: a real robot's log labelled with another robot's dynamics would look fine.
    anyhow::ensure!(
        label != LabelSource::Current || common.urdf.is_some(),
        "the current label needs the robot's link dynamics (τ_ID): pass --urdf ROBOT.urdf (and \
         --urdf-joint if the joint is named differently there); a robot log is never labelled \
         with the simulator's virtual leg"
    );
    Ok(label)
}

/// The link dynamics of the label, as the sidecar describes them.
struct LabelDynamics {
    /// The single-joint view's link model (the current label without a whole-body state).
    link: Option<frictionless_sim::params::LinkModel>,
    /// One line for the sidecar's `dynamics` and the summary.
    text: String,
    /// The whole-body state plan (`settings.import.whole_body`), or null.
    plan: serde_json::Value,
    /// Gravity of τ_ID from the URDF [m/s²] (`settings.import.gravity_m_s2`; `None`: no τ_ID).
    gravity_m_s2: Option<f64>,
}

/// The label's dynamics: the whole-body RNEA (`body`, with its plan and the warnings about held
/// and unknown joints), the single-joint view of the URDF, or none.
fn dynamics_of(
    runs: &[ImportedRun],
    joints: &[String],
    label: LabelSource,
    common: &CommonOptions,
    body: Option<&WholeBody>,
    warnings: &mut Vec<String>,
) -> anyhow::Result<LabelDynamics> {
    // Again with the joints `--joints all` found in the log.
    let mut labelled: Vec<&str> = joints.iter().map(String::as_str).collect();
    labelled.extend(common.urdf_joint.as_deref());
    crate::urdf::check_not_held(&labelled, &common.fixed_joints)?;
    let Some(b) = body else {
        if label != LabelSource::Current {
            return Ok(LabelDynamics {
                link: None,
                text: "none (the label does not use inverse dynamics)".into(),
                plan: serde_json::Value::Null,
                gravity_m_s2: None,
            });
        }
        // The single-joint view, when the log gives no whole-body state.
        anyhow::ensure!(
            joints.len() == 1,
            "labelling several joints with the current label needs the positions of every joint (--positions for CSV)"
        );
        let urdf_joint = common.urdf_joint.as_deref().unwrap_or(&joints[0]);
        let gravity = crate::urdf::gravity_m_s2(common.gravity_m_s2);
        let (m, d) = urdf_link(
            common.urdf.as_deref(),
            urdf_joint,
            &common.fixed_joints,
            gravity,
        )?;
        return Ok(LabelDynamics {
            link: Some(m),
            text: format!("single-joint view: {d}"),
            plan: serde_json::Value::Null,
            gravity_m_s2: Some(gravity),
        });
    };
    let log_names: Vec<String> = runs
        .iter()
        .flat_map(|r| {
            r.state
                .as_ref()
                .map(|s| s.names.clone())
                .unwrap_or_default()
        })
        .collect();
    let base = runs.iter().find_map(|r| {
        r.state
            .as_ref()
            .filter(|s| s.base_quat_xyzw.is_some())
            .map(|s| s.base_frame.as_deref())
    });
    let mut plan = b.plan(&log_names, joints, base);
    plan.wrenches = runs
        .first()
        .and_then(|r| r.state.as_ref())
        .map(|s| s.wrenches.iter().map(|w| w.frame.clone()).collect())
        .unwrap_or_default();
    for j in joints {
        anyhow::ensure!(
            b.robot().joint_index(j).is_ok(),
            "joint `{j}` is not a movable joint of the URDF {} (the whole-body label matches by name)",
            b.robot().source
        );
    }
    warnings.extend(plan.warnings());
    Ok(LabelDynamics {
        link: None,
        text: b.describe(&plan, "settings.import.whole_body"),
        plan: serde_json::to_value(&plan)?,
        gravity_m_s2: Some(b.robot().gravity_m_s2()),
    })
}

/// A gear ratio or torque constant the labelling needs but the command line did not give
/// (NaN in the settings) is reported as the missing flag.
fn name_the_flag(e: frictionless_ident::preprocess::PreprocessError) -> anyhow::Error {
    use frictionless_ident::preprocess::PreprocessError as P;
    match e {
        P::Config {
            name,
            value,
            requirement,
        } if value.is_nan() && matches!(name, "gear_ratio_signed" | "kt_nm_per_a") => {
            let (flag, what) = if name == "gear_ratio_signed" {
                ("--gear-ratio", "R (signed)")
            } else {
                ("--kt", "KT [Nm/A]")
            };
            anyhow::anyhow!(
                "{flag} is not given, and it is needed: {name} must be {requirement}; give `{flag} {what}` (or `NAME={what}` per joint)"
            )
        }
        e => e.into(),
    }
}

/// Each joint's label settings: the pipeline options, the gear ratio and torque constant.
fn joint_labels(
    joints: &[String],
    common: &CommonOptions,
    format: &str,
    default_gap_s: f64,
    label: LabelSource,
) -> anyhow::Result<Vec<JointLabel>> {
    let mut labels = Vec::with_capacity(joints.len());
    for j in joints {
        let mut cfg = PreprocessConfig::for_joint(j);
        cfg.gap_s = common.gap_s.unwrap_or(default_gap_s);
        if format == "mat" {
            // The .mat reader already cut chunks on the desired-current gaps; robot ticks are dense.
            cfg.gap_s = cfg.gap_s.max(1.0);
        }
        common.settings.apply(&mut cfg);
        labels.push(JointLabel {
            joint: j.clone(),
            label: SignalsLabel {
                source: label,
                gear_ratio_signed: per_joint(&common.gear_ratio, j, "--gear-ratio")?,
                kt_nm_per_a: per_joint(&common.kt, j, "--kt")?,
            },
            cfg,
        });
    }
    Ok(labels)
}

/// What every dataset of one whole-log import shares.
struct WholeImport<'a> {
    inputs: &'a Inputs<'a>,
    runs: &'a [ImportedRun],
    format: &'a str,
    label: LabelSource,
    joints: &'a [String],
    plan: &'a serde_json::Value,
    gravity_m_s2: Option<f64>,
    dynamics: &'a str,
    warnings: &'a [String],
    /// The plausibility warnings: the likely cause when a joint keeps nothing.
    suspicious: &'a [String],
    out: &'a Path,
}

impl WholeImport<'_> {
    /// Writes one joint's dataset and sidecar; refuses, before replacing anything, a dataset
    /// that keeps nothing of a run or no valid sample.
    fn write(&self, jl: &JointLabel, ds: &Dataset, sum: &SignalsSummary) -> anyhow::Result<()> {
        let (format, label) = (self.format, self.label);
        let joint = jl.joint.as_str();
        let out = out_path(self.out, joint);
        check_outputs(&self.inputs.paths(), &[&out, &out.with_extension("json")])?;
        let mut warnings = self.warnings.to_vec();
        if label == LabelSource::Given
            && let Some(w) = frictionless_logs::label_sign_warning(ds)
        {
            warnings.push(w);
        }
        // An import that keeps nothing is refused before it replaces anything, with the
        // plausibility findings as the likely cause.
        // A valid row is one with a finite label (a NaN label is nothing to fit on).
        let valid = ds
            .valid
            .iter()
            .zip(&ds.tau_f_label_nm)
            .filter(|(v, f)| **v && f.is_finite())
            .count();
        let empty_runs: Vec<String> = self
            .runs
            .iter()
            .zip(&sum.run_chunks)
            .filter(|(_, c)| c.is_empty())
            .map(|(r, _)| {
                format!(
                    "run {}: {} of {} rows read, 0 chunks",
                    r.name, r.report.rows_used, r.report.rows_read
                )
            })
            .collect();
        if valid == 0 || !empty_runs.is_empty() {
            bail!(
                "{joint}: {valid} valid samples of {}{}{}",
                ds.len(),
                if empty_runs.is_empty() {
                    String::new()
                } else {
                    format!("; nothing of {}", empty_runs.join(", "))
                },
                if self.suspicious.is_empty() {
                    "; check the units and --gap-s".to_string()
                } else {
                    format!("; likely why: {}", self.suspicious.join("; "))
                }
            );
        }
        // The CSV is written to a temporary file now and replaces the old dataset only together
        // with its sidecar (the sidecar last): a stopped import leaves the previous pair or no
        // sidecar.
        let mut csv_out = frictionless::output_file::AtomicFile::create(&out)
            .with_context(|| format!("cannot write {}", out.display()))?;
        ds.write_csv_to(&mut csv_out, &out)?;
        let (r, kt) = (jl.label.gear_ratio_signed, jl.label.kt_nm_per_a);
        let not_given = "not given (1 written as a placeholder)";
        let settings = serde_json::json!({
            "pipeline": jl.cfg,
            "import": {
                "format": format,
                "label": label,
                "joints_of_this_pass": self.joints,
                "gear_ratio_signed": r.map_or(not_given.to_string(), |r| r.to_string()),
                "kt_nm_per_a": kt.map_or(not_given.to_string(), |k| k.to_string()),
                "derivations": sum.derivations,
                "whole_body": self.plan,
                "gravity_m_s2": self.gravity_m_s2,
                "dropped_single_sample_chunks": sum.dropped_single_sample_chunks,
                "delta_theta_offsets_motor_rad": sum
                    .delta_theta_offsets_motor_rad
                    .iter()
                    .map(|v| if v.is_finite() { serde_json::json!(v) } else { serde_json::Value::Null })
                    .collect::<Vec<_>>(),
                "runs": self.inputs.reports(self.runs),
                "warnings": warnings,
            }
        });
        let side = self.inputs.sidecar(
            self.runs,
            jl,
            sum,
            ds,
            ds.len(),
            valid,
            self.dynamics.to_string(),
            settings,
        );
        commit_pair(csv_out, &out, &side)?;
        for w in &warnings[self.warnings.len()..] {
            eprintln!("warning: {joint}: {w}");
        }
        eprintln!(
            "frictl import {format}: {joint}: {} samples ({valid} valid, {} chunks, {} too short), label {label:?}, absent columns [{}] -> {}",
            ds.len(),
            side.chunks,
            sum.short_chunks,
            side.absent_columns.join(", "),
            out.display()
        );
        if let Some(line) = jl.cfg.limits.dropped_rows_line(&sum.dropped, ds.len()) {
            eprintln!("  {joint}: {line}");
        }
        Ok(())
    }
}
