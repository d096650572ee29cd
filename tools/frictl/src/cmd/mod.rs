//! One module per subcommand: its clap `Args` (from `frictl-cli`) and a `run` that calls the crates
//! doing the work.

pub mod acquire;
pub mod can;
pub mod config;
pub mod convert;
pub mod ctl;
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
pub mod inspect;
pub mod monitor;
pub mod predict;
pub mod preprocess;
pub mod record;
pub mod replay;
pub mod robot;
pub mod search;
pub mod sim;
pub mod train;

pub use frictl_cli::stage;

pub use frictionless_import::check_outputs;
