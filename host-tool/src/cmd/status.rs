//! `trueaxis status` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis status`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis status` is not implemented yet")
    }
}
