//! Arguments of `frictl can`.

use std::path::PathBuf;

/// Arguments of `frictl can`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// `frictl can` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Record frames from IFACE into FILE (candump -L format).
    Record {
        /// CAN interface, e.g. can0 or vcan0.
        iface: String,
        /// Output log file.
        file: PathBuf,
        /// Stop after this many frames (0 = no limit).
        #[arg(long, default_value_t = 0)]
        count: u64,
        /// Stop after this many seconds.
        #[arg(long)]
        seconds: Option<f64>,
    },
    /// Replay FILE, paced by its timestamps.
    Replay {
        /// Log file (candump -L format).
        file: PathBuf,
        /// Send everything on this interface instead of the one named in each line.
        #[arg(long)]
        iface: Option<String>,
        /// Repeat forever.
        #[arg(long = "loop")]
        repeat: bool,
        /// Time scale: 2 = twice as fast.
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
}
