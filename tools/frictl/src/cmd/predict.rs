//! `frictl predict FILE --input vectors.csv`: run a model on raw input vectors, one output per line.
//!
//! FILE is a `.fwt` weight file, or an `.onnx` / `.safetensors` file imported on the fly (f32). Each
//! CSV row (no header) is one raw, un-normalised input vector; each output line is the joint-side
//! friction torque [Nm] printed with Rust's shortest round-trip f32 formatting. The computation is
//! the real inference kernel ([`frictionless::kernel::Mlp`]), not a reference loop.

use std::io::{BufWriter, Write};

use anyhow::{Context, bail};
use frictionless::kernel::Mlp;
use frictionless::mlp::StorageDtype;

use super::import::{Format, load_foreign};

pub use frictl_cli::predict::*;

/// Runs `frictl predict`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let ext = args
        .file
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mut mlp = match ext.as_deref() {
        Some("onnx") => {
            let (w, _, _) = load_foreign(Format::Onnx, &args.file)?;
            Mlp::new(&w, StorageDtype::F32)?
        }
        Some("safetensors") => {
            let (w, _, _) = load_foreign(Format::Safetensors, &args.file)?;
            Mlp::new(&w, StorageDtype::F32)?
        }
        _ => {
            let f = frictionless::weights::read_file(&args.file)?;
            Mlp::new(&f.mlp, f.dtype)?
        }
    };
    let csv_name = args.input.display();
    let (input, _) = frictionless::regular_file::open(&args.input)
        .with_context(|| format!("cannot read {csv_name}"))?;
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(input);
    let n = mlp.n_inputs();
    let mut out = BufWriter::new(std::io::stdout().lock());
    let mut x = Vec::with_capacity(n);
    let mut rows = 0usize;
    for (row, rec) in reader.records().enumerate() {
        rows += 1;
        let line = row + 1;
        let rec = rec.with_context(|| format!("{csv_name}: row {line}"))?;
        if rec.len() != n {
            bail!(
                "{csv_name}: row {line} has {} values, the model takes {n}",
                rec.len()
            );
        }
        x.clear();
        for (col, field) in rec.iter().enumerate() {
            let v: f32 = field.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{csv_name}: row {line}, column {}: `{field}` is not a number",
                    col + 1
                )
            })?;
            if !v.is_finite() {
                bail!(
                    "{csv_name}: row {line}, column {}: `{field}` is not finite",
                    col + 1
                );
            }
            x.push(v);
        }
        let y = mlp.forward(&x);
        writeln!(out, "{y:?}")?;
    }
    out.flush()?;
    if rows == 0 {
        bail!("{csv_name}: no rows (the model takes {n} values per row)");
    }
    Ok(())
}
