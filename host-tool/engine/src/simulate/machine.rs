//! The synthetic 3-axis machine: the 21 geometric errors (per axis three
//! translations — positioning and two straightnesses — and three rotations —
//! roll, pitch, yaw — plus three squarenesses) and the volumetric error they
//! give at the tool point.
//!
//! Kinematic chain and sign conventions (documented in docs/cli.md):
//! a serial stack X → Y → Z → tool, the tool pointing along −Z with length
//! `tool_mm` (the Abbe arm along the spindle). Each carriage k has a
//! translation error δ_k(q_k) (µm) and a small rotation ε_k(q_k) (µrad,
//! right-handed about +X, +Y, +Z) about its own reference point; the
//! reference points are (x, 0, 0) for X, (x, y, 0) for Y and (x, y, z) for Z,
//! so the arm from carriage k to the tool point is
//! a_X = (0, y, z − L), a_Y = (0, 0, z − L), a_Z = (0, 0, −L).
//! The first-order (small-angle) homogeneous-transform product, with the
//! second-order products (ε·δ, ε·ε ~ 1e-10 relative) dropped, is
//!
//! e = Σ_k [δ_k(q_k) + ε_k(q_k) × a_k] + squareness,
//!
//! with squareness as tilted axis directions: Y runs along (−S_xy, 1, 0) and
//! Z along (−S_xz, −S_yz, 1), i.e. a positive S_xy means the angle between
//! +X and +Y is larger than 90°, and it gives e_x = −S_xy·y exactly.
//!
//! Each error function is a polynomial in the normalised position
//! u = q / travel ∈ [0, 1] plus optional sine waves (smooth shapes that no
//! low-order polynomial holds). With cubic translations and at most
//! quadratic rotations (the `mill800` preset) every volumetric component is
//! inside the span of the seed's `cubic19` terms, so a cubic19 fit of the
//! plain preset reaches the noise floor — effects and `mill800-wavy` are
//! what it cannot follow.

use std::f64::consts::TAU;

use anyhow::bail;
use serde::{Deserialize, Serialize};

/// A sine component of an error function.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Wave {
    /// Amplitude (µm for translations, µrad for rotations).
    pub amp: f64,
    /// Period along the axis, mm.
    pub period_mm: f64,
    /// Phase at position 0, rad.
    pub phase_rad: f64,
}

/// One error component of one axis as a function of that axis' position.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorFn {
    /// Coefficients of 1, u, u², … with u = position / travel (µm or µrad).
    pub poly: Vec<f64>,
    /// Smooth non-polynomial shapes added to the polynomial.
    pub waves: Vec<Wave>,
}

impl ErrorFn {
    /// A polynomial in u.
    pub fn poly(coef: &[f64]) -> ErrorFn {
        ErrorFn {
            poly: coef.to_vec(),
            waves: Vec::new(),
        }
    }

    /// Value at position `pos_mm` on an axis of `travel_mm`.
    pub fn eval(&self, pos_mm: f64, travel_mm: f64) -> f64 {
        let u = pos_mm / travel_mm;
        // Horner's rule.
        let p = self.poly.iter().rev().fold(0.0, |acc, c| acc * u + c);
        let w: f64 = self
            .waves
            .iter()
            .map(|w| w.amp * (TAU * pos_mm / w.period_mm + w.phase_rad).sin())
            .sum();
        p + w
    }
}

/// The six error motions of one carriage.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisErrors {
    /// Translation errors along X, Y, Z in µm (the component along the axis
    /// itself is its positioning error, the other two its straightness).
    pub trans_um: [ErrorFn; 3],
    /// Rotations about X, Y, Z in µrad (roll, pitch, yaw for the X axis).
    pub rot_urad: [ErrorFn; 3],
}

/// The three squareness errors, µrad (sign convention in the module doc).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Squareness {
    /// Y against X: e_x = −xy·y.
    pub xy_urad: f64,
    /// Z against X: e_x = −xz·z.
    pub xz_urad: f64,
    /// Z against Y: e_y = −yz·z.
    pub yz_urad: f64,
}

/// A 3-axis machine's geometry: travels and the 21 geometric errors.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// Preset name, for metadata (`mill800`, or `custom`).
    pub name: String,
    /// Travel of X, Y, Z in mm; positions run from 0 to the travel.
    pub travel_mm: [f64; 3],
    /// Error motions of the X, Y and Z carriages.
    pub axes: [AxisErrors; 3],
    /// Squareness errors.
    pub squareness: Squareness,
    /// Spindle-axis tilt about X and Y (A0T, B0T), µrad: the tool's axis
    /// is tilted so that e += (A0T, B0T, 0) × (0, 0, −L) (docs/volumetric.md).
    #[serde(default)]
    pub tilt_urad: [f64; 2],
}

/// The ranges a realistic preset's errors lie in (ARCHITECTURE.md,
/// "Physical magnitudes for simulation"), as the peak |value| of each error
/// function over its axis' travel; checked for `mill800` by a test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Realistic {
    /// Positioning (translation along the axis itself), µm: a C3–C5 lead
    /// screw over 500–800 mm (lead class ±3 (C0) … ±23 (C5) µm per 300 mm).
    pub positioning_um: [f64; 2],
    /// Straightness (the two other translations), µm: ~10 µm / 500 mm.
    pub straightness_um: [f64; 2],
    /// Roll, pitch, yaw, µrad.
    pub angular_urad: [f64; 2],
    /// |squareness|, µrad.
    pub squareness_urad: [f64; 2],
}

/// See [`Realistic`].
pub const REALISTIC: Realistic = Realistic {
    positioning_um: [5.0, 25.0],
    straightness_um: [5.0, 15.0],
    angular_urad: [10.0, 60.0],
    squareness_urad: [20.0, 40.0],
};

/// Names accepted by [`Machine::preset`].
pub const PRESETS: [&str; 4] = ["mill800", "mill800-wavy", "perfect800", "mill800-21"];

impl Machine {
    /// The machine with a lead (periodic) error of `amp_um` with period
    /// `period_mm` and phase `phase_rad` on top of `axis`' positioning (a
    /// screw's cyclic error, as tests and examples put one on a preset).
    pub fn with_lead(
        mut self,
        axis: usize,
        amp_um: f64,
        period_mm: f64,
        phase_rad: f64,
    ) -> Machine {
        self.axes[axis].trans_um[axis].waves.push(Wave {
            amp: amp_um,
            period_mm,
            phase_rad,
        });
        self
    }

    /// A machine with the seed's travels (800 × 500 × 500 mm) and no error
    /// at all: the base for tests that switch on one error at a time.
    pub fn perfect(travel_mm: [f64; 3]) -> Machine {
        Machine {
            name: "custom".into(),
            travel_mm,
            ..Machine::default()
        }
    }

    /// The named preset:
    /// - `mill800`: the seed's vertical mill (X 800, Y 500, Z 500 mm) with
    ///   all 21 errors inside the ranges of [`REALISTIC`] (ARCHITECTURE.md's
    ///   magnitudes): positioning 8.9–12 µm over the travel (a C3–C5 lead
    ///   screw, uncompensated), straightness 6–7.5 µm (~9–10 µm peak to
    ///   valley, "~10 µm / 500 mm"), roll / pitch / yaw 13–38 µrad,
    ///   squareness 20–30 µrad; cubic translations, quadratic angles. The
    ///   angles times their Abbe arms (up to 500 mm) are the largest part
    ///   of the volumetric error, as on a real mill.
    /// - `mill800-wavy`: the same plus long-wave shapes (periods 180–320 mm,
    ///   0.8–1.5 µm / 4 µrad) that a cubic cannot follow.
    /// - `perfect800`: the same travels with no errors.
    /// - `mill800-21`: `mill800` plus the spindle-axis tilt A0T = 12 µrad,
    ///   B0T = −10 µrad: all 21 errors and the tilt (issue 26).
    pub fn preset(name: &str) -> anyhow::Result<Machine> {
        let p = ErrorFn::poly;
        let mut m = match name {
            "perfect800" => Machine::perfect([800.0, 500.0, 500.0]),
            "mill800" | "mill800-wavy" | "mill800-21" => Machine {
                name: name.into(),
                travel_mm: [800.0, 500.0, 500.0],
                // Peaks over the travel in the comments (µm, µrad).
                axes: [
                    AxisErrors {
                        trans_um: [
                            p(&[0.0, 14.0, -7.0, 5.0]),    // positioning 12
                            p(&[0.0, 24.0, -48.0, 18.0]),  // straightness 6.0
                            p(&[0.0, -15.0, 35.0, -12.5]), // straightness 7.5
                        ],
                        rot_urad: [
                            p(&[0.0, 80.0, -100.0]), // roll 20
                            p(&[0.0, 120.0, -96.0]), // pitch 37.5
                            p(&[0.0, -60.0, 84.0]),  // yaw 24
                        ],
                    },
                    AxisErrors {
                        trans_um: [
                            p(&[0.0, 17.5, -35.0, 10.5]), // straightness 7.0
                            p(&[0.0, -27.0, 15.0, 9.0]),  // positioning 8.9
                            p(&[0.0, -10.0, 22.5, -5.0]), // straightness 7.5
                        ],
                        rot_urad: [
                            p(&[0.0, 60.0, -40.0]), // 22.5
                            p(&[0.0, -36.0, 54.0]), // 18
                            p(&[0.0, 56.0, -40.0]), // 19.6
                        ],
                    },
                    AxisErrors {
                        trans_um: [
                            p(&[0.0, -21.0, 35.0, -7.0]), // straightness 7.0
                            p(&[0.0, 20.0, -44.0, 18.0]), // straightness 6.0
                            p(&[0.0, 25.0, -10.0, -7.5]), // positioning 10
                        ],
                        rot_urad: [
                            p(&[0.0, 54.0, -42.0]), // 17.4
                            p(&[0.0, -64.0, 80.0]), // 16
                            p(&[0.0, 40.0, -30.0]), // 13.3
                        ],
                    },
                ],
                squareness: Squareness {
                    xy_urad: 25.0,
                    xz_urad: -30.0,
                    yz_urad: 20.0,
                },
                tilt_urad: [0.0; 2],
            },
            other => bail!("unknown preset `{other}` (expected {})", PRESETS.join(", ")),
        };
        if name == "mill800-21" {
            m.tilt_urad = [12.0, -10.0];
        }
        if name == "mill800-wavy" {
            let wave = |amp: f64, period_mm: f64, phase_rad: f64| Wave {
                amp,
                period_mm,
                phase_rad,
            };
            m.axes[0].trans_um[1].waves.push(wave(1.5, 260.0, 0.4));
            m.axes[0].trans_um[0].waves.push(wave(1.0, 320.0, 1.1));
            m.axes[1].trans_um[1].waves.push(wave(1.0, 180.0, 2.0));
            m.axes[2].trans_um[0].waves.push(wave(0.8, 210.0, -0.7));
            m.axes[0].rot_urad[1].waves.push(wave(4.0, 300.0, 0.0));
        }
        Ok(m)
    }

    /// Volumetric error (actual − nominal tool-point position) in µm at the
    /// nominal axis positions `pos_mm` with tool length `tool_mm`, from the
    /// geometric errors alone (no effects, no noise).
    pub fn error_um(&self, pos_mm: [f64; 3], tool_mm: f64) -> [f64; 3] {
        self.error_at_um(pos_mm, tool_mm, [0.0, 0.0])
    }

    /// Rotation of the tool frame relative to the workpiece at `pos_mm`,
    /// µrad: the sum of the carriages' rotations (what an angular line
    /// reads before its zero; the tilt is no carriage rotation).
    pub fn angle_urad(&self, pos_mm: [f64; 3]) -> [f64; 3] {
        let mut w = [0.0; 3];
        for ((ax, &q), &tr) in self.axes.iter().zip(&pos_mm).zip(&self.travel_mm) {
            for (wi, f) in w.iter_mut().zip(&ax.rot_urad) {
                *wi += f.eval(q, tr);
            }
        }
        w
    }

    /// [`Machine::error_um`] at a point offset laterally by `tool_lat_mm`
    /// (x, y) from the spindle axis: the measured point is
    /// (x + tool_x, y + tool_y, z − tool_mm) (docs/volumetric.md).
    pub fn error_at_um(&self, pos_mm: [f64; 3], tool_mm: f64, tool_lat_mm: [f64; 2]) -> [f64; 3] {
        let [_, y, z] = pos_mm;
        let [tx, ty] = tool_lat_mm;
        let arms = [
            [tx, y + ty, z - tool_mm],
            [tx, ty, z - tool_mm],
            [tx, ty, -tool_mm],
        ];
        let mut e = [0.0; 3];
        for k in 0..3 {
            let q = pos_mm[k];
            let tr = self.travel_mm[k];
            let ax = &self.axes[k];
            let d = [0, 1, 2].map(|i| ax.trans_um[i].eval(q, tr));
            let r = [0, 1, 2].map(|i| ax.rot_urad[i].eval(q, tr));
            let a = arms[k];
            // ε × a, µrad·mm = nm → ·1e-3 for µm.
            let cross = [
                r[1] * a[2] - r[2] * a[1],
                r[2] * a[0] - r[0] * a[2],
                r[0] * a[1] - r[1] * a[0],
            ];
            for i in 0..3 {
                e[i] += d[i] + cross[i] * 1e-3;
            }
        }
        let s = &self.squareness;
        e[0] += -(s.xy_urad * y + s.xz_urad * z) * 1e-3;
        e[1] += -s.yz_urad * z * 1e-3;
        if self.tilt_urad != [0.0; 2] {
            // (A, B, 0) × (0, 0, −L) = (−B·L, A·L, 0).
            e[0] += -self.tilt_urad[1] * tool_mm * 1e-3;
            e[1] += self.tilt_urad[0] * tool_mm * 1e-3;
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AXES_NAMES: [&str; 3] = ["X", "Y", "Z"];

    #[test]
    fn perfect_machine_has_no_error() {
        let m = Machine::preset("perfect800").unwrap();
        assert_eq!(m.error_um([400.0, 250.0, 100.0], 50.0), [0.0; 3]);
    }

    #[test]
    fn pitch_of_x_times_arm() {
        // A constant pitch ε_y = 10 µrad of the X carriage with the tool
        // 100 mm below the spindle at z = 0: ε × a = (ε_y·a_z, 0, −ε_y·a_x)
        // with a = (0, y, −100) → e_x = 10 µrad · −100 mm = −1 µm.
        let mut m = Machine::perfect([800.0, 500.0, 500.0]);
        m.axes[0].rot_urad[1] = ErrorFn::poly(&[10.0]);
        let e = m.error_um([300.0, 200.0, 0.0], 100.0);
        assert!((e[0] - -1.0).abs() < 1e-12, "{e:?}");
        assert_eq!(e[1], 0.0);
        assert_eq!(e[2], 0.0);
    }

    /// Largest |f| of an error function over its axis' travel.
    fn peak(f: &ErrorFn, travel_mm: f64) -> f64 {
        (0..=1000)
            .map(|i| f.eval(travel_mm * i as f64 / 1000.0, travel_mm).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn each_of_the_21_errors_is_in_its_realistic_range() {
        let m = Machine::preset("mill800").unwrap();
        let inside = |v: f64, r: [f64; 2]| v >= r[0] && v <= r[1];
        for (k, ax) in m.axes.iter().enumerate() {
            let tr = m.travel_mm[k];
            for (i, f) in ax.trans_um.iter().enumerate() {
                let (what, range) = if i == k {
                    ("positioning", REALISTIC.positioning_um)
                } else {
                    ("straightness", REALISTIC.straightness_um)
                };
                let v = peak(f, tr);
                assert!(
                    inside(v, range),
                    "{} {what} along {}: peak {v:.2} µm, expected {range:?}",
                    AXES_NAMES[k],
                    AXES_NAMES[i]
                );
            }
            for (i, f) in ax.rot_urad.iter().enumerate() {
                let v = peak(f, tr);
                assert!(
                    inside(v, REALISTIC.angular_urad),
                    "{} rotation about {}: peak {v:.2} µrad, expected {:?}",
                    AXES_NAMES[k],
                    AXES_NAMES[i],
                    REALISTIC.angular_urad
                );
            }
        }
        let s = &m.squareness;
        for (name, v) in [("xy", s.xy_urad), ("xz", s.xz_urad), ("yz", s.yz_urad)] {
            assert!(
                inside(v.abs(), REALISTIC.squareness_urad),
                "squareness {name}: {v} µrad"
            );
        }
    }

    #[test]
    fn preset_magnitudes_are_realistic() {
        let m = Machine::preset("mill800").unwrap();
        let mut max = 0.0f64;
        for x in [0.0, 400.0, 800.0] {
            for y in [0.0, 250.0, 500.0] {
                for z in [0.0, 250.0, 500.0] {
                    for v in m.error_um([x, y, z], 0.0) {
                        max = max.max(v.abs());
                    }
                }
            }
        }
        // A usable mill before compensation: some tens of µm over the
        // volume, most of it angles times their Abbe arms.
        assert!(max > 10.0 && max < 100.0, "max |e| = {max}");
    }
}
