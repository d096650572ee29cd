//! `frictl train` — not built yet (issue #5).

/// Arguments of `frictl train`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl train`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl train` is not built yet (tracked in issue #5)")
}
