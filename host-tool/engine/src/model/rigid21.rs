//! The volumetric model `rigid21` (docs/volumetric.md): the 21 geometric
//! errors of ISO 230-1 (per axis positioning, two straightnesses, roll,
//! pitch, yaw; three squarenesses) and the spindle-axis tilt, on a
//! configurable kinematic chain, evaluated at any tool point — a tool
//! length and lateral offsets — as the error vector, the angle reading and
//! the reading along a beam direction.
//!
//! Each error function is a sum of Legendre polynomials in the axis'
//! normalised position over its measured travel; the degrees each kind
//! carries are the ISO 230-1 gauge of docs/volumetric.md § Parameterisation.
//! An error the data cannot determine is kept in the model as
//! `cannot_know`, with no coefficients, and evaluates as zero: the model
//! never states a value for it.

use serde::{Deserialize, Serialize};

use crate::data::{Dataset, AXES};

mod effects;

pub use effects::EffectAnswer;

/// Default degree of each error function (`rigid21` = `rigid21:4`).
pub const DEFAULT_DEGREE: usize = 4;

/// Highest degree `rigid21:D` accepts.
pub const MAX_DEGREE: usize = 10;

/// The kinematic chain (docs/volumetric.md § The kinematic chain): the
/// axes that carry the spindle and those that carry the workpiece, each
/// listed from the bed up (axis indices 0 = X, 1 = Y, 2 = Z). An axis in
/// neither list is not part of the machine.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Chain {
    /// Tool branch, from the bed to the carriage that carries the spindle.
    pub tool: Vec<usize>,
    /// Workpiece branch, from the bed to the carriage that carries the
    /// workpiece.
    pub workpiece: Vec<usize>,
}

impl Default for Chain {
    /// The simulator's vertical mill: X → Y → Z → tool.
    fn default() -> Chain {
        Chain {
            tool: vec![0, 1, 2],
            workpiece: Vec::new(),
        }
    }
}

impl Chain {
    /// The default order restricted to `axes` (all on the tool branch).
    pub fn of_axes(axes: &[usize]) -> Chain {
        Chain {
            tool: (0..3).filter(|a| axes.contains(a)).collect(),
            workpiece: Vec::new(),
        }
    }

    /// The axes of the machine, in index order.
    pub fn axes(&self) -> Vec<usize> {
        let mut a: Vec<usize> = self.tool.iter().chain(&self.workpiece).copied().collect();
        a.sort_unstable();
        a
    }

    /// The carriage that carries the spindle (top of the tool branch), if
    /// any axis does.
    pub fn spindle_carriage(&self) -> Option<usize> {
        self.tool.last().copied()
    }

    /// Reference point of axis `k`'s rotations at the axis positions `q`
    /// (docs/volumetric.md): on the tool branch the positions of `k` and the
    /// axes below it; on the workpiece branch those of the axes above it.
    pub fn reference_mm(&self, k: usize, q: [f64; 3]) -> [f64; 3] {
        let mut r = [0.0; 3];
        if let Some(i) = self.tool.iter().position(|&a| a == k) {
            for &a in &self.tool[..=i] {
                r[a] = q[a];
            }
        } else if let Some(i) = self.workpiece.iter().position(|&a| a == k) {
            for &a in &self.workpiece[i + 1..] {
                r[a] = q[a];
            }
        }
        r
    }

    /// Checks that every axis appears once; `Err` says what is wrong.
    pub fn check(&self) -> Result<(), String> {
        let all: Vec<usize> = self.tool.iter().chain(&self.workpiece).copied().collect();
        if all.is_empty() {
            return Err("the chain has no axis".into());
        }
        for (i, a) in all.iter().enumerate() {
            if *a > 2 {
                return Err(format!("axis index {a}, expected 0 (X), 1 (Y) or 2 (Z)"));
            }
            if all[..i].contains(a) {
                return Err(format!("axis {} appears twice", AXES[*a]));
            }
        }
        Ok(())
    }
}

/// What an error is (docs/volumetric.md § Parameterisation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// Translation along the axis itself (EXX, EYY, EZZ), µm.
    Positioning,
    /// Translation across the axis (EYX, EZX, …), µm.
    Straightness,
    /// Rotation of the axis' carriage (EAX … ECZ), µrad.
    Angle,
    /// Squareness of two axes' lines (C0Y, B0Z, A0Z), µrad.
    Squareness,
    /// Tilt of the spindle axis about X or Y (A0T, B0T), µrad.
    Tilt,
}

impl ErrorKind {
    /// True for the kinds whose values are µrad.
    pub fn is_angular(self) -> bool {
        !matches!(self, ErrorKind::Positioning | ErrorKind::Straightness)
    }

    /// The unit of the error's values.
    pub fn unit(self) -> &'static str {
        if self.is_angular() {
            "µrad"
        } else {
            "µm"
        }
    }
}

/// Whether the data determine an error (the identifiability answer).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Fitted: the coefficients are the estimate.
    Estimated,
    /// A null or near-null direction of the design reaches it: no value.
    CannotKnow,
}

/// One of the model's errors: an error function of one axis, or a
/// constant (squareness, tilt).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorTerm {
    /// ISO 230-1 name: `EXX`, `EYX`, …, `ECZ`, `C0Y`, `B0Z`, `A0Z`, `A0T`, `B0T`.
    pub name: String,
    /// What it is.
    pub kind: ErrorKind,
    /// The axis whose motion it belongs to (0 = X, 1 = Y, 2 = Z): the
    /// moving axis of a function, the later axis of a squareness; `None`
    /// for the tilt.
    pub axis: Option<usize>,
    /// The direction of a translation, or the rotation axis of an angle,
    /// squareness or tilt (0 = X, 1 = Y, 2 = Z).
    pub component: usize,
    /// Legendre degrees of the coefficients, in order (`[0]` for a constant).
    pub degrees: Vec<usize>,
    /// Estimated or cannot_know.
    pub status: Status,
    /// One coefficient per degree, µm or µrad; absent when `cannot_know`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coef: Option<Vec<f64>>,
}

/// A point the model is evaluated at: axis positions, tool length along
/// the spindle and lateral offsets of the measured point
/// (docs/volumetric.md: p = (x + tool_x, y + tool_y, z − tool_mm)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToolPoint {
    /// Axis positions x, y, z, mm (0 for an axis the machine lacks).
    pub pos_mm: [f64; 3],
    /// Offset along the spindle axis (the tool points along −Z), mm.
    pub tool_mm: f64,
    /// Lateral offsets along X and Y, mm.
    pub tool_lat_mm: [f64; 2],
}

impl ToolPoint {
    /// The point of row `row` of `data`.
    pub fn of_row(data: &Dataset, row: usize) -> ToolPoint {
        ToolPoint {
            pos_mm: [0, 1, 2].map(|a| data.pos(a, row)),
            tool_mm: data.tool(row),
            tool_lat_mm: [data.tool_lat(0, row), data.tool_lat(1, row)],
        }
    }

    /// The measured point p, mm.
    pub fn point_mm(&self) -> [f64; 3] {
        [
            self.pos_mm[0] + self.tool_lat_mm[0],
            self.pos_mm[1] + self.tool_lat_mm[1],
            self.pos_mm[2] - self.tool_mm,
        ]
    }
}

/// The model's value at a tool point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prediction {
    /// Error e = actual − nominal of the measured point, µm.
    pub e_um: [f64; 3],
    /// Rotation of the tool frame relative to the workpiece about +X, +Y,
    /// +Z, µrad (what `ea_urad`, `eb_urad`, `ec_urad` read).
    pub angle_urad: [f64; 3],
}

impl Prediction {
    /// The reading along the unit direction `beam` (`e_beam_um`), µm.
    pub fn beam_um(&self, beam: [f64; 3]) -> f64 {
        (0..3).map(|i| beam[i] * self.e_um[i]).sum()
    }

    fn add_scaled(&mut self, other: &Prediction, c: f64) {
        for i in 0..3 {
            self.e_um[i] += c * other.e_um[i];
            self.angle_urad[i] += c * other.angle_urad[i];
        }
    }
}

/// The saved `rigid21` model (MODEL.json `"kind": "rigid21"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rigid21Model {
    /// Highest Legendre degree of each error function.
    pub degree: usize,
    /// The kinematic chain.
    pub chain: Chain,
    /// Per axis the measured travel [q_min, q_max] (mm) the normalised
    /// position s = 2 (q − q_min)/(q_max − q_min) − 1 runs over; `None`
    /// for an axis not in the chain.
    pub travel_mm: [Option<[f64; 2]>; 3],
    /// The errors, in the order of [`Rigid21Model::layout`].
    pub errors: Vec<ErrorTerm>,
    /// The named effects on top (`adds`; docs/volumetric.md § Effects on
    /// top): per target Σ coef · feature of the rows' data, in the linear
    /// models' terms and their normalisation (the travel's centre and
    /// half-span); absent without effects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects: Option<super::LinearModel>,
}

/// Legendre polynomials P_0 … P_n at s, by the three-term recurrence.
pub fn legendre(n: usize, s: f64) -> Vec<f64> {
    let mut p = Vec::with_capacity(n + 1);
    p.push(1.0);
    if n >= 1 {
        p.push(s);
    }
    for k in 2..=n {
        let kf = k as f64;
        let next = ((2.0 * kf - 1.0) * s * p[k - 1] - (kf - 1.0) * p[k - 2]) / kf;
        p.push(next);
    }
    p
}

/// The ISO 230-1 name of a translation along `dir` or a rotation about
/// `dir` (`angle`) of axis `axis`: `EXX`, `EYX`, `EAX`, …
pub fn function_name(axis: usize, dir: usize, angle: bool) -> String {
    let d = if angle {
        ["A", "B", "C"]
    } else {
        ["X", "Y", "Z"]
    }[dir];
    format!("E{d}{}", ["X", "Y", "Z"][axis])
}

/// An error in ISO 230-1 words: `X positioning`, `X straightness along
/// Y`, `X yaw` (for Z vertical: roll about the axis itself, yaw about Z;
/// Z's pitch about X, its yaw about Y), `squareness of Y to X`, `spindle
/// tilt about X`.
pub fn words(term: &ErrorTerm) -> String {
    let axis = |a: usize| ["X", "Y", "Z"][a];
    let c = term.component;
    match (term.kind, term.axis) {
        (ErrorKind::Positioning, Some(a)) => format!("{} positioning", axis(a)),
        (ErrorKind::Straightness, Some(a)) => {
            format!("{} straightness along {}", axis(a), axis(c))
        }
        (ErrorKind::Angle, Some(a)) => {
            let role = match (a, c) {
                (a, b) if a == b => "roll",
                (_, 2) | (2, 1) => "yaw",
                _ => "pitch",
            };
            format!("{} {role}", axis(a))
        }
        (ErrorKind::Squareness, Some(later)) => {
            format!("squareness of {} to {}", axis(later), axis(3 - later - c))
        }
        (ErrorKind::Tilt, _) => format!("spindle tilt about {}", axis(c)),
        _ => term.name.clone(),
    }
}

/// The squareness of `later` to `earlier` (both present, earlier < later):
/// its name and rotation axis (C0Y: Y to X about Z; B0Z: Z to X about Y;
/// A0Z: Z to Y about X).
pub fn squareness_of(earlier: usize, later: usize) -> (String, usize) {
    let about = 3 - earlier - later;
    (
        format!("{}0{}", ["A", "B", "C"][about], ["X", "Y", "Z"][later]),
        about,
    )
}

impl Rigid21Model {
    /// The same model with no machine error: every error function and
    /// constant zero and no effects on top — the uncompensated machine, as
    /// `compare` reads "before" (each set-up still placed).
    pub fn zeroed(&self) -> Rigid21Model {
        let mut zero = self.clone();
        for e in &mut zero.errors {
            if let Some(c) = e.coef.as_mut() {
                c.iter_mut().for_each(|v| *v = 0.0);
            }
        }
        zero.effects = None;
        zero
    }

    /// The errors a model of `degree` on `chain` has, in their fixed order
    /// (per axis in index order: the three translations, the three angles;
    /// then the squarenesses; then the tilt when a carriage carries the
    /// spindle), every one `estimated` with no coefficients yet. The degrees
    /// follow docs/volumetric.md § Parameterisation.
    pub fn layout(chain: &Chain, degree: usize) -> Vec<ErrorTerm> {
        let axes = chain.axes();
        let spindle = chain.spindle_carriage();
        let mut out = Vec::new();
        for &k in &axes {
            for dir in 0..3 {
                let (kind, first) = if dir == k {
                    (ErrorKind::Positioning, 1)
                } else {
                    (ErrorKind::Straightness, 2)
                };
                out.push(ErrorTerm {
                    name: function_name(k, dir, false),
                    kind,
                    axis: Some(k),
                    component: dir,
                    degrees: (first..=degree).collect(),
                    status: Status::Estimated,
                    coef: None,
                });
            }
            let first = if Some(k) == spindle { 0 } else { 1 };
            for about in 0..3 {
                out.push(ErrorTerm {
                    name: function_name(k, about, true),
                    kind: ErrorKind::Angle,
                    axis: Some(k),
                    component: about,
                    degrees: (first..=degree).collect(),
                    status: Status::Estimated,
                    coef: None,
                });
            }
        }
        for (i, &a) in axes.iter().enumerate() {
            for &b in &axes[i + 1..] {
                let (name, about) = squareness_of(a, b);
                out.push(ErrorTerm {
                    name,
                    kind: ErrorKind::Squareness,
                    axis: Some(b),
                    component: about,
                    degrees: vec![0],
                    status: Status::Estimated,
                    coef: None,
                });
            }
        }
        if spindle.is_some() {
            for (about, name) in ["A0T", "B0T"].into_iter().enumerate() {
                out.push(ErrorTerm {
                    name: name.into(),
                    kind: ErrorKind::Tilt,
                    axis: None,
                    component: about,
                    degrees: vec![0],
                    status: Status::Estimated,
                    coef: None,
                });
            }
        }
        out
    }

    /// Iterates over the model's errors (functions and constants).
    pub fn errors(&self) -> impl Iterator<Item = &ErrorTerm> {
        self.errors.iter()
    }

    /// The error named `name` (ISO 230-1), if the model has it.
    pub fn error(&self, name: &str) -> Option<&ErrorTerm> {
        self.errors.iter().find(|e| e.name == name)
    }

    /// Normalised position s ∈ [−1, 1] of `q_mm` on `axis`' measured travel.
    pub fn normalised(&self, axis: usize, q_mm: f64) -> f64 {
        match self.travel_mm[axis] {
            Some([lo, hi]) if hi > lo => 2.0 * (q_mm - lo) / (hi - lo) - 1.0,
            _ => 0.0,
        }
    }

    /// The value of error `term` at the axis positions `pos_mm` (µm or
    /// µrad; a constant's value anywhere); `None` for `cannot_know`.
    pub fn value(&self, term: &ErrorTerm, pos_mm: [f64; 3]) -> Option<f64> {
        let coef = term.coef.as_ref()?;
        let s = term.axis.map_or(0.0, |a| self.normalised(a, pos_mm[a]));
        Some(basis_sum(term, coef, s))
    }

    /// The effect of one unit (1 µm or 1 µrad) of `term`'s basis function
    /// of degree `degree` at tool point `pt`: what a coefficient multiplies
    /// (docs/volumetric.md, e(p) and the angle readings). The fit builds its
    /// design from it; [`Rigid21Model::predict`] sums it.
    pub fn unit_response(&self, term: &ErrorTerm, degree: usize, pt: &ToolPoint) -> Prediction {
        let q = pt.pos_mm;
        let b = match (term.kind, term.axis) {
            (ErrorKind::Positioning | ErrorKind::Straightness | ErrorKind::Angle, Some(a)) => {
                let s = self.normalised(a, q[a]);
                *legendre(degree, s).last().unwrap_or(&1.0)
            }
            _ => 1.0,
        };
        let mut out = Prediction::default();
        let c = term.component;
        match (term.kind, term.axis) {
            (ErrorKind::Positioning | ErrorKind::Straightness, _) => out.e_um[c] = b,
            (ErrorKind::Angle, Some(k)) => {
                let p = pt.point_mm();
                let r = self.chain.reference_mm(k, q);
                let arm = [p[0] - r[0], p[1] - r[1], p[2] - r[2]];
                let mut w = [0.0; 3];
                w[c] = b;
                out.e_um = cross_um(w, arm);
                out.angle_urad[c] = b;
            }
            (ErrorKind::Squareness, Some(later)) => {
                let mut w = [0.0; 3];
                w[c] = 1.0;
                let mut line = [0.0; 3];
                line[later] = q[later];
                out.e_um = cross_um(w, line);
            }
            (ErrorKind::Tilt, _) => {
                let mut w = [0.0; 3];
                w[c] = 1.0;
                out.e_um = cross_um(w, [0.0, 0.0, -pt.tool_mm]);
            }
            // An angle or squareness without its axis is refused by
            // `check`; it has no effect.
            _ => {}
        }
        out
    }

    /// The model at tool point `pt`: the error vector and the angle
    /// reading, summed over the estimated errors (a `cannot_know` error
    /// counts as zero).
    pub fn predict(&self, pt: &ToolPoint) -> Prediction {
        let mut out = Prediction::default();
        for term in &self.errors {
            let Some(coef) = &term.coef else { continue };
            for (&d, &c) in term.degrees.iter().zip(coef) {
                if c != 0.0 {
                    out.add_scaled(&self.unit_response(term, d, pt), c);
                }
            }
        }
        out
    }

    /// Checks the fields the types do not: the chain, travels for exactly
    /// the chain's axes, the layout of the errors for the chain and degree,
    /// coefficients present (one per degree, finite) exactly when
    /// `estimated`. `Err` names the field and what was expected.
    pub fn check(&self) -> Result<(), String> {
        self.chain
            .check()
            .map_err(|e| format!("model.chain: {e}"))?;
        if !(1..=MAX_DEGREE).contains(&self.degree) {
            return Err(format!(
                "model.degree: {}, expected 1 to {MAX_DEGREE}",
                self.degree
            ));
        }
        let axes = self.chain.axes();
        for a in 0..3 {
            match (self.travel_mm[a], axes.contains(&a)) {
                (Some([lo, hi]), true) if lo.is_finite() && hi.is_finite() && lo <= hi => {}
                (None, false) => {}
                _ => {
                    return Err(format!(
                        "model.travel_mm[{a}]: expected [low, high] in mm (finite, low ≤ high) for an axis of the chain, null otherwise"
                    ))
                }
            }
        }
        let want = Rigid21Model::layout(&self.chain, self.degree);
        if want.len() != self.errors.len() {
            return Err(format!(
                "model.errors: {} entries, expected {} for this chain",
                self.errors.len(),
                want.len()
            ));
        }
        for (i, (got, w)) in self.errors.iter().zip(&want).enumerate() {
            let same = got.name == w.name
                && got.kind == w.kind
                && got.axis == w.axis
                && got.component == w.component
                && got.degrees == w.degrees;
            if !same {
                return Err(format!(
                    "model.errors[{i}]: `{}`, expected `{}` with degrees {:?}",
                    got.name, w.name, w.degrees
                ));
            }
            match (&got.status, &got.coef) {
                (Status::Estimated, Some(c))
                    if c.len() == got.degrees.len() && c.iter().all(|v| v.is_finite()) => {}
                (Status::CannotKnow, None) => {}
                (Status::Estimated, _) => {
                    return Err(format!(
                        "model.errors[{i}].coef: expected {} finite coefficients for an estimated error",
                        got.degrees.len()
                    ))
                }
                (Status::CannotKnow, Some(_)) => {
                    return Err(format!(
                        "model.errors[{i}]: `{}` is cannot_know and must have no coefficients",
                        got.name
                    ))
                }
            }
        }
        self.check_effects()
    }
}

/// Σ c_n P_n(s) over the term's degrees.
fn basis_sum(term: &ErrorTerm, coef: &[f64], s: f64) -> f64 {
    let top = term.degrees.iter().copied().max().unwrap_or(0);
    let p = legendre(top, s);
    term.degrees.iter().zip(coef).map(|(&d, &c)| c * p[d]).sum()
}

/// ω × a with ω in µrad and a in mm, in µm.
fn cross_um(w: [f64; 3], a: [f64; 3]) -> [f64; 3] {
    [
        (w[1] * a[2] - w[2] * a[1]) * 1e-3,
        (w[2] * a[0] - w[0] * a[2]) * 1e-3,
        (w[0] * a[1] - w[1] * a[0]) * 1e-3,
    ]
}

/// One error's answer in `fit --json` `errors`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorAnswer {
    /// ISO 230-1 name.
    pub name: String,
    /// `estimated` or `cannot_know`.
    pub status: Status,
    /// µm or µrad.
    pub unit: String,
    /// Largest |value| over the travel (a constant's value, signed), for
    /// `estimated` only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak: Option<f64>,
    /// Standard uncertainty of `peak` (at the same position).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f64>,
    /// Legendre coefficients, for `estimated` only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coef: Option<Vec<f64>>,
    /// Covariance of `coef` (row and column per coefficient, µm² or
    /// µrad²), for `estimated` only: the ±2σ band of the function over the
    /// travel on a report page (σ(s)² = pᵀ C p, p the Legendre values).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coef_cov: Option<Vec<Vec<f64>>>,
    /// For `cannot_know` only: the largest error vector (µm) this error at
    /// its realistic size gives over the working volume and the measured
    /// tool range, and the tool length (mm) where.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hidden_um: Option<f64>,
    /// See `hidden_um`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hidden_at_tool_mm: Option<f64>,
}

/// What the data cannot see, and what would show it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// Per error, in the model's order.
    pub errors: Vec<ErrorAnswer>,
    /// The largest volumetric error (µm, vector length) over the working
    /// volume and the measured tool range that realistic-size errors in the
    /// directions these data cannot see give.
    pub hidden_um: f64,
    /// The errors that largest hidden error comes from.
    pub hidden_from: Vec<String>,
    /// The tool length, mm, at which it is largest.
    pub hidden_at_tool_mm: f64,
    /// The added measurement from the simulator's menu that removes the
    /// most of `hidden_um`, with what would then remain; `None` when
    /// nothing is hidden.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measure: Option<Measure>,
    /// The named effects on top (`adds`), fitted jointly with the errors;
    /// empty (the key absent) without effects.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub effects: Vec<EffectAnswer>,
}

/// A measurement to add.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measure {
    /// What to measure, in words.
    pub what: String,
    /// `hidden_um` once it is added.
    pub hidden_um_after: f64,
}

/// One reading kind's residual after the model and each set-up's own
/// unknowns (`compare` on a rigid21 model).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadingResidual {
    /// `ex`, `ey`, `ez`, `ea_urad`, `eb_urad`, `ec_urad` or `e_beam`.
    pub reading: String,
    /// µm or µrad.
    pub unit: String,
    /// Readings of this kind.
    pub count: usize,
    /// RMS of the residual.
    pub rms: f64,
    /// Largest |residual|.
    pub max_abs: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{ErrorFn, Machine};

    /// A rigid21 model of the default chain over 0…travel with every
    /// coefficient zero.
    fn zero_model(travel: [f64; 3], degree: usize) -> Rigid21Model {
        let chain = Chain::default();
        let mut errors = Rigid21Model::layout(&chain, degree);
        for e in &mut errors {
            e.coef = Some(vec![0.0; e.degrees.len()]);
        }
        Rigid21Model {
            degree,
            chain,
            travel_mm: travel.map(|t| Some([0.0, t])),
            errors,
            effects: None,
        }
    }

    fn set(m: &mut Rigid21Model, name: &str, degree: usize, c: f64) {
        let e = m.errors.iter_mut().find(|e| e.name == name).unwrap();
        let i = e.degrees.iter().position(|&d| d == degree).unwrap();
        e.coef.as_mut().unwrap()[i] = c;
    }

    #[test]
    fn the_default_chain_has_the_21_errors_and_the_tilt() {
        let names: Vec<String> = Rigid21Model::layout(&Chain::default(), 4)
            .into_iter()
            .map(|e| e.name)
            .collect();
        assert_eq!(names.len(), 23);
        assert_eq!(
            names[..6].to_vec(),
            ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"]
        );
        assert_eq!(names[18..].to_vec(), ["C0Y", "B0Z", "A0Z", "A0T", "B0T"]);
        // A two-axis X/Z lathe: 2 × 6 + 1 errors (and the tilt).
        let lathe = Rigid21Model::layout(&Chain::of_axes(&[0, 2]), 4);
        let n = lathe.iter().filter(|e| e.kind != ErrorKind::Tilt).count();
        assert_eq!(n, 13);
        assert!(lathe.iter().any(|e| e.name == "B0Z"));
    }

    #[test]
    fn legendre_matches_the_closed_forms() {
        let s = 0.3;
        let p = legendre(4, s);
        assert_eq!(p[0], 1.0);
        assert_eq!(p[1], s);
        assert!((p[2] - (3.0 * s * s - 1.0) / 2.0).abs() < 1e-15);
        assert!((p[3] - (5.0 * s.powi(3) - 3.0 * s) / 2.0).abs() < 1e-15);
        assert!((p[4] - (35.0 * s.powi(4) - 30.0 * s * s + 3.0) / 8.0).abs() < 1e-15);
    }

    #[test]
    fn evaluation_follows_the_simulators_chain() {
        // X pitch, Z yaw, squareness and a linear positioning error, each
        // also put into the simulator's machine: the same error at points
        // on the spindle axis, whatever the tool length.
        let travel = [800.0, 500.0, 500.0];
        let mut m = zero_model(travel, 2);
        let mut mach = Machine::perfect(travel);
        // EBX = 10 P1(s) + 4 P2(s); in u = x/800: s = 2u − 1.
        set(&mut m, "EBX", 1, 10.0);
        set(&mut m, "EBX", 2, 4.0);
        // 10 (2u − 1) + 4 (3 (2u − 1)² − 1)/2 = 10·(2u−1) + 6(4u²−4u+1) − 2
        mach.axes[0].rot_urad[1] = ErrorFn::poly(&[-10.0 + 6.0 - 2.0, 20.0 - 24.0, 24.0]);
        set(&mut m, "ECZ", 0, 7.0);
        mach.axes[2].rot_urad[2] = ErrorFn::poly(&[7.0]);
        set(&mut m, "EAY", 1, 5.0);
        mach.axes[1].rot_urad[0] = ErrorFn::poly(&[-5.0, 10.0]);
        set(&mut m, "EXX", 1, 3.0);
        mach.axes[0].trans_um[0] = ErrorFn::poly(&[-3.0, 6.0]);
        set(&mut m, "C0Y", 0, 25.0);
        set(&mut m, "B0Z", 0, 30.0);
        set(&mut m, "A0Z", 0, 20.0);
        mach.squareness.xy_urad = 25.0;
        mach.squareness.xz_urad = -30.0;
        mach.squareness.yz_urad = 20.0;
        for (x, y, z, l) in [
            (0.0, 0.0, 0.0, 0.0),
            (300.0, 200.0, 100.0, 150.0),
            (800.0, 500.0, 500.0, 50.0),
        ] {
            let want = mach.error_um([x, y, z], l);
            let got = m
                .predict(&ToolPoint {
                    pos_mm: [x, y, z],
                    tool_mm: l,
                    tool_lat_mm: [0.0, 0.0],
                })
                .e_um;
            for i in 0..3 {
                assert!((got[i] - want[i]).abs() < 1e-9, "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn lateral_offsets_tilt_and_angle_readings() {
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        // ECZ constant 10 µrad: no effect on the spindle axis, ±(offset)
        // µrad·mm off it.
        set(&mut m, "ECZ", 0, 10.0);
        let on_axis = ToolPoint {
            pos_mm: [100.0, 100.0, 100.0],
            tool_mm: 100.0,
            tool_lat_mm: [0.0, 0.0],
        };
        let p = m.predict(&on_axis);
        assert_eq!(p.e_um, [0.0, 0.0, 0.0]);
        assert_eq!(p.angle_urad, [0.0, 0.0, 10.0]);
        let off = ToolPoint {
            tool_lat_mm: [50.0, 0.0],
            ..on_axis
        };
        // ε × a with ε = (0, 0, 10), a = (50, 0, −100): (0, 0.5, 0) µm.
        let e = m.predict(&off).e_um;
        assert!((e[1] - 0.5).abs() < 1e-12 && e[0].abs() < 1e-12, "{e:?}");
        // A0T = 12 µrad: e_y = A0T · L, on the spindle axis only through L.
        let mut t = zero_model([800.0, 500.0, 500.0], 4);
        set(&mut t, "A0T", 0, 12.0);
        let p = t.predict(&on_axis);
        assert!((p.e_um[1] - 1.2).abs() < 1e-12, "{p:?}");
        assert_eq!(p.angle_urad, [0.0; 3], "the tilt is no carriage angle");
        assert!((p.beam_um([0.6, 0.8, 0.0]) - 0.96).abs() < 1e-12);
    }

    #[test]
    fn a_cannot_know_error_has_no_value_and_counts_as_zero() {
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        set(&mut m, "A0T", 0, 12.0);
        let e = m.errors.iter_mut().find(|e| e.name == "A0T").unwrap();
        e.status = Status::CannotKnow;
        e.coef = None;
        m.check().unwrap();
        let t = m.error("A0T").unwrap();
        assert_eq!(m.value(t, [0.0; 3]), None);
        let p = m.predict(&ToolPoint {
            tool_mm: 100.0,
            ..ToolPoint::default()
        });
        assert_eq!(p.e_um, [0.0; 3]);
        let json = serde_json::to_value(m.error("A0T").unwrap()).unwrap();
        assert!(json.get("coef").is_none(), "{json}");
        assert_eq!(json["status"], "cannot_know");
    }

    #[test]
    fn a_model_file_holds_it_and_reads_it_back() {
        use crate::model::{DataRef, FitStats, FittedModel, ModelFile, MODEL_FORMAT};
        let mut m = zero_model([800.0, 500.0, 500.0], 3);
        set(&mut m, "EBX", 1, 12.5);
        let file = ModelFile {
            format: MODEL_FORMAT.into(),
            seed: "rigid21:3".into(),
            adds: Vec::new(),
            data: DataRef {
                source: "t.csv".into(),
                sha256: String::new(),
                rows: 1,
                temp_range_c: None,
                outside_travel: Vec::new(),
            },
            model: FittedModel::Rigid21(m),
            stats: FitStats::default(),
        };
        file.validate().unwrap();
        let json = file.to_json().unwrap();
        assert!(json.contains("\"kind\": \"rigid21\""), "{json}");
        let back: ModelFile = serde_json::from_str(&json).unwrap();
        assert_eq!(back, file);
        let mut wrong = file.clone();
        wrong.seed = "rigid21".into();
        assert!(wrong.validate().unwrap_err().contains("does not describe"));
    }

    #[test]
    fn check_refuses_a_broken_layout() {
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        m.check().unwrap();
        m.errors[0].coef = Some(vec![1.0]);
        assert!(m.check().unwrap_err().contains("model.errors[0].coef"));
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        m.errors[4].status = Status::CannotKnow;
        assert!(m.check().unwrap_err().contains("must have no coefficients"));
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        m.errors.swap(0, 1);
        assert!(m.check().unwrap_err().contains("expected `EXX`"));
        let mut m = zero_model([800.0, 500.0, 500.0], 4);
        m.chain.tool = vec![0, 0, 2];
        assert!(m.check().unwrap_err().contains("appears twice"));
    }

    #[test]
    fn a_table_axis_turns_about_the_workpiece() {
        // X carries the workpiece, Y and Z the tool: X's yaw swings the
        // workpiece about its origin, so the arm is the point itself.
        let chain = Chain {
            tool: vec![1, 2],
            workpiece: vec![0],
        };
        let mut errors = Rigid21Model::layout(&chain, 2);
        for e in &mut errors {
            e.coef = Some(vec![0.0; e.degrees.len()]);
        }
        let mut m = Rigid21Model {
            degree: 2,
            chain,
            travel_mm: [Some([0.0, 800.0]), Some([0.0, 500.0]), Some([0.0, 500.0])],
            errors,
            effects: None,
        };
        set(&mut m, "ECX", 1, 10.0);
        let pt = ToolPoint {
            pos_mm: [800.0, 200.0, 0.0],
            ..ToolPoint::default()
        };
        // s = 1 → ε_z = 10 µrad; arm (800, 200, 0): e = (−2, 8, 0) µm.
        let e = m.predict(&pt).e_um;
        assert!(
            (e[0] + 2.0).abs() < 1e-12 && (e[1] - 8.0).abs() < 1e-12,
            "{e:?}"
        );
        assert_eq!(m.chain.spindle_carriage(), Some(2));
    }
}
