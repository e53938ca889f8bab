//! `trueaxis status --port PORT` — the board's identity (firmware,
//! protocol and table-format versions, active and standby tables) and its
//! telemetry (positions, corrections, loop timing, faults).

use anyhow::Result;

use crate::cmd::out::outln;
use crate::cmd::BoardPort;
use crate::link::{slot_json, slot_text, telemetry_json};

/// Arguments of `trueaxis status`.
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
        let id = client.identify()?;
        let t = client.status()?;
        let fw = format!("{}.{}.{}", id.firmware[0], id.firmware[1], id.firmware[2]);
        if self.json {
            outln!(
                "{}",
                serde_json::json!({
                    "port": self.board.port,
                    "firmware": fw,
                    "protocol": id.protocol,
                    "table_format": id.table_format,
                    "max_table_bytes": id.max_table_bytes,
                    "active": id.active.as_ref().map(slot_json),
                    "standby": id.standby.as_ref().map(slot_json),
                    "telemetry": telemetry_json(&t),
                })
            )?;
            return Ok(());
        }
        outln!(
            "board on {}: firmware {fw}, link protocol {}, table format {}",
            self.board.port,
            id.protocol,
            id.table_format
        )?;
        match &id.active {
            Some(a) => outln!("active table:  {}", slot_text(a))?,
            None => outln!("active table:  none (correction held at zero)")?,
        }
        if let Some(s) = &id.standby {
            outln!("standby table: {} (rollback target)", slot_text(s))?;
        }
        outln!(
            "loop: {} ticks at {} µs, worst gap {} µs, worst tick {} µs, {} overruns",
            t.ticks,
            t.period_us,
            t.worst_loop_us,
            t.worst_tick_us,
            t.overruns
        )?;
        outln!(
            "position nm:   {:?}{}",
            t.pos_nm,
            if t.injecting { " (injected)" } else { "" }
        )?;
        outln!(
            "correction nm: {:?} (model {:?})",
            t.corr_nm,
            t.model_corr_nm
        )?;
        let faults: Vec<_> = t.faults.names().collect();
        let latched: Vec<_> = t.faults_latched.names().collect();
        outln!(
            "faults: {} (latched: {})",
            if faults.is_empty() {
                "none".into()
            } else {
                faults.join(", ")
            },
            if latched.is_empty() {
                "none".into()
            } else {
                latched.join(", ")
            }
        )?;
        Ok(())
    }
}
