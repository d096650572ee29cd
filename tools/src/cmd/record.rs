//! `frictl record` — not built yet (issue #4).

/// Arguments of `frictl record`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl record`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl record` is not built yet (tracked in issue #4)")
}
