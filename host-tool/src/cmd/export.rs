//! `trueaxis export` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis export`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis export` is not implemented yet")
    }
}
