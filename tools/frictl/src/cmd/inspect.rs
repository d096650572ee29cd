//! `frictl inspect FILE [--json]`: a `.fwt` file's header, shapes, metadata and CRC status.
//!
//! Uses [`frictionless::weights::inspect`], which tolerates a bad CRC or a truncated payload so the
//! header can still be shown; the command then exits non-zero with the problem. Not a converter.

use anyhow::Context;

pub use frictl_cli::inspect::*;

/// Runs `frictl inspect`: prints the view, then fails if the file is not valid.
pub fn run(args: Args) -> anyhow::Result<()> {
    let path = args.file.display();
    // Regular files only, bounded (a FIFO or /dev/zero is refused before any read).
    let bytes = frictionless::weights::read_regular_bounded(&args.file)?;
    let view = frictionless::weights::inspect(&bytes)
        .with_context(|| format!("{path}: not a readable .fwt weight file"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&view)?);
    } else {
        println!("file           {path}");
        println!("{view}");
    }
    if let Some(e) = &view.error {
        anyhow::bail!("{path}: invalid .fwt file: {e}");
    }
    if !view.crc_ok {
        anyhow::bail!(
            "{path}: CRC-32C mismatch (stored {:#010x}, computed {:#010x})",
            view.crc_stored,
            view.crc_computed
        );
    }
    Ok(())
}
