//! `trueaxis reference --port PORT --axis x|y|z --at-mm POS` — tells the
//! board where an axis is: the count its encoder reads now is machine
//! position POS. The board corrects only once every axis with an encoder is
//! referenced (an encoder counts from wherever the board was switched on;
//! a correction keyed to position from a wrong origin moves the machine the
//! wrong way), then ramps the correction in at the table's slew. Run it
//! with the axis at rest at a known position (after the controller homed
//! it): the board refuses while an axis moves. After a reset, power loss or
//! an encoder fault the axis must be referenced again.

use anyhow::{bail, Context, Result};

use crate::cmd::out::outln;
use crate::cmd::{names_or_none, BoardPort};
use crate::link::{axes_json, axes_text, AXES};

/// An axis of the board.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// X (link axis 0).
    X,
    /// Y (link axis 1).
    Y,
    /// Z (link axis 2).
    Z,
}

/// Arguments of `trueaxis reference`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardPort,
    /// The axis to reference.
    #[arg(long, value_enum)]
    pub axis: Axis,
    /// The machine position the axis is at now, mm (e.g. 0 at the home
    /// position), within ±2147 mm.
    #[arg(long, allow_negative_numbers = true)]
    pub at_mm: f64,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `mm` as whole nm on the link (an i32), or why not.
fn pos_nm(mm: f64) -> Result<i32> {
    let nm = (mm * 1e6).round();
    if !nm.is_finite() || nm < f64::from(i32::MIN) || nm > f64::from(i32::MAX) {
        bail!("--at-mm {mm}: expected a position within ±2147 mm (the link carries nm in 32 bits)");
    }
    Ok(nm as i32)
}

impl Args {
    pub fn run(self) -> Result<()> {
        let pos_nm = pos_nm(self.at_mm)?;
        let axis = self.axis as u8;
        let name = AXES[usize::from(axis)];
        let mut client = self.board.open()?;
        client.identify()?;
        let t = client
            .reference(axis, pos_nm)
            .with_context(|| format!("referencing {name} on {}", self.board.port))?;
        let faults: Vec<_> = t.faults.names().collect();
        let all = (0..3).all(|a| t.referenced[a] || !t.reference_needed[a]);
        if self.json {
            outln!(
                "{}",
                serde_json::json!({
                    "port": self.board.port,
                    "axis": name,
                    "pos_nm": pos_nm,
                    "axes": axes_json(&t),
                    "all_referenced": all,
                    "faults": faults,
                })
            )?;
        } else {
            outln!(
                "{name} referenced at {:.6} mm on {}; axes: {}",
                f64::from(pos_nm) / 1e6,
                self.board.port,
                axes_text(&t)
            )?;
            if all {
                outln!("every axis that needs a reference has one: the correction ramps in at the table's slew")?;
            } else {
                outln!(
                    "the correction stays at zero until every axis with an encoder is referenced"
                )?;
            }
            outln!("faults: {}", names_or_none(&faults))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::pos_nm;

    #[test]
    fn positions_outside_the_link_range_are_refused() {
        assert_eq!(pos_nm(0.0).unwrap(), 0);
        assert_eq!(pos_nm(-12.345_678_9).unwrap(), -12_345_679);
        assert_eq!(pos_nm(2147.0).unwrap(), 2_147_000_000);
        for bad in [2148.0, -2148.0, f64::NAN, f64::INFINITY] {
            let e = pos_nm(bad).unwrap_err().to_string();
            assert!(e.contains("within ±2147 mm"), "{e}");
        }
    }
}
