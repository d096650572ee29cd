//! `frictl eval` — not built yet (issue #5).

/// Arguments of `frictl eval`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl eval`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl eval` is not built yet (tracked in issue #5)")
}
