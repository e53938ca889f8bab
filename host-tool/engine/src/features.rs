//! The vocabulary of linear compensation models: a `Feature` is one column of
//! a design matrix (a monomial of the normalised positions, a sine of a lead
//! screw's phase, a temperature rise times a position, …), a seed (`cubic19`,
//! `kinematic`) is a set of monomials per target, and an effect (`effect/`)
//! is what a user — or `diagnose` — adds with `fit --add
//! "<effect>:<key>=<value>,…"`, made of these columns.
//!
//! Defined once here because fit, diagnose, compare and export must agree on
//! what a column means: diagnose scores candidate columns, fit solves for
//! their coefficients, export turns each feature into a model-core table term.
//! Coefficients multiply a feature's value and give µm.

use std::f64::consts::TAU;
use std::fmt;

use anyhow::{anyhow, Result};
use serde::{Deserialize, Serialize};

use crate::data::{Dataset, AXES};

/// Position normalisation: u = (p − centre) / half_span ∈ [−1, 1] over the
/// data's travel. Polynomials in u keep the least-squares columns of equal
/// scale (a cubic in raw millimetres is ill-conditioned by 10⁸).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Norm {
    /// Centre of the travel per axis, mm.
    pub centre_mm: [f64; 3],
    /// Half the travel per axis, mm (1 for an axis not in the data; 0.001
    /// for an axis held at one position, whose u is then 0 on the data —
    /// never 0, so u is finite everywhere).
    pub half_span_mm: [f64; 3],
}

impl Norm {
    /// The normalisation spanning the data's positions.
    pub fn from_data(data: &Dataset) -> Norm {
        let mut centre_mm = [0.0; 3];
        let mut half_span_mm = [1.0; 3];
        for (axis, col) in data.pos_mm.iter().enumerate() {
            let Some(col) = col else { continue };
            let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if lo.is_finite() && hi.is_finite() {
                centre_mm[axis] = 0.5 * (lo + hi);
                // A single-position axis still needs a non-zero span.
                half_span_mm[axis] = (0.5 * (hi - lo)).max(1e-3);
            }
        }
        Norm {
            centre_mm,
            half_span_mm,
        }
    }

    /// Normalised coordinate of `pos_mm` on `axis`.
    pub fn u(&self, axis: usize, pos_mm: f64) -> f64 {
        (pos_mm - self.centre_mm[axis]) / self.half_span_mm[axis]
    }
}

/// Sine or cosine half of a periodic pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// sin(2πk·p/period)
    Sin,
    /// cos(2πk·p/period)
    Cos,
}

impl Phase {
    /// `sin` or `cos`.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Sin => "sin",
            Phase::Cos => "cos",
        }
    }
}

/// One column of a design matrix. `exp` is the monomial u_x^a·u_y^b·u_z^c
/// in normalised coordinates ([0, 0, 0] is the constant 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Feature {
    /// u_x^a · u_y^b · u_z^c.
    Monomial {
        /// Exponents (a, b, c).
        exp: [u8; 3],
    },
    /// sin or cos(2π·k·p_axis / period): cyclic lead-screw or scale error.
    Periodic {
        /// Axis index (0 = x).
        axis: usize,
        /// Period in mm (the screw lead, or the scale's pitch).
        period_mm: f64,
        /// Harmonic number k ≥ 1.
        harmonic: u8,
        /// Sine or cosine.
        phase: Phase,
    },
    /// (T − T_ref) in K, optionally first-order lagged, times a monomial.
    Thermal {
        /// The channel name (`bed` for `T_bed_C`).
        channel: String,
        /// Reference temperature, °C (the column is zero there).
        t_ref_c: f64,
        /// First-order lag time constant in s applied along `t_s` within each
        /// session (0 = the structure follows the sensor at once).
        lag_s: f64,
        /// Monomial multiplying the temperature rise.
        exp: [u8; 3],
    },
    /// dir_axis (±1): the reversal (backlash) error is ±half the backlash.
    Reversal {
        /// Axis index.
        axis: usize,
    },
    /// tool_mm × monomial: an angle (varying with position) times the Abbe arm.
    Abbe {
        /// Monomial giving the angle's shape along the travel.
        exp: [u8; 3],
    },
    /// (t_s / 3600)^power: slow drift in time that temperature does not explain.
    Drift {
        /// Power ≥ 1.
        power: u8,
    },
}

fn mono_name(exp: [u8; 3]) -> String {
    let parts: Vec<String> = (0..3)
        .filter(|&a| exp[a] > 0)
        .map(|a| match exp[a] {
            1 => AXES[a].to_string(),
            e => format!("{}^{e}", AXES[a]),
        })
        .collect();
    if parts.is_empty() {
        "1".into()
    } else {
        parts.join("·")
    }
}

/// `x.powi(e)` without the library call for the small exponents of a
/// model's monomials: the same products in the same order as the
/// library's square-and-multiply (bit-identical), inline.
fn powi(x: f64, e: u8) -> f64 {
    match e {
        0 => 1.0,
        1 => x,
        2 => x * x,
        3 => x * (x * x),
        4 => {
            let a = x * x;
            a * a
        }
        5 => {
            let a = x * x;
            x * (a * a)
        }
        _ => x.powi(i32::from(e)),
    }
}

impl fmt::Display for Feature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Feature::Monomial { exp } => write!(f, "{}", mono_name(*exp)),
            Feature::Periodic {
                axis,
                period_mm,
                harmonic,
                phase,
            } => write!(
                f,
                "{}(2π·{harmonic}·{}/{period_mm}mm)",
                phase.name(),
                AXES[*axis]
            ),
            Feature::Thermal {
                channel,
                lag_s,
                exp,
                ..
            } => {
                let lag = if *lag_s > 0.0 {
                    format!("[lag {lag_s}s]")
                } else {
                    String::new()
                };
                match exp {
                    [0, 0, 0] => write!(f, "ΔT_{channel}{lag}"),
                    e => write!(f, "ΔT_{channel}{lag}·{}", mono_name(*e)),
                }
            }
            Feature::Reversal { axis } => write!(f, "dir_{}", AXES[*axis]),
            Feature::Abbe { exp } => match exp {
                [0, 0, 0] => write!(f, "tool"),
                e => write!(f, "tool·{}", mono_name(*e)),
            },
            Feature::Drift { power: 1 } => write!(f, "t"),
            Feature::Drift { power } => write!(f, "t^{power}"),
        }
    }
}

impl Feature {
    /// The column of this feature over every row of `data`, in the unit that
    /// makes the coefficient µm: monomials are dimensionless, thermal columns
    /// are in K (coefficient µm/K), Abbe in mm (µm/mm = mrad), drift in h^p.
    ///
    /// Fails with a message naming the missing column when the data lacks
    /// what the feature needs (`dir_y`, `T_bed_C`, `tool_mm`, `t_s`).
    pub fn column(&self, data: &Dataset, norm: &Norm) -> Result<Vec<f64>> {
        let n = data.len();
        // A monomial over every row: only the axes it has are normalised
        // and multiplied in (the same products in the same order as
        // `mono`: the skipped factors are exactly 1.0).
        let mono_col = |exp: [u8; 3]| -> Vec<f64> {
            let mut out = vec![1.0; n];
            for a in (0..3).filter(|&a| exp[a] > 0) {
                match &data.pos_mm[a] {
                    Some(col) => {
                        for (o, &p) in out.iter_mut().zip(col) {
                            *o *= powi(norm.u(a, p), exp[a]);
                        }
                    }
                    None => out.iter_mut().for_each(|o| *o *= 0.0),
                }
            }
            out
        };
        Ok(match self {
            Feature::Monomial { exp } => mono_col(*exp),
            Feature::Periodic {
                axis,
                period_mm,
                harmonic,
                phase,
            } => {
                let pos = data.pos_mm[*axis].as_ref().ok_or_else(|| {
                    anyhow!(
                        "periodic term on {}: the data has no {}_mm column",
                        AXES[*axis],
                        AXES[*axis]
                    )
                })?;
                let k = f64::from(*harmonic);
                pos.iter()
                    .map(|p| {
                        let arg = TAU * k * p / period_mm;
                        match phase {
                            Phase::Sin => arg.sin(),
                            Phase::Cos => arg.cos(),
                        }
                    })
                    .collect()
            }
            Feature::Thermal {
                channel,
                t_ref_c,
                lag_s,
                exp,
            } => {
                let ch = data
                    .temp(channel)
                    .ok_or_else(|| anyhow!("thermal term: the data has no T_{channel}_C column"))?;
                let temp = if *lag_s > 0.0 {
                    let t_s = data.t_s.as_ref().ok_or_else(|| {
                        anyhow!("thermal term with a lag: the data has no t_s column")
                    })?;
                    lagged(&ch.temp_c, t_s, data.session_id.as_deref(), *lag_s)
                } else {
                    ch.temp_c.clone()
                };
                let m = mono_col(*exp);
                temp.iter().zip(m).map(|(t, m)| (t - t_ref_c) * m).collect()
            }
            Feature::Reversal { axis } => {
                let dir = data.dir[*axis].as_ref().ok_or_else(|| {
                    anyhow!(
                        "reversal term on {0}: the data has no dir_{0} column",
                        AXES[*axis]
                    )
                })?;
                dir.iter().map(|&d| f64::from(d)).collect()
            }
            Feature::Abbe { exp } => {
                let arm = data
                    .tool_mm
                    .as_ref()
                    .ok_or_else(|| anyhow!("abbe term: the data has no tool_mm column"))?;
                arm.iter().zip(mono_col(*exp)).map(|(a, m)| a * m).collect()
            }
            Feature::Drift { power } => {
                let t_s = data
                    .t_s
                    .as_ref()
                    .ok_or_else(|| anyhow!("drift term: the data has no t_s column"))?;
                t_s.iter()
                    .map(|t| (t / 3600.0).powi(i32::from(*power)))
                    .collect()
            }
        })
    }
}

/// First-order lag of a temperature series along time, restarted at each
/// session (a new session starts from the sensor's reading).
pub fn lagged(temp_c: &[f64], t_s: &[f64], session: Option<&[i64]>, tau_s: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(temp_c.len());
    for i in 0..temp_c.len() {
        let restart = i == 0 || session.is_some_and(|s| s[i] != s[i - 1]) || t_s[i] < t_s[i - 1];
        if restart {
            out.push(temp_c[i]);
        } else {
            let a = 1.0 - (-(t_s[i] - t_s[i - 1]) / tau_s).exp();
            let prev = out[i - 1];
            out.push(prev + a * (temp_c[i] - prev));
        }
    }
    out
}

// The seed sets are model-core's (`model_core::monomials`): the one list the
// table format, its docs and the host share (STYLE: define each format
// once). Their order is the order of the fit's columns and of MODEL.json's
// coefficients; every MODEL.json names each coefficient by its exponents, so
// files written with the order the host used to have (kinematic ey/ez: the
// other axes first) read and export the same. A seed's monomials on a data
// set are `model::Seed::monomials`.
pub use model_core::monomials::{kinematic, CUBIC19};

/// True when the feature's value changes with the position of `axis`.
pub fn feature_uses_axis(f: &Feature, axis: usize) -> bool {
    match f {
        Feature::Monomial { exp } | Feature::Abbe { exp } | Feature::Thermal { exp, .. } => {
            exp[axis] > 0
        }
        Feature::Periodic { axis: a, .. } | Feature::Reversal { axis: a } => *a == axis,
        Feature::Drift { .. } => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inline_powers_are_the_library_powers_bit_for_bit() {
        // Exponents the models use and one past; values across the
        // normalised range, past it, tiny and huge.
        let mut x = -3.7f64;
        while x < 3.7 {
            for v in [x, x * 1e-150, x * 1e100] {
                for e in 0..=7u8 {
                    assert_eq!(
                        powi(v, e).to_bits(),
                        v.powi(i32::from(e)).to_bits(),
                        "{v}^{e}"
                    );
                }
            }
            x += 0.013_7;
        }
    }

    #[test]
    fn cubic19_has_19_distinct_terms_and_no_xyz() {
        let mut v = CUBIC19.to_vec();
        v.sort();
        v.dedup();
        assert_eq!(v.len(), 19);
        assert!(!v.contains(&[1, 1, 1]));
        assert!(v.iter().all(|e| e.iter().sum::<u8>() <= 3));
    }

    #[test]
    fn kinematic_has_no_linear_cross_terms() {
        for t in 0..3 {
            let k = kinematic(t);
            assert_eq!(k.len(), 8);
            for e in k {
                let nonzero = e.iter().filter(|&&p| p > 0).count();
                assert!(nonzero <= 1, "{e:?} is a cross term");
                for a in 0..3 {
                    if a != t {
                        assert_ne!(e[a], 1, "{e:?} is linear in another axis");
                    }
                }
            }
        }
    }

    #[test]
    fn lag_approaches_step() {
        let t_s: Vec<f64> = (0..100).map(|i| f64::from(i) * 60.0).collect();
        let temp: Vec<f64> = (0..100).map(|i| if i < 10 { 20.0 } else { 25.0 }).collect();
        let lagged = lagged(&temp, &t_s, None, 600.0);
        // The step is first seen at row 10 (t = 600 s); ten 60 s updates later
        // (row 19, one time constant of exposure) it is 1 − 1/e of the way.
        assert!((lagged[19] - (20.0 + 5.0 * (1.0 - (-1.0f64).exp()))).abs() < 1e-9);
        assert!((lagged[99] - 25.0).abs() < 1e-3);
    }
}
