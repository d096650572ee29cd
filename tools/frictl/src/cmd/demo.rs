//! `frictl demo` — the whole method end to end on the virtual joints: the pipeline
//! (`frictionless_pipeline::demo`) runs every stage as a child of this executable.

pub use frictl_cli::demo::*;

/// Runs `frictl demo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    frictionless_pipeline::demo::run(args, &super::host::Frictl)
}
