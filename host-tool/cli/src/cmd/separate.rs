//! `trueaxis separate reversal` — part form and slide straightness from
//! two runs, the part turned 180° between them (docs/probe.md § separate).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use serde_json::json;

use crate::cmd::out;
use trueaxis_engine::{import, separate};

/// Arguments of `trueaxis separate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub cmd: Sub,
}

/// The separation methods.
#[derive(clap::Subcommand, Debug)]
pub enum Sub {
    /// Reversal: part form and slide straightness from runs at 0° and 180°.
    Reversal(Reversal),
}

/// `trueaxis separate reversal RUN0.csv RUN180.csv -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct Reversal {
    /// The run with the part at 0°: `<axis>_mm,d_um` (probe reading, µm).
    pub run0: PathBuf,
    /// The run with the part turned 180° and the probe reversed.
    pub run180: PathBuf,
    /// The travel axis [default: x].
    #[arg(long, default_value = "x", value_parser = ["x", "y", "z"])]
    pub axis: String,
    /// Where to write `<axis>_mm,part_um,slide_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Reversal {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(
            &[("run 0°", &self.run0), ("run 180°", &self.run180)],
            &[("-o", &self.output)],
        )?;
        let pos = format!("{}_mm", self.axis);
        let read = |p: &PathBuf| -> Result<Vec<(f64, f64)>> {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            Ok(import::read_columns(
                &text,
                &p.display().to_string(),
                [&pos, "d_um"],
                "the position and the probe reading",
            )?
            .into_iter()
            .map(|v| (v[0], v[1]))
            .collect())
        };
        let r =
            separate::reversal(&read(&self.run0)?, &read(&self.run180)?).with_context(|| {
                format!(
                    "{} and {}: cannot separate",
                    self.run0.display(),
                    self.run180.display()
                )
            })?;
        let mut csv = format!("{pos},part_um,slide_um\n");
        for i in 0..r.pos_mm.len() {
            let _ = writeln!(
                csv,
                "{},{:.5},{:.5}",
                r.pos_mm[i], r.part_um[i], r.slide_um[i]
            );
        }
        crate::workflow::write_file(&self.output, csv.as_bytes())?;
        let ci = r.point_sigma_um.map(|s| 1.96 * s);
        if r.left_out > 0 {
            eprintln!(
                "warning: {} readings of {} lie outside the travel of {}: left out",
                r.left_out,
                self.run0.display(),
                self.run180.display()
            );
        }
        if self.json {
            out::json_pretty(&json!({
                "output": self.output.display().to_string(),
                "points": r.pos_mm.len(),
                "part_pv_um": r.part_pv_um,
                "slide_pv_um": r.slide_pv_um,
                "run_noise_um": r.run_noise_um,
                "point_ci95_um": ci,
                "left_out": r.left_out,
            }))?;
        } else {
            let u = ci.map_or("unknown (fewer than 8 readings per run)".to_string(), |c| {
                format!("± {c:.3} µm per point (95 %)")
            });
            out::print(&format!(
                "{} points: part form {:.3} µm PV, slide straightness {:.3} µm PV (least-squares lines removed), {u}; written to {}\n",
                r.pos_mm.len(),
                r.part_pv_um,
                r.slide_pv_um,
                self.output.display()
            ))?;
        }
        Ok(())
    }
}

impl Args {
    pub fn run(self) -> Result<()> {
        match self.cmd {
            Sub::Reversal(r) => r.run(),
        }
    }
}
