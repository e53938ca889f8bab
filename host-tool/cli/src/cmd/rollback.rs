//! `trueaxis rollback --port PORT` — returns the board to the table it ran
//! before the last upload: the active (newest) table is revoked, the other
//! flash slot's becomes active, and the board is asked again which table
//! it runs. The board refuses while the axes move (`AxesMoving`) and when it
//! holds only one valid table (`NothingToRollBackTo`); either way the active
//! table stays. A retry after a lost answer gets the same answer and
//! writes nothing (the board remembers its last rollback).

use anyhow::{Context, Result};

use crate::cmd::out::outln;
use crate::cmd::BoardPort;
use crate::link::{slot_json, slot_text};

/// Arguments of `trueaxis rollback`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardPort,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let mut client = self.board.open()?;
        let report = client
            .rollback()
            .with_context(|| format!("rollback on {}", self.board.port))?;
        if self.json {
            outln!(
                "{}",
                serde_json::json!({
                    "port": self.board.port,
                    "revoked": slot_json(&report.revoked),
                    "active": slot_json(&report.active),
                    "retries": report.retries,
                    "verified": true,
                })
            )?;
        } else {
            outln!(
                "rolled back on {}: revoked {}; active {}, verified",
                self.board.port,
                slot_text(&report.revoked),
                slot_text(&report.active)
            )?;
        }
        Ok(())
    }
}
