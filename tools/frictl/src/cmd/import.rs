//! `frictl import onnx|safetensors IN -o OUT.fwt …`: a foreign model into a `.fwt` weight file;
//! `frictl import csv|mat|mcap LOG… -o OUT.csv …`: robot logs into a dataset (`super::import_log`).
//!
//! The network comes from [`frictionless_interop`]; the metadata a foreign file lacks (joint, signed gear
//! ratio, k_t, feature set, history) comes from the command line, falling back to `frictionless.*`
//! metadata written by `frictl export`. The history is inferred from the input width when omitted and
//! unambiguous. After writing, the file is read back and its kernel compared with the imported f32
//! network on random inputs. Not a trainer; no ONNX Runtime involved.

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, bail};
use frictionless::features::{FeatureSet, FeatureSpec};
use frictionless::kernel::Mlp;
use frictionless::mlp::{MlpWeights, StorageDtype};
use frictionless::units::GearRatio;
use frictionless::weights::{self, InputRange, ModelFile, ModelMeta, TrainingMeta};
use frictionless_interop::{self as interop, ModelHints, onnx, safetensors};

pub use frictl_cli::import::*;

/// Arguments of `frictl import`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to import.
    #[command(subcommand)]
    pub what: What,
}

/// The `frictl import` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// A model from ONNX (PyTorch export: Gemm/MatMul+Add/Relu chain) into a .fwt file.
    Onnx(ModelArgs),
    /// A model from safetensors (PyTorch nn.Sequential state dict) into a .fwt file.
    Safetensors(ModelArgs),
    /// CSV logs (any column names and units) into a dataset.
    Csv(super::import_log::CsvArgs),
    /// The YARP robot logger's MATLAB v7.3 files into a dataset (cargo feature `mat`).
    Mat(super::import_log::MatArgs),
    /// ROS 2 MCAP bags of sensor_msgs/JointState into a dataset.
    Mcap(super::import_log::McapArgs),
}

/// Parses `--input-range` for `spec`: `MIN:MAX` per block, then the temperature's if any.
fn parse_input_range(text: &str, spec: &FeatureSpec) -> anyhow::Result<InputRange> {
    let pairs: Vec<[f32; 2]> = text
        .split(',')
        .map(|p| {
            let (lo, hi) = p
                .split_once(':')
                .with_context(|| format!("--input-range: `{p}` is not MIN:MAX"))?;
            let v = |x: &str| {
                x.trim()
                    .parse::<f32>()
                    .with_context(|| format!("--input-range: `{x}` is not a number"))
            };
            Ok([v(lo)?, v(hi)?])
        })
        .collect::<anyhow::Result<_>>()?;
    let n_blocks = spec.set.n_blocks();
    let want = n_blocks + usize::from(spec.temperature);
    if pairs.len() != want {
        bail!(
            "--input-range: {} ranges given, {spec} needs {want} ({} block(s){})",
            pairs.len(),
            n_blocks,
            if spec.temperature {
                " + temperature"
            } else {
                ""
            }
        );
    }
    let mut r = InputRange {
        blocks: [[0.0; 2]; weights::RANGE_BLOCKS],
        temperature: [0.0; 2],
    };
    r.blocks[..n_blocks].copy_from_slice(&pairs[..n_blocks]);
    if spec.temperature {
        r.temperature = pairs[n_blocks];
    }
    Ok(r)
}

/// The network and metadata hints read from a foreign file, plus a one-line summary.
pub(crate) fn load_foreign(
    format: Format,
    path: &Path,
) -> anyhow::Result<(MlpWeights, ModelHints, String)> {
    let p = path.display();
    match format {
        Format::Onnx => {
            let imp = onnx::import_file(path)?;
            let hints = ModelHints::from_pairs(&imp.metadata)
                .map_err(|(k, v)| anyhow::anyhow!("{p}: metadata `{k}` = `{v}` does not parse"))?;
            let summary = format!(
                "ONNX opset {} (IR {}, producer `{}`), input `{}`, output `{}`, batch {}, normalisation {}",
                imp.opset,
                imp.ir_version,
                imp.producer,
                imp.input_name,
                imp.output_name,
                imp.batch_dim
                    .map_or("dynamic".to_string(), |b| b.to_string()),
                if imp.normalisation_found {
                    "folded out of the graph"
                } else {
                    "none (identity)"
                }
            );
            Ok((imp.mlp, hints, summary))
        }
        Format::Safetensors => {
            let imp = safetensors::import_file(path)?;
            let hints = ModelHints::from_pairs(&imp.metadata)
                .map_err(|(k, v)| anyhow::anyhow!("{p}: metadata `{k}` = `{v}` does not parse"))?;
            let mut summary = format!(
                "safetensors state dict, prefix `{}`, Linear index spacing {}, normalisation from {:?}",
                imp.prefix, imp.spacing, imp.norm_source
            );
            if !imp.ignored.is_empty() {
                summary.push_str(&format!(", ignored tensors: {}", imp.ignored.join(", ")));
            }
            Ok((imp.mlp, hints, summary))
        }
    }
}

/// Picks H for `n` inputs: the given one (checked), else the hint (checked), else n/2 or (n−1)/2.
pub(crate) fn resolve_history(
    n_inputs: usize,
    n_blocks: usize,
    temperature: bool,
    history: Option<usize>,
    hint: Option<usize>,
) -> anyhow::Result<usize> {
    let t = usize::from(temperature);
    let b = n_blocks.max(1);
    let check = |h: usize, source: &str| -> anyhow::Result<usize> {
        if h == 0 || b * h + t != n_inputs {
            bail!(
                "{source} {h}{} needs {} inputs ({b} block(s) of H), but the model has {n_inputs}",
                if temperature { " with temperature" } else { "" },
                b * h + t
            );
        }
        Ok(h)
    };
    if let Some(h) = history {
        return check(h, "--history");
    }
    if let Some(h) = hint {
        return check(h, "metadata `frictionless.history` =");
    }
    if n_inputs > t && (n_inputs - t).is_multiple_of(b) {
        Ok((n_inputs - t) / b)
    } else {
        bail!(
            "cannot infer the history from {n_inputs} inputs{} and {b} block(s): one extra input means temperature (pass --temperature) — or give --history",
            if temperature { " with temperature" } else { "" }
        )
    }
}

/// Runs `frictl import`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Onnx(a) => run_model(Format::Onnx, a),
        What::Safetensors(a) => run_model(Format::Safetensors, a),
        What::Csv(a) => super::import_log::run_csv(a.options()),
        What::Mat(a) => super::import_log::run_mat(a.options()),
        What::Mcap(a) => super::import_log::run_mcap(a.options()),
    }
}

/// Runs `frictl import onnx|safetensors`.
fn run_model(format: Format, args: ModelArgs) -> anyhow::Result<()> {
    super::check_outputs(&[&args.input], &[&args.output])?;
    let (mlp, hints, summary) = load_foreign(format, &args.input)?;
    let inp = args.input.display();
    let n = mlp.n_inputs();
    let temperature = args.temperature || hints.temperature.unwrap_or(false);
    let set: FeatureSet = match (args.features, hints.features) {
        (Some(f), _) => f.into(),
        (None, Some(f)) => f,
        (None, None) => bail!("{inp}: the file does not say its feature set; pass --features"),
    };
    let history = resolve_history(n, set.n_blocks(), temperature, args.history, hints.history)
        .with_context(|| format!("{inp}"))?;
    let joint_name = args
        .joint
        .or(hints.joint_name)
        .with_context(|| format!("{inp}: the file does not name its joint; pass --joint"))?;
    let r = args.gear_ratio.or(hints.gear_ratio).with_context(|| {
        format!("{inp}: the file does not give the gear ratio; pass --gear-ratio")
    })?;
    let gear_ratio = GearRatio::new(r).map_err(|e| anyhow::anyhow!("--gear-ratio: {e}"))?;
    let kt = args
        .kt
        .or(hints.kt_nm_per_a)
        .with_context(|| format!("{inp}: the file does not give k_t; pass --kt"))?;
    if !(kt.is_finite() && kt > 0.0) {
        bail!("--kt {kt}: the torque constant must be finite and positive");
    }
    let features = FeatureSpec {
        set,
        history,
        temperature,
    };
    let mut training = TrainingMeta::unknown(
        format!("frictl {}", env!("CARGO_PKG_VERSION")),
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    );
    training.input_range = args
        .input_range
        .as_deref()
        .map(|t| parse_input_range(t, &features))
        .transpose()?;
    let file = ModelFile {
        meta: ModelMeta {
            joint_name,
            gear_ratio,
            kt_nm_per_a: kt,
            features,
            scv: None,
            training,
        },
        dtype: args.dtype.into(),
        mlp,
    };
    weights::write_file(&args.output, &file)?;
    // Read back and compare the stored model with the imported f32 network.
    let back = weights::read_file(&args.output)?;
    let mut imported = Mlp::new(&file.mlp, StorageDtype::F32)?;
    let mut stored = Mlp::new(&back.mlp, back.dtype)?;
    let inputs = interop::random_inputs(&file.mlp.norm, 256, 1);
    let (diff, max_ref) = interop::max_output_change(&mut imported, &mut stored, &inputs);
    let sizes: Vec<String> = back.mlp.sizes().iter().map(|s| s.to_string()).collect();
    println!("read   {inp}: {summary}");
    println!(
        "wrote  {}: {} ({:?}), {} params, features {} H={} temperature={}",
        args.output.display(),
        sizes.join(" → "),
        back.dtype,
        back.mlp.n_params(),
        set,
        history,
        temperature
    );
    println!(
        "check  max |Δoutput| vs imported f32 on 256 random inputs: {diff:.3e} Nm (max |output| {max_ref:.3} Nm)"
    );
    if !diff.is_finite() {
        bail!(
            "{}: the stored model gives non-finite outputs",
            args.output.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_range_parses_per_block_then_temperature() {
        let spec = FeatureSpec {
            set: FeatureSet::DeltaThetaJointVel,
            history: 4,
            temperature: true,
        };
        let r = parse_input_range("-0.05:0.05, -2:2.5,20:45", &spec).unwrap();
        assert_eq!(r.blocks, [[-0.05, 0.05], [-2.0, 2.5], [0.0, 0.0]]);
        assert_eq!(r.temperature, [20.0, 45.0]);
        let e = parse_input_range("-1:1,-2:2", &spec)
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 ranges given") && e.contains("needs 3"), "{e}");
        assert!(parse_input_range("-1:1,x:2,1:2", &spec).is_err());
        assert!(parse_input_range("-1,1", &spec).is_err());
    }

    /// `frictl import csv` as a stage (the torque-sensed demo runs it): argv → clap → the same value.
    #[test]
    fn the_import_csv_stage_gives_its_arguments_back() {
        use super::super::import_log;
        use frictl_cli::stage::{argv, defaults, roundtrip};
        let p = std::path::PathBuf::from;
        let mut common: import_log::CommonArgs = defaults().unwrap();
        common.out = p("ds_{joint}.csv");
        common.label = Some(import_log::LabelArg::TorqueSensor);
        common.gear_ratio = vec!["-100".into(), "l_knee=-160".into()];
        common.fixed_joints = vec!["r_knee=-0.5".into()];
        common.gap_s = Some(-1.0);
        let args = import_log::CsvArgs {
            files: vec![p("a.csv"), p("-b.csv")],
            joint: vec!["l_knee".into()],
            columns: vec!["time=t".into()],
            delimiter: ';',
            common,
            ..defaults().unwrap()
        };
        let words = argv(&["import", "csv"], &args).expect("argv");
        let back: import_log::CsvArgs = roundtrip(2, &words).expect("roundtrip");
        assert_eq!(
            serde_json::to_value(&args).unwrap(),
            serde_json::to_value(&back).unwrap(),
            "{words:?}"
        );
    }
}
