//! `frictl dynamics` — not built yet (issue #3).

/// Arguments of `frictl dynamics`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl dynamics`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl dynamics` is not built yet (tracked in issue #3)")
}
