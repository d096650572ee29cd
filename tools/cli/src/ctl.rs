//! Arguments of `frictl ctl`.

use std::path::PathBuf;

/// Arguments of `frictl ctl`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Service-name prefix of the daemon (`[backend] service_prefix`).
    #[arg(long, default_value = "frictionless", global = true)]
    pub prefix: String,
    /// iceoryx2 root path (`[backend] root_path`); default: iceoryx2's.
    #[arg(long, global = true)]
    pub root_path: Option<PathBuf>,
    /// How long to wait for the daemon's answer [ms].
    #[arg(long, default_value_t = 2000, global = true)]
    pub timeout_ms: u64,
    /// What to do.
    #[command(subcommand)]
    pub command: CtlCommand,
}

/// `frictl ctl get|set`.
#[derive(clap::Subcommand, Debug)]
pub enum CtlCommand {
    /// A joint's values in use (and since when each was set at run time).
    Get {
        /// The joint (`[[joint]] name`).
        joint: String,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Set values of a joint: `kfc`, `max_output_friction`, `max_curr`, `compensation=on|off`,
    /// `ood=off|flag|static` (checked by the config's rules; applied from the next tick until a
    /// reload).
    Set {
        /// The joint (`[[joint]] name`).
        joint: String,
        /// `KEY=VALUE` pairs, sent in order; the first refusal stops.
        #[arg(required = true, value_name = "KEY=VALUE")]
        pairs: Vec<String>,
    },
}
