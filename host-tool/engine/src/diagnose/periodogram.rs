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
use std::sync::{Arc, Mutex, PoisonError};

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

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
    gls_from_sums(n, [sy, sc, ss, syy, syc, sys, scc, scs])
}

/// The power from the eight sums Σy, Σcos, Σsin, Σy², Σy·cos, Σy·sin,
/// Σcos², Σcos·sin over `n` samples.
fn gls_from_sums(n: f64, sums: [f64; 8]) -> f64 {
    let [sy, sc, ss, syy, syc, sys, scc, scs] = sums;
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

/// Frequencies × samples above which [`periodogram`] takes the FFT path.
const FAST_ABOVE: f64 = 4e6;

/// Generalised Lomb–Scargle power at the `count` evenly spaced frequencies
/// `f0 + i·df`, equal to [`gls_power`] at each up to round-off (~1e-12
/// relative) in O(samples + count·log count), via [`trig_sums`].
///
/// The sums that do not depend on `y` (Σcos, Σsin at f and at 2f) are
/// taken from [`unweighted_sums`], computed once per set of positions and
/// frequency grid: `diagnose` asks for the periodogram of each target's
/// residual at every step on the same lines.
pub fn gls_power_grid(pos_mm: &[f64], y: &[f64], f0: f64, df: f64, count: usize) -> Vec<f64> {
    let n = y.len() as f64;
    if n < 4.0 {
        return vec![0.0; count];
    }
    let (sy, syy) = y.iter().fold((0.0, 0.0), |(a, b), v| (a + v, b + v * v));
    let a = trig_sums(pos_mm, Some(y), f0, df, count);
    let u = unweighted_sums(pos_mm, f0, df, count);
    let (b, c) = (&u.at_f, &u.at_2f);
    (0..count)
        .map(|i| {
            gls_from_sums(
                n,
                [
                    sy,
                    b[i].0,
                    b[i].1,
                    syy,
                    a[i].0,
                    a[i].1,
                    // Σcos² = (n + Σcos 2θ)/2 and Σcos·sin = Σsin 2θ / 2:
                    // the unweighted sums at twice the frequency.
                    (n + c[i].0) / 2.0,
                    c[i].1 / 2.0,
                ],
            )
        })
        .collect()
}

/// The unweighted sums Σe^{i2π f p} of one set of positions on one
/// frequency grid, at f and at 2f, with what they were computed for.
struct Unweighted {
    pos_mm: Vec<f64>,
    f0: f64,
    df: f64,
    count: usize,
    at_f: Vec<(f64, f64)>,
    at_2f: Vec<(f64, f64)>,
}

/// How many sets of unweighted sums are kept: one per target and axis of a
/// 3-axis, 3-target data set (the targets' rows can differ), plus room
/// for the aliasing check's per-position means.
const UNWEIGHTED_KEPT: usize = 12;

/// The most recently used unweighted sums, newest last.
static UNWEIGHTED: Mutex<Vec<Arc<Unweighted>>> = Mutex::new(Vec::new());

/// [`trig_sums`] without weights at `f0 + i·df` and at twice those
/// frequencies, from a small cache keyed by the exact positions and grid
/// (two of the three FFT sets of [`gls_power_grid`]; a miss computes both
/// and keeps them, dropping the least recently used).
fn unweighted_sums(pos_mm: &[f64], f0: f64, df: f64, count: usize) -> Arc<Unweighted> {
    let same = |u: &Unweighted| {
        u.count == count
            && u.f0.to_bits() == f0.to_bits()
            && u.df.to_bits() == df.to_bits()
            && u.pos_mm.len() == pos_mm.len()
            && u.pos_mm
                .iter()
                .zip(pos_mm)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    };
    {
        let mut kept = UNWEIGHTED.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(i) = kept.iter().position(|u| same(u)) {
            let u = kept.remove(i);
            kept.push(Arc::clone(&u));
            return u;
        }
    }
    // Computed outside the lock: another target's periodogram runs meanwhile.
    let u = Arc::new(Unweighted {
        pos_mm: pos_mm.to_vec(),
        f0,
        df,
        count,
        at_f: trig_sums(pos_mm, None, f0, df, count),
        at_2f: trig_sums(pos_mm, None, 2.0 * f0, 2.0 * df, count),
    });
    let mut kept = UNWEIGHTED.lock().unwrap_or_else(PoisonError::into_inner);
    if !kept.iter().any(|k| same(k)) {
        if kept.len() >= UNWEIGHTED_KEPT {
            kept.remove(0);
        }
        kept.push(Arc::clone(&u));
    }
    u
}

/// Taylor terms binned per pass over the samples in [`trig_sums`].
const TERMS_AT_ONCE: usize = 8;

/// One planner for the process: it keeps the plan (twiddles, algorithm
/// choice) of each FFT length it has made.
static PLANNER: Mutex<Option<FftPlanner<f64>>> = Mutex::new(None);

/// The inverse-sign FFT of length `len`, X_i = Σ_k x_k e^{+i2π ik/len}
/// (unnormalised), planned once per length.
fn inverse_fft(len: usize) -> Arc<dyn Fft<f64>> {
    let mut planner = PLANNER.lock().unwrap_or_else(PoisonError::into_inner);
    planner
        .get_or_insert_with(FftPlanner::new)
        .plan_fft_inverse(len)
}

/// Σ_j w_j·e^{i2π f p_j} (re, im) for f = f0 + i·df, i in 0..count (w = 1
/// without `w`), to round-off, without a sin/cos per frequency and sample.
///
/// Each position is split into a grid point g_k = lo + k·h and an offset
/// δ (|δ| ≤ h/2), with h = 1/(L·df) for an FFT length L ≥ count, so that
/// the grid's phases e^{i2π·i·df·k·h} = e^{i2π·ik/L} are one FFT (k taken
/// mod L: the phase is L-periodic in k). The offset's phase is
/// e^{i2π fc δ}·e^{i2π u δ}, fc the middle frequency and u = f − fc, the
/// first taken into the weights, the second expanded in a Taylor series
/// Σ_m (i2π u δ)^m / m!, |2π u δ| ≤ π·count/(2L) = x ≤ π/2, summed until
/// x^m/m! < 1e-17: one FFT per term. A short FFT with more terms is the
/// cheaper trade (terms grow like log, the FFT like L): at L ≈ count
/// about 23 terms, at L ≈ 8·count about 12 for 8× the length.
pub fn trig_sums(
    pos_mm: &[f64],
    w: Option<&[f64]>,
    f0: f64,
    df: f64,
    count: usize,
) -> Vec<(f64, f64)> {
    let mut out = vec![(0.0, 0.0); count];
    if pos_mm.is_empty() || count == 0 {
        return out;
    }
    let lo = pos_mm.iter().copied().fold(f64::INFINITY, f64::min);
    let len = count.next_power_of_two().max(64);
    let h = 1.0 / (len as f64 * df);
    let fc = f0 + df * (count as f64 - 1.0) / 2.0;
    let x = std::f64::consts::PI * (count as f64) / (2.0 * len as f64);
    // Terms: x^m/m! < 1e-17.
    let mut terms = 1;
    let mut t = 1.0;
    while t >= 1e-17 && terms < 60 {
        t *= x / terms as f64;
        terms += 1;
    }
    // Grid cell and offset of each sample; the cell's base phase
    // e^{i2π f0 k h} and the offset's e^{i2π fc δ} go into the weight,
    // which is multiplied by δ once per term.
    let mut slot = Vec::with_capacity(pos_mm.len());
    let mut offset = Vec::with_capacity(pos_mm.len());
    let mut weight = Vec::with_capacity(pos_mm.len());
    for (j, &p) in pos_mm.iter().enumerate() {
        let wj = w.map_or(1.0, |w| w[j]);
        let k = ((p - lo) / h).round();
        let d = (p - lo) - k * h;
        let (s0, c0) = (TAU * (f0 * k * h + fc * d)).sin_cos();
        slot.push((k as u64 % len as u64) as usize);
        offset.push(d);
        weight.push(Complex::new(wj * c0, wj * s0));
    }
    // Term m's coefficient at frequency i: (i·2π(f_i − fc))^m / m!.
    let mut coef = vec![Complex::new(1.0, 0.0); count];
    let u: Vec<f64> = (0..count)
        .map(|i| TAU * df * (i as f64 - (count as f64 - 1.0) / 2.0))
        .collect();
    let mut sum = vec![Complex::new(0.0, 0.0); count];
    let fft = inverse_fft(len);
    let mut bins = vec![Complex::new(0.0, 0.0); len];
    let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    // The samples' moments Σ w·δ^m per grid cell, TERMS_AT_ONCE terms per
    // pass over the samples: a cell's terms side by side, so a sample adds
    // into one short run of memory (samples come in position order, cells
    // in order too), and one pass serves several FFTs.
    let mut moments = vec![Complex::new(0.0, 0.0); len * TERMS_AT_ONCE];
    for m0 in (0..terms).step_by(TERMS_AT_ONCE) {
        let now = TERMS_AT_ONCE.min(terms - m0);
        moments.fill(Complex::new(0.0, 0.0));
        for ((&s, wt), &d) in slot.iter().zip(weight.iter_mut()).zip(&offset) {
            let cell = &mut moments[s * TERMS_AT_ONCE..s * TERMS_AT_ONCE + now];
            for c in cell {
                *c += *wt;
                *wt *= d;
            }
        }
        for j in 0..now {
            for (b, cell) in bins.iter_mut().zip(moments.chunks_exact(TERMS_AT_ONCE)) {
                *b = cell[j];
            }
            fft.process_with_scratch(&mut bins, &mut scratch);
            let next = 1.0 / ((m0 + j) as f64 + 1.0);
            for (((c, s), &b), &u) in coef.iter_mut().zip(sum.iter_mut()).zip(&bins).zip(&u) {
                *s += *c * b;
                *c *= Complex::new(0.0, u * next);
            }
        }
    }
    for (i, (o, s)) in out.iter_mut().zip(&sum).enumerate() {
        let f = f0 + df * i as f64;
        let (sn, cs) = (TAU * f * lo).sin_cos();
        let v = s * Complex::new(cs, sn);
        *o = (v.re, v.im);
    }
    out
}

/// [`gls_power`] at the `count` evenly spaced frequencies `f0 + i·df` by a
/// phase recurrence per sample (two sin/cos per sample, not per frequency;
/// round-off grows with `count`, for the short refinement scans).
pub fn gls_power_scan(pos_mm: &[f64], y: &[f64], f0: f64, df: f64, count: usize) -> Vec<f64> {
    let n = y.len() as f64;
    if n < 4.0 {
        return vec![0.0; count];
    }
    let (sy, syy) = y.iter().fold((0.0, 0.0), |(a, b), v| (a + v, b + v * v));
    // Per frequency: Σcos, Σsin, Σy·cos, Σy·sin, Σcos 2θ, Σsin 2θ.
    let mut acc = vec![[0.0f64; 6]; count];
    for (p, v) in pos_mm.iter().zip(y) {
        let (s, c) = (TAU * f0 * p).sin_cos();
        let (ds, dc) = (TAU * df * p).sin_cos();
        let (mut c, mut s) = (c, s);
        for a in acc.iter_mut() {
            a[0] += c;
            a[1] += s;
            a[2] += v * c;
            a[3] += v * s;
            a[4] += c * c - s * s;
            a[5] += 2.0 * c * s;
            (c, s) = (c * dc - s * ds, c * ds + s * dc);
        }
    }
    acc.iter()
        .map(|a| {
            gls_from_sums(
                n,
                [
                    sy,
                    a[0],
                    a[1],
                    syy,
                    a[2],
                    a[3],
                    (n + a[4]) / 2.0,
                    a[5] / 2.0,
                ],
            )
        })
        .collect()
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
        freq.push(fmin + (fmax - fmin) * i as f64 / steps.max(1) as f64);
    }
    // Per-frequency sums cost (frequencies × samples) sin/cos pairs; past a
    // few million the same sums come from binned FFTs (equal to round-off).
    if steps >= 64 && (steps + 1) as f64 * pos_mm.len() as f64 > FAST_ABOVE {
        power = gls_power_grid(pos_mm, y, fmin, (fmax - fmin) / steps as f64, steps + 1);
    } else {
        power.extend(freq.iter().map(|&f| gls_power(pos_mm, y, f)));
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

    #[test]
    fn fast_sums_equal_the_direct_ones_to_round_off() {
        let pos: Vec<f64> = (0..3000)
            .map(|i| 17.0 + (i % 1500) as f64 * 0.31 + 0.05 * ((i * 7919) % 13) as f64 / 13.0)
            .collect();
        let y: Vec<f64> = pos
            .iter()
            .enumerate()
            .map(|(i, p)| (TAU * p / 5.08).sin() + 0.3 * (((i * 104729) % 101) as f64 / 50.0 - 1.0))
            .collect();
        let (f0, df, count) = (0.01, 0.0021, 700);
        let grid = gls_power_grid(&pos, &y, f0, df, count);
        let scan = gls_power_scan(&pos, &y, f0, df, 41);
        for i in 0..count {
            let direct = gls_power(&pos, &y, f0 + df * i as f64);
            assert!(
                (grid[i] - direct).abs() < 1e-10,
                "{i}: {} vs {direct}",
                grid[i]
            );
            if i < 41 {
                assert!(
                    (scan[i] - direct).abs() < 1e-11,
                    "{i}: {} vs {direct}",
                    scan[i]
                );
            }
        }
    }

    /// A line long and dense enough for [`periodogram`]'s fast path
    /// (frequencies × samples past [`FAST_ABOVE`]): uneven positions from
    /// a seeded generator, two directions over 400 mm, a 5.08 mm wave.
    fn long_line(seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = trueaxis_test_support::SplitMix64::new(seed);
        let pos: Vec<f64> = (0..4000)
            .map(|i| (i % 2000) as f64 * 0.2 + 0.05 * rng.unit())
            .collect();
        let y: Vec<f64> = pos
            .iter()
            .map(|p| 1.5 * (TAU * p / 5.08).sin() + 0.2 * rng.signed_unit())
            .collect();
        (pos, y)
    }

    /// Every 13th frequency of `pg` against [`gls_power`] there.
    fn assert_direct(pos: &[f64], y: &[f64], pg: &Periodogram) {
        for i in (0..pg.power.len()).step_by(13) {
            let direct = gls_power(pos, y, pg.freq_per_mm[i]);
            assert!(
                (pg.power[i] - direct).abs() < 1e-10,
                "{i}: {} vs {direct}",
                pg.power[i]
            );
        }
    }

    #[test]
    fn the_fast_path_and_its_shared_sums_equal_the_direct_power() {
        let (pos, y) = long_line(15);
        let (min_p, max_p) = (0.5, 100.0);
        let pg = periodogram(&pos, &y, min_p, max_p);
        assert!(pg.power.len() as f64 * pos.len() as f64 > FAST_ABOVE);
        assert_direct(&pos, &y, &pg);
        let k = pg.peak().unwrap();
        assert!((1.0 / pg.freq_per_mm[k] - 5.08).abs() < 0.02);
        // Another residual on the same positions reuses the unweighted
        // sums; other positions on the same grid must not.
        let (_, y2) = long_line(16);
        assert_direct(&pos, &y2, &periodogram(&pos, &y2, min_p, max_p));
        let shifted: Vec<f64> = pos.iter().map(|p| p + 0.37).collect();
        let mut moved = shifted.clone();
        moved[1234] += 0.01;
        for p in [&shifted, &moved] {
            let pg = periodogram(p, &y2, min_p, max_p);
            assert_direct(p, &y2, &pg);
        }
    }
}
