//! `trueaxis probe calibrate` and `trueaxis probe correct` — the probe's
//! effective radius and form error from a master-ball scan, and a workpiece
//! scan corrected with them (docs/on-machine.md).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out::{self, outln};
use trueaxis_engine::onmachine::probe::sphere::{self, Probe3d};
use trueaxis_engine::onmachine::probe::{self, ProbeFile, Side};
use trueaxis_engine::onmachine::probe_csv::Small;

/// Arguments of `trueaxis probe`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub cmd: Sub,
}

/// The probe subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Sub {
    /// Calibrate a probe on a master ball (a 2-D scan in one plane, or a 3-D
    /// scan over the ball with `--plane xyz`).
    Calibrate(Calibrate),
    /// Correct a workpiece scan with a calibrated probe.
    Correct(Correct),
}

/// The plane a 2-D scan lies in.
pub(crate) fn plane(s: &str) -> Result<[&'static str; 2]> {
    Ok(match s {
        "xz" => ["x", "z"],
        "yz" => ["y", "z"],
        "xy" => ["x", "y"],
        _ => bail!("--plane `{s}`: expected xz, yz or xy"),
    })
}

fn read(path: &std::path::Path, pl: [&str; 2], session: Option<i64>) -> Result<Vec<[f64; 2]>> {
    let text = crate::input::scan_text(path, session, Small::Positions)?;
    probe::read_scan(&text, &path.display().to_string(), pl)
}

/// The lines of the scan's rows: the campaign file's for a session of a
/// measurement CSV, else the small file's own.
fn lines_of(path: &std::path::Path, session: Option<i64>, own: Vec<usize>) -> Result<Vec<usize>> {
    Ok(crate::input::scan_lines(path, session)?.unwrap_or(own))
}

/// The outliers as the JSON shows them (each by its line), and the
/// warning that names them.
fn outliers_said(
    outliers: &[probe::Outlier],
    lines: &[usize],
    name: &str,
) -> (serde_json::Value, Option<String>) {
    let doc = outliers
        .iter()
        .map(|o| {
            json!({
                "line": lines.get(o.index),
                "residual_nm": o.residual_nm,
                "left_out": o.left_out,
            })
        })
        .collect::<Vec<_>>();
    let warn = (!outliers.is_empty()).then(|| {
        let list: Vec<String> = outliers
            .iter()
            .take(10)
            .map(|o| {
                format!(
                    "line {} ({:+.1} nm)",
                    lines.get(o.index).copied().unwrap_or(o.index + 1),
                    o.residual_nm
                )
            })
            .collect();
        let kept = outliers.iter().any(|o| !o.left_out);
        format!(
            "{name}: {} contact(s) far off the ball against their neighbours (dirt, a chip, a false trigger): {}{} — {}",
            outliers.len(),
            list.join(", "),
            if outliers.len() > 10 { ", …" } else { "" },
            if kept {
                "fitted with them (--keep-outliers)"
            } else {
                "left out of the calibration; clean the ball and the stylus and probe again if they repeat"
            }
        )
    });
    (json!(doc), warn)
}

/// The page's next step after a calibration written to `probe`.
/// What to run next after a 2-D calibration: a command that runs as
/// pasted where `calibrate` ran (no `SCAN.csv` placeholder, issue 28) —
/// the ball's own scan corrected with the calibration, a check that its
/// form falls to the noise; part scans are corrected the same way.
fn correct_next(
    scan: &std::path::Path,
    probe: &std::path::Path,
    plane: &str,
    session: Option<i64>,
) -> String {
    use crate::report::diagnose::shell_word;
    let stem = scan
        .file_stem()
        .map_or("scan".into(), |s| s.to_string_lossy().into_owned());
    let out = scan.with_file_name(format!("{stem}_corrected.csv"));
    let mut cmd = format!(
        "trueaxis probe correct {} --probe {}",
        shell_word(&scan.display().to_string()),
        shell_word(&probe.display().to_string()),
    );
    if plane != "xz" {
        cmd.push_str(&format!(" --plane {plane}"));
    }
    if let Some(n) = session {
        cmd.push_str(&format!(" --session {n}"));
    }
    cmd.push_str(&format!(" -o {}", shell_word(&out.display().to_string())));
    cmd
}

/// What to do next after a 3-D calibration, in words: a 3-D ball scan
/// corrected as a circle would mean nothing, and the part scans are not
/// known here.
fn correct_next_3d(probe: &std::path::Path) -> String {
    format!(
        "correct each part scan with this calibration: `trueaxis probe correct` with --probe {} (docs/on-machine.md)",
        probe.display()
    )
}

/// The nominal surface's outward normals in the scan's plane (`plane`:
/// axis indices) when the scan is a probe measurement CSV whose rows give
/// `normal_*`; None otherwise.
fn nominal_normals(
    path: &std::path::Path,
    session: Option<i64>,
    plane: [usize; 2],
) -> Result<Option<Vec<[f64; 2]>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !trueaxis_engine::onmachine::probe_csv::is_probe_csv(&text) {
        return Ok(None);
    }
    trueaxis_engine::onmachine::probe_csv::read(&text, &path.display().to_string())?
        .normals(session, plane)
}

/// `trueaxis probe calibrate SCAN.csv --ball-diameter-mm D -o PROBE.json`.
#[derive(clap::Args, Debug)]
pub struct Calibrate {
    /// The master-ball scan: probe-centre positions, one contact per row.
    pub scan: PathBuf,
    /// The master ball's calibrated diameter, mm (its certificate).
    #[arg(long)]
    pub ball_diameter_mm: f64,
    /// The plane of the scan, or `xyz` for a 3-D scan over the ball.
    #[arg(long, default_value = "xz")]
    pub plane: String,
    /// Where to write the probe file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an HTML page (verdict, the form against contact angle — or,
    /// in 3-D, a map of it over the calibrated directions) into this
    /// directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Fit the contacts found far off the ball too (they are named either
    /// way; by default they are left out).
    #[arg(long)]
    pub keep_outliers: bool,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Calibrate {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(&[("the scan", &self.scan)], &[("-o", &self.output)])?;
        if self.plane == "xyz" {
            return self.run_3d();
        }
        let pl = plane(&self.plane).map_err(|e| anyhow::anyhow!("{e} (or xyz for a 3-D scan)"))?;
        let text = crate::input::scan_text(&self.scan, self.session, Small::Positions)?;
        let name = self.scan.display().to_string();
        let (p, own) = probe::read_scan_lines(&text, &name, pl)?;
        let lines = lines_of(&self.scan, self.session, own)?;
        let mut cal = probe::calibrate_with(&p, self.ball_diameter_mm / 2.0, self.keep_outliers)
            .with_context(|| format!("{name}: cannot calibrate"))?;
        let (outliers, said) = outliers_said(&cal.outliers, &lines, &name);
        cal.warnings.extend(said);
        let pr = &cal.probe;
        self.write_probe(pr, &cal.warnings)?;
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::probe_page(
                    &crate::report::onmachine::ProbePage {
                        theta_deg: &cal.theta_deg,
                        form_nm: cal
                            .theta_deg
                            .iter()
                            .map(|t| pr.form_nm_at(t.to_radians()))
                            .collect(),
                        residual_nm: &cal.residual_nm,
                        radius_mm: (pr.probe_radius_mm, pr.probe_radius_ci95_mm),
                        form_pv_nm: pr.form_pv_nm,
                        ball_pv_nm: [cal.pv_without_form_nm, cal.pv_with_form_nm],
                        warnings: &cal.warnings,
                        next: correct_next(&self.scan, &self.output, &self.plane, self.session),
                    },
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            let pv = [cal.pv_without_form_nm, cal.pv_with_form_nm];
            self.print_json(report.as_ref(), pr, pv, outliers, &cal.warnings)?;
        } else {
            let mut s = String::new();
            let _ = writeln!(
                s,
                "{}: {} contacts over {:.1}°…{:.1}° on a {} mm master ball",
                self.scan.display(),
                pr.points,
                pr.theta_range_deg[0],
                pr.theta_range_deg[1],
                self.ball_diameter_mm
            );
            let _ = writeln!(
                s,
                "  probe radius   {:.6} mm ± {:.6} mm (95 %)",
                pr.probe_radius_mm, pr.probe_radius_ci95_mm
            );
            let _ = writeln!(
                s,
                "  ball centre    {}={:.6} mm, {}={:.6} mm",
                pl[0], pr.centre_mm[0], pl[1], pr.centre_mm[1]
            );
            if pr.order >= 2 {
                let _ = writeln!(s, "  form error     {:.1} nm PV over the arc, harmonics 2…{} (order chosen by held-out RMS)", pr.form_pv_nm, pr.order);
            } else {
                let _ = writeln!(s, "  form error     none supported by held-out data");
            }
            let _ = writeln!(s, "  on the ball    {:.1} nm PV with the radius only → {:.1} nm PV with the form (residual RMS {:.1} nm)", cal.pv_without_form_nm, cal.pv_with_form_nm, pr.residual_rms_nm);
            let _ = writeln!(s, "  probe file written to {}", self.output.display());
            let _ = writeln!(
                s,
                "next: {}",
                correct_next(&self.scan, &self.output, &self.plane, self.session)
            );
            if let Some(r) = &report {
                let _ = writeln!(s, "  report: {}", r.display());
            }
            out::print(&s)?;
        }
        Ok(())
    }
}

impl Calibrate {
    /// Writes the probe file (either kind) to `-o` and says the
    /// calibration's warnings on stderr.
    fn write_probe(&self, probe: &impl serde::Serialize, warnings: &[String]) -> Result<()> {
        crate::workflow::write_file(
            &self.output,
            (serde_json::to_string_pretty(probe)? + "\n").as_bytes(),
        )?;
        for w in warnings {
            eprintln!("warning: {w}");
        }
        Ok(())
    }

    /// The `--json` document of a calibration (either kind); `pv_nm` is
    /// the ball's PV without and with the form.
    fn print_json(
        &self,
        report: Option<&PathBuf>,
        probe: &impl serde::Serialize,
        pv_nm: [f64; 2],
        outliers: serde_json::Value,
        warnings: &[String],
    ) -> Result<()> {
        let doc = json!({
            "scan": self.scan.display().to_string(),
            "output": self.output.display().to_string(),
            "report": report.map(|p| p.display().to_string()),
            "probe": probe,
            "pv_without_form_nm": pv_nm[0],
            "pv_with_form_nm": pv_nm[1],
            "outliers": outliers,
            "warnings": warnings,
        });
        out::json_pretty(&doc)
    }

    /// `--plane xyz`: the 3-D calibration (docs/on-machine.md).
    fn run_3d(self) -> Result<()> {
        let text = crate::input::scan_text(&self.scan, self.session, Small::Positions)?;
        let name = self.scan.display().to_string();
        let (p, own) = sphere::read_scan_lines(&text, &name)?;
        let lines = lines_of(&self.scan, self.session, own)?;
        let mut cal = sphere::calibrate_with(&p, self.ball_diameter_mm / 2.0, self.keep_outliers)
            .with_context(|| format!("{name}: cannot calibrate"))?;
        let (outliers, said) = outliers_said(&cal.outliers, &lines, &name);
        cal.warnings.extend(said);
        let pr = &cal.probe;
        self.write_probe(pr, &cal.warnings)?;
        let report = self
            .report
            .as_ref()
            .map(|dir| {
                crate::report::onmachine::probe3d_page(
                    &crate::report::onmachine::Probe3dPage {
                        probe: pr,
                        // The contacts fitted (the page's residuals are
                        // theirs).
                        points: &p
                            .iter()
                            .enumerate()
                            .filter(|(i, _)| {
                                !cal.outliers.iter().any(|o| o.index == *i && o.left_out)
                            })
                            .map(|(_, q)| *q)
                            .collect::<Vec<_>>(),
                        residual_nm: &cal.residual_nm,
                        ball_pv_nm: [cal.pv_without_form_nm, cal.pv_with_form_nm],
                        warnings: &cal.warnings,
                        next: correct_next_3d(&self.output),
                    },
                    dir,
                )
            })
            .transpose()?;
        if self.json {
            let pv = [cal.pv_without_form_nm, cal.pv_with_form_nm];
            return self.print_json(report.as_ref(), pr, pv, outliers, &cal.warnings);
        }
        let mut s = String::new();
        let a = pr.cone_axis;
        let _ = writeln!(
            s,
            "{}: {} contacts within {:.1}° of ({:.3}, {:.3}, {:.3}) on a {} mm master ball",
            self.scan.display(),
            pr.points,
            pr.cone_half_angle_deg,
            a[0],
            a[1],
            a[2],
            self.ball_diameter_mm
        );
        let _ = writeln!(
            s,
            "  probe radius   {:.6} mm ± {:.6} mm (95 %)",
            pr.probe_radius_mm, pr.probe_radius_ci95_mm
        );
        let c = pr.centre_mm;
        let _ = writeln!(
            s,
            "  ball centre    x={:.6} mm, y={:.6} mm, z={:.6} mm",
            c[0], c[1], c[2]
        );
        if pr.degree >= 2 {
            let _ = writeln!(s, "  form error     {:.1} nm PV over the calibrated directions, degree 2…{} in the contact direction (chosen by held-out RMS)", pr.form_pv_nm, pr.degree);
        } else {
            let _ = writeln!(s, "  form error     none supported by held-out data");
        }
        let _ = writeln!(s, "  on the ball    {:.1} nm PV with the radius only → {:.1} nm PV with the form (residual RMS {:.1} nm)", cal.pv_without_form_nm, cal.pv_with_form_nm, pr.residual_rms_nm);
        let _ = writeln!(s, "  probe file written to {}", self.output.display());
        if let Some(r) = &report {
            let _ = writeln!(s, "  report: {}", r.display());
        }
        out::print(&s)
    }
}

/// A probe file of either kind (its `format` tells which).
pub(crate) enum AnyProbe {
    Plane(ProbeFile),
    Sphere(Probe3d),
}

pub(crate) fn read_probe(path: &PathBuf) -> Result<AnyProbe> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a trueaxis probe file (not JSON)", path.display()))?;
    let bad = || format!("{}: not a valid probe file", path.display());
    if v.get("format").and_then(|f| f.as_str()) == Some(sphere::PROBE3D_FORMAT) {
        let pr: Probe3d = serde_json::from_value(v).with_context(bad)?;
        pr.check().with_context(bad)?;
        Ok(AnyProbe::Sphere(pr))
    } else {
        let pr: ProbeFile = serde_json::from_value(v)
            .with_context(|| format!("{}: not a trueaxis probe file", path.display()))?;
        pr.check().with_context(bad)?;
        Ok(AnyProbe::Plane(pr))
    }
}

/// `--side`: the outward direction of the surface, ± an axis of the plane,
/// or `out` / `in` for a circle probed from outside (a boss) or inside (a
/// bore), the normals along its radii.
pub(crate) fn side(s: &str, pl: [&str; 2]) -> Result<Side> {
    Ok(match s {
        "out" => Side::Out,
        "in" => Side::In,
        s if s.len() == 2 && (s.starts_with('+') || s.starts_with('-')) => {
            let sign = if s.starts_with('-') { -1.0 } else { 1.0 };
            let axis = &s[1..];
            match pl.iter().position(|a| *a == axis) {
                Some(0) => Side::Toward([sign, 0.0]),
                Some(_) => Side::Toward([0.0, sign]),
                None => bail!(
                    "--side `{s}`: expected ± one of the plane's axes {} and {}",
                    pl[0],
                    pl[1]
                ),
            }
        }
        s => bail!(
            "--side `{s}`: expected +{0}, -{0}, +{1} or -{1} (or out / in for a circle probed from outside / inside)",
            pl[0],
            pl[1]
        ),
    })
}

/// `trueaxis probe correct SCAN.csv --probe PROBE.json -o SURFACE.csv`.
#[derive(clap::Args, Debug)]
pub struct Correct {
    /// The workpiece scan: probe-centre positions in scan order.
    pub scan: PathBuf,
    /// The probe file `probe calibrate` wrote.
    #[arg(long)]
    pub probe: PathBuf,
    /// The plane of the scan.
    #[arg(long, default_value = "xz")]
    pub plane: String,
    /// Which side of the part the probe touches: the outward direction of
    /// the surface, `+z`, `-z`, `+x`, `-x`, `+y`, `-y`, or `out` / `in` for
    /// a boss / a bore (all round or an arc: normals along the radii of the
    /// circle through the centres).
    #[arg(long, default_value = "+z", allow_hyphen_values = true)]
    pub side: String,
    /// The nominal shape the form error is taken against: `circle` or
    /// `line` (least squares).
    #[arg(long, default_value = "circle")]
    pub nominal: String,
    /// Where to write the corrected contact points (CSV).
    #[arg(short, long)]
    pub output: PathBuf,
    /// A measurement CSV with probe columns: the session to read
    /// (docs/cli.md § Measurement CSV, probe data).
    #[arg(long)]
    pub session: Option<i64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Correct {
    fn run(self) -> Result<()> {
        crate::input::refuse_overwrite(
            &[("the scan", &self.scan), ("the probe file", &self.probe)],
            &[("-o", &self.output)],
        )?;
        let pl = plane(&self.plane)?;
        let pr = read_probe(&self.probe)?;
        let side = side(&self.side, pl)?;
        let circle = match self.nominal.as_str() {
            "circle" => true,
            "line" => false,
            s => bail!("--nominal `{s}`: expected circle or line"),
        };
        let p = read(&self.scan, pl, self.session)?;
        let axis = |a: &str| match a {
            "x" => 0,
            "y" => 1,
            _ => 2,
        };
        // The nominal surface's normals when the scan gives them (a probe
        // measurement CSV with `normal_*`), else the centre path's.
        let nominal = nominal_normals(&self.scan, self.session, [axis(pl[0]), axis(pl[1])])?;
        let from_nominal = nominal.is_some();
        let normals = match nominal {
            Some(n) => n,
            None => probe::path_normals(&p, side)?,
        };
        let (contacts, calibrated) = match &pr {
            AnyProbe::Plane(pr) => (
                probe::contacts_along(&p, &normals, pr.probe_radius_mm, |t| {
                    pr.covers(t).then(|| pr.form_nm_at(t))
                })?,
                format!(
                    "{:.1}°…{:.1}°",
                    pr.theta_range_deg[0], pr.theta_range_deg[1]
                ),
            ),
            AnyProbe::Sphere(pr) => (
                probe::contacts_along(&p, &normals, pr.probe_radius_mm, |t| {
                    pr.in_plane([axis(pl[0]), axis(pl[1])], t)
                })?,
                format!(
                    "directions (within {:.1}° of the calibration's mean direction)",
                    pr.cone_half_angle_deg
                ),
            ),
        };
        let normals_from = match (from_nominal, side) {
            (true, _) => "nominal",
            (false, Side::Toward(_)) => "centre_path",
            (false, _) => "circle",
        };
        let outside = contacts.iter().filter(|c| !c.calibrated).count();
        let surf: Vec<[f64; 2]> = contacts.iter().map(|c| c.surface_mm).collect();
        // The same scan with the radius only (no form): what the form
        // correction changes.
        let radius_only: Vec<[f64; 2]> = contacts
            .iter()
            .map(|c| {
                let t = c.theta_deg.to_radians();
                let d = c.form_nm * 1e-6;
                [c.surface_mm[0] + d * t.cos(), c.surface_mm[1] + d * t.sin()]
            })
            .collect();
        let dev = probe::form_deviation_nm(&surf, circle)?;
        let dev0 = probe::form_deviation_nm(&radius_only, circle)?;
        let mut csv = format!(
            "# probe: {}\n# nominal: {}\n{}_mm,{}_mm,theta_deg,probe_form_nm,calibrated,deviation_nm\n",
            self.probe.display(),
            self.nominal,
            pl[0],
            pl[1]
        );
        for (c, d) in contacts.iter().zip(&dev) {
            let _ = writeln!(
                csv,
                "{},{},{:.4},{:.3},{},{:.3}",
                c.surface_mm[0], c.surface_mm[1], c.theta_deg, c.form_nm, c.calibrated, d
            );
        }
        crate::workflow::write_file(&self.output, csv.as_bytes())?;
        let mut warnings = Vec::new();
        if outside > 0 {
            warnings.push(format!(
                "{outside} of {} contacts have angles outside the calibrated {calibrated}: corrected with the radius only (the form error there is unknown — calibrate over the angles the part presents)",
                contacts.len(),
            ));
        }
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        if self.json {
            let doc = json!({
                "scan": self.scan.display().to_string(),
                "output": self.output.display().to_string(),
                "points": contacts.len(),
                "nominal": self.nominal,
                "normals": normals_from,
                "form_pv_nm": probe::pv(&dev),
                "form_pv_radius_only_nm": probe::pv(&dev0),
                "outside_calibration": outside,
                "warnings": warnings,
            });
            out::json_pretty(&doc)?;
        } else {
            outln!(
                "{}: {} contacts along the {} normals; part form vs a least-squares {}: {:.1} nm PV ({:.1} nm PV with the probe radius only); written to {}",
                self.scan.display(),
                contacts.len(),
                match normals_from {
                    "nominal" => "nominal surface's",
                    "circle" => "circle's radial",
                    _ => "centre path's",
                },
                self.nominal,
                probe::pv(&dev),
                probe::pv(&dev0),
                self.output.display()
            )?;
        }
        Ok(())
    }
}

impl Args {
    pub fn run(self) -> Result<()> {
        match self.cmd {
            Sub::Calibrate(c) => c.run(),
            Sub::Correct(c) => c.run(),
        }
    }
}
