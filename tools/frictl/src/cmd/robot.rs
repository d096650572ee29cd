//! `frictl robot` — a whole robot from one TOML file (schema: `frictionless_pipeline::robot`): the
//! pipeline (`frictionless_pipeline::robot_run`) runs every joint's stages as children of this
//! executable, or prints the plan.

pub use frictl_cli::robot::*;

/// Runs `frictl robot`.
pub fn run(args: Args) -> anyhow::Result<()> {
    frictionless_pipeline::robot_run::run(args, &super::host::Frictl)
}
