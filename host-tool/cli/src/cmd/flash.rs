//! `trueaxis flash TABLE.bin [--slot a|b] [--chip STM32F405RGTx]` — writes a
//! table into a flash slot through a debug probe, with the probe-rs library
//! (no subprocess), then reads it back to verify and resets the board so
//! it boots the new table.
//!
//! The slot addresses come from the repository's memory.x (compiled in with
//! `include_str!`: the one memory map the firmware links with), and the
//! slot image — header with sequence number and CRCs, revoke marker, table
//! — from model-core's `link::slot`, the format the firmware's table store
//! reads. The sequence number is one above the other slot's, so the new
//! table is the newest valid one at boot. Without `--slot`, the slot that
//! does not hold the newest table is written, keeping the old one as the
//! rollback target. The table is checked against the board's limits first
//! (model-core's `board`: the 24 KiB staging buffer each slot is read into
//! at boot, the model capacity) — the slot itself would take 128 KiB, the
//! board could not boot from such a table.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use probe_rs::flashing::DownloadOptions;
use probe_rs::probe::list::Lister;
use probe_rs::{MemoryInterface, Permissions};
use trueaxis_protocol::{slot, table_id, Slot};

use crate::cmd::out::outln;
use crate::input;

/// The firmware's memory map (repository root).
pub const MEMORY_X: &str = include_str!("../../../../memory.x");

/// Arguments of `trueaxis flash`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table (from `trueaxis export`).
    pub table: PathBuf,
    /// Slot to write (default: the one not holding the newest table).
    #[arg(long, value_parser = ["a", "b"])]
    pub slot: Option<String>,
    /// probe-rs target name of the chip.
    #[arg(long, default_value = "STM32F405RGTx")]
    pub chip: String,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// ORIGIN and LENGTH of a region of a memory.x `MEMORY` block.
pub fn region(memory_x: &str, name: &str) -> Result<(u32, u32)> {
    let line = memory_x
        .lines()
        .map(str::trim)
        .find(|l| l.split(|c: char| c.is_whitespace() || c == ':').next() == Some(name))
        .with_context(|| format!("memory.x has no {name} region"))?;
    let field = |key: &str| -> Result<u32> {
        let rest = line
            .split(key)
            .nth(1)
            .with_context(|| format!("memory.x {name}: no {key}"))?;
        let tok: String = rest
            .trim_start()
            .trim_start_matches('=')
            .trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        let v = if let Some(hex) = tok.strip_prefix("0x").or_else(|| tok.strip_prefix("0X")) {
            u32::from_str_radix(hex, 16).ok()
        } else if let Some(k) = tok.strip_suffix('K') {
            k.parse::<u32>().ok().map(|k| k * 1024)
        } else if let Some(m) = tok.strip_suffix('M') {
            m.parse::<u32>().ok().map(|m| m * 1024 * 1024)
        } else {
            tok.parse().ok()
        };
        v.with_context(|| format!("memory.x {name}: bad {key} `{tok}`"))
    };
    Ok((field("ORIGIN")?, field("LENGTH")?))
}

/// Addresses and size of slots A and B.
pub fn slots() -> Result<([u32; 2], u32)> {
    let (a, a_len) = region(MEMORY_X, "TABLE_A")?;
    let (b, b_len) = region(MEMORY_X, "TABLE_B")?;
    if a_len != b_len {
        bail!("memory.x: TABLE_A and TABLE_B differ in size");
    }
    Ok(([a, b], a_len))
}

impl Args {
    pub fn run(self) -> Result<()> {
        let bytes = input::load_board_table(&self.table)?;
        let (addr, slot_bytes) = slots()?;
        if bytes.len() as u64 + slot::BODY_AT as u64 > slot_bytes as u64 {
            bail!(
                "{}: {} bytes do not fit a {slot_bytes}-byte slot",
                self.table.display(),
                bytes.len()
            );
        }

        // The probe. No probe is the common case on a desk: say so plainly.
        let lister = Lister::new();
        let probes = lister.list_all();
        let Some(info) = probes.first() else {
            bail!(
                "no debug probe attached (probe-rs found none: ST-Link, CMSIS-DAP v2, J-Link …). \
                 Connect one to the board's SWD header, or use `trueaxis upload --port …` over the \
                 USB/serial link instead"
            );
        };
        let probe = info
            .open()
            .with_context(|| format!("cannot open debug probe {}", info.identifier))?;
        let mut session = probe
            .attach(self.chip.as_str(), Permissions::default())
            .with_context(|| {
                format!("cannot attach to {} through {}", self.chip, info.identifier)
            })?;

        // Which slot, and which sequence number.
        let mut headers = [[0u8; slot::HEADER_BYTES]; 2];
        {
            let mut core = session.core(0).context("cannot access core 0")?;
            for (h, &a) in headers.iter_mut().zip(&addr) {
                core.read(a as u64, h)
                    .context("cannot read the slot headers")?;
            }
        }
        let infos = [
            slot::decode_header(&headers[0], Slot::A),
            slot::decode_header(&headers[1], Slot::B),
        ];
        let target = match self.slot.as_deref() {
            Some("a") => 0,
            Some("b") => 1,
            _ => match infos {
                [Some(a), Some(b)] if a.seq >= b.seq => 1,
                [Some(_), None] => 1,
                _ => 0,
            },
        };
        let seq = infos[1 - target].map_or(1, |o| o.seq.wrapping_add(1));
        let which = [Slot::A, Slot::B][target];
        let image = slot::image(&bytes, which, seq);

        let mut loader = session.target().flash_loader();
        loader
            .add_data(addr[target] as u64, &image)
            .context("cannot prepare the flash write")?;
        let mut opts = DownloadOptions::default();
        opts.verify = true;
        loader
            .commit(&mut session, opts)
            .with_context(|| format!("flash write at {:#010x} failed", addr[target]))?;

        // Read back ourselves, then restart the board on the new table.
        let mut back = vec![0u8; image.len()];
        let mut core = session.core(0).context("cannot access core 0")?;
        core.read(addr[target] as u64, &mut back)
            .context("cannot read the slot back")?;
        if back != image {
            bail!(
                "verification failed: slot {which:?} at {:#010x} reads back differently",
                addr[target]
            );
        }
        core.reset().context("cannot reset the board")?;

        let crc32 = table_id(&bytes);
        if self.json {
            outln!(
                "{}",
                serde_json::json!({
                    "probe": info.identifier,
                    "chip": self.chip,
                    "slot": format!("{which:?}"),
                    "address": format!("{:#010x}", addr[target]),
                    "seq": seq,
                    "bytes": bytes.len(),
                    "crc32": format!("{crc32:#010x}"),
                    "verified": true,
                })
            )?;
        } else {
            outln!(
                "wrote {} bytes (CRC {crc32:#010x}) to slot {which:?} at {:#010x} (seq {seq}) through {}, verified, board reset",
                bytes.len(),
                addr[target],
                info.identifier
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_come_from_memory_x() {
        let ([a, b], len) = slots().unwrap();
        assert_eq!((a, b, len), (0x080C_0000, 0x080E_0000, 128 * 1024));
        assert_eq!(
            region(MEMORY_X, "FLASH").unwrap(),
            (0x0800_0000, 768 * 1024)
        );
        assert!(region(MEMORY_X, "TABLE_C").is_err());
    }
}
