//! One module per subcommand: each has its clap `Args` and a `run`.

pub mod acquire;
pub mod can;
pub mod convert;
pub mod demo;
pub mod distill;
pub mod dynamics;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod fit;
mod host;
pub mod import;
pub mod import_log;
mod import_stream;
pub mod inspect;
pub mod monitor;
pub mod predict;
pub mod preprocess;
pub mod record;
pub mod robot;
pub mod search;
pub mod sim;
pub mod train;

pub use frictl_cli::stage;

/// Refuses, before any work, an output that would overwrite one of the command's inputs (the same file
/// by device and inode, whatever the spelling of the path), whose directory does not exist, or that
/// exists and is not a regular file or is a symlink ([`frictionless::output_file::check`]: the
/// file is written through that module, which checks again). Every
/// command that reads files and writes others calls it first, so a mistake such as
/// `frictl preprocess log.csv -o log.csv` loses nothing and a long run does not fail at its end.
pub fn check_outputs(
    inputs: &[&std::path::Path],
    outputs: &[&std::path::Path],
) -> anyhow::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let id = |p: &std::path::Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    for out in outputs {
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
