//! Readings round a turn, resampled by angle (docs/on-machine.md § "Any
//! sampling"): one probe's readings at whatever spindle angles they were
//! taken — evenly spaced or not, one turn or many, any number per turn,
//! angles from an encoder, an index pulse or the spindle speed — become
//! the Fourier coefficients of the profile that repeats every turn (the
//! synchronous part, ISO 230-7), with what the angles cannot resolve
//! said, and what does not repeat (the asynchronous part) kept per reading.
//!
//! **Evenly spaced** angles (any count per turn, any start; readings at one
//! angle averaged over the turns) give the exact discrete Fourier
//! transform, harmonics 0 … ⌈n/2⌉ − 1 (the grid's Nyquist harmonic, which
//! has no phase on an even grid, is not used). **Uneven** angles (a time-
//! sampled log, jitter, gaps) are fitted by least squares up to the
//! harmonic the angles resolve: below the grid's and below 180° / (the
//! largest gap between the angles read), which is said when it cuts. The
//! normal equations are built from the sums `Σ cos dθ`, `Σ sin dθ`
//! (products of harmonics are harmonics), so a fit to many turns costs
//! `O(readings × harmonics + harmonics³)`.

use std::f64::consts::PI;

use anyhow::{bail, Result};
use nalgebra::{Complex, DMatrix, DVector};

/// One probe's readings in the order taken: spindle angle (degrees,
/// wrapped to a turn or counting on over several) and reading (µm).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Track {
    /// Spindle angle of each reading, degrees.
    pub angle_deg: Vec<f64>,
    /// The reading, µm.
    pub value_um: Vec<f64>,
}

/// The synchronous profile of a [`Track`]: `f(θ) = Re Σ_k F_k e^{ikθ}`.
#[derive(Clone, Debug, PartialEq)]
pub struct Spectrum {
    /// Samples per turn of the grid the profile is given on.
    pub samples: usize,
    /// The grid's first angle, degrees (the first angle read).
    pub offset_deg: f64,
    /// Whether the angles read were evenly spaced (an exact transform).
    pub even: bool,
    /// `F_0 … F_H` (`F_k = a_k − i b_k` for `a_k cos kθ + b_k sin kθ`), µm.
    pub coef: Vec<Complex<f64>>,
    /// The highest harmonic the grid holds (`⌈samples/2⌉ − 1`).
    pub grid_harmonics: usize,
    /// The largest gap between the angles read, degrees.
    pub largest_gap_deg: f64,
    /// Readings per grid angle (turns read, on average).
    pub turns: f64,
    /// Standard deviation of one reading about the synchronous profile
    /// (what does not repeat: noise and asynchronous motion), µm; `None`
    /// when the readings leave no degrees of freedom for it.
    pub reading_sigma_um: Option<f64>,
    /// Standard deviation of the synchronous profile at one grid angle, µm:
    /// the readings' over the turns averaged, or from second differences
    /// with one turn.
    pub point_sigma_um: Option<f64>,
    /// Each reading less the synchronous profile at its angle, µm.
    pub asynchronous_um: Vec<f64>,
    /// Each reading's angle, radians, wrapped to a turn.
    pub theta_rad: Vec<f64>,
}

impl Spectrum {
    /// The highest harmonic resolved.
    pub fn harmonics(&self) -> usize {
        self.coef.len() - 1
    }

    /// The grid's angles, radians.
    pub fn grid_rad(&self) -> Vec<f64> {
        let o = self.offset_deg.to_radians();
        (0..self.samples)
            .map(|i| o + 2.0 * PI * i as f64 / self.samples as f64)
            .collect()
    }

    /// Harmonics `keep(k)` of `coef` at angle `theta` (rad).
    pub fn synthesis(coef: &[Complex<f64>], theta: f64, keep: impl Fn(usize) -> bool) -> f64 {
        coef.iter()
            .enumerate()
            .filter(|(k, _)| keep(*k))
            .map(|(k, c)| (c * Complex::from_polar(1.0, k as f64 * theta)).re)
            .sum()
    }

    /// What the angles cannot resolve, said; `None` when nothing is lost.
    pub fn lost(&self) -> Option<String> {
        (self.harmonics() < self.grid_harmonics).then(|| {
            format!(
                "the angles read leave a gap of {:.3}°: harmonics above {} of the {} a turn of {} samples holds are not resolved",
                self.largest_gap_deg,
                self.harmonics(),
                self.grid_harmonics,
                self.samples
            )
        })
    }
}

/// Angle differences below this are one angle read again, degrees.
const SAME_DEG: f64 = 1e-4;

/// The synchronous profile of `track`: its angles wrapped to a turn, the
/// grid of `samples` per turn (`None`: the count the readings give — the
/// distinct angles, or the readings per turn of a time-sampled log).
pub fn spectrum(track: &Track, samples: Option<usize>) -> Result<Spectrum> {
    let m = track.angle_deg.len();
    if m != track.value_um.len() {
        bail!("{m} angles for {} readings", track.value_um.len());
    }
    if m < 16 {
        bail!("{m} readings; a turn needs at least 16");
    }
    let wrapped: Vec<f64> = track
        .angle_deg
        .iter()
        .map(|a| a.rem_euclid(360.0))
        .collect();
    // Distinct angles (a reading within SAME_DEG of another is the same
    // angle read again, in another turn).
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| wrapped[a].total_cmp(&wrapped[b]));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for &i in &order {
        match groups.last_mut() {
            Some(g) if wrapped[i] - wrapped[g[0]] < SAME_DEG => g.push(i),
            _ => groups.push(vec![i]),
        }
    }
    if groups.len() > 1
        && wrapped[groups[0][0]] + 360.0 - wrapped[groups[groups.len() - 1][0]] < SAME_DEG
    {
        let last = groups.pop().expect("more than one");
        groups[0].extend(last);
    }
    let mean = |g: &[usize], v: &[f64]| g.iter().map(|&i| v[i]).sum::<f64>() / g.len() as f64;
    let at: Vec<f64> = groups.iter().map(|g| mean(g, &wrapped)).collect();
    let n_distinct = groups.len();
    let mut largest_gap = at[0] + 360.0 - at[n_distinct - 1];
    for w in at.windows(2) {
        largest_gap = largest_gap.max(w[1] - w[0]);
    }
    // The turns read: from the angles counted on (or unwrapped in the
    // order taken) when they pass a turn, else the repeats per angle.
    let mut unwrapped = Vec::with_capacity(m);
    for (i, &a) in track.angle_deg.iter().enumerate() {
        unwrapped.push(match i {
            0 => a,
            _ => {
                let prev: f64 = unwrapped[i - 1];
                let d = (a - prev).rem_euclid(360.0);
                prev + if d > 180.0 { d - 360.0 } else { d }
            }
        });
    }
    let span = unwrapped.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - unwrapped.iter().copied().fold(f64::INFINITY, f64::min);
    let per_turn = if span > 360.0 && (m as f64) < 1.5 * n_distinct as f64 {
        // Nearly every reading at an angle of its own over several turns: a
        // log sampled in time (the readings over the turns they span).
        (m as f64 * 360.0 / (span * m as f64 / (m - 1) as f64)).round() as usize
    } else {
        n_distinct
    };
    let n = samples.unwrap_or(per_turn);
    if n < 16 {
        bail!("{n} samples per turn; a separation needs at least 16");
    }
    let step = 360.0 / n as f64;
    let offset = at[0];
    let even = n_distinct == n
        && at
            .iter()
            .enumerate()
            .all(|(k, a)| (a - offset - k as f64 * step).abs() < 0.02 * step);
    let grid_h = (n - 1) / 2;
    let (coef, fitted) = if even {
        // The exact transform of the turn-averaged readings on the grid.
        let v: Vec<f64> = groups.iter().map(|g| mean(g, &track.value_um)).collect();
        let coef: Vec<Complex<f64>> = (0..=grid_h)
            .map(|k| {
                let s: Complex<f64> = v
                    .iter()
                    .enumerate()
                    .map(|(j, x)| {
                        let t = (offset + j as f64 * step).to_radians();
                        Complex::from_polar(*x, -(k as f64) * t)
                    })
                    .sum();
                s * if k == 0 { 1.0 } else { 2.0 } / n as f64
            })
            .collect();
        let mut fitted = vec![0.0; m];
        for (g, x) in groups.iter().zip(&v) {
            for &i in g {
                fitted[i] = *x;
            }
        }
        (coef, fitted)
    } else {
        let h = grid_h.min((180.0 / largest_gap).floor() as usize);
        if h < 2 {
            bail!(
                "the angles read leave a gap of {largest_gap:.1}° in the turn: no harmonic above 1 (the centring) can be resolved"
            );
        }
        let theta: Vec<f64> = wrapped.iter().map(|a| a.to_radians()).collect();
        let coef = least_squares(&theta, &track.value_um, h)?;
        let fitted = theta
            .iter()
            .map(|&t| Spectrum::synthesis(&coef, t, |_| true))
            .collect();
        (coef, fitted)
    };
    let asynchronous: Vec<f64> = track
        .value_um
        .iter()
        .zip(&fitted)
        .map(|(v, f)| v - f)
        .collect();
    let params = if even { n } else { 2 * coef.len() - 1 };
    let dof = m.saturating_sub(params);
    let ss: f64 = asynchronous.iter().map(|e| e * e).sum();
    let reading_sigma = (dof >= 8.max(params / 4)).then(|| (ss / dof as f64).sqrt());
    let point_sigma = match reading_sigma {
        Some(s) => Some(s * (params as f64 / m as f64).sqrt()),
        None => {
            let mut v: Vec<(f64, f64)> = wrapped
                .iter()
                .copied()
                .zip(track.value_um.iter().copied())
                .collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            super::noise(&v.iter().map(|p| p.1).collect::<Vec<_>>())
        }
    };
    Ok(Spectrum {
        samples: n,
        offset_deg: offset,
        even,
        coef,
        grid_harmonics: grid_h,
        largest_gap_deg: largest_gap,
        turns: m as f64 / n as f64,
        reading_sigma_um: reading_sigma,
        point_sigma_um: point_sigma,
        asynchronous_um: asynchronous,
        theta_rad: wrapped.iter().map(|a| a.to_radians()).collect(),
    })
}

/// Least-squares Fourier coefficients `F_0 … F_h` of readings `y` at angles
/// `theta` (rad). The normal equations' entries are sums of harmonics of
/// the angles: `cos jθ cos lθ = ½ [cos (j−l)θ + cos (j+l)θ]` and so on,
/// so `Σ cos dθ`, `Σ sin dθ` for `d ≤ 2h` build them.
fn least_squares(theta: &[f64], y: &[f64], h: usize) -> Result<Vec<Complex<f64>>> {
    let mut c = vec![0.0; 2 * h + 1];
    let mut s = vec![0.0; 2 * h + 1];
    let mut rhs = vec![Complex::new(0.0, 0.0); h + 1];
    for (&t, &v) in theta.iter().zip(y) {
        let z = Complex::from_polar(1.0, t);
        let mut w = Complex::new(1.0, 0.0);
        for d in 0..=2 * h {
            c[d] += w.re;
            s[d] += w.im;
            if d <= h {
                rhs[d] += w * v;
            }
            w *= z;
        }
    }
    // Unknowns: a_0, then a_k, b_k for k = 1…h (cos, sin).
    let p = 2 * h + 1;
    let col = |j: usize| -> (usize, bool) {
        if j == 0 {
            (0, true)
        } else {
            (j.div_ceil(2), j % 2 == 1)
        }
    };
    let cc = |d: i64| c[d.unsigned_abs() as usize];
    let ss = |d: i64| s[d.unsigned_abs() as usize] * d.signum() as f64;
    let g = DMatrix::from_fn(p, p, |r, q| {
        let ((j, cj), (l, cl)) = (col(r), col(q));
        let (j, l) = (j as i64, l as i64);
        match (cj, cl) {
            (true, true) => 0.5 * (cc(j - l) + cc(j + l)),
            (false, false) => 0.5 * (cc(j - l) - cc(j + l)),
            (true, false) => 0.5 * (ss(j + l) - ss(j - l)),
            (false, true) => 0.5 * (ss(j + l) + ss(j - l)),
        }
    });
    let b = DVector::from_fn(p, |r, _| {
        let (k, cos) = col(r);
        if cos {
            rhs[k].re
        } else {
            rhs[k].im
        }
    });
    let Some(chol) = g.clone().cholesky() else {
        bail!("the angles read cannot resolve harmonics up to {h} (the fit is singular)");
    };
    let diag = chol.l_dirty().diagonal();
    let (lo, hi) = diag.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &v| {
        (a.min(v.abs()), b.max(v.abs()))
    });
    if lo < 1e-6 * hi {
        bail!("the angles read cannot resolve harmonics up to {h} (the fit is ill-conditioned)");
    }
    let x = chol.solve(&b);
    Ok((0..=h)
        .map(|k| {
            if k == 0 {
                Complex::new(x[0], 0.0)
            } else {
                Complex::new(x[2 * k - 1], -x[2 * k])
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_test_support::SplitMix64;

    fn profile(t: f64) -> f64 {
        0.3 + 1.2 * (t + 0.4).cos()
            + 2.0 * (3.0 * t).cos()
            + 0.7 * (7.0 * t + 1.1).sin()
            + 0.2 * (40.0 * t).cos()
    }

    fn coef_err(s: &Spectrum) -> f64 {
        (0..=s.harmonics().min(60))
            .map(|k| {
                let t: Vec<f64> = (0..720).map(|i| 2.0 * PI * i as f64 / 720.0).collect();
                let want: f64 = t
                    .iter()
                    .map(|&x| profile(x) * (k as f64 * x).cos())
                    .sum::<f64>()
                    * if k == 0 { 1.0 } else { 2.0 }
                    / 720.0;
                (s.coef[k].re - want).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn even_angles_of_any_count_give_the_exact_transform() {
        for n in [360usize, 512, 1024, 250] {
            // Three turns, the angles counting on, starting off zero.
            let a: Vec<f64> = (0..3 * n)
                .map(|i| 12.5 + 360.0 * i as f64 / n as f64)
                .collect();
            let track = Track {
                value_um: a.iter().map(|d| profile(d.to_radians())).collect(),
                angle_deg: a,
            };
            let s = spectrum(&track, None).unwrap();
            assert!(s.even && s.samples == n, "{n}: {} {}", s.even, s.samples);
            assert_eq!(s.harmonics(), (n - 1) / 2);
            assert!(coef_err(&s) < 1e-9, "{n}: {}", coef_err(&s));
            assert!((s.turns - 3.0).abs() < 1e-12 && s.lost().is_none());
        }
    }

    #[test]
    fn a_time_sampled_log_and_uneven_angles_are_fitted_by_angle() {
        // 7.3 turns at 400.37 samples a turn with the speed wandering 1 %,
        // 5 nm noise: every reading at its own angle.
        let mut rng = SplitMix64(3);
        let mut ang = 0.0;
        let (mut a, mut v) = (Vec::new(), Vec::new());
        for i in 0..2923 {
            ang += 360.0 / 400.37 * (1.0 + 0.01 * (i as f64 / 300.0).sin());
            a.push(ang);
            v.push(profile(ang.to_radians()) + 0.005 * rng.normal());
        }
        let s = spectrum(
            &Track {
                angle_deg: a,
                value_um: v,
            },
            None,
        )
        .unwrap();
        assert!(!s.even);
        assert!((395..=405).contains(&s.samples), "{}", s.samples);
        assert!(coef_err(&s) < 0.003, "{}", coef_err(&s));
        let sig = s.reading_sigma_um.unwrap();
        assert!((sig - 0.005).abs() < 0.001, "{sig}");
        // One turn with a 21° gap: harmonics above 8 are not resolved, said.
        let a: Vec<f64> = (0..340).map(|i| i as f64).collect();
        let track = Track {
            value_um: a
                .iter()
                .map(|d| profile(d.to_radians()) - 0.2 * (40.0 * d.to_radians()).cos())
                .collect(),
            angle_deg: a,
        };
        let s = spectrum(&track, Some(360)).unwrap();
        assert!(!s.even && s.harmonics() == 8, "{}", s.harmonics());
        assert!(s.lost().unwrap().contains("above 8"), "{:?}", s.lost());
        assert!((s.coef[3].re - 2.0).abs() < 1e-6, "{}", s.coef[3]);
    }
}
