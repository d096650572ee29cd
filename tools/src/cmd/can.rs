//! `frictl can` — not built yet (issue #6).

/// Arguments of `frictl can`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl can`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl can` is not built yet (tracked in issue #6)")
}
