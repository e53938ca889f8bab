//! `trueaxis iso230` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis iso230`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis iso230` is not implemented yet")
    }
}
