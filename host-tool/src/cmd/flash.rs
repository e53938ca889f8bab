//! `trueaxis flash` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis flash`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis flash` is not implemented yet")
    }
}
