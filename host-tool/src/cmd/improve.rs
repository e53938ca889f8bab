//! `trueaxis improve` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis improve`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis improve` is not implemented yet")
    }
}
