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

mod kinds;
use kinds::{arc, roundness, straightness};

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
    /// The highest harmonic the multi-step separation keeps (a roundness
    /// instrument's filter, undulations per revolution); `None`: all.
    pub upr: Option<usize>,
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
) -> Result<(Vec<f64>, crate::linalg::lsq::LsqSolution)> {
    let rows: Vec<Vec<f64>> = x.iter().map(|&v| cols(v)).collect();
    let k = rows[0].len();
    let a = DMatrix::from_fn(x.len(), k, |i, j| rows[i][j]);
    let b = DVector::from_column_slice(y);
    let s = crate::linalg::lsq::solve(&a, &b, None)?;
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

#[cfg(test)]
mod tests;
