//! Distillation behind `frictl distill`: a smaller (or differently stored) student learns a trained
//! teacher, and is accepted only if it is as accurate **against the data** on a held-out set.
//!
//! What it **is**:
//! - [`probe_inputs`]: random input rows drawn uniformly inside a model's stored training input range
//!   (the probe set of `frictl convert`'s gate and of distillation);
//! - [`distill`]: builds the student's training rows — every training window of the datasets with the
//!   target `w·τ̂_teacher + (1 − w)·τ_F label` and the SCV prior term (the trainer's loss
//!   `(1 − λ)·MSE(target) + λ·MSE(SCV)` is unchanged), plus probe rows whose target is the teacher's
//!   output alone (the SCV term then also pulls towards the teacher) — and runs the ordinary
//!   [`super::Trainer`] with the teacher's input normalisation; the weights kept are the best on the
//!   validation set **against the label**;
//! - [`distill_probes`]: distillation without data — training, validation and gate rows are all
//!   probes inside the teacher's input range with the teacher's output as target; gated by
//!   [`ProbeGate`] on the output RMSE against the teacher on probes never trained on;
//! - [`Gate`]: the student's and the teacher's RMSE against the label on the test set (whole held-out
//!   runs), overall and per |ṡ| band ([`DEFAULT_BAND_EDGES_RAD_S`]), both run on the kernel frictiond
//!   uses ([`frictionless::kernel::Mlp`], stored dtype); it passes when every figure of the student is
//!   ≤ `max_rmse_ratio` × the teacher's (bands with fewer than `min_band_samples` rows are reported but
//!   not gated).
//!
//! The student inherits the teacher's features, history, normalisation, joint, gear ratio, k_t, SCV
//! prior, filtering and stored input range; with [`DistillConfig::history`] it reads only the newest
//! samples of each feature block (a shorter history: fewer inputs, a smaller first layer) and keeps
//! the teacher's normalisation of those inputs; its header records the teacher file's SHA-256
//! (`teacher_sha256`, `.fwt` ≥ 1.5), the datasets' hash and its own validation/test RMSE.
//!
//! What it is **not**: no second trainer (the loss, optimiser and data pipeline are the ones of
//! `frictl train`), no file writing (the command writes the student only when the gate passes).

use std::borrow::Cow;
use std::ops::ControlFlow;

use frictionless::features::FeatureSpec;
use frictionless::friction::ScvParams;
use frictionless::kernel::Mlp;
use frictionless::mlp::{MlpWeights, Normalisation, StorageDtype};
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta, round_to_dtype};
use frictionless_dataset::bands::{DEFAULT_BAND_EDGES_RAD_S, ResidualProfile};
use serde::{Deserialize, Serialize};

use super::data::{DeltaThetaOffset, SetData, Split};
use super::pipeline::{self, PipelineError, ScvPrior, Sources};
use super::{Dataset, EpochReport, Predictor, TrainConfig, Trainer};
use frictionless::features::WarmupPolicy;

/// How probe rows are drawn inside a model's input range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProbeKind {
    /// Every input drawn independently and uniformly inside its range: each of a block's H samples
    /// alone, so most rows are histories no sensor gives (a value jumping across the whole range
    /// from one sample to the next).
    #[default]
    Uniform,
    /// Each feature block the history of a smooth signal inside its range, as the daemon feeds it:
    /// a sinusoid of random centre, amplitude, phase and frequency up to
    /// [`TRAJECTORY_MAX_RAD_PER_SAMPLE`], plus uniform noise of ±[`TRAJECTORY_NOISE_SHARE`] of the
    /// range, clipped to the range; the blocks are independent of each other; the temperature is
    /// uniform in its range.
    Trajectory,
}

/// Highest angular frequency of a trajectory probe's signal [rad per history sample]: 20 Hz at the
/// 1 kHz tick.
pub const TRAJECTORY_MAX_RAD_PER_SAMPLE: f32 = 2.0 * std::f32::consts::PI * 20.0 / 1000.0;

/// Half-width of a trajectory probe's uniform noise, as a share of the block's range.
pub const TRAJECTORY_NOISE_SHARE: f32 = 0.01;

/// Random input rows inside the training input range of `file` (each of a block's H samples drawn
/// independently inside that block's range, the temperature inside its range), or inside
/// mean ± 3·scale of the normalisation for a file without a stored range. Deterministic in `seed`.
pub fn probe_inputs(file: &ModelFile, count: usize, seed: u64) -> Vec<Vec<f32>> {
    probe_inputs_of_kind(file, count, seed, ProbeKind::Uniform)
}

/// [`probe_inputs`] drawn as `kind` says. Deterministic in `seed`.
pub fn probe_inputs_of_kind(
    file: &ModelFile,
    count: usize,
    seed: u64,
    kind: ProbeKind,
) -> Vec<Vec<f32>> {
    // SplitMix64: uniform in [0, 1) from the top 24 bits.
    let mut state = seed;
    let mut uniform = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let norm = &file.mlp.norm;
    let spec = &file.meta.features;
    let n = file.mlp.n_inputs();
    let h = spec.history.max(1);
    let n_blocks = spec.set.n_blocks();
    let range_of = |i: usize| -> [f32; 2] {
        match &file.meta.training.input_range {
            Some(r) if i < n_blocks * h => r.blocks[(i / h).min(r.blocks.len() - 1)],
            Some(r) if spec.temperature => r.temperature,
            _ => [
                norm.mean[i] - 3.0 * norm.scale[i].abs(),
                norm.mean[i] + 3.0 * norm.scale[i].abs(),
            ],
        }
    };
    let ranges: Vec<[f32; 2]> = (0..n).map(range_of).collect();
    let history_inputs = (n_blocks * h).min(n);
    (0..count)
        .map(|_| match kind {
            ProbeKind::Uniform => ranges
                .iter()
                .map(|r| r[0] + (r[1] - r[0]) * uniform())
                .collect(),
            ProbeKind::Trajectory => {
                let mut row = Vec::with_capacity(n);
                for b in 0..history_inputs.div_ceil(h) {
                    // The signal in units of the block's range: u ∈ [0, 1].
                    let amp = 0.5 * uniform();
                    let centre = amp + (1.0 - 2.0 * amp) * uniform();
                    let omega = TRAJECTORY_MAX_RAD_PER_SAMPLE * uniform();
                    let phase = 2.0 * std::f32::consts::PI * uniform();
                    for k in 0..h.min(history_inputs - b * h) {
                        let noise = TRAJECTORY_NOISE_SHARE * (2.0 * uniform() - 1.0);
                        let u = (centre + amp * (omega * k as f32 + phase).sin() + noise)
                            .clamp(0.0, 1.0);
                        let r = ranges[b * h + k];
                        row.push(r[0] + (r[1] - r[0]) * u);
                    }
                }
                row.extend(
                    ranges[history_inputs..]
                        .iter()
                        .map(|r| r[0] + (r[1] - r[0]) * uniform()),
                );
                row
            }
        })
        .collect()
}

/// Where the student's training starts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StudentInit {
    /// A fresh random initialisation (the trainer's).
    #[default]
    Fresh,
    /// The teacher pruned to the student's widths ([`crate::prune::prune`], refitted on up to
    /// [`PRUNE_ROWS`] of the training rows): same depth as the teacher, each layer at most as wide.
    Prune,
}

/// The most training rows (evenly spaced over all of them) the pruned start is refitted on.
pub const PRUNE_ROWS: usize = 40_000;

/// The trainer of a student with the teacher's normalisation, started as `init` says; with
/// [`StudentInit::Prune`], also the pruned starting weights.
fn student_trainer(
    teacher: &MlpWeights,
    init: StudentInit,
    cfg: TrainConfig,
    data: &Dataset<'_>,
    val: Option<&Dataset<'_>>,
) -> Result<(Trainer, Option<MlpWeights>), PipelineError> {
    match init {
        StudentInit::Fresh => Ok((
            Trainer::with_normalisation(cfg, teacher.norm.clone(), data, val)?,
            None,
        )),
        StudentInit::Prune => {
            let (n, n_in) = (data.n_rows(), data.n_inputs);
            let rows = n.min(PRUNE_ROWS);
            let x: Vec<f32> = (0..rows)
                .flat_map(|i| {
                    let r = i * n / rows;
                    data.x[r * n_in..(r + 1) * n_in].iter().copied()
                })
                .collect();
            let start = crate::prune::prune(teacher, &cfg.hidden, &x)
                .map_err(|e| usage(format!("--init prune: {e}")))?;
            Ok((Trainer::from_init(cfg, &start, data, val)?, Some(start)))
        }
    }
}

/// How to distil.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DistillConfig {
    /// The student's hyper-parameters (hidden widths, epochs, seed, …; `lambda` weighs the SCV term).
    pub train: TrainConfig,
    /// Storage dtype of the student.
    pub dtype: StorageDtype,
    /// Weight w of the teacher's output in the target of the dataset rows, in [0, 1] (1: the
    /// teacher only; 0: the label only, i.e. plain training plus probes).
    pub teacher_weight: f32,
    /// Probe rows drawn inside the teacher's input range (targets: the teacher's output).
    pub probes: usize,
    /// How the probe rows are drawn.
    #[serde(default)]
    pub probe_kind: ProbeKind,
    /// Cosine decay of the learning rate from `train.lr` to this over the epochs (`None`: constant).
    #[serde(default)]
    pub lr_final: Option<f32>,
    /// Where the student starts.
    #[serde(default)]
    pub init: StudentInit,
    /// The gate: every student RMSE must be ≤ this × the teacher's (e.g. 1.05).
    pub max_rmse_ratio: f64,
    /// |ṡ| bands with fewer test rows are reported but not gated.
    pub min_band_samples: usize,
    /// Warm-up policy the inputs are built with (the teacher's).
    pub warmup: WarmupPolicy,
    /// Where Δθ is latched (the teacher's).
    pub delta_theta_offset: DeltaThetaOffset,
    /// The student's history length H: the newest `history` samples of each of the teacher's feature
    /// blocks (`None`: the teacher's H). At most the teacher's.
    #[serde(default)]
    pub history: Option<usize>,
}

/// The student's feature spec: the teacher's with history `history` (`None`: the teacher's), and
/// the teacher input column each student input reads (per block its newest samples, oldest first,
/// then the temperature). Errors unless 1 ≤ `history` ≤ the teacher's H.
pub fn student_inputs(
    teacher: &FeatureSpec,
    history: Option<usize>,
) -> Result<(FeatureSpec, Vec<usize>), PipelineError> {
    let (ht, hs) = (teacher.history, history.unwrap_or(teacher.history));
    if !(1..=ht).contains(&hs) {
        return Err(usage(format!(
            "--history {hs}: the student's history must be between 1 and the teacher's {ht}"
        )));
    }
    let spec = FeatureSpec {
        history: hs,
        ..*teacher
    };
    let mut cols: Vec<usize> = (0..teacher.set.n_blocks())
        .flat_map(|b| b * ht + (ht - hs)..(b + 1) * ht)
        .collect();
    if let Some(t) = teacher.temperature_index() {
        cols.push(t);
    }
    debug_assert_eq!(cols.len(), spec.n_inputs());
    Ok((spec, cols))
}

/// Whether `cols` are all `n` columns in order (the student reads the teacher's inputs).
fn all_columns(cols: &[usize], n: usize) -> bool {
    cols.len() == n && cols.iter().enumerate().all(|(i, &c)| i == c)
}

/// The columns `cols` of every row of `x` (rows of `n` values).
fn take_columns(x: &[f32], n: usize, cols: &[usize]) -> Vec<f32> {
    x.chunks_exact(n.max(1))
        .flat_map(|row| cols.iter().map(move |&c| row[c]))
        .collect()
}

/// The student's rows of `x`: `x` itself when it reads every column, else [`take_columns`].
fn student_rows<'a>(x: &'a [f32], n: usize, cols: &[usize]) -> Cow<'a, [f32]> {
    if all_columns(cols, n) {
        Cow::Borrowed(x)
    } else {
        Cow::Owned(take_columns(x, n, cols))
    }
}

/// `w` seen through the input columns `cols`: its normalisation and first layer restricted to them
/// (the dropped inputs then sit at their normalised mean, 0). `w` itself when `cols` are all of
/// its inputs in order.
fn restricted(w: &MlpWeights, cols: &[usize]) -> MlpWeights {
    let n = w.n_inputs();
    if all_columns(cols, n) {
        return w.clone();
    }
    let mut v = w.clone();
    v.norm = Normalisation {
        mean: cols.iter().map(|&c| w.norm.mean[c]).collect(),
        scale: cols.iter().map(|&c| w.norm.scale[c]).collect(),
    };
    if let Some(first) = v.layers.first_mut() {
        first.weight = take_columns(&w.layers[0].weight, n, cols);
        first.n_in = cols.len();
    }
    v
}

/// One gated figure: teacher and student RMSE against the label on the test set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GateRow {
    /// `"all"` or the band, e.g. `"0.1 ≤ |ṡ| < 0.5 rad/s"`.
    pub what: String,
    /// Test rows in it.
    pub n: usize,
    /// Teacher RMSE \[Nm\].
    pub teacher_rmse_nm: f64,
    /// Student RMSE \[Nm\].
    pub student_rmse_nm: f64,
    /// Whether this row is gated (enough rows).
    pub gated: bool,
    /// Whether it passes (always true when not gated).
    pub passed: bool,
}

/// The accuracy gate: the student against the teacher, both against the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gate {
    /// The bound on student / teacher RMSE.
    pub max_rmse_ratio: f64,
    /// Overall, then per |ṡ| band.
    pub rows: Vec<GateRow>,
}

impl Gate {
    /// Whether every gated row passes.
    pub fn passed(&self) -> bool {
        self.rows.iter().all(|r| r.passed)
    }

    /// One line per row: `what n teacher student ratio verdict`.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<26} {:>7} {:>12} {:>12} {:>7}\n",
            "test set (held out)", "rows", "teacher [Nm]", "student [Nm]", "ratio"
        );
        for r in &self.rows {
            let verdict = match (r.gated, r.passed) {
                (false, _) => "not gated (few rows)",
                (true, true) => "ok",
                (true, false) => "FAIL",
            };
            s.push_str(&format!(
                "{:<26} {:>7} {:>12.5} {:>12.5} {:>7.3} {verdict}\n",
                r.what,
                r.n,
                r.teacher_rmse_nm,
                r.student_rmse_nm,
                r.student_rmse_nm / r.teacher_rmse_nm
            ));
        }
        s
    }
}

/// The result of [`distill`]: the student (not yet written) and its gate.
#[derive(Clone, Debug)]
pub struct Distilled {
    /// The student model, metadata inherited from the teacher, `teacher_sha256` set.
    pub model: ModelFile,
    /// The accuracy gate on the test set.
    pub gate: Gate,
    /// Training rows from the datasets, and probe rows.
    pub rows: (usize, usize),
    /// 1-based epoch of the kept (best-on-validation) weights.
    pub best_epoch: usize,
    /// Student RMSE on the validation set \[Nm\] (`None` without one).
    pub val_rmse_nm: Option<f64>,
}

fn usage(m: impl Into<String>) -> PipelineError {
    PipelineError::Usage(m.into())
}

/// The SCV prior of the teacher (a neutral zero prior with λ forced to 0 when the teacher has none).
fn teacher_prior(teacher: &ModelFile) -> ScvPrior {
    let params = teacher.meta.scv.unwrap_or(ScvParams {
        kc: 0.0,
        ka: 1.0,
        kv: 0.0,
        ks: 0.0,
        vs: 1.0,
        alpha: 2.0,
    });
    ScvPrior {
        path: "teacher".into(),
        model: "teacher".into(),
        params,
    }
}

/// Outputs of `file` on the kernel frictiond runs (stored dtype, fastest path), one per row.
fn kernel_outputs(file: &ModelFile, x: &[f32]) -> Result<Vec<f32>, PipelineError> {
    let mut mlp = Mlp::new(&file.mlp, file.dtype)
        .map_err(|e| usage(format!("the model cannot run on the kernel: {e}")))?;
    let n = file.mlp.n_inputs().max(1);
    Ok(x.chunks_exact(n).map(|row| mlp.forward(row)).collect())
}

fn band_name(lo: f64, hi: Option<f64>) -> String {
    match hi {
        Some(h) => format!("{lo} ≤ |ṡ| < {h} rad/s"),
        None => format!("|ṡ| ≥ {lo} rad/s"),
    }
}

/// The gate of `student` against `teacher` on `set` (rows mapped back to `sources` for ṡ): the
/// teacher reads `set.x`, the student the same rows as `student_x` (its own inputs).
pub fn gate(
    teacher: &ModelFile,
    student: &ModelFile,
    sources: &Sources,
    set: &SetData,
    student_x: &[f32],
    max_rmse_ratio: f64,
    min_band_samples: usize,
) -> Result<Gate, PipelineError> {
    let profile = |file: &ModelFile, x: &[f32]| -> Result<ResidualProfile, PipelineError> {
        let y = kernel_outputs(file, x)?;
        let rows = set
            .rows
            .iter()
            .zip(&y)
            .zip(&set.y_label_nm)
            .map(|((&(d, k), &p), &l)| {
                let ds = &sources.list[d as usize].data;
                (ds.sdot_rad_s[k], f64::NAN, f64::from(l) - f64::from(p))
            });
        Ok(ResidualProfile::from_rows(
            rows,
            &DEFAULT_BAND_EDGES_RAD_S,
            1.0,
        ))
    };
    let (t, s) = (profile(teacher, &set.x)?, profile(student, student_x)?);
    let row = |what: String, n: usize, tr: Option<f64>, sr: Option<f64>, gated: bool| {
        let (tr, sr) = (tr.unwrap_or(f64::NAN), sr.unwrap_or(f64::NAN));
        let gated = gated && tr.is_finite();
        GateRow {
            what,
            n,
            teacher_rmse_nm: tr,
            student_rmse_nm: sr,
            gated,
            // A NaN student RMSE fails the comparison.
            passed: !gated || sr <= max_rmse_ratio * tr,
        }
    };
    let mut rows = vec![row(
        "all".into(),
        t.all.n,
        t.all.rmse_nm,
        s.all.rmse_nm,
        true,
    )];
    for (tb, sb) in t.bands.iter().zip(&s.bands) {
        if tb.stats.n == 0 {
            continue;
        }
        rows.push(row(
            band_name(tb.lo_rad_s, tb.hi_rad_s),
            tb.stats.n,
            tb.stats.rmse_nm,
            sb.stats.rmse_nm,
            tb.stats.n >= min_band_samples,
        ));
    }
    Ok(Gate {
        max_rmse_ratio,
        rows,
    })
}

/// Distils `teacher` (its file's SHA-256 `teacher_sha256`) on `sources` split by `split` into a
/// student of `cfg.train.hidden`, and gates it on the test set. Errors when the datasets do not
/// match the teacher (gear ratio, k_t), when there is no test set, or when training fails;
/// a student that fails the gate is returned with `gate.passed() == false` (the caller writes
/// nothing then).
pub fn distill(
    teacher: &ModelFile,
    teacher_sha256: [u8; 32],
    sources: &Sources,
    split: &Split,
    cfg: &DistillConfig,
    on_epoch: impl FnMut(&EpochReport) -> ControlFlow<()>,
) -> Result<Distilled, PipelineError> {
    let meta = &teacher.meta;
    if sources.gear_ratio.get() != meta.gear_ratio.get() {
        return Err(usage(format!(
            "the datasets' signed gear ratio {} differs from the teacher's {}",
            sources.gear_ratio.get(),
            meta.gear_ratio.get()
        )));
    }
    if sources.kt_nm_per_a != meta.kt_nm_per_a {
        return Err(usage(format!(
            "the datasets' k_t {} Nm/A differs from the teacher's {} Nm/A",
            sources.kt_nm_per_a, meta.kt_nm_per_a
        )));
    }
    if !(0.0..=1.0).contains(&cfg.teacher_weight) {
        return Err(usage(format!(
            "--teacher-weight {}: must be in [0, 1]",
            cfg.teacher_weight
        )));
    }
    if !(cfg.max_rmse_ratio.is_finite() && cfg.max_rmse_ratio > 0.0) {
        return Err(usage(format!(
            "--max-rmse-ratio {}: must be finite and positive",
            cfg.max_rmse_ratio
        )));
    }
    if split.test.is_empty() {
        return Err(usage(
            "distillation is gated on held-out data: give --test-run NAME (or --test-frac > 0, \
             --test-chunks, --test-dataset)",
        ));
    }
    let scv = teacher_prior(teacher);
    let prepared = pipeline::prepare(
        sources,
        &scv,
        split,
        &meta.features,
        cfg.warmup,
        cfg.delta_theta_offset,
    )?;
    let n_in = meta.features.n_inputs();
    let (student_spec, cols) = student_inputs(&meta.features, cfg.history)?;
    let student_x = |x| student_rows(x, n_in, &cols);
    let threads = cfg.train.threads.max(1);
    // Teacher targets through the batched trainer path (the teacher's stored weights, f32 math).
    let mut teacher_pred = Predictor::new(&teacher.mlp, threads)?;
    let train = &prepared.train;
    let y_teacher = teacher_pred.predict(&train.x)?;
    let w = cfg.teacher_weight;
    let mut x = student_x(&train.x).into_owned();
    let mut y: Vec<f32> = y_teacher
        .iter()
        .zip(&train.y_label_nm)
        .map(|(&t, &l)| w * t + (1.0 - w) * l)
        .collect();
    let mut s = train.y_scv_nm.clone();
    let probes: Vec<f32> = probe_inputs_of_kind(
        teacher,
        cfg.probes,
        cfg.train.seed ^ 0x9E37_79B9,
        cfg.probe_kind,
    )
    .into_iter()
    .flatten()
    .collect();
    let y_probe = teacher_pred.predict(&probes)?;
    x.extend_from_slice(&student_x(&probes));
    y.extend_from_slice(&y_probe);
    s.extend_from_slice(&y_probe);
    let mut tcfg = cfg.train.clone();
    if meta.scv.is_none() {
        tcfg.lambda = 0.0;
    }
    let data = Dataset {
        x: &x,
        y_label_nm: &y,
        y_scv_nm: &s,
        n_inputs: cols.len(),
    };
    let (val_x, test_x) = (student_x(&prepared.val.x), student_x(&prepared.test.x));
    let val_view = Dataset {
        x: &val_x,
        n_inputs: cols.len(),
        ..prepared.val.view()
    };
    let val = (!prepared.val.is_empty()).then_some(&val_view);
    let view = restricted(&teacher.mlp, &cols);
    let (mut trainer, _) = student_trainer(&view, cfg.init, tcfg, &data, val)?;
    if let Some(end) = cfg.lr_final {
        trainer.set_cosine_decay(end)?;
    }
    let outcome = trainer.train(on_epoch)?;
    let weights = round_to_dtype(&outcome.weights, cfg.dtype);
    let mut student = ModelFile {
        meta: ModelMeta {
            training: TrainingMeta {
                dataset_sha256: sources.dataset_sha256,
                val_rmse_nm: f32::NAN,
                test_rmse_nm: f32::NAN,
                created_unix_s: pipeline::created_unix_s(),
                tool_version: format!("frictl {}", env!("CARGO_PKG_VERSION")),
                filtering: meta.training.filtering,
                input_range: meta.training.input_range,
                quant_max_error_nm: None,
                teacher_sha256: Some(teacher_sha256),
            },
            features: student_spec,
            ..meta.clone()
        },
        dtype: cfg.dtype,
        mlp: weights,
    };
    let rmse_on = |set: &SetData, x: &[f32]| -> Result<Option<f64>, PipelineError> {
        if set.is_empty() {
            return Ok(None);
        }
        let y = kernel_outputs(&student, x)?;
        Ok(Some(super::rmse(&y, &set.y_label_nm)))
    };
    let val_rmse = rmse_on(&prepared.val, &val_x)?;
    let test_rmse = rmse_on(&prepared.test, &test_x)?;
    student.meta.training.val_rmse_nm = val_rmse.map_or(f32::NAN, |v| v as f32);
    student.meta.training.test_rmse_nm = test_rmse.map_or(f32::NAN, |v| v as f32);
    let gate = gate(
        teacher,
        &student,
        sources,
        &prepared.test,
        &test_x,
        cfg.max_rmse_ratio,
        cfg.min_band_samples,
    )?;
    Ok(Distilled {
        model: student,
        gate,
        rows: (train.len(), cfg.probes),
        best_epoch: outcome.best_epoch,
        val_rmse_nm: val_rmse,
    })
}

/// How to distil without data ([`distill_probes`]): every row is a probe inside the teacher's input
/// range, the teacher's output its only target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProbeDistillConfig {
    /// The student's hyper-parameters (hidden widths, epochs, seed, …; `lambda` is ignored: there is
    /// no label, hence no SCV term).
    pub train: TrainConfig,
    /// Storage dtype of the student.
    pub dtype: StorageDtype,
    /// Training probes.
    pub probes: usize,
    /// Validation probes (a second draw; the weights kept are the best against the teacher on them).
    pub val_probes: usize,
    /// Gate probes (a third draw, never used in training or selection).
    pub test_probes: usize,
    /// The gate: the student's output RMSE against the teacher on the gate probes must be ≤ this \[Nm\].
    pub max_rmse_nm: f64,
    /// How every probe (training, validation, gate) is drawn.
    #[serde(default)]
    pub probe_kind: ProbeKind,
    /// Cosine decay of the learning rate from `train.lr` to this over the epochs (`None`: constant).
    #[serde(default)]
    pub lr_final: Option<f32>,
    /// Where the student starts.
    #[serde(default)]
    pub init: StudentInit,
}

/// The gate of a probe-only distillation: student against teacher inside the teacher's input range,
/// both on the kernel frictiond runs (stored dtype).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProbeGate {
    /// Gate probes.
    pub n: usize,
    /// How they were drawn.
    #[serde(default)]
    pub probe_kind: ProbeKind,
    /// RMS of student − teacher output \[Nm\].
    pub rmse_vs_teacher_nm: f64,
    /// Largest |student − teacher| \[Nm\].
    pub max_abs_vs_teacher_nm: f64,
    /// With trajectory probes: the RMSE on as many uniform probes (reported, not gated) \[Nm\].
    #[serde(default)]
    pub uniform_rmse_vs_teacher_nm: Option<f64>,
    /// Standard deviation of the teacher's output on the probes \[Nm\] (the scale of the function).
    pub teacher_std_nm: f64,
    /// The bound on `rmse_vs_teacher_nm` \[Nm\].
    pub max_rmse_nm: f64,
}

impl ProbeGate {
    /// Whether the student is within the bound (a NaN RMSE fails).
    pub fn passed(&self) -> bool {
        self.rmse_vs_teacher_nm <= self.max_rmse_nm
    }

    /// One line: probes, RMSE, max |Δ|, the teacher's spread and the verdict.
    pub fn line(&self) -> String {
        let uniform = self
            .uniform_rmse_vs_teacher_nm
            .map(|u| format!(" (on uniform probes: {u:.5} Nm, not gated)"))
            .unwrap_or_default();
        format!(
            "gate ({} {} probes in the input range): RMSE vs teacher {:.5} Nm (bound {} Nm), max |Δ| {:.5} Nm, teacher output std {:.5} Nm{}: {}",
            self.n,
            match self.probe_kind {
                ProbeKind::Uniform => "uniform",
                ProbeKind::Trajectory => "trajectory",
            },
            self.rmse_vs_teacher_nm,
            self.max_rmse_nm,
            self.max_abs_vs_teacher_nm,
            self.teacher_std_nm,
            uniform,
            if self.passed() { "ok" } else { "FAIL" }
        )
    }
}

/// The result of [`distill_probes`].
#[derive(Clone, Debug)]
pub struct ProbeDistilled {
    /// The student model, metadata inherited from the teacher, `teacher_sha256` set; its
    /// `val_rmse_nm` / `test_rmse_nm` are its RMSE against the teacher on the validation and gate
    /// probes (there is no label).
    pub model: ModelFile,
    /// The gate.
    pub gate: ProbeGate,
    /// 1-based epoch of the kept weights.
    pub best_epoch: usize,
    /// With [`StudentInit::Prune`]: the pruned start's RMSE against the teacher on the validation
    /// probes, before any training \[Nm\] (f32 math).
    pub start_rmse_vs_teacher_nm: Option<f64>,
}

/// Distils `teacher` without data: training, validation and gate rows are independent draws of
/// [`probe_inputs`] (seeds derived from `cfg.train.seed`), targets the teacher's output. The student
/// keeps the teacher's normalisation and metadata (as [`distill`]) and records `teacher_sha256`; it is
/// returned whether or not the gate passes (the caller writes it only when it does).
pub fn distill_probes(
    teacher: &ModelFile,
    teacher_sha256: [u8; 32],
    cfg: &ProbeDistillConfig,
    on_epoch: impl FnMut(&EpochReport) -> ControlFlow<()>,
) -> Result<ProbeDistilled, PipelineError> {
    if cfg.probes == 0 || cfg.val_probes == 0 || cfg.test_probes == 0 {
        return Err(usage(format!(
            "probe-only distillation needs training, validation and gate probes (got {}, {}, {})",
            cfg.probes, cfg.val_probes, cfg.test_probes
        )));
    }
    if !(cfg.max_rmse_nm.is_finite() && cfg.max_rmse_nm > 0.0) {
        return Err(usage(format!(
            "--max-rmse-nm {}: must be finite and positive",
            cfg.max_rmse_nm
        )));
    }
    let n_in = teacher.mlp.n_inputs();
    let seed = cfg.train.seed;
    let draw = |count: usize, salt: u64| -> Vec<f32> {
        probe_inputs_of_kind(teacher, count, seed ^ salt, cfg.probe_kind)
            .into_iter()
            .flatten()
            .collect()
    };
    let (x, x_val, x_test) = (
        draw(cfg.probes, 0x9E37_79B9),
        draw(cfg.val_probes, 0x85EB_CA6B_0000),
        draw(cfg.test_probes, 0xC2B2_AE35_0000_0000),
    );
    let mut teacher_pred = Predictor::new(&teacher.mlp, cfg.train.threads.max(1))?;
    let y = teacher_pred.predict(&x)?;
    let y_val = teacher_pred.predict(&x_val)?;
    let data = Dataset {
        x: &x,
        y_label_nm: &y,
        y_scv_nm: &y,
        n_inputs: n_in,
    };
    let val = Dataset {
        x: &x_val,
        y_label_nm: &y_val,
        y_scv_nm: &y_val,
        n_inputs: n_in,
    };
    let tcfg = TrainConfig {
        lambda: 0.0,
        ..cfg.train.clone()
    };
    let (mut trainer, start) = student_trainer(&teacher.mlp, cfg.init, tcfg, &data, Some(&val))?;
    let start_rmse_vs_teacher_nm = match &start {
        Some(w) => Some(super::rmse(
            &Predictor::new(w, cfg.train.threads.max(1))?.predict(&x_val)?,
            &y_val,
        )),
        None => None,
    };
    if let Some(end) = cfg.lr_final {
        trainer.set_cosine_decay(end)?;
    }
    let outcome = trainer.train(on_epoch)?;
    let meta = &teacher.meta;
    let mut student = ModelFile {
        meta: ModelMeta {
            training: TrainingMeta {
                dataset_sha256: [0; 32],
                val_rmse_nm: f32::NAN,
                test_rmse_nm: f32::NAN,
                created_unix_s: pipeline::created_unix_s(),
                tool_version: format!("frictl {}", env!("CARGO_PKG_VERSION")),
                filtering: meta.training.filtering,
                input_range: meta.training.input_range,
                quant_max_error_nm: None,
                teacher_sha256: Some(teacher_sha256),
            },
            ..meta.clone()
        },
        dtype: cfg.dtype,
        mlp: round_to_dtype(&outcome.weights, cfg.dtype),
    };
    // Both on the kernel frictiond runs, stored dtypes.
    let t_val = kernel_outputs(teacher, &x_val)?;
    let s_val = kernel_outputs(&student, &x_val)?;
    let t_test = kernel_outputs(teacher, &x_test)?;
    let s_test = kernel_outputs(&student, &x_test)?;
    let rmse_test = super::rmse(&s_test, &t_test);
    student.meta.training.val_rmse_nm = super::rmse(&s_val, &t_val) as f32;
    student.meta.training.test_rmse_nm = rmse_test as f32;
    let max_abs = s_test
        .iter()
        .zip(&t_test)
        .map(|(s, t)| f64::from((s - t).abs()))
        .fold(
            0.0,
            |m: f64, d| if d.is_nan() { f64::NAN } else { m.max(d) },
        );
    // The same student on uniform probes, reported beside a trajectory gate (not gated).
    let uniform_rmse = match cfg.probe_kind {
        ProbeKind::Uniform => None,
        ProbeKind::Trajectory => {
            let x_u: Vec<f32> =
                probe_inputs(teacher, cfg.test_probes, seed ^ 0xD6E8_FEB8_6659_FD93)
                    .into_iter()
                    .flatten()
                    .collect();
            Some(super::rmse(
                &kernel_outputs(&student, &x_u)?,
                &kernel_outputs(teacher, &x_u)?,
            ))
        }
    };
    let n = t_test.len() as f64;
    let mean = t_test.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = t_test
        .iter()
        .map(|&v| (f64::from(v) - mean).powi(2))
        .sum::<f64>()
        / n;
    Ok(ProbeDistilled {
        model: student,
        gate: ProbeGate {
            n: t_test.len(),
            probe_kind: cfg.probe_kind,
            rmse_vs_teacher_nm: rmse_test,
            uniform_rmse_vs_teacher_nm: uniform_rmse,
            max_abs_vs_teacher_nm: max_abs,
            teacher_std_nm: var.sqrt(),
            max_rmse_nm: cfg.max_rmse_nm,
        },
        best_epoch: outcome.best_epoch,
        start_rmse_vs_teacher_nm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random 2·10 + temperature → 8 → 1 network with stored input ranges.
    fn ranged_model() -> ModelFile {
        use frictionless::features::{FeatureSet, FeatureSpec};
        use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
        use frictionless::units::GearRatio;
        use frictionless::weights::{InputRange, ModelMeta, TrainingMeta, layout};
        let features = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 10,
            temperature: true,
        };
        let mut blocks = [[0.0f32; 2]; layout::RANGE_BLOCKS];
        blocks[0] = [-0.05, 0.03];
        blocks[1] = [-2.0, 4.0];
        let mut training = TrainingMeta::unknown("probe test", 0);
        training.input_range = Some(InputRange {
            blocks,
            temperature: [25.0, 60.0],
        });
        let spec = RandomMlpSpec {
            sizes: vec![features.n_inputs(), 8, 1],
            weights: WeightInit::Uniform { amp: 0.5 },
            bias: -0.1..0.1,
            norm: NormInit::Identity,
        };
        ModelFile {
            meta: ModelMeta {
                joint_name: "j".into(),
                gear_ratio: GearRatio::new(-100.0).unwrap(),
                kt_nm_per_a: 0.1,
                features,
                scv: None,
                training,
            },
            dtype: StorageDtype::F32,
            mlp: seeded_mlp(&spec, 1).unwrap(),
        }
    }

    #[test]
    fn trajectory_probes_are_smooth_histories_inside_the_range_and_uniform_ones_are_not() {
        let file = ranged_model();
        let ranges = [[-0.05f32, 0.03], [-2.0, 4.0]];
        // The largest step between adjacent samples of a trajectory, as a share of the range.
        let bound = 0.5 * TRAJECTORY_MAX_RAD_PER_SAMPLE + 2.0 * TRAJECTORY_NOISE_SHARE + 1e-5;
        let steepest = |kind| {
            let rows = probe_inputs_of_kind(&file, 2000, 7, kind);
            let mut worst = 0.0f32;
            for row in &rows {
                assert_eq!(row.len(), 21);
                for (b, r) in ranges.iter().enumerate() {
                    let block = &row[b * 10..b * 10 + 10];
                    assert!(block.iter().all(|v| (r[0]..=r[1]).contains(v)), "{block:?}");
                    for w in block.windows(2) {
                        worst = worst.max((w[1] - w[0]).abs() / (r[1] - r[0]));
                    }
                }
                assert!((25.0..=60.0).contains(&row[20]), "temperature {}", row[20]);
            }
            worst
        };
        let traj = steepest(ProbeKind::Trajectory);
        assert!(traj <= bound, "trajectory step {traj} > {bound}");
        let uni = steepest(ProbeKind::Uniform);
        assert!(uni > 0.9, "uniform probes jump across the range: {uni}");
        // Deterministic in the seed, different across seeds.
        let a = probe_inputs_of_kind(&file, 3, 1, ProbeKind::Trajectory);
        assert_eq!(a, probe_inputs_of_kind(&file, 3, 1, ProbeKind::Trajectory));
        assert_ne!(a, probe_inputs_of_kind(&file, 3, 2, ProbeKind::Trajectory));
    }

    fn row(t: f64, s: f64, gated: bool, r: f64) -> GateRow {
        GateRow {
            what: "x".into(),
            n: 10,
            teacher_rmse_nm: t,
            student_rmse_nm: s,
            gated,
            passed: !gated || s <= r * t,
        }
    }

    #[test]
    fn a_shorter_student_history_reads_the_newest_samples_and_keeps_their_normalisation() {
        let teacher = ranged_model();
        let spec = &teacher.meta.features; // 2 blocks × H 10 + temperature
        let (same, all) = student_inputs(spec, None).unwrap();
        assert_eq!(&same, spec);
        assert_eq!(all, (0..21).collect::<Vec<_>>());
        let (short, cols) = student_inputs(spec, Some(3)).unwrap();
        assert_eq!(short.history, 3);
        assert_eq!(short.n_inputs(), 7);
        // Block b's newest samples are its last columns (oldest first), the temperature last.
        assert_eq!(cols, vec![7, 8, 9, 17, 18, 19, 20]);
        for bad in [0, 11] {
            let e = student_inputs(spec, Some(bad)).unwrap_err().to_string();
            assert!(
                e.contains(&format!("--history {bad}")) && e.contains("10"),
                "{e}"
            );
        }
        // Two rows of 21 inputs whose values are their column numbers (+100 on the second).
        let x: Vec<f32> = (0..42).map(|i| (i % 21 + 100 * (i / 21)) as f32).collect();
        assert_eq!(
            take_columns(&x, 21, &cols),
            [
                7., 8., 9., 17., 18., 19., 20., 107., 108., 109., 117., 118., 119., 120.
            ]
        );
        // The restricted teacher: the kept inputs' normalisation and first-layer columns, and the
        // same output as the full teacher when the dropped inputs sit at their mean.
        let mut w = teacher.mlp.clone();
        w.norm.mean = (0..21).map(|i| 0.1 * i as f32).collect();
        w.norm.scale = (0..21).map(|i| 1.0 + 0.05 * i as f32).collect();
        let r = restricted(&w, &cols);
        assert_eq!(r.n_inputs(), 7);
        assert_eq!(
            r.norm.mean,
            cols.iter().map(|&c| w.norm.mean[c]).collect::<Vec<_>>()
        );
        assert_eq!(
            r.norm.scale,
            cols.iter().map(|&c| w.norm.scale[c]).collect::<Vec<_>>()
        );
        let mut full = w.norm.mean.clone();
        for (k, &c) in cols.iter().enumerate() {
            full[c] += 0.3 * (k as f32 - 3.0);
        }
        let kept = take_columns(&full, 21, &cols);
        let (a, b) = (w.forward_reference(&full)[0], r.forward_reference(&kept)[0]);
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        assert_eq!(restricted(&w, &all), w);
    }

    #[test]
    fn gate_passes_only_when_every_gated_row_does() {
        let g = Gate {
            max_rmse_ratio: 1.05,
            rows: vec![row(1.0, 1.04, true, 1.05), row(1.0, 3.0, false, 1.05)],
        };
        assert!(g.passed());
        let g = Gate {
            max_rmse_ratio: 1.05,
            rows: vec![row(1.0, 1.04, true, 1.05), row(1.0, 1.06, true, 1.05)],
        };
        assert!(!g.passed());
        assert!(g.table().contains("FAIL"));
        assert!(!row(1.0, f64::NAN, true, 1.05).passed, "NaN fails");
    }
}
