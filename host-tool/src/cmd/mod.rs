//! One module per subcommand; each exposes `Args` (clap) with `run`.

pub mod compare;
pub mod demo;
pub mod diagnose;
pub mod export;
pub mod fit;
pub mod flash;
pub mod history;
pub mod import;
pub mod improve;
pub mod input;
pub mod iso230;
pub mod monitor;
pub mod out;
pub mod rollback;
pub mod simulate;
pub mod status;
pub mod upload;

/// `--port`: the board a link command (`upload`, `rollback`, `status`,
/// `monitor`) talks to.
#[derive(clap::Args, Debug)]
pub struct BoardPort {
    /// Serial port of the board (`/dev/ttyACM0`, `COM3`) or `tcp://HOST:PORT`.
    #[arg(long)]
    pub port: String,
}

impl BoardPort {
    /// Opens the link with the default timing (500 ms, 4 tries).
    pub fn open(&self) -> anyhow::Result<crate::link::Client> {
        Ok(crate::link::Client::open(
            &self.port,
            crate::link::Timing::default(),
        )?)
    }
}
