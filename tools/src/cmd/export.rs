//! `frictl export` — not built yet (issue #2).

/// Arguments of `frictl export`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl export`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl export` is not built yet (tracked in issue #2)")
}
