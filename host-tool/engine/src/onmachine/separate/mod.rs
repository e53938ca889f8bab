//! Error separation (docs/on-machine.md § separate): the reversal method splits
//! a straightness measurement into the part's form and the slide's
//! straightness. Run 1 (part at 0°, probe on one side) reads
//! `T1(x) = P(x) + S(x)`; after turning the part 180° about the travel axis
//! and reversing the probe, the part's form faces the probe the same way
//! while the slide's motion reads with the opposite sign:
//! `T2(x) = P(x) − S(x)`. So `P = (T1 + T2)/2`, `S = (T1 − T2)/2`, each
//! defined up to a straight line (the set-up's offset and tilt, removed by
//! least squares: the straightness convention).
//!
//! The noise of each run is estimated from its second differences
//! (robustly: median absolute value), which cancel a smooth profile; `P`
//! and `S` then carry `σ/√2` each per point if the runs' noise is
//! independent.
//!
//! Round a turning part: `spindle` separates roundness from the spindle's
//! error motion (three probes, or one probe and the part remounted in
//! steps) with the error motion of ISO 230-7 — from readings resampled by
//! angle (`turn`), whatever their sampling.

pub mod spindle;
pub mod turn;

pub use spindle::{multi_step, three_probe, ErrorMotion, MultiStep, Step, ThreeProbe};
pub use turn::{spectrum, Spectrum, Track};

use anyhow::{bail, Result};

/// The two halves of a reversal.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Reversal {
    /// Positions along the travel (run 1's, inside run 2's range), mm.
    pub pos_mm: Vec<f64>,
    /// The part's form, µm, least-squares line removed.
    pub part_um: Vec<f64>,
    /// The slide's straightness, µm, least-squares line removed.
    pub slide_um: Vec<f64>,
    /// Peak to valley of each, µm.
    pub part_pv_um: f64,
    /// Peak to valley of the slide, µm.
    pub slide_pv_um: f64,
    /// Noise of each run, µm (second differences); `None` with fewer
    /// than 8 points.
    pub run_noise_um: [Option<f64>; 2],
    /// Standard uncertainty of each point of P and S, µm.
    pub point_sigma_um: Option<f64>,
    /// Run-1 rows outside run 2's range, left out.
    pub left_out: usize,
}

fn line_removed(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let mx = x.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let k = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    x.iter()
        .zip(y)
        .map(|(a, b)| b - my - k * (a - mx))
        .collect()
}

/// Peak to valley of `v` (the one definition the probing commands —
/// separate, probe, workpiece — use).
pub fn pv(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - v.iter().copied().fold(f64::INFINITY, f64::min)
}

/// Noise from second differences of evenly enough spaced readings: the
/// median |Δ²| scaled to σ (Δ² of white noise has variance 6σ²; the
/// median of |N(0, 6σ²)| is 0.6745·√6·σ). `None` with fewer than 8.
pub fn noise(y: &[f64]) -> Option<f64> {
    if y.len() < 8 {
        return None;
    }
    let mut d: Vec<f64> = y
        .windows(3)
        .map(|w| (w[0] - 2.0 * w[1] + w[2]).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    let med = d[d.len() / 2];
    Some(med / (0.674_489_75 * 6f64.sqrt()))
}

/// The two-sided quantile that the largest of `n` independent standard
/// normal deviates stays below with 95 % probability: `P(|N| > z) =
/// 1 − 0.95^(1/n)`. A peak to valley is taken over all points, so its
/// interval needs every point's bound at once, not one point's 1.96 (with
/// 500 points the noise's extremes lie near ±3 σ).
pub fn z_all(n: usize) -> f64 {
    let tail = 1.0 - 0.95f64.powf(1.0 / n.max(1) as f64);
    // erfc(z/√2) = tail, by bisection on Abramowitz & Stegun 7.1.26
    // (absolute error below 1.5·10⁻⁷, relative below 0.2 % out to z = 5).
    let erfc = |x: f64| {
        let t = 1.0 / (1.0 + 0.327_591_1 * x);
        let p = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        p * (-x * x).exp()
    };
    let (mut lo, mut hi) = (0.0f64, 8.0f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if erfc(mid / 2f64.sqrt()) > tail {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A touch-trigger probe's run as readings: `(position along the travel,
/// touch position along the probe's approach axis)` in mm become `(pos,
/// sign·(touch − first touch))` in µm, `sign` +1 when the probe moves in
/// −touch to meet the surface (the surface faces +), −1 the other way — so
/// a surface nearer the probe reads more, as an analogue probe's does
/// (its ball radius and pre-travel are constants of the run: in the line
/// removed).
pub fn touch_readings(rows: &[[f64; 2]], sign: f64) -> Vec<(f64, f64)> {
    let first = rows.first().map_or(0.0, |r| r[1]);
    rows.iter()
        .map(|r| (r[0], sign * (r[1] - first) * 1e3))
        .collect()
}

/// Separates run 1 `(pos, reading)` and run 2 (both µm readings at mm
/// positions, each sorted or not) by the reversal method.
pub fn reversal(run1: &[(f64, f64)], run2: &[(f64, f64)]) -> Result<Reversal> {
    let mut a = run1.to_vec();
    let mut b = run2.to_vec();
    a.sort_by(|p, q| p.0.total_cmp(&q.0));
    b.sort_by(|p, q| p.0.total_cmp(&q.0));
    if a.len() < 3 || b.len() < 3 {
        bail!(
            "each run needs at least 3 readings (got {} and {})",
            a.len(),
            b.len()
        );
    }
    if let Some(w) = b.windows(2).find(|w| w[0].0 == w[1].0) {
        bail!(
            "run 2 has two readings at {} mm; average repeats first",
            w[0].0
        );
    }
    let (lo, hi) = (b[0].0, b[b.len() - 1].0);
    // Run 2 interpolated (linearly) at run 1's positions inside its range.
    let mut pos = Vec::new();
    let mut t1 = Vec::new();
    let mut t2 = Vec::new();
    let mut left_out = 0;
    for &(x, y) in &a {
        if x < lo || x > hi {
            left_out += 1;
            continue;
        }
        let k = b.partition_point(|p| p.0 <= x).clamp(1, b.len() - 1);
        let (p0, p1) = (b[k - 1], b[k]);
        let f = (x - p0.0) / (p1.0 - p0.0);
        pos.push(x);
        t1.push(y);
        t2.push(p0.1 + f * (p1.1 - p0.1));
    }
    if pos.len() < 3 {
        bail!(
            "the runs overlap in {} positions; the two orientations must cover the same travel",
            pos.len()
        );
    }
    let p: Vec<f64> = t1.iter().zip(&t2).map(|(a, b)| 0.5 * (a + b)).collect();
    let s: Vec<f64> = t1.iter().zip(&t2).map(|(a, b)| 0.5 * (a - b)).collect();
    let part_um = line_removed(&pos, &p);
    let slide_um = line_removed(&pos, &s);
    let n1 = noise(&a.iter().map(|q| q.1).collect::<Vec<_>>());
    let n2 = noise(&b.iter().map(|q| q.1).collect::<Vec<_>>());
    let point_sigma_um = match (n1, n2) {
        (Some(x), Some(y)) => Some(0.5 * (x * x + y * y).sqrt()),
        _ => None,
    };
    Ok(Reversal {
        part_pv_um: pv(&part_um),
        slide_pv_um: pv(&slide_um),
        pos_mm: pos,
        part_um,
        slide_um,
        run_noise_um: [n1, n2],
        point_sigma_um,
        left_out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reversal_splits_part_form_from_slide_straightness() {
        // Part: a 2 µm bow; slide: a 3 µm wave plus tilt; run 2 measured at
        // shifted positions with its own offset and tilt (set-up).
        let part = |x: f64| 2.0 * ((x - 150.0) / 150.0).powi(2);
        let slide = |x: f64| 1.5 * (x / 60.0).sin() + 0.004 * x;
        // 20 nm of white noise per reading (fixed seed).
        let mut rng = trueaxis_test_support::SplitMix64(11);
        let run1: Vec<(f64, f64)> = (0..=300)
            .map(|i| {
                let x = i as f64;
                (x, part(x) + slide(x) + 0.02 * rng.normal())
            })
            .collect();
        let run2: Vec<(f64, f64)> = (0..=600)
            .map(|i| {
                let x = i as f64 * 0.5 + 0.25;
                (
                    x,
                    part(x) - slide(x) + 0.7 - 0.001 * x + 0.02 * rng.normal(),
                )
            })
            .collect();
        let r = reversal(&run1, &run2).unwrap();
        let truth_p = line_removed(
            &r.pos_mm,
            &r.pos_mm.iter().map(|&x| part(x)).collect::<Vec<_>>(),
        );
        let truth_s = line_removed(
            &r.pos_mm,
            &r.pos_mm.iter().map(|&x| slide(x)).collect::<Vec<_>>(),
        );
        let worst = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f64, f64::max)
        };
        assert!(
            worst(&r.part_um, &truth_p) < 0.05,
            "{}",
            worst(&r.part_um, &truth_p)
        );
        assert!(
            worst(&r.slide_um, &truth_s) < 0.05,
            "{}",
            worst(&r.slide_um, &truth_s)
        );
        // Run 1's ends outside run 2's 0.25…300.25 mm: the first is left out.
        assert_eq!(r.left_out, 1);
        // Each run's noise from its second differences: 0.02 µm.
        for n in r.run_noise_um {
            let n = n.unwrap();
            assert!((0.014..0.028).contains(&n), "{n}");
        }
        let sigma = r.point_sigma_um.unwrap();
        assert!((sigma - 0.02 / 2f64.sqrt()).abs() < 0.005, "{sigma}");
    }

    #[test]
    fn runs_that_do_not_overlap_are_refused() {
        let a: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, 0.0)).collect();
        let b: Vec<(f64, f64)> = (20..30).map(|i| (i as f64, 0.0)).collect();
        assert!(reversal(&a, &b)
            .unwrap_err()
            .to_string()
            .contains("same travel"));
    }
}
