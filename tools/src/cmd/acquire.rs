//! `frictl acquire` — not built yet (issue #3).

/// Arguments of `frictl acquire`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl acquire`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl acquire` is not built yet (tracked in issue #3)")
}
