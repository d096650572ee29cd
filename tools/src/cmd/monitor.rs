//! `frictl monitor` — not built yet (issue #4).

/// Arguments of `frictl monitor`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl monitor`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl monitor` is not built yet (tracked in issue #4)")
}
