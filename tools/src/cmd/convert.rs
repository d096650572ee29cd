//! `frictl convert` — not built yet (issue #2).

/// Arguments of `frictl convert`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl convert`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl convert` is not built yet (tracked in issue #2)")
}
