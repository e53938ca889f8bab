//! On-machine probing (docs/on-machine.md): the probe's effective radius and its
//! form error as a function of contact angle, calibrated on a master ball,
//! and the correction of a workpiece scan with them.
//!
//! **Geometry (2-D, the XZ plane).** Each scan row is the probe ball's
//! centre at one contact, `(x, z)` in mm. Touching a ball of radius `R`
//! centred at `c`, the centre lies at
//! `|p − c| = R + r + f(θ)`, with `θ = atan2(z − c_z, x − c_x)` the contact
//! angle (the direction from the ball's centre to the probe's, which is the
//! outward surface normal at the contact), `r` the probe's effective radius
//! and `f` its form error. `f` is a Fourier series in θ from the second
//! harmonic up (`f = Σ_{k=2..K} a_k cos kθ + b_k sin kθ`): its mean is the
//! radius and its first harmonic a shift of the centre, so neither can be
//! told from them. On a partial arc the higher harmonics are not
//! orthogonal to radius and centre either; the fitted form is therefore
//! made orthogonal to `1, cos θ, sin θ` over the calibrated angles (that
//! part goes to radius and centre), so `r` is the radius that fits best
//! with a form error of zero mean and no tilt. The order `K` is chosen by
//! held-out RMS over 5 folds of contiguous angular blocks — the smallest
//! `K` within 2 % of the best — not fixed. Solved by Gauss–Newton from an
//! algebraic circle fit; 95 % intervals from the final linearised least
//! squares (1.96 σ).
//!
//! **Correcting a scan.** On a workpiece the centre path is the surface
//! offset by the probe, so the surface normal at each contact is the
//! normal of the centre path (the tangency relation: probe and part touch
//! where their tangents agree), taken from neighbouring rows. The contact
//! point is `s = p − (r + f(θ)) n`. A contact angle outside the calibrated
//! arc has an unknown form error: such rows are flagged and corrected with
//! the radius only, never with an extrapolated series.

use std::f64::consts::PI;

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::linalg::lsq;

pub mod robust;
pub mod sphere;

pub use robust::Outlier;

/// Format tag of a probe file.
pub const PROBE_FORMAT: &str = "trueaxis-probe/1";

/// Highest form order tried.
pub const MAX_ORDER: usize = 12;

/// A calibrated probe: what `probe calibrate` writes and `probe correct`
/// reads (docs/on-machine.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProbeFile {
    /// [`PROBE_FORMAT`].
    pub format: String,
    /// The master ball's radius the calibration assumed, mm.
    pub ball_radius_mm: f64,
    /// The probe's effective radius, mm.
    pub probe_radius_mm: f64,
    /// Half-width of its 95 % interval, mm.
    pub probe_radius_ci95_mm: f64,
    /// The fitted ball centre `[x, z]`, mm.
    pub centre_mm: [f64; 2],
    /// Form order K (0: no form error term).
    pub order: usize,
    /// Form coefficients, nm: `[a_2, b_2, a_3, b_3, …]` (cos, sin).
    pub form_nm: Vec<f64>,
    /// Half-widths of their 95 % intervals, nm.
    pub form_ci95_nm: Vec<f64>,
    /// The mean and the first harmonic removed from the series over the
    /// calibrated angles (`f − c0 − c1 cos θ − s1 sin θ`), nm: applied when
    /// the series is evaluated, so `f` has zero mean and no tilt there.
    pub form_rigid_nm: [f64; 3],
    /// The calibrated contact angles, degrees `[lo, hi]`.
    pub theta_range_deg: [f64; 2],
    /// Peak to valley of the form error over the calibrated arc, nm.
    pub form_pv_nm: f64,
    /// RMS of what is left after radius, centre and form, nm (noise).
    pub residual_rms_nm: f64,
    /// Held-out RMS per order tried `[order, nm]`.
    pub held_out_rms_nm: Vec<[f64; 2]>,
    /// Points in the calibration.
    pub points: usize,
    /// The resolution the ball scan's coordinates were written at, mm,
    /// when coarser than 10⁻⁷ mm: no interval above is below it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantum_mm: Option<f64>,
}

impl ProbeFile {
    /// The form error at contact angle `theta` (rad), nm.
    pub fn form_nm_at(&self, theta: f64) -> f64 {
        let raw: f64 = (2..=self.order)
            .map(|k| {
                let i = 2 * (k - 2);
                self.form_nm[i] * (k as f64 * theta).cos()
                    + self.form_nm[i + 1] * (k as f64 * theta).sin()
            })
            .sum();
        let [c0, c1, s1] = self.form_rigid_nm;
        raw - c0 - c1 * theta.cos() - s1 * theta.sin()
    }

    /// Whether `theta` (rad) lies in the calibrated arc (1° margin).
    pub fn covers(&self, theta: f64) -> bool {
        let d = wrap_deg(theta.to_degrees());
        let [lo, hi] = self.theta_range_deg;
        d >= lo - 1.0 && d <= hi + 1.0
    }

    /// Checks a probe file read from disk.
    pub fn check(&self) -> Result<()> {
        if self.format != PROBE_FORMAT {
            bail!(
                "not a trueaxis probe file (format `{}`, expected `{PROBE_FORMAT}`)",
                self.format
            );
        }
        let n = if self.order >= 2 {
            2 * (self.order - 1)
        } else {
            0
        };
        if self.order == 1 || self.form_nm.len() != n || self.form_ci95_nm.len() != n {
            bail!(
                "order {} needs {n} form coefficients, found {}",
                self.order,
                self.form_nm.len()
            );
        }
        let finite = [self.ball_radius_mm, self.probe_radius_mm, self.form_pv_nm]
            .iter()
            .chain(&self.form_nm)
            .chain(&self.form_rigid_nm)
            .chain(&self.theta_range_deg)
            .all(|v| v.is_finite());
        if !finite
            || self.probe_radius_mm <= 0.0
            || self.theta_range_deg[0] > self.theta_range_deg[1]
        {
            bail!("a value is not finite, the probe radius not positive or the angle range empty");
        }
        Ok(())
    }
}

/// Angle in degrees wrapped to (−180, 180].
fn wrap_deg(d: f64) -> f64 {
    let mut d = d % 360.0;
    if d <= -180.0 {
        d += 360.0;
    } else if d > 180.0 {
        d -= 360.0;
    }
    d
}

/// The form order chosen by held-out RMS, shared by the 2-D and 3-D
/// calibrations: each order of `orders` is fitted (`fit(train rows,
/// order)` → the residual of every point, mm) on 4 of the 5 folds
/// (`fold[i]` ∈ 0…4) and scored on the fifth, each held-out residual's
/// square at most `clip`² (mm: one contact cannot decide); an order whose
/// fit fails on a fold is not scored. Returns the held-out RMS per order,
/// nm, and the smallest order within 2 % of the best (0 when none was
/// scored).
pub(crate) fn choose_order(
    orders: impl Iterator<Item = usize>,
    fold: &[usize],
    clip: f64,
    fit: impl Fn(&[usize], usize) -> Result<Vec<f64>>,
) -> (Vec<(usize, f64)>, usize) {
    let mut held: Vec<(usize, f64)> = Vec::new();
    'orders: for order in orders {
        let (mut ss, mut n) = (0.0, 0usize);
        for k in 0..5 {
            let train: Vec<usize> = (0..fold.len()).filter(|&i| fold[i] != k).collect();
            let Ok(resid) = fit(&train, order) else {
                continue 'orders;
            };
            for i in (0..fold.len()).filter(|&i| fold[i] == k) {
                ss += (resid[i] * resid[i]).min(clip * clip);
                n += 1;
            }
        }
        if n > 0 {
            held.push((order, (ss / n as f64).sqrt() * 1e6));
        }
    }
    let best = held.iter().map(|h| h.1).fold(f64::INFINITY, f64::min);
    let order = held.iter().find(|h| h.1 <= 1.02 * best).map_or(0, |h| h.0);
    (held, order)
}

/// Columns of the design for rows at angles `theta`: `[cos θ, sin θ, 1,
/// form…]` scaled for the Gauss–Newton step (centre x, centre z, radius,
/// form in mm).
fn form_cols(theta: f64, order: usize) -> Vec<f64> {
    let mut v = Vec::with_capacity(2 * order);
    for k in 2..=order {
        v.push((k as f64 * theta).cos());
        v.push((k as f64 * theta).sin());
    }
    v
}

/// The result of one fit at a given order.
struct Fit {
    centre: [f64; 2],
    total_radius: f64,
    form: Vec<f64>, // mm
    form_sd: Vec<f64>,
    resid: Vec<f64>, // mm, per point
}

/// Algebraic (Kåsa) circle fit: centre and radius.
pub fn kasa(p: &[[f64; 2]]) -> Result<([f64; 2], f64)> {
    let n = p.len();
    let a = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => p[i][0],
        1 => p[i][1],
        _ => 1.0,
    });
    let b = DVector::from_fn(n, |i, _| p[i][0] * p[i][0] + p[i][1] * p[i][1]);
    let s = lsq::solve(&a, &b, None)?;
    let (cx, cz) = (s.coef[0] / 2.0, s.coef[1] / 2.0);
    let r2 = s.coef[2] + cx * cx + cz * cz;
    if r2.is_nan() || r2 <= 0.0 {
        bail!("the points do not lie on a circle");
    }
    Ok(([cx, cz], r2.sqrt()))
}

/// Gauss–Newton fit of centre, total radius and a form series of `order`
/// to the rows `use_rows` of `p`.
fn fit_order(
    p: &[[f64; 2]],
    use_rows: &[usize],
    order: usize,
    start: ([f64; 2], f64),
) -> Result<Fit> {
    let nf = if order >= 2 { 2 * (order - 1) } else { 0 };
    let (mut c, mut rt) = start;
    let mut form = vec![0.0; nf];
    let mut last = None;
    for _ in 0..30 {
        let n = use_rows.len();
        let mut a = DMatrix::zeros(n, 3 + nf);
        let mut b = DVector::zeros(n);
        for (row, &i) in use_rows.iter().enumerate() {
            let (dx, dz) = (p[i][0] - c[0], p[i][1] - c[1]);
            let d = (dx * dx + dz * dz).sqrt();
            let th = dz.atan2(dx);
            let fc = form_cols(th, order);
            let f: f64 = fc.iter().zip(&form).map(|(u, v)| u * v).sum();
            // ρ = d − (rt + f); ∂ρ/∂c = −(dx, dz)/d; ∂ρ/∂rt = −1; ∂ρ/∂a = −col.
            b[row] = d - rt - f;
            a[(row, 0)] = dx / d;
            a[(row, 1)] = dz / d;
            a[(row, 2)] = 1.0;
            for (j, v) in fc.iter().enumerate() {
                a[(row, 3 + j)] = *v;
            }
        }
        let s = lsq::solve(&a, &b, None)?;
        c[0] += s.coef[0];
        c[1] += s.coef[1];
        rt += s.coef[2];
        for (j, f) in form.iter_mut().enumerate() {
            *f += s.coef[3 + j];
        }
        let step = s.coef.amax();
        last = Some(s);
        if step < 1e-12 {
            break;
        }
    }
    let s = last.expect("at least one iteration");
    let resid: Vec<f64> = (0..p.len())
        .map(|i| {
            let (dx, dz) = (p[i][0] - c[0], p[i][1] - c[1]);
            let th = dz.atan2(dx);
            let f: f64 = form_cols(th, order)
                .iter()
                .zip(&form)
                .map(|(u, v)| u * v)
                .sum();
            (dx * dx + dz * dz).sqrt() - rt - f
        })
        .collect();
    Ok(Fit {
        centre: c,
        total_radius: rt,
        form_sd: (0..nf).map(|j| s.coef_sd[3 + j]).collect(),
        form,
        resid,
    })
}

/// What a calibration says beyond the probe file: per order the held-out
/// RMS, and warnings.
#[derive(Clone, Debug, Serialize)]
pub struct Calibration {
    /// The probe file to write.
    pub probe: ProbeFile,
    /// Residual per point after the chosen model, nm (for plots).
    pub residual_nm: Vec<f64>,
    /// Contact angle per point, degrees.
    pub theta_deg: Vec<f64>,
    /// Peak to valley of the distance to the fitted circle without the
    /// form term (radius and centre only), nm — what the form correction
    /// starts from.
    pub pv_without_form_nm: f64,
    /// Peak to valley of the residual with it, nm.
    pub pv_with_form_nm: f64,
    /// Problems with the calibration data.
    pub warnings: Vec<String>,
    /// Contacts far off the ball (robust/outliers), named.
    pub outliers: Vec<Outlier>,
}

/// The highest form order `n` contacts support.
fn max_order(n: usize) -> usize {
    MAX_ORDER.min((n / 10).saturating_sub(3) / 2 + 1)
}

/// Calibrates a probe on a master ball of radius `ball_radius_mm` from the
/// probe-centre positions `p` (mm) of a 2-D scan in one plane, outlier
/// contacts left out ([`calibrate_with`]).
pub fn calibrate(p: &[[f64; 2]], ball_radius_mm: f64) -> Result<Calibration> {
    calibrate_with(p, ball_radius_mm, false)
}

/// [`calibrate`], the outlier contacts found against the most flexible
/// form ([`robust::flag`]) named and — unless `keep_outliers` — left out
/// before anything else is fitted; a coordinate quantum found in the scan
/// is the floor of every interval.
pub fn calibrate_with(
    p: &[[f64; 2]],
    ball_radius_mm: f64,
    keep_outliers: bool,
) -> Result<Calibration> {
    if !(ball_radius_mm.is_finite() && ball_radius_mm > 0.0) {
        bail!("the master ball radius must be a positive number of mm, got {ball_radius_mm}");
    }
    if p.len() < 12 {
        bail!("{} points on the ball; a calibration needs at least 12 (a few hundred along the arc for a form error)", p.len());
    }
    let q = robust::quantum(p.iter().flatten().copied());
    let floor = q.map_or(0.0, |q| q / 12f64.sqrt());
    let start = kasa(p)?;
    // Each contact against its neighbours in angle (robust::flag).
    let (rigid, theta) = rigid_fit(p, start)?;
    let near = robust::nearest(p.len(), |i, j| {
        let d = (theta[i] - theta[j]).rem_euclid(2.0 * PI);
        d.min(2.0 * PI - d)
    });
    let (flagged, cut) = robust::flag(&rigid.resid, &near, floor);
    let used: Vec<[f64; 2]> = (0..p.len())
        .filter(|i| keep_outliers || !flagged.contains(i))
        .map(|i| p[i])
        .collect();
    let mut cal = calibrate_points(&used, ball_radius_mm, cut)?;
    let pr = &cal.probe;
    cal.outliers = flagged
        .iter()
        .map(|&i| {
            let (dx, dz) = (p[i][0] - pr.centre_mm[0], p[i][1] - pr.centre_mm[1]);
            let d = dx.hypot(dz) - pr.ball_radius_mm - pr.probe_radius_mm;
            Outlier {
                index: i,
                residual_nm: d * 1e6 - pr.form_nm_at(dz.atan2(dx)),
                left_out: !keep_outliers,
            }
        })
        .collect();
    let pr = &mut cal.probe;
    let said = robust::Resolution {
        quantum_mm: &mut pr.quantum_mm,
        radius_ci95_mm: &mut pr.probe_radius_ci95_mm,
        form_ci95_nm: &mut pr.form_ci95_nm,
        residual_rms_nm: pr.residual_rms_nm,
    }
    .apply(q);
    cal.warnings.extend(said);
    Ok(cal)
}

/// The ball's centre and radius alone fitted to all of `p`, and each
/// contact's angle from that centre.
fn rigid_fit(p: &[[f64; 2]], start: ([f64; 2], f64)) -> Result<(Fit, Vec<f64>)> {
    let all: Vec<usize> = (0..p.len()).collect();
    let rigid = fit_order(p, &all, 0, start)?;
    let theta = p
        .iter()
        .map(|q| (q[1] - rigid.centre[1]).atan2(q[0] - rigid.centre[0]))
        .collect();
    Ok((rigid, theta))
}

/// The calibration proper on the contacts `p` kept; `clip` (mm) bounds
/// one held-out residual's say in the order.
fn calibrate_points(p: &[[f64; 2]], ball_radius_mm: f64, clip: f64) -> Result<Calibration> {
    if p.len() < 12 {
        bail!(
            "{} points on the ball besides the outliers; a calibration needs at least 12",
            p.len()
        );
    }
    let start = kasa(p)?;
    let all: Vec<usize> = (0..p.len()).collect();
    let (rigid, theta) = rigid_fit(p, start)?;
    // The arc, as the smallest interval of angles covering the points
    // (wrapped so that an arc through ±180° stays one interval).
    let mut deg: Vec<f64> = theta.iter().map(|t| t.to_degrees()).collect();
    deg.sort_by(f64::total_cmp);
    let mut gap = (deg[0] + 360.0 - deg[deg.len() - 1], deg.len() - 1);
    for i in 0..deg.len() - 1 {
        if deg[i + 1] - deg[i] > gap.0 {
            gap = (deg[i + 1] - deg[i], i);
        }
    }
    let (lo, hi) = if gap.1 == deg.len() - 1 {
        (deg[0], deg[deg.len() - 1])
    } else {
        (deg[gap.1 + 1], deg[gap.1] + 360.0)
    };
    let arc = hi - lo;
    let mut warnings = Vec::new();
    if arc < 90.0 {
        warnings.push(format!(
            "the scan covers {arc:.0}° of the ball: on so short an arc a form error of low order cannot be told from the probe radius and the ball centre — scan at least 120° (the contact angles the workpiece will see)"
        ));
    }
    // Folds: 20 contiguous angular blocks dealt round-robin to 5 folds.
    let fold_of = |i: usize| -> usize {
        let d = wrap_deg(theta[i].to_degrees() - lo);
        let d = if d < 0.0 { d + 360.0 } else { d };
        let block = ((d / arc.max(1e-9)) * 20.0).floor().clamp(0.0, 19.0) as usize;
        block % 5
    };
    let folds: Vec<usize> = (0..p.len()).map(fold_of).collect();
    let (held, order) = choose_order(
        std::iter::once(0).chain(2..=max_order(p.len())),
        &folds,
        clip,
        |train, order| Ok(fit_order(p, train, order, start)?.resid),
    );
    let fit = fit_order(p, &all, order, start)?;
    // Make the form orthogonal to 1, cos θ, sin θ over the calibration
    // angles: that part belongs to radius and centre.
    let thetas: Vec<f64> = p
        .iter()
        .map(|q| (q[1] - fit.centre[1]).atan2(q[0] - fit.centre[0]))
        .collect();
    let raw: Vec<f64> = thetas
        .iter()
        .map(|&t| {
            form_cols(t, order)
                .iter()
                .zip(&fit.form)
                .map(|(u, v)| u * v)
                .sum::<f64>()
                * 1e6
        })
        .collect();
    let rig = DMatrix::from_fn(p.len(), 3, |i, j| match j {
        0 => 1.0,
        1 => thetas[i].cos(),
        _ => thetas[i].sin(),
    });
    let proj = lsq::solve(&rig, &DVector::from_vec(raw.clone()), None)?;
    let form_rigid_nm = [proj.coef[0], proj.coef[1], proj.coef[2]];
    // Radius and centre take the removed part (nm → mm): moving the
    // centre by δ changes each distance by −δ·n, so the first harmonic
    // `c1 cos θ + s1 sin θ` left out of the form is a centre further by
    // (c1, s1).
    let total_radius = fit.total_radius + form_rigid_nm[0] * 1e-6;
    let centre = [
        fit.centre[0] + form_rigid_nm[1] * 1e-6,
        fit.centre[1] + form_rigid_nm[2] * 1e-6,
    ];
    // The radius's interval in this parameterisation (form orthogonal to
    // radius and centre): the rigid columns alone at the final centre,
    // with the full model's residual as the noise.
    let rig_lin = DMatrix::from_fn(p.len(), 3, |i, j| match j {
        0 => thetas[i].cos(),
        1 => thetas[i].sin(),
        _ => 1.0,
    });
    let radius_sd = lsq::solve(&rig_lin, &DVector::from_vec(fit.resid.clone()), None)?.coef_sd[2];
    let mut probe = ProbeFile {
        format: PROBE_FORMAT.into(),
        ball_radius_mm,
        probe_radius_mm: total_radius - ball_radius_mm,
        probe_radius_ci95_mm: 1.96 * radius_sd,
        centre_mm: centre,
        order,
        form_nm: fit.form.iter().map(|v| v * 1e6).collect(),
        form_ci95_nm: fit.form_sd.iter().map(|v| 1.96 * v * 1e6).collect(),
        form_rigid_nm,
        theta_range_deg: [wrap_deg(lo), wrap_deg(lo) + arc],
        form_pv_nm: 0.0,
        residual_rms_nm: 0.0,
        held_out_rms_nm: held.iter().map(|&(o, v)| [o as f64, v]).collect(),
        points: p.len(),
        quantum_mm: None,
    };
    if probe.probe_radius_mm <= 0.0 {
        bail!(
            "the fitted radius {:.6} mm is not above the master ball's {ball_radius_mm} mm: the scan is not of the probe's centre on this ball (check the ball diameter and that the rows are centre positions)",
            total_radius
        );
    }
    let form_at: Vec<f64> = thetas.iter().map(|&t| probe.form_nm_at(t)).collect();
    let (fmin, fmax) = form_at
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    probe.form_pv_nm = if order >= 2 { fmax - fmin } else { 0.0 };
    let resid_nm: Vec<f64> = fit.resid.iter().map(|v| v * 1e6).collect();
    probe.residual_rms_nm =
        (resid_nm.iter().map(|v| v * v).sum::<f64>() / resid_nm.len() as f64).sqrt();
    let without: Vec<f64> = rigid.resid.iter().map(|v| v * 1e6).collect();
    if order == 0 {
        warnings.push(
            "no form error term is supported by held-out data: the probe is calibrated as a sphere of the fitted radius".into(),
        );
    }
    Ok(Calibration {
        pv_without_form_nm: pv(&without),
        pv_with_form_nm: pv(&resid_nm),
        residual_nm: resid_nm,
        theta_deg: thetas.iter().map(|t| t.to_degrees()).collect(),
        probe,
        warnings,
        outliers: Vec::new(),
    })
}

/// Which way the part's surface faces where the probe touches it — the
/// outward normal, from the material toward the probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Side {
    /// Roughly this direction in the plane (`[0, 1]`: probed from above,
    /// +z); each normal is the centre path's, turned toward it.
    Toward([f64; 2]),
    /// Away from the centre of the circle the scan lies on: a boss or a
    /// shaft probed from outside, all round or along an arc.
    Out,
    /// Toward that centre: a bore probed from inside.
    In,
}

/// One corrected contact of a workpiece scan.
#[derive(Clone, Debug, Serialize)]
pub struct Contact {
    /// The contact point on the part, `[x, z]` mm.
    pub surface_mm: [f64; 2],
    /// Contact angle, degrees.
    pub theta_deg: f64,
    /// The probe form error applied, nm (0 outside the calibrated arc).
    pub form_nm: f64,
    /// Whether the angle lies in the calibrated arc.
    pub calibrated: bool,
}

/// Corrects a workpiece scan (probe-centre positions `p`, mm, in scan
/// order) with `probe`. `side` says which way the part's surface faces
/// where the probe touches it: it orients the normals.
pub fn correct(probe: &ProbeFile, p: &[[f64; 2]], side: Side) -> Result<Vec<Contact>> {
    correct_with(p, side, probe.probe_radius_mm, |t| {
        probe.covers(t).then(|| probe.form_nm_at(t))
    })
}

/// [`correct`] with any calibrated probe: radius `r` (mm) and `form(θ)`,
/// the form error at contact angle θ (rad, in the scan's plane), nm, or
/// `None` outside the calibrated directions (corrected with the radius
/// only, flagged). A 3-D probe file gives it with
/// [`sphere::Probe3d::in_plane`].
pub fn correct_with(
    p: &[[f64; 2]],
    side: Side,
    r: f64,
    form: impl Fn(f64) -> Option<f64>,
) -> Result<Vec<Contact>> {
    contacts_along(p, &path_normals(p, side)?, r, form)
}

/// The outward normals of the probe-centre path `p` (the tangency
/// relation: the part's normal at the contact is the centre path's):
/// toward [`Side::Toward`]'s direction from each point's neighbours, or —
/// a circle probed from outside or inside ([`Side::Out`], [`Side::In`]) —
/// along the radius of the least-squares circle through the centres,
/// exact at every point of a full circle, where no one direction could
/// orient them.
pub fn path_normals(p: &[[f64; 2]], side: Side) -> Result<Vec<[f64; 2]>> {
    if p.len() < 3 {
        bail!(
            "{} points; a scan needs at least 3 to take normals from",
            p.len()
        );
    }
    let side = match side {
        Side::Toward(d) => d,
        Side::Out | Side::In => {
            let (c, _) = kasa(p)?;
            let s = if side == Side::Out { 1.0 } else { -1.0 };
            return p
                .iter()
                .enumerate()
                .map(|(i, q)| {
                    let (dx, dz) = (q[0] - c[0], q[1] - c[1]);
                    let l = dx.hypot(dz);
                    if l.is_nan() || l <= 0.0 {
                        bail!("point {} of the scan is the centre of its circle", i + 1);
                    }
                    Ok([s * dx / l, s * dz / l])
                })
                .collect();
        }
    };
    let mut out = Vec::with_capacity(p.len());
    for i in 0..p.len() {
        let (a, b) = (p[i.saturating_sub(1)], p[(i + 1).min(p.len() - 1)]);
        let (tx, tz) = (b[0] - a[0], b[1] - a[1]);
        let len = (tx * tx + tz * tz).sqrt();
        if len.is_nan() || len <= 0.0 {
            bail!(
                "points {} and {} of the scan coincide: no tangent between them",
                i.saturating_sub(1) + 1,
                (i + 1).min(p.len() - 1) + 1
            );
        }
        let mut n = [-tz / len, tx / len];
        if n[0] * side[0] + n[1] * side[1] < 0.0 {
            n = [-n[0], -n[1]];
        }
        out.push(n);
    }
    Ok(out)
}

/// The contacts of probe-centre positions `p` along the outward unit
/// normals `normals` (one per point: the centre path's, or the nominal
/// surface's when the scan gives them — exact where the path's are only
/// a chord's, at the ends of a coarse scan): contact = centre − (r + f(θ))·n.
pub fn contacts_along(
    p: &[[f64; 2]],
    normals: &[[f64; 2]],
    r: f64,
    form: impl Fn(f64) -> Option<f64>,
) -> Result<Vec<Contact>> {
    if normals.len() != p.len() {
        bail!("{} points but {} normals", p.len(), normals.len());
    }
    let mut out = Vec::with_capacity(p.len());
    for (c, n) in p.iter().zip(normals) {
        let theta = n[1].atan2(n[0]);
        let known = form(theta);
        let calibrated = known.is_some();
        let form_nm = known.unwrap_or(0.0);
        let d = r + form_nm * 1e-6;
        out.push(Contact {
            surface_mm: [c[0] - d * n[0], c[1] - d * n[1]],
            theta_deg: theta.to_degrees(),
            form_nm,
            calibrated,
        });
    }
    Ok(out)
}

/// Deviation of points from their least-squares circle (`circle`) or line,
/// nm, signed outward / along +normal.
pub fn form_deviation_nm(s: &[[f64; 2]], circle: bool) -> Result<Vec<f64>> {
    if circle {
        let (c, r) = kasa(s)?;
        let all: Vec<usize> = (0..s.len()).collect();
        let f = fit_order(s, &all, 0, (c, r))?;
        Ok(f.resid.iter().map(|v| v * 1e6).collect())
    } else {
        let n = s.len();
        let a = DMatrix::from_fn(n, 2, |i, j| if j == 0 { s[i][0] } else { 1.0 });
        let b = DVector::from_fn(n, |i, _| s[i][1]);
        let l = lsq::solve(&a, &b, None)?;
        let k = (1.0 + l.coef[0] * l.coef[0]).sqrt();
        Ok((0..n)
            .map(|i| (s[i][1] - l.coef[0] * s[i][0] - l.coef[1]) / k * 1e6)
            .collect())
    }
}

pub use crate::onmachine::separate::pv;

/// `theta` in the convention of the module, from degrees.
pub fn rad(deg: f64) -> f64 {
    deg * PI / 180.0
}

/// Reads a probe scan: a CSV with a header naming the two columns of the
/// plane (`x_mm,z_mm` for `plane = ["x", "z"]`), `#` comment lines, one
/// probe-centre position per row (docs/on-machine.md). Other columns are
/// ignored. Errors name the file, line and column.
pub fn read_scan(text: &str, name: &str, plane: [&str; 2]) -> Result<Vec<[f64; 2]>> {
    Ok(read_scan_lines(text, name, plane)?.0)
}

/// [`read_scan`], and each point's line in the text.
pub fn read_scan_lines(
    text: &str,
    name: &str,
    plane: [&str; 2],
) -> Result<(Vec<[f64; 2]>, Vec<usize>)> {
    let cols = [format!("{}_mm", plane[0]), format!("{}_mm", plane[1])];
    let rows = crate::import::read_table(
        text,
        name,
        &[cols[0].as_str(), cols[1].as_str()],
        &format!("the probe centre in the {}{} plane", plane[0], plane[1]),
    )?;
    Ok((
        rows.iter().map(|r| [r[0], r[1]]).collect(),
        rows.iter().map(|r| r[2] as usize).collect(),
    ))
}

#[cfg(test)]
mod tests;
