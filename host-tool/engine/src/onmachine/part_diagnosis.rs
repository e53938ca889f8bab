//! The diagnosis loop on part scans (docs/on-machine.md § diagnose-part):
//! *which error is in my measurement — the part, the probe or the
//! machine?* For each candidate source — probe radius, probe form, part
//! form, slide straightness, spindle error motion, thermal drift during the
//! scan — the scan and whatever else the user measured either give its size
//! with a 95 % interval, or the answer is that this kind of scan cannot
//! contain it, or that **these data cannot tell it** from another source,
//! with the measurement that would. A single-orientation scan reads sums:
//! part form + slide straightness along a slide, part roundness + spindle
//! error motion round a turning part, part form + probe form (and part
//! size + probe radius) along an arc. Those sums are reported as sums,
//! never split by assumption — a confident wrong split is the worst
//! answer this module could give.
//!
//! The separations themselves are the ones of `separate` (reversal,
//! multi-step) and `probe` (the ball calibration, the correction along the
//! normals); this module only decides what the data at hand identify.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::onmachine::probe;
use crate::onmachine::separate::{self, pv};

/// z-value of a two-sided 95 % interval.
const Z95: f64 = 1.96;

/// The part scan: one of the three kinds the on-machine commands read.
#[derive(Clone, Debug)]
pub enum Scan {
    /// A probe read along a straight part on a slide: positions (mm) and
    /// readings (µm), in scan order.
    Straightness {
        /// Position along the travel, mm.
        pos_mm: Vec<f64>,
        /// Reading, µm.
        d_um: Vec<f64>,
    },
    /// One fixed probe reading a turning part: rotation angles (degrees)
    /// and readings (µm), in scan order.
    Roundness {
        /// Rotation angle, degrees.
        c_deg: Vec<f64>,
        /// Reading, µm.
        p_um: Vec<f64>,
    },
    /// Probe-centre positions along an arc (or all round) of a round part
    /// in a plane, mm, in scan order; `side` which way the surface faces
    /// where the probe touches (as `probe correct`'s).
    Arc {
        /// Probe-centre positions, mm.
        p_mm: Vec<[f64; 2]>,
        /// Outward direction of the surface at the contacts.
        side: probe::Side,
    },
}

impl Scan {
    /// The kind's name (`straightness`, `roundness`, `arc`).
    pub fn kind(&self) -> &'static str {
        match self {
            Scan::Straightness { .. } => "straightness",
            Scan::Roundness { .. } => "roundness",
            Scan::Arc { .. } => "arc",
        }
    }

    fn len(&self) -> usize {
        match self {
            Scan::Straightness { pos_mm, .. } => pos_mm.len(),
            Scan::Roundness { c_deg, .. } => c_deg.len(),
            Scan::Arc { p_mm, .. } => p_mm.len(),
        }
    }
}

/// A calibrated probe, of either kind of probe file, as this module needs
/// it.
#[allow(missing_debug_implementations)] // holds a closure
pub struct KnownProbe<'a> {
    /// Effective radius, mm.
    pub radius_mm: f64,
    /// Half-width of its 95 % interval, mm.
    pub radius_ci95_mm: f64,
    /// Peak to valley of the form over the calibrated directions, nm.
    pub form_pv_nm: f64,
    /// Half-width of the 95 % interval of the form at one angle, nm
    /// (typically: a least-squares fit of p coefficients to N points of
    /// noise σ has an average pointwise standard deviation σ·√(p/N)).
    pub form_ci95_nm: f64,
    /// The form at an in-plane contact angle (rad), nm; `None` outside the
    /// calibrated directions.
    pub form: &'a dyn Fn(f64) -> Option<f64>,
}

/// What else was measured besides the scan.
#[derive(Default)]
#[allow(missing_debug_implementations)] // holds a closure
pub struct Evidence<'a> {
    /// Time stamps of the scan's rows, s.
    pub t_s: Option<Vec<f64>>,
    /// The probe calibrated on a master ball.
    pub probe: Option<KnownProbe<'a>>,
    /// The part's known diameter (a gauge of certified size), mm.
    pub part_diameter_mm: Option<f64>,
    /// A straightness scan's second run, the part turned 180° and the
    /// probe reversed: `(pos_mm, d_um)`.
    pub reversal: Option<Vec<(f64, f64)>>,
    /// A multi-step set: the readings of each step at their spindle
    /// angles.
    pub multi_step: Option<Vec<separate::Step>>,
}

/// A candidate source of error in a part scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// The probe's effective radius (against what is assumed).
    ProbeRadius,
    /// The probe's form error as a function of contact direction (lobing).
    ProbeForm,
    /// The part's form (straightness, roundness or profile).
    PartForm,
    /// The straightness of the slide the probe or part rides on.
    SlideStraightness,
    /// The spindle's radial error motion.
    SpindleErrorMotion,
    /// Thermal growth (drift of the reading) during the scan.
    ThermalDrift,
}

impl Source {
    /// Every source, in the order they are reported.
    pub const ALL: [Source; 6] = [
        Source::ProbeRadius,
        Source::ProbeForm,
        Source::PartForm,
        Source::SlideStraightness,
        Source::SpindleErrorMotion,
        Source::ThermalDrift,
    ];

    /// Human name.
    pub fn label(self) -> &'static str {
        match self {
            Source::ProbeRadius => "probe radius",
            Source::ProbeForm => "probe form",
            Source::PartForm => "part form",
            Source::SlideStraightness => "slide straightness",
            Source::SpindleErrorMotion => "spindle error motion",
            Source::ThermalDrift => "thermal drift",
        }
    }
}

/// What the data say about one source.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Its size is identified by these data (with a 95 % interval).
    Estimated,
    /// This kind of scan cannot contain it.
    NotInScan,
    /// It may be in the scan, but these data cannot tell it from another
    /// source: `measure` says what would.
    CannotKnow,
}

/// What the user could give the diagnosis besides the scan (the
/// [`Evidence`] field it fills). The engine names it; the command line
/// writes it as its flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Input {
    /// The straightness run with the part turned 180° ([`Evidence::reversal`]).
    Reversal,
    /// A multi-step set ([`Evidence::multi_step`]).
    MultiStep,
    /// A probe file from the ball calibration ([`Evidence::probe`]).
    Probe,
    /// The part's known diameter ([`Evidence::part_diameter_mm`]).
    PartDiameter,
}

impl Input {
    /// The input in the engine's words (what a caller without flags says).
    pub fn words(self) -> &'static str {
        match self {
            Input::Reversal => "the run with the part turned 180°",
            Input::MultiStep => "the multi-step set",
            Input::Probe => "the probe file",
            Input::PartDiameter => "the part's known diameter",
        }
    }
}

/// One piece of a [`Measure`].
#[derive(Clone, Debug, PartialEq)]
pub enum Piece {
    /// Words.
    Say(String),
    /// An input to give, named by the caller (a flag at the command line).
    Give(Input),
}

/// What to measure to know a source (or what an estimate leaves out):
/// words and the [`Input`]s that would carry the measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct Measure(pub Vec<Piece>);

impl Measure {
    /// Words only.
    fn say(s: impl Into<String>) -> Measure {
        Measure(vec![Piece::Say(s.into())])
    }

    /// The text, each input named by `name`.
    pub fn render(&self, name: impl Fn(Input) -> String) -> String {
        self.0
            .iter()
            .map(|p| match p {
                Piece::Say(s) => s.clone(),
                Piece::Give(i) => name(*i),
            })
            .collect()
    }

    /// Whether it asks for `input`.
    pub fn gives(&self, input: Input) -> bool {
        self.0.contains(&Piece::Give(input))
    }
}

impl std::fmt::Display for Measure {
    /// In the engine's words ([`Input::words`]).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(|i| i.words().to_string()))
    }
}

impl Serialize for Measure {
    /// As its text in the engine's words; a command writes its own.
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// One source's finding.
#[derive(Clone, Debug, Serialize)]
pub struct Finding {
    /// The source.
    pub source: Source,
    /// Identified, not in this scan, or not identifiable from these data.
    pub status: Status,
    /// The estimate (`estimated` only), in `unit`.
    pub value: Option<f64>,
    /// Its 95 % interval `[lo, hi]`, in `unit`.
    pub ci95: Option<[f64; 2]>,
    /// Unit of `value`: `mm`, `µm`, `nm` or `µm/min`.
    pub unit: &'static str,
    /// What the value is, or why there is none.
    pub what: String,
    /// What to measure to know it (or the part of it an estimate leaves
    /// out).
    pub measure: Option<Measure>,
}

/// A sum the scan reads that these data cannot split.
#[derive(Clone, Debug, Serialize)]
pub struct Combined {
    /// The sources in the sum.
    pub sources: Vec<Source>,
    /// Its peak to valley, in `unit`.
    pub pv: f64,
    /// `µm` or `nm`.
    pub unit: &'static str,
    /// Its 95 % interval `[lo, hi]`, in `unit` (every point's bound at
    /// once), when the noise is known.
    pub ci95: Option<[f64; 2]>,
    /// What the sum is (which harmonics, what was removed).
    pub what: String,
    /// What would separate it.
    pub measure: Option<Measure>,
}

/// A sum of `sources` with its PV and, with the per-point uncertainty
/// `ci` (every point at once), its interval.
fn combined_sum(
    sources: Vec<Source>,
    pv_: f64,
    ci: Option<f64>,
    unit: &'static str,
    what: String,
    measure: Measure,
) -> Combined {
    Combined {
        sources,
        pv: pv_,
        unit,
        ci95: ci
            .filter(|c| c.is_finite())
            .map(|c| [(pv_ - 2.0 * c).max(0.0), pv_ + 2.0 * c]),
        what,
        measure: Some(measure),
    }
}

/// The diagnosis of one part scan.
#[derive(Clone, Debug, Serialize)]
pub struct PartDiagnosis {
    /// `straightness`, `roundness` or `arc`.
    pub kind: &'static str,
    /// Rows of the scan.
    pub points: usize,
    /// Reading noise from the scan's second differences, µm.
    pub noise_um: Option<f64>,
    /// One finding per source, in [`Source::ALL`]'s order.
    pub findings: Vec<Finding>,
    /// The sums these data read but cannot split.
    pub combined: Vec<Combined>,
    /// What the scan reads, for a plot: `(position, deviation)` — along
    /// the travel (mm, line removed), round the turn (°, harmonics 0 and 1
    /// removed) or over the contact angle (°, the least-squares circle
    /// removed), a drift found removed; in `profile_unit`.
    #[serde(skip)]
    pub profile: Vec<(f64, f64)>,
    /// Unit of the profile's deviations (`µm` or `nm`).
    #[serde(skip)]
    pub profile_unit: &'static str,
}

impl PartDiagnosis {
    /// The finding for `s`.
    pub fn get(&self, s: Source) -> &Finding {
        self.findings
            .iter()
            .find(|f| f.source == s)
            .expect("every source has a finding")
    }
}

fn estimated(source: Source, value: f64, half: f64, unit: &'static str, what: String) -> Finding {
    Finding {
        source,
        status: Status::Estimated,
        value: Some(value),
        ci95: Some([value - half, value + half]),
        unit,
        what,
        measure: None,
    }
}

pub use crate::onmachine::separate::z_all;

/// A peak to valley with its interval: when every point is within `ci` of
/// the truth at once (95 %: `ci = z_all(n)·σ`), the peak and the valley
/// are each off by at most that, so the PV by at most `2·ci` (never below
/// 0).
fn pv_estimated(source: Source, pv_: f64, ci: f64, unit: &'static str, what: String) -> Finding {
    let mut f = estimated(source, pv_, 2.0 * ci, unit, what);
    f.ci95 = Some([(pv_ - 2.0 * ci).max(0.0), pv_ + 2.0 * ci]);
    f
}

fn not_in_scan(source: Source, unit: &'static str, why: &str) -> Finding {
    Finding {
        source,
        status: Status::NotInScan,
        value: None,
        ci95: None,
        unit,
        what: why.to_string(),
        measure: None,
    }
}

fn cannot_know(source: Source, unit: &'static str, why: String, measure: Measure) -> Finding {
    Finding {
        source,
        status: Status::CannotKnow,
        value: None,
        ci95: None,
        unit,
        what: why,
        measure: Some(measure),
    }
}

/// `y` minus its least-squares fit on the columns `cols(x)`, and the
/// solution.
fn remove_fit(
    x: &[f64],
    y: &[f64],
    cols: impl Fn(f64) -> Vec<f64>,
) -> Result<(Vec<f64>, crate::lsq::LsqSolution)> {
    let rows: Vec<Vec<f64>> = x.iter().map(|&v| cols(v)).collect();
    let k = rows[0].len();
    let a = DMatrix::from_fn(x.len(), k, |i, j| rows[i][j]);
    let b = DVector::from_column_slice(y);
    let s = crate::lsq::solve(&a, &b, None)?;
    let r = y
        .iter()
        .zip(&rows)
        .map(|(v, row)| {
            v - row
                .iter()
                .zip(s.coef.iter())
                .map(|(a, c)| a * c)
                .sum::<f64>()
        })
        .collect();
    Ok((r, s))
}

/// The thermal drift from a position read again later with time stamps:
/// the finding (rate in µm/min) and the rate in µm/s when identified.
/// `reading_um[i]` is the reading at row i, `same(j)` whether row j is at
/// row 0's position.
fn thermal(
    reading_um: &[f64],
    t_s: Option<&[f64]>,
    noise_um: Option<f64>,
    same: impl Fn(usize) -> bool,
    repeat_how: &str,
) -> (Finding, Option<f64>) {
    let unit = "µm/min";
    let Some(t) = t_s else {
        return (
            cannot_know(
                Source::ThermalDrift,
                unit,
                "the scan has no time stamps: a drift during the scan reads as form".into(),
                Measure::say(format!("add a `t_s` column (seconds) and {repeat_how}")),
            ),
            None,
        );
    };
    let Some(j) = (1..reading_um.len())
        .rev()
        .find(|&j| same(j) && t[j] > t[0])
    else {
        return (
            cannot_know(
                Source::ThermalDrift,
                unit,
                "no position is read twice: a drift during the scan reads as form".into(),
                Measure::say(format!("{repeat_how}, with its time stamp")),
            ),
            None,
        );
    };
    let Some(sigma) = noise_um else {
        return (
            cannot_know(
                Source::ThermalDrift,
                unit,
                "too few readings to know their noise".into(),
                Measure::say("read at least 8 points"),
            ),
            None,
        );
    };
    let dt_min = (t[j] - t[0]) / 60.0;
    let drift = reading_um[j] - reading_um[0];
    let half = Z95 * 2f64.sqrt() * sigma;
    let f = estimated(
        Source::ThermalDrift,
        drift / dt_min,
        half / dt_min,
        unit,
        format!(
            "the start position read again {:.1} min later (row {}) moved {drift:+.3} ± {half:.3} µm; taken as linear in time and removed from the readings",
            dt_min,
            j + 1
        ),
    );
    (f, Some(drift / (t[j] - t[0])))
}

/// Diagnoses a part scan with the evidence at hand.
pub fn diagnose(scan: &Scan, ev: &Evidence) -> Result<PartDiagnosis> {
    let n = scan.len();
    if n < 8 {
        bail!("{n} points; a part scan needs at least 8");
    }
    if let Some(t) = &ev.t_s {
        if t.len() != n {
            bail!("{} time stamps for {n} points", t.len());
        }
    }
    match scan {
        Scan::Straightness { pos_mm, d_um } => straightness(pos_mm, d_um, ev),
        Scan::Roundness { c_deg, p_um } => roundness(c_deg, p_um, ev),
        Scan::Arc { p_mm, side } => arc(p_mm, *side, ev),
    }
}

/// Readings with a linear drift in time removed.
fn without_drift(r: &[f64], t: Option<&[f64]>, rate_per_s: Option<f64>) -> Vec<f64> {
    match (t, rate_per_s) {
        (Some(t), Some(k)) => r.iter().zip(t).map(|(v, ti)| v - k * (ti - t[0])).collect(),
        _ => r.to_vec(),
    }
}

const PROBE_ONE_DIRECTION: &str = "the probe touches the part in one direction all along: its radius and form add a constant, which carries no form";

fn straightness(pos: &[f64], d: &[f64], ev: &Evidence) -> Result<PartDiagnosis> {
    let noise = separate::noise(d);
    let t = ev.t_s.as_deref();
    let (th, rate) = thermal(
        d,
        t,
        noise,
        |j| (pos[j] - pos[0]).abs() < 1e-6,
        "read the start position again at the end",
    );
    let d = without_drift(d, t, rate);
    let (sum, _) = remove_fit(pos, &d, |x| vec![1.0, x])?;
    let mut findings = vec![
        not_in_scan(Source::ProbeRadius, "mm", PROBE_ONE_DIRECTION),
        not_in_scan(Source::ProbeForm, "nm", PROBE_ONE_DIRECTION),
    ];
    let mut combined = Vec::new();
    if let Some(r180) = &ev.reversal {
        let run1: Vec<(f64, f64)> = pos.iter().copied().zip(d.iter().copied()).collect();
        let rv = separate::reversal(&run1, r180)?;
        let ci = z_all(rv.pos_mm.len()) * rv.point_sigma_um.unwrap_or(f64::NAN);
        let left = "line removed; an error that changed between the two runs (drift between them) is in both halves";
        findings.push(pv_estimated(
            Source::PartForm,
            rv.part_pv_um,
            ci,
            "µm",
            format!("peak to valley from the reversal pair, {left}"),
        ));
        findings.push(pv_estimated(
            Source::SlideStraightness,
            rv.slide_pv_um,
            ci,
            "µm",
            format!("peak to valley from the reversal pair, {left}"),
        ));
    } else {
        let why = format!(
            "one orientation reads part form + slide straightness as one sum ({:.3} µm PV together, line removed)",
            pv(&sum)
        );
        let m = Measure(vec![
            Piece::Say(
                "turn the part 180° about the travel, reverse the probe and scan again: ".into(),
            ),
            Piece::Give(Input::Reversal),
            Piece::Say(" (separate reversal)".into()),
        ]);
        findings.push(cannot_know(Source::PartForm, "µm", why.clone(), m.clone()));
        findings.push(cannot_know(Source::SlideStraightness, "µm", why, m.clone()));
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SlideStraightness],
            pv(&sum),
            noise.map(|n| z_all(pos.len()) * n),
            "µm",
            "the readings along the travel, line removed".into(),
            m,
        ));
    }
    findings.push(not_in_scan(
        Source::SpindleErrorMotion,
        "µm",
        "the spindle does not turn during a straightness scan",
    ));
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "straightness",
        points: pos.len(),
        noise_um: noise,
        findings,
        combined,
        profile: pos.iter().copied().zip(sum).collect(),
        profile_unit: "µm",
    })
}

fn roundness(c_deg: &[f64], p: &[f64], ev: &Evidence) -> Result<PartDiagnosis> {
    let noise = separate::noise(p);
    let t = ev.t_s.as_deref();
    let same = |j: usize| {
        let d = (c_deg[j] - c_deg[0]).rem_euclid(360.0);
        d.min(360.0 - d) < 1e-6
    };
    let (th, rate) = thermal(
        p,
        t,
        noise,
        same,
        "close the turn (read the start angle again at the end)",
    );
    let p = without_drift(p, t, rate);
    let (sum, _) = remove_fit(c_deg, &p, |c| {
        let r = c.to_radians();
        vec![1.0, r.cos(), r.sin()]
    })?;
    let mut findings = vec![
        not_in_scan(Source::ProbeRadius, "mm", "a fixed probe touches the turning part in one direction: its radius only adds to the size"),
        not_in_scan(Source::ProbeForm, "nm", "a fixed probe touches the turning part in one direction: its form adds a constant, which is not roundness"),
    ];
    let mut combined = Vec::new();
    if let Some(steps) = &ev.multi_step {
        let ms = separate::multi_step(steps, None)?;
        let list: Vec<String> = ms
            .inseparable_harmonics
            .iter()
            .take(4)
            .map(|k| k.to_string())
            .collect();
        let list = format!("{}, …", list.join(", "));
        let mut part = estimated(
            Source::PartForm,
            ms.part_pv_um,
            0.0,
            "µm",
            format!("roundness (harmonics 2…) from the multi-step set of {} steps, without its harmonics {list}", ms.steps),
        );
        part.ci95 = Some(ms.part_ci95_um);
        let remedy = format!(
            "the part's harmonics {list} cannot be told from the spindle's with {} steps: a multi-step whose number of steps divides none of the lobes you look for, or three probes (separate three-probe)",
            ms.steps
        );
        part.measure = Some(Measure::say(remedy.clone()));
        findings.push(part);
        let em = &ms.error_motion;
        let mut spin = estimated(
            Source::SpindleErrorMotion,
            em.synchronous_um,
            0.0,
            "µm",
            format!(
                "synchronous radial error motion along the probe (ISO 230-7: the turn average, its once-per-turn term — centring, {:.3} µm — left out) from the multi-step set, without harmonics {list}",
                em.centring_um
            ),
        );
        spin.ci95 = Some(em.synchronous_ci95_um);
        spin.measure = Some(Measure::say(remedy.clone()));
        findings.push(spin);
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SpindleErrorMotion],
            ms.error_motion.excluded_pv_um,
            Some(z_all(ms.samples) * ms.point_sigma_um),
            "µm",
            format!(
                "harmonics {list}: the part's and the spindle's, which {} steps cannot tell apart",
                ms.steps
            ),
            Measure::say(remedy),
        ));
    } else {
        let why = format!(
            "one orientation reads part roundness + spindle error motion as one sum ({:.3} µm PV together, harmonics 0 and 1 removed)",
            pv(&sum)
        );
        let m = Measure(vec![
            Piece::Say("remount the part at N equally spaced steps and read a turn at each: ".into()),
            Piece::Give(Input::MultiStep),
            Piece::Say(" (separate multi-step; the part's lobes at multiples of N stay inseparable, so choose N dividing none you look for), or read it with three probes (separate three-probe)".into()),
        ]);
        findings.push(cannot_know(Source::PartForm, "µm", why.clone(), m.clone()));
        findings.push(cannot_know(
            Source::SpindleErrorMotion,
            "µm",
            why,
            m.clone(),
        ));
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SpindleErrorMotion],
            pv(&sum),
            noise.map(|n| z_all(c_deg.len()) * n),
            "µm",
            "the readings round the turn, harmonics 0 and 1 removed".into(),
            m,
        ));
    }
    findings.insert(
        3,
        not_in_scan(
            Source::SlideStraightness,
            "µm",
            "no slide moves during a roundness scan",
        ),
    );
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "roundness",
        points: c_deg.len(),
        noise_um: noise,
        findings,
        combined,
        profile: c_deg.iter().copied().zip(sum).collect(),
        profile_unit: "µm",
    })
}

fn arc(p: &[[f64; 2]], side: probe::Side, ev: &Evidence) -> Result<PartDiagnosis> {
    let (c, rc) = probe::kasa(p)?;
    let theta: Vec<f64> = p.iter().map(|q| (q[1] - c[1]).atan2(q[0] - c[0])).collect();
    let dev_um: Vec<f64> = p
        .iter()
        .map(|q| ((q[0] - c[0]).hypot(q[1] - c[1]) - rc) * 1e3)
        .collect();
    let noise = separate::noise(&dev_um);
    let t = ev.t_s.as_deref();
    let (th, _) = thermal(
        &dev_um,
        t,
        noise,
        |j| (p[j][0] - p[0][0]).hypot(p[j][1] - p[0][1]) < 0.01,
        "probe the first point again at the end",
    );
    // The deviations from the circle, radius and centre removed (as a
    // linear fit they carry the radius's standard deviation per unit noise).
    let (resid, sol) = remove_fit(&theta, &dev_um, |t| vec![1.0, t.cos(), t.sin()])?;
    let sd_unit = sol.coef_sd[0] / (sol.rss / sol.dof.max(1) as f64).sqrt();
    let sigma = noise.unwrap_or(f64::NAN);
    let raw_pv_nm = pv(&resid) * 1e3;
    // Convex (probed from outside): the centre path's radius is the part's
    // plus the probe's; a bore's is the part's minus the probe's.
    let mid = p[p.len() / 2];
    let convex = match side {
        probe::Side::Out => true,
        probe::Side::In => false,
        probe::Side::Toward(d) => (mid[0] - c[0]) * d[0] + (mid[1] - c[1]) * d[1] > 0.0,
    };
    let sign = if convex { 1.0 } else { -1.0 };
    let from_diameter = ev
        .part_diameter_mm
        .map(|d| (sign * (rc - d / 2.0), Z95 * sigma * sd_unit * 1e-3));
    let mut findings = Vec::new();
    let mut combined = Vec::new();
    findings.push(match (&ev.probe, from_diameter) {
        (Some(k), d) => {
            let mut f = estimated(Source::ProbeRadius, k.radius_mm, k.radius_ci95_mm, "mm", "effective radius from the ball calibration".into());
            if let Some((r, h)) = d {
                f.what.push_str(&format!(
                    "; the known diameter gives {r:.6} ± {h:.6} mm (with the form of zero mean over these contact angles)"
                ));
            }
            f
        }
        (None, Some((r, h))) => estimated(
            Source::ProbeRadius,
            r,
            h,
            "mm",
            format!(
                "the centre path's radius {rc:.6} mm {} the known radius; with the probe's and the part's form of zero mean and no tilt over these contact angles, the diameter taken as exact",
                if convex { "less" } else { "from" }
            ),
        ),
        (None, None) => cannot_know(
            Source::ProbeRadius,
            "mm",
            format!("the centre path's radius ({rc:.6} mm) holds the part's radius and the probe's as one sum"),
            Measure(vec![
                Piece::Say("calibrate the probe on a master ball (probe calibrate, then ".into()),
                Piece::Give(Input::Probe),
                Piece::Say(") or scan a part of known diameter (".into()),
                Piece::Give(Input::PartDiameter),
                Piece::Say(")".into()),
            ]),
        ),
    });
    let slide = cannot_know(
        Source::SlideStraightness,
        "nm",
        "an arc is scanned by moving two slides: their straightness adds to the form at the same points".into(),
        Measure::say("run a reversal along each slide (separate reversal)"),
    );
    match &ev.probe {
        Some(k) => {
            let contacts = probe::correct_with(p, side, k.radius_mm, |t| (k.form)(t))?;
            let outside = contacts.iter().filter(|x| !x.calibrated).count();
            // What the probe's form puts into this scan's form: its values
            // at the calibrated contacts less what the least-squares circle
            // takes (1, cos θ, sin θ over these angles) — the same whatever
            // convention the probe file keeps (a 2-D file's form has no
            // mean or tilt over the ball's arc, a 3-D file's over the
            // sphere). The interval is the series' (a smooth function: its
            // error at the peak and at the valley each within that).
            let cal: Vec<&probe::Contact> = contacts.iter().filter(|x| x.calibrated).collect();
            let in_scan = if cal.len() >= 4 {
                let t: Vec<f64> = cal.iter().map(|x| x.theta_deg.to_radians()).collect();
                let f: Vec<f64> = cal.iter().map(|x| x.form_nm).collect();
                pv(&remove_fit(&t, &f, |t| vec![1.0, t.cos(), t.sin()])?.0)
            } else {
                0.0
            };
            let mut pf = pv_estimated(
                Source::ProbeForm,
                in_scan,
                k.form_ci95_nm,
                "nm",
                format!(
                    "peak to valley of its form over this scan's contact angles less what a circle takes there, from the ball calibration ({:.1} nm PV over all the calibrated directions)",
                    k.form_pv_nm
                ),
            );
            if outside > 0 {
                pf.measure = Some(Measure::say(format!("{outside} contact(s) lie outside the calibrated directions (corrected with the radius only): calibrate over the angles the part presents")));
            }
            findings.push(pf);
            // The corrected contacts still hold the straightness of the
            // slides that carried the probe along the arc: a sum, said as
            // one (its interval is the noise's; the split is unknown).
            let s: Vec<[f64; 2]> = contacts.iter().map(|x| x.surface_mm).collect();
            let dev = probe::form_deviation_nm(&s, true)?;
            let by_reversal = Measure::say("run a reversal along each slide (separate reversal), or scan the part turned on the table so the slides' errors move with it");
            findings.push(cannot_know(
                Source::PartForm,
                "nm",
                format!("the probe-corrected arc holds the part's form and the straightness of the slides that moved the probe along it as one sum ({:.1} nm PV together, against the least-squares circle)", pv(&dev)),
                by_reversal.clone(),
            ));
            combined.push(combined_sum(
                vec![Source::PartForm, Source::SlideStraightness],
                pv(&dev),
                Some(z_all(p.len()) * sigma * 1e3),
                "nm",
                "the arc corrected with the probe's radius and form, against the least-squares circle".into(),
                by_reversal,
            ));
        }
        None => {
            let why = format!("on one scan the probe's form at a contact angle and the part's form there are one sum ({raw_pv_nm:.1} nm PV together, against the least-squares circle)");
            let calibrate = |how: &str| {
                Measure(vec![
                    Piece::Say(format!(
                        "calibrate the probe on a master ball{how} (probe calibrate, then "
                    )),
                    Piece::Give(Input::Probe),
                    Piece::Say(")".into()),
                ])
            };
            findings.push(cannot_know(
                Source::ProbeForm,
                "nm",
                why.clone(),
                calibrate(" over the same contact angles"),
            ));
            findings.push(cannot_know(Source::PartForm, "nm", why, calibrate("")));
            combined.push(combined_sum(
                vec![
                    Source::ProbeForm,
                    Source::PartForm,
                    Source::SlideStraightness,
                ],
                raw_pv_nm,
                Some(z_all(p.len()) * sigma * 1e3),
                "nm",
                "the probe centres against their least-squares circle".into(),
                calibrate(""),
            ));
        }
    }
    findings.push(slide);
    findings.push(not_in_scan(
        Source::SpindleErrorMotion,
        "µm",
        "the spindle does not turn during the scan",
    ));
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "arc",
        points: p.len(),
        noise_um: noise,
        findings,
        combined,
        profile: theta
            .iter()
            .zip(&resid)
            .map(|(t, r)| (t.to_degrees(), r * 1e3))
            .collect(),
        profile_unit: "nm",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quantile_of_the_largest_of_n_normals() {
        // One point: the usual 1.96; 500 points: about 3.9 (the tables of
        // the normal: P(|N| > 3.89) = 1.0e-4 = 1 − 0.95^(1/500)).
        assert!((z_all(1) - 1.96).abs() < 0.005, "{}", z_all(1));
        assert!((z_all(500) - 3.89).abs() < 0.02, "{}", z_all(500));
        assert!(z_all(100) < z_all(1000));
    }

    /// A straightness run of part + slide (fixed seed), and its reversal.
    fn runs(drift_um_per_s: f64) -> (Scan, Vec<f64>, Vec<(f64, f64)>) {
        let part = |x: f64| 2.0 * ((x - 100.0) / 100.0).powi(2);
        let slide = |x: f64| 1.5 * (x / 30.0).sin();
        let mut rng = trueaxis_test_support::SplitMix64(5);
        // Out and back to the start: 0…200 mm, then 0 again, 2 s a point.
        let mut pos: Vec<f64> = (0..=100).map(|i| 2.0 * i as f64).collect();
        pos.push(0.0);
        let t: Vec<f64> = (0..pos.len()).map(|i| 2.0 * i as f64).collect();
        let d: Vec<f64> = pos
            .iter()
            .zip(&t)
            .map(|(&x, &ts)| part(x) + slide(x) + drift_um_per_s * ts + 0.02 * rng.normal())
            .collect();
        let r180 = (0..=100)
            .map(|i| {
                let x = 2.0 * i as f64;
                (x, part(x) - slide(x) + 0.02 * rng.normal())
            })
            .collect();
        (
            Scan::Straightness {
                pos_mm: pos,
                d_um: d,
            },
            t,
            r180,
        )
    }

    #[test]
    fn one_orientation_says_the_sum_and_a_reversal_splits_it() {
        let (scan, t, r180) = runs(0.0);
        let one = diagnose(&scan, &Evidence::default()).unwrap();
        for s in [Source::PartForm, Source::SlideStraightness] {
            let f = one.get(s);
            assert_eq!(f.status, Status::CannotKnow);
            assert!(f.value.is_none() && f.measure.as_ref().unwrap().gives(Input::Reversal));
        }
        assert_eq!(one.get(Source::ProbeRadius).status, Status::NotInScan);
        assert!(one
            .get(Source::ThermalDrift)
            .measure
            .as_ref()
            .unwrap()
            .to_string()
            .contains("t_s"));
        assert_eq!(one.combined.len(), 1);
        let both = diagnose(
            &scan,
            &Evidence {
                reversal: Some(r180),
                t_s: Some(t),
                ..Default::default()
            },
        )
        .unwrap();
        // Part: a symmetric bow of 2 µm at the ends; its line is flat, so
        // its PV stays 2 µm.
        let part = both.get(Source::PartForm);
        assert_eq!(part.status, Status::Estimated);
        let [lo, hi] = part.ci95.unwrap();
        assert!(lo <= 2.0 && 2.0 <= hi && hi - lo < 0.5, "{part:?}");
        assert_eq!(
            both.get(Source::SlideStraightness).status,
            Status::Estimated
        );
        // The start read again, no drift: estimated, zero inside.
        let th = both.get(Source::ThermalDrift);
        let [lo, hi] = th.ci95.unwrap();
        assert!(lo < 0.0 && hi > 0.0, "{th:?}");
    }

    #[test]
    fn a_drift_during_the_scan_is_measured_from_the_start_read_again() {
        // 0.6 µm/min over the 202 s run: 2 µm at the end.
        let (scan, t, _) = runs(0.01);
        let d = diagnose(
            &scan,
            &Evidence {
                t_s: Some(t),
                ..Default::default()
            },
        )
        .unwrap();
        let th = d.get(Source::ThermalDrift);
        let [lo, hi] = th.ci95.unwrap();
        assert!(lo < 0.6 && 0.6 < hi && hi - lo < 0.1, "{th:?}");
    }
}
