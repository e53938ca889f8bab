//! Fitting `rigid21` (docs/volumetric.md): one joint weighted linear least
//! squares over every reading — ex/ey/ez, the angle readings and the beam
//! readings — with each set-up's unknowns (zeros, alignment slopes,
//! rigid-body frames) as nuisance columns projected out, and the answer to
//! which errors these data can determine at all.
//!
//! Identifiability: the design's model columns are scaled by realistic
//! sizes ([`SIZE_TRANSLATION_UM`], [`SIZE_ANGLE_URAD`]) and the set-up
//! unknowns projected out; a right singular vector whose singular value is
//! below [`NEAR_NULL`] — a realistic-size change that moves the readings by
//! less than that many standard deviations in all — is a direction the
//! data cannot see. An error whose coefficients such a direction reaches
//! is `cannot_know`: it gets no value and is left out of the solve.

use std::collections::HashMap;

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use crate::data::{Dataset, ANGLES, TARGETS};
use crate::effect::Effect;
use crate::model::rigid21::{
    Chain, ErrorAnswer, ErrorKind, Identifiability, Measure, Prediction, ReadingResidual,
    Rigid21Model, Status, ToolPoint,
};
use crate::simulate::instruments::{self, Instrument};
use crate::simulate::Machine;

pub(crate) mod effects;

/// Realistic size of a translation error (positioning, straightness), µm.
pub const SIZE_TRANSLATION_UM: f64 = 10.0;
/// Realistic size of an angle, squareness or tilt, µrad.
pub const SIZE_ANGLE_URAD: f64 = 30.0;
/// A scaled design direction with a singular value below this is one the
/// data cannot see (in standard deviations of the readings, summed in
/// quadrature over all of them).
pub const NEAR_NULL: f64 = 3.0;
/// Share of a null direction's weight on an error's coefficients above
/// which the error is `cannot_know`.
pub(crate) const REACH: f64 = 0.02;

/// A parameter: error `term` (index in the layout), Legendre degree.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Param {
    pub(crate) term: usize,
    pub(crate) degree: usize,
    /// Realistic size of one unit of the scaled coefficient.
    pub(crate) size: f64,
}

/// The design with set-up unknowns projected out, weighted by 1/u.
pub(crate) struct Projected {
    pub(crate) m: DMatrix<f64>,
    pub(crate) b: DVector<f64>,
    /// (row, reading kind) of each observation, for residual statistics.
    pub(crate) obs: Vec<(usize, Reading)>,
    pub(crate) nuisance: usize,
}

/// What an observation reads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Reading {
    E(usize),
    Angle(usize),
    Beam,
}

impl Reading {
    /// The `rms_um` key of its kind.
    fn key(self) -> String {
        match self {
            Reading::E(c) => TARGETS[c].to_string(),
            Reading::Angle(c) => format!("{}_urad", ANGLES[c]),
            Reading::Beam => "e_beam".into(),
        }
    }
}

/// The model skeleton for `data`: the chain of its moving axes (default
/// order) and their measured travels, every error `estimated`, no
/// coefficients.
pub fn skeleton(data: &Dataset, degree: usize) -> Result<Rigid21Model> {
    let axes = data.varying_axes();
    if axes.is_empty() {
        bail!("rigid21 needs at least one axis that moves in the data");
    }
    let chain = Chain::of_axes(&axes);
    let travel_mm = [0, 1, 2].map(|a| {
        axes.contains(&a).then(|| {
            let col = data.pos_mm[a].as_deref().unwrap_or(&[]);
            let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            [lo, hi]
        })
    });
    Ok(Rigid21Model {
        degree,
        errors: Rigid21Model::layout(&chain, degree),
        effects: None,
        chain,
        travel_mm,
    })
}

pub(crate) fn params_of(model: &Rigid21Model) -> Vec<Param> {
    let mut out = Vec::new();
    for (t, e) in model.errors.iter().enumerate() {
        let size = if e.kind.is_angular() {
            SIZE_ANGLE_URAD
        } else {
            SIZE_TRANSLATION_UM
        };
        for &d in &e.degrees {
            out.push(Param {
                term: t,
                degree: d,
                size,
            });
        }
    }
    out
}

/// Builds the weighted design of `data` for `model`'s parameters (scaled
/// by their sizes) and projects the set-up unknowns out
/// (docs/volumetric.md § Set-ups).
pub(crate) fn projected(data: &Dataset, model: &Rigid21Model, params: &[Param]) -> Projected {
    projected_with(data, model, params, &[])
}

/// A column beyond the model's: its effect at row `r`'s tool point
/// (diagnose's candidates — a periodic lead error — scored on the same
/// design; a named effect on top, which reads the row's data).
pub(crate) type ExtraColumn<'a> = &'a dyn Fn(usize, &ToolPoint) -> Prediction;

/// [`projected`] with `extra` columns (unit size) after the parameters'.
pub(crate) fn projected_with(
    data: &Dataset,
    model: &Rigid21Model,
    params: &[Param],
    extra: &[ExtraColumn],
) -> Projected {
    let n = data.len();
    let sizes: Vec<f64> = params
        .iter()
        .map(|p| p.size)
        .chain(extra.iter().map(|_| 1.0))
        .collect();
    let params_len = sizes.len();
    // Set-up groups and their moving axes.
    let group = |r: usize| data.setup_id.as_ref().map(|s| s[r]);
    let mut moving: HashMap<Option<i64>, Vec<usize>> = HashMap::new();
    {
        let mut first: HashMap<Option<i64>, [f64; 3]> = HashMap::new();
        for r in 0..n {
            let p = [0, 1, 2].map(|a| data.pos(a, r));
            let f = *first.entry(group(r)).or_insert(p);
            let mv = moving.entry(group(r)).or_default();
            for a in 0..3 {
                if p[a] != f[a] && !mv.contains(&a) {
                    mv.push(a);
                }
            }
        }
    }
    // Beam set-ups whose direction turns (a ballbar circle): the bar's own
    // zero besides the centre's offset (n · t cannot hold a constant when
    // n turns; on one direction it is that zero already).
    let mut turning: HashMap<Option<i64>, bool> = HashMap::new();
    if let Some(dirs) = data.beam_dir.as_ref() {
        let mut first: HashMap<Option<i64>, [f64; 3]> = HashMap::new();
        for (r, d) in dirs.iter().enumerate() {
            if let Some(d) = d {
                let f = *first.entry(group(r)).or_insert(*d);
                if f != *d {
                    turning.insert(group(r), true);
                }
            }
        }
    }
    let mut nuis: HashMap<(Option<i64>, u8, usize), usize> = HashMap::new();
    let mut rows_m: Vec<Vec<f64>> = Vec::new();
    let mut rows_n: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut b: Vec<f64> = Vec::new();
    let mut obs = Vec::new();
    let mut col = |key: (Option<i64>, u8, usize)| {
        let k = nuis.len();
        *nuis.entry(key).or_insert(k)
    };
    for r in 0..n {
        let pt = ToolPoint::of_row(data, r);
        let resp: Vec<Prediction> = params
            .iter()
            .map(|p| model.unit_response(&model.errors[p.term], p.degree, &pt))
            .chain(extra.iter().map(|f| f(r, &pt)))
            .collect();
        let u = data.u_um.as_ref().map_or(1.0, |v| v[r]);
        let w = 1.0 / u;
        let g = group(r);
        let mv = moving.get(&g).cloned().unwrap_or_default();
        let mut push = |value: f64,
                        kind: Reading,
                        model_row: Vec<f64>,
                        nrow: Vec<(usize, f64)>,
                        rows_m: &mut Vec<Vec<f64>>,
                        rows_n: &mut Vec<Vec<(usize, f64)>>,
                        b: &mut Vec<f64>| {
            rows_m.push(model_row.iter().map(|v| v * w).collect());
            rows_n.push(nrow.into_iter().map(|(c, v)| (c, v * w)).collect());
            b.push(value * w);
            obs.push((r, kind));
        };
        let p = pt.point_mm();
        for c in 0..3 {
            let Some(v) = data.err_um[c].as_ref().and_then(|col| col[r]) else {
                continue;
            };
            let mrow: Vec<f64> = sizes
                .iter()
                .zip(&resp)
                .map(|(pa, re)| re.e_um[c] * pa)
                .collect();
            let mut nrow = Vec::new();
            if g.is_none() || mv.len() >= 2 {
                // A rigid-body frame: t + ω × p (ω in µrad, p in m → µm·1e-3·1e3).
                nrow.push((col((g, 0, c)), 1.0));
                for j in 0..3 {
                    let mut wv = [0.0; 3];
                    wv[j] = 1.0;
                    let cr = [
                        wv[1] * p[2] - wv[2] * p[1],
                        wv[2] * p[0] - wv[0] * p[2],
                        wv[0] * p[1] - wv[1] * p[0],
                    ];
                    if cr[c] != 0.0 {
                        nrow.push((col((g, 1, j)), cr[c] * 1e-3));
                    }
                }
            } else {
                nrow.push((col((g, 2, c)), 1.0));
                if let [k] = mv[..] {
                    if k != c {
                        nrow.push((col((g, 3, c)), data.pos(k, r) * 1e-3));
                    }
                }
            }
            push(
                v,
                Reading::E(c),
                mrow,
                nrow,
                &mut rows_m,
                &mut rows_n,
                &mut b,
            );
        }
        for c in 0..3 {
            let Some(v) = data.angle_urad[c].as_ref().and_then(|col| col[r]) else {
                continue;
            };
            let mrow: Vec<f64> = sizes
                .iter()
                .zip(&resp)
                .map(|(pa, re)| re.angle_urad[c] * pa)
                .collect();
            let nrow = if g.is_some() {
                vec![(col((g, 4, c)), 1.0)]
            } else {
                Vec::new()
            };
            push(
                v,
                Reading::Angle(c),
                mrow,
                nrow,
                &mut rows_m,
                &mut rows_n,
                &mut b,
            );
        }
        if let (Some(Some(v)), Some(Some(d))) = (
            data.beam_um.as_ref().map(|c| c[r]),
            data.beam_dir.as_ref().map(|c| c[r]),
        ) {
            let mrow: Vec<f64> = sizes
                .iter()
                .zip(&resp)
                .map(|(pa, re)| re.beam_um(d) * pa)
                .collect();
            let nrow = if g.is_some() {
                let mut nrow: Vec<(usize, f64)> = (0..3)
                    .filter(|&j| d[j] != 0.0)
                    .map(|j| (col((g, 5, j)), d[j]))
                    .collect();
                if turning.contains_key(&g) {
                    nrow.push((col((g, 6, 0)), 1.0));
                }
                nrow
            } else {
                Vec::new()
            };
            push(
                v,
                Reading::Beam,
                mrow,
                nrow,
                &mut rows_m,
                &mut rows_n,
                &mut b,
            );
        }
    }
    let rows = b.len();
    let nn = nuis.len();
    let mut m = DMatrix::from_fn(rows, params_len, |i, j| rows_m[i][j]);
    let mut bv = DVector::from_vec(b);
    if nn > 0 {
        let mut nm = DMatrix::zeros(rows, nn);
        for (i, row) in rows_n.iter().enumerate() {
            for &(c, v) in row {
                nm[(i, c)] += v;
            }
        }
        // An orthonormal basis of the nuisance columns' span (SVD: rank
        // deficient sets — a frame seen on one line — are fine).
        let svd = nm.svd(true, false);
        let smax = svd.singular_values.max();
        if let Some(uu) = svd.u {
            let keep: Vec<usize> = (0..svd.singular_values.len())
                .filter(|&i| svd.singular_values[i] > smax * 1e-10)
                .collect();
            let q = uu.select_columns(&keep);
            let qtm = q.transpose() * &m;
            m -= &q * qtm;
            let qtb = q.transpose() * &bv;
            bv -= &q * qtb;
        }
    }
    Projected {
        m,
        b: bv,
        obs,
        nuisance: nn,
    }
}

/// Null and near-null directions (columns, unit length in scaled
/// coefficients) of a projected design.
fn null_directions(m: &DMatrix<f64>) -> DMatrix<f64> {
    let p = m.ncols();
    // Gram matrix eigen-decomposition: p is small (≤ a few hundred).
    let g = m.transpose() * m;
    let eig = g.symmetric_eigen();
    let lmax = eig.eigenvalues.max().max(0.0);
    let cols: Vec<usize> = (0..p)
        .filter(|&i| {
            let l = eig.eigenvalues[i].max(0.0);
            l.sqrt() < NEAR_NULL || l <= lmax * 1e-20
        })
        .collect();
    eig.eigenvectors.select_columns(&cols)
}

/// The evaluation points of the working volume: a 5-point grid per axis
/// of the chain over its travel, at the smallest and largest tool length
/// of the data and on the spindle axis.
fn volume_points(model: &Rigid21Model, tools_mm: [f64; 2]) -> Vec<ToolPoint> {
    let grid = |a: usize| -> Vec<f64> {
        match model.travel_mm[a] {
            Some([lo, hi]) => (0..5).map(|i| lo + (hi - lo) * i as f64 / 4.0).collect(),
            None => vec![0.0],
        }
    };
    let mut out = Vec::new();
    for &x in &grid(0) {
        for &y in &grid(1) {
            for &z in &grid(2) {
                for &t in &tools_mm {
                    out.push(ToolPoint {
                        pos_mm: [x, y, z],
                        tool_mm: t,
                        tool_lat_mm: [0.0, 0.0],
                    });
                }
            }
        }
    }
    out
}

/// The largest error vector the null directions `nulls` give at the
/// points, the tool length there and the maximising direction.
fn hidden(
    model: &Rigid21Model,
    params: &[Param],
    nulls: &DMatrix<f64>,
    points: &[ToolPoint],
) -> (f64, f64, Option<DVector<f64>>) {
    if nulls.ncols() == 0 {
        return (0.0, 0.0, None);
    }
    let mut best = (0.0, 0.0, None);
    for pt in points {
        // G: 3 × params, the error vector per scaled coefficient.
        let mut g = DMatrix::zeros(3, params.len());
        for (j, p) in params.iter().enumerate() {
            let e = model
                .unit_response(&model.errors[p.term], p.degree, pt)
                .e_um;
            for c in 0..3 {
                g[(c, j)] = e[c] * p.size;
            }
        }
        let gn = g * nulls;
        let svd = gn.clone().svd(false, true);
        let (i, s) = svd.singular_values.argmax();
        if s > best.0 {
            let v = svd.v_t.map(|vt| nulls * vt.row(i).transpose());
            best = (s, pt.tool_mm, v);
        }
    }
    best
}

/// The menu of added measurements (the simulator's instruments) for a
/// machine of the model's travels.
fn menu(model: &Rigid21Model, tools_mm: [f64; 2]) -> Vec<(String, Vec<Instrument>)> {
    let tr = [0, 1, 2].map(|a| model.travel_mm[a].map_or(0.0, |[lo, hi]| hi - lo));
    let long = if tools_mm[1] > tools_mm[0] {
        tools_mm[1]
    } else {
        tools_mm[0] + 150.0
    };
    let mid = tr.map(|t| t * 0.5);
    let moving: Vec<usize> = model.chain.axes();
    vec![
        (
            format!(
                "tracker at two tool lengths ({} and {} mm) and lateral offsets",
                tools_mm[0], long
            ),
            vec![Instrument::Tracker {
                tools_mm: vec![tools_mm[0], long],
                lateral_mm: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
                points: 40,
            }],
        ),
        (
            "angular lines (roll, pitch, yaw) along each axis".into(),
            moving
                .iter()
                .map(|&axis| Instrument::Angular {
                    axis,
                    at_mm: mid,
                    points: 11,
                })
                .collect(),
        ),
        (
            "laser lines at two parallel offsets".into(),
            instruments::laser_lines(tr, &[tools_mm[0]])
                .into_iter()
                .filter(|i| matches!(i, Instrument::Line { axis, .. } if moving.contains(axis)))
                .collect(),
        ),
        (
            "body diagonals (ISO 230-6)".into(),
            instruments::body_diagonals(tr),
        ),
        (
            "laser lines with a 100 mm lateral target offset".into(),
            moving
                .iter()
                .map(|&axis| Instrument::Line {
                    axis,
                    at_mm: mid,
                    tool_mm: tools_mm[0],
                    tool_lat_mm: [100.0, 100.0],
                    straightness: true,
                    points: 11,
                })
                .collect(),
        ),
    ]
}

/// The rows of `plan` on a perfect machine of the model's travels, moved
/// to its measured range, restricted to the chain's axes.
fn menu_data(model: &Rigid21Model, plan: &[Instrument]) -> Dataset {
    let tr = [0, 1, 2].map(|a| model.travel_mm[a].map_or(0.0, |[lo, hi]| hi - lo));
    let mut d = instruments::measure(&Machine::perfect(tr), plan, 0, false);
    for a in 0..3 {
        match model.travel_mm[a] {
            Some([lo, _]) => {
                if let Some(c) = d.pos_mm[a].as_mut() {
                    c.iter_mut().for_each(|v| *v += lo);
                }
            }
            None => d.pos_mm[a] = None,
        }
    }
    d
}

/// What [`fit`] returns: the model, the identifiability answer and per
/// reading kind (key, RMS of the residual in the reading's unit, count).
pub type Fitted = (Rigid21Model, Identifiability, Vec<(String, f64, usize)>);

/// The fit of `rigid21:<degree>` to `data`: the model (cannot_know errors
/// without coefficients), the answer per error, and the RMS of the
/// weighted-back residuals per reading kind (`ex`, `ea_urad`, `e_beam`, …).
pub fn fit(data: &Dataset, degree: usize) -> Result<Fitted> {
    fit_with(data, degree, &[])
}

/// [`fit`] with the named effects `adds` on top, fitted jointly
/// (docs/volumetric.md § Effects on top). Refused when the data lack a
/// column an effect reads or cannot tell an effect from the errors.
pub fn fit_with(data: &Dataset, degree: usize, adds: &[Effect]) -> Result<Fitted> {
    let mut model = skeleton(data, degree)?;
    let params = params_of(&model);
    let norm = model.travel_norm();
    let fx = effects::columns(data, adds, &norm)?;
    let boxed = effects::as_columns(&fx);
    let extra: Vec<ExtraColumn> = boxed.iter().map(|b| b.as_ref() as ExtraColumn).collect();
    let pr = projected_with(data, &model, &params, &extra);
    if pr.b.len() <= pr.nuisance {
        bail!("rigid21: no readings left once each set-up's own zeros and frames are taken out");
    }
    let all_nulls = null_directions(&pr.m);
    effects::refuse_unseen(&model, &params, adds, &fx, &all_nulls)?;
    // The effects are seen: the model's near-null directions are those of
    // its own parameters.
    let nulls = all_nulls.rows(0, params.len()).into_owned();
    // Errors a null direction reaches.
    // Per coefficient: an error is cannot_know when a null direction
    // reaches any of its coefficients; the solve leaves out only the
    // reached coefficients, so the visible shape of a cannot_know error
    // (a roll's curvature seen by offset lines whose slope is lost) is
    // fitted and biases no estimated error — but it is never reported or
    // stored (docs/volumetric.md).
    let mut cannot = vec![false; model.errors.len()];
    let mut keep: Vec<usize> = Vec::new();
    for (j, p) in params.iter().enumerate() {
        let reach: f64 = (0..nulls.ncols()).map(|k| nulls[(j, k)].powi(2)).sum();
        if reach > REACH {
            cannot[p.term] = true;
        } else {
            keep.push(j);
        }
    }
    let kept_model = keep.len();
    keep.extend(params.len()..params.len() + fx.len());
    let (x, resid, cov) = solve_kept(&pr, &keep);
    let keep = &keep[..kept_model];
    let (saved, effect_answers) = effects::saved(
        adds,
        &fx,
        &x.as_slice()[kept_model..],
        &(kept_model..x.len())
            .map(|k| cov[(k, k)])
            .collect::<Vec<_>>(),
        norm,
    );
    if !adds.is_empty() {
        model.effects = Some(saved);
    }
    for (i, e) in model.errors.iter_mut().enumerate() {
        if cannot[i] {
            e.status = Status::CannotKnow;
            e.coef = None;
        } else {
            e.status = Status::Estimated;
            e.coef = Some(Vec::with_capacity(e.degrees.len()));
        }
    }
    for (k, &j) in keep.iter().enumerate() {
        let p = params[j];
        if let Some(c) = model.errors[p.term].coef.as_mut() {
            c.push(x[k] * p.size);
        }
    }
    // Per error: peak over the travel and its σ.
    let mut answers = Vec::new();
    for (t, e) in model.errors.iter().enumerate() {
        let idx: Vec<(usize, usize)> = keep
            .iter()
            .enumerate()
            .filter(|(_, &j)| params[j].term == t)
            .map(|(k, &j)| (k, j))
            .collect();
        let (peak, sigma) = if cannot[t] {
            (None, None)
        } else {
            let qs: Vec<Option<f64>> = match e.axis.filter(|_| e.kind != ErrorKind::Squareness) {
                Some(a) => {
                    let [lo, hi] = model.travel_mm[a].unwrap_or([0.0, 0.0]);
                    (0..=100)
                        .map(|i| Some(lo + (hi - lo) * i as f64 / 100.0))
                        .collect()
                }
                None => vec![None],
            };
            let mut best = (0.0f64, 0.0f64, 0.0f64);
            for q in qs {
                let s = match (e.axis, q) {
                    (Some(a), Some(q)) => model.normalised(a, q),
                    _ => 0.0,
                };
                let pl = crate::model::rigid21::legendre(model.degree, s);
                let v: f64 = idx
                    .iter()
                    .map(|&(k, j)| x[k] * params[j].size * pl[params[j].degree])
                    .sum();
                if v.abs() >= best.0.abs() {
                    let var: f64 = idx
                        .iter()
                        .flat_map(|&(k1, j1)| idx.iter().map(move |&(k2, j2)| (k1, j1, k2, j2)))
                        .map(|(k1, j1, k2, j2)| {
                            cov[(k1, k2)]
                                * params[j1].size
                                * params[j2].size
                                * pl[params[j1].degree]
                                * pl[params[j2].degree]
                        })
                        .sum();
                    best = (v, var.max(0.0).sqrt(), 0.0);
                }
            }
            if e.degrees.first() == Some(&0) || e.kind == ErrorKind::Squareness {
                (Some(best.0), Some(best.1))
            } else {
                (Some(best.0.abs()), Some(best.1))
            }
        };
        answers.push(ErrorAnswer {
            name: e.name.clone(),
            status: e.status,
            unit: e.kind.unit().into(),
            peak,
            sigma,
            coef: e.coef.clone(),
            coef_cov: (!cannot[t]).then(|| {
                idx.iter()
                    .map(|&(k1, j1)| {
                        idx.iter()
                            .map(|&(k2, j2)| cov[(k1, k2)] * params[j1].size * params[j2].size)
                            .collect()
                    })
                    .collect()
            }),
            hidden_um: None,
            hidden_at_tool_mm: None,
        });
    }
    // Hidden error and the measurement that removes the most of it.
    let tools = tool_range(data);
    let points = volume_points(&model, tools);
    for (t, a) in answers.iter_mut().enumerate() {
        if a.status != Status::CannotKnow {
            continue;
        }
        let own: Vec<usize> = (0..params.len()).filter(|&j| params[j].term == t).collect();
        let dirs = DMatrix::from_fn(params.len(), own.len(), |i, k| {
            f64::from(u8::from(i == own[k]))
        });
        let (h, at, _) = hidden(&model, &params, &dirs, &points);
        a.hidden_um = Some(h);
        a.hidden_at_tool_mm = Some(at);
    }
    let (h, h_tool, hv) = hidden(&model, &params, &nulls, &points);
    let hidden_from = hv.map_or(Vec::new(), |v| {
        let mut share: Vec<(f64, usize)> = Vec::new();
        for (j, p) in params.iter().enumerate() {
            match share.iter_mut().find(|(_, t)| *t == p.term) {
                Some(s) => s.0 += v[j] * v[j],
                None => share.push((v[j] * v[j], p.term)),
            }
        }
        share.sort_by(|a, b| b.0.total_cmp(&a.0));
        share
            .iter()
            .filter(|(s, _)| *s > 0.1)
            .map(|(_, t)| model.errors[*t].name.clone())
            .collect()
    });
    let measure = if h > 0.05 {
        let mut best: Option<Measure> = None;
        for (what, plan) in menu(&model, tools) {
            let extra = menu_data(&model, &plan);
            if extra.is_empty() {
                continue;
            }
            let pe = projected(&extra, &model, &params);
            let mut both = DMatrix::zeros(pr.m.nrows() + pe.m.nrows(), params.len());
            both.rows_mut(0, pr.m.nrows())
                .copy_from(&pr.m.columns(0, params.len()));
            both.rows_mut(pr.m.nrows(), pe.m.nrows()).copy_from(&pe.m);
            let n2 = null_directions(&both);
            let (h2, _, _) = hidden(&model, &params, &n2, &points);
            if best.as_ref().is_none_or(|b| h2 < b.hidden_um_after) {
                best = Some(Measure {
                    what,
                    hidden_um_after: h2,
                });
            }
        }
        best
    } else {
        None
    };
    // Residuals per reading kind, back in the reading's unit.
    let mut stats: Vec<(String, f64, usize)> = Vec::new();
    for (i, &(r, kind)) in pr.obs.iter().enumerate() {
        let u = data.u_um.as_ref().map_or(1.0, |v| v[r]);
        let v = resid[i] * u;
        let key = kind.key();
        match stats.iter_mut().find(|(k, _, _)| *k == key) {
            Some(s) => {
                s.1 += v * v;
                s.2 += 1;
            }
            None => stats.push((key, v * v, 1)),
        }
    }
    for s in &mut stats {
        s.1 = (s.1 / s.2 as f64).sqrt();
    }
    Ok((
        model,
        Identifiability {
            errors: answers,
            hidden_um: h,
            hidden_from,
            hidden_at_tool_mm: h_tool,
            measure,
            effects: effect_answers,
        },
        stats,
    ))
}

/// The weighted least-squares solution on the kept (scaled) columns, the
/// weighted residual and the covariance of the solution (s² V Σ⁻² Vᵀ, s²
/// the residual variance per degree of freedom). With no column kept the
/// solution is empty and the residual the projected readings.
fn solve_kept(pr: &Projected, keep: &[usize]) -> (DVector<f64>, DVector<f64>, DMatrix<f64>) {
    if keep.is_empty() {
        return (DVector::zeros(0), pr.b.clone(), DMatrix::zeros(0, 0));
    }
    let mk = pr.m.select_columns(keep);
    let svd = mk.clone().svd(true, true);
    let tol = svd.singular_values.max() * 1e-12;
    let inv: Vec<f64> = svd
        .singular_values
        .iter()
        .map(|&s| if s > tol { 1.0 / s } else { 0.0 })
        .collect();
    let (Some(u), Some(vt)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        unreachable!("SVD computed with U and Vᵀ");
    };
    let utb = u.transpose() * &pr.b;
    let scaled = DVector::from_fn(inv.len(), |k, _| utb[k] * inv[k]);
    let x = vt.transpose() * scaled;
    let resid = &pr.b - &mk * &x;
    let dof = pr.b.len() as f64 - keep.len() as f64 - pr.nuisance as f64;
    let s2 = if dof > 0.0 {
        resid.norm_squared() / dof
    } else {
        1.0
    };
    let cov = DMatrix::from_fn(keep.len(), keep.len(), |i, j| {
        s2 * (0..inv.len())
            .map(|k| vt[(k, i)] * inv[k] * inv[k] * vt[(k, j)])
            .sum::<f64>()
    });
    (x, resid, cov)
}

/// What [`reading_residuals`] returns: the model plus set-up value per
/// row for ex, ey, ez, and the residual per reading kind.
pub type Compared = ([Option<Vec<f64>>; 3], Vec<ReadingResidual>);

/// `model` evaluated at each row's tool point and compared with every
/// reading of `data` (docs/volumetric.md): each set-up's unknowns (zeros,
/// alignment slopes, frames) are fitted to what the model leaves, as the
/// instrument's own placement, never as the machine's error. Returns the
/// model plus set-up value per row for ex, ey, ez (what `compare`'s
/// statistics use) and the residual per reading kind. Err when the data
/// lack a column one of the model's effects reads.
pub fn reading_residuals(model: &Rigid21Model, data: &Dataset) -> Result<Compared> {
    let mut left = data.clone();
    // The named effects on top read the row's data (docs/volumetric.md).
    let preds: Vec<Prediction> = model.predict_readings(data)?;
    for c in 0..3 {
        if let Some(col) = left.err_um[c].as_mut() {
            for (r, v) in col.iter_mut().enumerate() {
                if let Some(v) = v {
                    *v -= preds[r].e_um[c];
                }
            }
        }
        if let Some(col) = left.angle_urad[c].as_mut() {
            for (r, v) in col.iter_mut().enumerate() {
                if let Some(v) = v {
                    *v -= preds[r].angle_urad[c];
                }
            }
        }
    }
    if let (Some(col), Some(dirs)) = (left.beam_um.as_mut(), data.beam_dir.as_ref()) {
        for (r, v) in col.iter_mut().enumerate() {
            if let (Some(v), Some(d)) = (v.as_mut(), dirs[r]) {
                *v -= preds[r].beam_um(d);
            }
        }
    }
    let pr = projected(&left, model, &[]);
    let mut fitted: [Option<Vec<f64>>; 3] =
        [0, 1, 2].map(|c| data.err_um[c].as_ref().map(|_| vec![f64::NAN; data.len()]));
    let mut out: Vec<ReadingResidual> = Vec::new();
    for (i, &(r, kind)) in pr.obs.iter().enumerate() {
        let u = data.u_um.as_ref().map_or(1.0, |v| v[r]);
        let res = pr.b[i] * u;
        if let (Reading::E(c), Some(Some(v))) = (
            kind,
            data.err_um[kind_target(kind)].as_ref().map(|col| col[r]),
        ) {
            if let Some(f) = fitted[c].as_mut() {
                f[r] = v - res;
            }
        }
        let key = kind.key();
        let unit = if matches!(kind, Reading::Angle(_)) {
            "µrad"
        } else {
            "µm"
        };
        let entry = match out.iter_mut().position(|o| o.reading == key) {
            Some(k) => &mut out[k],
            None => {
                out.push(ReadingResidual {
                    reading: key,
                    unit: unit.into(),
                    count: 0,
                    rms: 0.0,
                    max_abs: 0.0,
                });
                out.last_mut().expect("just pushed")
            }
        };
        entry.count += 1;
        entry.rms += res * res;
        entry.max_abs = entry.max_abs.max(res.abs());
    }
    for o in &mut out {
        o.rms = (o.rms / o.count as f64).sqrt();
    }
    Ok((fitted, out))
}

/// The ex/ey/ez column of an `E` reading (0 for the others, unused).
fn kind_target(kind: Reading) -> usize {
    match kind {
        Reading::E(c) => c,
        _ => 0,
    }
}

/// The smallest and largest tool length of the data, mm.
fn tool_range(data: &Dataset) -> [f64; 2] {
    match &data.tool_mm {
        Some(v) if !v.is_empty() => [
            v.iter().copied().fold(f64::INFINITY, f64::min),
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ],
        _ => [0.0, 0.0],
    }
}

/// The plain-words summary of what these data cannot tell (the text
/// output of `fit`): "cannot know A0T, B0T from these data: up to 2.3 µm at
/// tool 150 mm; measure: tracker …".
pub fn cannot_know_text(id: &Identifiability) -> Option<String> {
    let names: Vec<&str> = id
        .errors
        .iter()
        .filter(|e| e.status == Status::CannotKnow)
        .map(|e| e.name.as_str())
        .collect();
    if names.is_empty() {
        return None;
    }
    let from = if id.hidden_from.is_empty() {
        String::new()
    } else {
        format!(" (mostly {})", id.hidden_from.join(", "))
    };
    let measure = id.measure.as_ref().map_or(String::new(), |m| {
        format!(
            "; measure: {} (then up to {:.1} µm)",
            m.what, m.hidden_um_after
        )
    });
    Some(format!(
        "cannot know {} from these data: at realistic sizes (10 µm, 30 µrad) up to {:.1} µm at tool {} mm{from}{measure}",
        names.join(", "),
        id.hidden_um,
        id.hidden_at_tool_mm
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::instruments::{body_diagonals, laser_lines, measure};

    fn mill() -> Machine {
        Machine::preset("mill800-21").unwrap()
    }

    fn status(id: &Identifiability, name: &str) -> Status {
        id.errors.iter().find(|e| e.name == name).unwrap().status
    }

    /// Max over the points of |truth − model| after the best rigid-body
    /// placement (t + ω × p) of the model's frame: the gauge leaves the
    /// frame free, and a workpiece is set up by probing anyway.
    #[test]
    fn tracker_at_two_tool_lengths_estimates_all_21_and_the_tilt() {
        let m = mill();
        let plan = vec![
            Instrument::Tracker {
                tools_mm: vec![0.0, 150.0],
                lateral_mm: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
                points: 150,
            },
            Instrument::Tracker {
                tools_mm: vec![0.0, 150.0],
                lateral_mm: vec![[0.0, 0.0], [-100.0, 0.0], [0.0, -100.0]],
                points: 150,
            },
        ];
        let data = measure(&m, &plan, 7, true);
        let (model, id, _) = fit(&data, 4).unwrap();
        // The truth in the model's gauge: the same plan without noise
        // (degree 4 holds mill800's cubic translations and quadratic angles
        // exactly).
        let (_, exact, _) = fit(&measure(&m, &plan, 7, false), 4).unwrap();
        for (e, t) in id.errors.iter().zip(&exact.errors) {
            assert_eq!(e.status, Status::Estimated, "{}", e.name);
            let (v, s, tv) = (e.peak.unwrap(), e.sigma.unwrap(), t.peak.unwrap());
            assert!(
                (v - tv).abs() <= 4.0 * s + 1e-9,
                "{}: {v} ± {s}, truth {tv}",
                e.name
            );
        }
        let tilt = exact.errors.iter().find(|e| e.name == "A0T").unwrap();
        assert!(
            (tilt.peak.unwrap() - m.tilt_urad[0]).abs() < 0.5,
            "{tilt:?}"
        );
        // The volumetric error at points the fit never saw, at other tool
        // lengths and offsets: from tens of µm to ≤ 1.5 µm.
        // (Both after the one rigid frame the gauge leaves free.)
        let checks = super::super::volumetric_check::against_machine(
            &m,
            &model,
            &[40.0, 120.0, 250.0],
            60,
            99,
        );
        for c in &checks {
            assert!(c.before_max_um > 20.0, "{c:?}");
            assert!(c.after_max_um <= 1.5, "{c:?}");
        }
    }

    /// Every estimated error of the noisy fit within 4σ of the same
    /// plan's noise-free fit (the truth in the gauge): no confident wrong
    /// answer. Returns the noisy answer.
    fn honest(m: &Machine, plan: &[Instrument], keep_axes: &[usize], seed: u64) -> Identifiability {
        let ((_, id, _), wrong) =
            super::super::volumetric_check::against_noise_free(m, plan, keep_axes, 4, seed)
                .unwrap();
        assert!(wrong.is_empty(), "{wrong:?}");
        id
    }

    #[test]
    fn compare_sees_the_noise_once_set_ups_are_placed() {
        let m = mill();
        let plan = [Instrument::Tracker {
            tools_mm: vec![0.0, 150.0],
            lateral_mm: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
            points: 100,
        }];
        let data = measure(&m, &plan, 4, true);
        let (model, id, _) = fit(&data, 4).unwrap();
        assert!(id.errors.iter().all(|e| e.status == Status::Estimated));
        // On a fresh station (another seed: other points, frame, noise).
        let fresh = measure(&m, &plan, 8, true);
        let (fitted, kinds) = reading_residuals(&model, &fresh).unwrap();
        for k in &kinds {
            assert!(k.rms < 1.0, "{k:?}");
        }
        assert!(fitted[0].as_ref().unwrap().iter().all(|v| v.is_finite()));
        // A model that is all zero leaves the machine's error.
        let (_, kinds0) = reading_residuals(&model.zeroed(), &fresh).unwrap();
        assert!(kinds0.iter().any(|k| k.rms > 2.0), "{kinds0:?}");
    }

    #[test]
    fn a_two_axis_lathe_has_13_errors_and_answers_honestly() {
        // X and Z only (the machine's Y at 0), lines at two tool lengths
        // and two parallel offsets along Z / X.
        let m = mill();
        let mut plan = Vec::new();
        for (axis, other) in [(0usize, 2usize), (2, 0)] {
            for tool in [0.0, 100.0] {
                for side in [0.2, 0.8] {
                    let mut at = [0.0; 3];
                    at[other] = m.travel_mm[other] * side;
                    plan.push(instruments::laser_line(axis, at, tool));
                }
            }
        }
        let id = honest(&m, &plan, &[0, 2], 21);
        let n = id.errors.iter().filter(|e| !e.name.ends_with('T')).count();
        assert_eq!(
            n,
            13,
            "{:?}",
            id.errors.iter().map(|e| &e.name).collect::<Vec<_>>()
        );
        assert_eq!(status(&id, "A0T"), Status::CannotKnow);
    }

    #[test]
    fn one_tracker_station_at_one_tool_length_cannot_know_the_tilt() {
        let m = mill();
        let plan = [Instrument::Tracker {
            tools_mm: vec![100.0],
            lateral_mm: vec![[0.0, 0.0]],
            points: 120,
        }];
        let id = honest(&m, &plan, &[0, 1, 2], 5);
        for name in ["A0T", "B0T", "ECZ"] {
            assert_eq!(status(&id, name), Status::CannotKnow, "{name}");
        }
    }

    #[test]
    fn laser_lines_cannot_know_the_tilt_and_say_how_much_it_hides() {
        let m = mill();
        let tr = m.travel_mm;
        let data = measure(&m, &laser_lines(tr, &[0.0, 150.0]), 3, true);
        let (model, id, _) = fit(&data, 4).unwrap();
        assert_eq!(status(&id, "A0T"), Status::CannotKnow);
        assert_eq!(status(&id, "B0T"), Status::CannotKnow);
        assert!(model.error("A0T").unwrap().coef.is_none());
        // 30 µrad over 150 mm: 4.5 µm, at the longest tool.
        let a0t = id.errors.iter().find(|e| e.name == "A0T").unwrap();
        assert!((a0t.hidden_um.unwrap() - 4.5).abs() < 1e-9, "{a0t:?}");
        assert_eq!(a0t.hidden_at_tool_mm, Some(150.0));
        assert!(id.hidden_um >= 4.5, "{id:?}");
        // Tool on the spindle axis: ECY, ECZ get no value.
        assert_eq!(status(&id, "ECY"), Status::CannotKnow);
        assert_eq!(status(&id, "ECZ"), Status::CannotKnow);
        let text = cannot_know_text(&id).unwrap();
        assert!(text.contains("A0T") && text.contains("measure:"), "{text}");
    }

    #[test]
    fn diagonals_alone_leave_most_errors_unknown_and_name_what_to_add() {
        let m = mill();
        let data = measure(&m, &body_diagonals(m.travel_mm), 5, true);
        let (_, id, _) = fit(&data, 4).unwrap();
        let unknown = id
            .errors
            .iter()
            .filter(|e| e.status == Status::CannotKnow)
            .count();
        assert!(
            unknown * 2 > id.errors.len(),
            "{unknown} of {}",
            id.errors.len()
        );
        let ms = id.measure.as_ref().expect("a measurement to add");
        assert!(
            ms.hidden_um_after < id.hidden_um,
            "{ms:?} vs {}",
            id.hidden_um
        );
        for e in id.errors.iter().filter(|e| e.status == Status::CannotKnow) {
            assert!(e.peak.is_none() && e.coef.is_none());
        }
    }
}
