//! `frictl experiment` — not built yet (issue #7).

/// Arguments of `frictl experiment`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl experiment`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl experiment` is not built yet (tracked in issue #7)")
}
