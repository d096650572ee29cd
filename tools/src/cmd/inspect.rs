//! `frictl inspect` — not built yet (issue #2).

/// Arguments of `frictl inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl inspect`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl inspect` is not built yet (tracked in issue #2)")
}
