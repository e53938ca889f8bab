//! A part's roundness and the spindle's radial error motion, separated
//! (docs/on-machine.md § three-probe, § multi-step, § "Error motion").
//!
//! Both methods work harmonic by harmonic on the readings resampled by
//! angle ([`super::turn`]), so any number of samples per turn, any number of
//! steps, uneven angles and time-sampled logs give the same answer.
//!
//! **Error motion (ISO 230-7, fixed sensitive direction)**, the same
//! definition from both methods: the spindle's radial motion along the
//! sensitive direction (probe 1, or the one probe of the multi-step) as a
//! function of its angle. The *synchronous* error motion is the part that
//! repeats every turn (the turn average); its value is the peak to valley
//! about the least-squares centre — harmonics 0 (the probe's zero) and 1
//! left out. Harmonic 1 is the once-per-turn term: the artefact's centring
//! on the spindle, which no measurement tells from a once-per-turn motion
//! of the spindle; it is reported as `centring_um`, not error motion. The
//! *asynchronous* error motion is what does not repeat: its value the
//! largest spread of the readings about the synchronous profile at one
//! angle over the turns read (reading noise is in it). The *total* error
//! motion's value is the peak to valley of every reading's motion
//! (synchronous + asynchronous), centring left out. Harmonics a method
//! cannot tell from the part's (a three-probe spacing's blind spots, a
//! multi-step's multiples of the step count) are in neither the part nor
//! the error motion: their sum is given as a sum (`excluded_pv_um`) and
//! named.

use anyhow::{bail, Result};
use nalgebra::Complex;
use serde::Serialize;

use super::turn::{spectrum, Spectrum, Track};
use super::{pv, z_all};

/// The error motion of a spindle along one sensitive direction, ISO 230-7
/// (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ErrorMotion {
    /// Synchronous error motion value, µm: peak to valley of the turn
    /// average, harmonics 0 and 1 and `excluded_harmonics` left out.
    pub synchronous_um: f64,
    /// Its 95 % interval `[lo, hi]`, µm (every point's bound at once:
    /// ± 2·z_n·σ).
    pub synchronous_ci95_um: [f64; 2],
    /// Asynchronous error motion value, µm: the largest spread about the
    /// synchronous profile at one angle over the turns; `None` with one
    /// turn.
    pub asynchronous_um: Option<f64>,
    /// Total error motion value, µm: peak to valley of every reading's
    /// motion, centring left out.
    pub total_um: f64,
    /// Amplitude of the once-per-turn term left out (centring), µm.
    pub centring_um: f64,
    /// Harmonics this method cannot tell from the part's.
    pub excluded_harmonics: Vec<usize>,
    /// Peak to valley of part + spindle together at those harmonics, µm.
    pub excluded_pv_um: f64,
    /// Standard uncertainty of one point of the synchronous profile, µm.
    pub point_sigma_um: f64,
    /// Turns read (readings per angle, on average).
    pub turns: f64,
}

/// The largest spread of `e` (a reading less the synchronous profile at
/// its angle) among the readings in one of `n` sectors of the turn (grid
/// offset `offset` rad); `None` when no sector holds two readings.
fn asynchronous_value(theta: &[f64], e: &[f64], n: usize, offset: f64) -> Option<f64> {
    let mut lo = vec![f64::INFINITY; n];
    let mut hi = vec![f64::NEG_INFINITY; n];
    let mut count = vec![0usize; n];
    let step = 2.0 * std::f64::consts::PI / n as f64;
    for (t, v) in theta.iter().zip(e) {
        let k = (((t - offset) / step).round() as i64).rem_euclid(n as i64) as usize;
        lo[k] = lo[k].min(*v);
        hi[k] = hi[k].max(*v);
        count[k] += 1;
    }
    (0..n)
        .filter(|&k| count[k] >= 2)
        .map(|k| hi[k] - lo[k])
        .reduce(f64::max)
}

/// The synchronous profile's value from the separated spectrum `sync`
/// (harmonics `keep`), and the error motion of readings whose asynchronous
/// parts are `tracks` (each: angles and residuals).
#[allow(clippy::too_many_arguments)]
fn error_motion(
    sync: &[Complex<f64>],
    keep: impl Fn(usize) -> bool + Copy,
    grid: &[f64],
    centring: Complex<f64>,
    excluded: Vec<usize>,
    excluded_pv: f64,
    point_sigma: f64,
    tracks: &[&Spectrum],
) -> ErrorMotion {
    let n = grid.len();
    let profile: Vec<f64> = grid
        .iter()
        .map(|&t| Spectrum::synthesis(sync, t, keep))
        .collect();
    let value = pv(&profile);
    let half = 2.0 * z_all(n) * point_sigma;
    let mut total = Vec::new();
    let mut asynchronous: Option<f64> = None;
    for s in tracks {
        for (t, e) in s.theta_rad.iter().zip(&s.asynchronous_um) {
            total.push(Spectrum::synthesis(sync, *t, keep) + e);
        }
        let a = asynchronous_value(&s.theta_rad, &s.asynchronous_um, n, grid[0]);
        asynchronous = match (asynchronous, a) {
            (Some(x), Some(y)) => Some(x.max(y)),
            (x, y) => x.or(y),
        };
    }
    ErrorMotion {
        synchronous_um: value,
        synchronous_ci95_um: [(value - half).max(0.0), value + half],
        asynchronous_um: asynchronous,
        total_um: pv(&total),
        centring_um: centring.norm(),
        excluded_harmonics: excluded,
        excluded_pv_um: excluded_pv,
        point_sigma_um: point_sigma,
        turns: tracks.iter().map(|s| s.turns).sum::<f64>() / tracks.len().max(1) as f64,
    }
}

/// Profile of harmonics `keep` of `coef` on `grid`.
fn on_grid(coef: &[Complex<f64>], grid: &[f64], keep: impl Fn(usize) -> bool + Copy) -> Vec<f64> {
    grid.iter()
        .map(|&t| Spectrum::synthesis(coef, t, keep))
        .collect()
}

/// The result of a three-probe roundness separation.
#[derive(Clone, Debug, Serialize)]
pub struct ThreeProbe {
    /// Samples per turn.
    pub samples: usize,
    /// The grid's angles, degrees.
    pub angle_deg: Vec<f64>,
    /// The part's roundness profile on the grid, µm (harmonics 2… that
    /// the probes see).
    pub part_um: Vec<f64>,
    /// The spindle's synchronous radial error motion along probe 1, µm
    /// (harmonics 2… that the probes see; centring left out).
    pub spindle_x_um: Vec<f64>,
    /// …and perpendicular to it (toward +90°), µm.
    pub spindle_y_um: Vec<f64>,
    /// Probe 1's reading at the harmonics the probes cannot see: part and
    /// spindle together, µm.
    pub unseen_um: Vec<f64>,
    /// Peak to valley of the part's roundness, µm.
    pub part_pv_um: f64,
    /// Its 95 % interval, µm.
    pub part_ci95_um: [f64; 2],
    /// Synchronous error motion value along probe 1, µm
    /// (`error_motion.synchronous_um`).
    pub spindle_x_pv_um: f64,
    /// Harmonics the probe angles cannot see (|W(k)| below 10 % of its
    /// largest): left out of the part and the error motion, named.
    pub unseen_harmonics: Vec<usize>,
    /// Per harmonic 2… the factor by which reading noise is amplified in
    /// the part's profile (1/|W(k)|).
    pub noise_gain: Vec<[f64; 2]>,
    /// The error motion along probe 1 (the sensitive direction).
    pub error_motion: ErrorMotion,
    /// What the angles read cannot resolve, per probe that loses some.
    pub lost: Vec<String>,
}

/// Separates a part's roundness from the spindle's radial error motion
/// with three probes at `angles_deg` (the first the reference and
/// sensitive direction), each probe's readings a [`Track`] of its own
/// (the same angles or not). The combination `m1 + a m2 + b m3` with
/// `1 + a cos α + b cos β = 0` and `a sin α + b sin β = 0` cancels the
/// error motion; the part's harmonic k is the combination's divided by
/// `W(k) = 1 + a e^{−ikα} + b e^{−ikβ}`. Where `|W(k)|` is below 10 % of its
/// largest the probes cannot see harmonic k: it is left out of the part
/// and of the error motion, named, and probe 1's reading there (part and
/// spindle together) given as `unseen_um`.
///
/// `upr`: the highest harmonic kept (undulations per revolution, a
/// roundness instrument's filter); `None` keeps all the angles resolve.
pub fn three_probe(
    tracks: &[Track; 3],
    angles_deg: [f64; 3],
    upr: Option<usize>,
) -> Result<ThreeProbe> {
    let (al, be) = (
        (angles_deg[1] - angles_deg[0]).to_radians(),
        (angles_deg[2] - angles_deg[0]).to_radians(),
    );
    let det = al.cos() * be.sin() - be.cos() * al.sin();
    if det.abs() < 1e-6 {
        bail!("the probe angles {angles_deg:?} are collinear (0° and 180° apart): they cannot separate the spindle's motion");
    }
    let s1 = spectrum(&tracks[0], None).map_err(|e| anyhow::anyhow!("probe 1: {e}"))?;
    let n = s1.samples;
    let s2 = spectrum(&tracks[1], Some(n)).map_err(|e| anyhow::anyhow!("probe 2: {e}"))?;
    let s3 = spectrum(&tracks[2], Some(n)).map_err(|e| anyhow::anyhow!("probe 3: {e}"))?;
    let spectra = [&s1, &s2, &s3];
    let h = spectra
        .iter()
        .map(|s| s.harmonics())
        .min()
        .unwrap_or(0)
        .min(upr.unwrap_or(usize::MAX));
    if h < 2 {
        bail!("no harmonic from 2 up is kept (upr {h})");
    }
    let lost: Vec<String> = spectra
        .iter()
        .enumerate()
        .filter_map(|(p, s)| s.lost().map(|l| format!("probe {}: {l}", p + 1)))
        .collect();
    // Solve 1 + a cos α + b cos β = 0, a sin α + b sin β = 0.
    let a = -be.sin() / det;
    let b = al.sin() / det;
    let w = |k: usize| -> Complex<f64> {
        let kf = k as f64;
        Complex::new(1.0, 0.0)
            + a * Complex::from_polar(1.0, -kf * al)
            + b * Complex::from_polar(1.0, -kf * be)
    };
    let wmax = (2..=h).map(|k| w(k).norm()).fold(0.0f64, f64::max);
    let zero = Complex::new(0.0, 0.0);
    let mut part = vec![zero; h + 1];
    let mut x = vec![zero; h + 1];
    let mut y = vec![zero; h + 1];
    let mut unseen_c = vec![zero; h + 1];
    let mut unseen = Vec::new();
    let mut noise_gain = Vec::new();
    // Noise: each probe's turn-averaged reading σ; the per-point variance
    // of a profile is Σ_k (2/n) Σ_p σ_p² |c_p(k)|² over the harmonics kept.
    let sig: Vec<f64> = spectra
        .iter()
        .map(|s| s.point_sigma_um.unwrap_or(0.0))
        .collect();
    let (mut var_x, mut var_r) = (0.0, 0.0);
    for k in 2..=h {
        let wk = w(k);
        let mag = wk.norm();
        noise_gain.push([k as f64, if mag > 0.0 { 1.0 / mag } else { f64::INFINITY }]);
        let m1 = s1.coef[k];
        if mag < 0.1 * wmax {
            unseen.push(k);
            unseen_c[k] = m1;
            continue;
        }
        let kf = k as f64;
        let (e_a, e_b) = (
            Complex::from_polar(1.0, -kf * al),
            Complex::from_polar(1.0, -kf * be),
        );
        let r = (m1 + a * s2.coef[k] + b * s3.coef[k]) / wk;
        part[k] = r;
        x[k] = m1 - r;
        // Probe 2 at α sees r(θ − α) + x cos α + y sin α.
        y[k] = if al.sin().abs() > 1e-6 {
            (s2.coef[k] - r * e_a - x[k] * al.cos()) / al.sin()
        } else {
            (s3.coef[k] - r * e_b - x[k] * be.cos()) / be.sin()
        };
        let c1 = Complex::new(1.0, 0.0) - Complex::new(1.0, 0.0) / wk;
        var_x += sig[0].powi(2) * c1.norm_sqr()
            + (sig[1] * a).powi(2) / wk.norm_sqr()
            + (sig[2] * b).powi(2) / wk.norm_sqr();
        var_r += (sig[0].powi(2) + (sig[1] * a).powi(2) + (sig[2] * b).powi(2)) / wk.norm_sqr();
    }
    let grid = s1.grid_rad();
    let all = |_: usize| true;
    let part_um = on_grid(&part, &grid, all);
    let unseen_um = on_grid(&unseen_c, &grid, all);
    let point_sigma = (2.0 * var_x / n as f64).sqrt();
    let em = error_motion(
        &x,
        all,
        &grid,
        s1.coef[1],
        unseen.clone(),
        pv(&unseen_um),
        point_sigma,
        &[&s1],
    );
    let part_pv = pv(&part_um);
    let part_half = 2.0 * z_all(n) * (2.0 * var_r / n as f64).sqrt();
    Ok(ThreeProbe {
        samples: n,
        angle_deg: grid.iter().map(|t| t.to_degrees()).collect(),
        part_pv_um: part_pv,
        part_ci95_um: [(part_pv - part_half).max(0.0), part_pv + part_half],
        spindle_x_pv_um: em.synchronous_um,
        part_um,
        spindle_x_um: on_grid(&x, &grid, all),
        spindle_y_um: on_grid(&y, &grid, all),
        unseen_um,
        unseen_harmonics: unseen,
        noise_gain,
        error_motion: em,
        lost,
    })
}

/// One step of a multi-step set: the part's angular position on the
/// spindle (turned by `+step_deg` against it) and the probe's readings.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The part's position on the spindle, degrees.
    pub step_deg: f64,
    /// The readings at their spindle angles.
    pub track: Track,
}

/// The result of a multi-step roundness separation.
#[derive(Clone, Debug, Serialize)]
pub struct MultiStep {
    /// Samples per turn.
    pub samples: usize,
    /// Number of steps (part positions on the spindle).
    pub steps: usize,
    /// The grid's angles, degrees (spindle angle; for the part, its angle
    /// where it passes the probe in the first step).
    pub angle_deg: Vec<f64>,
    /// The part's roundness on the grid, µm (harmonics 2… the steps
    /// separate).
    pub part_um: Vec<f64>,
    /// The spindle's synchronous radial error motion along the probe, µm
    /// (harmonics 2… the steps separate; centring left out).
    pub spindle_um: Vec<f64>,
    /// Part and spindle together at the harmonics the steps cannot
    /// separate (in the spindle's frame), µm.
    pub inseparable_um: Vec<f64>,
    /// Peak to valley of the part's roundness, µm.
    pub part_pv_um: f64,
    /// Its 95 % interval, µm.
    pub part_ci95_um: [f64; 2],
    /// Synchronous error motion value, µm (`error_motion.synchronous_um`).
    pub spindle_pv_um: f64,
    /// The harmonics (≥ 2) the steps cannot separate: every step sees
    /// them at the same phase (with N equal steps the multiples of N).
    pub inseparable_harmonics: Vec<usize>,
    /// RMS of what neither the part nor the spindle explains, µm (reading
    /// noise and what changed between steps).
    pub residual_rms_um: f64,
    /// Standard uncertainty of each point of `spindle_um`, µm.
    pub point_sigma_um: f64,
    /// The error motion along the probe.
    pub error_motion: ErrorMotion,
    /// What the angles read cannot resolve, per step that loses some.
    pub lost: Vec<String>,
}

/// Separates a part's roundness from the spindle's radial error motion by
/// the multi-step method: one probe, the part mounted on the spindle at
/// positions `φ_j` (any number ≥ 2, equally spaced or not), each read over
/// whole turns at any spindle angles: `m_j(θ) = r(θ − φ_j) + s(θ)`. Per
/// harmonic k ≥ 2 the step readings `M_j(k) = R(k) e^{−ikφ_j} + S(k)` are
/// solved for `R` and `S` by least squares; where every step sees harmonic
/// k at nearly the same phase (`|Σ e^{−ikφ_j}|² > 0.99 N²`: with N equal
/// steps the multiples of N) they cannot be told apart — named, left out of
/// both, their sum given. Harmonics 0 and 1 (size, centring — each
/// remounting recentres the part) are left out per step. `upr` as for
/// [`three_probe`].
pub fn multi_step(steps: &[Step], upr: Option<usize>) -> Result<MultiStep> {
    let nst = steps.len();
    if nst < 2 {
        bail!("{nst} step(s); multi-step separation needs the part at 2 or more positions on the spindle");
    }
    let s0 = spectrum(&steps[0].track, None)
        .map_err(|e| anyhow::anyhow!("step {}°: {e}", steps[0].step_deg))?;
    let n = s0.samples;
    let mut spectra = vec![s0];
    for st in &steps[1..] {
        spectra.push(
            spectrum(&st.track, Some(n))
                .map_err(|e| anyhow::anyhow!("step {}°: {e}", st.step_deg))?,
        );
    }
    let h = spectra
        .iter()
        .map(|s| s.harmonics())
        .min()
        .unwrap_or(0)
        .min(upr.unwrap_or(usize::MAX));
    if h < 2 {
        bail!("no harmonic from 2 up is kept (upr {h})");
    }
    let lost: Vec<String> = steps
        .iter()
        .zip(&spectra)
        .filter_map(|(st, s)| s.lost().map(|l| format!("step {}°: {l}", st.step_deg)))
        .collect();
    let phi: Vec<f64> = steps
        .iter()
        .map(|s| (s.step_deg - steps[0].step_deg).to_radians())
        .collect();
    let zero = Complex::new(0.0, 0.0);
    let (mut part, mut spin, mut both) = (vec![zero; h + 1], vec![zero; h + 1], vec![zero; h + 1]);
    let mut inseparable = Vec::new();
    let (mut ss, mut dof) = (0.0, 0usize);
    let (mut gain_s, mut gain_r) = (0.0, 0.0);
    let nf = nst as f64;
    for k in 2..=h {
        let u: Vec<Complex<f64>> = phi
            .iter()
            .map(|p| Complex::from_polar(1.0, -(k as f64) * p))
            .collect();
        let m: Vec<Complex<f64>> = spectra.iter().map(|s| s.coef[k]).collect();
        let su: Complex<f64> = u.iter().sum();
        let sm: Complex<f64> = m.iter().sum();
        let det = nf * nf - su.norm_sqr();
        if det < 0.01 * nf * nf {
            // Every step sees it at the same phase: one sum.
            inseparable.push(k);
            both[k] = sm / nf;
            ss += m.iter().map(|v| (v - both[k]).norm_sqr()).sum::<f64>();
            dof += nst - 1;
            continue;
        }
        let sum: Complex<f64> = u.iter().zip(&m).map(|(a, b)| a.conj() * b).sum();
        let r = (nf * sum - su.conj() * sm) / det;
        let s = (nf * sm - su * sum) / det;
        part[k] = r;
        spin[k] = s;
        ss += u
            .iter()
            .zip(&m)
            .map(|(a, b)| (b - r * a - s).norm_sqr())
            .sum::<f64>();
        dof += nst - 2;
        gain_s += nf / det;
        gain_r += nf / det;
    }
    // σ of one turn-averaged reading from what neither profile explains
    // (a coefficient of white noise σ on n points has E|M|² = 4σ²/n).
    let sigma_m = if dof > 0 {
        (n as f64 / 4.0 * ss / dof as f64).sqrt()
    } else {
        spectra
            .iter()
            .filter_map(|s| s.point_sigma_um)
            .fold(0.0, f64::max)
    };
    let residual_rms = (ss / (2.0 * nf)).sqrt();
    let point_sigma = sigma_m * (2.0 * gain_s / n as f64).sqrt();
    let grid = spectra[0].grid_rad();
    let all = |_: usize| true;
    let part_um = on_grid(&part, &grid, all);
    let inseparable_um = on_grid(&both, &grid, all);
    let refs: Vec<&Spectrum> = spectra.iter().collect();
    let em = error_motion(
        &spin,
        all,
        &grid,
        spectra[0].coef[1],
        inseparable.clone(),
        pv(&inseparable_um),
        point_sigma,
        &refs,
    );
    let part_pv = pv(&part_um);
    let part_half = 2.0 * z_all(n) * sigma_m * (2.0 * gain_r / n as f64).sqrt();
    Ok(MultiStep {
        samples: n,
        steps: nst,
        angle_deg: grid.iter().map(|t| t.to_degrees()).collect(),
        part_pv_um: part_pv,
        part_ci95_um: [(part_pv - part_half).max(0.0), part_pv + part_half],
        spindle_pv_um: em.synchronous_um,
        part_um,
        spindle_um: on_grid(&spin, &grid, all),
        inseparable_um,
        inseparable_harmonics: inseparable,
        residual_rms_um: residual_rms,
        point_sigma_um: point_sigma,
        error_motion: em,
        lost,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;
    use trueaxis_test_support::SplitMix64;

    fn part(t: f64) -> f64 {
        2.0 * (3.0 * t).cos()
            + 1.0 * (5.0 * t + 0.4).sin()
            + 0.6 * (8.0 * t).cos()
            + 0.3 * (13.0 * t + 1.0).sin()
    }
    /// Spindle motion along x (probe 1) and y.
    fn sx(t: f64) -> f64 {
        0.8 * (2.0 * t + 0.2).cos() + 0.4 * (7.0 * t).sin() + 0.2 * (16.0 * t).cos()
    }
    fn sy(t: f64) -> f64 {
        0.5 * (2.0 * t).sin() + 0.3 * (4.0 * t + 1.0).cos()
    }

    /// PV of the profile `f` (harmonics 2… `keep`) on a fine grid.
    fn pv_of(f: impl Fn(f64) -> f64) -> f64 {
        pv(&(0..3600)
            .map(|i| f(2.0 * PI * i as f64 / 3600.0))
            .collect::<Vec<_>>())
    }

    fn three(n: usize, turns: usize, angles: [f64; 3], noise: f64, seed: u64) -> [Track; 3] {
        let mut rng = SplitMix64(seed);
        let mut tr: [Track; 3] = Default::default();
        for i in 0..n * turns {
            let c = 360.0 * i as f64 / n as f64;
            let t = c.to_radians();
            for (p, a) in angles.iter().enumerate() {
                let a = a.to_radians();
                // The part off centre by 0.9 µm (the once-per-turn term).
                let v = part(t - a)
                    + 0.9 * (t - a + 0.3).cos()
                    + sx(t) * a.cos()
                    + sy(t) * a.sin()
                    + noise * rng.normal();
                tr[p].angle_deg.push(c);
                tr[p].value_um.push(v);
            }
        }
        tr
    }

    fn steps(n: usize, count: usize, turns: usize, noise: f64, seed: u64) -> Vec<Step> {
        let mut rng = SplitMix64(seed);
        (0..count)
            .map(|j| {
                let st = 360.0 * j as f64 / count as f64;
                let phi = st.to_radians();
                let (e, z) = (3.0 * j as f64, 0.5 * j as f64);
                let mut tr = Track::default();
                for i in 0..n * turns {
                    let c = 360.0 * i as f64 / n as f64;
                    let t = c.to_radians();
                    tr.angle_deg.push(c);
                    tr.value_um.push(
                        part(t - phi)
                            + sx(t)
                            + e * (t + 0.7 * j as f64).cos()
                            + z
                            + noise * rng.normal(),
                    );
                }
                Step {
                    step_deg: st,
                    track: tr,
                }
            })
            .collect()
    }

    #[test]
    fn three_probes_separate_roundness_from_the_iso_error_motion() {
        let angles = [0.0, 99.84, 202.5];
        for n in [360, 512, 1024] {
            let s = three_probe(&three(n, 1, angles, 0.0, 1), angles, None).unwrap();
            let worst = (0..n)
                .map(|i| (s.part_um[i] - part(2.0 * PI * i as f64 / n as f64)).abs())
                .fold(0.0f64, f64::max);
            assert!(worst < 1e-9, "{n}: part off by {worst}");
            // The error motion: sx without its mean and once-per-turn term
            // (it has none) — the part's centring is not in it, reported
            // as centring (0.9 µm).
            let worst_x = (0..n)
                .map(|i| (s.spindle_x_um[i] - sx(2.0 * PI * i as f64 / n as f64)).abs())
                .fold(0.0f64, f64::max);
            assert!(worst_x < 1e-9, "{n}: error motion off by {worst_x}");
            let worst_y = (0..n)
                .map(|i| (s.spindle_y_um[i] - sy(2.0 * PI * i as f64 / n as f64)).abs())
                .fold(0.0f64, f64::max);
            assert!(worst_y < 1e-9, "{n}: y off by {worst_y}");
            assert!((s.error_motion.centring_um - 0.9).abs() < 1e-9);
            assert!((s.spindle_x_pv_um - pv_of(sx)).abs() < 0.01);
        }
    }

    #[test]
    fn probes_at_0_90_180_cannot_see_odd_lobes_and_say_so() {
        let angles = [0.0, 90.0, 180.0];
        let s = three_probe(&three(256, 1, angles, 0.0, 1), angles, None).unwrap();
        for k in [3, 5, 7, 13] {
            assert!(
                s.unseen_harmonics.contains(&k),
                "{k}: {:?}",
                s.unseen_harmonics
            );
        }
        assert!(!s.unseen_harmonics.contains(&4));
        // Out of the error motion too; their sum (part + spindle: the
        // part's 3, 5, 13 and the spindle's 7) given as one.
        assert!(s.error_motion.excluded_harmonics.contains(&7));
        assert!(s.error_motion.excluded_pv_um > 3.0);
        assert!(three_probe(&three(256, 1, angles, 0.0, 1), [0.0, 180.0, 360.0], None).is_err());
    }

    #[test]
    fn the_steps_separate_part_and_spindle_except_their_common_harmonics() {
        for (n, count) in [(360, 4), (360, 5), (360, 7), (512, 8), (1024, 5), (250, 7)] {
            let s = multi_step(&steps(n, count, 1, 0.0, 5), None).unwrap();
            let ins = |k: usize| k.is_multiple_of(count);
            assert!(
                s.inseparable_harmonics.iter().all(|&k| ins(k))
                    && (2..=(n - 1) / 2).filter(|&k| ins(k)).count()
                        == s.inseparable_harmonics.len(),
                "{n}×{count}: {:?}",
                s.inseparable_harmonics
            );
            let (mut wp, mut ws, mut wb) = (0.0f64, 0.0f64, 0.0f64);
            for i in 0..n {
                let t = 2.0 * PI * i as f64 / n as f64;
                let keep = |f: &dyn Fn(f64) -> f64, k: usize| -> f64 {
                    // The harmonic k of f at t, by its definition above.
                    let c: f64 = (0..720)
                        .map(|j| {
                            let u = 2.0 * PI * j as f64 / 720.0;
                            f(u) * (k as f64 * (t - u)).cos()
                        })
                        .sum::<f64>()
                        / 360.0;
                    c
                };
                let lobes = [3usize, 5, 8, 13];
                let spin = [2usize, 7, 16];
                let p_seen: f64 = lobes
                    .iter()
                    .filter(|&&k| !ins(k))
                    .map(|&k| keep(&part, k))
                    .sum();
                let s_seen: f64 = spin
                    .iter()
                    .filter(|&&k| !ins(k))
                    .map(|&k| keep(&sx, k))
                    .sum();
                let both: f64 = lobes
                    .iter()
                    .filter(|&&k| ins(k))
                    .map(|&k| keep(&part, k))
                    .sum::<f64>()
                    + spin
                        .iter()
                        .filter(|&&k| ins(k))
                        .map(|&k| keep(&sx, k))
                        .sum::<f64>();
                wp = wp.max((s.part_um[i] - p_seen).abs());
                ws = ws.max((s.spindle_um[i] - s_seen).abs());
                wb = wb.max((s.inseparable_um[i] - both).abs());
            }
            assert!(
                wp < 1e-6 && ws < 1e-6 && wb < 1e-6,
                "{n}×{count}: {wp} {ws} {wb}"
            );
            assert!(s.residual_rms_um < 1e-9);
        }
    }

    #[test]
    fn both_methods_give_the_same_error_motion_within_their_intervals() {
        // One spindle, two turns, 5 nm noise: three probes and 5 steps.
        let angles = [0.0, 99.84, 202.5];
        let t = three_probe(&three(512, 2, angles, 0.005, 9), angles, None).unwrap();
        let m = multi_step(&steps(512, 5, 2, 0.005, 10), None).unwrap();
        let truth = pv_of(sx);
        for (name, e) in [
            ("three-probe", &t.error_motion),
            ("multi-step", &m.error_motion),
        ] {
            let [lo, hi] = e.synchronous_ci95_um;
            assert!(lo <= truth && truth <= hi, "{name}: {e:?} vs {truth}");
            assert!(
                (e.synchronous_um - truth).abs() < 0.1 * truth,
                "{name}: {e:?}"
            );
            // Two turns: the asynchronous value is the noise's spread.
            let a = e.asynchronous_um.unwrap();
            assert!(a > 0.0 && a < 0.06, "{name}: {a}");
            assert!(e.total_um >= e.synchronous_um);
        }
        let (a, b) = (
            t.error_motion.synchronous_ci95_um,
            m.error_motion.synchronous_ci95_um,
        );
        assert!(a[0] <= b[1] && b[0] <= a[1], "{a:?} {b:?}");
        // 7 steps cannot tell the spindle's 7th harmonic from the part's: the
        // estimate leaves it out and says so, and its interval holds the
        // motion it claims (the rest), not the whole.
        let m7 = multi_step(&steps(512, 7, 2, 0.005, 11), None).unwrap();
        let e = &m7.error_motion;
        assert!(e.excluded_harmonics.starts_with(&[7, 14]));
        let claimed = pv_of(|t| sx(t) - 0.4 * (7.0 * t).sin());
        let [lo, hi] = e.synchronous_ci95_um;
        assert!(lo <= claimed && claimed <= hi, "{e:?} vs {claimed}");
        // The sum at 7: the spindle's 0.4 µm sine (the part has no 7th).
        assert!(
            (e.excluded_pv_um - 0.8).abs() < 0.02,
            "{}",
            e.excluded_pv_um
        );
    }

    #[test]
    fn reading_noise_gives_the_uncertainty_and_bad_sets_are_refused() {
        let s = multi_step(&steps(360, 6, 1, 0.05, 5), None).unwrap();
        // The spindle's profile holds the harmonics 6 steps separate (2…179
        // less the 29 multiples of 6): 149 of them, each σ²/6 · 2/360.
        let want = 0.05 * (2.0f64 * 149.0 / (6.0 * 360.0)).sqrt();
        assert!(
            (s.point_sigma_um - want).abs() < 0.003,
            "{} vs {want}",
            s.point_sigma_um
        );
        assert!(multi_step(&steps(360, 1, 1, 0.0, 5), None).is_err());
        // Every step at the same position separates nothing.
        let mut same = steps(360, 3, 1, 0.0, 5);
        for st in &mut same {
            st.step_deg = 0.0;
        }
        assert_eq!(
            multi_step(&same, None).unwrap().inseparable_harmonics.len(),
            178
        );
    }
}
