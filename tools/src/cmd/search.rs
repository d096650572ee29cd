//! `frictl search` — not built yet (issue #5).

/// Arguments of `frictl search`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl search`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl search` is not built yet (tracked in issue #5)")
}
