//! `frictl export onnx|safetensors IN.fwt -o OUT`: a `.fwt` model for other tools.
//!
//! ONNX: a `Gemm`/`Relu` graph (input `input` `[batch, n]`, output `output` `[batch, 1]`, opset 13,
//! dynamic batch) with the normalisation as `Sub`+`Div` (default) or a diagonal `Gemm`, so the model
//! can be checked with ONNX Runtime. safetensors: a PyTorch `nn.Sequential` state dict (`0.weight`,
//! `0.bias`, `2.weight`, …, plus `norm.mean`/`norm.scale`). Both carry the joint metadata. Reduced
//! precision weights are exported as the f32 values they decode to. Not an importer.

use anyhow::Context;
use frictionless_interop::{META_PREFIX, ModelHints, onnx, safetensors};

pub use frictl_cli::export::*;

/// Runs `frictl export`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_outputs(&[&args.input], &[&args.output])?;
    let file = frictionless::weights::read_file(&args.input)?;
    let mut meta = ModelHints::from_meta(&file.meta).to_pairs();
    meta.push((
        format!("{META_PREFIX}storage_dtype"),
        format!("{:?}", file.dtype).to_lowercase(),
    ));
    let bytes = match args.format {
        Format::Onnx => {
            let opts = onnx::ExportOptions {
                norm: match args.norm {
                    Norm::SubDiv => onnx::NormExport::SubDiv,
                    Norm::DiagonalGemm => onnx::NormExport::DiagonalGemm,
                },
                metadata: meta,
            };
            onnx::export_bytes(&file.mlp, &opts)
                .with_context(|| format!("exporting {}", args.input.display()))?
        }
        Format::Safetensors => safetensors::export_bytes(&file.mlp, &meta)
            .with_context(|| format!("exporting {}", args.input.display()))?,
    };
    frictionless::output_file::write(&args.output, &bytes)
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    let sizes: Vec<String> = file.mlp.sizes().iter().map(|s| s.to_string()).collect();
    println!(
        "wrote {} ({:?}, {} bytes): {}",
        args.output.display(),
        args.format,
        bytes.len(),
        sizes.join(" → ")
    );
    Ok(())
}
