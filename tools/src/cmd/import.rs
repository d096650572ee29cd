//! `frictl import` — not built yet (issue #2).

/// Arguments of `frictl import`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl import`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl import` is not built yet (tracked in issue #2)")
}
