//! `trueaxis diagnose` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis diagnose`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis diagnose` is not implemented yet")
    }
}
