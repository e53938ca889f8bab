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
//! 5. `sparse_differences`: third differences along lines whose spacing is
//!    wider than dense: an upper bound when the residual has shape on the
//!    scale of the spacing.
//!
//! Every estimate is robust: each difference d is normalised by its weights
//! (z = d/‖w‖, ~ N(0, σ²) when no shape is left); a first σ is the median
//! |z| / 0.6745, and the floor is the RMS of the z within 3 of those σ
//! (corrected for the clip). A beam-break spike spoils a few differences but
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
    /// Third differences along lines wider than dense (an upper bound).
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
                "third differences along sparse lines (an upper bound)"
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
}

/// Fewest differences for an estimate to be used.
const MIN_DOF: usize = 20;
/// Widest spacing of a dense line, mm: third differences at this spacing
/// leave under 5 % of a wave of 150 mm or longer.
pub const CLOSE_SPACING_MM: f64 = 25.0;
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
fn robust_sigma(z: &mut [f64]) -> f64 {
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
    let s0 = med / MEDIAN_ABS_NORMAL;
    let kept: Vec<f64> = z.iter().copied().filter(|v| *v <= CLIP * s0).collect();
    if s0 == 0.0 || kept.is_empty() {
        return s0;
    }
    (kept.iter().map(|v| v * v).sum::<f64>() / kept.len() as f64 / CLIP_VARIANCE).sqrt()
}

/// Differences beyond this many first-scale σ are left out of the RMS.
const CLIP: f64 = 3.0;
/// E[z² | |z| ≤ 3] for a standard normal: 1 − 2·3·φ(3)/(2Φ(3) − 1).
const CLIP_VARIANCE: f64 = 0.973_336;

fn floor(mut z: Vec<f64>, method: NoiseMethod) -> Option<NoiseFloor> {
    (z.len() >= MIN_DOF).then(|| NoiseFloor {
        dof: z.len(),
        sigma_um: robust_sigma(&mut z),
        method,
    })
}

/// Noise floor of `resid_um` on data rows `rows` (same order), or `None`
/// when the data has neither `u_um`, repeats nor lines to estimate it from.
pub fn noise_floor(data: &Dataset, rows: &[usize], resid_um: &[f64]) -> Option<NoiseFloor> {
    if let Some(u) = &data.u_um {
        let ms = rows.iter().map(|&r| u[r] * u[r]).sum::<f64>() / rows.len().max(1) as f64;
        if ms > 0.0 {
            return Some(NoiseFloor {
                sigma_um: ms.sqrt(),
                dof: rows.len(),
                method: NoiseMethod::Uncertainty,
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
    if let Some(f) = floor(z, NoiseMethod::Repeats) {
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
    let (mut dense, mut sparse) = (Vec::new(), Vec::new());
    let even = |h1: i64, h2: i64| (h1 - h2).abs() <= (h1.max(h2) / 100).max(2);
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
            for w in l.windows(4) {
                let h = [w[1].0 - w[0].0, w[2].0 - w[1].0, w[3].0 - w[2].0];
                if !(even(h[0], h[1]) && even(h[1], h[2])) {
                    continue;
                }
                let r = |k: usize| resid_um[w[k].1];
                let d = (r(0) - 3.0 * r(1) + 3.0 * r(2) - r(3)) / 20f64.sqrt();
                if h[1] as f64 <= CLOSE_SPACING_MM * 1000.0 {
                    dense.push(d);
                } else {
                    sparse.push(d);
                }
            }
        }
    }
    if let Some(f) = floor(dense, NoiseMethod::Differences) {
        return Some(f);
    }

    // The lattice stencil Δ²_a Δ²_b: three evenly spaced points along a from
    // row i, and from each of them three along b at one common spacing.
    let triple = |axis: usize, i: usize| -> Option<([usize; 3], i64)> {
        let (j1, h1) = next[axis][i]?;
        let (j2, h2) = next[axis][j1]?;
        even(h1, h2).then_some(([i, j1, j2], h1))
    };
    let mut grid = Vec::new();
    for a in 0..3 {
        for b in a + 1..3 {
            for i in 0..n {
                let Some((along_a, _)) = triple(a, i) else {
                    continue;
                };
                let Some((_, g)) = triple(b, i) else {
                    continue;
                };
                let cols: Option<Vec<[usize; 3]>> = along_a
                    .iter()
                    .map(|&j| triple(b, j).filter(|(_, gj)| even(*gj, g)).map(|t| t.0))
                    .collect();
                let Some(cols) = cols else {
                    continue;
                };
                let w = [1.0, -2.0, 1.0];
                let d: f64 = (0..3)
                    .flat_map(|p| (0..3).map(move |q| (p, q)))
                    .map(|(p, q)| w[p] * w[q] * resid_um[cols[p][q]])
                    .sum();
                grid.push(d / 6.0);
            }
        }
    }
    floor(grid, NoiseMethod::GridDifferences)
        .or_else(|| floor(sparse, NoiseMethod::SparseDifferences))
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

    #[test]
    fn repeats_are_preferred() {
        let pos: Vec<f64> = (0..300).map(|i| (i % 50) as f64 * 10.0).collect();
        let d = Dataset {
            pos_mm: [Some(pos), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..300).collect();
        let resid: Vec<f64> = (0..300)
            .map(|i| (i % 50) as f64 + 0.1 * pseudo_noise(i))
            .collect();
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
