//! `frictl convert IN.fwt -o OUT.fwt --dtype f32|f16|bf16|int16|int8|auto [--max-error-nm 0.01]
//! [--dataset FILE]`: re-write a weight file with another storage precision, behind an accuracy gate.
//!
//! The gate compares the converted model with the input model (computed in f32) on a probe set: random
//! inputs drawn uniformly inside the file's stored training input range (`.fwt` ≥ 1.2; every one of a
//! block's H samples inside that block's range, the temperature inside its range) or, for a file
//! without a range, inside mean ± 3·scale of the normalisation; plus, with `--dataset`, every input row
//! the model's feature set builds from that dataset CSV (hold-zero warm-up, Δθ latched at the first
//! row, as `frictl train` builds them). The converted model runs on **every kernel path this CPU
//! has** (the daemon runs the fastest: for int8 with AVX-512 VNNI, u8 activations; int16 gives the
//! same bits on every path); the reference is
//! the input model's f32 reference forward pass. It prints max and p99 |Δτ̂_F| in Nm per path and
//! refuses (non-zero exit, nothing written) when the worst path's max exceeds `--max-error-nm`.
//! `--dtype auto` writes the smallest dtype that passes (int8; then int16, the fastest 2-byte
//! storage; then f16, bf16; f32 when none does). The measured max is stored in the output's
//! `quant_max_error_nm` header field (format ≥ 1.3).
//!
//! Not a quantiser with calibration: f16/bf16 round to nearest-even, int8 and int16 are symmetric per
//! output channel (`max |w| / 127`, `max |w| / 8191`). Biases and the normalisation stay f32 in every
//! dtype.

use anyhow::{Context, bail};
use frictionless::features::WarmupPolicy;
use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::{MlpWeights, StorageDtype};
use frictionless::weights::{self, ModelFile};
use frictionless_dataset::Dataset;
use frictionless_train::data::{DeltaThetaOffset, build_inputs};

/// The error of one converted model on one kernel path.
#[derive(Clone, Copy, Debug)]
pub struct PathError {
    /// The kernel path.
    pub path: KernelPath,
    /// max |Δτ̂_F| over the probe set [Nm].
    pub max_nm: f32,
    /// 99th percentile of |Δτ̂_F| [Nm].
    pub p99_nm: f32,
}

pub use frictionless_train::distill::probe_inputs;

pub use frictl_cli::convert::*;

/// The input rows the model's feature set builds from a dataset CSV. The dataset must suit the
/// model as `frictl eval` requires ([`super::eval::check_pinn_on_dataset`]: its gear ratio, its
/// columns) and contribute at least one row.
fn dataset_inputs(
    model_path: &std::path::Path,
    file: &ModelFile,
    path: &std::path::Path,
) -> anyhow::Result<Vec<Vec<f32>>> {
    let ds = Dataset::read_csv(path).with_context(|| format!("cannot read {}", path.display()))?;
    let side: Option<frictionless_dataset::DatasetSidecar> =
        frictionless::regular_file::read_text(&path.with_extension("json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
    if let Some(w) = super::eval::check_pinn_on_dataset(model_path, file, path, &ds, side.as_ref())?
    {
        eprintln!("frictl convert: warning: {w}");
    }
    let w = build_inputs(
        &ds,
        &file.meta.features,
        file.meta.gear_ratio,
        WarmupPolicy::HoldZero,
        DeltaThetaOffset::Run,
    )
    .with_context(|| format!("{}: cannot build the model's inputs", path.display()))?;
    anyhow::ensure!(
        !w.is_empty(),
        "--dataset {}: contributes 0 input rows ({} rows, {} valid; a row needs to be valid with a full history of {}): nothing to check the conversion on",
        path.display(),
        ds.len(),
        ds.valid.iter().filter(|v| **v).count(),
        file.meta.features.history
    );
    Ok((0..w.len()).map(|i| w.input(i).to_vec()).collect())
}

/// |Δτ̂_F| of `mlp` stored as `dtype` against `reference` (its f32 outputs on `inputs`) on every
/// available kernel path.
pub fn errors_per_path(
    mlp: &MlpWeights,
    dtype: StorageDtype,
    inputs: &[Vec<f32>],
    reference: &[f32],
) -> anyhow::Result<Vec<PathError>> {
    let mut out = Vec::new();
    for path in KernelPath::available() {
        let mut m = Mlp::new(mlp, dtype)?.with_path(path)?;
        let mut e: Vec<f32> = inputs
            .iter()
            .zip(reference)
            .map(|(x, &y)| {
                let d = (m.forward(x) - y).abs();
                if d.is_nan() { f32::INFINITY } else { d }
            })
            .collect();
        e.sort_by(f32::total_cmp);
        let p99 = e
            .get(((e.len() as f64 * 0.99).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(0.0);
        out.push(PathError {
            path,
            max_nm: e.last().copied().unwrap_or(0.0),
            p99_nm: p99,
        });
    }
    Ok(out)
}

/// Runs `frictl convert`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_outputs(&[&args.input], &[&args.output])?;
    if !(args.max_error_nm.is_finite() && args.max_error_nm >= 0.0) {
        bail!(
            "--max-error-nm {}: must be finite and ≥ 0",
            args.max_error_nm
        );
    }
    let mut file = weights::read_file(&args.input)?;
    // Each probe: its inputs and the reference output, then one output per kernel path.
    frictl_cli::count::fits_in_memory(
        &format!("--samples {}", args.samples),
        args.samples,
        (file.mlp.n_inputs() + 8) * std::mem::size_of::<f32>() + std::mem::size_of::<Vec<f32>>(),
        frictl_cli::count::available_memory_bytes(),
    )?;
    let old_dtype = file.dtype;
    let mut inputs = probe_inputs(&file, args.samples, args.seed);
    let n_random = inputs.len();
    if let Some(ds) = &args.dataset {
        inputs.extend(dataset_inputs(&args.input, &file, ds)?);
    }
    if inputs.is_empty() {
        bail!("no probe inputs: use --samples > 0 or --dataset");
    }
    let reference: Vec<f32> = inputs
        .iter()
        .map(|x| file.mlp.forward_reference(x)[0])
        .collect();
    let max_ref = reference.iter().fold(0f32, |m, y| m.max(y.abs()));
    println!(
        "probe set: {n_random} random inputs {} + {} dataset rows; max |τ̂_F| {max_ref:.3} Nm",
        if file.meta.training.input_range.is_some() {
            "inside the training range"
        } else {
            "inside mean ± 3·scale (no training range stored)"
        },
        inputs.len() - n_random
    );
    let candidates: &[StorageDtype] = match args.dtype {
        Target::F32 => &[StorageDtype::F32],
        Target::F16 => &[StorageDtype::F16],
        Target::Bf16 => &[StorageDtype::Bf16],
        Target::Int8 => &[StorageDtype::Int8],
        Target::Int16 => &[StorageDtype::Int16],
        // f32 is the lossless fallback: written whatever its rounding-level difference.
        Target::Auto => &[
            StorageDtype::Int8,
            StorageDtype::Int16,
            StorageDtype::F16,
            StorageDtype::Bf16,
            StorageDtype::F32,
        ],
    };
    let joint = file.meta.joint_name.clone();
    let mut last_refusal = String::new();
    for &dtype in candidates {
        let errs = errors_per_path(&file.mlp, dtype, &inputs, &reference)?;
        for e in &errs {
            println!(
                "{:<5} {:<10} max |Δτ̂_F| {:.3e} Nm, p99 {:.3e} Nm",
                dtype.name(),
                e.path.name(),
                e.max_nm,
                e.p99_nm
            );
        }
        let worst = errs
            .iter()
            .max_by(|a, b| a.max_nm.total_cmp(&b.max_nm))
            .copied()
            .context("no kernel path available")?;
        let lossless_fallback = args.dtype == Target::Auto && dtype == StorageDtype::F32;
        if !(worst.max_nm <= args.max_error_nm || lossless_fallback) {
            last_refusal = format!(
                "model `{joint}` ({}) as {}: max |Δτ̂_F| {:.3e} Nm (path {}) exceeds the bound {:.3e} Nm",
                args.input.display(),
                dtype.name(),
                worst.max_nm,
                worst.path,
                args.max_error_nm
            );
            if args.dtype == Target::Auto {
                println!("{last_refusal}; trying a wider dtype");
            }
            continue;
        }
        file.dtype = dtype;
        file.meta.training.quant_max_error_nm =
            (dtype != StorageDtype::F32).then_some(worst.max_nm);
        weights::write_file(&args.output, &file)?;
        let back = weights::read_file(&args.output)?;
        println!(
            "wrote {}: {} → {} (max |Δτ̂_F| {:.3e} Nm on {}, p99 {:.3e} Nm, bound {:.3e} Nm)",
            args.output.display(),
            old_dtype.name(),
            back.dtype.name(),
            worst.max_nm,
            worst.path,
            worst.p99_nm,
            args.max_error_nm
        );
        return Ok(());
    }
    bail!("{last_refusal}; {} not written", args.output.display())
}
