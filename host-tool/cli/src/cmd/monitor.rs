//! `trueaxis monitor --port PORT` — live telemetry: one line per sample
//! (positions, per-axis referencing, temperatures, model and output corrections, model flags,
//! loop timing, faults). With
//! `--json`, the samples are collected and written as one JSON document
//! (`{"samples": [...]}`) at the end, so `--count` defaults to 1 there.

use std::time::Duration;

use anyhow::Result;

use crate::cmd::out::outln;
use crate::cmd::{model_flag_names, telemetry_json, temps_text, BoardPort};

/// Arguments of `trueaxis monitor`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardPort,
    /// Number of samples (default: until interrupted; 1 with --json).
    #[arg(long, allow_negative_numbers = true)]
    pub count: Option<u64>,
    /// Time between samples, ms.
    #[arg(long, default_value_t = 200, allow_negative_numbers = true)]
    pub interval_ms: u64,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let mut client = self.board.open()?;
        let count = self.count.or(self.json.then_some(1));
        let mut samples = Vec::new();
        let mut k = 0u64;
        while count.is_none_or(|c| k < c) {
            if k > 0 {
                std::thread::sleep(Duration::from_millis(self.interval_ms));
            }
            let t = client.status()?;
            if self.json {
                samples.push(telemetry_json(&t));
            } else {
                let faults: Vec<_> = t.faults.names().collect();
                outln!(
                    "t={:>10.3}s pos_nm={:?} ref=[{}] temps=[{}] corr_nm={:?} model_nm={:?} model_flags={} worst_loop_us={} faults={}",
                    t.uptime_us as f64 / 1e6,
                    t.pos_nm,
                    ref_flags(&t),
                    temps_text(&t.temp_mc),
                    t.corr_nm,
                    t.model_corr_nm,
                    {
                        let f = model_flag_names(t.model_flags);
                        if f.is_empty() {
                            "none".into()
                        } else {
                            f.join(",")
                        }
                    },
                    t.worst_loop_us,
                    if faults.is_empty() {
                        "none".into()
                    } else {
                        faults.join(",")
                    }
                )?;
            }
            k += 1;
        }
        if self.json {
            outln!(
                "{}",
                serde_json::json!({ "port": self.board.port, "samples": samples })
            )?;
        }
        Ok(())
    }
}

/// Per axis, compact: `x` referenced, `-` not referenced though needed,
/// `.` needs none (`ref=[x,-,.]`).
fn ref_flags(t: &trueaxis_protocol::Telemetry) -> String {
    (0..3)
        .map(|a| match (t.referenced[a], t.reference_needed[a]) {
            (true, _) => crate::link::AXES[a],
            (false, true) => "-",
            (false, false) => ".",
        })
        .collect::<Vec<_>>()
        .join(",")
}
