//! `trueaxis fit` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis fit`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis fit` is not implemented yet")
    }
}
