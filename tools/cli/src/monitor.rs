//! Arguments of `frictl monitor`.

use std::path::PathBuf;

/// Arguments of `frictl monitor`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Service-name prefix of the daemon (`[backend] service_prefix`).
    #[arg(long, default_value = "frictionless")]
    pub prefix: String,
    /// iceoryx2 root path (`[backend] root_path`); default: iceoryx2's.
    #[arg(long)]
    pub root_path: Option<PathBuf>,
    /// Refresh interval [ms].
    #[arg(long, default_value_t = 500)]
    pub interval_ms: u64,
    /// Print one snapshot and exit.
    #[arg(long)]
    pub once: bool,
    /// Give up after this many seconds without a status (0 = wait forever).
    #[arg(long, default_value_t = 10)]
    pub timeout_s: u64,
}
