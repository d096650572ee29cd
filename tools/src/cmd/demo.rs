//! `frictl demo` — not built yet (issue #7).

/// Arguments of `frictl demo`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `frictl demo`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`frictl demo` is not built yet (tracked in issue #7)")
}
