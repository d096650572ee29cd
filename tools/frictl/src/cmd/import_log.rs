//! `frictl import csv|mat|mcap LOG… -o OUT.csv`: robot logs into the dataset format (CSV + JSON
//! sidecar) that `fit`, `train`, `eval` and `search` read. The arguments are `frictl-cli`'s, the work
//! `frictionless-import`'s.

pub use frictionless_import::{run_csv, run_mat, run_mcap};
pub use frictl_cli::import_log::*;
