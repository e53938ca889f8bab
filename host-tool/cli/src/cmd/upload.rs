//! `trueaxis upload TABLE.bin --port PORT` — sends a table to the board
//! over the link (USB CDC-ACM / UART, or `tcp://HOST:PORT` for emulators):
//! validates it locally with model-core's parser and against the board's
//! limits (model-core's `board`: staging buffer, model capacity) first,
//! uploads it in acknowledged chunks (resuming an interrupted upload of the
//! same table), commits it to the free flash slot, activates it and checks
//! that the board reports the new table's CRC.

use std::path::PathBuf;

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};

use crate::cmd::out::outln;
use crate::cmd::BoardPort;
use crate::input;
use crate::link::{slot_json, slot_text, ClientError};

/// Arguments of `trueaxis upload`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table (from `trueaxis export`).
    pub table: PathBuf,
    #[command(flatten)]
    pub board: BoardPort,
    /// Write one JSON document to stdout instead of text (and no progress bar).
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let bytes = input::load_board_table(&self.table)?;
        let mut client = self.board.open()?;
        let bar = if self.json {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(bytes.len() as u64).with_style(
                ProgressStyle::with_template("{msg} [{bar:40}] {bytes}/{total_bytes}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            )
        };
        bar.set_message("uploading");
        let report = match client.upload(&bytes, |done, _| bar.set_position(done)) {
            Ok(r) => r,
            Err(e) => {
                // A link lost after the last chunk may have lost only the
                // answer: the board commits and runs a table in one step.
                let lost = matches!(e, ClientError::Io { .. } | ClientError::Timeout { .. });
                let hint = if lost {
                    format!(
                        " (if the link was lost after the last chunk, the board may run the new table already: `trueaxis status --port {}` tells; running this upload again resumes it or finds it running)",
                        self.board.port
                    )
                } else {
                    String::new()
                };
                return Err(anyhow::Error::new(e).context(format!(
                    "upload of {} to {}{hint}",
                    self.table.display(),
                    self.board.port
                )));
            }
        };
        bar.finish_and_clear();
        if self.json {
            outln!(
                "{}",
                serde_json::json!({
                    "port": self.board.port,
                    "bytes": report.bytes,
                    "crc32": format!("{:#010x}", report.crc32),
                    "resumed_at": report.resumed_at,
                    "chunks": report.chunks,
                    "retries": report.retries,
                    "committed": slot_json(&report.committed),
                    "active": slot_json(&report.activated),
                    "verified": true,
                    "already_active": report.already_active,
                })
            )?;
        } else if report.already_active {
            outln!(
                "{} (CRC {:#010x}) already runs on {}: {}; nothing written, the standby table kept",
                self.table.display(),
                report.crc32,
                self.board.port,
                slot_text(&report.activated)
            )?;
        } else {
            if report.resumed_at > 0 {
                outln!("resumed an earlier upload at byte {}", report.resumed_at)?;
            }
            outln!(
                "uploaded {} bytes (CRC {:#010x}) to {}: committed to {}, active and verified",
                report.bytes,
                report.crc32,
                self.board.port,
                slot_text(&report.committed)
            )?;
        }
        Ok(())
    }
}
