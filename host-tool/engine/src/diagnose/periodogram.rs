//! Lines of measurement points and the Lomb–Scargle periodogram of residuals
//! along them: how `diagnose` finds a lead-screw or scale period that nobody
//! told it about (5.08 mm as readily as 5 mm), and how it knows when the
//! sampling cannot see short periods at all (aliasing).
//!
//! The periodogram uses the densest lines along the axis
//! ([`crate::lines::densest_lines`], here also as `dense_lines`): on a 50 mm
//! grid a 5 mm period is invisible, and pooling grid rows into the
//! periodogram only adds aliased power.
//!
//! The periodogram is the generalised (floating-mean) Lomb–Scargle form of
//! Zechmeister & Kürster (2009): at each frequency, the share of the
//! residual variance explained by a constant plus a sine and a cosine, on
//! unevenly spaced samples.

use std::f64::consts::TAU;

pub use crate::lines::{densest_lines as dense_lines, DenseLines};

/// A periodogram: power (share of variance explained, 0..1) per frequency.
#[derive(Clone, Debug)]
pub struct Periodogram {
    /// Frequencies, cycles per mm, ascending.
    pub freq_per_mm: Vec<f64>,
    /// Power at each frequency, 0..1.
    pub power: Vec<f64>,
}

impl Periodogram {
    /// Index of the highest peak.
    pub fn peak(&self) -> Option<usize> {
        (0..self.power.len()).max_by(|&a, &b| self.power[a].total_cmp(&self.power[b]))
    }

    /// Median power: the periodogram's noise level.
    pub fn median_power(&self) -> f64 {
        let mut p = self.power.clone();
        if p.is_empty() {
            return 0.0;
        }
        p.sort_by(f64::total_cmp);
        p[p.len() / 2]
    }
}

/// Generalised Lomb–Scargle power of `y` sampled at `pos_mm`, at one frequency.
pub fn gls_power(pos_mm: &[f64], y: &[f64], f: f64) -> f64 {
    let n = y.len() as f64;
    if n < 4.0 {
        return 0.0;
    }
    let (mut sy, mut sc, mut ss, mut syy, mut syc, mut sys, mut scc, mut scs) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (p, v) in pos_mm.iter().zip(y) {
        let (s, c) = (TAU * f * p).sin_cos();
        sy += v;
        sc += c;
        ss += s;
        syy += v * v;
        syc += v * c;
        sys += v * s;
        scc += c * c;
        scs += c * s;
    }
    let (sy, sc, ss) = (sy / n, sc / n, ss / n);
    let yy = syy / n - sy * sy;
    let yc = syc / n - sy * sc;
    let ys = sys / n - sy * ss;
    let cc = scc / n - sc * sc;
    let sss = 1.0 - scc / n - ss * ss;
    let cs = scs / n - sc * ss;
    let d = cc * sss - cs * cs;
    if yy <= 0.0 || d <= 1e-12 {
        return 0.0;
    }
    ((sss * yc * yc + cc * ys * ys - 2.0 * cs * yc * ys) / (yy * d)).clamp(0.0, 1.0)
}

/// The periodogram of `y` at `pos_mm` for periods from `min_period_mm` to
/// `max_period_mm`, oversampled 5× relative to the natural resolution
/// 1/span (a peak is not missed between grid frequencies).
pub fn periodogram(
    pos_mm: &[f64],
    y: &[f64],
    min_period_mm: f64,
    max_period_mm: f64,
) -> Periodogram {
    let lo = pos_mm.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = pos_mm.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = (hi - lo).max(1e-9);
    let fmin = 1.0 / max_period_mm;
    let fmax = 1.0 / min_period_mm;
    let df = 1.0 / (5.0 * span);
    let mut freq = Vec::new();
    let mut power = Vec::new();
    if fmax <= fmin || fmax.is_nan() || fmin.is_nan() || !df.is_finite() {
        return Periodogram {
            freq_per_mm: freq,
            power,
        };
    }
    // Bounded so that a pathological span/spacing cannot run for minutes.
    let steps = (((fmax - fmin) / df).ceil() as usize).min(200_000);
    for i in 0..=steps {
        let f = fmin + (fmax - fmin) * i as f64 / steps.max(1) as f64;
        freq.push(f);
        power.push(gls_power(pos_mm, y, f));
    }
    Periodogram {
        freq_per_mm: freq,
        power,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_an_odd_period_on_uneven_samples() {
        // Uneven positions (a jittered 0.5 mm step) and a 5.08 mm period.
        let pos: Vec<f64> = (0..1200)
            .map(|i| i as f64 * 0.5 + 0.2 * ((i * 7919) % 13) as f64 / 13.0)
            .collect();
        let y: Vec<f64> = pos
            .iter()
            .enumerate()
            .map(|(i, p)| {
                2.0 * (TAU * p / 5.08 + 0.4).sin()
                    + 0.3 * (((i * 104729) % 101) as f64 / 50.0 - 1.0)
                    + 7.0
            })
            .collect();
        let pg = periodogram(&pos, &y, 1.0, 200.0);
        let k = pg.peak().unwrap();
        let period = 1.0 / pg.freq_per_mm[k];
        assert!((period - 5.08).abs() < 0.01, "{period}");
        assert!(pg.power[k] > 50.0 * pg.median_power());
    }
}
