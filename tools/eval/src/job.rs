//! One whole evaluation as a library call (what `frictl eval` runs): the models and datasets named by
//! path are loaded, the held-out rows chosen, every model scored, the breakdown and the drift monitor
//! added, and the figures drawn.
//!
//! What it is: [`EvalJob`] (the inputs, as plain values) → [`run`] → [`EvalOutcome`] (the report, its
//! JSON, the drift report, the figures written and the warnings, in order). The caller prints and
//! writes what it wants.
//!
//! What it is not: an argument parser or a printer: [`run`] prints nothing and writes only the
//! figures under [`EvalJob::figures_dir`].

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use frictionless::weights::ModelFile;
use frictionless_dataset::bands::ResidualProfile;
use frictionless_dataset::{Dataset, DatasetSidecar, MotionRange, RunInfo, dataset_runs};
use frictionless_train::data::{Block, ChunkKey};

use crate::drift::{self, Coverage, DriftOptions, DriftReport};
use crate::{
    DatasetEval, EvalError, EvalOptions, ModelSpec, Report, TrainingRange, load_static_model, plot,
};

/// What to evaluate, and how.
#[derive(Clone, Debug, Default)]
pub struct EvalJob {
    /// Dataset CSVs; every row is scored unless `test_runs` or `test_datasets` hold runs out (then
    /// these are the training runs, whose range of s and ṡ marks extrapolation).
    pub datasets: Vec<PathBuf>,
    /// Held-out datasets, each scored whole.
    pub test_datasets: Vec<PathBuf>,
    /// Held-out runs by name (a sidecar's run name, or the file stem of a dataset without runs).
    pub test_runs: Vec<String>,
    /// CV, SCV and LuGre fit JSON files.
    pub cv: Option<PathBuf>,
    /// SCV fit JSON.
    pub scv: Option<PathBuf>,
    /// LuGre fit JSON.
    pub lugre: Option<PathBuf>,
    /// PINN `.fwt` files.
    pub pinns: Vec<PathBuf>,
    /// The training report (its test split, training range and curves).
    pub train_report: Option<PathBuf>,
    /// Score only the chunks the training report marks as its test split.
    pub test_only: bool,
    /// |ṡ| band edges [rad/s], increasing.
    pub band_edges: Vec<f64>,
    /// Scoring settings.
    pub options: EvalOptions,
    /// The drift monitor's thresholds (checked by the caller), or no drift monitor.
    pub drift: Option<DriftOptions>,
    /// The drift monitor's reference datasets.
    pub references: Vec<PathBuf>,
    /// Where to draw the figures (created if missing), or none.
    pub figures_dir: Option<PathBuf>,
    /// The chunk of the time-series and hysteresis figures (default: most sliding rows).
    pub plot_chunk: Option<u32>,
}

/// What an evaluation gave.
#[derive(Debug)]
pub struct EvalOutcome {
    /// The report (`frictionless-eval-v1`).
    pub report: Report,
    /// The drift report, with the drift monitor.
    pub drift: Option<DriftReport>,
    /// The report as JSON, the drift report under the key `drift`.
    pub json: serde_json::Value,
    /// Why the drift monitor reached no verdict (nothing was checked), if so; the figures are then
    /// not drawn.
    pub unchecked: Option<String>,
    /// The figures written.
    pub figures: Vec<PathBuf>,
    /// Warnings, in the order they arose.
    pub warnings: Vec<String>,
    /// Models evaluated and datasets scored.
    pub counts: (usize, usize),
}

/// One loaded dataset: path, rows, joint name (sidecar) and runs.
struct Loaded {
    path: PathBuf,
    ds: Dataset,
    joint: String,
    runs: Vec<RunInfo>,
}

/// The models' display names of PINN files: `pinn` for one, `pinn:<stem>` for several.
fn pinn_names(paths: &[PathBuf]) -> Vec<String> {
    if paths.len() == 1 {
        return vec!["pinn".into()];
    }
    let mut out: Vec<String> = Vec::new();
    for (i, p) in paths.iter().enumerate() {
        let stem = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| i.to_string());
        let mut name = format!("pinn:{stem}");
        if out.contains(&name) {
            name = format!("pinn:{stem}#{i}");
        }
        out.push(name);
    }
    out
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> EvalError {
    EvalError::Io {
        path: path.display().to_string(),
        msg: e.to_string(),
    }
}

fn read_json(path: &Path) -> Result<serde_json::Value, EvalError> {
    let text = frictionless::regular_file::read_text(path).map_err(|e| io_err(path, e))?;
    serde_json::from_str(&text).map_err(|e| io_err(path, format!("not JSON: {e}")))
}

/// A dataset and its sidecar (absent or unreadable: none).
fn read_dataset(path: &Path) -> Result<(Dataset, Option<DatasetSidecar>), EvalError> {
    let ds = Dataset::read_csv(path).map_err(|e| EvalError::Dataset {
        path: path.display().to_string(),
        msg: e.to_string(),
    })?;
    let side = frictionless::regular_file::read_text(&path.with_extension("json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    Ok((ds, side))
}

/// Refuses a dataset the PINN `file` (from `model_path`) cannot be run on: a column its inputs read
/// is absent from the dataset (sidecar's `absent_columns`), or the dataset's sidecar records another
/// gear ratio (Δθ would be wrong). Returns a warning when the joint names differ. The one check of
/// `frictl eval` and `frictl convert --dataset`.
pub fn check_pinn_on_dataset(
    model_path: &Path,
    file: &ModelFile,
    ds_path: &Path,
    ds: &Dataset,
    side: Option<&DatasetSidecar>,
) -> Result<Option<String>, EvalError> {
    let what = || {
        format!(
            "PINN {} on dataset {}",
            model_path.display(),
            ds_path.display()
        )
    };
    let absent = side.map_or(&[][..], |s| &s.absent_columns[..]);
    ds.check_inputs(&file.meta.features, absent)
        .map_err(|e| EvalError::Dataset {
            path: what(),
            msg: e.to_string(),
        })?;
    let Some(s) = side else { return Ok(None) };
    let r = file.meta.gear_ratio.get();
    if (r - s.gear_ratio_signed).abs() > 1e-9 * r.abs() {
        return Err(EvalError::Dataset {
            path: what(),
            msg: format!(
                "the PINN was trained with gear ratio {r} but the dataset has gear_ratio_signed = {} (Δθ would be wrong)",
                s.gear_ratio_signed
            ),
        });
    }
    Ok(
        (!file.meta.joint_name.is_empty()
            && !s.joint.is_empty()
            && file.meta.joint_name != s.joint)
            .then(|| {
                format!(
                    "PINN {} is for joint {:?}, dataset {} is {:?}",
                    model_path.display(),
                    file.meta.joint_name,
                    ds_path.display(),
                    s.joint
                )
            }),
    )
}

/// The models in report order: none, CV, SCV, LuGre, then the PINNs (with their files).
/// A PINN file and its path.
type PinnFile = (PathBuf, ModelFile);

fn load_models(job: &EvalJob) -> Result<(Vec<ModelSpec>, Vec<PinnFile>), EvalError> {
    let mut models = vec![ModelSpec::none()];
    for (name, path) in [("cv", &job.cv), ("scv", &job.scv), ("lugre", &job.lugre)] {
        if let Some(p) = path {
            models.push(ModelSpec::static_model(name, load_static_model(p)?));
        }
    }
    let mut pinn_files = Vec::new();
    for (p, name) in job.pinns.iter().zip(pinn_names(&job.pinns)) {
        let f = frictionless::weights::read_file(p).map_err(|e| EvalError::Pinn {
            path: p.display().to_string(),
            msg: e.to_string(),
        })?;
        let spec = ModelSpec::pinn(&name, &f, job.options.warmup).map_err(|e| EvalError::Pinn {
            path: p.display().to_string(),
            msg: e.to_string(),
        })?;
        models.push(spec);
        pinn_files.push((p.clone(), f));
    }
    Ok((models, pinn_files))
}

/// Every dataset (training then held-out), each checked against every PINN.
fn load_datasets(
    paths: &[PathBuf],
    blocks: &[Vec<Block>],
    pinn_files: &[PinnFile],
    warnings: &mut Vec<String>,
) -> Result<Vec<Loaded>, EvalError> {
    let mut loaded = Vec::new();
    for (p, b) in paths.iter().zip(blocks) {
        let (ds, side) = read_dataset(p)?;
        let joint = side.as_ref().map(|s| s.joint.clone()).unwrap_or_default();
        // A PINN whose inputs read a column this dataset lacks is refused by name (a torque-sensed
        // dataset has no motor angle: fine for joint-vel, not for delta-theta-joint-vel).
        for (fp, f) in pinn_files {
            if let Some(w) = check_pinn_on_dataset(fp, f, p, &ds, side.as_ref())? {
                warnings.push(w);
            }
        }
        let mut runs = dataset_runs(p, side.as_ref(), &ds);
        // A split by time blocks names the blocks' keys: the dataset is read through the same
        // blocks, and each run keeps the blocks cut from its chunks.
        let ds = match b.first() {
            Some(first) => {
                for run in &mut runs {
                    let cut: Vec<u32> = b
                        .iter()
                        .filter(|k| run.chunks.contains(&k.chunk))
                        .map(|k| k.key.chunk)
                        .collect();
                    run.chunks.extend(cut);
                }
                frictionless_train::data::with_blocks(&ds, first.key.dataset, b)
            }
            None => ds,
        };
        loaded.push(Loaded {
            path: p.clone(),
            ds,
            joint,
            runs,
        });
    }
    Ok(loaded)
}

/// The held-out runs of each dataset, and the motion range of the training runs. Held out: the
/// named runs and every run of a held-out dataset (the first `n_train` datasets are the training
/// ones); without either, every run is scored.
fn hold_out(
    job: &EvalJob,
    loaded: &[Loaded],
) -> Result<(Vec<Vec<RunInfo>>, MotionRange), EvalError> {
    let holding_out = !job.test_runs.is_empty() || !job.test_datasets.is_empty();
    let mut held = Vec::new();
    let mut train_range = MotionRange::default();
    for (i, l) in loaded.iter().enumerate() {
        let whole = i >= job.datasets.len();
        let (h, t): (Vec<RunInfo>, Vec<RunInfo>) = l
            .runs
            .iter()
            .cloned()
            .partition(|r| !holding_out || whole || job.test_runs.contains(&r.name));
        for r in &t {
            train_range.merge(&MotionRange::of_chunks(&l.ds, &r.chunks));
        }
        held.push(h);
    }
    for name in &job.test_runs {
        if !held.iter().flatten().any(|r| &r.name == name) {
            let known: Vec<&str> = loaded
                .iter()
                .flat_map(|l| l.runs.iter().map(|r| r.name.as_str()))
                .collect();
            return Err(EvalError::UnknownRun {
                name: name.clone(),
                known: known.join(", "),
            });
        }
    }
    Ok((held, train_range))
}

/// The training range: of the training runs when runs are held out, else the training report's.
fn training_range(
    job: &EvalJob,
    train_range: MotionRange,
) -> Result<Option<TrainingRange>, EvalError> {
    let holding_out = !job.test_runs.is_empty() || !job.test_datasets.is_empty();
    if holding_out && train_range.rows > 0 {
        return Ok(Some(TrainingRange {
            source: "datasets".into(),
            range: train_range,
        }));
    }
    let Some(r) = &job.train_report else {
        return Ok(None);
    };
    let v = read_json(r)?;
    match v.get("training_range").filter(|x| !x.is_null()) {
        Some(x) => Ok(Some(TrainingRange {
            source: "train_report".into(),
            range: serde_json::from_value(x.clone()).map_err(|e| EvalError::TrainReport {
                path: r.display().to_string(),
                msg: format!("key `training_range` is not a range: {e}"),
            })?,
        })),
        None => Ok(None),
    }
}

/// Runs the evaluation `job` describes.
pub fn run(job: &EvalJob) -> Result<EvalOutcome, EvalError> {
    let mut warnings = Vec::new();
    let (models, pinn_files) = load_models(job)?;
    crate::runs::check_band_edges(&job.band_edges)?;
    let all_paths: Vec<PathBuf> = job
        .datasets
        .iter()
        .chain(&job.test_datasets)
        .cloned()
        .collect();
    let (test_chunks, blocks) = test_split(job, &all_paths)?;
    let loaded = load_datasets(&all_paths, &blocks, &pinn_files, &mut warnings)?;
    let (held, train_range) = hold_out(job, &loaded)?;
    let training_range = training_range(job, train_range)?;
    let holding_out = !job.test_runs.is_empty() || !job.test_datasets.is_empty();

    let mut evals = Vec::new();
    let mut parts = Vec::new();
    let mut scored_paths = Vec::new();
    for (i, l) in loaded.iter().enumerate() {
        if held[i].is_empty() {
            continue;
        }
        let held_chunks: BTreeSet<u32> = held[i].iter().flat_map(|r| r.chunks.clone()).collect();
        let filter: Option<BTreeSet<u32>> = match (&test_chunks, holding_out) {
            (Some(t), true) => Some(t[i].intersection(&held_chunks).copied().collect()),
            (Some(t), false) => Some(t[i].clone()),
            (None, true) => Some(held_chunks),
            (None, false) => None,
        };
        let name = l.path.display().to_string();
        let ev = crate::evaluate(&name, &l.ds, &models, filter.as_ref(), &job.options)?;
        let extrap =
            crate::runs::extrapolated_mask(&l.ds, training_range.as_ref().map(|t| &t.range));
        parts.push((held[i].clone(), extrap));
        evals.push((ev, &l.ds, l.joint.clone()));
        scored_paths.push(l.path.clone());
    }
    check_some_scored(&evals, &loaded)?;
    let mut report = crate::build_report(&models, &evals, &job.options, job.test_only);
    crate::add_breakdown(
        &mut report,
        &models,
        &evals,
        &parts,
        &job.band_edges,
        training_range.clone(),
        job.options.v_sliding_rad_s,
    );
    let drift = match &job.drift {
        Some(o) => Some(drift_monitor(job, o, &models, &pinn_files, &evals)?),
        None => None,
    };
    let json = report_json(&report, drift.as_ref())?;
    let unchecked = drift.as_ref().and_then(unchecked_reasons);
    let mut figures = Vec::new();
    if let (Some(dir), None) = (&job.figures_dir, &unchecked) {
        let figs = Figures {
            dir,
            models: &models,
            range: training_range.as_ref().map(|t| &t.range),
            v_sliding_rad_s: job.options.v_sliding_rad_s,
            plot_chunk: job.plot_chunk,
        };
        figures = figs.draw(
            &evals,
            &scored_paths,
            &parts,
            drift.as_ref(),
            job,
            &mut warnings,
        )?;
    }
    Ok(EvalOutcome {
        report,
        drift,
        json,
        unchecked,
        figures,
        warnings,
        counts: (models.len(), evals.len()),
    })
}

/// The test chunks to score (only with `--test-only`, from the training report) and, then, each
/// dataset's blocks of the report's split (else none).
#[allow(clippy::type_complexity)]
fn test_split(
    job: &EvalJob,
    all_paths: &[PathBuf],
) -> Result<(Option<Vec<BTreeSet<u32>>>, Vec<Vec<Block>>), EvalError> {
    let test_chunks = match (&job.train_report, job.test_only) {
        (Some(r), true) => Some(crate::test_chunks_from_report(r, all_paths)?),
        (None, true) => {
            return Err(EvalError::Selection(
                "scoring the test split only needs the training report".into(),
            ));
        }
        (_, false) => None,
    };
    let blocks = match (&test_chunks, &job.train_report) {
        (Some(_), Some(r)) => report_blocks(r, all_paths)?,
        _ => vec![Vec::new(); all_paths.len()],
    };
    Ok((test_chunks, blocks))
}

/// An error when no row of any dataset was scored, with each dataset's row counts.
fn check_some_scored(
    evals: &[(DatasetEval, &Dataset, String)],
    loaded: &[Loaded],
) -> Result<(), EvalError> {
    let scored: usize = evals
        .iter()
        .map(|(ev, _, _)| ev.mask.iter().filter(|m| **m).count())
        .sum();
    if scored == 0 {
        let per: Vec<String> = loaded
            .iter()
            .map(|l| {
                format!(
                    "{}: {} rows, {} valid",
                    l.path.display(),
                    l.ds.len(),
                    l.ds.valid.iter().filter(|v| **v).count()
                )
            })
            .collect();
        return Err(EvalError::Selection(format!(
            "0 rows scored, nothing evaluated ({}); a row is scored when it is valid, in a scored run or chunk, every PINN's history is ready and every output is finite",
            per.join("; ")
        )));
    }
    Ok(())
}

/// The report as JSON, with the drift report under `drift` when there is one.
fn report_json(
    report: &Report,
    drift: Option<&DriftReport>,
) -> Result<serde_json::Value, EvalError> {
    let mut json = serde_json::to_value(report).map_err(|e| EvalError::Selection(e.to_string()))?;
    if let (Some(d), Some(m)) = (drift, json.as_object_mut()) {
        let v = serde_json::to_value(d).map_err(|e| EvalError::Selection(e.to_string()))?;
        m.insert("drift".into(), v);
    }
    Ok(json)
}

/// Why the drift check is unchecked (each unchecked model's reasons), if it is.
fn unchecked_reasons(d: &DriftReport) -> Option<String> {
    (d.verdict == "unchecked").then(|| {
        d.models
            .iter()
            .filter(|m| m.verdict == "unchecked")
            .flat_map(|m| m.reasons.iter().map(move |r| format!("{}: {r}", m.model)))
            .collect::<Vec<_>>()
            .join("; ")
    })
}

/// The figures of one evaluation.
struct Figures<'a> {
    dir: &'a Path,
    models: &'a [ModelSpec],
    range: Option<&'a MotionRange>,
    v_sliding_rad_s: f64,
    plot_chunk: Option<u32>,
}

type Part = (Vec<RunInfo>, Vec<bool>);

impl Figures<'_> {
    /// Per dataset: friction vs velocity, the time series and (with a motor encoder) the hysteresis
    /// of one chunk; per model the drift bands; the training curves of the training report.
    fn draw(
        &self,
        evals: &[(DatasetEval, &Dataset, String)],
        paths: &[PathBuf],
        parts: &[Part],
        drift: Option<&DriftReport>,
        job: &EvalJob,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<PathBuf>, EvalError> {
        std::fs::create_dir_all(self.dir).map_err(|e| io_err(self.dir, e))?;
        if plot::init_font().is_none() {
            warnings.push(
                "no TrueType font found (set FRICTL_FONT=path/to/font.ttf); figures are drawn without text"
                    .into(),
            );
        }
        let mut written = Vec::new();
        for (((ev, ds, _), p), (_, extrap)) in evals.iter().zip(paths).zip(parts) {
            let stem = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "dataset".into());
            let f = self.dir.join(format!("{stem}_friction_vs_velocity.png"));
            plot::friction_vs_velocity(&f, ds, ev, self.models, self.range)?;
            written.push(f);
            let Some(chunk) = plot::pick_chunk(ds, ev, self.v_sliding_rad_s, self.plot_chunk)
            else {
                continue;
            };
            let f = self.dir.join(format!("{stem}_timeseries.png"));
            plot::timeseries(&f, ds, ev, self.models, chunk, extrap)?;
            written.push(f);
            // Δθ needs a motor encoder: a dataset without one (NaN column) has no hysteresis.
            if ds.delta_theta_motor_rad[chunk.0..chunk.1]
                .iter()
                .any(|v| v.is_finite())
            {
                let f = self.dir.join(format!("{stem}_hysteresis.png"));
                plot::hysteresis(&f, ds, chunk)?;
                written.push(f);
            } else {
                warnings.push(format!(
                    "{}: no Δθ (no motor encoder): hysteresis figure skipped",
                    p.display()
                ));
            }
        }
        for m in drift.iter().flat_map(|d| &d.models) {
            let name: String = m
                .model
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect();
            let f = self.dir.join(format!("drift_{name}.png"));
            plot::drift_bands(&f, m)?;
            written.push(f);
        }
        if let Some(r) = &job.train_report {
            let v = read_json(r)?;
            let f = self.dir.join("training_curves.png");
            match plot::training_curves(&f, &v) {
                Ok(()) => written.push(f),
                Err(e) => warnings.push(e.to_string()),
            }
        }
        Ok(written)
    }
}

/// The drift monitor: every model but `none` on the scored rows against its reference (see
/// [`crate::drift`] for the reference order and the rule).
fn drift_monitor(
    job: &EvalJob,
    o: &DriftOptions,
    models: &[ModelSpec],
    pinn_files: &[PinnFile],
    evals: &[(DatasetEval, &Dataset, String)],
) -> Result<DriftReport, EvalError> {
    // The reference datasets, scored like the new log (every valid row whose history is ready).
    let mut refs = Vec::new();
    for p in &job.references {
        let (ds, side) = read_dataset(p)?;
        let absent = side.as_ref().map_or(&[][..], |s| &s.absent_columns[..]);
        for (fp, f) in pinn_files {
            ds.check_inputs(&f.meta.features, absent)
                .map_err(|e| EvalError::Dataset {
                    path: format!("PINN {} on reference {}", fp.display(), p.display()),
                    msg: e.to_string(),
                })?;
        }
        let ev = crate::evaluate(&p.display().to_string(), &ds, models, None, &job.options)?;
        refs.push((ev, ds));
    }
    let ref_pairs: Vec<(&DatasetEval, &Dataset)> = refs.iter().map(|(e, d)| (e, d)).collect();
    let new_pairs: Vec<(&DatasetEval, &Dataset)> = evals.iter().map(|(e, d, _)| (e, *d)).collect();
    let train_report = job.train_report.as_deref().map(read_json).transpose()?;
    let first_pinn = models.len() - pinn_files.len();
    let profile = |pairs: &[(&DatasetEval, &Dataset)], i: usize| {
        ResidualProfile::from_rows(
            drift::residual_rows(pairs, i),
            &job.band_edges,
            o.temperature_bin_c,
        )
    };
    let mut out = Vec::new();
    for (i, m) in models.iter().enumerate().skip(1) {
        let file = i.checked_sub(first_pinn).map(|j| &pinn_files[j].1);
        let reference = if !ref_pairs.is_empty() {
            Some(drift::Reference {
                source: "reference_datasets".into(),
                profile: profile(&ref_pairs, i),
            })
        } else {
            let from_report = train_report
                .as_ref()
                .filter(|_| file.is_some() && pinn_files.len() == 1)
                .and_then(|v| {
                    drift::train_report_reference(v, &job.band_edges, o.temperature_bin_c)
                });
            from_report.or_else(|| file.and_then(drift::fwt_reference))
        };
        let coverage = coverage(&new_pairs, m, job.options.delta_theta_offset, o);
        out.push(drift::model_drift(
            &m.name,
            profile(&new_pairs, i),
            reference,
            coverage,
            o,
        ));
    }
    Ok(drift::report(out, o))
}

/// The time blocks of the training report's split ([`Block`], key `split.blocks`) per evaluated
/// dataset (matched like [`crate::test_chunks_from_report`]: by SHA-256, else by path); empty lists
/// when the split is by chunks (no key).
fn report_blocks(report: &Path, datasets: &[PathBuf]) -> Result<Vec<Vec<Block>>, EvalError> {
    let mut out = vec![Vec::new(); datasets.len()];
    let v = read_json(report)?;
    let Some(blocks) = v.pointer("/split/blocks") else {
        return Ok(out);
    };
    let blocks: Vec<Block> =
        serde_json::from_value(blocks.clone()).map_err(|e| EvalError::TrainReport {
            path: report.display().to_string(),
            msg: format!("key `split.blocks` is not a list of blocks: {e}"),
        })?;
    let rep_ds = v
        .get("datasets")
        .and_then(serde_json::Value::as_array)
        .cloned()
        .unwrap_or_default();
    let field =
        |d: &serde_json::Value, k: &str| d.get(k).and_then(|x| x.as_str()).map(str::to_owned);
    for (i, d) in datasets.iter().enumerate() {
        let sha = frictionless_dataset::file_sha256_hex(d).map_err(|e| io_err(d, e))?;
        let path = d.display().to_string();
        let Some(di) = rep_ds
            .iter()
            .position(|rd| field(rd, "sha256").as_deref() == Some(sha.as_str()))
            .or_else(|| {
                rep_ds
                    .iter()
                    .position(|rd| field(rd, "path").as_deref() == Some(path.as_str()))
            })
        else {
            continue;
        };
        out[i] = blocks
            .iter()
            .filter(|b| b.key.dataset as usize == di)
            .map(|b| Block {
                key: ChunkKey {
                    dataset: i as u32,
                    chunk: b.key.chunk,
                },
                ..*b
            })
            .collect();
    }
    Ok(out)
}

/// The share of the scored rows outside a PINN's input range (none for a static model).
fn coverage(
    pairs: &[(&DatasetEval, &Dataset)],
    m: &ModelSpec,
    offset: frictionless_train::data::DeltaThetaOffset,
    o: &DriftOptions,
) -> Option<Coverage> {
    let mut coverage: Option<Coverage> = None;
    for (ev, ds) in pairs {
        let Some(mask) = drift::out_of_range_mask(ds, &m.model, offset, o.range_margin) else {
            continue;
        };
        let c = coverage.get_or_insert(Coverage {
            rows: 0,
            out_of_range: 0,
            out_of_range_share: 0.0,
            margin: o.range_margin,
        });
        for (k, &out) in mask.iter().enumerate() {
            if ev.mask[k] {
                c.rows += 1;
                c.out_of_range += usize::from(out);
            }
        }
    }
    if let Some(c) = &mut coverage {
        c.out_of_range_share = c.out_of_range as f64 / c.rows.max(1) as f64;
    }
    coverage
}
