//! `trueaxis upload` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis upload`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis upload` is not implemented yet")
    }
}
