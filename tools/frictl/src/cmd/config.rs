//! `frictl config` — one frictiond `[[joint]]` for a fitted static model (`frictl fit --json`) or a
//! PINN (`.fwt`, with its train report), written as a complete shared-memory config after
//! frictiond's own checker (`frictiond_config::parse`, what `frictiond --check` runs) has accepted it.
//!
//! A PINN joint gets its encoder semantics (`motor_encoder`; for an absolute encoder the Δθ offset
//! its training latched, none for an incremental one, whose model must have been trained latched per
//! chunk), the limits given, and with `--fit` its static model as the fallback while its inputs are
//! outside the training range (`ood = "static"` by default then).

use std::path::Path;

use anyhow::{Context, bail};
use frictiond_config::{
    JointConfig, ModelKind, MotorEncoder, OodMode, RawConfig, WarmupName, default_ood_margin,
    default_ood_ramp_ms,
};
use frictionless_dataset::fit_file::FittedModel;
use frictionless_train::data::DeltaThetaOffset;
use frictionless_train::pipeline::TrainReport;

pub use frictl_cli::config::*;

/// The Δθ offset the training datasets of `report` were latched with (one value for all of them),
/// `None` when latched per chunk or when the model reads no Δθ.
fn trained_offset(report: &TrainReport, path: &Path) -> anyhow::Result<Option<f64>> {
    let training: Vec<usize> = report
        .split
        .train
        .iter()
        .chain(&report.split.val)
        .map(|k| k.dataset as usize)
        .collect();
    let offsets: Vec<Option<f64>> = report
        .datasets
        .iter()
        .enumerate()
        .filter(|(i, _)| training.contains(i))
        .map(|(_, d)| d.delta_theta_offset_motor_rad)
        .collect();
    match offsets.first() {
        Some(Some(v)) if offsets.iter().all(|o| *o == Some(*v)) => Ok(Some(*v)),
        Some(Some(_)) => bail!(
            "--train-report {}: the training datasets were latched with different Δθ offsets ({offsets:?}); frictiond takes one: train with --motor-encoder incremental, or with one calibrated --delta-theta-offset",
            path.display()
        ),
        _ => Ok(None),
    }
}

fn set_static_keys(j: &mut JointConfig, fitted: &FittedModel) {
    for (k, v) in super::fit::daemon_keys(fitted) {
        let slot = match k {
            "kc" => &mut j.kc,
            "kv" => &mut j.kv,
            "ka" => &mut j.ka,
            "ks" => &mut j.ks,
            "vs" => &mut j.vs,
            "alpha" => &mut j.alpha,
            "sigma0" => &mut j.sigma0,
            _ => &mut j.sigma1,
        };
        *slot = Some(v);
    }
}

/// Runs `frictl config`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut inputs: Vec<&Path> = Vec::new();
    inputs.extend(args.fit.as_deref());
    inputs.extend(args.pinn.as_deref());
    inputs.extend(args.train_report.as_deref());
    super::check_outputs(&inputs, &[&args.out])?;
    let fitted = args
        .fit
        .as_deref()
        .map(|p| FittedModel::read(p).with_context(|| format!("--fit {}", p.display())))
        .transpose()?;
    let encoder = match args.motor_encoder {
        frictl_cli::train::MotorEncoder::Absolute => MotorEncoder::Absolute,
        frictl_cli::train::MotorEncoder::Incremental => MotorEncoder::Incremental,
    };
    let mut j = JointConfig {
        name: args.joint.clone().unwrap_or_default(),
        index: args.index,
        gear_ratio: args.gear_ratio.unwrap_or(f64::NAN),
        kt: args.kt.unwrap_or(f64::NAN),
        max_curr: args.max_curr,
        kfc: args.kfc,
        kp: 0.0,
        ki: 0.0,
        max_output_friction: args.max_output_friction.unwrap_or(f64::INFINITY),
        joint_velocity_threshold_rad_s: 0.0,
        lpf: None,
        friction_model: ModelKind::None,
        kc: None,
        kv: None,
        ka: None,
        ks: None,
        vs: None,
        alpha: None,
        sigma0: None,
        sigma1: None,
        model: None,
        model_for: None,
        warmup: WarmupName::HoldZero,
        delta_theta_offset_motor_rad: None,
        motor_encoder: encoder,
        speed_current_limit: None,
        ood: OodMode::default(),
        ood_margin: default_ood_margin(),
        ood_ramp_ms: default_ood_ramp_ms(),
        alternate: Vec::new(),
    };
    match &args.pinn {
        Some(model_path) => {
            let model = frictionless::weights::read_file(model_path)
                .with_context(|| format!("--pinn {}", model_path.display()))?;
            let meta = &model.meta;
            if j.name.is_empty() {
                j.name = meta.joint_name.clone();
            }
            j.gear_ratio = args.gear_ratio.unwrap_or(meta.gear_ratio.get());
            j.kt = args.kt.unwrap_or(meta.kt_nm_per_a);
            j.friction_model = ModelKind::Pinn;
            j.model = Some(
                std::path::absolute(model_path)
                    .with_context(|| format!("--pinn {}", model_path.display()))?,
            );
            let reads_delta_theta = meta.features.set.uses_delta_theta();
            let report: Option<TrainReport> = args
                .train_report
                .as_deref()
                .map(|p| -> anyhow::Result<TrainReport> {
                    let t = frictionless::regular_file::read_text(p)
                        .with_context(|| format!("--train-report {}", p.display()))?;
                    serde_json::from_str(&t).with_context(|| {
                        format!(
                            "--train-report {}: not a `frictl train` report",
                            p.display()
                        )
                    })
                })
                .transpose()?;
            match (encoder, reads_delta_theta, &report, &args.train_report) {
                (_, false, _, _) => {}
                (MotorEncoder::Absolute, true, Some(r), Some(p)) => {
                    j.delta_theta_offset_motor_rad = trained_offset(r, p)?;
                }
                (MotorEncoder::Absolute, true, _, _) => bail!(
                    "--pinn {} reads Δθ, whose offset depends on the encoder zero the training latched: give --train-report (absolute encoder), or --motor-encoder incremental for a model trained latched per chunk",
                    model_path.display()
                ),
                (MotorEncoder::Incremental, true, Some(r), Some(p)) => {
                    if r.delta_theta_offset != DeltaThetaOffset::Chunk {
                        bail!(
                            "--train-report {}: the model was trained with --delta-theta-offset {}, a fixed encoder zero; an incremental encoder has a new one at every power-up: retrain with --motor-encoder incremental",
                            p.display(),
                            r.delta_theta_offset
                        );
                    }
                }
                (MotorEncoder::Incremental, true, _, _) => {}
            }
            if let Some(f) = &fitted {
                if !matches!(f.kind(), ModelKind::Cv | ModelKind::Scv) {
                    bail!(
                        "--fit: a PINN joint falls back to a CV or SCV model, not {}",
                        f.tag()
                    );
                }
                set_static_keys(&mut j, f);
            }
            j.ood = match (args.ood, &fitted) {
                (Some(Ood::Static), None) => {
                    bail!("--ood static needs --fit (the static model to fall back to)")
                }
                (Some(Ood::Static), Some(_)) | (None, Some(_)) => OodMode::Static,
                (Some(Ood::Flag), _) | (None, None) => OodMode::Flag,
                (Some(Ood::Off), _) => OodMode::Off,
            };
        }
        None => {
            let f = fitted
                .as_ref()
                .context("give --fit FIT.json (a static model) or --pinn MODEL.fwt")?;
            if args.train_report.is_some() || args.ood.is_some() {
                bail!("--train-report and --ood are for a PINN joint (--pinn)");
            }
            if j.name.is_empty() {
                bail!("--joint NAME is required for a fitted model (a fit file names no joint)");
            }
            if args.gear_ratio.is_none() || args.kt.is_none() {
                bail!("--gear-ratio and --kt are required for a fitted model");
            }
            j.friction_model = f.kind();
            set_static_keys(&mut j, f);
        }
    }
    let text = toml::to_string(&RawConfig::shm(vec![j])).context("cannot encode the config")?;
    let text = format!(
        "# written by frictl config; check with `frictiond --config {} --check`\n{text}",
        args.out.display()
    );
    frictiond_config::parse(&args.out, &text).map_err(|e| {
        anyhow::anyhow!("the [[joint]] frictl config built is not accepted by frictiond: {e}")
    })?;
    frictionless::output_file::write(&args.out, &text)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!("frictl config: {} (checked)", args.out.display());
    Ok(())
}
