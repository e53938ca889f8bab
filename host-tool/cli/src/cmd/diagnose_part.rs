//! `trueaxis diagnose-part` — the diagnosis loop on a part scan
//! (docs/on-machine.md § diagnose-part): for each candidate source of error
//! (probe radius, probe form, part form, slide straightness, spindle error
//! motion, thermal drift) its size with a 95 % interval when the scan and
//! the other measurements given identify it, otherwise what this scan
//! cannot contain or what would tell it apart.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out;
use crate::cmd::probe::{plane, read_probe, side, AnyProbe};
use crate::cmd::separate::{read_multi_step, read_run, AngleArgs};
use trueaxis_engine::import;
use trueaxis_engine::onmachine::part_diagnosis::{
    self, Evidence, Input, KnownProbe, Scan, Source, Status,
};
use trueaxis_engine::onmachine::probe_csv::{self, Small};

/// `trueaxis diagnose-part SCAN.csv [--probe P] [--reversal R] [--multi-step M]`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The part scan: a straightness run (`<axis>_mm,d_um`), a roundness
    /// turn (`c_deg,p_um`) or probe-centre positions along an arc
    /// (`x_mm,z_mm` in the plane of `--plane`); a `t_s` column (seconds)
    /// gives time stamps. The kind is read from the header.
    pub scan: PathBuf,
    /// The travel axis of a straightness run.
    #[arg(long, default_value = "x", value_parser = ["x", "y", "z"])]
    pub axis: String,
    /// The plane of an arc scan.
    #[arg(long, default_value = "xz")]
    pub plane: String,
    /// An arc scan: the outward direction of the surface where the probe
    /// touches, `+z`, `-x`, …
    #[arg(long, default_value = "+z", allow_hyphen_values = true)]
    pub side: String,
    /// The probe calibrated on a master ball (`probe calibrate`'s file,
    /// 2-D or 3-D).
    #[arg(long)]
    pub probe: Option<PathBuf>,
    /// An arc scan of a part of known diameter (a certified gauge), mm.
    #[arg(long)]
    pub part_diameter_mm: Option<f64>,
    /// A straightness scan's second run, the part turned 180° and the probe
    /// reversed (`<axis>_mm,d_um`).
    #[arg(long)]
    pub reversal: Option<PathBuf>,
    /// A roundness scan's multi-step set (`c_deg,step_deg,p_um`).
    #[arg(long)]
    pub multi_step: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session of the scan (a
    /// straightness session with rows at `orientation_deg` 180 is its own
    /// reversal pair).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write an HTML page (verdict, the sources, the scan) into this
    /// directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// How the multi-step set's spindle angle is known, when its file
    /// alone does not say.
    #[command(flatten)]
    pub angle: AngleArgs,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let raw = std::fs::read_to_string(&self.scan)
            .with_context(|| format!("cannot read {}", self.scan.display()))?;
        let name = self.scan.display().to_string();
        // One session of a measurement CSV with probe columns: its kind
        // from what its rows hold (readings round a turn, readings along a
        // travel, or probe-centre positions).
        let mut pair = None;
        let text = if probe_csv::is_probe_csv(&raw) {
            let t = probe_csv::read(&raw, &name)?;
            let rows = t.select(self.session)?;
            let has = |c: &str| rows.iter().any(|r| r.get(c).is_some());
            let a = self.axis.chars().next().unwrap_or('x');
            let kind = if has("d_um") && has("c_deg") {
                Small::Roundness
            } else if has("d_um") {
                if rows.iter().any(|r| {
                    r.get("orientation_deg")
                        .is_some_and(|o| o.rem_euclid(360.0) > 90.0)
                }) {
                    pair = Some(t.small(self.session, Small::Straightness(a, 180))?);
                }
                Small::Straightness(a, 0)
            } else {
                Small::Positions
            };
            t.small(self.session, kind)?
        } else {
            crate::input::scan_text(&self.scan, self.session, Small::Positions)?
        };
        let head = crate::input::header(&text);
        let has = |c: &str| head.iter().any(|h| h == c);
        let pos = format!("{}_mm", self.axis);
        let pl = plane(&self.plane)?;
        // The kind from the header; the time stamps from a `t_s` or a
        // `time` column (clock times).
        let cols: Vec<String> = if has("p_um") {
            vec!["c_deg".into(), "p_um".into()]
        } else if has("d_um") {
            vec![pos.clone(), "d_um".into()]
        } else {
            vec![format!("{}_mm", pl[0]), format!("{}_mm", pl[1])]
        };
        let times = trueaxis_engine::onmachine::clock::times(&text, &name)?;
        let names: Vec<&str> = cols.iter().map(String::as_str).collect();
        let rows = import::read_table(
            &text,
            &name,
            &names,
            "a straightness run (<axis>_mm,d_um), a roundness turn (c_deg,p_um) or probe-centre positions of an arc",
        )?;
        let col = |k: usize| rows.iter().map(|r| r[k]).collect::<Vec<f64>>();
        let scan = if has("p_um") {
            Scan::Roundness {
                c_deg: col(0),
                p_um: col(1),
            }
        } else if has("d_um") {
            Scan::Straightness {
                pos_mm: col(0),
                d_um: col(1),
            }
        } else {
            Scan::Arc {
                p_mm: rows.iter().map(|r| [r[0], r[1]]).collect(),
                side: side(&self.side, pl)?,
            }
        };
        let kind = scan.kind();
        let refuse = |flag: &str, given: bool, needs: &str| -> Result<()> {
            if given && kind != needs {
                bail!("{flag} belongs to a {needs} scan; {name} is a {kind} scan");
            }
            Ok(())
        };
        refuse(
            "--reversal",
            self.reversal.is_some() || pair.is_some(),
            "straightness",
        )?;
        refuse("--multi-step", self.multi_step.is_some(), "roundness")?;
        refuse("--probe", self.probe.is_some(), "arc")?;
        refuse("--part-diameter-mm", self.part_diameter_mm.is_some(), "arc")?;
        if let Some(d) = self.part_diameter_mm {
            if !(d.is_finite() && d > 0.0) {
                bail!("--part-diameter-mm {d}: expected a positive diameter in mm");
            }
        }
        let probe = self.probe.as_ref().map(read_probe).transpose()?;
        let axis = |a: &str| match a {
            "x" => 0,
            "y" => 1,
            _ => 2,
        };
        let in_plane = [axis(pl[0]), axis(pl[1])];
        let form = |t: f64| -> Option<f64> {
            match &probe {
                Some(AnyProbe::Plane(p)) => p.covers(t).then(|| p.form_nm_at(t)),
                Some(AnyProbe::Sphere(p)) => p.in_plane(in_plane, t),
                None => None,
            }
        };
        // The form's 95 % half-width at one angle: a least-squares fit of
        // p coefficients to N points of noise σ has an average pointwise
        // variance σ²·p/N (the trace of the hat matrix over N).
        let ci = |rms: f64, p: usize, n: usize| 1.96 * rms * (p as f64 / n.max(1) as f64).sqrt();
        let known = probe.as_ref().map(|p| match p {
            // Never below the resolution the ball was logged at.
            AnyProbe::Plane(p) => KnownProbe {
                radius_mm: p.probe_radius_mm,
                radius_ci95_mm: p.probe_radius_ci95_mm,
                form_pv_nm: p.form_pv_nm,
                form_ci95_nm: ci(p.residual_rms_nm, p.form_nm.len(), p.points)
                    .max(p.quantum_mm.unwrap_or(0.0) * 1e6),
                form: &form,
            },
            AnyProbe::Sphere(p) => KnownProbe {
                radius_mm: p.probe_radius_mm,
                radius_ci95_mm: p.probe_radius_ci95_mm,
                form_pv_nm: p.form_pv_nm,
                form_ci95_nm: ci(p.residual_rms_nm, p.form_nm.len(), p.points)
                    .max(p.quantum_mm.unwrap_or(0.0) * 1e6),
                form: &form,
            },
        });
        let ev = Evidence {
            t_s: times,
            probe: known,
            part_diameter_mm: self.part_diameter_mm,
            reversal: match (&self.reversal, &pair) {
                (Some(p), _) => Some(read_run(p, &self.axis, None, 180, None)?),
                (None, Some(text)) => Some(
                    import::read_columns(text, &name, [pos.as_str(), "d_um"], "the 180° run")?
                        .into_iter()
                        .map(|v| (v[0], v[1]))
                        .collect(),
                ),
                (None, None) => None,
            },
            multi_step: self
                .multi_step
                .as_ref()
                .map(|p| read_multi_step(p, None, &self.angle).map(|r| r.1))
                .transpose()?,
            upr: self.angle.upr,
        };
        let d = part_diagnosis::diagnose(&scan, &ev)
            .with_context(|| format!("{name}: cannot diagnose"))?;
        let verdict = verdict(&d);
        let measures: Vec<Option<String>> = d
            .findings
            .iter()
            .map(|f| f.measure.as_ref().map(|m| m.render(flag)))
            .collect();
        let sum_measures: Vec<Option<String>> = d
            .combined
            .iter()
            .map(|c| c.measure.as_ref().map(|m| m.render(flag)))
            .collect();
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::part_diagnosis_page(
                    &d,
                    &verdict,
                    &measures,
                    &sum_measures,
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            // Each `measure` as this command words it (its flags).
            let with_flags = |v: &mut serde_json::Value, m: &[Option<String>]| {
                if let Some(a) = v.as_array_mut() {
                    for (f, m) in a.iter_mut().zip(m) {
                        f["measure"] = json!(m);
                    }
                }
            };
            let mut findings = serde_json::to_value(&d.findings)?;
            with_flags(&mut findings, &measures);
            let mut combined = serde_json::to_value(&d.combined)?;
            with_flags(&mut combined, &sum_measures);
            let doc = json!({
                "scan": name,
                "kind": d.kind,
                "points": d.points,
                "noise_um": d.noise_um,
                "verdict": verdict,
                "findings": findings,
                "combined": combined,
                "report": report.as_ref().map(|p| p.display().to_string()),
            });
            return out::json_pretty(&doc);
        }
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{name}: {} {} scan, {} points{}",
            if d.kind == "arc" { "an" } else { "a" },
            d.kind,
            d.points,
            d.noise_um
                .map(|n| format!(", reading noise {n:.3} µm"))
                .unwrap_or_default()
        );
        let _ = writeln!(s, "  {verdict}");
        for (f, measure) in d.findings.iter().zip(&measures) {
            let head = match (f.status, f.value, f.ci95) {
                (Status::Estimated, Some(v), Some([lo, hi])) => {
                    format!(
                        "{v:.prec$} {u}  (95 %: {lo:.prec$} … {hi:.prec$} {u})",
                        u = f.unit,
                        prec = precision(f.unit)
                    )
                }
                (Status::NotInScan, ..) => "not in this scan".into(),
                _ => "cannot know from these data".into(),
            };
            let _ = writeln!(s, "  {:<21} {head}", f.source.label());
            let _ = writeln!(s, "  {:<21}   {}", "", f.what);
            if let Some(m) = measure {
                let _ = writeln!(s, "  {:<21}   measure: {m}", "");
            }
        }
        for (c, m) in d.combined.iter().zip(&sum_measures) {
            let labels: Vec<&str> = c.sources.iter().map(|s| s.label()).collect();
            let _ = writeln!(s, "  sum: {}  {}", labels.join(" + "), sum_size(c));
            let _ = writeln!(s, "  {:<21}   {}", "", c.what);
            if let Some(m) = m {
                let _ = writeln!(s, "  {:<21}   measure: {m}", "");
            }
        }
        if let Some(r) = &report {
            let _ = writeln!(s, "  report: {}", r.display());
        }
        out::print(&s)
    }
}

/// An input the diagnosis asks for, as the flag that gives it.
fn flag(i: Input) -> String {
    match i {
        Input::Reversal => "--reversal RUN180.csv",
        Input::MultiStep => "--multi-step STEPS.csv",
        Input::Probe => "--probe PROBE.json",
        Input::PartDiameter => "--part-diameter-mm D",
    }
    .into()
}

/// A sum's PV with its interval, as the text and the page show it.
pub fn sum_size(c: &part_diagnosis::Combined) -> String {
    let p = precision(c.unit);
    match c.ci95 {
        Some([lo, hi]) => format!(
            "{:.p$} {u} PV (95 %: {lo:.p$} … {hi:.p$} {u})",
            c.pv,
            u = c.unit
        ),
        None => format!("{:.p$} {} PV", c.pv, c.unit),
    }
}

fn precision(unit: &str) -> usize {
    match unit {
        "mm" => 6,
        "nm" => 1,
        _ => 3,
    }
}

/// One sentence: what is identified, what these data cannot tell.
pub fn verdict(d: &part_diagnosis::PartDiagnosis) -> String {
    let names = |st: Status| -> Vec<&str> {
        Source::ALL
            .iter()
            .filter(|s| d.get(**s).status == st)
            .map(|s| s.label())
            .collect()
    };
    let known = names(Status::Estimated);
    let unknown = names(Status::CannotKnow);
    let mut v = if known.is_empty() {
        "these data identify none of the sources".to_string()
    } else {
        format!("identified: {}", known.join(", "))
    };
    if !unknown.is_empty() {
        let _ = write!(v, "; cannot know from these data: {}", unknown.join(", "));
    }
    // The sums the data read, each said as one (never split).
    for c in &d.combined {
        let labels: Vec<&str> = c.sources.iter().map(|s| s.label()).collect();
        // A sum of sources each estimated apart is a part of them (the
        // harmonics a method cannot split): say which.
        let part = if c
            .sources
            .iter()
            .all(|s| d.get(*s).status == Status::Estimated)
        {
            format!(": {}", c.what)
        } else {
            String::new()
        };
        let _ = write!(
            v,
            " ({} together {:.3} {} PV{part})",
            labels.join(" + "),
            c.pv,
            c.unit
        );
    }
    v
}
