//! `trueaxis import` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis import`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis import` is not implemented yet")
    }
}
