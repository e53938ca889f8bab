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
use trueaxis_engine::onmachine::{separate, spindle_log};

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

/// How the spindle angle of a log's rows is known when the file alone
/// does not say (docs/on-machine.md § Spindle logs).
#[derive(clap::Args, Debug, Clone, Copy, Default)]
pub struct AngleArgs {
    /// Encoder counts per turn, for a log with an `encoder` column.
    #[arg(long)]
    pub counts_per_turn: Option<f64>,
    /// The spindle speed, rev/min, for a log with time stamps but no angle,
    /// encoder, index or `rpm` column.
    #[arg(long)]
    pub rpm: Option<f64>,
    /// Keep harmonics up to this many undulations per revolution (a
    /// roundness instrument's filter: 15, 50, 150, 500, …) in the roundness
    /// and the error motion [default: all the angles resolve].
    #[arg(long)]
    pub upr: Option<usize>,
}

impl AngleArgs {
    pub(crate) fn options(&self) -> spindle_log::Options {
        spindle_log::Options {
            counts_per_turn: self.counts_per_turn,
            rpm: self.rpm,
        }
    }
}

/// The error motion (ISO 230-7) as the JSON and text show it.
fn error_motion_json(e: &separate::ErrorMotion) -> serde_json::Value {
    json!({
        "synchronous_um": e.synchronous_um,
        "synchronous_ci95_um": e.synchronous_ci95_um,
        "asynchronous_um": e.asynchronous_um,
        "total_um": e.total_um,
        "centring_um": e.centring_um,
        "excluded_harmonics": e.excluded_harmonics,
        "excluded_pv_um": e.excluded_pv_um,
        "turns": e.turns,
    })
}

/// The error motion in one line of text.
fn error_motion_text(e: &separate::ErrorMotion) -> String {
    format!(
        "synchronous {:.3} µm (95 %: {:.3} … {:.3}){}, total {:.3} µm; centring {:.3} µm left out",
        e.synchronous_um,
        e.synchronous_ci95_um[0],
        e.synchronous_ci95_um[1],
        e.asynchronous_um
            .map(|a| format!(", asynchronous {a:.3} µm"))
            .unwrap_or_default(),
        e.total_um,
        e.centring_um
    )
}

/// `trueaxis separate three-probe SCAN.csv --angles-deg 0,A,B -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct ThreeProbe {
    /// The three probes' readings round the turn: `p1_um,p2_um,p3_um` (on
    /// one row or each on rows of its own) and the spindle angle (`c_deg`,
    /// `encoder`, `index` or time stamps with the speed), any number of
    /// samples per turn and turns.
    pub scan: PathBuf,
    /// The probes' angular positions around the part, degrees: `0,A,B`.
    #[arg(long, allow_hyphen_values = true)]
    pub angles_deg: String,
    /// Where to write `c_deg,part_um,spindle_x_um,spindle_y_um,unseen_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    #[command(flatten)]
    pub angle: AngleArgs,
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
        let log = spindle_log::read(
            &text,
            &name,
            &["p1_um", "p2_um", "p3_um"],
            &self.angle.options(),
        )?;
        let [t1, t2, t3]: [separate::Track; 3] = log
            .tracks
            .try_into()
            .map_err(|_| anyhow::anyhow!("three probes expected"))?;
        let r = separate::three_probe(
            &[t1, t2, t3],
            [angles[0], angles[1], angles[2]],
            self.angle.upr,
        )
        .with_context(|| format!("{name}: cannot separate"))?;
        let n = r.samples;
        let mut csv = String::from("c_deg,part_um,spindle_x_um,spindle_y_um,unseen_um\n");
        for (i, k) in r.angle_deg.iter().enumerate() {
            let _ = writeln!(
                csv,
                "{:.3},{:.5},{:.5},{:.5},{:.5}",
                k, r.part_um[i], r.spindle_x_um[i], r.spindle_y_um[i], r.unseen_um[i]
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
                "probes at {}° cannot see {} harmonic(s) of the part ({}{}): lobes of those orders are left out of the roundness and the error motion (part and spindle together there: {:.3} µm PV) — {remedy}",
                self.angles_deg,
                r.unseen_harmonics.len(),
                list.join(", "),
                if r.unseen_harmonics.len() > 12 { ", …" } else { "" },
                r.error_motion.excluded_pv_um
            ));
        }
        warnings.extend(r.lost.iter().cloned());
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
                        part_ci95_um: r.part_ci95_um,
                        spindle: vec![
                            ("along probe 1", r.spindle_x_um.as_slice()),
                            ("perpendicular", r.spindle_y_um.as_slice()),
                        ],
                        part_pv_um: r.part_pv_um,
                        error_motion: &r.error_motion,
                        blind: &r.unseen_harmonics,
                        blind_meaning: "of the part: the probe spacing cannot see them (left out of the roundness and the error motion)",
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
                "upr": self.angle.upr,
                "angle_from": log.angle_from,
                "part_pv_um": r.part_pv_um,
                "part_ci95_um": r.part_ci95_um,
                "spindle_x_pv_um": r.spindle_x_pv_um,
                "error_motion": error_motion_json(&r.error_motion),
                "unseen_harmonics": r.unseen_harmonics,
                "noise_gain": r.noise_gain,
                "warnings": warnings,
            }))?;
        } else {
            out::print(&format!(
                "{n} samples per turn: part roundness {:.3} µm PV; spindle error motion along probe 1 (ISO 230-7): {}; {} harmonic(s) unseen; written to {}\n",
                r.part_pv_um,
                error_motion_text(&r.error_motion),
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

/// `trueaxis separate multi-step SCAN.csv -o OUT.csv`.
#[derive(clap::Args, Debug)]
pub struct MultiStep {
    /// `step_deg` (the part's angular position on the spindle), `p_um` (the
    /// probe's reading) and the spindle angle (`c_deg`, `encoder` or
    /// `index`): any number of steps, samples per turn and turns.
    pub scan: PathBuf,
    /// Where to write `angle_deg,part_um,spindle_um,inseparable_um`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    #[command(flatten)]
    pub angle: AngleArgs,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Reads a multi-step set (`step_deg`, `p_um` and the spindle angle,
/// docs/on-machine.md): each step's readings at their spindle angles.
pub(crate) fn read_multi_step(
    path: &std::path::Path,
    session: Option<i64>,
    angle: &AngleArgs,
) -> Result<(spindle_log::AngleFrom, Vec<separate::Step>)> {
    let text = crate::input::scan_text(path, session, Small::MultiStep)?;
    let name = path.display().to_string();
    spindle_log::multi_step(&text, &name, "p_um", &angle.options())
}

/// Reads a straightness run: `<axis>_mm,d_um` (an analogue probe's
/// reading, docs/on-machine.md), or a touch-trigger probe's positions
/// `<axis>_mm,<b>_mm` (`b` the axis it touches along: `side`'s, or the one
/// other position column) — or from a measurement CSV with probe columns
/// the rows of `session` at `orientation` (0 or 180°). `side` is the
/// surface's outward direction in the 0° run (`+z`: touched from above);
/// the 180° run is touched from the other side.
pub(crate) fn read_run(
    p: &std::path::Path,
    axis: &str,
    session: Option<i64>,
    orientation: u16,
    side: Option<&str>,
) -> Result<Vec<(f64, f64)>> {
    let pos = format!("{axis}_mm");
    let a = axis.chars().next().unwrap_or('x');
    let text = crate::input::scan_text(p, session, Small::Straightness(a, orientation))?;
    let name = p.display().to_string();
    let head: Vec<String> = crate::input::header(&text);
    if head.iter().any(|h| h == "d_um") || !head.iter().any(|h| h.ends_with("_mm") && *h != pos) {
        return Ok(import::read_columns(
            &text,
            &name,
            [&pos, "d_um"],
            "the position and the probe reading",
        )?
        .into_iter()
        .map(|v| (v[0], v[1]))
        .collect());
    }
    // Touch positions: along `side`'s axis, or the one other position
    // column.
    let (sign, b) = match side {
        Some(s)
            if s.len() == 2 && (s.starts_with('+') || s.starts_with('-')) && &s[1..] != axis =>
        {
            (
                if s.starts_with('-') { -1.0 } else { 1.0 },
                format!("{}_mm", &s[1..]),
            )
        }
        Some(s) => {
            bail!("--side `{s}`: expected + or − an axis other than the travel `{axis}` (e.g. +z)")
        }
        None => {
            let others: Vec<&String> = head
                .iter()
                .filter(|h| h.ends_with("_mm") && **h != pos)
                .collect();
            match others.as_slice() {
                [one] => (1.0, one.to_string()),
                _ => bail!(
                    "{name}: touch positions in {}: say which axis the probe touches along with --side (e.g. +z)",
                    others.iter().map(|c| format!("`{c}`")).collect::<Vec<_>>().join(" and ")
                ),
            }
        }
    };
    let sign = if orientation == 180 { -sign } else { sign };
    let rows = import::read_columns(
        &text,
        &name,
        [&pos, &b],
        "the position along the travel and the touch position",
    )?;
    Ok(separate::touch_readings(&rows, sign))
}

impl MultiStep {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(&[("the scan", &self.scan)], &[("-o", &self.output)])?;
        let name = self.scan.display().to_string();
        let (angle_from, steps) = read_multi_step(&self.scan, self.session, &self.angle)?;
        let r = separate::multi_step(&steps, self.angle.upr)
            .with_context(|| format!("{name}: cannot separate"))?;
        let mut csv = String::from("angle_deg,part_um,spindle_um,inseparable_um\n");
        for (i, a) in r.angle_deg.iter().enumerate() {
            let _ = writeln!(
                csv,
                "{a:.3},{:.5},{:.5},{:.5}",
                r.part_um[i], r.spindle_um[i], r.inseparable_um[i]
            );
        }
        crate::workflow::write_file(&self.output, csv.as_bytes())?;
        let list: Vec<String> = r
            .inseparable_harmonics
            .iter()
            .take(8)
            .map(|k| k.to_string())
            .collect();
        let mut warnings = vec![format!(
            "with {} steps the part's harmonics {}{} cannot be told from the spindle's: they are left out of part_um and spindle_um, their sum is inseparable_um ({:.3} µm PV) — measure again with a number of steps that is not a divisor of the lobes you look for (e.g. {} steps)",
            r.steps,
            list.join(", "),
            if r.inseparable_harmonics.len() > 8 { ", …" } else { "" },
            r.error_motion.excluded_pv_um,
            r.steps + 1
        )];
        warnings.extend(r.lost.iter().cloned());
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
                        part_ci95_um: r.part_ci95_um,
                        spindle: vec![("along the probe", r.spindle_um.as_slice())],
                        part_pv_um: r.part_pv_um,
                        error_motion: &r.error_motion,
                        blind: &r.inseparable_harmonics,
                        blind_meaning: "of the part cannot be told from the spindle's (left out of both; their sum is given)",
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
                "upr": self.angle.upr,
                "angle_from": angle_from,
                "part_pv_um": r.part_pv_um,
                "part_ci95_um": r.part_ci95_um,
                "spindle_pv_um": r.spindle_pv_um,
                "error_motion": error_motion_json(&r.error_motion),
                "inseparable_harmonics": r.inseparable_harmonics,
                "residual_rms_um": r.residual_rms_um,
                "point_ci95_um": if ci.is_finite() { json!(ci) } else { json!(null) },
                "warnings": warnings,
            }))?;
        } else {
            out::print(&format!(
                "{} steps × {} samples per turn: part roundness {:.3} µm PV; spindle error motion (ISO 230-7): {} (± {:.3} µm per point, 95 %); written to {}\n",
                r.steps,
                r.samples,
                r.part_pv_um,
                error_motion_text(&r.error_motion),
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
    /// The run with the part at 0°: `<axis>_mm,d_um` (probe reading, µm),
    /// or a touch-trigger probe's positions `<axis>_mm,<b>_mm`.
    pub run0: PathBuf,
    /// The run with the part turned 180° and the probe reversed (left out
    /// when RUN0 is a measurement CSV whose session holds both
    /// orientations, `orientation_deg` 0 and 180).
    pub run180: Option<PathBuf>,
    /// The travel axis.
    #[arg(long, default_value = "x", value_parser = ["x", "y", "z"])]
    pub axis: String,
    /// Touch-trigger positions: the surface's outward direction in the 0°
    /// run, `+z`, `-y`, … (the 180° run is touched from the other side)
    /// [default: + the one other position column].
    #[arg(long, allow_hyphen_values = true)]
    pub side: Option<String>,
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
        let read =
            |p: &PathBuf, o: u16| read_run(p, &self.axis, self.session, o, self.side.as_deref());
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
            // Which error is in a part scan, with the reversal telling
            // part and slide apart (the two runs as given).
            if let Some(run180) = &self.run180 {
                let w = |p: &std::path::Path| {
                    crate::report::diagnose::shell_word(&p.display().to_string())
                };
                out::print(&format!(
                    "next: trueaxis diagnose-part {} --reversal {} --axis {}\n",
                    w(&self.run0),
                    w(run180),
                    self.axis
                ))?;
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
