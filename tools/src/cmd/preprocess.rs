//! `frictl preprocess` — not built yet (issue #5).

/// Arguments of `frictl preprocess`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl preprocess`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl preprocess` is not built yet (tracked in issue #5)")
}
