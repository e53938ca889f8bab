//! A simulated on-machine measurement campaign (docs/on-machine.md,
//! "Simulated campaign"): every file the on-machine commands read, made
//! from hidden effects with known values, so each command is tested
//! against a known answer — a lobed probe of known radius and form, a part
//! of known form, a slide of known straightness, a spindle of known error
//! motion, and a grinder that removes a known fraction of the depth it is
//! commanded to remove.
//!
//! `trueaxis simulate --scenario on-machine -o DIR` writes [`FILES`] and
//! `truth.json` (a [`Truth`]); with `--after-pass PASS.csv` it writes the
//! part's scan after that correction pass was ground instead.

use std::f64::consts::PI;

use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::simulate::normal;

pub mod cases;

/// The scenario's name.
pub const ON_MACHINE: &str = "on-machine";

/// The files of the campaign, in the order they are written.
pub const FILES: [&str; 10] = [
    "ball.csv",
    "ball3d.csv",
    "part.csv",
    "run0.csv",
    "run180.csv",
    "three-probe.csv",
    "multi-step.csv",
    "grinder.csv",
    "roundness.csv",
    "truth.json",
];

/// Master ball diameter, mm.
pub const BALL_DIAMETER_MM: f64 = 4.0;
/// The probe's nominal radius, mm (what a user would assume).
pub const PROBE_NOMINAL_RADIUS_MM: f64 = 0.5;
/// Its true effective radius, mm.
pub const PROBE_RADIUS_MM: f64 = 0.49715;
/// Probe reading noise (ball and part scans), nm (standard deviation).
pub const PROBE_NOISE_NM: f64 = 5.0;
/// Three-probe spacing, degrees.
pub const THREE_PROBE_ANGLES_DEG: [f64; 3] = [0.0, 99.84, 202.5];
/// Multi-step: number of steps.
pub const STEPS: usize = 5;
/// The grinder removes this fraction of the commanded depth.
pub const REMOVAL_EFFICIENCY: f64 = 0.8;
/// Grinder scan: generatrices (rotation angles) and points along z.
pub const GENERATRICES: usize = 12;
/// Points per generatrix.
pub const Z_POINTS: usize = 41;
/// Measured length along z, mm.
pub const LENGTH_MM: f64 = 120.0;
/// Dial-gauge noise of the µm-scale runs (reversal, roundness, grinder), µm.
pub const GAUGE_NOISE_UM: f64 = 0.05;
/// Thermal drift of the reading during the timed roundness scan, µm/min.
pub const THERMAL_DRIFT_UM_PER_MIN: f64 = 0.05;
/// Seconds per degree of the timed roundness scan (one turn: 12 min).
pub const ROUNDNESS_S_PER_DEG: f64 = 2.0;

/// The probe's form error in contact direction `n` (unit vector), nm:
/// three lobes round the stylus growing toward the equator and a term in
/// the polar angle. In the XZ plane at contact angle θ it is
/// `probe_form_nm([cos θ, 0, sin θ])`.
pub fn probe_form_nm(n: [f64; 3]) -> f64 {
    let s = (1.0 - n[2] * n[2]).max(0.0).sqrt();
    let az = n[1].atan2(n[0]);
    60.0 * s.powi(3) * (3.0 * az).cos() + 40.0 * n[2] * n[2] - 25.0 * s * s * (2.0 * az).sin()
}

/// The 2-D part (a 25 mm radius in XZ): its form, nm, at angle θ.
pub fn part_arc_form_nm(t: f64) -> f64 {
    100.0 * (6.0 * t).cos()
}

/// The straight part of the reversal runs: its form, µm, at x (mm).
pub fn straight_part_um(x: f64) -> f64 {
    let u = x / 200.0;
    1.5 * (2.0 * PI * u).sin() + 0.8 * (u - 0.5).powi(2) * 4.0
}

/// The slide's straightness, µm, at x (mm).
pub fn slide_um(x: f64) -> f64 {
    let u = x / 200.0;
    2.0 * (PI * u).sin() + 0.6 * (5.0 * PI * u + 0.3).cos()
}

/// The turned part's roundness, µm, at part angle t (rad).
pub fn roundness_um(t: f64) -> f64 {
    2.0 * (3.0 * t).cos() + 1.0 * (7.0 * t + 0.4).sin() + 0.5 * (10.0 * t).cos()
}

/// The spindle's radial error motion (x along probe 1, y at +90°), µm.
pub fn spindle_xy_um(t: f64) -> [f64; 2] {
    [
        0.6 * (2.0 * t + 0.3).cos() + 0.3 * (4.0 * t).sin(),
        0.5 * (2.0 * t).sin() + 0.2 * (5.0 * t + 1.0).cos(),
    ]
}

/// The ground part's deviation from its nominal radius before any pass,
/// µm (`+` = proud): a taper, a barrel and three lobes.
pub fn grinder_form_um(c_deg: f64, z_mm: f64) -> f64 {
    let u = 2.0 * z_mm / LENGTH_MM - 1.0;
    let c = c_deg.to_radians();
    4.0 * u + 6.0 * (1.5 * u * u - 0.5) + 2.5 * (3.0 * c).cos() * (1.0 + 0.3 * u)
}

/// What the campaign hides, written to `truth.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Truth {
    /// The scenario's name.
    pub scenario: &'static str,
    /// Seed of the noise.
    pub seed: u64,
    /// Master ball diameter, mm.
    pub ball_diameter_mm: f64,
    /// The probe's effective radius, mm, and its nominal one.
    pub probe_radius_mm: f64,
    /// Nominal probe radius, mm.
    pub probe_nominal_radius_mm: f64,
    /// Probe form: the formula (docs/on-machine.md).
    pub probe_form: &'static str,
    /// Probe and gauge noise.
    pub probe_noise_nm: f64,
    /// Gauge noise, µm.
    pub gauge_noise_um: f64,
    /// Peak to valley of the straight part's form and of the slide, µm
    /// (each with its least-squares line removed, over 0…200 mm).
    pub reversal_part_pv_um: f64,
    /// See above.
    pub reversal_slide_pv_um: f64,
    /// Three-probe angles, degrees.
    pub three_probe_angles_deg: [f64; 3],
    /// Peak to valley of the roundness, µm.
    pub roundness_pv_um: f64,
    /// The spindle's synchronous radial error motion along probe 1 (x),
    /// ISO 230-7 (once-per-turn term left out; it has none), µm.
    pub spindle_error_motion_um: f64,
    /// Multi-step steps.
    pub multi_step_steps: usize,
    /// The grinder's removal efficiency.
    pub removal_efficiency: f64,
    /// Peak to valley of the ground part's form over the measured length,
    /// µm (mean radius removed).
    pub grinder_form_pv_um: f64,
    /// Thermal drift of the reading during `roundness.csv`, µm/min.
    pub thermal_drift_um_per_min: f64,
}

fn pv(v: impl Iterator<Item = f64>) -> f64 {
    let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    hi - lo
}

/// `v` minus its least-squares line over `x`.
fn detrend(x: &[f64], v: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let (mx, mv) = (x.iter().sum::<f64>() / n, v.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let sxv: f64 = x.iter().zip(v).map(|(a, b)| (a - mx) * (b - mv)).sum();
    let k = sxv / sxx;
    x.iter()
        .zip(v)
        .map(|(a, b)| b - mv - k * (a - mx))
        .collect()
}

/// The grinder's scan points: `GENERATRICES` angles × `Z_POINTS` along z.
fn grinder_points() -> Vec<[f64; 2]> {
    let mut p = Vec::new();
    for g in 0..GENERATRICES {
        let c = 360.0 * g as f64 / GENERATRICES as f64;
        for k in 0..Z_POINTS {
            p.push([c, LENGTH_MM * k as f64 / (Z_POINTS - 1) as f64]);
        }
    }
    p
}

fn grinder_csv(dev: impl Fn(f64, f64) -> f64, rng: &mut ChaCha8Rng, what: &str) -> String {
    let mut s = format!(
        "# generator: trueaxis simulate, scenario on-machine ({what})\nc_deg,z_mm,dev_um\n"
    );
    for [c, z] in grinder_points() {
        let v = dev(c, z) + GAUGE_NOISE_UM * normal(rng);
        s.push_str(&format!("{c},{z},{v:.4}\n"));
    }
    s
}

/// The campaign: `(file name, content)` for each of [`FILES`].
pub fn campaign(seed: u64) -> Vec<(&'static str, String)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rb = BALL_DIAMETER_MM / 2.0;
    let head = |what: &str, cols: &str| {
        format!("# generator: trueaxis simulate, scenario on-machine ({what})\n# seed: {seed}\n{cols}\n")
    };
    // 2-D ball: 401 contacts over 10°…170° in XZ, ball at (100, 50).
    let mut ball = head("master ball, XZ arc, probe centre at contact", "x_mm,z_mm");
    for i in 0..=400 {
        let t = (10.0 + 160.0 * i as f64 / 400.0f64).to_radians();
        let f = probe_form_nm([t.cos(), 0.0, t.sin()]) + PROBE_NOISE_NM * normal(&mut rng);
        let d = rb + PROBE_RADIUS_MM + f * 1e-6;
        ball.push_str(&format!(
            "{:.7},{:.7}\n",
            100.0 + d * t.cos(),
            50.0 + d * t.sin()
        ));
    }
    // 3-D ball: the pole and 10 rings to 85°, 36 contacts each.
    let mut ball3d = head("master ball, upper hemisphere", "x_mm,y_mm,z_mm");
    for ring in 0..=10 {
        let pol = (8.5 * ring as f64).to_radians();
        for j in 0..(if ring == 0 { 1 } else { 36 }) {
            let az = (10.0 * j as f64).to_radians();
            let n = [pol.sin() * az.cos(), pol.sin() * az.sin(), pol.cos()];
            let d = rb
                + PROBE_RADIUS_MM
                + (probe_form_nm(n) + PROBE_NOISE_NM * normal(&mut rng)) * 1e-6;
            ball3d.push_str(&format!(
                "{:.7},{:.7},{:.7}\n",
                100.0 + d * n[0],
                20.0 + d * n[1],
                50.0 + d * n[2]
            ));
        }
    }
    // A 2-D part scan with the same probe: 25 mm radius, 6 lobes, 20°…160°.
    let mut part = head("part arc in XZ, probe centre at contact", "x_mm,z_mm");
    for i in 0..=500 {
        let t = (20.0 + 140.0 * i as f64 / 500.0f64).to_radians();
        let surf = 25.0 + part_arc_form_nm(t) * 1e-6;
        let d = surf
            + PROBE_RADIUS_MM
            + (probe_form_nm([t.cos(), 0.0, t.sin()]) + PROBE_NOISE_NM * normal(&mut rng)) * 1e-6;
        part.push_str(&format!("{:.7},{:.7}\n", d * t.cos(), d * t.sin()));
    }
    // Reversal: 0…200 mm every 2 mm; each set-up adds its own line.
    let xs: Vec<f64> = (0..=100).map(|i| 2.0 * i as f64).collect();
    let mut run0 = head("reversal, part at 0°", "x_mm,d_um");
    let mut run180 = head("reversal, part turned 180°, probe reversed", "x_mm,d_um");
    for &x in &xs {
        let v0 =
            straight_part_um(x) + slide_um(x) + 0.3 + 0.004 * x + GAUGE_NOISE_UM * normal(&mut rng);
        run0.push_str(&format!("{x},{v0:.4}\n"));
    }
    for &x in &xs {
        let v1 =
            straight_part_um(x) - slide_um(x) - 1.1 + 0.002 * x + GAUGE_NOISE_UM * normal(&mut rng);
        run180.push_str(&format!("{x},{v1:.4}\n"));
    }
    // Three probes, 360 samples per turn, two turns.
    let mut three = head(
        "three probes round a turning part",
        "c_deg,p1_um,p2_um,p3_um",
    );
    for turn in 0..2 {
        for i in 0..360 {
            let t = (i as f64).to_radians();
            let [sx, sy] = spindle_xy_um(t);
            let mut row = format!("{}", i + 360 * turn);
            for a in THREE_PROBE_ANGLES_DEG {
                let a = a.to_radians();
                let v = roundness_um(t - a)
                    + sx * a.cos()
                    + sy * a.sin()
                    + GAUGE_NOISE_UM * normal(&mut rng);
                row.push_str(&format!(",{v:.4}"));
            }
            three.push_str(&row);
            three.push('\n');
        }
    }
    // Multi-step: the same part remounted at STEPS steps, one probe at 0°.
    let mut multi = head(
        "multi-step: one probe, the part remounted",
        "c_deg,step_deg,p_um",
    );
    for j in 0..STEPS {
        let st = 360.0 * j as f64 / STEPS as f64;
        for i in 0..360 {
            let t = (i as f64).to_radians();
            // Each remounting recentres the part (harmonic 1).
            let v = roundness_um(t - st.to_radians())
                + spindle_xy_um(t)[0]
                + 1.5 * j as f64 * (t + 0.2 * j as f64).cos()
                + GAUGE_NOISE_UM * normal(&mut rng);
            multi.push_str(&format!("{i},{st},{v:.4}\n"));
        }
    }
    let grinder = grinder_csv(grinder_form_um, &mut rng, "ground part before a pass");
    // One probe round the part as mounted in the multi-step's first step,
    // timed and closing the turn (0…360°), while the reading drifts.
    let mut round = head(
        "one probe round a turning part, timed, closing the turn; the reading drifts",
        "c_deg,p_um,t_s",
    );
    for i in 0..=360 {
        let t = (i as f64).to_radians();
        let t_s = ROUNDNESS_S_PER_DEG * i as f64;
        let v = roundness_um(t)
            + spindle_xy_um(t)[0]
            + 0.8 * (t + 0.5).cos()
            + THERMAL_DRIFT_UM_PER_MIN * t_s / 60.0
            + GAUGE_NOISE_UM * normal(&mut rng);
        round.push_str(&format!("{i},{v:.4},{t_s}\n"));
    }
    let truth = truth(seed);
    vec![
        ("ball.csv", ball),
        ("ball3d.csv", ball3d),
        ("part.csv", part),
        ("run0.csv", run0),
        ("run180.csv", run180),
        ("three-probe.csv", three),
        ("multi-step.csv", multi),
        ("grinder.csv", grinder),
        ("roundness.csv", round),
        (
            "truth.json",
            serde_json::to_string_pretty(&truth).expect("plain data") + "\n",
        ),
    ]
}

/// The hidden values of the campaign.
pub fn truth(seed: u64) -> Truth {
    let xs: Vec<f64> = (0..=2000).map(|i| 0.1 * i as f64).collect();
    let p: Vec<f64> = xs.iter().map(|&x| straight_part_um(x)).collect();
    let s: Vec<f64> = xs.iter().map(|&x| slide_um(x)).collect();
    let g = grinder_points();
    let mean = g.iter().map(|q| grinder_form_um(q[0], q[1])).sum::<f64>() / g.len() as f64;
    Truth {
        scenario: ON_MACHINE,
        seed,
        ball_diameter_mm: BALL_DIAMETER_MM,
        probe_radius_mm: PROBE_RADIUS_MM,
        probe_nominal_radius_mm: PROBE_NOMINAL_RADIUS_MM,
        probe_form: "60 sin³(polar) cos(3 az) + 40 cos²(polar) − 25 sin²(polar) sin(2 az) nm",
        probe_noise_nm: PROBE_NOISE_NM,
        gauge_noise_um: GAUGE_NOISE_UM,
        reversal_part_pv_um: pv(detrend(&xs, &p).into_iter()),
        reversal_slide_pv_um: pv(detrend(&xs, &s).into_iter()),
        three_probe_angles_deg: THREE_PROBE_ANGLES_DEG,
        roundness_pv_um: pv((0..3600).map(|i| roundness_um((i as f64 / 10.0).to_radians()))),
        spindle_error_motion_um: pv(
            (0..3600).map(|i| spindle_xy_um((i as f64 / 10.0).to_radians())[0])
        ),
        multi_step_steps: STEPS,
        removal_efficiency: REMOVAL_EFFICIENCY,
        grinder_form_pv_um: pv(g.iter().map(|q| grinder_form_um(q[0], q[1]) - mean)),
        thermal_drift_um_per_min: THERMAL_DRIFT_UM_PER_MIN,
    }
}

/// The ground part re-measured after a correction pass: `pass` holds the
/// pass's points `[c_deg, z_mm, offset_um]` (the `--pass-csv` of
/// `trueaxis workpiece`: the commanded radial offset, `−` = cut deeper);
/// the grinder removes [`REMOVAL_EFFICIENCY`] of each commanded depth, so
/// the part's deviation becomes `dev + η·offset` (the offset interpolated
/// bilinearly over the pass's grid, periodic in c). Fails when the pass
/// does not cover the scanned length or is not a grid.
pub fn after_pass(seed: u64, pass: &[[f64; 3]]) -> anyhow::Result<String> {
    let mut zs: Vec<f64> = pass.iter().map(|p| p[1]).collect();
    zs.sort_by(f64::total_cmp);
    zs.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let mut cs: Vec<f64> = pass.iter().map(|p| p[0].rem_euclid(360.0)).collect();
    cs.sort_by(f64::total_cmp);
    cs.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    if zs.len() < 2 || cs.len() < 3 {
        anyhow::bail!(
            "the pass has {} stations along z and {} angles; a pass grid needs at least 2 and 3",
            zs.len(),
            cs.len()
        );
    }
    if zs[0] > 1e-6 || zs[zs.len() - 1] < LENGTH_MM - 1e-6 {
        anyhow::bail!(
            "the pass covers z {}…{} mm, the part is measured over 0…{LENGTH_MM} mm: grind the whole length",
            zs[0],
            zs[zs.len() - 1]
        );
    }
    let mut grid = vec![vec![f64::NAN; cs.len()]; zs.len()];
    for p in pass {
        let zi = zs.iter().position(|z| (z - p[1]).abs() < 1e-9);
        let ci = cs
            .iter()
            .position(|c| (c - p[0].rem_euclid(360.0)).abs() < 1e-6);
        if let (Some(zi), Some(ci)) = (zi, ci) {
            grid[zi][ci] = p[2];
        }
    }
    if grid.iter().flatten().any(|v| v.is_nan()) {
        anyhow::bail!("the pass is not a full grid of stations × angles: some points are missing");
    }
    let offset = |c: f64, z: f64| -> f64 {
        let zi = zs.partition_point(|&v| v <= z).clamp(1, zs.len() - 1) - 1;
        let fz = ((z - zs[zi]) / (zs[zi + 1] - zs[zi])).clamp(0.0, 1.0);
        let c = c.rem_euclid(360.0);
        let m = cs.len();
        // The angles either side of c, periodic over the turn.
        let (j0, c0, j1, c1) = match cs.partition_point(|&v| v <= c) {
            0 => (m - 1, cs[m - 1] - 360.0, 0, cs[0]),
            k if k == m => (m - 1, cs[m - 1], 0, cs[0] + 360.0),
            k => (k - 1, cs[k - 1], k, cs[k]),
        };
        let fc = ((c - c0) / (c1 - c0)).clamp(0.0, 1.0);
        let at = |zi: usize| grid[zi][j0] * (1.0 - fc) + grid[zi][j1] * fc;
        at(zi) * (1.0 - fz) + at(zi + 1) * fz
    };
    // Another noise stream than the first measurement's.
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0005_EEDA_F7E2_u64);
    Ok(grinder_csv(
        |c, z| grinder_form_um(c, z) + REMOVAL_EFFICIENCY * offset(c, z),
        &mut rng,
        "ground part after a correction pass",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_campaign_is_reproducible_and_complete() {
        let a = campaign(3);
        let b = campaign(3);
        assert_eq!(a, b);
        assert_eq!(a.iter().map(|f| f.0).collect::<Vec<_>>(), FILES.to_vec());
        assert_ne!(a[0].1, campaign(4)[0].1);
        let t = truth(3);
        assert!(t.roundness_pv_um > 4.0 && t.grinder_form_pv_um > 10.0);
    }

    #[test]
    fn a_pass_of_the_true_form_leaves_one_minus_the_efficiency() {
        // A pass commanding exactly −form on a fine grid.
        let mut pass = Vec::new();
        for k in 0..=60 {
            let z = LENGTH_MM * k as f64 / 60.0;
            for j in 0..72 {
                let c = 5.0 * j as f64;
                pass.push([c, z, -grinder_form_um(c, z)]);
            }
        }
        let after = after_pass(1, &pass).unwrap();
        let mut worst = 0.0f64;
        for l in after.lines().filter(|l| !l.starts_with('#')).skip(1) {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            let want = (1.0 - REMOVAL_EFFICIENCY) * grinder_form_um(v[0], v[1]);
            worst = worst.max((v[2] - want).abs());
        }
        // Noise (0.05 µm σ) and the interpolation of a 5° × 2 mm grid.
        assert!(worst < 0.35, "{worst}");
        let short: Vec<[f64; 3]> = pass.iter().filter(|p| p[1] < 100.0).copied().collect();
        assert!(after_pass(1, &short)
            .unwrap_err()
            .to_string()
            .contains("grind the whole length"));
    }
}
