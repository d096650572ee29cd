//! # `frictionless-import`: robot logs into datasets
//!
//! Crate table: `tools/import`. What it **is**: the work behind `frictl import csv|mat|mcap` — the
//! runs `frictionless-logs` reads, labelled by `frictionless-ident`'s one pipeline (the `current`
//! label's τ_ID from the whole robot's state when the log has it, else the single-joint view of the
//! URDF), one dataset and sidecar (`frictionless-dataset`) per labelled joint, written atomically:
//! - [`options`]: what an import is asked to do, as plain values (no argument parser);
//! - [`whole`]: the log held in memory, joints labelled in passes of a few;
//! - [`stream`]: `--window-samples N`, the log read and labelled in windows, never held whole;
//! - [`urdf`]: the robot from `--urdf` and `--fixed-joint` (also `frictl preprocess`'s);
//! - `shared` (private, below both imports): output paths, per-joint values, the plausibility
//!   checks, the inputs' sidecar and the committing of a dataset with its sidecar;
//! - [`check_outputs`]: the refusal, before any work, of an output that would overwrite an input.
//!
//! It takes [`options`] (which `frictl-cli` fills from the command line) and reports with `anyhow`.
//! What it is **not**: an argument parser, a log reader (`frictionless-logs`) or the label pipeline
//! (`frictionless-ident`); formats, roles and units are in `docs/robot-logs.md`.

#![warn(missing_docs)]

pub mod options;
mod shared;
pub mod stream;
pub mod urdf;
pub mod whole;

pub use options::{CommonOptions, CsvOptions, MatOptions, McapOptions};
pub use urdf::{gravity_m_s2, parse_fixed_joints, urdf_link, urdf_whole_body};
pub use whole::{run_csv, run_mat, run_mcap};

/// Refuses, before any work, an output that would overwrite one of the command's inputs (the same file
/// by device and inode, whatever the spelling of the path), that is another output of the command
/// (the same canonical path, e.g. `--report R -o R`), whose directory does not exist, or that
/// exists and is not a regular file or is a symlink ([`frictionless::output_file::check`]: the
/// file is written through that module, which checks again). Every
/// command that reads files and writes others calls it first with every file it reads, the implicit
/// ones included (sidecars, a model's training report), so a mistake such as
/// `frictl preprocess log.csv -o log.csv` loses nothing and a long run does not fail at its end.
pub fn check_outputs(
    inputs: &[&std::path::Path],
    outputs: &[&std::path::Path],
) -> anyhow::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let id = |p: &std::path::Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    // The canonical directory and file name: equal for two spellings of one path, existing or not.
    let canonical = |p: &std::path::Path| {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => std::path::Path::new("."),
        };
        std::fs::canonicalize(dir)
            .ok()
            .map(|d| (d, p.file_name().map(|n| n.to_os_string())))
    };
    for (k, out) in outputs.iter().enumerate() {
        if let Some(other) = outputs[..k].iter().find(|o| {
            (canonical(o).is_some() && canonical(o) == canonical(out))
                || id(o).is_some_and(|i| id(out) == Some(i))
        }) {
            anyhow::bail!(
                "{}: is also another output of this command ({}); refusing to write both to one \
                 file (nothing was written)",
                out.display(),
                other.display()
            );
        }
        let dir = match out.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => std::path::Path::new("."),
        };
        anyhow::ensure!(
            dir.is_dir(),
            "{}: the output directory {} does not exist",
            out.display(),
            dir.display()
        );
        frictionless::output_file::check(out)
            .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
        let Some(out_id) = id(out) else { continue };
        if let Some(input) = inputs.iter().find(|i| id(i) == Some(out_id)) {
            anyhow::bail!(
                "{}: is also an input of this command ({}); refusing to overwrite it (nothing was written)",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}
