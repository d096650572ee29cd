//! Arguments of `frictl inspect`.

use std::path::PathBuf;

/// Arguments of `frictl inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The `.fwt` weight file.
    pub file: PathBuf,
    /// Print the view as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}
