//! # `frictl-cli`: frictl's command line
//!
//! What it **is**: every `frictl` subcommand's clap arguments (the `Args` structs and their value
//! enums, one module per subcommand, named after it) and the typed stage builder ([`stage::argv`]),
//! which turns a stage's `Args` value into the command line of a child `frictl`. The pipelines
//! (`frictionless-pipeline`) build their stages from these types, so a renamed or retyped argument
//! fails to compile there.
//!
//! What it is **not**: it does no work. The `frictl` binary parses these arguments and calls the
//! library crates of `tools/`; the work of `frictl import csv|mat|mcap` is
//! `frictionless-import`'s.

#![warn(missing_docs)]
// The arguments' doc comments are clap's `--help` text, which writes units as `[ms]`: not links.
#![allow(rustdoc::broken_intra_doc_links)]

pub mod acquire;
pub mod can;
pub mod config;
pub mod convert;
pub mod count;
pub mod ctl;
pub mod demo;
pub mod distill;
pub mod dynamics;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod fit;
pub mod import;
pub mod import_log;
pub mod inspect;
pub mod monitor;
pub mod predict;
pub mod preprocess;
pub mod record;
pub mod robot;
pub mod search;
pub mod sim;
pub mod stage;
pub mod train;
