//! `trueaxis demo` — placeholder until its issue lands; fails loudly.

/// Arguments of `trueaxis demo`.
#[derive(clap::Args, Debug)]
pub struct Args {}

impl Args {
    pub fn run(self) -> anyhow::Result<()> {
        anyhow::bail!("`trueaxis demo` is not implemented yet")
    }
}
