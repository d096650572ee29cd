//! Arguments of `frictl record`.

use std::path::PathBuf;

/// Arguments of `frictl record`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Service-name prefix of the daemon.
    #[arg(long, default_value = "frictionless")]
    pub prefix: String,
    /// iceoryx2 root path; default: iceoryx2's.
    #[arg(long)]
    pub root_path: Option<PathBuf>,
    /// Number of joints to record (indices 0..n).
    #[arg(long, default_value_t = 2)]
    pub joints: usize,
    /// Stop after this many seconds (0 = until a signal).
    #[arg(long, default_value_t = 0.0)]
    pub duration_s: f64,
    /// Stop after this many rows (0 = unlimited).
    #[arg(long, default_value_t = 0)]
    pub max_rows: u64,
}
