//! `trueaxis history` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis history`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis history` is not implemented yet")
    }
}
