//! Probe calibration from a 3-D scan of the master ball (docs/on-machine.md,
//! "3-D calibration").
//!
//! **Geometry.** Each row is the probe ball's centre `p` at one contact on
//! a master ball of radius `R` centred at `c`: `|p − c| = R + r + f(n)`,
//! with `n = (p − c)/|p − c|` the contact direction (the ball's outward
//! normal at the contact), `r` the probe's effective radius and `f` its form
//! error as a function of direction. `f` is a polynomial in `(nx, ny, nz)`
//! on the unit sphere of degree 2…L — the monomials `nx^a ny^b nz^c` with
//! `c ≤ 1` (nz² = 1 − nx² − ny² on the sphere), which span the spherical
//! harmonics of degree ≤ L, `(L+1)²` functions; the four of degree ≤ 1 are
//! the radius and the centre and are left to them. As in the 2-D case the
//! fitted form is made orthogonal to `1, nx, ny, nz` over the calibrated
//! directions (that part goes to radius and centre), so `r` is the radius
//! that fits best with a form error of zero mean and no tilt. `L` is chosen
//! by held-out RMS over 5 folds of direction cells (the smallest `L` within
//! 2 % of the best).
//!
//! **Coverage.** What was calibrated is a cone of directions: its axis (the
//! mean contact direction) and half angle (the largest angle of a contact
//! from it); a direction outside it gets no form value (never an
//! extrapolated polynomial).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::linalg::lsq;

/// Format tag of a 3-D probe file.
pub const PROBE3D_FORMAT: &str = "trueaxis-probe3d/1";

/// Highest form degree tried.
pub const MAX_DEGREE: usize = 6;

/// The exponents `[a, b, c]` of the form monomials of degree 2…`degree`
/// (`c ≤ 1`), in a fixed order: by degree, then `c`, then `b`.
pub fn form_terms(degree: usize) -> Vec<[u8; 3]> {
    let mut t = Vec::new();
    for d in 2..=degree {
        for c in 0..=1usize.min(d) {
            for b in 0..=(d - c) {
                t.push([(d - c - b) as u8, b as u8, c as u8]);
            }
        }
    }
    t
}

fn monomial(n: [f64; 3], e: [u8; 3]) -> f64 {
    n[0].powi(e[0] as i32) * n[1].powi(e[1] as i32) * n[2].powi(e[2] as i32)
}

/// A probe calibrated in 3-D: what `probe calibrate --plane xyz` writes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Probe3d {
    /// [`PROBE3D_FORMAT`].
    pub format: String,
    /// The master ball's radius the calibration assumed, mm.
    pub ball_radius_mm: f64,
    /// The probe's effective radius, mm.
    pub probe_radius_mm: f64,
    /// Half-width of its 95 % interval, mm.
    pub probe_radius_ci95_mm: f64,
    /// The fitted ball centre `[x, y, z]`, mm.
    pub centre_mm: [f64; 3],
    /// Form degree L (0: no form error term).
    pub degree: usize,
    /// The form monomials' exponents `[a, b, c]` (`nx^a ny^b nz^c`).
    pub terms: Vec<[u8; 3]>,
    /// Their coefficients, nm.
    pub form_nm: Vec<f64>,
    /// Half-widths of their 95 % intervals, nm.
    pub form_ci95_nm: Vec<f64>,
    /// The mean and the degree-1 part removed from the polynomial over the
    /// calibrated directions (`f − c0 − cx nx − cy ny − cz nz`), nm.
    pub form_rigid_nm: [f64; 4],
    /// Axis of the calibrated cone of directions (unit vector).
    pub cone_axis: [f64; 3],
    /// Its half angle, degrees.
    pub cone_half_angle_deg: f64,
    /// Peak to valley of the form error over the calibrated directions, nm.
    pub form_pv_nm: f64,
    /// RMS of what is left after radius, centre and form, nm (noise).
    pub residual_rms_nm: f64,
    /// Held-out RMS per degree tried `[degree, nm]`.
    pub held_out_rms_nm: Vec<[f64; 2]>,
    /// Points in the calibration.
    pub points: usize,
    /// The resolution the ball scan's coordinates were written at, mm,
    /// when coarser than 10⁻⁷ mm: no interval above is below it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantum_mm: Option<f64>,
}

impl Probe3d {
    /// The form error in direction `n` (unit vector), nm.
    pub fn form_nm_at(&self, n: [f64; 3]) -> f64 {
        let raw: f64 = self
            .terms
            .iter()
            .zip(&self.form_nm)
            .map(|(&e, &a)| a * monomial(n, e))
            .sum();
        let [c0, cx, cy, cz] = self.form_rigid_nm;
        raw - c0 - cx * n[0] - cy * n[1] - cz * n[2]
    }

    /// The form error at contact angle θ (rad) in the plane of the axes
    /// `plane` (0 = x, 1 = y, 2 = z; θ from the first toward the second),
    /// nm, or `None` outside the calibrated cone: the lookup
    /// [`super::correct_with`] takes, so a probe calibrated once in 3-D
    /// corrects scans in any plane.
    pub fn in_plane(&self, plane: [usize; 2], theta: f64) -> Option<f64> {
        let mut n = [0.0; 3];
        n[plane[0]] = theta.cos();
        n[plane[1]] = theta.sin();
        self.covers(n).then(|| self.form_nm_at(n))
    }

    /// Whether direction `n` lies in the calibrated cone (1° margin).
    pub fn covers(&self, n: [f64; 3]) -> bool {
        angle_deg(n, self.cone_axis) <= self.cone_half_angle_deg + 1.0
    }

    /// Checks a probe file read from disk.
    pub fn check(&self) -> Result<()> {
        if self.format != PROBE3D_FORMAT {
            bail!(
                "not a trueaxis 3-D probe file (format `{}`, expected `{PROBE3D_FORMAT}`)",
                self.format
            );
        }
        if self.terms.len() != self.form_nm.len()
            || self.form_ci95_nm.len() != self.form_nm.len()
            || self.terms != form_terms(self.degree.max(1))
        {
            bail!(
                "degree {} needs {} form coefficients in the order of docs/on-machine.md, found {} terms and {} coefficients",
                self.degree,
                form_terms(self.degree.max(1)).len(),
                self.terms.len(),
                self.form_nm.len()
            );
        }
        let axis_len = self.cone_axis.iter().map(|v| v * v).sum::<f64>().sqrt();
        let finite = [
            self.ball_radius_mm,
            self.probe_radius_mm,
            self.form_pv_nm,
            self.cone_half_angle_deg,
        ]
        .iter()
        .chain(&self.form_nm)
        .chain(&self.form_rigid_nm)
        .chain(&self.centre_mm)
        .all(|v| v.is_finite());
        if !finite
            || self.probe_radius_mm <= 0.0
            || (axis_len - 1.0).abs() > 1e-6
            || !(0.0..=180.0).contains(&self.cone_half_angle_deg)
        {
            bail!("a value is not finite, the probe radius not positive, the cone axis not a unit vector or its angle outside 0…180°");
        }
        Ok(())
    }
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
    d.acos().to_degrees()
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

/// One fit at a given degree.
struct Fit {
    centre: [f64; 3],
    total_radius: f64,
    form: Vec<f64>, // mm
    form_sd: Vec<f64>,
    resid: Vec<f64>, // mm, every point
}

/// Algebraic sphere fit: centre and radius.
fn algebraic(p: &[[f64; 3]]) -> Result<([f64; 3], f64)> {
    let n = p.len();
    let a = DMatrix::from_fn(n, 4, |i, j| if j < 3 { p[i][j] } else { 1.0 });
    let b = DVector::from_fn(n, |i, _| p[i].iter().map(|v| v * v).sum::<f64>());
    let s = lsq::solve(&a, &b, None)
        .map_err(|e| anyhow::anyhow!("the points do not span a sphere: {e}"))?;
    let c = [s.coef[0] / 2.0, s.coef[1] / 2.0, s.coef[2] / 2.0];
    let r2 = s.coef[3] + c.iter().map(|v| v * v).sum::<f64>();
    if r2.is_nan() || r2 <= 0.0 {
        bail!("the points do not lie on a sphere");
    }
    Ok((c, r2.sqrt()))
}

/// [`dir`] for the wing's tests.
#[cfg(test)]
pub(crate) fn tests_dir(p: [f64; 3], c: [f64; 3]) -> ([f64; 3], f64) {
    dir(p, c)
}

fn dir(p: [f64; 3], c: [f64; 3]) -> ([f64; 3], f64) {
    let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    ([d[0] / l, d[1] / l, d[2] / l], l)
}

/// Gauss–Newton fit of centre, total radius and a form polynomial of
/// `degree` to the rows `rows` of `p`.
fn fit_degree(
    p: &[[f64; 3]],
    rows: &[usize],
    degree: usize,
    start: ([f64; 3], f64),
) -> Result<Fit> {
    let terms = if degree >= 2 {
        form_terms(degree)
    } else {
        Vec::new()
    };
    let nf = terms.len();
    let (mut c, mut rt) = start;
    let mut form = vec![0.0; nf];
    let mut last = None;
    for _ in 0..30 {
        let mut a = DMatrix::zeros(rows.len(), 4 + nf);
        let mut b = DVector::zeros(rows.len());
        for (row, &i) in rows.iter().enumerate() {
            let (n, d) = dir(p[i], c);
            let f: f64 = terms
                .iter()
                .zip(&form)
                .map(|(&e, v)| v * monomial(n, e))
                .sum();
            // ρ = d − (rt + f); ∂ρ/∂c = −n (f's dependence on c through n
            // is second order for a form of nm on a radius of mm).
            b[row] = d - rt - f;
            for (k, v) in n.iter().enumerate() {
                a[(row, k)] = *v;
            }
            a[(row, 3)] = 1.0;
            for (j, &e) in terms.iter().enumerate() {
                a[(row, 4 + j)] = monomial(n, e);
            }
        }
        let s = lsq::solve(&a, &b, None)?;
        for (k, ck) in c.iter_mut().enumerate() {
            *ck += s.coef[k];
        }
        rt += s.coef[3];
        for (j, f) in form.iter_mut().enumerate() {
            *f += s.coef[4 + j];
        }
        let step = s.coef.amax();
        last = Some(s);
        if step < 1e-12 {
            break;
        }
    }
    let s = last.expect("at least one iteration");
    let resid = p
        .iter()
        .map(|&q| {
            let (n, d) = dir(q, c);
            let f: f64 = terms
                .iter()
                .zip(&form)
                .map(|(&e, v)| v * monomial(n, e))
                .sum();
            d - rt - f
        })
        .collect();
    Ok(Fit {
        centre: c,
        total_radius: rt,
        form_sd: (0..nf).map(|j| s.coef_sd[4 + j]).collect(),
        form,
        resid,
    })
}

/// What a 3-D calibration says beyond the probe file.
#[derive(Clone, Debug, Serialize)]
pub struct Calibration3d {
    /// The probe file to write.
    pub probe: Probe3d,
    /// Residual per point after the chosen model, nm.
    pub residual_nm: Vec<f64>,
    /// Peak to valley of the distance to the fitted sphere with the radius
    /// and centre only, nm.
    pub pv_without_form_nm: f64,
    /// Peak to valley of the residual with the form, nm.
    pub pv_with_form_nm: f64,
    /// Problems with the calibration data.
    pub warnings: Vec<String>,
    /// Contacts far off the ball, named (`super::robust`).
    pub outliers: Vec<super::Outlier>,
}

/// The degrees `n` contacts support: 0, then 2… while every coefficient
/// has at least 10 contacts.
fn degrees(n: usize) -> impl Iterator<Item = usize> {
    std::iter::once(0)
        .chain(2..=MAX_DEGREE)
        .take_while(move |&d| (4 + form_terms(d.max(1)).len()) * 10 <= n)
}

/// Calibrates a probe on a master ball of radius `ball_radius_mm` from the
/// probe-centre positions `p` (mm) of a 3-D scan over the ball, outlier
/// contacts left out ([`calibrate_with`]).
pub fn calibrate(p: &[[f64; 3]], ball_radius_mm: f64) -> Result<Calibration3d> {
    calibrate_with(p, ball_radius_mm, false)
}

/// [`calibrate`], the outlier contacts found against the most flexible
/// form named and — unless `keep_outliers` — left out before anything
/// else is fitted; a coordinate quantum is the floor of every interval (as
/// the 2-D calibration, `super::calibrate_with`).
pub fn calibrate_with(
    p: &[[f64; 3]],
    ball_radius_mm: f64,
    keep_outliers: bool,
) -> Result<Calibration3d> {
    if !(ball_radius_mm.is_finite() && ball_radius_mm > 0.0) {
        bail!("the master ball radius must be a positive number of mm, got {ball_radius_mm}");
    }
    if p.len() < 20 {
        bail!(
            "{} points on the ball; a 3-D calibration needs at least 20 (a few hundred over the ball for a form error)",
            p.len()
        );
    }
    let q = super::robust::quantum(p.iter().flatten().copied());
    let floor = q.map_or(0.0, |q| q / 12f64.sqrt());
    let start = algebraic(p)?;
    // Each contact against its neighbours in direction (robust::flag).
    let all: Vec<usize> = (0..p.len()).collect();
    let rigid = fit_degree(p, &all, 0, start)?;
    let dirs: Vec<[f64; 3]> = p.iter().map(|&q| dir(q, rigid.centre).0).collect();
    let near = super::robust::nearest(p.len(), |i, j| {
        let (a, b) = (dirs[i], dirs[j]);
        (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
    });
    let (flagged, cut) = super::robust::flag(&rigid.resid, &near, floor);
    let used: Vec<[f64; 3]> = (0..p.len())
        .filter(|i| keep_outliers || !flagged.contains(i))
        .map(|i| p[i])
        .collect();
    let mut cal = calibrate_points(&used, ball_radius_mm, cut)?;
    let pr = &cal.probe;
    cal.outliers = flagged
        .iter()
        .map(|&i| {
            let (n, d) = dir(p[i], pr.centre_mm);
            super::Outlier {
                index: i,
                residual_nm: (d - pr.ball_radius_mm - pr.probe_radius_mm) * 1e6 - pr.form_nm_at(n),
                left_out: !keep_outliers,
            }
        })
        .collect();
    let pr = &mut cal.probe;
    let said = super::robust::Resolution {
        quantum_mm: &mut pr.quantum_mm,
        radius_ci95_mm: &mut pr.probe_radius_ci95_mm,
        form_ci95_nm: &mut pr.form_ci95_nm,
        residual_rms_nm: pr.residual_rms_nm,
    }
    .apply(q);
    cal.warnings.extend(said);
    Ok(cal)
}

/// The calibration proper on the contacts `p` kept; `clip` (mm) bounds
/// one held-out residual's say in the degree.
fn calibrate_points(p: &[[f64; 3]], ball_radius_mm: f64, clip: f64) -> Result<Calibration3d> {
    if p.len() < 20 {
        bail!(
            "{} points on the ball besides the outliers; a 3-D calibration needs at least 20",
            p.len()
        );
    }
    let start = algebraic(p)?;
    let all: Vec<usize> = (0..p.len()).collect();
    let rigid = fit_degree(p, &all, 0, start)?;
    let dirs: Vec<[f64; 3]> = p.iter().map(|&q| dir(q, rigid.centre).0).collect();
    let mean = dirs
        .iter()
        .fold([0.0; 3], |m, n| [m[0] + n[0], m[1] + n[1], m[2] + n[2]]);
    let mut warnings = Vec::new();
    let mean_len = mean.iter().map(|v| v * v).sum::<f64>().sqrt() / p.len() as f64;
    let axis = if mean_len < 0.05 {
        // Contacts all round the ball: the cone is the whole sphere.
        [0.0, 0.0, 1.0]
    } else {
        unit(mean)
    };
    let angles: Vec<f64> = dirs.iter().map(|&n| angle_deg(n, axis)).collect();
    let half = if mean_len < 0.05 {
        180.0
    } else {
        angles.iter().copied().fold(0.0, f64::max)
    };
    if half < 45.0 {
        warnings.push(format!(
            "the contacts lie within {half:.0}° of their mean direction: on so small a cap a form error of low degree cannot be told from the probe radius and the ball centre — scan at least a hemisphere (the directions the workpiece will see)"
        ));
    }
    // Folds: direction cells (4 rings of the angle from the axis × 5
    // sectors of the azimuth around it), cell index mod 5 — contiguous
    // patches of directions, so a fold tests prediction into a gap.
    let (e1, e2) = {
        let t = if axis[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let d = t[0] * axis[0] + t[1] * axis[1] + t[2] * axis[2];
        let e1 = unit([t[0] - d * axis[0], t[1] - d * axis[1], t[2] - d * axis[2]]);
        let e2 = [
            axis[1] * e1[2] - axis[2] * e1[1],
            axis[2] * e1[0] - axis[0] * e1[2],
            axis[0] * e1[1] - axis[1] * e1[0],
        ];
        (e1, e2)
    };
    let fold: Vec<usize> = dirs
        .iter()
        .zip(&angles)
        .map(|(n, &a)| {
            let ring = ((a / half.max(1e-9)) * 4.0).floor().clamp(0.0, 3.0) as usize;
            let u = n[0] * e1[0] + n[1] * e1[1] + n[2] * e1[2];
            let v = n[0] * e2[0] + n[1] * e2[1] + n[2] * e2[2];
            let az = v.atan2(u).to_degrees().rem_euclid(360.0);
            let sector = ((az / 72.0).floor() as usize).min(4);
            (ring + sector) % 5
        })
        .collect();
    let (held, degree) = super::choose_order(degrees(p.len()), &fold, clip, |train, d| {
        Ok(fit_degree(p, train, d, start)?.resid)
    });
    let fit = fit_degree(p, &all, degree, start)?;
    let terms = if degree >= 2 {
        form_terms(degree)
    } else {
        Vec::new()
    };
    let dirs: Vec<[f64; 3]> = p.iter().map(|&q| dir(q, fit.centre).0).collect();
    // The form made orthogonal to 1, nx, ny, nz over the calibrated
    // directions: that part belongs to radius and centre.
    let raw: Vec<f64> = dirs
        .iter()
        .map(|&n| {
            terms
                .iter()
                .zip(&fit.form)
                .map(|(&e, v)| v * monomial(n, e))
                .sum::<f64>()
                * 1e6
        })
        .collect();
    let rig = DMatrix::from_fn(p.len(), 4, |i, j| if j == 0 { 1.0 } else { dirs[i][j - 1] });
    let proj = lsq::solve(&rig, &DVector::from_vec(raw), None)?;
    let form_rigid_nm = [proj.coef[0], proj.coef[1], proj.coef[2], proj.coef[3]];
    let total_radius = fit.total_radius + form_rigid_nm[0] * 1e-6;
    let centre = [
        // As in 2-D: the degree-1 part left out of the form is a centre
        // further by (cx, cy, cz).
        fit.centre[0] + form_rigid_nm[1] * 1e-6,
        fit.centre[1] + form_rigid_nm[2] * 1e-6,
        fit.centre[2] + form_rigid_nm[3] * 1e-6,
    ];
    // The radius's interval with the form orthogonal to it: the rigid
    // columns at the final centre, the full model's residual as the noise.
    let radius_sd = lsq::solve(&rig, &DVector::from_vec(fit.resid.clone()), None)?.coef_sd[0];
    if total_radius <= ball_radius_mm {
        bail!(
            "the fitted radius {total_radius:.6} mm is not above the master ball's {ball_radius_mm} mm: the scan is not of the probe's centre on this ball (check the ball diameter and that the rows are centre positions)"
        );
    }
    let mut probe = Probe3d {
        format: PROBE3D_FORMAT.into(),
        ball_radius_mm,
        probe_radius_mm: total_radius - ball_radius_mm,
        probe_radius_ci95_mm: 1.96 * radius_sd,
        centre_mm: centre,
        degree,
        terms: form_terms(degree.max(1)),
        form_nm: fit.form.iter().map(|v| v * 1e6).collect(),
        form_ci95_nm: fit.form_sd.iter().map(|v| 1.96 * v * 1e6).collect(),
        form_rigid_nm,
        cone_axis: axis,
        cone_half_angle_deg: half,
        form_pv_nm: 0.0,
        residual_rms_nm: 0.0,
        held_out_rms_nm: held.iter().map(|&(d, v)| [d as f64, v]).collect(),
        points: p.len(),
        quantum_mm: None,
    };
    if degree >= 2 {
        let f: Vec<f64> = dirs.iter().map(|&n| probe.form_nm_at(n)).collect();
        probe.form_pv_nm = crate::onmachine::separate::pv(&f);
    } else {
        warnings.push(
            "no form error term is supported by held-out data: the probe is calibrated as a sphere of the fitted radius".into(),
        );
    }
    let resid_nm: Vec<f64> = fit.resid.iter().map(|v| v * 1e6).collect();
    probe.residual_rms_nm =
        (resid_nm.iter().map(|v| v * v).sum::<f64>() / resid_nm.len() as f64).sqrt();
    let without: Vec<f64> = rigid.resid.iter().map(|v| v * 1e6).collect();
    Ok(Calibration3d {
        pv_without_form_nm: crate::onmachine::separate::pv(&without),
        pv_with_form_nm: crate::onmachine::separate::pv(&resid_nm),
        residual_nm: resid_nm,
        probe,
        warnings,
        outliers: Vec::new(),
    })
}

/// Reads a 3-D probe scan: `x_mm,y_mm,z_mm` columns (others ignored), `#`
/// comments; errors name the file, line and column.
pub fn read_scan(text: &str, name: &str) -> Result<Vec<[f64; 3]>> {
    Ok(read_scan_lines(text, name)?.0)
}

/// [`read_scan`], and each point's line in the text.
pub fn read_scan_lines(text: &str, name: &str) -> Result<(Vec<[f64; 3]>, Vec<usize>)> {
    let rows = crate::import::read_table(
        text,
        name,
        &["x_mm", "y_mm", "z_mm"],
        "the probe centre in 3-D",
    )?;
    Ok((
        rows.iter().map(|r| [r[0], r[1], r[2]]).collect(),
        rows.iter().map(|r| r[3] as usize).collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_test_support::{assert_any, SplitMix64};

    /// The largest |a − b| over pairs of `a` and `b`.
    fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
        let diffs = a.iter().zip(b).map(|(a, b)| (a - b).abs());
        diffs.fold(0.0f64, f64::max)
    }

    /// A 0.49715 mm probe with lobing (3 lobes around the stylus and a
    /// term that grows toward the equator, ~170 nm PV) on a 2 mm master
    /// ball, contacts over the upper hemisphere (polar 0…85°, 10 rings ×
    /// 36 azimuths + the pole), 5 nm noise.
    fn form(n: [f64; 3]) -> f64 {
        let s = (1.0 - n[2] * n[2]).max(0.0).sqrt();
        let az = n[1].atan2(n[0]);
        60.0 * s.powi(3) * (3.0 * az).cos() + 40.0 * n[2] * n[2] - 25.0 * s * s * (2.0 * az).sin()
    }

    fn hemisphere(seed: u64, polar_max: f64) -> Vec<[f64; 3]> {
        let mut rng = SplitMix64(seed);
        let (rb, rp, c) = (2.0, 0.49715, [12.5, -3.0, 40.0]);
        let mut p = Vec::new();
        for ring in 0..=10 {
            let pol = (polar_max * ring as f64 / 10.0).to_radians();
            let k = if ring == 0 { 1 } else { 36 };
            for j in 0..k {
                let az = (j as f64 * 10.0 + 5.0 * (ring % 2) as f64).to_radians();
                let n = [pol.sin() * az.cos(), pol.sin() * az.sin(), pol.cos()];
                let d = rb + rp + (form(n) + 5.0 * rng.normal()) * 1e-6;
                p.push([c[0] + d * n[0], c[1] + d * n[1], c[2] + d * n[2]]);
            }
        }
        p
    }

    #[test]
    fn the_terms_span_the_harmonics() {
        for l in 1..=MAX_DEGREE {
            // 4 rigid functions + the form terms = (L+1)² on the sphere.
            assert_eq!(4 + form_terms(l).len(), (l + 1) * (l + 1), "degree {l}");
        }
    }

    #[test]
    fn a_hemisphere_scan_gives_the_probe_radius_and_its_form() {
        let p = hemisphere(1, 85.0);
        let cal = calibrate(&p, 2.0).unwrap();
        let pr = &cal.probe;
        // The truth in the file's convention: the form made orthogonal to
        // 1, nx, ny, nz over the contact directions, its mean in the radius.
        let c = [12.5, -3.0, 40.0];
        let dirs: Vec<[f64; 3]> = p.iter().map(|&q| dir(q, c).0).collect();
        let truth: Vec<f64> = dirs.iter().map(|&n| form(n)).collect();
        let rig = DMatrix::from_fn(p.len(), 4, |i, j| if j == 0 { 1.0 } else { dirs[i][j - 1] });
        let proj = lsq::solve(&rig, &DVector::from_vec(truth.clone()), None).unwrap();
        let r_true = 0.49715 + proj.coef[0] * 1e-6;
        assert!(
            (pr.probe_radius_mm - r_true).abs() < 5e-6,
            "radius {} vs {r_true}",
            pr.probe_radius_mm
        );
        assert!(
            pr.probe_radius_ci95_mm < 5e-6,
            "{}",
            pr.probe_radius_ci95_mm
        );
        let true_perp: Vec<f64> = dirs
            .iter()
            .zip(&truth)
            .map(|(n, f)| {
                f - proj.coef[0] - proj.coef[1] * n[0] - proj.coef[2] * n[1] - proj.coef[3] * n[2]
            })
            .collect();
        let fitted: Vec<f64> = dirs.iter().map(|&n| pr.form_nm_at(n)).collect();
        let pv_true = crate::onmachine::separate::pv(&true_perp);
        assert!(
            (pr.form_pv_nm - pv_true).abs() < 10.0,
            "form PV {} vs {pv_true}",
            pr.form_pv_nm
        );
        let worst = max_abs_diff(&fitted, &true_perp);
        assert!(worst < 10.0, "form recovered to {worst} nm");
        assert!(
            pr.degree >= 3,
            "degree {} {:?}",
            pr.degree,
            pr.held_out_rms_nm
        );
        assert!(
            (pr.residual_rms_nm - 5.0).abs() < 1.0,
            "{}",
            pr.residual_rms_nm
        );
        assert!(cal.pv_without_form_nm > 120.0, "{}", cal.pv_without_form_nm);
        assert!(cal.pv_with_form_nm < 40.0, "{}", cal.pv_with_form_nm);
        assert!(
            (pr.cone_half_angle_deg - 85.0).abs() < 3.0,
            "{}",
            pr.cone_half_angle_deg
        );
        assert!(pr.covers([0.0, 0.0, 1.0]) && !pr.covers([0.0, 0.0, -1.0]));
        pr.check().unwrap();
    }

    #[test]
    fn a_round_probe_gets_no_form_and_a_small_cap_is_warned() {
        let mut rng = SplitMix64(3);
        let p: Vec<[f64; 3]> = hemisphere(2, 80.0)
            .iter()
            .map(|q| {
                let (n, _) = dir(*q, [12.5, -3.0, 40.0]);
                let d = 2.5 + 5.0 * rng.normal() * 1e-6;
                [12.5 + d * n[0], -3.0 + d * n[1], 40.0 + d * n[2]]
            })
            .collect();
        let cal = calibrate(&p, 2.0).unwrap();
        assert!(
            cal.probe.degree <= 2,
            "degree {} for a round probe",
            cal.probe.degree
        );
        assert!(cal.probe.form_pv_nm < 15.0, "{}", cal.probe.form_pv_nm);
        assert!((cal.probe.probe_radius_mm - 0.5).abs() < 3e-6);
        let cap = calibrate(&hemisphere(4, 30.0), 2.0).unwrap();
        assert_any(&cap.warnings, |w| w.contains("scan at least a hemisphere"));
        let e = calibrate(&p, 3.0).unwrap_err();
        assert!(format!("{e}").contains("not above the master ball"), "{e}");
    }

    #[test]
    fn a_probe_calibrated_in_3d_corrects_a_scan_in_a_plane() {
        let pr = calibrate(&hemisphere(6, 85.0), 2.0).unwrap().probe;
        // A part in the xz plane: a 20 mm arc with a 4-lobe form of 150 nm,
        // probed from above over 30°…150° (polar 60°…0°…60°: inside the
        // calibrated cone), by the probe of `form`.
        let lobes = |t: f64| 150.0 * (4.0 * t).cos();
        let (mut centres, mut truth) = (Vec::new(), Vec::new());
        for i in 0..=600 {
            let t = (30.0 + 120.0 * i as f64 / 600.0).to_radians();
            let surf = 20.0 + lobes(t) * 1e-6;
            truth.push([surf * t.cos(), surf * t.sin()]);
            let d = surf + 0.49715 + form([t.cos(), 0.0, t.sin()]) * 1e-6;
            centres.push([d * t.cos(), d * t.sin()]);
        }
        let c = crate::onmachine::probe::correct_with(
            &centres,
            crate::onmachine::probe::Side::Toward([0.0, 1.0]),
            pr.probe_radius_mm,
            |t| pr.in_plane([0, 2], t),
        )
        .unwrap();
        assert!(c.iter().all(|k| k.calibrated));
        let s: Vec<[f64; 2]> = c.iter().map(|k| k.surface_mm).collect();
        let dev = crate::onmachine::probe::form_deviation_nm(&s, true).unwrap();
        let dev_true = crate::onmachine::probe::form_deviation_nm(&truth, true).unwrap();
        let worst = max_abs_diff(&dev, &dev_true);
        // With the radius only, what of the probe's form a circle does not
        // absorb along this arc (measured: 17 nm; corrected: 1.4 nm) would
        // be in the part.
        let radius_only: Vec<[f64; 2]> = centres
            .iter()
            .zip(&c)
            .map(|(q, k)| {
                let t = k.theta_deg.to_radians();
                [q[0] - 0.49715 * t.cos(), q[1] - 0.49715 * t.sin()]
            })
            .collect();
        let dev0 = crate::onmachine::probe::form_deviation_nm(&radius_only, true).unwrap();
        let worst0 = max_abs_diff(&dev0, &dev_true);
        assert!(worst < 5.0, "part form recovered to {worst} nm");
        assert!(worst0 > 10.0, "radius only: {worst0} nm");
        // Below the equator (probed from underneath) nothing was calibrated.
        assert_eq!(pr.in_plane([0, 2], (-90f64).to_radians()), None);
    }

    #[test]
    fn a_damaged_probe_file_is_refused() {
        let mut pr = calibrate(&hemisphere(5, 85.0), 2.0).unwrap().probe;
        pr.form_nm.pop();
        assert!(pr.check().is_err());
        let mut pr2 = calibrate(&hemisphere(5, 85.0), 2.0).unwrap().probe;
        pr2.cone_axis = [0.0, 0.0, 2.0];
        assert!(pr2.check().is_err());
    }
}
