//! `trueaxis separate` — reversal (part form and slide straightness from two
//! runs, the part turned 180° between them), three-probe and multi-step
//! roundness (part roundness and spindle error motion; docs/on-machine.md).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out;
use trueaxis_engine::import;
use trueaxis_engine::onmachine::probe_csv::Small;
use trueaxis_engine::onmachine::separate;

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
    /// Three probes: part roundness and spindle error motion.
    ThreeProbe(ThreeProbe),
    /// Multi-step: part roundness and spindle error motion from one probe,
    /// the part remounted at equally spaced steps.
    MultiStep(MultiStep),
}

/// `trueaxis separate three-probe SCAN.csv --angles-deg 0,A,B -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct ThreeProbe {
    /// `c_deg,p1_um,p2_um,p3_um`: the three probes' readings at equally
    /// spaced rotation angles over one or more whole turns.
    pub scan: PathBuf,
    /// The probes' angular positions around the part, degrees: `0,A,B`.
    #[arg(long, allow_hyphen_values = true)]
    pub angles_deg: String,
    /// Where to write `c_deg,part_um,spindle_x_um,spindle_y_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl ThreeProbe {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(&[("the scan", &self.scan)], &[("-o", &self.output)])?;
        let angles: Vec<f64> = self
            .angles_deg
            .split(',')
            .map(|a| a.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .filter(|v| v.len() == 3)
            .with_context(|| {
                format!(
                    "--angles-deg `{}`: expected three angles in degrees, e.g. 0,99.84,202.5",
                    self.angles_deg
                )
            })?;
        let text = crate::input::scan_text(&self.scan, self.session, Small::ThreeProbe)?;
        let name = self.scan.display().to_string();
        let rows = import::read_table(
            &text,
            &name,
            &["c_deg", "p1_um", "p2_um", "p3_um"],
            "the rotation angle and the three probes' readings",
        )?;
        let (keys, readings) = turn_bins(&rows, &name, "three-probe")?;
        let n = keys.len();
        let readings: Vec<[f64; 3]> = readings.iter().map(|v| [v[0], v[1], v[2]]).collect();
        let r = separate::three_probe(&readings, [angles[0], angles[1], angles[2]])
            .with_context(|| format!("{name}: cannot separate"))?;
        let mut csv = String::from("c_deg,part_um,spindle_x_um,spindle_y_um\n");
        for (i, k) in keys.iter().enumerate() {
            let _ = writeln!(
                csv,
                "{:.3},{:.5},{:.5},{:.5}",
                k, r.part_um[i], r.spindle_x_um[i], r.spindle_y_um[i]
            );
        }
        crate::workflow::write_file(&self.output, csv.as_bytes())?;
        let mut warnings = Vec::new();
        // The spacing suggested when another one is used; with it, the
        // remedy is a probe more (its blind harmonics start at 111).
        let good = [0.0, 99.84, 202.5];
        let uses_good = angles.iter().zip(good).all(|(a, g)| (a - g).abs() < 0.01);
        if !r.unseen_harmonics.is_empty() {
            let list: Vec<String> = r
                .unseen_harmonics
                .iter()
                .take(12)
                .map(|k| k.to_string())
                .collect();
            let remedy = if uses_good {
                "add a fourth probe to see them"
            } else {
                "change the angles (e.g. 0, 99.84, 202.5, blind only from harmonic 111 up) or add a probe"
            };
            warnings.push(format!(
                "probes at {}° cannot see {} harmonic(s) of the part ({}{}): lobes of those orders are left out of the roundness — {remedy}",
                self.angles_deg,
                r.unseen_harmonics.len(),
                list.join(", "),
                if r.unseen_harmonics.len() > 12 { ", …" } else { "" }
            ));
        }
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::roundness_page(
                    &crate::report::onmachine::Roundness {
                        method: "three-probe",
                        command: format!(
                            "to see the {} hidden harmonic(s): {}",
                            r.unseen_harmonics.len(),
                            if uses_good {
                                "add a fourth probe"
                            } else {
                                "measure again with the probes at 0, 99.84, 202.5° (blind only from harmonic 111 up)"
                            }
                        ),
                        part_um: &r.part_um,
                        spindle: vec![
                            ("along probe 1", r.spindle_x_um.as_slice()),
                            ("perpendicular", r.spindle_y_um.as_slice()),
                        ],
                        part_pv_um: r.part_pv_um,
                        spindle_pv_um: r.spindle_x_pv_um,
                        blind: &r.unseen_harmonics,
                        blind_meaning: "of the part: the probe spacing cannot see them (left out of the roundness)",
                        ci95_um: None,
                    },
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            out::json_pretty(&json!({
                "output": self.output.display().to_string(),
                "report": report.as_ref().map(|p| p.display().to_string()),
                "samples": r.samples,
                "part_pv_um": r.part_pv_um,
                "spindle_x_pv_um": r.spindle_x_pv_um,
                "unseen_harmonics": r.unseen_harmonics,
                "noise_gain": r.noise_gain,
                "warnings": warnings,
            }))?;
        } else {
            out::print(&format!(
                "{n} samples per turn: part roundness {:.3} µm PV, spindle error motion {:.3} µm PV along probe 1; {} harmonic(s) unseen; written to {}\n",
                r.part_pv_um,
                r.spindle_x_pv_um,
                r.unseen_harmonics.len(),
                self.output.display()
            ))?;
            if let Some(p) = &report {
                out::print(&format!("report: {}\n", p.display()))?;
            }
        }
        Ok(())
    }
}

/// One turn of readings from rows `[angle_deg, values…]`: the distinct
/// angles (to 0.001°, wrapped to 0…360) in order and each one's values
/// averaged over the turns that read it. The angles must be evenly spaced
/// over the turn (`method` names the separation in the message).
fn turn_bins(rows: &[Vec<f64>], name: &str, method: &str) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
    let key = |c: f64| (c.rem_euclid(360.0) * 1000.0).round() as i64 % 360_000;
    let width = rows.first().map_or(1, |r| r.len()) - 1;
    let mut bins: std::collections::BTreeMap<i64, (Vec<f64>, usize)> = Default::default();
    for r in rows {
        let e = bins.entry(key(r[0])).or_insert((vec![0.0; width], 0));
        for k in 0..width {
            e.0[k] += r[k + 1];
        }
        e.1 += 1;
    }
    let n = bins.len();
    let step = 360_000 / n.max(1) as i64;
    let first = *bins.keys().next().context("no readings")?;
    if let Some((i, (&k, _))) = bins
        .iter()
        .enumerate()
        .find(|(i, (&k, _))| (k - first - *i as i64 * step).abs() > 1)
    {
        bail!(
            "{name}: the angles are not evenly spaced over the turn: the {}th distinct angle is {:.3}°, expected {:.3}° ({n} per turn); {method} separation needs equal steps",
            i + 1,
            k as f64 / 1000.0,
            (first + i as i64 * step) as f64 / 1000.0
        );
    }
    Ok((
        bins.keys().map(|k| *k as f64 / 1000.0).collect(),
        bins.values()
            .map(|(v, c)| v.iter().map(|x| x / *c as f64).collect())
            .collect(),
    ))
}

/// `trueaxis separate multi-step SCAN.csv -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct MultiStep {
    /// `c_deg,step_deg,p_um`: the spindle angle, the part's angular position
    /// on the spindle (equally spaced steps over 360°) and the probe's
    /// reading, one or more whole turns per step.
    pub scan: PathBuf,
    /// Where to write `angle_deg,part_um,spindle_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Reads a multi-step file (`c_deg,step_deg,p_um`, docs/on-machine.md):
/// the spindle angles and one turn of readings per step, each step read at
/// the same evenly spaced angles (several turns averaged).
pub(crate) fn read_multi_step(
    path: &std::path::Path,
    session: Option<i64>,
) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
    let text = crate::input::scan_text(path, session, Small::MultiStep)?;
    let name = path.display().to_string();
    let rows = import::read_table(
        &text,
        &name,
        &["c_deg", "step_deg", "p_um"],
        "the spindle angle, the part's step and the probe reading",
    )?;
    // Steps: the distinct part positions, evenly spaced over the turn.
    let step_rows: Vec<Vec<f64>> = rows.iter().map(|r| vec![r[1], 0.0]).collect();
    let (steps, _) = turn_bins(&step_rows, &format!("{name}: step_deg"), "multi-step")?;
    let key = |c: f64| (c.rem_euclid(360.0) * 1000.0).round() as i64 % 360_000;
    let mut runs = Vec::new();
    let mut angles: Option<Vec<f64>> = None;
    for &st in &steps {
        let mine: Vec<Vec<f64>> = rows
            .iter()
            .filter(|r| key(r[1]) == key(st))
            .map(|r| vec![r[0], r[2]])
            .collect();
        let (a, v) = turn_bins(&mine, &format!("{name}: step {st}°"), "multi-step")?;
        match &angles {
                None => angles = Some(a),
                Some(a0) if a0 != &a => bail!(
                    "{name}: step {st}° is read at {} spindle angles from {:.3}°, step {}° at {} from {:.3}°: every step must be read at the same spindle angles",
                    a.len(),
                    a[0],
                    steps[0],
                    a0.len(),
                    a0[0]
                ),
                Some(_) => {}
            }
        runs.push(v.into_iter().map(|x| x[0]).collect::<Vec<f64>>());
    }
    Ok((angles.context("no readings")?, runs))
}

/// Reads a straightness run: `<axis>_mm,d_um` (docs/on-machine.md), or
/// from a measurement CSV with probe columns the rows of `session` at
/// `orientation` (0 or 180°).
pub(crate) fn read_run(
    p: &std::path::Path,
    axis: &str,
    session: Option<i64>,
    orientation: u16,
) -> Result<Vec<(f64, f64)>> {
    let pos = format!("{axis}_mm");
    let a = axis.chars().next().unwrap_or('x');
    let text = crate::input::scan_text(p, session, Small::Straightness(a, orientation))?;
    Ok(import::read_columns(
        &text,
        &p.display().to_string(),
        [&pos, "d_um"],
        "the position and the probe reading",
    )?
    .into_iter()
    .map(|v| (v[0], v[1]))
    .collect())
}

impl MultiStep {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(&[("the scan", &self.scan)], &[("-o", &self.output)])?;
        let name = self.scan.display().to_string();
        let (angles, runs) = read_multi_step(&self.scan, self.session)?;
        let r = separate::multi_step(&runs).with_context(|| format!("{name}: cannot separate"))?;
        let mut csv = String::from("angle_deg,part_um,spindle_um\n");
        for (i, a) in angles.iter().enumerate() {
            let _ = writeln!(csv, "{a:.3},{:.5},{:.5}", r.part_um[i], r.spindle_um[i]);
        }
        crate::workflow::write_file(&self.output, csv.as_bytes())?;
        let list: Vec<String> = r
            .inseparable_harmonics
            .iter()
            .take(8)
            .map(|k| k.to_string())
            .collect();
        let warnings = vec![format!(
            "with {} steps the part's harmonics {}{} cannot be told from the spindle's: they are left in spindle_um, not in part_um — measure again with a number of steps that is not a divisor of the lobes you look for (e.g. {} steps)",
            r.steps,
            list.join(", "),
            if r.inseparable_harmonics.len() > 8 { ", …" } else { "" },
            r.steps + 1
        )];
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        let ci = 1.96 * r.point_sigma_um;
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::roundness_page(
                    &crate::report::onmachine::Roundness {
                        method: "multi-step",
                        command: format!(
                            "to separate harmonics {}, {}, …: remount the part in {} steps and run trueaxis separate multi-step again",
                            r.steps,
                            2 * r.steps,
                            r.steps + 1
                        ),
                        part_um: &r.part_um,
                        spindle: vec![("along the probe", r.spindle_um.as_slice())],
                        part_pv_um: r.part_pv_um,
                        spindle_pv_um: r.spindle_pv_um,
                        blind: &r.inseparable_harmonics,
                        blind_meaning: "of the part cannot be told from the spindle's (they are in the spindle's profile)",
                        ci95_um: ci.is_finite().then_some(ci),
                    },
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            out::json_pretty(&json!({
                "output": self.output.display().to_string(),
                "report": report.as_ref().map(|p| p.display().to_string()),
                "samples": r.samples,
                "steps": r.steps,
                "part_pv_um": r.part_pv_um,
                "spindle_pv_um": r.spindle_pv_um,
                "inseparable_harmonics": r.inseparable_harmonics,
                "residual_rms_um": r.residual_rms_um,
                "point_ci95_um": if ci.is_finite() { json!(ci) } else { json!(null) },
                "warnings": warnings,
            }))?;
        } else {
            out::print(&format!(
                "{} steps × {} samples per turn: part roundness {:.3} µm PV, spindle error motion {:.3} µm PV (± {:.3} µm per point, 95 %); written to {}\n",
                r.steps,
                r.samples,
                r.part_pv_um,
                r.spindle_pv_um,
                ci,
                self.output.display()
            ))?;
            if let Some(p) = &report {
                out::print(&format!("report: {}\n", p.display()))?;
            }
        }
        Ok(())
    }
}

/// `trueaxis separate reversal RUN0.csv RUN180.csv -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct Reversal {
    /// The run with the part at 0°: `<axis>_mm,d_um` (probe reading, µm).
    pub run0: PathBuf,
    /// The run with the part turned 180° and the probe reversed (left out
    /// when RUN0 is a measurement CSV whose session holds both
    /// orientations, `orientation_deg` 0 and 180).
    pub run180: Option<PathBuf>,
    /// The travel axis [default: x].
    #[arg(long, default_value = "x", value_parser = ["x", "y", "z"])]
    pub axis: String,
    /// Where to write `<axis>_mm,part_um,slide_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Reversal {
    fn run(self) -> Result<()> {
        let run180 = match &self.run180 {
            Some(p) => p.clone(),
            None => {
                // Reading one small file as both runs would separate
                // nothing and say the slide is straight: refused.
                let text = std::fs::read_to_string(&self.run0)
                    .with_context(|| format!("cannot read {}", self.run0.display()))?;
                if !trueaxis_engine::onmachine::probe_csv::is_probe_csv(&text) {
                    bail!(
                        "{}: give the 180° run as RUN180.csv (or a measurement CSV whose session holds both orientations)",
                        self.run0.display()
                    );
                }
                self.run0.clone()
            }
        };
        crate::input::refuse_overwrite(
            &[("run 0°", &self.run0), ("run 180°", &run180)],
            &[("-o", &self.output)],
        )?;
        let pos = format!("{}_mm", self.axis);
        let read = |p: &PathBuf, o: u16| read_run(p, &self.axis, self.session, o);
        let r =
            separate::reversal(&read(&self.run0, 0)?, &read(&run180, 180)?).with_context(|| {
                format!(
                    "{} and {}: cannot separate",
                    self.run0.display(),
                    run180.display()
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
                run180.display()
            );
        }
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::reversal_page(
                    &self.axis,
                    &r.pos_mm,
                    &r.part_um,
                    &r.slide_um,
                    [r.part_pv_um, r.slide_pv_um],
                    ci,
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            out::json_pretty(&json!({
                "output": self.output.display().to_string(),
                "report": report.as_ref().map(|p| p.display().to_string()),
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
            if let Some(p) = &report {
                out::print(&format!("report: {}\n", p.display()))?;
            }
        }
        Ok(())
    }
}

impl Args {
    pub fn run(self) -> Result<()> {
        match self.cmd {
            Sub::Reversal(r) => r.run(),
            Sub::ThreeProbe(t) => t.run(),
            Sub::MultiStep(m) => m.run(),
        }
    }
}
