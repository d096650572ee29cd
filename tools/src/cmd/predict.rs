//! `frictl predict` — not built yet (issue #2).

/// Arguments of `frictl predict`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl predict`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl predict` is not built yet (tracked in issue #2)")
}
