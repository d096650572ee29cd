//! `frictl sim` — not built yet (issue #3).

/// Arguments of `frictl sim`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl sim`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl sim` is not built yet (tracked in issue #3)")
}
