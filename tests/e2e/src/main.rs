//! `trueaxis-e2e` — the host side of the end-to-end runs against the board
//! image in QEMU (tests/src/bin/board.rs). xtask starts QEMU with USART1 on
//! a TCP server socket and runs this program with the port:
//!
//! - `trueaxis-e2e check --port P --trueaxis BIN --table T.bin --other O.bin`
//!   is the end-to-end test: garbage survived, `trueaxis upload` of T,
//!   positions injected along a trajectory with the board's corrections
//!   equal to model-core's fixed-point evaluation of T on the host (bit
//!   exact), a cut upload of O that leaves T active. Exit 0 = pass.
//! - `trueaxis-e2e show --port P --table T.bin [--trueaxis BIN]` uploads T
//!   and prints the board's corrections beside the host's (the end of
//!   `cargo xtask demo`).
//! - `trueaxis-e2e write-tables DIR` writes the synthetic tables of
//!   build/tables.rs (cubic19, full, nn_3x16x3) as .bin files.
//!
//! `--other` defaults to build/tables.rs's `full` table.

mod check;
mod link;
#[path = "../../build/tables.rs"]
#[allow(dead_code)] // shared with the QEMU crate's build script
mod tables;

use std::path::PathBuf;
use std::process::ExitCode;

/// Parsed command line.
#[derive(Debug)]
struct Cli {
    cmd: String,
    port: u16,
    trueaxis: Option<PathBuf>,
    table: PathBuf,
    other: Option<PathBuf>,
}

fn parse_cli() -> Result<Cli, String> {
    let mut args = std::env::args().skip(1);
    let cmd = args
        .next()
        .ok_or("usage: trueaxis-e2e check|show --port P --table T.bin ... | write-tables DIR")?;
    if cmd == "write-tables" {
        let dir = args.next().ok_or("write-tables needs a directory")?;
        return Ok(Cli {
            cmd,
            port: 0,
            trueaxis: None,
            table: PathBuf::from(dir),
            other: None,
        });
    }
    let (mut port, mut trueaxis, mut table, mut other) = (None, None, None, None);
    while let Some(flag) = args.next() {
        let value = args.next().ok_or_else(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--port" => port = Some(value.parse::<u16>().map_err(|e| format!("--port: {e}"))?),
            "--trueaxis" => trueaxis = Some(PathBuf::from(value)),
            "--table" => table = Some(PathBuf::from(value)),
            "--other" => other = Some(PathBuf::from(value)),
            _ => return Err(format!("unknown flag {flag}")),
        }
    }
    Ok(Cli {
        cmd,
        port: port.ok_or("--port is required")?,
        trueaxis,
        table: table.ok_or("--table is required")?,
        other,
    })
}

fn main() -> ExitCode {
    let cli = match parse_cli() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("trueaxis-e2e: {e}");
            return ExitCode::from(2);
        }
    };
    let result = match cli.cmd.as_str() {
        "check" => check::check(&cli),
        "show" => check::show(&cli),
        "write-tables" => write_tables(&cli.table),
        other => Err(format!("unknown command {other}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("trueaxis-e2e: FAILED: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Writes build/tables.rs's tables into `dir`.
fn write_tables(dir: &std::path::Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
    type Build = fn(u64) -> Result<Vec<u8>, model_core::EncodeError>;
    let all: [(&str, Build); 3] = [
        ("cubic19", tables::cubic19),
        ("full", tables::full),
        ("nn_3x16x3", tables::nn_3x16x3),
    ];
    for (name, build) in all {
        let bytes = build(0x0E2E).map_err(|e| format!("{name}: {e}"))?;
        let path = dir.join(format!("{name}.bin"));
        std::fs::write(&path, bytes).map_err(|e| format!("write {}: {e}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
