//! `trueaxis` — the host tool. `main` only parses the command line and
//! dispatches to one module per subcommand (src/cmd/); each module owns its
//! clap struct (with `///` help on every flag) and a `run` method.
//!
//! Exit codes (docs/cli.md): 0 ok, 1 bad input or a failed check (message
//! on stderr), 2 usage error (clap's own exit code). A stdout closed by its
//! reader ends the command quietly with 0.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use trueaxis::cmd;

/// Machine-tool error compensation: import measurements, fit a model, see
/// where it fails, add the missing effect, export and upload the table.
#[derive(Parser, Debug)]
#[command(name = "trueaxis", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Convert a measurement file (Renishaw .rtl or CSV) to the trueaxis CSV.
    Import(cmd::import::Args),
    /// Generate measurements of a synthetic machine.
    Simulate(cmd::simulate::Args),
    /// Fit a compensation model to measurements.
    Fit(cmd::fit::Args),
    /// Compare a fitted model with measurements; where does it fail?
    Compare(cmd::compare::Args),
    /// Find which physical effect the model is missing.
    Diagnose(cmd::diagnose::Args),
    /// Run the diagnose → add → refit loop until the noise floor.
    Improve(cmd::improve::Args),
    /// Show how the error fell, fit by fit.
    History(cmd::history::Args),
    /// ISO 230-2 evaluation of bidirectional positioning runs.
    Iso230(cmd::iso230::Args),
    /// On-machine probing: calibrate a probe on a master ball, correct a scan.
    Probe(cmd::probe::Args),
    /// Error separation: part form vs slide straightness (reversal).
    Separate(cmd::separate::Args),
    /// A part's form from on-machine probing and the correction pass.
    Workpiece(cmd::workpiece::Args),
    /// Which error is in a part scan: probe, part, slide, spindle or drift.
    DiagnosePart(cmd::diagnose_part::Args),
    /// Export a model as a firmware table or a controller's compensation file.
    Export(cmd::export::Args),
    /// Upload a table to the board over the serial link.
    Upload(cmd::upload::Args),
    /// Show the board's identity and status.
    Status(cmd::status::Args),
    /// Return the board to the table it ran before the last upload.
    Rollback(cmd::rollback::Args),
    /// Live telemetry from the board.
    Monitor(cmd::monitor::Args),
    /// Tell the board where an axis is (it corrects only from referenced axes).
    Reference(cmd::reference::Args),
    /// Write a table into a flash slot through a debug probe (probe-rs).
    Flash(cmd::flash::Args),
    /// The guided end-to-end job on built-in data.
    Demo(cmd::demo::Args),
}

fn main() -> ExitCode {
    let json = std::env::args_os().skip(1).any(|a| a == "--json");
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => cmd::out::usage_exit(e, json),
    };
    let result = match cli.command {
        Command::Import(a) => a.run(),
        Command::Simulate(a) => a.run(),
        Command::Fit(a) => a.run(),
        Command::Compare(a) => a.run(),
        Command::Diagnose(a) => a.run(),
        Command::Improve(a) => a.run(),
        Command::History(a) => a.run(),
        Command::Iso230(a) => a.run(),
        Command::Probe(a) => a.run(),
        Command::Separate(a) => a.run(),
        Command::Workpiece(a) => a.run(),
        Command::DiagnosePart(a) => a.run(),
        Command::Export(a) => a.run(),
        Command::Upload(a) => a.run(),
        Command::Status(a) => a.run(),
        Command::Rollback(a) => a.run(),
        Command::Monitor(a) => a.run(),
        Command::Reference(a) => a.run(),
        Command::Flash(a) => a.run(),
        Command::Demo(a) => a.run(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // The reader of our stdout went away (`… | head`): it wanted no
        // more output, which is not a failure (cmd/out.rs).
        Err(e) if cmd::out::is_stdout_closed(&e) => ExitCode::SUCCESS,
        Err(e) => {
            // Whatever an input slipped into the message, no control
            // character reaches the terminal (docs/cli.md).
            let msg = trueaxis_engine::import::escape_controls(&cmd::flags::render(&e));
            eprintln!("error: {msg}");
            // Under --json stdout carries one document, an error too.
            if json {
                cmd::out::json_error(&e, 1);
            }
            ExitCode::FAILURE
        }
    }
}
