//! `frictl distill TEACHER.fwt --dataset DS.csv … -o STUDENT.fwt [--hidden 32,32] [--dtype …]`:
//! train a small student on a teacher's outputs (training windows of the datasets plus probes inside
//! the teacher's stored input range, with the label and SCV terms of the datasets), and write it only
//! if its RMSE against the data on held-out runs is within `--max-rmse-ratio` of the teacher's,
//! overall and per |ṡ| band. The method is `frictionless_train::distill`; the student inherits the
//! teacher's inputs, normalisation and metadata and records the teacher's SHA-256; `--history H`
//! gives it only the newest H samples of each of the teacher's feature blocks.
//!
//! The held-out set: `--test-run`/`--test-chunks`/`--test-dataset`/`--test-frac` as in `frictl train`;
//! without any of them, the split of the teacher's training report (`TEACHER.train.json`) when its
//! datasets are these (same SHA-256, same order), so the gate is on data the teacher never saw.
//! The warm-up policy and the Δθ latch also default to the teacher report's.
//!
//! `--probes-only N` distils without data: N training probes inside the teacher's stored input range
//! (plus N/4 validation and N/4 gate probes, independent draws), the teacher's output the only
//! target; the gate is the output RMSE against the teacher on the gate probes, ≤ `--max-rmse-nm`.
//!
//! `--init prune` starts the student from the teacher narrowed to `--hidden`
//! (`frictionless_train::prune`) instead of a random initialisation.

use std::ops::ControlFlow;
use std::path::PathBuf;

use anyhow::{Context, bail};
use frictionless::features::WarmupPolicy;
use frictionless::mlp::StorageDtype;
use frictionless_train::TrainConfig;
use frictionless_train::data::{DeltaThetaOffset, SplitSpec};
use frictionless_train::distill::{self, DistillConfig};
use frictionless_train::pipeline::{self, TrainReport};

use super::train::cores;

pub use frictl_cli::distill::*;

/// The teacher's training report: `--teacher-report`, else the one next to the teacher (read when it
/// exists, so an input of the command either way).
fn teacher_report_path(args: &Args) -> PathBuf {
    args.teacher_report
        .clone()
        .unwrap_or_else(|| pipeline::default_report_path(&args.teacher))
}

/// Bytes one probe row costs a distillation of `teacher` (its inputs as f32 in the probe set, the
/// student's copy and the trainer's batches, its target), for [`frictl_cli::count::fits_in_memory`].
fn probe_bytes(teacher: &frictionless::weights::ModelFile) -> usize {
    (teacher.mlp.n_inputs() + 2) * std::mem::size_of::<f32>() * 4
}

/// The teacher's training report, if one is given or sits next to the teacher.
fn teacher_report(args: &Args) -> anyhow::Result<Option<TrainReport>> {
    let (path, given) = (teacher_report_path(args), args.teacher_report.is_some());
    if !given && !path.exists() {
        if args.delta_theta_offset.is_none() || args.warmup.is_none() {
            eprintln!(
                "frictl distill: no training report of the teacher at {} (give --teacher-report); \
                 unless --delta-theta-offset and --warmup say otherwise, the Δθ offset is latched per \
                 run and the warm-up holds zero. Both must be how the teacher was trained, or its \
                 targets are computed on inputs it never saw",
                path.display()
            );
        }
        return Ok(None);
    }
    let text = frictionless::regular_file::read_text(&path)
        .with_context(|| format!("--teacher-report {}: cannot read", path.display()))?;
    let report: TrainReport = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a `frictl train` report", path.display()))?;
    Ok(Some(report))
}

/// `frictl distill --probes-only N`.
fn run_probes_only(args: &Args, probes: usize) -> anyhow::Result<()> {
    if let Some(h) = args.history {
        anyhow::bail!(
            "--history {h}: a shorter student history needs data (--dataset); --probes-only \
             students keep the teacher's history"
        );
    }
    // The teacher's report is not read here, but it is the teacher's: never overwritten.
    let report = teacher_report_path(args);
    super::check_outputs(&[&args.teacher, &report], &[&args.out])?;
    let teacher = frictionless::weights::read_file(&args.teacher)
        .with_context(|| format!("teacher {}", args.teacher.display()))?;
    // Training probes plus a quarter each for validation and the gate.
    frictl_cli::count::fits_in_memory(
        &format!("--probes-only {probes}"),
        probes.saturating_add(2 * (probes / 4).max(1)),
        probe_bytes(&teacher),
        frictl_cli::count::available_memory_bytes(),
    )?;
    let teacher_sha256 = frictionless_dataset::file_sha256(&args.teacher)
        .with_context(|| format!("teacher {}: cannot read", args.teacher.display()))?;
    if teacher.meta.training.input_range.is_none() {
        eprintln!(
            "frictl distill: {} stores no input range; probes are drawn in mean ± 3·scale of its \
             normalisation",
            args.teacher.display()
        );
    }
    let cfg = distill::ProbeDistillConfig {
        train: TrainConfig {
            hidden: args.hidden.clone(),
            dropout: 0.0,
            lambda: 0.0,
            lr: args.lr,
            batch_size: args.batch,
            epochs: args.epochs,
            seed: args.seed,
            threads: args.threads.unwrap_or_else(cores).max(1),
            patience: None,
            abort_loss: Some(1000.0),
        },
        dtype: args.dtype.into(),
        probes,
        val_probes: (probes / 4).max(1),
        test_probes: (probes / 4).max(1),
        max_rmse_nm: args.max_rmse_nm,
        probe_kind: args.probe_kind.into(),
        lr_final: args.lr_final,
        init: args.init.into(),
    };
    if !args.quiet {
        eprintln!(
            "frictl distill: {} → hidden {:?} ({}), probes only: {} train / {} val / {} gate",
            args.teacher.display(),
            args.hidden,
            StorageDtype::from(args.dtype).name(),
            cfg.probes,
            cfg.val_probes,
            cfg.test_probes
        );
    }
    let quiet = args.quiet;
    let epochs = args.epochs;
    let out = distill::distill_probes(&teacher, teacher_sha256, &cfg, |r| {
        if !quiet {
            let val = r
                .val_rmse_nm
                .map_or(String::new(), |v| format!(" val rmse vs teacher {v:.5} Nm"));
            eprintln!(
                "epoch {}/{epochs} train loss {:.6}{val}{}",
                r.epoch,
                r.train_loss,
                if r.is_best { " *" } else { "" }
            );
        }
        ControlFlow::Continue(())
    })?;
    if let Some(start) = out.start_rmse_vs_teacher_nm {
        println!(
            "pruned start (before training): RMSE vs teacher {start:.5} Nm on the validation probes"
        );
    }
    println!("{}", out.gate.line());
    print_inference(&teacher, &out.model);
    if !out.gate.passed() {
        bail!(
            "the student (hidden {:?}) is not within {} Nm RMS of the teacher inside its input \
             range; {} not written",
            args.hidden,
            args.max_rmse_nm,
            args.out.display()
        );
    }
    frictionless::weights::write_file(&args.out, &out.model)?;
    println!(
        "wrote {}: hidden {:?} {}, {} MAC (teacher {} MAC), best epoch {}",
        args.out.display(),
        args.hidden,
        out.model.dtype.name(),
        out.model.mlp.macs(),
        teacher.mlp.macs(),
        out.best_epoch
    );
    Ok(())
}

/// Prints the hot and cold inference time of teacher and student on this CPU.
fn print_inference(
    teacher: &frictionless::weights::ModelFile,
    student: &frictionless::weights::ModelFile,
) {
    let us = |f: &frictionless::weights::ModelFile| {
        frictionless_train::search::inference_us(f).map_or("-".into(), |(hot, cold)| {
            format!("hot {hot:.3} µs, cold {cold:.2} µs")
        })
    };
    println!(
        "inference on this CPU (kernel, stored dtype): teacher {}; student {}",
        us(teacher),
        us(student)
    );
}

/// Runs `frictl distill`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(probes) = args.probes_only {
        return run_probes_only(&args, probes);
    }
    let out = distill_file(&args)?;
    print!("{}", out.gate.table());
    let us = |t: Option<(f64, f64)>| {
        t.map_or("-".into(), |(hot, cold)| {
            format!("hot {hot:.3} µs, cold {cold:.2} µs")
        })
    };
    println!(
        "inference on this CPU (kernel, stored dtype): teacher {}; student {}",
        us(out.teacher_us),
        us(out.student_us)
    );
    if !out.written {
        bail!(
            "the student (hidden {:?}) is not within {}× the teacher's held-out RMSE (rows marked \
             FAIL above); {} not written",
            args.hidden,
            args.max_rmse_ratio,
            args.out.display()
        );
    }
    println!(
        "wrote {}: hidden {:?} {}, best epoch {}, val RMSE {} Nm, test RMSE {:.5} Nm (teacher {:.5} Nm)",
        args.out.display(),
        args.hidden,
        out.model.dtype.name(),
        out.best_epoch,
        out.val_rmse_nm.map_or("-".into(), |v| format!("{v:.5}")),
        out.model.meta.training.test_rmse_nm,
        out.gate.rows[0].teacher_rmse_nm
    );
    Ok(())
}

/// What [`distill_file`] did.
#[derive(Debug)]
pub struct Outcome {
    /// The held-out gate (overall first, then per |ṡ| band).
    pub gate: distill::Gate,
    /// Whether the student passed and was written to `Args::out`.
    pub written: bool,
    /// The student (written only when `written`).
    pub model: frictionless::weights::ModelFile,
    /// 1-based epoch of the kept weights.
    pub best_epoch: usize,
    /// The student's validation RMSE \[Nm\].
    pub val_rmse_nm: Option<f64>,
    /// Hot and cold inference time of the teacher on this CPU \[µs\].
    pub teacher_us: Option<(f64, f64)>,
    /// Hot and cold inference time of the student \[µs\].
    pub student_us: Option<(f64, f64)>,
}

/// Distils `args.teacher` on `args.datasets` (the typed entry of `frictl distill` and of the
/// pipelines' distillation stage): writes the student to `args.out` only when the held-out gate
/// passes and says which in [`Outcome::written`]; errors on bad input or a failed training.
pub fn distill_file(args: &Args) -> anyhow::Result<Outcome> {
    let datasets = args.held_out.all_datasets(&args.datasets)?;
    let sidecars: Vec<PathBuf> = datasets.iter().map(|d| d.with_extension("json")).collect();
    let mut inputs: Vec<&std::path::Path> = datasets.iter().map(PathBuf::as_path).collect();
    inputs.extend(sidecars.iter().map(PathBuf::as_path));
    inputs.push(&args.teacher);
    let report_path = teacher_report_path(args);
    inputs.push(&report_path);
    super::check_outputs(&inputs, &[&args.out])?;
    let teacher = frictionless::weights::read_file(&args.teacher)
        .with_context(|| format!("teacher {}", args.teacher.display()))?;
    if let Some(p) = args.probes {
        frictl_cli::count::fits_in_memory(
            &format!("--probes {p}"),
            p,
            probe_bytes(&teacher),
            frictl_cli::count::available_memory_bytes(),
        )?;
    }
    // Checked against the teacher's H before any dataset is read.
    let (student_spec, _) = distill::student_inputs(&teacher.meta.features, args.history)?;
    let teacher_sha256 = frictionless_dataset::file_sha256(&args.teacher)
        .with_context(|| format!("teacher {}: cannot read", args.teacher.display()))?;
    let report = teacher_report(args)?;
    let sources = pipeline::load_sources(&datasets)?;
    frictl_cli::train::distinct_contents(&sources, args.datasets.len())?;
    if sources.joint != teacher.meta.joint_name {
        bail!(
            "the datasets are of joint `{}`, the teacher {} of `{}`",
            sources.joint,
            args.teacher.display(),
            teacher.meta.joint_name
        );
    }
    let split_spec = student_split(args, report.as_ref(), &sources)?;
    let split = pipeline::split_for(&sources, &split_spec)?;
    let cfg = distill_config(args, report.as_ref(), &sources, &split);
    let probes = cfg.probes;
    if !args.quiet {
        eprintln!(
            "frictl distill: {} [{}] {} → [{}] hidden {:?} ({}), {} probes; chunks train {} / val {} / test {}",
            sources.joint,
            teacher.meta.features,
            args.teacher.display(),
            student_spec,
            args.hidden,
            StorageDtype::from(args.dtype).name(),
            probes,
            split.train.len(),
            split.val.len(),
            split.test.len()
        );
    }
    let quiet = args.quiet;
    let out = distill::distill(&teacher, teacher_sha256, &sources, &split, &cfg, |r| {
        if !quiet {
            let val = r
                .val_rmse_nm
                .map_or(String::new(), |v| format!(" val rmse {v:.4} Nm"));
            eprintln!(
                "epoch {}/{} train loss {:.5}{val}{}",
                r.epoch,
                args.epochs,
                r.train_loss,
                if r.is_best { " *" } else { "" }
            );
        }
        ControlFlow::Continue(())
    })?;
    let written = out.gate.passed();
    if written {
        frictionless::weights::write_file(&args.out, &out.model)?;
    }
    Ok(Outcome {
        written,
        teacher_us: frictionless_train::search::inference_us(&teacher),
        student_us: frictionless_train::search::inference_us(&out.model),
        gate: out.gate,
        model: out.model,
        best_epoch: out.best_epoch,
        val_rmse_nm: out.val_rmse_nm,
    })
}

/// The split the student trains on: the teacher's own when it was trained on exactly these files
/// and no split option is given, else the options' (defaults 0.15 / 0.15).
fn student_split(
    args: &Args,
    report: Option<&TrainReport>,
    sources: &pipeline::Sources,
) -> anyhow::Result<SplitSpec> {
    let explicit_split = args.val_frac.is_some()
        || args.test_frac.is_some()
        || args.test_chunks.is_some()
        || !args.held_out.test_runs.is_empty()
        || !args.held_out.test_datasets.is_empty();
    // The teacher's own split when it was trained on exactly these files.
    let same_data = report.filter(|r| {
        r.datasets.len() == sources.list.len()
            && r.datasets.iter().zip(&sources.list).all(|(d, s)| {
                d.sha256
                    == s.sha256
                        .iter()
                        .map(|b| format!("{b:02x}"))
                        .collect::<String>()
            })
    });
    Ok(match same_data {
        Some(r) if !explicit_split => r.split.spec.clone(),
        _ => SplitSpec {
            val_frac: args.val_frac.unwrap_or(0.15),
            test_frac: args.test_frac.unwrap_or(0.15),
            seed: args.seed,
            test_chunks: args.held_out.test_chunks(
                sources,
                &args.test_chunks,
                args.datasets.len(),
            )?,
        },
    })
}

/// The distillation's settings from the options, with the teacher's warm-up and Δθ offset where
/// the options leave them (from its train report `report`); probes default to a quarter of the
/// training rows.
fn distill_config(
    args: &Args,
    report: Option<&TrainReport>,
    sources: &pipeline::Sources,
    split: &frictionless_train::data::Split,
) -> DistillConfig {
    let warmup: WarmupPolicy = match (args.warmup, report) {
        (Some(w), _) => w.into(),
        (None, Some(r)) => r.warmup,
        (None, None) => WarmupPolicy::HoldZero,
    };
    let delta_theta_offset = match (args.delta_theta_offset, report) {
        (Some(d), _) => d,
        (None, Some(r)) => r.delta_theta_offset,
        (None, None) => DeltaThetaOffset::Run,
    };
    let threads = args.threads.unwrap_or_else(cores).max(1);
    // Probes default to a quarter of the training rows (counted after preparing; estimated here
    // from the valid rows of the training chunks).
    let probes = args.probes.unwrap_or_else(|| {
        let train_rows: usize = split
            .train
            .iter()
            .map(|k| split.valid_rows(*k, &sources.list[k.dataset as usize].data))
            .sum();
        train_rows / 4
    });
    DistillConfig {
        train: TrainConfig {
            hidden: args.hidden.clone(),
            dropout: 0.0,
            lambda: args.lambda,
            lr: args.lr,
            batch_size: args.batch,
            epochs: args.epochs,
            seed: args.seed,
            threads,
            patience: None,
            abort_loss: Some(1000.0),
        },
        probe_kind: args.probe_kind.into(),
        lr_final: args.lr_final,
        init: args.init.into(),
        dtype: args.dtype.into(),
        teacher_weight: args.teacher_weight,
        probes,
        max_rmse_ratio: args.max_rmse_ratio,
        min_band_samples: args.min_band_samples,
        warmup,
        delta_theta_offset,
        history: args.history,
    }
}
