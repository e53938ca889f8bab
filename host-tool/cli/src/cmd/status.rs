//! `trueaxis status --port PORT` — the board's identity (firmware,
//! protocol and table-format versions, active and standby tables) and its
//! telemetry (positions, per-axis referencing, temperatures, corrections,
//! model flags, loop timing, faults). `--clear-faults` first clears the board's latched
//! faults (`ClearFaults`), then reports.

use anyhow::Result;

use crate::cmd::out::outln;
use crate::cmd::{model_flag_names, names_or_none, telemetry_json, temps_text, BoardPort};
use crate::link::{axes_text, slot_json, slot_text};

/// Arguments of `trueaxis status`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardPort,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Clear the board's latched faults first (the correction slews back
    /// to the model's; a fault whose cause remains comes back at the next
    /// tick), then report.
    #[arg(long)]
    pub clear_faults: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let mut client = self.board.open()?;
        let id = client.identify()?;
        let cleared = if self.clear_faults {
            let before = client.status()?;
            client.clear_faults()?;
            Some(before.faults_latched.names().collect::<Vec<_>>())
        } else {
            None
        };
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
                    "cleared_faults": cleared,
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
        if let Some(c) = &cleared {
            outln!(
                "cleared latched faults: {} (the correction slews back to the model's; a fault whose cause remains comes back at the next tick)",
                names_or_none(c)
            )?;
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
        outln!("referencing:   {}", axes_text(&t))?;
        outln!("temperatures:  {}", temps_text(&t.temp_mc))?;
        outln!(
            "correction nm: {:?} (model {:?})",
            t.corr_nm,
            t.model_corr_nm
        )?;
        outln!(
            "model flags: {}",
            names_or_none(&model_flag_names(t.model_flags))
        )?;
        let faults: Vec<_> = t.faults.names().collect();
        let latched: Vec<_> = t.faults_latched.names().collect();
        outln!(
            "faults: {} (latched: {})",
            names_or_none(&faults),
            names_or_none(&latched)
        )?;
        Ok(())
    }
}
