//! The noise floor: how small the residual can get when nothing systematic
//! is left, estimated so that shape the model has not caught yet is *not*
//! counted as noise (issue 12). In order of preference:
//!
//! 1. `uncertainty`: the data's own `u_um` column (RMS over the rows) — the
//!    user measured it, nothing here can know better.
//! 2. `repeats`: the same nominal point read again with every nominal input
//!    equal — position, approach directions, tool length, session — and
//!    close in time (consecutive readings of a group at most
//!    [`MAX_REPEAT_GAP_S`] apart, so a slow drift or warm-up between runs is
//!    not noise). Three tool lengths at one point are not repeats: the tool
//!    length is an input, and an Abbe error differs between them.
//! 3. `differences`: third-order differences r₀ − 3r₁ + 3r₂ − r₃ of four
//!    consecutive, evenly spaced points along a dense line (spacing ≤
//!    [`CLOSE_SPACING_MM`]; the points share every other input as above). A
//!    cubic along the line cancels exactly, and a wave of period P leaves
//!    (2 sin(πh/P))³/√20 of its amplitude — 5 % for P = 10 h — where the
//!    old neighbour difference left 2 sin(πh/P)/√2 (the wavy preset's
//!    180–320 mm shapes on a 25–50 mm line counted as noise).
//! 4. `grid_differences`: on a lattice without dense lines, the 3×3 stencil
//!    Δ²_a Δ²_b (second differences along two axes) on evenly spaced points
//!    sharing every other input. A serial machine's geometric errors are sums
//!    of f(q_k)·(affine in another axis) — positioning, straightness, and the
//!    angles times their arms — and every such term is affine along a or
//!    along b, so the stencil cancels it whatever its shape; so does an
//!    effect of one axis (a lead screw's periodic error).
//! 5. `sparse_differences`: an **upper bound** when none of the above can
//!    be trusted: third differences along every line (fifth where the
//!    third still see more shape), else the lattice's Δ³_a Δ³_b.
//!
//! A difference cancels a smooth shape only when the shape is smooth over
//! the 4–6 points it spans: a 9 × 9 bed map on a 25 mm grid is a "dense"
//! line by spacing, yet its third differences are the bed's shape (10 µm
//! against µm-level probe noise). So each difference estimate is checked
//! against one of higher order on the same points — fifth differences
//! along lines, Δ³_a Δ³_b on the lattice: on noise both give σ, but shape
//! leaks into the lower order by a factor (2 sin(πh/P))² more than into
//! the higher. When the higher order is below [`SHAPE_RATIO`] times the
//! lower (the lower ≥ 1.33× the noise if the higher were clean — the
//! verdict's own 1.3× margin), shape remains: that estimate is not a
//! floor, the next method is tried, and with none left the floor is
//! `sparse_differences`, said to be an upper bound (diagnose warns
//! `noise_floor_upper_bound`: re-probe points to measure repeatability).
//!
//! Every estimate is robust: each difference d is normalised by its weights
//! (z = d/‖w‖, ~ N(0, σ²) when no shape is left); a first σ is the median
//! |z| / 0.6745, and the floor is the RMS of the z within 3 of those σ
//! (corrected for the clip), the clip repeated with the new σ until the
//! kept set stops changing. A beam-break spike spoils a few differences but
//! does not move the floor — the old mean of squares let 0.5 % of 20–40 µm
//! spikes lift a 0.15 µm floor to 2.2 µm. All are taken on the current
//! model's residuals.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::data::Dataset;

/// How the noise floor was estimated (docs/cli.md § diagnose, `noise_method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseMethod {
    /// The data's `u_um` column.
    Uncertainty,
    /// Repeated readings of a point with every nominal input equal.
    Repeats,
    /// Third differences along dense, evenly spaced lines.
    Differences,
    /// Second differences along two axes of a lattice.
    GridDifferences,
    /// Differences that still see shape (an upper bound).
    SparseDifferences,
}

impl NoiseMethod {
    /// The method in words, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            NoiseMethod::Uncertainty => "the u_um column",
            NoiseMethod::Repeats => "repeated readings",
            NoiseMethod::Differences => "third differences along dense lines",
            NoiseMethod::GridDifferences => "second differences across the grid",
            NoiseMethod::SparseDifferences => {
                "differences that still see the shape (an upper bound)"
            }
        }
    }
}

/// A noise-floor estimate for one target.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct NoiseFloor {
    /// Standard deviation of the measurement noise, µm.
    pub sigma_um: f64,
    /// Number of differences (or rows, for `uncertainty`) behind it.
    pub dof: usize,
    /// How it was estimated.
    pub method: NoiseMethod,
    /// The reading quantum of the target's values (µm) when they sit on a
    /// grid ([`quantum`]); the floor is never below its q/√12.
    pub quantum_um: Option<f64>,
}

/// Fewest differences for an estimate to be used (and fewest repeated
/// points that make a `repeats` floor: what to re-probe when the floor is
/// only an upper bound).
pub const MIN_DOF: usize = 20;
/// A difference estimate is taken as a floor only when the estimate of the
/// next higher order on the same points is at least this share of it: on
/// noise both are σ (their ratio scatters by ~10 % with a few hundred
/// differences); below it, shape leaks into the lower order.
pub const SHAPE_RATIO: f64 = 0.75;
/// Widest spacing of a dense line, mm. A difference of order k spans k
/// steps, and cancels a shape only when the shape is smooth over them: a
/// guide's bumps and a scraped way's pattern are 20–60 mm wide, so a
/// dense line's five steps must fit inside one (5 × 10 = 50 mm). On
/// coarser lines a shape at the scale of the spacing looks like noise to
/// every order (a 40 mm guide bump on a 25 mm line: 1.4× the noise, third
/// and fifth differences alike), so they give an upper bound only.
pub const CLOSE_SPACING_MM: f64 = 10.0;
/// Longest time between two readings of a point that count as a repeat, s.
pub const MAX_REPEAT_GAP_S: f64 = 900.0;
/// Median |z| of a standard normal: σ = median |d/‖w‖| / this.
const MEDIAN_ABS_NORMAL: f64 = 0.674_489_750_196_081_7;

/// Positions and tool lengths are compared at 1 µm.
fn key(v: f64) -> i64 {
    (v * 1000.0).round() as i64
}

/// Robust σ from normalised differences (each ~ N(0, σ²) without shape):
/// a first scale from the median |z|, then the RMS of the differences
/// within [`CLIP`] times it, corrected for the clipping — as robust as the
/// median (a spike beyond the clip does not count) but nearly as precise as
/// an RMS (the median alone scatters ±20 % on 30 repeats).
///
/// `least` is the smallest first scale (q/√12 of quantised readings, else
/// 0): on readings quantised coarser than their noise most differences are
/// exactly 0, the median |z| is 0, and the clip would keep only the zeros.
fn robust_sigma(z: &mut [f64], least: f64) -> f64 {
    for v in z.iter_mut() {
        *v = v.abs();
    }
    z.sort_unstable_by(f64::total_cmp);
    let n = z.len();
    let med = if n % 2 == 1 {
        z[n / 2]
    } else {
        0.5 * (z[n / 2 - 1] + z[n / 2])
    };
    let mut s = (med / MEDIAN_ABS_NORMAL).max(least);
    // The clip is repeated with the new σ until the kept set stops
    // changing (on noise the first pass is already it; a cluster of large
    // differences that lifted the median is trimmed further).
    let mut kept_n = usize::MAX;
    for _ in 0..10 {
        // `z` is sorted: the kept values are a prefix.
        let k = z.partition_point(|v| *v <= CLIP * s);
        if s == 0.0 || k == 0 || k == kept_n {
            break;
        }
        kept_n = k;
        s = (z[..k].iter().map(|v| v * v).sum::<f64>() / k as f64 / CLIP_VARIANCE).sqrt();
    }
    s
}

/// Differences beyond this many first-scale σ are left out of the RMS.
const CLIP: f64 = 3.0;
/// E[z² | |z| ≤ 3] for a standard normal: 1 − 2·3·φ(3)/(2Φ(3) − 1).
const CLIP_VARIANCE: f64 = 0.973_336;

fn floor(mut z: Vec<f64>, method: NoiseMethod, least: f64) -> Option<NoiseFloor> {
    (z.len() >= MIN_DOF).then(|| NoiseFloor {
        dof: z.len(),
        sigma_um: robust_sigma(&mut z, least),
        method,
        quantum_um: None,
    })
}

/// The floor of `low` (normalised differences of one order) when the
/// differences of the next order on the same points, `high`, agree with it
/// (σ_high ≥ [`SHAPE_RATIO`]·σ_low); `Err` with the higher order's
/// estimate when they disagree (shape remains: an upper bound only, the
/// higher order the tighter one), `Ok(None)` when `low` is too few. With too few higher-order differences to check, the
/// lower order is trusted (the old rule).
fn checked(
    low: Vec<f64>,
    high: Vec<f64>,
    method: NoiseMethod,
    least: f64,
) -> Result<Option<NoiseFloor>, NoiseFloor> {
    let Some(lo) = floor(low, method, least) else {
        return Ok(None);
    };
    match floor(high, method, least) {
        Some(hi) if hi.sigma_um < SHAPE_RATIO * lo.sigma_um => Err(hi),
        _ => Ok(Some(lo)),
    }
}

/// Noise floor of `resid_um` on data rows `rows` (same order), or `None`
/// when the data has neither `u_um`, repeats nor lines to estimate it from
/// (or what they give is 0: no floor, never a floor of 0). Rows that
/// repeat an earlier row exactly ([`Dataset::duplicate_rows`]) are left
/// out: a copy is not a second reading.
pub fn noise_floor(data: &Dataset, rows: &[usize], resid_um: &[f64]) -> Option<NoiseFloor> {
    floor_with_quantum(data, rows, resid_um, None)
}

/// [`noise_floor`] of target `t`, never below the reading quantum of its
/// values: q/√12 when [`quantum`] finds one (the rounding error of a
/// reading is uniform over one step). Measured differences of quantised
/// readings already hold that rounding when the noise dithers it; when the
/// noise is finer than the step most differences are exactly 0 and miss
/// it — so the floor is the larger of the two, not their sum.
pub fn target_noise_floor(
    data: &Dataset,
    t: usize,
    rows: &[usize],
    resid_um: &[f64],
) -> Option<NoiseFloor> {
    let q = data.err_um[t]
        .as_ref()
        .and_then(|c| quantum(rows.iter().filter_map(|&r| c[r])));
    floor_with_quantum(data, rows, resid_um, q)
}

/// Fewest values [`quantum`] looks for a grid in.
const QUANTUM_MIN_VALUES: usize = 20;
/// Values closer than this (µm) are one grid step apart by rounding of
/// the written decimals, not by the reading.
const QUANTUM_TOL_UM: f64 = 1e-6;
/// A grid finer than this (µm) is no reading quantum worth a floor (the
/// decimals a file was written with, or none at all; its q/√12 would be
/// below 0.6 nm).
const QUANTUM_MIN_UM: f64 = 2e-3;

/// The reading quantum of `values` (µm): the step of the grid every value
/// sits on (a laser's or an encoder's resolution, a logger's rounding,
/// 0.25 µm on a spindle's axial probe), found as the greatest common
/// divisor of the differences between them (to [`QUANTUM_TOL_UM`]);
/// `None` when there are fewer than [`QUANTUM_MIN_VALUES`] or the grid is
/// finer than [`QUANTUM_MIN_UM`] (unquantised).
pub fn quantum(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.len() < QUANTUM_MIN_VALUES {
        return None;
    }
    v.sort_unstable_by(f64::total_cmp);
    v.dedup();
    if v.len() < 2 {
        return None;
    }
    let gcd = |mut a: f64, mut b: f64| {
        while b > QUANTUM_TOL_UM {
            let mut r = a % b;
            if b - r <= QUANTUM_TOL_UM {
                r = 0.0;
            }
            a = b;
            b = r;
        }
        a
    };
    let mut g = v[1] - v[0];
    for w in v.windows(2) {
        g = gcd(w[1] - w[0], g);
        if g < QUANTUM_MIN_UM {
            return None;
        }
    }
    Some(g)
}

fn floor_with_quantum(
    data: &Dataset,
    rows: &[usize],
    resid_um: &[f64],
    quantum_um: Option<f64>,
) -> Option<NoiseFloor> {
    let copies: std::collections::HashSet<usize> =
        data.duplicate_rows().into_iter().map(|(r, _)| r).collect();
    let (rows, resid): (Vec<usize>, Vec<f64>) = rows
        .iter()
        .zip(resid_um)
        .filter(|(r, _)| !copies.contains(r))
        .map(|(&r, &e)| (r, e))
        .unzip();
    let least = quantum_um.map_or(0.0, |q| q / 12f64.sqrt());
    estimate(data, &rows, &resid, least)
        .map(|f| NoiseFloor {
            sigma_um: f.sigma_um.max(least),
            quantum_um,
            ..f
        })
        .filter(|f| f.sigma_um > 0.0)
}

/// The floor before the quantum's bound, each robust σ seeded with at
/// least `least`.
fn estimate(data: &Dataset, rows: &[usize], resid_um: &[f64], least: f64) -> Option<NoiseFloor> {
    if let Some(u) = &data.u_um {
        let ms = rows.iter().map(|&r| u[r] * u[r]).sum::<f64>() / rows.len().max(1) as f64;
        if ms > 0.0 {
            return Some(NoiseFloor {
                sigma_um: ms.sqrt(),
                dof: rows.len(),
                method: NoiseMethod::Uncertainty,
                quantum_um: None,
            });
        }
    }
    // Every nominal input but the position: approach directions, tool
    // length, session.
    let inputs = |r: usize| -> Vec<i64> {
        let mut k: Vec<i64> = (0..3)
            .map(|a| data.dir[a].as_ref().map_or(0, |d| i64::from(d[r])))
            .collect();
        k.push(data.tool_mm.as_ref().map_or(0, |v| key(v[r])));
        k.push(data.session_id.as_ref().map_or(0, |v| v[r]));
        k
    };
    let pos = |r: usize| -> [i64; 3] { [0, 1, 2].map(|a| key(data.pos(a, r))) };
    let mut points: BTreeMap<(Vec<i64>, [i64; 3]), Vec<usize>> = BTreeMap::new();
    for (i, &r) in rows.iter().enumerate() {
        points.entry((inputs(r), pos(r))).or_default().push(i);
    }

    // Repeats: consecutive readings of a point, in time order.
    let time = |i: usize| data.t_s.as_ref().map(|t| t[rows[i]]);
    let mut z = Vec::new();
    for g in points.values().filter(|g| g.len() > 1) {
        let mut g = g.clone();
        g.sort_by(|&a, &b| {
            time(a)
                .unwrap_or(0.0)
                .total_cmp(&time(b).unwrap_or(0.0))
                .then(a.cmp(&b))
        });
        for w in g.windows(2) {
            let close = match (time(w[0]), time(w[1])) {
                (Some(t0), Some(t1)) => t1 - t0 <= MAX_REPEAT_GAP_S,
                _ => true,
            };
            if close {
                z.push((resid_um[w[1]] - resid_um[w[0]]) / 2f64.sqrt());
            }
        }
    }
    if let Some(f) = floor(z, NoiseMethod::Repeats, least) {
        return Some(f);
    }

    // Lines: the k-th reading of each point (a plan run twice gives two
    // lines, not one line with every point doubled) along each axis, the
    // other axes' positions and every other input equal. `next[a][i]`: the
    // following point of row i's line along axis a, and the gap (µm).
    let n = rows.len();
    let mut occurrence = vec![0i64; n];
    for g in points.values() {
        for (k, &i) in g.iter().enumerate() {
            occurrence[i] = k as i64;
        }
    }
    let mut next: [Vec<Option<(usize, i64)>>; 3] = Default::default();
    // Third and fifth differences, along dense and along sparse lines.
    let (mut dense, mut sparse) = (Vec::new(), Vec::new());
    let (mut dense5, mut sparse5) = (Vec::new(), Vec::new());
    let even = |h1: i64, h2: i64| (h1 - h2).abs() <= (h1.max(h2) / 100).max(2);
    let evenly = |h: &[i64]| h.windows(2).all(|w| even(w[0], w[1]));
    for axis in 0..3 {
        next[axis] = vec![None; n];
        if data.pos_mm[axis].is_none() {
            continue;
        }
        let mut lines: BTreeMap<Vec<i64>, Vec<(i64, usize)>> = BTreeMap::new();
        for (i, &r) in rows.iter().enumerate() {
            let p = pos(r);
            let mut k = inputs(r);
            k.push(occurrence[i]);
            k.extend((0..3).filter(|&a| a != axis).map(|a| p[a]));
            lines.entry(k).or_default().push((p[axis], i));
        }
        for mut l in lines.into_values() {
            l.sort_unstable();
            for w in l.windows(2) {
                next[axis][w[0].1] = Some((w[1].1, w[1].0 - w[0].0));
            }
            for (order, weights) in [(3, &W3[..]), (5, &W5[..])] {
                for w in l.windows(order + 1) {
                    let h: Vec<i64> = w.windows(2).map(|p| p[1].0 - p[0].0).collect();
                    if !evenly(&h) {
                        continue;
                    }
                    let d = difference(weights, |k| resid_um[w[k].1]);
                    let is_dense = h[0] as f64 <= CLOSE_SPACING_MM * 1000.0;
                    match (order, is_dense) {
                        (3, true) => dense.push(d),
                        (3, false) => sparse.push(d),
                        (_, true) => dense5.push(d),
                        (_, false) => sparse5.push(d),
                    }
                }
            }
        }
    }
    let mut lines_all = dense.clone();
    lines_all.extend_from_slice(&sparse);
    let mut lines_all5 = dense5.clone();
    lines_all5.extend_from_slice(&sparse5);
    if let Ok(Some(f)) = checked(dense, dense5, NoiseMethod::Differences, least) {
        return Some(f);
    }

    // The lattice stencils Δ^k_a Δ^k_b (k = 2, and k = 3 to check it): k+1
    // evenly spaced points along a from row i, and from each of them k+1
    // along b at one common spacing.
    let run = |axis: usize, i: usize, len: usize| -> Option<(Vec<usize>, i64)> {
        let mut pts = vec![i];
        let mut gap = None;
        while pts.len() < len {
            let (j, h) = next[axis][*pts.last()?]?;
            if gap.is_some_and(|g| !even(g, h)) {
                return None;
            }
            gap.get_or_insert(h);
            pts.push(j);
        }
        Some((pts, gap?))
    };
    let stencil = |weights: &[f64]| -> Vec<f64> {
        let len = weights.len();
        let norm: f64 = weights.iter().map(|w| w * w).sum();
        let mut out = Vec::new();
        for a in 0..3 {
            for b in a + 1..3 {
                for i in 0..n {
                    let Some((along_a, _)) = run(a, i, len) else {
                        continue;
                    };
                    let Some((_, g)) = run(b, i, len) else {
                        continue;
                    };
                    let cols: Option<Vec<Vec<usize>>> = along_a
                        .iter()
                        .map(|&j| run(b, j, len).filter(|(_, gj)| even(*gj, g)).map(|t| t.0))
                        .collect();
                    let Some(cols) = cols else {
                        continue;
                    };
                    let d: f64 = (0..len)
                        .flat_map(|p| (0..len).map(move |q| (p, q)))
                        .map(|(p, q)| weights[p] * weights[q] * resid_um[cols[p][q]])
                        .sum();
                    out.push(d / norm);
                }
            }
        }
        out
    };
    let grid_bound = match checked(
        stencil(&W2),
        stencil(&W3),
        NoiseMethod::GridDifferences,
        least,
    ) {
        Ok(Some(f)) => return Some(f),
        Ok(None) => None,
        Err(hi) => Some(hi),
    };
    // Nothing trusted: an upper bound from every line — its third
    // differences, or its fifth where the third still see more shape —
    // else from the lattice's higher-order stencil. (Not the smallest of
    // all estimates: with a few dozen differences each, the smallest of
    // four fell to 0.5× the noise on a 50 mm line.)
    let lines = match checked(lines_all, lines_all5, NoiseMethod::SparseDifferences, least) {
        Ok(f) => f,
        Err(hi) => Some(hi),
    };
    lines.or(grid_bound).map(|f| NoiseFloor {
        method: NoiseMethod::SparseDifferences,
        ..f
    })
}

/// The `noise_floor_upper_bound` warning of a target whose floor is
/// `sparse_differences`: what the floor is, and how many readings to
/// repeat so that `repeats` can measure it ([`MIN_DOF`] pairs, each within
/// [`MAX_REPEAT_GAP_S`] of the first reading).
pub(super) fn upper_bound_warning(
    target: &str,
    nf: &NoiseFloor,
    data: &Dataset,
    rows: &[usize],
) -> Option<super::Warning> {
    if nf.method != NoiseMethod::SparseDifferences {
        return None;
    }
    let what = reprobe(data, rows, " (or repeat the whole map)");
    Some(super::Warning {
        code: "noise_floor_upper_bound".into(),
        detail: format!(
            "{target}: the noise floor is an upper bound ({:.3} µm from {}: the points are more than {} mm apart, or differences of higher order on them disagree, so shape on the scale of the spacing is counted in it); {what}, each within {} min of its first reading, to measure repeatability",
            nf.sigma_um,
            nf.method.describe(),
            CLOSE_SPACING_MM,
            (MAX_REPEAT_GAP_S / 60.0).round()
        ),
    })
}

/// The `reading_quantum` warning of a target whose floor is set by its
/// reading quantum (q/√12 above what the differences measure): the
/// readings are coarser than their noise, so no model can get below it.
pub(super) fn quantum_warning(target: &str, nf: &NoiseFloor) -> Option<super::Warning> {
    let q = nf.quantum_um?;
    let least = q / 12f64.sqrt();
    (nf.sigma_um <= least).then(|| super::Warning {
        code: "reading_quantum".into(),
        detail: format!(
            "{target}: the readings are quantised in steps of {q:.4} µm, coarser than their noise (most differences between neighbouring readings are exactly 0), so the noise floor is the rounding's own q/√12 = {least:.4} µm: a residual below it cannot be measured at this resolution"
        ),
    })
}

/// What to re-probe so that `repeats` can measure the floor: [`MIN_DOF`]
/// of the points (`many` added after it), or each point enough times.
fn reprobe(data: &Dataset, rows: &[usize], many: &str) -> String {
    let points: std::collections::BTreeSet<[i64; 3]> = rows
        .iter()
        .map(|&r| [0, 1, 2].map(|a| key(data.pos(a, r))))
        .collect();
    let m = points.len().max(1);
    if m >= MIN_DOF {
        format!("re-probe {MIN_DOF} of its {m} points{many}")
    } else {
        format!(
            "re-probe each of its {m} points {} more times",
            MIN_DOF.div_ceil(m)
        )
    }
}

/// The `noise_floor_unknown` warning of a target without a floor: these
/// data cannot say how small its residual can get (no `u_um`, no repeated
/// readings, no evenly spaced line or lattice to difference), so nothing
/// is said to be at or above it — and what to measure so that `repeats`
/// can ([`MIN_DOF`] repeated readings, each within [`MAX_REPEAT_GAP_S`]
/// of the first).
pub(super) fn unknown_warning(target: &str, data: &Dataset, rows: &[usize]) -> super::Warning {
    let what = reprobe(data, rows, "");
    let copies = data.duplicate_rows().len();
    super::Warning {
        code: "noise_floor_unknown".into(),
        detail: format!(
            "{target}: the noise floor cannot be known from these data (no u_um column, no repeated readings{}, no evenly spaced line or lattice to difference), so the residual is not compared with it; {what}, each within {} min of its first reading (or give the instrument's uncertainty as u_um), to measure it",
            if copies > 0 {
                format!(" — the {copies} rows that repeat another exactly are copies, not readings")
            } else {
                String::new()
            },
            (MAX_REPEAT_GAP_S / 60.0).round()
        ),
    }
}

/// Difference weights of order 2, 3 and 5 (binomial, alternating).
const W2: [f64; 3] = [1.0, -2.0, 1.0];
const W3: [f64; 4] = [1.0, -3.0, 3.0, -1.0];
const W5: [f64; 6] = [1.0, -5.0, 10.0, -10.0, 5.0, -1.0];

/// A difference Σ wₖ·r(k), normalised by ‖w‖ (~ N(0, σ²) on noise).
fn difference(weights: &[f64], r: impl Fn(usize) -> f64) -> f64 {
    let norm: f64 = weights.iter().map(|w| w * w).sum::<f64>().sqrt();
    weights
        .iter()
        .enumerate()
        .map(|(k, w)| w * r(k))
        .sum::<f64>()
        / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pseudo_noise(i: usize) -> f64 {
        // A deterministic, uniform, uncorrelated sequence in [−1, 1)
        // (σ = 1/√3): the SplitMix64 finaliser of the index.
        let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    #[test]
    fn differences_see_noise_not_a_smooth_trend() {
        let n = 1000;
        let d = Dataset {
            pos_mm: [Some((0..n).map(|i| i as f64).collect()), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let resid: Vec<f64> = (0..n)
            .map(|i| 5.0 * (i as f64 / 300.0).sin() + pseudo_noise(i))
            .collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::Differences);
        let sigma = (1.0f64 / 3.0).sqrt();
        assert!((nf.sigma_um / sigma - 1.0).abs() < 0.15, "{}", nf.sigma_um);
    }

    /// A 5 mm line over a 30 mm waviness of 2 µm (a scraped way): third
    /// differences keep (2 sin(π/6))³/√20 = 22 % of it, ~0.3 µm RMS against
    /// 0.06 µm of noise, fifth differences 6 % — they disagree, so the floor
    /// is an upper bound (main called the shape noise: `differences`).
    #[test]
    fn a_dense_line_whose_fifth_differences_disagree_is_an_upper_bound() {
        let n = 400;
        let d = Dataset {
            pos_mm: [Some((0..n).map(|i| i as f64 * 5.0).collect()), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let resid: Vec<f64> = (0..n)
            .map(|i| {
                2.0 * (std::f64::consts::TAU * i as f64 * 5.0 / 30.0).sin() + 0.1 * pseudo_noise(i)
            })
            .collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::SparseDifferences, "{nf:?}");
        // Without the wave the same line measures the noise.
        let clean: Vec<f64> = (0..n).map(|i| 0.1 * pseudo_noise(i)).collect();
        let nf = noise_floor(&d, &rows, &clean).unwrap();
        assert_eq!(nf.method, NoiseMethod::Differences);
        let ratio = nf.sigma_um / (0.1 * uniform_sigma());
        assert!((0.85..1.15).contains(&ratio), "{ratio}");
    }

    #[test]
    fn repeats_are_preferred() {
        let pos: Vec<f64> = (0..300).map(|i| (i % 50) as f64 * 10.0).collect();
        let resid: Vec<f64> = (0..300)
            .map(|i| (i % 50) as f64 + 0.1 * pseudo_noise(i))
            .collect();
        // The readings themselves: repeats differ in their value (rows
        // equal in every column are copies, not repeats).
        let d = Dataset {
            pos_mm: [Some(pos), None, None],
            err_um: [Some(resid.iter().copied().map(Some).collect()), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..300).collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::Repeats);
        assert_eq!(nf.dof, 250);
        assert!(nf.sigma_um < 0.1);
    }

    /// 1/√3: the σ of `pseudo_noise`.
    fn uniform_sigma() -> f64 {
        (1.0f64 / 3.0).sqrt()
    }

    #[test]
    fn tool_lengths_are_an_input_not_repeats() {
        // 50 points 10 mm apart, each read with three tool lengths: an Abbe
        // error of 48.5 µrad × tool differs between them by up to 7 µm.
        let (mut x, mut tool) = (Vec::new(), Vec::new());
        for t in [0.0, 100.0, 150.0] {
            for i in 0..50 {
                x.push(i as f64 * 10.0);
                tool.push(t);
            }
        }
        let n = x.len();
        let resid: Vec<f64> = (0..n)
            .map(|i| 0.0485 * tool[i] + 0.1 * pseudo_noise(i))
            .collect();
        let d = Dataset {
            pos_mm: [Some(x), None, None],
            tool_mm: Some(tool),
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::Differences);
        let ratio = nf.sigma_um / (0.1 * uniform_sigma());
        assert!((0.8..1.2).contains(&ratio), "{ratio}");
    }

    #[test]
    fn readings_an_hour_apart_are_not_repeats() {
        // A 50-point line measured twice, an hour apart, with 2 µm of warm-up
        // between the runs: not noise.
        let x: Vec<f64> = (0..100).map(|i| (i % 50) as f64 * 5.0).collect();
        let t: Vec<f64> = (0..100)
            .map(|i| (i / 50) as f64 * 3600.0 + (i % 50) as f64 * 5.0)
            .collect();
        let resid: Vec<f64> = (0..100)
            .map(|i| 2.0 * (i / 50) as f64 + 0.1 * pseudo_noise(i))
            .collect();
        let d = Dataset {
            pos_mm: [Some(x), None, None],
            t_s: Some(t),
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..100).collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::Differences);
        let ratio = nf.sigma_um / (0.1 * uniform_sigma());
        assert!((0.8..1.2).contains(&ratio), "{ratio}");
    }

    #[test]
    fn spikes_do_not_lift_the_floor() {
        // 0.5 % beam breaks of 20–40 µm on 0.15 µm-scale noise.
        let n = 2000;
        let d = Dataset {
            pos_mm: [Some((0..n).map(|i| i as f64 * 0.5).collect()), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let resid: Vec<f64> = (0..n)
            .map(|i| {
                let spike = if i % 200 == 17 {
                    20.0 + (i % 3) as f64 * 10.0
                } else {
                    0.0
                };
                0.26 * pseudo_noise(i) + spike
            })
            .collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        let ratio = nf.sigma_um / (0.26 * uniform_sigma());
        assert!((0.85..1.15).contains(&ratio), "{ratio}");
    }

    #[test]
    fn u_um_is_the_floor_when_given() {
        let pos: Vec<f64> = (0..300).map(|i| (i % 50) as f64 * 10.0).collect();
        let d = Dataset {
            pos_mm: [Some(pos), None, None],
            u_um: Some(vec![0.3; 300]),
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..300).collect();
        let resid: Vec<f64> = (0..300).map(pseudo_noise).collect();
        let nf = noise_floor(&d, &rows, &resid).unwrap();
        assert_eq!(nf.method, NoiseMethod::Uncertainty);
        assert!((nf.sigma_um - 0.3).abs() < 1e-12);
    }
}
