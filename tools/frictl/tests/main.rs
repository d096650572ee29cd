//! Integration tests of `frictl`: the binary as a process (`CARGO_BIN_EXE_frictl`), the plant server, experiments with `frictiond`.
//!
//! One test binary for the crate (one link step); each module tests one area.

mod acquire_live;
mod acquire_protocol;
mod cli_models;
mod demo_chain;
mod docs_workflow;
mod dynamics_cli;
mod eval_drift;
mod eval_synthetic;
mod experiment_controller;
mod experiment_leg;
mod experiment_online_offline;
mod experiment_oracle;
mod files_cli;
mod fit_lugre;
mod fit_scv;
mod import_cli;
mod leg_frictiond;
mod onpolicy_cli;
mod plant_common;
mod preprocess_cli;
mod replay_cli;
mod robot_cli;
mod search_cli;
mod sim_serve_shm;
mod train_cli;
mod train_one_recording;
mod train_split;
mod util;
mod vcan_cia402_canopen;
mod vcan_sim_serve;
