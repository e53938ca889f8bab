//! `trueaxis simulate` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis simulate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis simulate` is not implemented yet")
    }
}
