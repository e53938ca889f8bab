//! The trueaxis host tool as a library: the binary (`src/main.rs`) only
//! dispatches; benches and integration tests call these modules directly.
//!
//! - `data`: the measurement data set (CONTRACT.md §1) every command works on.
//! - `cmd`: one module per subcommand.

pub mod cmd;
pub mod compare;
pub mod data;
pub mod features;
pub mod import;
pub mod iso230;
pub mod report;
pub mod simulate;
