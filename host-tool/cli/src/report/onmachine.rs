//! The on-machine pages (docs/on-machine.md, "Reports"): `probe calibrate`
//! (2-D and 3-D),
//! `separate reversal|three-probe|multi-step` and `workpiece` with
//! `--report DIR`. Each opens with a verdict card; roundness is drawn as a
//! polar plot (the profile around a base circle, deviations magnified),
//! straightness and generatrices as profiles.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;

use super::plot::{Drawing as _, HeatMap, MapPair, Series, XyPlot};
use super::{esc, Page, Tone, Verdict};

/// Colours of the polar plot's profiles (the pages' palette order).
const COLOURS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];

/// A polar plot of profiles sampled at equally spaced angles (µm, angle
/// `i·360/n` degrees, 0° at the right, counter-clockwise): each drawn as
/// `base + gain·value` around a base circle, the gain chosen so that the
/// largest |value| of all profiles takes 40 % of the base radius; dashed
/// rings at ±that value say the scale. A hand-written SVG with a viewBox
/// (it scales to its container).
pub fn polar_svg(title: &str, profiles: &[(&str, &[f64])]) -> String {
    let (w, h) = (560.0, 600.0);
    let (cx, cy, base) = (280.0, 330.0, 160.0);
    let max = profiles
        .iter()
        .flat_map(|p| p.1.iter())
        .map(|v| v.abs())
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let gain = 0.4 * base / max;
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" preserveAspectRatio="xMidYMid meet" font-family="sans-serif"><title>{}</title><rect width="{w}" height="{h}" fill="white"/><text x="{}" y="28" font-size="18" text-anchor="middle">{}</text>"#,
        esc(title),
        w / 2.0,
        esc(title)
    );
    // Rings: base ± max, and the base circle.
    for (r, label) in [
        (
            base - gain * max,
            format!("−{}", super::plot::format_value(max)),
        ),
        (base, "0".to_string()),
        (
            base + gain * max,
            format!("+{} µm", super::plot::format_value(max)),
        ),
    ] {
        let dash = if label == "0" {
            ""
        } else {
            r#" stroke-dasharray="5,4""#
        };
        let _ = write!(
            s,
            r##"<circle cx="{cx}" cy="{cy}" r="{r:.1}" fill="none" stroke="#999"{dash}/><text x="{:.1}" y="{:.1}" font-size="12" fill="#555">{}</text>"##,
            cx + 4.0,
            cy - r - 3.0,
            esc(&label)
        );
    }
    // Angle spokes every 30°.
    for k in 0..12 {
        let a = (30.0 * k as f64).to_radians();
        let (r0, r1) = (base - gain * max - 10.0, base + gain * max + 8.0);
        let _ = write!(
            s,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" font-size="12" text-anchor="middle" dominant-baseline="middle" fill="#555">{}°</text>"##,
            cx + r0 * a.cos(),
            cy - r0 * a.sin(),
            cx + r1 * a.cos(),
            cy - r1 * a.sin(),
            cx + (r1 + 16.0) * a.cos(),
            cy - (r1 + 16.0) * a.sin(),
            30 * k
        );
    }
    // The profiles, closed.
    for (i, (name, v)) in profiles.iter().enumerate() {
        let n = v.len().max(1);
        let mut d = String::new();
        for (k, x) in v.iter().enumerate() {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let r = base + gain * if x.is_finite() { *x } else { 0.0 };
            let _ = write!(
                d,
                "{}{:.1},{:.1} ",
                if k == 0 { "M" } else { "L" },
                cx + r * a.cos(),
                cy - r * a.sin()
            );
        }
        d.push('Z');
        let c = COLOURS[i % COLOURS.len()];
        let _ = write!(
            s,
            r#"<path d="{d}" fill="none" stroke="{c}" stroke-width="1.8"/><rect x="20" y="{:.0}" width="18" height="4" fill="{c}"/><text x="44" y="{:.0}" font-size="14">{}</text>"#,
            50.0 + 20.0 * i as f64,
            55.0 + 20.0 * i as f64,
            esc(name)
        );
    }
    s.push_str("</svg>");
    s
}

/// Writes `page` into `dir` and returns the index.html path.
fn write(page: &Page, dir: &Path) -> Result<PathBuf> {
    page.write(dir)
}

/// The roundness page of `separate three-probe` and `separate multi-step`:
/// the part and the spindle as polar plots, what the method cannot see.
#[derive(Debug)]
pub struct Roundness<'a> {
    /// `three-probe` or `multi-step`.
    pub method: &'a str,
    /// The command that made it.
    pub command: String,
    /// Part roundness, µm, at equally spaced angles.
    pub part_um: &'a [f64],
    /// Its PV's 95 % interval, µm.
    pub part_ci95_um: [f64; 2],
    /// Spindle error motion profiles `(name, µm)`.
    pub spindle: Vec<(&'a str, &'a [f64])>,
    /// Part PV, µm.
    pub part_pv_um: f64,
    /// The error motion along the sensitive direction (ISO 230-7).
    pub error_motion: &'a trueaxis_engine::onmachine::separate::ErrorMotion,
    /// Harmonics the method cannot see or separate.
    pub blind: &'a [usize],
    /// What the blind harmonics mean, in words.
    pub blind_meaning: &'a str,
    /// The per-point 95 % interval, µm, if known.
    pub ci95_um: Option<f64>,
}

/// Writes the roundness page into `dir`.
pub fn roundness_page(r: &Roundness, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new(format!("Roundness by {} separation", r.method));
    let blind = if r.blind.is_empty() {
        "every harmonic from 2 up is seen".to_string()
    } else {
        let list: Vec<String> = r.blind.iter().take(10).map(|k| k.to_string()).collect();
        format!(
            "harmonics {}{} {}",
            list.join(", "),
            if r.blind.len() > 10 { ", …" } else { "" },
            r.blind_meaning
        )
    };
    let e = r.error_motion;
    let mut details = vec![
        format!(
            "spindle error motion (ISO 230-7, along the sensitive direction): synchronous {:.3} µm (95 %: {:.3} … {:.3} µm){}, total {:.3} µm",
            e.synchronous_um,
            e.synchronous_ci95_um[0],
            e.synchronous_ci95_um[1],
            e.asynchronous_um
                .map(|a| format!(", asynchronous {a:.3} µm (reading noise included)"))
                .unwrap_or_else(|| ", asynchronous unknown (one turn read)".into()),
            e.total_um
        ),
        format!(
            "the once-per-turn term — the part's centring, {:.3} µm, with any once-per-turn motion of the spindle, which no measurement tells from it — is left out of both",
            e.centring_um
        ),
        format!("cannot know: {blind}"),
    ];
    if !r.blind.is_empty() {
        details.push(format!(
            "at those harmonics part and spindle together: {:.3} µm PV (a sum, not split)",
            e.excluded_pv_um
        ));
    }
    if let Some(ci) = r.ci95_um {
        details.push(format!("each point ± {ci:.3} µm (95 %)"));
    }
    page.verdict(Verdict {
        headline: format!(
            "The part is {:.3} µm out of round (PV, 95 %: {:.3} … {:.3} µm; harmonics 0 and 1 — size and centring — removed).",
            r.part_pv_um, r.part_ci95_um[0], r.part_ci95_um[1]
        ),
        details,
        // What the method cannot see is in `details`; the command's warning
        // says the same, so the card does not repeat it.
        warnings: Vec::new(),
        next: Some(r.command.clone()),
        tone: if r.blind.is_empty() { Tone::Good } else { Tone::Action },
    });
    page.heading("Part and spindle");
    page.grid_wide(vec![
        super::Figure {
            name: "part".into(),
            caption: "the part's roundness around its base circle (deviations magnified)".into(),
            svg: polar_svg("part roundness (µm)", &[("part", r.part_um)]),
            narrow: None,
        },
        super::Figure {
            name: "spindle".into(),
            caption: "the spindle's synchronous radial error motion, centring left out (deviations magnified)".into(),
            svg: polar_svg("spindle error motion (µm)", &r.spindle),
            narrow: None,
        },
    ]);
    write(&page, dir)
}

/// The reversal page: part form and slide straightness along the travel.
pub fn reversal_page(
    axis: &str,
    pos_mm: &[f64],
    part_um: &[f64],
    slide_um: &[f64],
    pv: [f64; 2],
    ci95_um: Option<f64>,
    dir: &Path,
) -> Result<PathBuf> {
    let mut page = Page::new("Reversal: part form and slide straightness");
    page.verdict(Verdict {
        headline: format!(
            "Part form {:.3} µm PV, slide straightness {:.3} µm PV (least-squares lines removed).",
            pv[0], pv[1]
        ),
        details: vec![
            ci95_um.map_or("the per-point uncertainty is unknown (fewer than 8 readings per run)".into(), |c| {
                format!("each point ± {c:.3} µm (95 %), from the runs' own noise")
            }),
            "cannot know: the part's and the slide's straight lines (offset and tilt of the set-ups), nor an error that changed between the two runs (thermal drift adds to both halves)".into(),
        ],
        warnings: Vec::new(),
        next: None,
        tone: Tone::Good,
    });
    let pts = |v: &[f64]| pos_mm.iter().copied().zip(v.iter().copied()).collect();
    let plot = XyPlot::new(
        "part form and slide straightness",
        format!("{axis} (mm)"),
        "deviation (µm)",
    )
    .with(Series::line("part form", pts(part_um)))
    .with(Series::line("slide straightness", pts(slide_um)));
    page.plot(
        "profiles",
        "the two separated profiles along the travel",
        &plot,
    )?;
    write(&page, dir)
}

/// The probe calibration page: the probe's form against contact angle and
/// the ball's residual with and without it.
#[derive(Debug)]
pub struct ProbePage<'a> {
    /// Contact angles, degrees.
    pub theta_deg: &'a [f64],
    /// Form error at each contact, nm.
    pub form_nm: Vec<f64>,
    /// Residual with the form, nm.
    pub residual_nm: &'a [f64],
    /// Radius ± 95 %, mm.
    pub radius_mm: (f64, f64),
    /// Form PV, nm, and the ball's PV before/after.
    pub form_pv_nm: f64,
    /// See above.
    pub ball_pv_nm: [f64; 2],
    /// Warnings.
    pub warnings: &'a [String],
    /// The command to run next.
    pub next: String,
}

/// What the radius's interval is about (issue 28: a simulated probe's
/// true radius lay outside it without a word on why).
pub const RADIUS_CONVENTION: &str = "the radius is the one that fits best with a form error of zero mean and no tilt over the calibrated angles (docs/on-machine.md): the interval is that radius's; a radius defined otherwise — a simulation's truth, a nominal value — differs by the mean of the form over the arc and may lie outside it";

/// Writes the probe calibration page into `dir`.
pub fn probe_page(p: &ProbePage, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new("Probe calibration on the master ball");
    page.verdict(Verdict {
        headline: format!(
            "Probe radius {:.6} mm ± {:.1} nm (95 %); form error {:.0} nm PV over the calibrated arc.",
            p.radius_mm.0,
            p.radius_mm.1 * 1e6,
            p.form_pv_nm
        ),
        details: vec![format!(
            "on the ball: {:.0} nm PV with the radius only → {:.0} nm PV with the form",
            p.ball_pv_nm[0], p.ball_pv_nm[1]
        ),
        "cannot know: the form outside the calibrated angles (never extrapolated: such contacts get the radius only)".into(),
        RADIUS_CONVENTION.into()],
        warnings: p.warnings.to_vec(),
        next: Some(p.next.clone()),
        tone: if p.warnings.is_empty() { Tone::Good } else { Tone::Unknown },
    });
    let xy = |v: &[f64]| -> Vec<(f64, f64)> {
        p.theta_deg.iter().copied().zip(v.iter().copied()).collect()
    };
    let mut order: Vec<usize> = (0..p.theta_deg.len()).collect();
    order.sort_by(|&a, &b| p.theta_deg[a].total_cmp(&p.theta_deg[b]));
    let form: Vec<(f64, f64)> = order
        .iter()
        .map(|&i| (p.theta_deg[i], p.form_nm[i]))
        .collect();
    let plot = XyPlot::new(
        "the probe's form error",
        "contact angle (°)",
        "form error (nm)",
    )
    .with(Series::line("fitted form", form))
    .with(Series::points(
        "residual on the ball with it",
        xy(p.residual_nm),
    ));
    page.plot(
        "form",
        "the form error against contact angle, and what is left on the ball",
        &plot,
    )?;
    write(&page, dir)
}

/// The 3-D probe calibration page: the form over the calibrated cone of
/// directions as a map (azimuth round the cone's axis × angle from it),
/// beside the ball's residual with the form on the same colour scale.
#[derive(Debug)]
pub struct Probe3dPage<'a> {
    /// The probe file.
    pub probe: &'a trueaxis_engine::onmachine::probe::sphere::Probe3d,
    /// The probe-centre positions of the scan, mm.
    pub points: &'a [[f64; 3]],
    /// Residual per point with the form, nm.
    pub residual_nm: &'a [f64],
    /// The ball's PV with the radius only and with the form, nm.
    pub ball_pv_nm: [f64; 2],
    /// Warnings.
    pub warnings: &'a [String],
    /// The command to run next.
    pub next: String,
}

/// An orthonormal pair perpendicular to the unit vector `a` (the first
/// along x's projection, or y's when `a` is near x), so that a direction
/// is `cos ψ·a + sin ψ (cos φ·u + sin φ·v)`; for `a = +z` φ is the usual
/// azimuth from +x.
fn cone_frame(a: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let e = if a[0].abs() > 0.9 {
        [0.0, 1.0, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let d = e[0] * a[0] + e[1] * a[1] + e[2] * a[2];
    let u = [e[0] - d * a[0], e[1] - d * a[1], e[2] - d * a[2]];
    let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = [u[0] / l, u[1] / l, u[2] / l];
    let v = [
        a[1] * u[2] - a[2] * u[1],
        a[2] * u[0] - a[0] * u[2],
        a[0] * u[1] - a[1] * u[0],
    ];
    (u, v)
}

/// Writes the 3-D probe calibration page into `dir`.
pub fn probe3d_page(p: &Probe3dPage, dir: &Path) -> Result<PathBuf> {
    let pr = p.probe;
    let a = pr.cone_axis;
    let (u, v) = cone_frame(a);
    let half = pr.cone_half_angle_deg;
    let mut page = Page::new("Probe calibration on the master ball (3-D)");
    page.verdict(Verdict {
        headline: format!(
            "Probe radius {:.6} mm ± {:.1} nm (95 %); form error {:.0} nm PV over a cone of {:.1}° round ({:.3}, {:.3}, {:.3}).",
            pr.probe_radius_mm,
            pr.probe_radius_ci95_mm * 1e6,
            pr.form_pv_nm,
            half,
            a[0] + 0.0,
            a[1] + 0.0,
            a[2] + 0.0
        )
        .replace("-0.000", "0.000"),
        details: vec![
            format!(
                "on the ball: {:.0} nm PV with the radius only → {:.0} nm PV with the form (degree {}, chosen by held-out RMS)",
                p.ball_pv_nm[0], p.ball_pv_nm[1], pr.degree
            ),
            format!(
                "cannot know: the form in directions more than {half:.1}° from the cone's axis (the grey band of the map) — contacts there are corrected with the radius only, never an extrapolated polynomial; to know them, scan the ball over those directions"
            ),
            RADIUS_CONVENTION.replace("calibrated angles", "calibrated cone"),
        ],
        warnings: p.warnings.to_vec(),
        next: Some(p.next.clone()),
        tone: if p.warnings.is_empty() { Tone::Good } else { Tone::Unknown },
    });
    // The map: every 10° of azimuth, every ~5° from the axis out to 20°
    // past the cone (those cells empty: not calibrated).
    let outer = (half + 20.0).min(180.0);
    let rows = ((outer / 5.0).ceil() as usize).max(2);
    let ys: Vec<f64> = (0..=rows).map(|i| outer * i as f64 / rows as f64).collect();
    let xs: Vec<f64> = (0..36).map(|i| 10.0 * i as f64).collect();
    let dir_at = |phi: f64, psi: f64| {
        let (sp, cp) = psi.to_radians().sin_cos();
        let (sf, cf) = phi.to_radians().sin_cos();
        [0, 1, 2].map(|k| cp * a[k] + sp * (cf * u[k] + sf * v[k]))
    };
    let mut values = Vec::with_capacity(xs.len() * ys.len());
    for &psi in &ys {
        for &phi in &xs {
            values.push((psi <= half + 1e-9).then(|| pr.form_nm_at(dir_at(phi, psi))));
        }
    }
    let mut form = HeatMap::from_points(
        "fitted form error",
        "azimuth round the axis (°)",
        "angle from the axis (°)",
        "nm",
        &[],
        1.0,
    );
    form.x = xs;
    form.y = ys;
    form.values = values;
    // The ball's residual at each contact, in the same coordinates.
    let c = pr.centre_mm;
    let pts: Vec<(f64, f64, f64)> = p
        .points
        .iter()
        .zip(p.residual_nm)
        .map(|(q, r)| {
            let d = [q[0] - c[0], q[1] - c[1], q[2] - c[2]];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let n = [d[0] / l, d[1] / l, d[2] / l];
            let dot = |w: [f64; 3]| n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
            let psi = dot(a).clamp(-1.0, 1.0).acos().to_degrees();
            // To 0.01° (rings of a scan land on one row, 360° on 0°).
            let round = |x: f64| (x * 100.0).round() / 100.0;
            let phi = round(dot(v).atan2(dot(u)).to_degrees()).rem_euclid(360.0);
            // Near the axis the azimuth means nothing (and a pole contact
            // a hair off it would make a column of its own): put it at 0.
            (if psi < 1.0 { 0.0 } else { phi }, round(psi), *r)
        })
        .collect();
    let resid = HeatMap::from_points(
        "residual on the ball with it",
        "azimuth round the axis (°)",
        "angle from the axis (°)",
        "nm",
        &pts,
        2.0,
    );
    page.plot(
        "form-map",
        "the probe's form error over the calibrated directions (left; grey: outside the cone, not calibrated) and what is left on the ball with it (right), on one colour scale",
        &MapPair {
                    before: &form,
                    after: &resid,
                },
    )?;
    write(&page, dir)
}

/// The `diagnose-part` page: the verdict (what is identified, what these
/// data cannot know and the sums they read), one row per source with its
/// size or the measurement that would tell it (`measures`: each finding's,
/// as the command words it), and the scan's profile.
pub fn part_diagnosis_page(
    d: &trueaxis_engine::onmachine::part_diagnosis::PartDiagnosis,
    verdict: &str,
    measures: &[Option<String>],
    sum_measures: &[Option<String>],
    dir: &Path,
) -> Result<PathBuf> {
    use trueaxis_engine::onmachine::part_diagnosis::Status;
    let mut page = Page::new("Which error is in this part scan");
    // Every measurement that would tell more: for what cannot be known,
    // and for what an estimate leaves out (a multi-step's inseparable
    // harmonics, the slides in a corrected arc).
    let wanted: Vec<String> = d
        .findings
        .iter()
        .zip(measures)
        .filter_map(|(f, m)| {
            let m = m.as_ref()?;
            Some(match f.status {
                Status::CannotKnow => {
                    format!("cannot know from these data — {}: {m}", f.source.label())
                }
                _ => format!("not in the estimate of the {} — {m}", f.source.label()),
            })
        })
        .collect();
    let unknown = !wanted.is_empty();
    let mut details = vec![format!(
        "{} scan, {}{}",
        crate::report::a_or_an(d.kind),
        crate::report::count(d.points, "point"),
        d.noise_um
            .map(|n| format!(", reading noise {n:.3} µm"))
            .unwrap_or_default()
    )];
    details.extend(wanted);
    page.verdict(Verdict {
        headline: {
            let mut c = verdict.chars();
            c.next()
                .map(|f| format!("{}{}.", f.to_uppercase(), c.as_str()))
                .unwrap_or_default()
        },
        details,
        warnings: Vec::new(),
        next: None,
        tone: if unknown { Tone::Unknown } else { Tone::Good },
    });
    let rows = d
        .findings
        .iter()
        .zip(measures)
        .map(|(f, m)| {
            let size = match (f.value, f.ci95) {
                (Some(v), Some([lo, hi])) => {
                    let p = if f.unit == "mm" { 6 } else { 3 };
                    format!("{v:.p$} {u} (95 %: {lo:.p$} … {hi:.p$})", u = f.unit)
                }
                _ => "—".into(),
            };
            let status = match f.status {
                Status::Estimated => "estimated",
                Status::NotInScan => "not in this scan",
                Status::CannotKnow => "cannot know from these data",
            };
            vec![
                f.source.label().to_string(),
                status.to_string(),
                size,
                f.what.clone(),
                m.clone().unwrap_or_default(),
            ]
        })
        .collect();
    page.table(&["source", "status", "size", "what", "measure"], rows);
    if !d.combined.is_empty() {
        // The sums the scan reads: sized as sums, never split.
        page.heading("Read only as sums");
        let rows = d
            .combined
            .iter()
            .zip(sum_measures)
            .map(|(c, m)| {
                let p = if c.unit == "nm" { 1 } else { 3 };
                let size = match c.ci95 {
                    Some([lo, hi]) => format!(
                        "{:.p$} {u} PV (95 %: {lo:.p$} … {hi:.p$})",
                        c.pv,
                        u = c.unit
                    ),
                    None => format!("{:.p$} {} PV", c.pv, c.unit),
                };
                let labels: Vec<&str> = c.sources.iter().map(|s| s.label()).collect();
                vec![
                    labels.join(" + "),
                    size,
                    c.what.clone(),
                    m.clone().unwrap_or_default(),
                ]
            })
            .collect();
        page.table(&["together", "size", "what", "measure"], rows);
    }
    if !d.profile.is_empty() {
        let (x, what) = match d.kind {
            "straightness" => ("position (mm)", "the readings, line removed"),
            "roundness" => (
                "rotation angle (°)",
                "the readings round the turn, harmonics 0 and 1 removed",
            ),
            _ => (
                "contact angle (°)",
                "the centre path against its least-squares circle",
            ),
        };
        let plot = XyPlot::new(
            "what the scan reads",
            x,
            format!("deviation ({})", d.profile_unit),
        )
        .with(Series::points("scan", d.profile.clone()));
        page.plot(
            "scan",
            format!("{what}: every source it holds, summed (a drift found is removed)"),
            &plot,
        )?;
    }
    write(&page, dir)
}

/// The workpiece page: the form along each generatrix (points and fit),
/// the form around the part at mid-length, and the history.
#[derive(Debug)]
pub struct WorkpiecePage<'a> {
    /// `(c_deg, z_mm, dev_um)` of the scan.
    pub points: &'a [[f64; 3]],
    /// The fitted form (its deviation at `(c_deg, z_mm)`, µm: `at`).
    pub form: &'a trueaxis_engine::onmachine::workpiece::Form,
    /// The measured length, mm.
    pub z_range_mm: [f64; 2],
    /// Form PV, RMS and eccentricity, µm.
    pub form_pv_um: f64,
    /// See above.
    pub form_rms_um: f64,
    /// See above.
    pub eccentricity_um: f64,
    /// The part's history: form PV per pass, µm.
    pub history_pv_um: Vec<f64>,
    /// Warnings.
    pub warnings: &'a [String],
    /// The command to run next.
    pub next: Option<String>,
}

/// Writes the workpiece page into `dir`.
pub fn workpiece_page(w: &WorkpiecePage, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new("Workpiece form");
    let mut details = vec![
        format!(
            "RMS {:.3} µm; eccentricity {:.3} µm (set-up, not form)",
            w.form_rms_um, w.eccentricity_um
        ),
        "cannot know from one set-up: how much of this is the part and how much the machine measuring it (the slide's straightness along z, the spindle's error motion around c) — the correction pass corrects both while they repeat; to tell them apart, turn the part 180° and run trueaxis separate reversal, or remount it in steps and run trueaxis separate multi-step".into(),
    ];
    if w.history_pv_um.len() > 1 {
        details.push(format!(
            "pass by pass: {} µm PV",
            w.history_pv_um
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(" → ")
        ));
    }
    page.verdict(Verdict {
        headline: format!(
            "The part's form is {:.3} µm PV over the measured length.",
            w.form_pv_um
        ),
        details,
        warnings: w.warnings.to_vec(),
        next: w.next.clone(),
        tone: Tone::Action,
    });
    // Generatrices: the distinct c angles (at most 6 drawn).
    let mut cs: Vec<f64> = w.points.iter().map(|p| p[0]).collect();
    cs.sort_by(f64::total_cmp);
    cs.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let step = cs.len().div_ceil(6).max(1);
    // One y scale for every generatrix (and the fit over the measured
    // length): they are compared by height.
    let [z0, z1] = w.z_range_mm;
    let (lo, hi) = cs
        .iter()
        .flat_map(|&c| (0..=100).map(move |k| (c, z0 + (z1 - z0) * k as f64 / 100.0)))
        .map(|(c, z)| w.form.at(c, z))
        .chain(w.points.iter().map(|p| p[2]))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    let pad = 0.08 * (hi - lo).max(1e-6);
    let mut figs = Vec::new();
    for &c in cs.iter().step_by(step) {
        let mut pts: Vec<(f64, f64)> = w
            .points
            .iter()
            .filter(|p| (p[0] - c).abs() < 1e-6)
            .map(|p| (p[1], p[2]))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let fit: Vec<(f64, f64)> = (0..=100)
            .map(|k| {
                let z = z0 + (z1 - z0) * k as f64 / 100.0;
                (z, w.form.at(c, z))
            })
            .collect();
        let plot = XyPlot::new(
            format!("generatrix at c = {c:.0}°"),
            "z (mm)",
            "deviation (µm)",
        )
        .with(Series::points("measured", pts))
        .with(Series::line("fitted form", fit))
        .with_y_range(lo - pad, hi + pad);
        figs.push(super::Figure {
            name: format!("gen{}", (c * 10.0).round() as i64),
            caption: format!("along z at c = {c:.1}°"),
            svg: plot.svg()?,
            narrow: plot.phone_svg()?,
        });
    }
    let zm = 0.5 * (w.z_range_mm[0] + w.z_range_mm[1]);
    let around: Vec<f64> = (0..360).map(|k| w.form.at(k as f64, zm)).collect();
    page.heading("Around the part at mid-length");
    page.figure(
        "around",
        format!("the fitted form around the part at z = {zm:.1} mm (deviations magnified)"),
        polar_svg("form around the part (µm)", &[("fitted form", &around)]),
    );
    page.heading("Along the generatrices");
    page.grid_wide(figs);
    write(&page, dir)
}
