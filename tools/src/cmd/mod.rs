//! One module per subcommand: each has its clap `Args` and a `run`.

pub mod inspect;
pub mod import;
pub mod export;
pub mod convert;
pub mod predict;
pub mod dynamics;
pub mod sim;
pub mod acquire;
pub mod preprocess;
pub mod fit;
pub mod train;
pub mod search;
pub mod eval;
pub mod experiment;
pub mod monitor;
pub mod record;
pub mod can;
pub mod demo;
