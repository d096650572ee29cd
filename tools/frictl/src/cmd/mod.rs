//! One module per subcommand: each has its clap `Args` and a `run`.

pub mod acquire;
pub mod can;
pub mod convert;
pub mod demo;
pub mod dynamics;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod fit;
pub mod import;
pub mod inspect;
pub mod monitor;
pub mod predict;
pub mod preprocess;
pub mod record;
pub mod search;
pub mod sim;
pub mod train;
