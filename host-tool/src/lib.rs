//! The trueaxis host tool as a library: the binary (`src/main.rs`) only
//! dispatches; benches and integration tests call these modules directly.
//!
//! - `data`: the measurement data set (CONTRACT.md §1) every command works on.
//! - `cmd`: one module per subcommand.
//! - `import`: measurement files in (contract CSV, Renishaw .rtl) and the CSV out.
//! - `simulate`: the synthetic machine (21 geometric errors, effects, plans, noise).
//! - `iso230`: ISO 230-2 evaluation of bidirectional positioning runs.

pub mod cmd;
pub mod compare;
pub mod data;
pub mod diagnose;
pub mod export;
pub mod features;
pub mod fit;
pub mod history;
pub mod holdout;
pub mod import;
pub mod iso230;
pub mod link;
pub mod lsq;
pub mod model;
pub mod report;
pub mod simulate;
