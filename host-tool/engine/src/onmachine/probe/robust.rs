//! What keeps a ball calibration honest on real data (docs/on-machine.md
//! § "Outliers and resolution"), for the 2-D and the 3-D fit alike:
//!
//! - **Outlier contacts** (a chip on the ball, a false trigger, a skipped
//!   sample) are found against their neighbours: each contact's distance
//!   from the ball (radius and centre fitted) less the median of its ten
//!   nearest contacts' (in angle, or in direction over the ball) — a
//!   median follows any lobing smooth over ten contacts, so a real lobe is
//!   never taken for an outlier, and is not moved by one. A contact is
//!   flagged when that difference exceeds `max(1.5·z_n, 5)` robust σ
//!   (1.4826 × the median absolute deviation; `z_n` the 95 % bound of the
//!   largest of n normal deviates: pure noise is flagged in well under 5 %
//!   of calibrations). They are named (row, size) and left out by default,
//!   before the form order is chosen: an outlier cannot change the order.
//! - **A coordinate quantum**: a control that logs positions to 0.1 µm
//!   rounds every coordinate to a multiple of it (≈ 29 nm RMS). The
//!   largest step of 1, 2 or 5 × 10ᵏ mm that every coordinate is a whole
//!   multiple of is taken as the resolution; no interval is claimed below
//!   it.

use serde::Serialize;

use crate::onmachine::separate::z_all;

/// A contact that lies far off the calibrated ball.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outlier {
    /// Its row among the scan's contacts (0-based).
    pub index: usize,
    /// Its distance from the calibrated ball and form, nm (+ outward).
    pub residual_nm: f64,
    /// Whether it was left out of the calibration.
    pub left_out: bool,
}

/// 1.4826 × the median absolute deviation from the median: the standard
/// deviation of normal data, unmoved by a few wild values.
pub fn robust_sigma(r: &[f64]) -> f64 {
    if r.is_empty() {
        return 0.0;
    }
    let m = median(&mut r.to_vec());
    1.4826 * median(&mut r.iter().map(|x| (x - m).abs()).collect::<Vec<_>>())
}

/// How far out, in robust σ, a contact is an outlier among `n`.
pub fn threshold(n: usize) -> f64 {
    (1.5 * z_all(n)).max(5.0)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The outliers among contacts with distances `resid` from the ball (mm),
/// each compared with the median of its `neighbours`: flagged beyond
/// [`threshold`] robust σ of those differences (σ at least `floor_mm`).
/// Returns the flagged rows and the cut used, mm. More than a tenth of
/// the contacts is not a few bad ones but a scan the ball does not
/// describe: then none is flagged.
pub(crate) fn flag(resid: &[f64], neighbours: &[Vec<usize>], floor_mm: f64) -> (Vec<usize>, f64) {
    let n = resid.len();
    let score: Vec<f64> = (0..n)
        .map(|i| {
            let mut v: Vec<f64> = neighbours[i].iter().map(|&j| resid[j]).collect();
            if v.is_empty() {
                0.0
            } else {
                resid[i] - median(&mut v)
            }
        })
        .collect();
    let cut = threshold(n) * robust_sigma(&score).max(floor_mm);
    let flagged: Vec<usize> = (0..n).filter(|&i| score[i].abs() > cut).collect();
    if flagged.len() > n / 10 {
        return (Vec::new(), cut);
    }
    (flagged, cut)
}

/// The ten nearest contacts of each, by `dist(i, j)` (all the others
/// when fewer).
pub(crate) fn nearest(n: usize, dist: impl Fn(usize, usize) -> f64) -> Vec<Vec<usize>> {
    (0..n)
        .map(|i| {
            let mut d: Vec<(f64, usize)> = (0..n)
                .filter(|&j| j != i)
                .map(|j| (dist(i, j), j))
                .collect();
            let k = d.len().min(10);
            if k < d.len() {
                d.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
            }
            d.truncate(k);
            d.into_iter().map(|x| x.1).collect()
        })
        .collect()
}

/// The resolution the coordinates were written at: the largest of 1, 2
/// or 5 × 10ᵏ mm (10⁻⁷ … 10⁻² mm) that every value is a whole multiple of;
/// `None` when none is (or fewer than 10 values, or all equal).
pub fn quantum(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.into_iter().collect();
    if v.len() < 10 || v.iter().all(|x| *x == v[0]) {
        return None;
    }
    let mut steps = Vec::new();
    for k in (-7..=-2).rev() {
        let d = 10f64.powi(k);
        steps.extend([5.0 * d, 2.0 * d, d]);
    }
    steps.into_iter().find(|&q| {
        v.iter().all(|x| {
            let m = x / q;
            // Within a thousandth of a step, allowing for the double's own
            // rounding of a decimal.
            (m - m.round()).abs() < 1e-3 + 4.0 * f64::EPSILON * m.abs()
        })
    })
}

/// What a calibration's coordinate quantum changes in its probe file:
/// `quantum_mm` set, the radius's and each form coefficient's 95 %
/// half-width raised to it, and a warning in `warnings` when it matters
/// ([`quantum_warning`]). A quantum of 10⁻⁷ mm (coordinates written to
/// 0.1 nm) changes nothing.
pub(crate) struct Resolution<'a> {
    /// The probe file's `quantum_mm`.
    pub quantum_mm: &'a mut Option<f64>,
    /// Its radius's 95 % half-width, mm.
    pub radius_ci95_mm: &'a mut f64,
    /// Its form coefficients' 95 % half-widths, nm.
    pub form_ci95_nm: &'a mut [f64],
    /// Its residual RMS, nm.
    pub residual_rms_nm: f64,
}

impl Resolution<'_> {
    /// Applies the quantum `q` (mm), if any; the warning, if one is due.
    pub(crate) fn apply(self, q: Option<f64>) -> Option<String> {
        let q = q.filter(|&q| q > 1e-7)?;
        *self.quantum_mm = Some(q);
        let raised =
            floor_all([self.radius_ci95_mm], q) | floor_all(self.form_ci95_nm.iter_mut(), q * 1e6);
        quantum_warning(q, raised, self.residual_rms_nm)
    }
}

/// Raises each 95 % half-width in `ci` to at least `floor`; whether any
/// was raised.
pub(crate) fn floor_all<'a>(ci: impl IntoIterator<Item = &'a mut f64>, floor: f64) -> bool {
    let mut raised = false;
    for c in ci {
        if *c < floor {
            *c = floor;
            raised = true;
        }
    }
    raised
}

/// The warning for coordinates written at `q` mm when it limits the
/// intervals (`raised`) or is a third of the residual RMS or more.
pub(crate) fn quantum_warning(q: f64, raised: bool, residual_rms_nm: f64) -> Option<String> {
    let rms_nm = q / 12f64.sqrt() * 1e6;
    (raised || rms_nm * 3.0 >= residual_rms_nm).then(|| {
        format!(
            "the coordinates are whole multiples of {q} mm (written at that resolution: {rms_nm:.1} nm RMS of rounding in each): no interval is claimed below {q} mm — log the positions with more decimals for a finer calibration"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_test_support::assert_any;

    #[test]
    fn the_resolution_of_logged_coordinates() {
        let v: Vec<f64> = (0..50).map(|i| 102.4971 + 0.0003 * i as f64).collect();
        assert_eq!(quantum(v.iter().copied()), Some(1e-4));
        let fine: Vec<f64> = (0..50)
            .map(|i| 102.4971234 + 0.0000013 * i as f64)
            .collect();
        assert_eq!(quantum(fine.iter().copied()), Some(1e-7));
        let raw: Vec<f64> = (0..50).map(|i| (i as f64 * 0.7).sin() * 3.1).collect();
        assert_eq!(quantum(raw), None);
        let half: Vec<f64> = (0..50).map(|i| 10.0 + 0.0005 * i as f64).collect();
        assert_eq!(quantum(half), Some(5e-4));
    }

    /// A 2-D ball scan: 401 contacts over 10°…170° of a `rb` ball by a
    /// `rp` probe with a 3-lobe and a 6-lobe pre-travel (a kinematic
    /// probe), 5 nm noise, centres rounded to `q` mm (0: not).
    fn ball(rb: f64, rp: f64, q: f64, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = trueaxis_test_support::SplitMix64(seed);
        let round = |v: f64| if q > 0.0 { (v / q).round() * q } else { v };
        (0..=400)
            .map(|i| {
                let t = (10.0 + 160.0 * i as f64 / 400.0f64).to_radians();
                let f = 70.0 * (3.0 * t + 0.3).cos() + 25.0 * (6.0 * t).cos();
                let d = rb + rp + (f + 5.0 * rng.normal()) * 1e-6;
                [round(30.0 + d * t.cos()), round(-4.0 + d * t.sin())]
            })
            .collect()
    }

    #[test]
    fn outlier_contacts_are_named_left_out_and_cannot_change_the_order() {
        for (rb, rp) in [(2.0, 0.49715), (12.7, 1.5), (4.0, 0.25)] {
            let clean = crate::onmachine::probe::calibrate(&ball(rb, rp, 0.0, 3), rb).unwrap();
            assert!(clean.outliers.is_empty(), "{:?}", clean.outliers);
            // The ball centre in the file's convention: the true one moved
            // by the first harmonic of the true form over the arc (the part
            // the form leaves to the centre).
            let th: Vec<f64> = (0..=400)
                .map(|i| (10.0 + 0.4 * i as f64).to_radians())
                .collect();
            let a =
                nalgebra::DMatrix::from_fn(th.len(), 3, |i, j| [1.0, th[i].cos(), th[i].sin()][j]);
            let f = nalgebra::DVector::from_iterator(
                th.len(),
                th.iter()
                    .map(|t| 70.0 * (3.0 * t + 0.3).cos() + 25.0 * (6.0 * t).cos()),
            );
            let s = crate::linalg::lsq::solve(&a, &f, None).unwrap();
            let c = clean.probe.centre_mm;
            let (ex, ez) = (
                c[0] - 30.0 - s.coef[1] * 1e-6,
                c[1] + 4.0 - s.coef[2] * 1e-6,
            );
            // (With the first harmonic taken the wrong way the centre is off
            // by twice it: 135 nm here.)
            assert!(
                ex.hypot(ez) < 15e-6,
                "centre off by {ex} {ez} mm, first harmonic {} {}",
                s.coef[1],
                s.coef[2]
            );
            let mut p = ball(rb, rp, 0.0, 3);
            // Two bad contacts, +380 and −240 nm off the ball.
            for (i, nm) in [(57usize, 380.0), (212, -240.0)] {
                let (dx, dz) = (p[i][0] - 30.0, p[i][1] + 4.0);
                let l = dx.hypot(dz);
                p[i] = [p[i][0] + nm * 1e-6 * dx / l, p[i][1] + nm * 1e-6 * dz / l];
            }
            let cal = crate::onmachine::probe::calibrate(&p, rb).unwrap();
            let named: Vec<(usize, f64)> = cal
                .outliers
                .iter()
                .map(|o| (o.index, o.residual_nm))
                .collect();
            assert_eq!(named.len(), 2, "{rb}/{rp}: {named:?}");
            assert!(
                named[0].0 == 57 && (named[0].1 - 380.0).abs() < 20.0,
                "{named:?}"
            );
            assert!(
                named[1].0 == 212 && (named[1].1 + 240.0).abs() < 20.0,
                "{named:?}"
            );
            assert_eq!(cal.probe.order, clean.probe.order, "{rb}/{rp}");
            assert!((cal.probe.probe_radius_mm - clean.probe.probe_radius_mm).abs() < 1e-6);
            assert!(cal.pv_with_form_nm < 50.0, "{}", cal.pv_with_form_nm);
            // Kept on request: named still, and the fit is worse.
            let kept = crate::onmachine::probe::calibrate_with(&p, rb, true).unwrap();
            assert!(kept.outliers.iter().all(|o| !o.left_out) && kept.outliers.len() == 2);
            assert!(kept.pv_with_form_nm > 500.0, "{}", kept.pv_with_form_nm);
        }
    }

    #[test]
    fn a_coordinate_quantum_is_found_and_no_interval_claimed_below_it() {
        let cal = crate::onmachine::probe::calibrate(&ball(2.0, 0.49715, 1e-4, 4), 2.0).unwrap();
        assert_eq!(cal.probe.quantum_mm, Some(1e-4));
        assert!(
            cal.probe.probe_radius_ci95_mm >= 1e-4,
            "{}",
            cal.probe.probe_radius_ci95_mm
        );
        assert!(cal.probe.form_ci95_nm.iter().all(|&c| c >= 100.0));
        assert_any(&cal.warnings, |w| w.contains("multiples of 0.0001 mm"));
        // Written to 0.1 nm: nothing said, nothing floored.
        let fine = crate::onmachine::probe::calibrate(&ball(2.0, 0.49715, 1e-7, 4), 2.0).unwrap();
        assert_eq!(fine.probe.quantum_mm, None);
        assert!(fine.probe.probe_radius_ci95_mm < 5e-6);
    }

    #[test]
    fn a_3d_calibration_names_outliers_and_sees_a_polar_degree_4_form() {
        // A cone past the equator (polar 0…105°, a probe calibrated for
        // undercuts), 3 lobes round the stylus and a polar P4 term of 40 nm,
        // two bad contacts.
        let form = |n: [f64; 3]| {
            let s = (1.0 - n[2] * n[2]).max(0.0).sqrt();
            let az = n[1].atan2(n[0]);
            let x = n[2];
            60.0 * s.powi(3) * (3.0 * az).cos()
                + 40.0 * (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0
        };
        let mut rng = trueaxis_test_support::SplitMix64(8);
        let mut p = Vec::new();
        for ring in 0..=10 {
            let pol = (10.5 * ring as f64).to_radians();
            for j in 0..(if ring == 0 { 1 } else { 36 }) {
                let az = (10.0 * j as f64).to_radians();
                let n = [pol.sin() * az.cos(), pol.sin() * az.sin(), pol.cos()];
                let d = 3.0 + 1.0 + (form(n) + 5.0 * rng.normal()) * 1e-6;
                p.push([d * n[0], d * n[1], 20.0 + d * n[2]]);
            }
        }
        for (i, nm) in [(40usize, 400.0), (300, -300.0)] {
            let (n, _) = crate::onmachine::probe::sphere::tests_dir(p[i], [0.0, 0.0, 20.0]);
            p[i] = [
                p[i][0] + nm * 1e-6 * n[0],
                p[i][1] + nm * 1e-6 * n[1],
                p[i][2] + nm * 1e-6 * n[2],
            ];
        }
        let cal = crate::onmachine::probe::sphere::calibrate(&p, 3.0).unwrap();
        let idx: Vec<usize> = cal.outliers.iter().map(|o| o.index).collect();
        assert_eq!(idx, vec![40, 300], "{:?}", cal.outliers);
        assert!(
            (cal.outliers[0].residual_nm - 400.0).abs() < 25.0,
            "{:?}",
            cal.outliers
        );
        assert!(
            (cal.outliers[1].residual_nm + 300.0).abs() < 25.0,
            "{:?}",
            cal.outliers
        );
        assert!(
            cal.probe.degree >= 4,
            "{} {:?}",
            cal.probe.degree,
            cal.probe.held_out_rms_nm
        );
        // Along an XZ arc 0…180° the fitted form, less what a circle takes,
        // matches the true one within 3 nm.
        let th: Vec<f64> = (0..=180).map(|i| (i as f64).to_radians()).collect();
        let rest = |f: &dyn Fn(f64) -> f64| -> Vec<f64> {
            let y: Vec<f64> = th.iter().map(|&t| f(t)).collect();
            let a =
                nalgebra::DMatrix::from_fn(th.len(), 3, |i, j| [1.0, th[i].cos(), th[i].sin()][j]);
            let s = crate::linalg::lsq::solve(&a, &nalgebra::DVector::from_vec(y.clone()), None)
                .unwrap();
            y.iter()
                .zip(&th)
                .map(|(v, t)| v - s.coef[0] - s.coef[1] * t.cos() - s.coef[2] * t.sin())
                .collect()
        };
        let fit = rest(&|t| cal.probe.form_nm_at([t.cos(), 0.0, t.sin()]));
        let tru = rest(&|t| form([t.cos(), 0.0, t.sin()]));
        let worst = fit
            .iter()
            .zip(&tru)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 3.0, "{worst} nm");
    }

    #[test]
    fn the_robust_scale_ignores_a_few_wild_values() {
        let mut rng = trueaxis_test_support::SplitMix64(2);
        let mut r: Vec<f64> = (0..400).map(|_| rng.normal()).collect();
        r[10] = 80.0;
        r[300] = -50.0;
        let s = robust_sigma(&r);
        assert!((s - 1.0).abs() < 0.1, "{s}");
    }
}
