//! `frictl fit` — not built yet (issue #5).

/// Arguments of `frictl fit`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl fit`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl fit` is not built yet (tracked in issue #5)")
}
