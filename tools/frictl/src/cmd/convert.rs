//! `frictl convert IN.fwt -o OUT.fwt --dtype f32|f16|bf16`: re-write a weight file with another
//! storage precision and report how much the outputs move.
//!
//! The output change is measured through the real kernel on random inputs drawn around the model's
//! normalisation statistics (mean + scale·N(0,1)). Biases and normalisation stay f32 in every dtype.
//! Not a quantiser with calibration: rounding is round-to-nearest-even.

use std::path::PathBuf;

use frictionless::kernel::Mlp;
use frictionless::weights;
use frictionless_interop as interop;

use super::import::Dtype;

/// Arguments of `frictl convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The `.fwt` weight file to read.
    pub input: PathBuf,
    /// The `.fwt` file to write.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// Storage precision of the written file.
    #[arg(long, value_enum)]
    pub dtype: Dtype,
    /// Number of random inputs for the output-change report.
    #[arg(long, default_value_t = 1000)]
    pub samples: usize,
    /// Seed of the random inputs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `frictl convert`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_outputs(&[&args.input], &[&args.output])?;
    let mut file = weights::read_file(&args.input)?;
    let old_dtype = file.dtype;
    let mut before = Mlp::new(&file.mlp, old_dtype)?;
    file.dtype = args.dtype.into();
    weights::write_file(&args.output, &file)?;
    let back = weights::read_file(&args.output)?;
    let mut after = Mlp::new(&back.mlp, back.dtype)?;
    let inputs = interop::random_inputs(&file.mlp.norm, args.samples, args.seed);
    let (diff, max_ref) = interop::max_output_change(&mut before, &mut after, &inputs);
    println!(
        "wrote {}: {:?} → {:?}",
        args.output.display(),
        old_dtype,
        back.dtype
    );
    println!(
        "max |Δoutput| on {} random inputs: {diff:.3e} Nm (max |output| {max_ref:.3} Nm, relative {:.3e})",
        args.samples,
        if max_ref > 0.0 { diff / max_ref } else { 0.0 }
    );
    Ok(())
}
