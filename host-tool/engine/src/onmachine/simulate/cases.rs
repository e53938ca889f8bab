//! Probing cases made independently of the campaign, for the tests
//! (docs/on-machine.md § "Tested cases"): spindles read at any number of
//! samples per turn, steps and turns, off-centre parts, time-sampled logs
//! with an index pulse; master balls and probes of other sizes with a
//! kinematic probe's 3- and 6-lobe pre-travel, a polar term, outlier
//! contacts and positions logged at a coarse resolution; part arcs probed
//! from outside or inside with the slides' straightness in them. Each is
//! a fixed seed and its truth, in the files' own columns.

use std::f64::consts::PI;
use std::fmt::Write as _;

use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::simulate::normal;

/// A profile round the turn: `(harmonic k, amplitude, phase rad)` terms of
/// `Σ a cos(kθ + φ)`.
pub type Harmonics = Vec<(usize, f64, f64)>;

/// The profile `h` at angle `t` (rad), without the harmonics in `out`.
pub fn at(h: &[(usize, f64, f64)], t: f64, out: &[usize]) -> f64 {
    h.iter()
        .filter(|(k, _, _)| !out.contains(k))
        .map(|&(k, a, p)| a * (k as f64 * t + p).cos())
        .sum()
}

/// Peak to valley of `f` over a turn (3600 points).
fn pv_turn(f: impl Fn(f64) -> f64) -> f64 {
    let v: Vec<f64> = (0..3600).map(|i| f(2.0 * PI * i as f64 / 3600.0)).collect();
    crate::onmachine::separate::pv(&v)
}

/// A spindle turning a round part, read by three probes and by one probe
/// with the part remounted in steps.
#[derive(Clone, Debug)]
pub struct SpindleCase {
    /// Samples per turn.
    pub samples: usize,
    /// Turns read (per step for the multi-step set).
    pub turns: usize,
    /// Steps of the multi-step set (equally spaced).
    pub steps: usize,
    /// The three probes' angles, degrees.
    pub probe_angles_deg: [f64; 3],
    /// The part's roundness, µm (harmonics ≥ 2).
    pub part: Harmonics,
    /// The spindle's synchronous radial motion along x (probe 1) and y, µm
    /// (harmonics ≥ 2).
    pub spindle_x: Harmonics,
    /// See above.
    pub spindle_y: Harmonics,
    /// The part's centring on the spindle (once per turn), µm; each
    /// remounting of the multi-step set has its own, as large.
    pub centring_um: f64,
    /// Amplitude of the spindle's asynchronous motion, µm (at 3.37 and
    /// 2.71 cycles a turn along x and y).
    pub async_um: f64,
    /// Reading noise, µm.
    pub noise_um: f64,
}

impl SpindleCase {
    /// The synchronous error motion along x (ISO 230-7), harmonics `out`
    /// left out, µm.
    pub fn error_motion_um(&self, out: &[usize]) -> f64 {
        pv_turn(|t| at(&self.spindle_x, t, out))
    }

    /// The part's roundness, harmonics `out` left out, µm.
    pub fn part_pv_um(&self, out: &[usize]) -> f64 {
        pv_turn(|t| at(&self.part, t, out))
    }

    /// The spindle's motion at angle `t` after `u` turns: `[x, y]`, µm.
    fn motion(&self, t: f64, u: f64) -> [f64; 2] {
        [
            at(&self.spindle_x, t, &[]) + self.async_um * (2.0 * PI * 3.37 * u).sin(),
            at(&self.spindle_y, t, &[]) + self.async_um * (2.0 * PI * 2.71 * u + 1.0).sin(),
        ]
    }

    /// What a probe at `a` (rad) reads at spindle angle `t` after `u` turns.
    fn reading(&self, t: f64, u: f64, a: f64, rng: &mut ChaCha8Rng) -> f64 {
        let [x, y] = self.motion(t, u);
        at(&self.part, t - a, &[])
            + self.centring_um * (t - a + 0.4).cos()
            + x * a.cos()
            + y * a.sin()
            + self.noise_um * normal(rng)
    }

    /// `c_deg,p1_um,p2_um,p3_um`: the three probes, the angle counting on
    /// over the turns.
    pub fn three_probe_csv(&self, seed: u64) -> String {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = format!(
            "# three probes at {:?}°, {} samples a turn, {} turns (seed {seed})\nc_deg,p1_um,p2_um,p3_um\n",
            self.probe_angles_deg, self.samples, self.turns
        );
        for i in 0..self.samples * self.turns {
            let c = 360.0 * i as f64 / self.samples as f64;
            let u = i as f64 / self.samples as f64;
            let _ = write!(s, "{c}");
            for a in self.probe_angles_deg {
                let v = self.reading(c.to_radians(), u, a.to_radians(), &mut rng);
                let _ = write!(s, ",{v:.5}");
            }
            s.push('\n');
        }
        s
    }

    /// `c_deg,step_deg,p_um`: one probe at 0°, the part remounted at each
    /// of the steps (each with its own centring and probe zero).
    pub fn multi_step_csv(&self, seed: u64) -> String {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = format!(
            "# multi-step, {} steps, {} samples a turn, {} turns (seed {seed})\nc_deg,step_deg,p_um\n",
            self.steps, self.samples, self.turns
        );
        for j in 0..self.steps {
            let st = 360.0 * j as f64 / self.steps as f64;
            let (ce, ph, zero) = (
                self.centring_um * (0.5 + 0.5 * normal(&mut rng).abs()),
                PI * normal(&mut rng),
                normal(&mut rng),
            );
            for i in 0..self.samples * self.turns {
                let c = 360.0 * i as f64 / self.samples as f64;
                let t = c.to_radians();
                let u = (j * self.turns) as f64 + i as f64 / self.samples as f64;
                let phi = st.to_radians();
                let v = at(&self.part, t - phi, &[])
                    + ce * (t - phi + ph).cos()
                    + zero
                    + self.motion(t, u)[0]
                    + self.noise_um * normal(&mut rng);
                let _ = writeln!(s, "{c},{st},{v:.5}");
            }
        }
        s
    }

    /// A spindle analyser's log of the three probes sampled in time:
    /// `t_s,index,p1_um,p2_um,p3_um` at `rate_hz`, the spindle at `rpm`
    /// wandering ±1 % (so no sample repeats an angle), the index pulse 5 on
    /// the first sample of each turn, 0 otherwise.
    pub fn three_probe_log(&self, rpm: f64, rate_hz: f64, seed: u64) -> String {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = format!(
            "# spindle analyser log: {rate_hz} Hz, {rpm} rev/min ±1 % (seed {seed})\nt_s,index,p1_um,p2_um,p3_um\n"
        );
        let (mut theta, mut last_turn) = (0.0f64, -1i64);
        let n = (self.turns as f64 * 60.0 / rpm * rate_hz) as usize;
        for i in 0..n {
            let t_s = i as f64 / rate_hz;
            let turn = (theta / (2.0 * PI)).floor() as i64;
            let index = if turn > last_turn { 5 } else { 0 };
            last_turn = turn;
            let _ = write!(s, "{t_s:.6},{index}");
            for a in self.probe_angles_deg {
                let v = self.reading(theta, theta / (2.0 * PI), a.to_radians(), &mut rng);
                let _ = write!(s, ",{v:.5}");
            }
            s.push('\n');
            let speed = rpm / 60.0 * (1.0 + 0.01 * (2.0 * PI * t_s / 7.0).sin());
            theta += 2.0 * PI * speed / rate_hz;
        }
        s
    }
}

/// A master ball and a probe: sizes, the probe's form and how the scan
/// was logged.
#[derive(Clone, Debug)]
pub struct BallCase {
    /// Ball diameter, mm.
    pub ball_diameter_mm: f64,
    /// The probe's effective radius, mm.
    pub probe_radius_mm: f64,
    /// Pre-travel lobes round the stylus `(lobes, nm, phase)`, growing as
    /// sin³ of the angle from the stylus axis (a kinematic probe: 3 and 6).
    pub lobes: Harmonics,
    /// A polar term: `nm · P4(cos polar)`.
    pub polar_nm: f64,
    /// Probe noise, nm.
    pub noise_nm: f64,
    /// Contacts pushed off the ball: `(row, nm)`.
    pub outliers: Vec<(usize, f64)>,
    /// Coordinates rounded to this, mm (0: written to 10⁻⁷ mm).
    pub quantum_mm: f64,
}

impl BallCase {
    /// The probe's form in contact direction `n`, nm.
    pub fn form_nm(&self, n: [f64; 3]) -> f64 {
        let s = (1.0 - n[2] * n[2]).max(0.0).sqrt();
        let az = n[1].atan2(n[0]);
        let x = n[2];
        s.powi(3) * at(&self.lobes, az, &[])
            + self.polar_nm * (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0
    }

    fn coord(&self, v: f64) -> String {
        if self.quantum_mm > 0.0 {
            let q = self.quantum_mm;
            let d = (-q.log10()).ceil().max(0.0) as usize;
            format!("{:.d$}", (v / q).round() * q)
        } else {
            format!("{v:.7}")
        }
    }

    /// Contact `i` at direction `n` on the ball centred at `c`.
    fn contact(&self, i: usize, n: [f64; 3], c: [f64; 3], rng: &mut ChaCha8Rng) -> [f64; 3] {
        let extra = self
            .outliers
            .iter()
            .filter(|o| o.0 == i)
            .map(|o| o.1)
            .sum::<f64>();
        let d = self.ball_diameter_mm / 2.0
            + self.probe_radius_mm
            + (self.form_nm(n) + self.noise_nm * normal(rng) + extra) * 1e-6;
        [c[0] + d * n[0], c[1] + d * n[1], c[2] + d * n[2]]
    }

    /// `x_mm,z_mm`: `points` contacts over `lo…hi` degrees of the ball in
    /// XZ (centre 60, −20).
    pub fn arc_csv(&self, lo: f64, hi: f64, points: usize, seed: u64) -> String {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = String::from("# master ball, XZ arc\nx_mm,z_mm\n");
        for i in 0..points {
            let t = (lo + (hi - lo) * i as f64 / (points - 1) as f64).to_radians();
            let p = self.contact(i, [t.cos(), 0.0, t.sin()], [60.0, 0.0, -20.0], &mut rng);
            let _ = writeln!(s, "{},{}", self.coord(p[0]), self.coord(p[2]));
        }
        s
    }

    /// `x_mm,y_mm,z_mm`: the pole and 10 rings to `polar_max` degrees, 36
    /// contacts each (centre 60, 15, −20).
    pub fn sphere_csv(&self, polar_max: f64, seed: u64) -> String {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = String::from("# master ball, rings from the pole\nx_mm,y_mm,z_mm\n");
        let mut i = 0;
        for ring in 0..=10 {
            let pol = (polar_max * ring as f64 / 10.0).to_radians();
            for j in 0..(if ring == 0 { 1 } else { 36 }) {
                let az = (10.0 * j as f64 + 5.0 * (ring % 2) as f64).to_radians();
                let n = [pol.sin() * az.cos(), pol.sin() * az.sin(), pol.cos()];
                let p = self.contact(i, n, [60.0, 15.0, -20.0], &mut rng);
                let _ = writeln!(
                    s,
                    "{},{},{}",
                    self.coord(p[0]),
                    self.coord(p[1]),
                    self.coord(p[2])
                );
                i += 1;
            }
        }
        s
    }
}

/// A round part probed along an arc in XZ (centre at the origin).
#[derive(Clone, Debug)]
pub struct PartArc {
    /// Nominal radius, mm.
    pub radius_mm: f64,
    /// Its lobes `(k, nm, phase)`.
    pub lobes: Harmonics,
    /// Probed from outside (a boss) or inside (a bore).
    pub outside: bool,
    /// Contact angles, degrees `[lo, hi]` (0…360 for a full circle).
    pub arc_deg: [f64; 2],
    /// Contacts.
    pub points: usize,
    /// The z slide's straightness along x: `nm · sin(2π x / (2 radius))`.
    pub slide_nm: f64,
}

impl PartArc {
    /// The probe centres of the scan by `probe` (`x_mm,z_mm`), and the
    /// surface as the machine sees it without noise or probe (the part's
    /// form plus the slide's error: the sum the scan can give), mm.
    pub fn scan(&self, probe: &BallCase, seed: u64) -> (String, Vec<[f64; 2]>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = String::from("# part arc in XZ, probe centre at contact\nx_mm,z_mm\n");
        let mut seen = Vec::new();
        let full = (self.arc_deg[1] - self.arc_deg[0]).abs() >= 359.999;
        let n = if full { self.points } else { self.points - 1 };
        for i in 0..self.points {
            let t = (self.arc_deg[0] + (self.arc_deg[1] - self.arc_deg[0]) * i as f64 / n as f64)
                .to_radians();
            let radial = [t.cos(), t.sin()];
            let r = self.radius_mm + at(&self.lobes, t, &[]) * 1e-6;
            // The surface's outward normal (toward the probe) and the
            // probe's contact direction.
            let out = if self.outside {
                radial
            } else {
                [-radial[0], -radial[1]]
            };
            let d = probe.probe_radius_mm
                + (probe.form_nm([out[0], 0.0, out[1]]) + probe.noise_nm * normal(&mut rng)) * 1e-6;
            let surf = [r * radial[0], r * radial[1]];
            // The z slide is off by e(x): the centre the control reports is
            // that much from where the probe really was.
            let e = self.slide_nm * 1e-6 * (PI * surf[0] / self.radius_mm).sin();
            let c = [surf[0] + d * out[0], surf[1] + d * out[1] - e];
            seen.push([surf[0], surf[1] - e]);
            let _ = writeln!(s, "{:.7},{:.7}", c[0], c[1]);
        }
        (s, seen)
    }
}
