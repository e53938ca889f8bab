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

/// The result of a three-probe roundness separation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ThreeProbe {
    /// Samples per turn.
    pub samples: usize,
    /// The part's roundness profile at `k·360/samples` degrees, µm
    /// (harmonics 2…samples/2 that the probes see).
    pub part_um: Vec<f64>,
    /// The spindle's radial error motion along probe 1, µm.
    pub spindle_x_um: Vec<f64>,
    /// …and perpendicular to it (toward +90°), µm.
    pub spindle_y_um: Vec<f64>,
    /// Peak to valley of the part's roundness, µm.
    pub part_pv_um: f64,
    /// Peak to valley of the spindle motion along probe 1, µm.
    pub spindle_x_pv_um: f64,
    /// Harmonics the probe angles cannot see (|W(k)| below 10 % of its
    /// largest): left out of the part and named.
    pub unseen_harmonics: Vec<usize>,
    /// Per harmonic 2…samples/2 the factor by which reading noise is
    /// amplified in the part's profile (1/|W(k)|), for the uncertainty.
    pub noise_gain: Vec<[f64; 2]>,
}

/// Separates a part's roundness from the spindle's radial error motion
/// with three probes at `angles_deg` (the first is the reference
/// direction) read at `samples` equally spaced rotation angles
/// (`readings[i] = [p1, p2, p3]` µm at `i·360/samples` degrees; one turn,
/// or several averaged by the caller). The combination `m1 + a m2 + b m3`
/// with `1 + a cos α + b cos β = 0` and `a sin α + b sin β = 0` cancels the
/// error motion; in Fourier terms the part's harmonic k is then the
/// combination's divided by `W(k) = 1 + a e^{−ikα} + b e^{−ikβ}`. Where
/// `|W(k)|` is small the probes cannot see harmonic k (the spacing's
/// blind spots, like the aliasing of a coarse grid): it is left out and
/// named. Harmonics 0 and 1 (size and centring) are not roundness.
pub fn three_probe(readings: &[[f64; 3]], angles_deg: [f64; 3]) -> Result<ThreeProbe> {
    let n = readings.len();
    if n < 16 {
        bail!("{n} samples per turn; three-probe separation needs at least 16");
    }
    let (al, be) = (
        (angles_deg[1] - angles_deg[0]).to_radians(),
        (angles_deg[2] - angles_deg[0]).to_radians(),
    );
    let det = al.cos() * be.sin() - be.cos() * al.sin();
    if det.abs() < 1e-6 {
        bail!("the probe angles {angles_deg:?} are collinear (0° and 180° apart): they cannot separate the spindle's motion");
    }
    // Solve 1 + a cos α + b cos β = 0, a sin α + b sin β = 0.
    let a = -be.sin() / det;
    let b = al.sin() / det;
    let m: Vec<f64> = readings
        .iter()
        .map(|r| r[0] + a * r[1] + b * r[2])
        .collect();
    let w = |k: usize| -> (f64, f64) {
        let kf = k as f64;
        (
            1.0 + a * (kf * al).cos() + b * (kf * be).cos(),
            -(a * (kf * al).sin() + b * (kf * be).sin()),
        )
    };
    let half = n / 2;
    let wmax = (2..=half)
        .map(|k| w(k).0.hypot(w(k).1))
        .fold(0.0f64, f64::max);
    let mut unseen = Vec::new();
    let mut noise_gain = Vec::new();
    let mut part = vec![0.0; n];
    for k in 2..half {
        // DFT of the combination at harmonic k.
        let (mut re, mut im) = (0.0, 0.0);
        for (i, v) in m.iter().enumerate() {
            let t = 2.0 * std::f64::consts::PI * (k * i) as f64 / n as f64;
            re += v * t.cos();
            im -= v * t.sin();
        }
        let (wr, wi) = w(k);
        let mag = wr.hypot(wi);
        noise_gain.push([k as f64, if mag > 0.0 { 1.0 / mag } else { f64::INFINITY }]);
        if mag < 0.1 * wmax {
            unseen.push(k);
            continue;
        }
        // R(k) = M(k) / W(k).
        let d = wr * wr + wi * wi;
        let (rr, ri) = ((re * wr + im * wi) / d, (im * wr - re * wi) / d);
        for (i, p) in part.iter_mut().enumerate() {
            let t = 2.0 * std::f64::consts::PI * (k * i) as f64 / n as f64;
            *p += 2.0 / n as f64 * (rr * t.cos() - ri * t.sin());
        }
    }
    // Error motion: probe 1 sees r(θ) + x(θ); probe 2 at α sees
    // r(θ − α) + x cos α + y sin α (the part's profile passes probe 2 α
    // later).
    let shift = |theta_rad: f64, i: usize| -> f64 {
        let s =
            (i as f64 - theta_rad / (2.0 * std::f64::consts::PI) * n as f64).rem_euclid(n as f64);
        let (i0, f) = (s.floor() as usize % n, s - s.floor());
        part[i0] * (1.0 - f) + part[(i0 + 1) % n] * f
    };
    let x: Vec<f64> = (0..n).map(|i| readings[i][0] - part[i]).collect();
    let y: Vec<f64> = (0..n)
        .map(|i| {
            if al.sin().abs() > 1e-6 {
                (readings[i][1] - shift(al, i) - x[i] * al.cos()) / al.sin()
            } else {
                (readings[i][2] - shift(be, i) - x[i] * be.cos()) / be.sin()
            }
        })
        .collect();
    // Remove each motion's mean (the probes' zero).
    let centred = |v: Vec<f64>| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.into_iter().map(|x| x - m).collect::<Vec<_>>()
    };
    let (x, y) = (centred(x), centred(y));
    Ok(ThreeProbe {
        samples: n,
        part_pv_um: pv(&part),
        spindle_x_pv_um: pv(&x),
        part_um: part,
        spindle_x_um: x,
        spindle_y_um: y,
        unseen_harmonics: unseen,
        noise_gain,
    })
}

#[cfg(test)]
mod three_probe_tests {
    use super::*;

    fn readings(n: usize, angles: [f64; 3]) -> (Vec<[f64; 3]>, Vec<f64>) {
        let part =
            |t: f64| 2.0 * (3.0 * t).cos() + 1.0 * (7.0 * t + 0.4).sin() + 0.5 * (15.0 * t).cos();
        let sx = |t: f64| 1.2 * (t + 0.3).cos() + 0.4 * (4.0 * t).sin() + 0.2 * (9.0 * t).cos();
        let sy = |t: f64| 0.8 * (t).sin() + 0.3 * (5.0 * t + 1.0).cos();
        let r: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let t = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
                let probe = |a: f64| {
                    let a = a.to_radians();
                    part(t - a) + sx(t) * a.cos() + sy(t) * a.sin()
                };
                [probe(angles[0]), probe(angles[1]), probe(angles[2])]
            })
            .collect();
        let truth = (0..n)
            .map(|i| part(2.0 * std::f64::consts::PI * i as f64 / n as f64))
            .collect();
        (r, truth)
    }

    #[test]
    fn three_probes_separate_roundness_from_spindle_motion() {
        let angles = [0.0, 99.84, 202.5];
        let (r, truth) = readings(512, angles);
        let s = three_probe(&r, angles).unwrap();
        let worst = s
            .part_um
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        assert!(worst < 0.02, "{worst}, unseen {:?}", s.unseen_harmonics);
        assert!(!s
            .unseen_harmonics
            .iter()
            .any(|&k| k == 3 || k == 7 || k == 15));
        // The spindle's motion along probe 1, its mean removed.
        let sx: Vec<f64> = (0..512)
            .map(|i| {
                let t = 2.0 * std::f64::consts::PI * i as f64 / 512.0;
                1.2 * (t + 0.3).cos() + 0.4 * (4.0 * t).sin() + 0.2 * (9.0 * t).cos()
            })
            .collect();
        let m = sx.iter().sum::<f64>() / 512.0;
        let worst_x = s
            .spindle_x_um
            .iter()
            .zip(&sx)
            .map(|(a, b)| (a - (b - m)).abs())
            .fold(0.0f64, f64::max);
        assert!(worst_x < 0.05, "{worst_x}");
    }

    #[test]
    fn probes_at_0_90_180_cannot_see_odd_lobes_and_say_so() {
        let angles = [0.0, 90.0, 180.0];
        let (r, _) = readings(256, angles);
        let s = three_probe(&r, angles).unwrap();
        for k in [3, 5, 7, 15] {
            assert!(
                s.unseen_harmonics.contains(&k),
                "{k} not named: {:?}",
                s.unseen_harmonics
            );
        }
        assert!(!s.unseen_harmonics.contains(&4));
        assert!(three_probe(&r, [0.0, 180.0, 360.0]).is_err());
    }
}

/// The result of a multi-step roundness separation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MultiStep {
    /// Samples per turn.
    pub samples: usize,
    /// Number of steps (part positions on the spindle).
    pub steps: usize,
    /// The part's roundness at part angle `k·360/samples` degrees, µm
    /// (harmonics 2…samples/2 except the multiples of `steps`).
    pub part_um: Vec<f64>,
    /// The spindle's radial error motion along the probe at spindle angle
    /// `k·360/samples`, µm (harmonics 2…; it also holds the part's
    /// harmonics that are multiples of `steps`, which cannot be told apart).
    pub spindle_um: Vec<f64>,
    /// Peak to valley of the part's roundness, µm.
    pub part_pv_um: f64,
    /// Peak to valley of the spindle's motion, µm.
    pub spindle_pv_um: f64,
    /// The harmonics (multiples of `steps`, ≥ 2) the steps cannot separate.
    pub inseparable_harmonics: Vec<usize>,
    /// RMS of what neither the part nor the spindle explains, µm (reading
    /// noise and what changed between steps).
    pub residual_rms_um: f64,
    /// Standard uncertainty of each point of `part_um` and `spindle_um`
    /// from that residual, µm (σ/√steps).
    pub point_sigma_um: f64,
}

/// Removes harmonics 0 and 1 (size and centring) from one turn of
/// equally spaced samples.
fn without_h01(v: &[f64]) -> Vec<f64> {
    let n = v.len() as f64;
    let (mut c0, mut a1, mut b1) = (0.0, 0.0, 0.0);
    for (i, x) in v.iter().enumerate() {
        let t = 2.0 * std::f64::consts::PI * i as f64 / n;
        c0 += x / n;
        a1 += 2.0 * x * t.cos() / n;
        b1 += 2.0 * x * t.sin() / n;
    }
    v.iter()
        .enumerate()
        .map(|(i, x)| {
            let t = 2.0 * std::f64::consts::PI * i as f64 / n;
            x - c0 - a1 * t.cos() - b1 * t.sin()
        })
        .collect()
}

/// Separates a part's roundness from the spindle's radial error motion by
/// the multi-step method: one probe, the part mounted on the spindle at
/// `steps` equally spaced angular positions `φ_j = j·360°/steps` (turned
/// by `+φ_j` against the spindle), each read at the same `samples` equally
/// spaced spindle angles: `runs[j][i] = r(θ_i − φ_j) + s(θ_i)`. The mean over
/// the steps at one spindle angle keeps the spindle's motion `s` and, of
/// the part, only its harmonics that are multiples of `steps`; subtracting
/// it from each step and turning back gives the part without them. Those
/// harmonics cannot be separated by `steps` positions (they stay in the
/// spindle's profile) and are named. `samples` must be a multiple of
/// `steps` (each step a whole number of samples). Harmonics 0 and 1 (size,
/// centring — each remounting recentres the part) are removed per step.
pub fn multi_step(runs: &[Vec<f64>]) -> Result<MultiStep> {
    let steps = runs.len();
    if steps < 2 {
        bail!("{steps} step(s); multi-step separation needs the part at 2 or more positions on the spindle");
    }
    let n = runs[0].len();
    if n < 16 {
        bail!("{n} samples per turn; multi-step separation needs at least 16");
    }
    if let Some(j) = runs.iter().position(|r| r.len() != n) {
        bail!(
            "step {j} has {} samples per turn, step 0 has {n}: every step must be read at the same spindle angles",
            runs[j].len()
        );
    }
    if !n.is_multiple_of(steps) {
        bail!("{n} samples per turn is not a multiple of the {steps} steps: each step must turn the part by a whole number of samples ({} samples per step is not whole)", n as f64 / steps as f64);
    }
    let per = n / steps;
    let m: Vec<Vec<f64>> = runs.iter().map(|r| without_h01(r)).collect();
    let spindle: Vec<f64> = (0..n)
        .map(|i| m.iter().map(|r| r[i]).sum::<f64>() / steps as f64)
        .collect();
    // Part angle ψ_i is at spindle angle ψ_i + φ_j in step j.
    let part: Vec<f64> = (0..n)
        .map(|i| {
            (0..steps)
                .map(|j| {
                    let k = (i + j * per) % n;
                    m[j][k] - spindle[k]
                })
                .sum::<f64>()
                / steps as f64
        })
        .collect();
    let mut ss = 0.0;
    for (j, r) in m.iter().enumerate() {
        for (k, v) in r.iter().enumerate() {
            let psi = (k + n - j * per) % n;
            let e = v - spindle[k] - part[psi];
            ss += e * e;
        }
    }
    // Fitted: n spindle values + n part values, less the n/steps… shared
    // harmonics (counted once): about 2n − n/steps parameters of n·steps.
    let dof = (n * steps) as f64 - (2 * n - per) as f64;
    let residual_rms = (ss / (n * steps) as f64).sqrt();
    let sigma = if dof > 0.0 {
        (ss / dof).sqrt()
    } else {
        f64::NAN
    };
    let inseparable: Vec<usize> = (1..)
        .map(|k| k * steps)
        .take_while(|&k| k <= n / 2)
        .filter(|&k| k >= 2)
        .collect();
    Ok(MultiStep {
        samples: n,
        steps,
        part_pv_um: pv(&part),
        spindle_pv_um: pv(&spindle),
        part_um: part,
        spindle_um: spindle,
        inseparable_harmonics: inseparable,
        residual_rms_um: residual_rms,
        point_sigma_um: sigma / (steps as f64).sqrt(),
    })
}

#[cfg(test)]
mod multi_step_tests {
    use super::*;
    use std::f64::consts::PI;

    fn part(t: f64) -> f64 {
        2.0 * (3.0 * t).cos()
            + 1.0 * (5.0 * t + 0.4).sin()
            + 0.6 * (8.0 * t).cos()
            + 0.3 * (13.0 * t + 1.0).sin()
    }
    fn spindle(t: f64) -> f64 {
        0.8 * (2.0 * t + 0.2).cos() + 0.4 * (7.0 * t).sin() + 0.2 * (16.0 * t).cos()
    }

    fn runs(n: usize, steps: usize, noise: f64) -> Vec<Vec<f64>> {
        let mut rng = trueaxis_test_support::SplitMix64(5);
        (0..steps)
            .map(|j| {
                let phi = 2.0 * PI * j as f64 / steps as f64;
                // Each remounting shifts the centre (harmonic 1) and the
                // probe's zero.
                let (e, z) = (3.0 * j as f64, 0.5 * j as f64);
                (0..n)
                    .map(|i| {
                        let t = 2.0 * PI * i as f64 / n as f64;
                        part(t - phi)
                            + spindle(t)
                            + e * (t + 0.7 * j as f64).cos()
                            + z
                            + noise * rng.normal()
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_steps_separate_part_and_spindle_except_their_common_harmonics() {
        let (n, steps) = (360, 4);
        let s = multi_step(&runs(n, steps, 0.0)).unwrap();
        // With 4 steps, the part's 8th harmonic (a multiple of 4) goes to
        // the spindle, and is named.
        assert_eq!(s.inseparable_harmonics[..3], [4, 8, 12]);
        let mut worst_p = 0.0f64;
        let mut worst_s = 0.0f64;
        for i in 0..n {
            let t = 2.0 * PI * i as f64 / n as f64;
            let p_seen = part(t) - 0.6 * (8.0 * t).cos();
            let s_seen = spindle(t) + 0.6 * (8.0 * t).cos();
            worst_p = worst_p.max((s.part_um[i] - p_seen).abs());
            worst_s = worst_s.max((s.spindle_um[i] - s_seen).abs());
        }
        assert!(worst_p < 1e-9, "part off by {worst_p}");
        assert!(worst_s < 1e-9, "spindle off by {worst_s}");
        assert!(s.residual_rms_um < 1e-9);
        // With 5 steps the 8th harmonic is separated (the 5th is not).
        let s5 = multi_step(&runs(360, 5, 0.0)).unwrap();
        assert!(s5.inseparable_harmonics.contains(&5) && !s5.inseparable_harmonics.contains(&8));
        let worst5 = (0..360)
            .map(|i| {
                let t = 2.0 * PI * i as f64 / 360.0;
                (s5.part_um[i] - (part(t) - 1.0 * (5.0 * t + 0.4).sin())).abs()
            })
            .fold(0.0f64, f64::max);
        assert!(worst5 < 1e-9, "{worst5}");
    }

    #[test]
    fn reading_noise_gives_the_uncertainty_and_bad_layouts_are_refused() {
        let s = multi_step(&runs(360, 6, 0.05)).unwrap();
        assert!(
            (s.point_sigma_um - 0.05 / 6f64.sqrt()).abs() < 0.005,
            "{}",
            s.point_sigma_um
        );
        let e = multi_step(&runs(350, 4, 0.0)).unwrap_err().to_string();
        assert!(e.contains("not a multiple of the 4 steps"), "{e}");
        let mut r = runs(360, 3, 0.0);
        r[2].pop();
        assert!(multi_step(&r)
            .unwrap_err()
            .to_string()
            .contains("same spindle angles"));
        assert!(multi_step(&runs(360, 1, 0.0)).is_err());
    }
}
