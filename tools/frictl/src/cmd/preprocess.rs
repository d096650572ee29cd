//! `frictl preprocess` — acquisition log (CSV + JSON sidecar) → labelled dataset (CSV + JSON sidecar).
//!
//! See `frictionless_ident::preprocess` for the pipeline and `frictionless_dataset` for the columns.

use anyhow::Context;
use frictionless_ident::dataset_file::{Provenance, write_dataset};
use frictionless_ident::preprocess::{LogMeta, PreprocessConfig, RawLog, preprocess};

pub use frictionless_import::{urdf_link, urdf_whole_body};
pub use frictl_cli::preprocess::*;

/// Runs `frictl preprocess`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let sidecar_path = args.log.with_extension("json");
    super::check_outputs(
        &[&args.log, &sidecar_path],
        &[&args.out, &args.out.with_extension("json")],
    )?;
    anyhow::ensure!(
        !args.log.exists() || sidecar_path.exists(),
        "{}: no sidecar {} beside it, so it is not a `frictl acquire` log; a robot's own log (CSV, YARP \
         .mat, ROS 2 MCAP) is labelled by `frictl import csv|mat|mcap` (docs/robot-logs.md)",
        args.log.display(),
        sidecar_path.display()
    );
    let meta = LogMeta::read_json(&sidecar_path)?;
    let log = RawLog::read_csv(&args.log)?;
    let sha = frictionless_dataset::file_sha256_hex(&args.log)
        .with_context(|| format!("cannot read {}", args.log.display()))?;

    if let Some(positions) = &args.positions {
        return run_whole_body(&args, positions, &meta, &log, sha, started);
    }
    let use_sidecar = match (args.link_from_sidecar, args.link) {
        (true, _) | (_, LinkSource::Sidecar) => true,
        (false, LinkSource::Urdf) => false,
        (false, LinkSource::Auto) => args.urdf.is_none() && meta.plant_link.is_some(),
    };
    let gravity = frictionless_import::gravity_m_s2(args.pipeline.gravity_m_s2);
    let (link_model, dynamics) = if use_sidecar {
        if let Some(g) = args.pipeline.gravity_m_s2 {
            anyhow::bail!(
                "--gravity-m-s2 {g}: the simulator's link model from the sidecar (--link sidecar, \
                 or --link auto on a simulated log) has its own gravity; --gravity-m-s2 sets a \
                 URDF's (--link urdf)"
            );
        }
        let l = meta.plant_link.clone().with_context(|| {
            format!(
                "--link sidecar: {} has no plant.link (not a simulated log); use --link urdf",
                sidecar_path.display()
            )
        })?;
        let d = format!("simulator link model from the sidecar: {l:?}");
        (l, d)
    } else {
        let joint = args.joint.clone().unwrap_or_else(|| meta.joint.clone());
        urdf_link(args.urdf.as_deref(), &joint, &args.fixed_joints, gravity)?
    };
    let link = frictionless_sim::link::link_from_model(&link_model)?;

    let cfg = pipeline_config(&args, &meta)?;
    let (ds, summary) = preprocess(&log, &meta, link.as_ref(), &cfg)?;
    let mut settings = serde_json::to_value(&cfg)?;
    if !use_sidecar {
        settings["gravity_m_s2"] = gravity.into();
    }
    write_settings(
        &args, &meta, sha, settings, &cfg, dynamics, ds, summary, started,
    )
}

/// The pipeline settings of `args` for the log's joint.
fn pipeline_config(args: &Args, meta: &LogMeta) -> anyhow::Result<PreprocessConfig> {
    let mut cfg = PreprocessConfig::for_joint(&meta.joint);
    args.pipeline.apply(&mut cfg);
    cfg.gap_s = args.gap_s;
    if let Some(j) = &args.subtract_reflected_inertia {
        cfg.subtract_reflected_inertia_kgm2 = if j == "sidecar" {
            meta.j_eq_kgm2.context(
                "--subtract-reflected-inertia sidecar: the sidecar has no plant.j_motor_kgm2",
            )?
        } else {
            j.parse()
                .with_context(|| format!("--subtract-reflected-inertia {j:?} is not a number"))?
        };
    }
    Ok(cfg)
}

/// `frictl preprocess --positions TEMPLATE`: τ_ID from the whole body, every URDF joint whose
/// column the template names.
fn run_whole_body(
    args: &Args,
    positions: &str,
    meta: &LogMeta,
    log: &RawLog,
    sha: String,
    started: std::time::Instant,
) -> anyhow::Result<()> {
    const JOINT: &str = "{joint}";
    for (flag, t) in [
        ("--positions", Some(positions)),
        ("--velocities", args.velocities.as_deref()),
        ("--accelerations", args.accelerations.as_deref()),
    ] {
        if let Some(t) = t {
            anyhow::ensure!(
                t.contains(JOINT),
                "{flag} {t:?}: the template must hold {JOINT} (e.g. `q_{JOINT}`)"
            );
        }
    }
    let gravity = frictionless_import::gravity_m_s2(args.pipeline.gravity_m_s2);
    let body = urdf_whole_body(args.urdf.as_deref(), &args.fixed_joints, gravity)?;
    let mut cols = frictionless_dataset::read_columns(&args.log)?;
    let mut names = Vec::new();
    let (mut q, mut qd, mut qdd) = (Vec::new(), Vec::new(), Vec::new());
    for j in body.robot().joint_names() {
        if let Some(v) = cols.remove(&positions.replace(JOINT, j)) {
            names.push(j.to_string());
            q.push(v);
            let mut take =
                |t: &Option<String>| t.as_ref().and_then(|t| cols.remove(&t.replace(JOINT, j)));
            qd.push(take(&args.velocities));
            qdd.push(take(&args.accelerations));
        }
    }
    anyhow::ensure!(
        !names.is_empty() || body.robot().joint_index(&meta.joint).is_ok(),
        "{}: --positions {positions:?} matches no column for any URDF joint",
        args.log.display()
    );
    if names.is_empty() {
        eprintln!(
            "warning: --positions {positions:?} matches no column of {}: only the log's own joint moves",
            args.log.display()
        );
    }
    let state = frictionless_ident::preprocess::JointStates {
        names,
        q,
        qdot: qd,
        qddot: qdd,
        base_quat_xyzw: None,
        base_frame: None,
        wrenches: Vec::new(),
    };
    let plan = body.plan(&state.names, std::slice::from_ref(&meta.joint), None);
    for w in plan.warnings() {
        eprintln!("warning: {w}");
    }
    let cfg = pipeline_config(args, meta)?;
    let (ds, summary) =
        frictionless_ident::preprocess::preprocess_whole_body(log, meta, &body, &state, &cfg)?;
    let dynamics = body.describe(&plan, "settings.whole_body");
    let mut settings = serde_json::to_value(&cfg)?;
    settings["gravity_m_s2"] = gravity.into();
    settings["whole_body"] = serde_json::to_value(&plan)?;
    write_settings(
        args, meta, sha, settings, &cfg, dynamics, ds, summary, started,
    )
}

/// Writes the dataset and its sidecar (`settings` as given), and prints the summary.
#[allow(clippy::too_many_arguments)]
fn write_settings(
    args: &Args,
    meta: &LogMeta,
    sha: String,
    settings: serde_json::Value,
    cfg: &PreprocessConfig,
    dynamics: String,
    ds: frictionless_dataset::Dataset,
    summary: frictionless_ident::preprocess::PreprocessSummary,
    started: std::time::Instant,
) -> anyhow::Result<()> {
    let mut settings = settings;
    let dynamics_line = format!("\n  tau_ID: {dynamics}");
    if let (Some(r), Some(map)) = (summary.ripple, settings.as_object_mut()) {
        map.insert("ripple_fit".into(), serde_json::to_value(r)?);
    }
    write_dataset(
        &args.out,
        &ds,
        &summary,
        &Provenance {
            input_log: args.log.display().to_string(),
            input_sha256: sha,
            meta,
            fs_hz: cfg.fs_hz,
            settings,
            dynamics,
        },
    )?;
    let valid = ds.valid.iter().filter(|v| **v).count();
    let mut msg = format!(
        "frictl preprocess: {} samples ({valid} valid, {} chunks, {} too short) in {:.2} s -> {}",
        ds.len(),
        summary.chunks,
        summary.short_chunks,
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    msg += &dynamics_line;
    if let Some(line) = cfg.limits.dropped_rows_line(&summary.dropped, ds.len()) {
        msg += &format!("\n  {line}");
    }
    match (cfg.ripple, summary.ripple) {
        (frictionless_ident::preprocess::Ripple::Off, _) => {}
        (_, Some(r)) => msg += &format!("\n  {}", r.describe()),
        (_, None) => msg += "\n  wave-generator ripple not identified: too few sliding rows",
    }
    if let Some(t) = &ds.tau_f_true_nm {
        let (mut e2, mut n) = (0.0, 0usize);
        for (k, truth) in t.iter().enumerate() {
            if ds.valid[k] && ds.sdot_rad_s[k].abs() > 0.03 {
                e2 += (ds.tau_f_label_nm[k] - truth).powi(2);
                n += 1;
            }
        }
        if n > 0 {
            msg += &format!(
                "\n  label vs simulator truth: RMS {:.3} Nm on {n} valid sliding samples",
                (e2 / n as f64).sqrt()
            );
        }
    }
    eprintln!("{msg}");
    Ok(())
}
