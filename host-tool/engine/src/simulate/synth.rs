//! A small synthetic machine with an answer key, for testing and
//! benchmarking the diagnosis: an 800 × 500 × 500 mm mill measured on a
//! 100 mm grid plus dense lines (1 mm) along each axis, forward and
//! backward, with one or more hidden effects of known family, amplitude
//! and place, optional smooth misfit that the cubic19 seed cannot fit, and
//! Gaussian noise from a fixed seed.
//!
//! Beside [`super::simulate`] rather than through it: the tests and the
//! Monte Carlo benchmark need exact control of what is hidden and where —
//! the answer key — and of the misfit, which must lie outside the seed's
//! span by construction; and its data sets stay bit for bit those the
//! tests and BENCHMARKS.md were made with. Everything is deterministic for a seed (a SplitMix64
//! stream, `splitmix.rs`, bit-identical on every platform and to the one
//! of `trueaxis-test-support` these data sets were first drawn from).

use std::f64::consts::TAU;

use super::splitmix::SplitMix64;

use crate::data::{Dataset, TempChannel};
use crate::features::{kinematic, lagged, Norm, CUBIC19};

use crate::linalg::basis::Basis;

/// A hidden effect family with a fixed physical size at amplitude 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hidden {
    /// ey += 2.5 µm · sin(2π·y/5.08 mm + 0.7): a 5.08 mm (0.2 in) lead.
    Periodic,
    /// ex += 11.5 µm/m/K · x · ΔT_bed, the structure lagging the sensor by
    /// `SynthConfig::thermal_lag_s` (600 s).
    Thermal,
    /// ex += 4 µm · dir_x: 8 µm of backlash.
    Reversal,
    /// ex += 40 µrad · tool_mm: a pitch error times the Abbe arm.
    Abbe,
    /// ez += 2 µm/h · t.
    Drift,
    /// ey += 30 µrad · x (found with the `kinematic` seed only).
    Squareness,
    /// ez += 3 µm · T5(u_z), a fifth-degree straightness.
    HigherOrder,
    /// ex += 2 µm · sin(2π·x/5 mm + 0.3): a 5 mm lead on x (not in `ALL`:
    /// for tests with several effects on one target).
    PeriodicX,
    /// ex += 0.05 µrad/mm · x · tool_mm: a pitch growing along x (40 µrad
    /// at x = 800 mm) times the Abbe arm (not in `ALL`: for tests with
    /// several effects on one target).
    AbbeX,
}

impl Hidden {
    /// Every family, in the order of docs/cli.md.
    pub const ALL: [Hidden; 7] = [
        Hidden::Periodic,
        Hidden::Thermal,
        Hidden::Reversal,
        Hidden::Abbe,
        Hidden::Drift,
        Hidden::Squareness,
        Hidden::HigherOrder,
    ];

    /// The answer key: (family, target, axis) diagnose should name.
    pub fn expected(self) -> (&'static str, &'static str, Option<&'static str>) {
        match self {
            Hidden::Periodic => ("periodic", "ey", Some("y")),
            Hidden::Thermal => ("thermal", "ex", Some("x")),
            Hidden::Reversal => ("reversal", "ex", Some("x")),
            Hidden::Abbe => ("abbe", "ex", None),
            Hidden::Drift => ("drift", "ez", None),
            Hidden::Squareness => ("squareness", "ey", Some("x")),
            Hidden::HigherOrder => ("higher_order", "ez", Some("z")),
            Hidden::PeriodicX => ("periodic", "ex", Some("x")),
            Hidden::AbbeX => ("abbe", "ex", Some("x")),
        }
    }

    /// The seed model the family is diagnosed against (squareness is in
    /// cubic19's span by construction).
    pub fn seed(self) -> &'static str {
        match self {
            Hidden::Squareness => "kinematic",
            _ => "cubic19",
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        self.expected().0
    }
}

/// Which points are measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    /// 100 mm grid plus dense 1 mm lines along x, y and z.
    GridAndLines,
    /// The 100 mm grid only.
    GridOnly,
}

/// A synthetic measurement campaign.
#[derive(Clone, Debug)]
pub struct SynthConfig {
    /// Random seed (noise, base geometry, misfit shape).
    pub seed: u64,
    /// Measurement noise, µm (standard deviation).
    pub noise_um: f64,
    /// Hidden effects.
    pub hidden: Vec<Hidden>,
    /// Multiplies every hidden effect's size.
    pub amplitude: f64,
    /// RMS of the smooth misfit outside cubic19's span, µm (0 = none).
    pub misfit_um: f64,
    /// Points measured.
    pub plan: Plan,
    /// Forward and backward traverses; false = every approach from below.
    pub bidirectional: bool,
    /// Lag of the structure behind the bed sensor in `Hidden::Thermal`, s.
    pub thermal_lag_s: f64,
    /// The whole plan measured once per tool length (0, 75, 150 mm), one
    /// after the other — tool length then goes with time, as when a user
    /// measures tool length by tool length; false = the tool length
    /// changes by pass.
    pub tools_in_turn: bool,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            seed: 1,
            noise_um: 0.3,
            hidden: Vec::new(),
            amplitude: 1.0,
            misfit_um: 0.0,
            plan: Plan::GridAndLines,
            bidirectional: true,
            thermal_lag_s: 600.0,
            tools_in_turn: false,
        }
    }
}

const TRAVEL_MM: [f64; 3] = [800.0, 500.0, 500.0];

/// Generates the data set.
pub fn generate(cfg: &SynthConfig) -> Dataset {
    let mut rng = SplitMix64(cfg.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5EED);
    // Passes: (fixed positions, moving axis, start, stop, step).
    let mut pts: Vec<([f64; 3], [i8; 3], i64)> = Vec::new();
    let mut pass = 0i64;
    let mut line = |pts: &mut Vec<([f64; 3], [i8; 3], i64)>,
                    axis: usize,
                    at: [f64; 3],
                    step: f64,
                    back: bool| {
        let n = (TRAVEL_MM[axis] / step).round() as usize;
        let dir: i8 = if back && cfg.bidirectional { -1 } else { 1 };
        for i in 0..=n {
            let k = if dir < 0 { n - i } else { i };
            let mut p = at;
            p[axis] = k as f64 * step;
            let mut d = [1i8; 3];
            d[axis] = dir;
            pts.push((p, d, pass));
        }
        pass += 1;
    };
    let centre = [400.0, 250.0, 250.0];
    let dense = cfg.plan == Plan::GridAndLines;
    if dense {
        for axis in 0..3 {
            line(&mut pts, axis, centre, 1.0, false);
        }
    }
    let mut serp = false;
    for iz in 0..=5 {
        for iy in 0..=5 {
            line(
                &mut pts,
                0,
                [0.0, iy as f64 * 100.0, iz as f64 * 100.0],
                100.0,
                serp,
            );
            serp = !serp;
        }
    }
    if dense {
        for axis in (0..3).rev() {
            line(&mut pts, axis, centre, 1.0, true);
        }
    }
    const TOOLS_MM: [f64; 3] = [0.0, 75.0, 150.0];
    let tool_of: Vec<f64> = if cfg.tools_in_turn {
        let one = pts.clone();
        pts.clear();
        for k in 0..TOOLS_MM.len() as i64 {
            pts.extend(one.iter().map(|p| (p.0, p.1, p.2 + k * pass)));
        }
        (0..pts.len()).map(|i| TOOLS_MM[i / one.len()]).collect()
    } else {
        pts.iter().map(|p| TOOLS_MM[(p.2 % 3) as usize]).collect()
    };
    let n = pts.len();
    let t_s: Vec<f64> = (0..n).map(|i| 2.0 * i as f64).collect();
    let t_bed: Vec<f64> = t_s
        .iter()
        .map(|t| 20.0 + 3.0 * (1.0 - (-t / 3000.0).exp()) + 0.25 * (TAU * t / 1700.0).sin())
        .collect();
    let t_air: Vec<f64> = t_s
        .iter()
        .map(|t| 20.5 + 0.6 * (TAU * t / 4000.0 + 1.0).sin())
        .collect();
    let tool = tool_of;
    let mut d = Dataset {
        source: format!("synth:seed={}", cfg.seed),
        pos_mm: [0, 1, 2].map(|a| Some(pts.iter().map(|p| p.0[a]).collect())),
        t_s: Some(t_s.clone()),
        dir: [0, 1, 2].map(|a| Some(pts.iter().map(|p| p.1[a]).collect())),
        temps: vec![
            TempChannel {
                name: "bed".into(),
                temp_c: t_bed.clone(),
            },
            TempChannel {
                name: "air".into(),
                temp_c: t_air,
            },
        ],
        tool_mm: Some(tool.clone()),
        pass_id: Some(pts.iter().map(|p| p.2).collect()),
        ..Dataset::default()
    };
    let norm = Norm::from_data(&d);
    let u = |r: usize| [0, 1, 2].map(|a| norm.u(a, d.pos(a, r)));
    let mono =
        |e: [u8; 3], uu: [f64; 3]| (0..3).map(|a| uu[a].powi(i32::from(e[a]))).product::<f64>();
    let lag_bed = lagged(&t_bed, &t_s, None, cfg.thermal_lag_s);
    let mut err = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    for (t, e) in err.iter_mut().enumerate() {
        // Base geometry inside the kinematic seed (so inside cubic19 too).
        let coef: Vec<(f64, [u8; 3])> = kinematic(t)
            .iter()
            .map(|&m| (5.0 * rng.normal(), m))
            .collect();
        for (r, v) in e.iter_mut().enumerate() {
            *v = coef.iter().map(|(c, m)| c * mono(*m, u(r))).sum();
        }
    }
    let a = cfg.amplitude;
    for h in &cfg.hidden {
        for r in 0..n {
            let p = pts[r].0;
            match h {
                Hidden::Periodic => err[1][r] += a * 2.5 * (TAU * p[1] / 5.08 + 0.7).sin(),
                Hidden::PeriodicX => err[0][r] += a * 2.0 * (TAU * p[0] / 5.0 + 0.3).sin(),
                Hidden::Thermal => err[0][r] += a * 11.5e-3 * p[0] * (lag_bed[r] - 20.0),
                Hidden::Reversal => err[0][r] += a * 4.0 * f64::from(pts[r].1[0]),
                Hidden::Abbe => err[0][r] += a * 40e-3 * tool[r],
                Hidden::AbbeX => err[0][r] += a * 0.05e-3 * p[0] * tool[r],
                Hidden::Drift => err[2][r] += a * 2.0 * t_s[r] / 3600.0,
                Hidden::Squareness => err[1][r] += a * 30e-3 * p[0],
                Hidden::HigherOrder => {
                    let z = u(r)[2];
                    err[2][r] += a * 3.0 * (16.0 * z.powi(5) - 20.0 * z.powi(3) + 5.0 * z) / 4.0;
                }
            }
        }
    }
    if cfg.misfit_um > 0.0 {
        let cols: Vec<Vec<f64>> = CUBIC19
            .iter()
            .map(|&m| (0..n).map(|r| mono(m, u(r))).collect())
            .collect();
        let basis = Basis::new(&cols, n);
        for e in err.iter_mut() {
            // A smooth bump at a random place, with the seed's part removed
            // so that exactly `misfit_um` RMS is left for no model to fit.
            let c = [0; 3].map(|_| 1.2 * rng.unit_open() - 0.6);
            let w = 0.25 + 0.2 * rng.unit_open();
            let bump: Vec<f64> = (0..n)
                .map(|r| {
                    let uu = u(r);
                    let d2: f64 = (0..3).map(|a| (uu[a] - c[a]).powi(2)).sum();
                    (-d2 / w).exp()
                })
                .collect();
            let res = basis.residual(&bump);
            let rms = (res.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
            for (v, m) in e.iter_mut().zip(&res) {
                *v += cfg.misfit_um * m / rms.max(1e-12);
            }
        }
    }
    for e in err.iter_mut() {
        for v in e.iter_mut() {
            *v += cfg.noise_um * rng.normal();
        }
    }
    d.err_um = err.map(|e| Some(e.into_iter().map(Some).collect()));
    d
}
