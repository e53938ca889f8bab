//! The `trueaxis` command-line tool as a library: the binary
//! (`src/main.rs`) only parses the command line and dispatches. Everything
//! that computes lives in the engine crate (`trueaxis_engine`); this crate
//! holds what a user touches — subcommands, terminal output and progress
//! bars, the HTML reports, the board link and the probe.
//!
//! - `cmd`: one module per subcommand (its clap arguments and its `run`).
//! - `report`: the HTML pages and SVG plots of compare, diagnose, history, iso230.
//! - `input`: reading what the user names — data files, board tables — with the checks every command applies.
//! - `workflow`: the building blocks several commands share (so none calls another).
//! - `link`: the board link client (serial port or TCP) behind upload/status/rollback/monitor.

pub mod cmd;
pub mod input;
pub mod link;
pub mod report;
pub mod workflow;
