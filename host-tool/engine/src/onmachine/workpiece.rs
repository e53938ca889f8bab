//! Workpiece form from on-machine probing of a turned or ground part, and
//! the correction pass (docs/on-machine.md § workpiece): points along several
//! generatrices (lines along z at fixed rotation angles c), the radial
//! deviation from the nominal at each. The seed fits a least-squares cubic
//! along each generatrix and across the circumference; here the surface is
//!
//! `dev(c, z) = Σ_{j ≤ J} Σ_{h ≤ H} (a_jh cos hc + b_jh sin hc) · L_j(z)`
//!
//! (`L_j` Legendre polynomials over the measured length, `h = 0` the mean
//! profile along z), with the degree `J` along z and the harmonics `H`
//! around chosen by held-out RMS (the seed's cubic, `J = 3`, is one of the
//! candidates, not a given): folds are checkerboard patches — contiguous z
//! blocks crossed with generatrices — so a term that only interpolates the
//! points it saw does not win. `H` is at most `(generatrices − 1) / 2`:
//! lobes above that alias and cannot be seen (said).
//!
//! The correction pass assumes the error repeats (the machine's geometry,
//! deflection, wear — what made the form): the next pass is commanded at
//! the nominal minus the fitted deviation, so the material left proud is
//! cut and a hollow is not cut deeper. Measure again to verify; the
//! history of the part shows the form falling pass by pass.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::linalg::lsq;

/// One probed point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Rotation angle, degrees.
    pub c_deg: f64,
    /// Position along the axis, mm.
    pub z_mm: f64,
    /// Radial deviation from the nominal radius, µm (+ = material proud).
    pub dev_um: f64,
}

/// The fitted form of a part.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Form {
    /// Degree along z.
    pub degree_z: usize,
    /// Harmonics around.
    pub harmonics: usize,
    /// The measured length `[z_min, z_max]`, mm.
    pub z_range_mm: [f64; 2],
    /// Coefficients, µm, in [`Form::basis`] order.
    pub coef_um: Vec<f64>,
    /// Held-out RMS per candidate `[degree_z, harmonics, µm]`.
    pub held_out_rms_um: Vec<[f64; 3]>,
    /// RMS of the points about the fitted surface, µm.
    pub residual_rms_um: f64,
    /// Peak to valley of the fitted surface over the measured length and
    /// the full circumference (its mean radius removed), µm.
    pub form_pv_um: f64,
    /// RMS of the same, µm.
    pub form_rms_um: f64,
    /// Eccentricity: amplitude of the first harmonic averaged over z, µm
    /// (the part's axis off the rotation axis: set-up, not form).
    pub eccentricity_um: f64,
    /// Generatrices (distinct angles) measured.
    pub generatrices: usize,
    /// Points fitted.
    pub points: usize,
}

/// Legendre polynomials `P_0 … P_n` at `t ∈ [−1, 1]`.
fn legendre(t: f64, n: usize) -> Vec<f64> {
    let mut p = vec![1.0, t];
    for k in 1..n {
        let k = k as f64;
        let next = ((2.0 * k + 1.0) * t * p[k as usize] - k * p[k as usize - 1]) / (k + 1.0);
        p.push(next);
    }
    p.truncate(n + 1);
    p
}

impl Form {
    /// The basis at (c, z): for j in 0..=J, h in 0..=H: L_j·cos hc, and for
    /// h ≥ 1 L_j·sin hc.
    fn basis(j_max: usize, h_max: usize, z_range: [f64; 2], c_deg: f64, z_mm: f64) -> Vec<f64> {
        let span = (z_range[1] - z_range[0]).max(1e-12);
        let t = 2.0 * (z_mm - z_range[0]) / span - 1.0;
        let l = legendre(t, j_max);
        let c = c_deg.to_radians();
        let mut v = Vec::new();
        for lj in l.iter().take(j_max + 1) {
            v.push(*lj);
            for h in 1..=h_max {
                v.push(lj * (h as f64 * c).cos());
                v.push(lj * (h as f64 * c).sin());
            }
        }
        v
    }

    /// The fitted deviation at (c, z), µm.
    pub fn at(&self, c_deg: f64, z_mm: f64) -> f64 {
        Form::basis(self.degree_z, self.harmonics, self.z_range_mm, c_deg, z_mm)
            .iter()
            .zip(&self.coef_um)
            .map(|(b, a)| b * a)
            .sum()
    }
}

fn fit_terms(
    p: &[Point],
    rows: &[usize],
    j: usize,
    h: usize,
    zr: [f64; 2],
) -> Result<DVector<f64>> {
    let ncol = (j + 1) * (2 * h + 1);
    let a = DMatrix::from_fn(rows.len(), ncol, |r, k| {
        Form::basis(j, h, zr, p[rows[r]].c_deg, p[rows[r]].z_mm)[k]
    });
    let b = DVector::from_fn(rows.len(), |r, _| p[rows[r]].dev_um);
    Ok(lsq::solve(&a, &b, None)?.coef)
}

/// As [`fit_terms`] by the normal equations (Cholesky): the hold-out's
/// many small fits, where the final fit's rank and conditioning checks
/// are not needed; `None` when the normal matrix is not positive definite.
fn fit_terms_fast(
    p: &[Point],
    rows: &[usize],
    j: usize,
    h: usize,
    zr: [f64; 2],
) -> Option<DVector<f64>> {
    let ncol = (j + 1) * (2 * h + 1);
    let mut ata = DMatrix::zeros(ncol, ncol);
    let mut atb = DVector::zeros(ncol);
    for &i in rows {
        let v = Form::basis(j, h, zr, p[i].c_deg, p[i].z_mm);
        for a in 0..ncol {
            atb[a] += v[a] * p[i].dev_um;
            for b in 0..ncol {
                ata[(a, b)] += v[a] * v[b];
            }
        }
    }
    ata.cholesky().map(|c| c.solve(&atb))
}

/// The distinct generatrix angles (to 0.01°), ascending.
fn generatrices(p: &[Point]) -> Vec<i64> {
    let mut g: Vec<i64> = p
        .iter()
        .map(|q| (q.c_deg.rem_euclid(360.0) * 100.0).round() as i64 % 36000)
        .collect();
    g.sort_unstable();
    g.dedup();
    g
}

/// Fits the form of a part from its probed points; `warnings` receives
/// what the data cannot show.
pub fn fit(p: &[Point], warnings: &mut Vec<String>) -> Result<Form> {
    if p.len() < 8 {
        bail!("{} points; a workpiece form needs at least 8", p.len());
    }
    let gens = generatrices(p);
    let zr = p
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[a, b], q| {
            [a.min(q.z_mm), b.max(q.z_mm)]
        });
    let mut zs: Vec<i64> = p.iter().map(|q| (q.z_mm * 1000.0).round() as i64).collect();
    zs.sort_unstable();
    zs.dedup();
    let h_max = ((gens.len().saturating_sub(1)) / 2).min(8);
    let j_max = zs.len().saturating_sub(1).min(5);
    if gens.len() < 3 {
        warnings.push(format!(
            "{} generatrix(es): the form around the part (roundness, lobing) cannot be known from them — measure at least 5 angles (N angles show lobes up to (N − 1)/2)",
            gens.len()
        ));
    } else {
        warnings.push(format!(
            "{} generatrices show lobes up to {h_max} per turn; more lobes (a {}-lobe chatter, say) alias into fewer — measure more angles to see them",
            gens.len(),
            h_max + 1
        ));
    }
    // Folds: z in 4 contiguous blocks × generatrix index, mod 5.
    let fold = |q: &Point| -> usize {
        let g = gens
            .iter()
            .position(|&a| a == (q.c_deg.rem_euclid(360.0) * 100.0).round() as i64 % 36000)
            .unwrap_or(0);
        let zb = (((q.z_mm - zr[0]) / (zr[1] - zr[0]).max(1e-12)) * 4.0)
            .floor()
            .clamp(0.0, 3.0) as usize;
        (g + zb) % 5
    };
    let folds: Vec<usize> = p.iter().map(fold).collect();
    let mut held = Vec::new();
    for j in 0..=j_max {
        for h in 0..=h_max {
            let ncol = (j + 1) * (2 * h + 1);
            let mut ss = 0.0;
            let mut n = 0usize;
            let mut ok = true;
            for f in 0..5 {
                let train: Vec<usize> = (0..p.len()).filter(|&i| folds[i] != f).collect();
                if train.len() <= ncol {
                    ok = false;
                    break;
                }
                match fit_terms_fast(p, &train, j, h, zr) {
                    Some(coef) => {
                        for i in (0..p.len()).filter(|&i| folds[i] == f) {
                            let pred: f64 = Form::basis(j, h, zr, p[i].c_deg, p[i].z_mm)
                                .iter()
                                .zip(coef.iter())
                                .map(|(b, a)| b * a)
                                .sum();
                            ss += (p[i].dev_um - pred).powi(2);
                            n += 1;
                        }
                    }
                    None => {
                        ok = false;
                        break;
                    }
                }
            }
            if ok && n > 0 {
                held.push([j as f64, h as f64, (ss / n as f64).sqrt()]);
            }
        }
    }
    if held.is_empty() {
        bail!(
            "no surface could be fitted and held out on these points (too few along z or around)"
        );
    }
    let best = held.iter().map(|h| h[2]).fold(f64::INFINITY, f64::min);
    // The fewest terms within 2 % of the best held-out RMS.
    let pick = held
        .iter()
        .filter(|h| h[2] <= 1.02 * best)
        .min_by_key(|h| ((h[0] as usize + 1) * (2 * h[1] as usize + 1), h[0] as usize))
        .copied()
        .expect("the best is within 2 % of itself");
    let (j, h) = (pick[0] as usize, pick[1] as usize);
    let all: Vec<usize> = (0..p.len()).collect();
    let coef = fit_terms(p, &all, j, h, zr)?;
    let mut form = Form {
        degree_z: j,
        harmonics: h,
        z_range_mm: zr,
        coef_um: coef.iter().copied().collect(),
        held_out_rms_um: held,
        residual_rms_um: 0.0,
        form_pv_um: 0.0,
        form_rms_um: 0.0,
        eccentricity_um: 0.0,
        generatrices: gens.len(),
        points: p.len(),
    };
    let res: Vec<f64> = p
        .iter()
        .map(|q| q.dev_um - form.at(q.c_deg, q.z_mm))
        .collect();
    form.residual_rms_um = (res.iter().map(|v| v * v).sum::<f64>() / res.len() as f64).sqrt();
    // The surface on a 1° × 50-step grid, its mean removed.
    let grid: Vec<f64> = (0..360)
        .flat_map(|c| (0..=50).map(move |k| (c as f64, zr[0] + (zr[1] - zr[0]) * k as f64 / 50.0)))
        .map(|(c, z)| form.at(c, z))
        .collect();
    let mean = grid.iter().sum::<f64>() / grid.len() as f64;
    form.form_pv_um = crate::onmachine::separate::pv(&grid);
    form.form_rms_um =
        (grid.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / grid.len() as f64).sqrt();
    if h >= 1 {
        // a_01, b_01: the j = 0 first harmonic (mean over z of Legendre P0).
        form.eccentricity_um = form.coef_um[1].hypot(form.coef_um[2]);
    }
    Ok(form)
}

/// The correction pass: at each (c, z) the radial command offset, µm — the
/// fitted deviation with its sign turned (cut deeper where the part is
/// proud).
pub fn correction_um(form: &Form, c_deg: f64, z_mm: f64) -> f64 {
    -form.at(c_deg, z_mm)
}

/// A G-code dialect for the correction pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// Fanuc / ISO 6983: `%`, `O` program number, `G90 G21`, `M30`.
    Fanuc,
    /// Siemens Sinumerik: `G90 G71`, `M30`.
    Siemens,
}

/// A pass grid that cannot be walked: a C step outside (0, 90]° or no Z
/// step. Its text names the Z step count in the engine's words; a caller
/// with a flag for it writes [`PassGridError::text`] with the flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}", PassGridError::text("a Z step count"))]
pub struct PassGridError;

impl PassGridError {
    /// The message, the Z step count called `z_steps`.
    pub fn text(z_steps: &str) -> String {
        format!("the C step must be in (0, 90]° and the Z stations at least 2 ({z_steps} ≥ 1)")
    }
}

/// The points of the correction pass `[c_deg, z_mm]`: at each of
/// `z_steps + 1` stations along the measured length, a closed turn (0° …
/// 360°) in steps of about `c_step_deg` (360° divided evenly). The G-code
/// and the CSV of the pass both walk it.
pub fn pass_points(form: &Form, c_step_deg: f64, z_steps: usize) -> Result<Vec<[f64; 2]>> {
    if !(c_step_deg > 0.0 && c_step_deg <= 90.0) || z_steps == 0 {
        return Err(PassGridError.into());
    }
    let [z0, z1] = form.z_range_mm;
    let steps = (360.0 / c_step_deg).round() as usize;
    Ok((0..=z_steps)
        .flat_map(|k| {
            let z = z0 + (z1 - z0) * k as f64 / z_steps as f64;
            (0..=steps).map(move |i| [360.0 * i as f64 / steps as f64, z])
        })
        .collect())
}

/// The correction pass as G-code: `X` in diameter (mm), `Z` (mm), `C` (°),
/// a point every `c_step_deg` around at each of `z_steps + 1` stations
/// along the measured length, `X = nominal diameter + 2 · offset`.
pub fn gcode(
    form: &Form,
    dialect: Dialect,
    nominal_diameter_mm: f64,
    feed_mm_min: f64,
    c_step_deg: f64,
    z_steps: usize,
) -> Result<String> {
    if !nominal_diameter_mm.is_finite() || nominal_diameter_mm <= 0.0 {
        bail!("the nominal diameter must be a positive number of mm");
    }
    if feed_mm_min.is_nan() || feed_mm_min <= 0.0 {
        bail!("the feed must be positive");
    }
    let points = pass_points(form, c_step_deg, z_steps)?;
    let mut s = String::new();
    let head = match dialect {
        Dialect::Fanuc => "%\nO1000 (TRUEAXIS CORRECTION PASS)\nG90 G21 G94\n",
        Dialect::Siemens => "; trueaxis correction pass\nG90 G71 G94\n",
    };
    s.push_str(head);
    for [c, z] in points {
        let x = nominal_diameter_mm + 2.0 * correction_um(form, c, z) * 1e-3;
        let line = match dialect {
            Dialect::Fanuc => format!("G01 X{x:.4} Z{z:.3} C{c:.3} F{feed_mm_min:.1}\n"),
            Dialect::Siemens => format!("G1 X={x:.4} Z={z:.3} C={c:.3} F={feed_mm_min:.1}\n"),
        };
        s.push_str(&line);
    }
    s.push_str(match dialect {
        Dialect::Fanuc => "M30\n%\n",
        Dialect::Siemens => "M30\n",
    });
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_test_support::SplitMix64;

    /// A part with a 3 µm taper, a 2 µm barrel, a 1.5 µm 3-lobe form and
    /// 4 µm of eccentricity, probed on 12 generatrices × 21 stations, 0.2 µm
    /// noise.
    fn part(noise: f64) -> (Vec<Point>, impl Fn(f64, f64) -> f64) {
        let truth = |c: f64, z: f64| {
            let t = (z - 50.0) / 50.0;
            let cr = c.to_radians();
            1.5 * t + 2.0 * (t * t - 1.0 / 3.0) + 1.5 * (3.0 * cr).cos() + 4.0 * cr.sin()
        };
        let mut rng = SplitMix64(4);
        let mut p = Vec::new();
        for g in 0..12 {
            for k in 0..=20 {
                let (c, z) = (30.0 * g as f64, 5.0 * k as f64);
                p.push(Point {
                    c_deg: c,
                    z_mm: z,
                    dev_um: truth(c, z) + noise * rng.normal(),
                });
            }
        }
        (p, truth)
    }

    #[test]
    fn the_form_of_a_part_is_found_with_the_terms_the_data_support() {
        let (p, truth) = part(0.2);
        let mut w = Vec::new();
        let f = fit(&p, &mut w).unwrap();
        assert_eq!((f.degree_z, f.harmonics), (2, 3), "{:?}", f.held_out_rms_um);
        assert!(
            (f.residual_rms_um - 0.2).abs() < 0.04,
            "{}",
            f.residual_rms_um
        );
        assert!(
            (f.eccentricity_um - 4.0).abs() < 0.1,
            "{}",
            f.eccentricity_um
        );
        let worst = (0..360)
            .step_by(7)
            .flat_map(|c| (0..=10).map(move |k| (c as f64, 10.0 * k as f64)))
            .map(|(c, z)| (f.at(c, z) - truth(c, z)).abs())
            .fold(0.0f64, f64::max);
        assert!(worst < 0.25, "{worst}");
        assert!(w.iter().any(|m| m.contains("lobes up to 5")), "{w:?}");
    }

    #[test]
    fn a_correction_pass_removes_a_repeating_error() {
        let (p, _) = part(0.0);
        let f = fit(&p, &mut Vec::new()).unwrap();
        // The machine repeats its error: the next part is the error plus
        // the commanded offset.
        let after: Vec<f64> = p
            .iter()
            .map(|q| q.dev_um + correction_um(&f, q.c_deg, q.z_mm))
            .collect();
        let pv = crate::onmachine::separate::pv;
        let before: Vec<f64> = p.iter().map(|q| q.dev_um).collect();
        assert!(
            pv(&before) > 10.0 && pv(&after) < 0.01,
            "{} → {}",
            pv(&before),
            pv(&after)
        );
        let g = gcode(&f, Dialect::Fanuc, 40.0, 200.0, 30.0, 4).unwrap();
        assert!(g.starts_with("%\nO1000") && g.ends_with("M30\n%\n"));
        assert_eq!(g.lines().filter(|l| l.starts_with("G01 ")).count(), 5 * 13);
        // At c = 90°, z = 0 the part is proud by 1.5·(−1) + 2·(2/3) + 1.5·cos 270° + 4 = 3.83 µm:
        // the command cuts 2 × 3.83 µm deeper on the diameter.
        let line = g.lines().find(|l| l.contains(" Z0.000 C90.000")).unwrap();
        let x: f64 = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix('X'))
            .unwrap()
            .parse()
            .unwrap();
        assert!((x - (40.0 - 2.0 * 3.8333e-3)).abs() < 2e-4, "{line}");
        let s = gcode(&f, Dialect::Siemens, 40.0, 200.0, 30.0, 4).unwrap();
        assert!(s.contains("G1 X=") && !s.contains('%'));
    }

    #[test]
    fn two_generatrices_say_roundness_is_unknown() {
        let (p, _) = part(0.2);
        let two: Vec<Point> = p
            .into_iter()
            .filter(|q| q.c_deg == 0.0 || q.c_deg == 180.0)
            .collect();
        let mut w = Vec::new();
        let f = fit(&two, &mut w).unwrap();
        assert_eq!(f.harmonics, 0);
        assert!(w[0].contains("cannot be known"), "{w:?}");
    }
}
