//! `trueaxis workpiece` — a turned or ground part's form from on-machine
//! probing, the correction pass as G-code and CSV, and the part's history
//! pass by pass (docs/on-machine.md § workpiece).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out;
use trueaxis_engine::import;
use trueaxis_engine::onmachine::workpiece::{self, Dialect, Point};

/// Arguments of `trueaxis workpiece`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scan: `c_deg,z_mm,dev_um` (rotation angle, position along the
    /// axis, radial deviation from the nominal, + = material proud).
    pub scan: PathBuf,
    /// Write the fitted form (JSON).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Write the correction pass as G-code in this dialect: fanuc or siemens.
    #[arg(long, value_parser = ["fanuc", "siemens"])]
    pub gcode: Option<String>,
    /// Where the G-code goes (with --gcode).
    #[arg(long)]
    pub gcode_out: Option<PathBuf>,
    /// Where the correction pass goes as CSV `c_deg,z_mm,fitted_um,offset_um`.
    #[arg(long)]
    pub pass_csv: Option<PathBuf>,
    /// The nominal diameter, mm (with --gcode: X is programmed in diameter).
    #[arg(long)]
    pub nominal_diameter_mm: Option<f64>,
    /// Feed of the correction pass, mm/min.
    #[arg(long, default_value_t = 100.0)]
    pub feed_mm_min: f64,
    /// Angle between points of the pass, degrees.
    #[arg(long, default_value_t = 10.0)]
    pub c_step_deg: f64,
    /// Stations along z of the pass (intervals).
    #[arg(long, default_value_t = 20)]
    pub z_steps: usize,
    /// Write an HTML page (the form along the generatrices and around the
    /// part, the history) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The part's history (appended: one entry per measured pass).
    #[arg(long)]
    pub history: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let outs: Vec<(&str, &std::path::Path)> = [
            ("-o", self.output.as_ref()),
            ("--gcode-out", self.gcode_out.as_ref()),
            ("--pass-csv", self.pass_csv.as_ref()),
            ("--history", self.history.as_ref()),
            ("--report", self.report.as_ref()),
        ]
        .into_iter()
        .filter_map(|(n, p)| p.map(|p| (n, p.as_path())))
        .collect();
        crate::input::refuse_overwrite(&[("the scan", self.scan.as_path())], &outs)?;
        if self.gcode.is_some() != self.gcode_out.is_some() {
            bail!("--gcode and --gcode-out go together (the dialect and the file)");
        }
        if self.gcode.is_some() && self.nominal_diameter_mm.is_none() {
            bail!("--gcode needs --nominal-diameter-mm (X is programmed in diameter)");
        }
        let text = crate::input::scan_text(
            &self.scan,
            self.session,
            trueaxis_engine::onmachine::probe_csv::Small::Workpiece,
        )?;
        let rows = import::read_table(
            &text,
            &self.scan.display().to_string(),
            &["c_deg", "z_mm", "dev_um"],
            "the rotation angle, the position along the axis and the radial deviation",
        )?;
        let pts: Vec<Point> = rows
            .iter()
            .map(|r| Point {
                c_deg: r[0],
                z_mm: r[1],
                dev_um: r[2],
            })
            .collect();
        let mut warnings = Vec::new();
        let form = workpiece::fit(&pts, &mut warnings)
            .with_context(|| format!("{}: cannot fit the part's form", self.scan.display()))?;
        if let Some(o) = &self.output {
            crate::workflow::write_file(
                o,
                (serde_json::to_string_pretty(&form)? + "\n").as_bytes(),
            )?;
        }
        if let (Some(d), Some(path)) = (self.gcode.as_deref(), &self.gcode_out) {
            let dialect = if d == "fanuc" {
                Dialect::Fanuc
            } else {
                Dialect::Siemens
            };
            let g = workpiece::gcode(
                &form,
                dialect,
                self.nominal_diameter_mm.expect("checked"),
                self.feed_mm_min,
                self.c_step_deg,
                self.z_steps,
            )?;
            crate::workflow::write_file(path, g.as_bytes())?;
        }
        if let Some(path) = &self.pass_csv {
            let mut csv = String::from("c_deg,z_mm,fitted_um,offset_um\n");
            for [c, z] in workpiece::pass_points(&form, self.c_step_deg, self.z_steps)? {
                let f = form.at(c, z);
                let _ = writeln!(
                    csv,
                    "{c:.3},{z:.3},{f:.4},{:.4}",
                    workpiece::correction_um(&form, c, z)
                );
            }
            crate::workflow::write_file(path, csv.as_bytes())?;
        }
        // The part's history: one entry per measured pass.
        let mut passes: Vec<serde_json::Value> = Vec::new();
        if let Some(h) = &self.history {
            if h.exists() {
                let t = std::fs::read_to_string(h)
                    .with_context(|| format!("cannot read {}", h.display()))?;
                passes = serde_json::from_str(&t).with_context(|| {
                    format!("{}: not a part history (a JSON list of passes); move it away to start a new one", h.display())
                })?;
            }
            passes.push(json!({
                "pass": passes.len() + 1,
                "scan": self.scan.display().to_string(),
                "form_pv_um": form.form_pv_um,
                "form_rms_um": form.form_rms_um,
                "eccentricity_um": form.eccentricity_um,
                "residual_rms_um": form.residual_rms_um,
            }));
            crate::workflow::write_file(
                h,
                (serde_json::to_string_pretty(&passes)? + "\n").as_bytes(),
            )?;
        }
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        let report = match &self.report {
            Some(dir) => {
                let pts: Vec<[f64; 3]> = pts.iter().map(|p| [p.c_deg, p.z_mm, p.dev_um]).collect();
                let next = self.pass_csv.as_ref().map(|p| {
                    format!(
                        "grind the pass in {}, measure the part again and run trueaxis workpiece NEW.csv{}",
                        p.display(),
                        self.history
                            .as_ref()
                            .map_or(String::new(), |h| format!(" --history {}", h.display()))
                    )
                });
                Some(crate::report::onmachine::workpiece_page(
                    &crate::report::onmachine::WorkpiecePage {
                        points: &pts,
                        form: &form,
                        z_range_mm: form.z_range_mm,
                        form_pv_um: form.form_pv_um,
                        form_rms_um: form.form_rms_um,
                        eccentricity_um: form.eccentricity_um,
                        history_pv_um: passes
                            .iter()
                            .filter_map(|p| p["form_pv_um"].as_f64())
                            .collect(),
                        warnings: &warnings,
                        next,
                    },
                    dir,
                )?)
            }
            None => None,
        };
        if self.json {
            out::json_pretty(&json!({
                "scan": self.scan.display().to_string(),
                "form": form,
                "history": passes,
                "report": report.as_ref().map(|p| p.display().to_string()),
                "warnings": warnings,
            }))?;
        } else {
            let mut s = String::new();
            let _ = writeln!(
                s,
                "{}: {} points on {} generatrices, z {:.1}…{:.1} mm",
                self.scan.display(),
                form.points,
                form.generatrices,
                form.z_range_mm[0],
                form.z_range_mm[1]
            );
            let _ = writeln!(
                s,
                "  form {:.3} µm PV, {:.3} µm RMS (degree {} along z, {} harmonics around, chosen by held-out RMS); eccentricity {:.3} µm; points about the surface {:.3} µm RMS",
                form.form_pv_um, form.form_rms_um, form.degree_z, form.harmonics, form.eccentricity_um, form.residual_rms_um
            );
            for p in &passes {
                let _ = writeln!(
                    s,
                    "  pass {}: form {:.3} µm PV ({})",
                    p["pass"],
                    p["form_pv_um"].as_f64().unwrap_or(f64::NAN),
                    p["scan"].as_str().unwrap_or("")
                );
            }
            if let Some(r) = &report {
                let _ = writeln!(s, "  report: {}", r.display());
            }
            out::print(&s)?;
        }
        Ok(())
    }
}
