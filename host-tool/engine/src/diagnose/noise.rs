//! The noise floor: how small the residual can get when nothing systematic
//! is left. From repeats (the same nominal point, approached the same way,
//! measured more than once: pooled within-point variance) when there are
//! enough of them, else from short-range differences along dense lines (the
//! von Neumann / Rice estimator: neighbouring points share every smooth
//! error, so half the mean squared difference of neighbours is the noise
//! variance). Both are taken on the current model's residuals; while an
//! effect with a short period is still missing the difference estimate is
//! an upper bound, and it falls once that effect is in the model.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::data::Dataset;

/// How the noise floor was estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseMethod {
    /// Pooled variance of repeated points.
    Repeats,
    /// Neighbour differences along dense lines.
    Differences,
}

/// A noise-floor estimate for one target.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct NoiseFloor {
    /// Standard deviation of the measurement noise, µm.
    pub sigma_um: f64,
    /// Degrees of freedom behind the estimate.
    pub dof: usize,
    /// How it was estimated.
    pub method: NoiseMethod,
}

/// Fewest degrees of freedom for a repeat-based estimate to be preferred.
const MIN_REPEAT_DOF: usize = 20;

fn key(v: f64) -> i64 {
    (v * 1000.0).round() as i64
}

/// Noise floor of `resid_um` on data rows `rows` (same order), or `None`
/// when the data has neither repeats nor lines to estimate it from.
pub fn noise_floor(data: &Dataset, rows: &[usize], resid_um: &[f64]) -> Option<NoiseFloor> {
    // Repeats: same nominal position and same approach directions.
    let mut groups: BTreeMap<Vec<i64>, Vec<f64>> = BTreeMap::new();
    for (i, &r) in rows.iter().enumerate() {
        let mut k: Vec<i64> = (0..3).map(|a| key(data.pos(a, r))).collect();
        for a in 0..3 {
            k.push(data.dir[a].as_ref().map_or(0, |d| i64::from(d[r])));
        }
        groups.entry(k).or_default().push(resid_um[i]);
    }
    let (mut ss, mut dof) = (0.0, 0usize);
    for g in groups.values().filter(|g| g.len() > 1) {
        let m = g.iter().sum::<f64>() / g.len() as f64;
        ss += g.iter().map(|v| (v - m).powi(2)).sum::<f64>();
        dof += g.len() - 1;
    }
    if dof >= MIN_REPEAT_DOF {
        return Some(NoiseFloor {
            sigma_um: (ss / dof as f64).sqrt(),
            dof,
            method: NoiseMethod::Repeats,
        });
    }
    // Differences along lines: rows sharing the other axes' positions and
    // the approach direction, sorted along each axis in turn; only
    // neighbours at the line's own (median) spacing count, so jumps across a
    // gap do not inflate the estimate.
    let local: BTreeMap<usize, usize> = rows.iter().enumerate().map(|(i, &r)| (r, i)).collect();
    let (mut sd, mut nd) = (0.0, 0usize);
    for axis in data.axes() {
        let mut lines: BTreeMap<Vec<i64>, Vec<(i64, usize)>> = BTreeMap::new();
        for &r in rows {
            let mut k: Vec<i64> = (0..3)
                .filter(|&a| a != axis)
                .map(|a| key(data.pos(a, r)))
                .collect();
            for a in 0..3 {
                k.push(data.dir[a].as_ref().map_or(0, |d| i64::from(d[r])));
            }
            lines
                .entry(k)
                .or_default()
                .push((key(data.pos(axis, r)), r));
        }
        for mut l in lines.into_values() {
            if l.len() < 8 {
                continue;
            }
            l.sort_unstable();
            let mut steps: Vec<i64> = l
                .windows(2)
                .map(|w| w[1].0 - w[0].0)
                .filter(|d| *d > 0)
                .collect();
            if steps.is_empty() {
                continue;
            }
            steps.sort_unstable();
            let med = steps[steps.len() / 2];
            for w in l.windows(2) {
                let d = w[1].0 - w[0].0;
                if d > 0 && d <= med + med / 2 {
                    let diff = resid_um[local[&w[1].1]] - resid_um[local[&w[0].1]];
                    sd += diff * diff;
                    nd += 1;
                }
            }
        }
    }
    (nd >= MIN_REPEAT_DOF).then(|| NoiseFloor {
        sigma_um: (sd / (2.0 * nd as f64)).sqrt(),
        dof: nd,
        method: NoiseMethod::Differences,
    })
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
}
