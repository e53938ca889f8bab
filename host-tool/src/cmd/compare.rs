//! `trueaxis compare` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis compare`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis compare` is not implemented yet")
    }
}
