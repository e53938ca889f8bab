//! What the on-machine wing's CLI tests share: a profile's peak to valley,
//! the least-squares circle (`1, cos θ, sin θ`) taken out of a profile,
//! the least-squares line taken out of a straightness profile, the rows
//! of a corrected scan (`probe correct`'s output) and a calibration on the
//! 4 mm master ball.

use std::path::Path;

use serde_json::Value;

use super::{json, run, s};

/// Peak to valley.
pub fn pv(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::MIN, f64::max) - v.iter().copied().fold(f64::MAX, f64::min)
}

/// The least-squares fit of `f` by `c0 + c1 cos θ + s1 sin θ` over
/// `angles` (normal equations, 3 × 3, Cramer's rule).
pub fn rigid_fit(angles: &[f64], f: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut m = [[0.0; 3]; 3];
    let mut v = [0.0; 3];
    for &t in angles {
        let b = [1.0, t.cos(), t.sin()];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += b[i] * b[j];
            }
            v[i] += b[i] * f(t);
        }
    }
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    [0, 1, 2].map(|k| {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = v[i];
        }
        det(mk) / d
    })
}

/// `f` minus its least-squares fit by `c0 + c1 cos θ + s1 sin θ` over
/// `angles`, at each angle: what is left once radius and centre are fitted.
pub fn without_rigid(angles: &[f64], f: impl Fn(f64) -> f64) -> Vec<f64> {
    let c = rigid_fit(angles, &f);
    angles
        .iter()
        .map(|&t| f(t) - c[0] - c[1] * t.cos() - c[2] * t.sin())
        .collect()
}

/// The peak to valley of `f` over `xs` once its least-squares line is
/// removed.
pub fn pv_line_removed(xs: &[f64], f: &dyn Fn(f64) -> f64) -> f64 {
    let n = xs.len() as f64;
    let (mx, my) = (
        xs.iter().sum::<f64>() / n,
        xs.iter().map(|&x| f(x)).sum::<f64>() / n,
    );
    let k = xs.iter().map(|&x| (x - mx) * (f(x) - my)).sum::<f64>()
        / xs.iter().map(|&x| (x - mx).powi(2)).sum::<f64>();
    let r: Vec<f64> = xs.iter().map(|&x| f(x) - my - k * (x - mx)).collect();
    pv(&r)
}

/// The rows of a corrected scan (`x_mm, z_mm, theta_deg, probe_form_nm,
/// calibrated, deviation_nm`; `calibrated` as 1.0 or 0.0).
pub fn surface_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|c| if c == "true" { 1.0 } else { c.parse().unwrap() })
                .collect()
        })
        .collect()
}

/// `trueaxis probe calibrate SCAN --ball-diameter-mm 4 [--plane xyz] -o
/// OUT` with `more` and `--json`: its document.
pub fn calibrate_on_4mm_ball(scan: &Path, xyz: bool, out: &Path, more: &[&str]) -> Value {
    let mut args = vec!["probe", "calibrate", s(scan), "--ball-diameter-mm", "4"];
    if xyz {
        args.extend(["--plane", "xyz"]);
    }
    args.extend(["-o", s(out)]);
    args.extend(more);
    args.push("--json");
    json(&run(&args))
}

/// A part's scan corrected with a probe file: `trueaxis probe correct
/// SCAN --probe PROBE -o OUT` with `more` and `--json`: its document, the
/// rows written (as [`surface_rows`]) and their contact angles, radians.
pub fn correct_scan(
    scan: &Path,
    probe: &Path,
    out: &Path,
    more: &[&str],
) -> (Value, Vec<Vec<f64>>, Vec<f64>) {
    let mut args = vec!["probe", "correct", s(scan), "--probe", s(probe)];
    args.extend(more);
    args.extend(["-o", s(out), "--json"]);
    let doc = json(&run(&args));
    let rows = surface_rows(out);
    let theta = rows.iter().map(|r| r[2].to_radians()).collect();
    (doc, rows, theta)
}

/// The contact directions of the 3-D ball scans: the pole and 10 rings
/// (8.5° apart in polar angle) of 36 azimuths (10° apart).
pub fn ball_scan_dirs() -> Vec<[f64; 3]> {
    let mut dirs = vec![[0.0, 0.0, 1.0]];
    for ring in 1..=10 {
        let pol = (8.5 * ring as f64).to_radians();
        for j in 0..36 {
            let az = (10.0 * j as f64).to_radians();
            dirs.push([pol.sin() * az.cos(), pol.sin() * az.sin(), pol.cos()]);
        }
    }
    dirs
}

/// The probe's form as a function of its contact direction (3-D): lobes
/// around the stylus growing toward the equator and a term in the polar
/// angle (~170 nm PV over the upper hemisphere).
pub fn probe_form_3d_nm(n: [f64; 3]) -> f64 {
    let s = (1.0 - n[2] * n[2]).max(0.0).sqrt();
    let az = n[1].atan2(n[0]);
    60.0 * s.powi(3) * (3.0 * az).cos() + 40.0 * n[2] * n[2] - 25.0 * s * s * (2.0 * az).sin()
}
