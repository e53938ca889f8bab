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
