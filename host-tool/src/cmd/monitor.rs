//! `trueaxis monitor` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis monitor`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis monitor` is not implemented yet")
    }
}
