//! A candidate's physical parameter (CTE, backlash, amplitude, angle,
//! drift rate, …) with its 95 % interval and a plausibility check, and the
//! covariance that takes a searched thermal lag's own uncertainty into
//! account.

use crate::effect::{Effect, Family};
use crate::features::Feature;

use super::candidates::Proposal;
use super::target::{FwlFit, State, TargetData};
use super::Physical;
use crate::linalg::basis::small_fit;

/// The `params` key of a physical parameter: its name and unit
/// (`cte` in µm/m/K → `cte_um_per_m_k`).
pub(super) fn param_key(ph: &Physical) -> String {
    let unit = ph
        .unit
        .replace('µ', "u")
        .replace('/', "_per_")
        .to_lowercase();
    format!("{}_{unit}", ph.name)
}

pub(super) fn physical(
    td: &TargetData,
    p: &Proposal,
    ff: &FwlFit,
    sigma2: f64,
) -> Option<Physical> {
    let beta = &ff.fit.beta;
    let cov = |i: usize, j: usize| sigma2 * ff.fit.xtx_inv[(i, j)];
    let lin = |scale: f64, name: &str, unit: &str, max_abs: f64, expected: &str| {
        let v = beta[0] * scale;
        let se = cov(0, 0).max(0.0).sqrt() * scale.abs();
        Some(Physical {
            name: name.into(),
            unit: unit.into(),
            value: v,
            ci95: [v - 1.96 * se, v + 1.96 * se],
            plausible: v.abs() <= max_abs,
            expected: expected.into(),
        })
    };
    let half = |a: usize| td.norm.half_span_mm[a];
    match p.family {
        Family::Periodic => {
            let (a, b) = (beta[0], beta[1]);
            let amp = (a * a + b * b).sqrt();
            let se = if amp > 0.0 {
                ((a * a * cov(0, 0) + b * b * cov(1, 1) + 2.0 * a * b * cov(0, 1)) / (amp * amp))
                    .max(0.0)
                    .sqrt()
            } else {
                0.0
            };
            let e = Effect::parse(&p.spec).ok()?;
            let period = match e.features.first()? {
                Feature::Periodic { period_mm, .. } => *period_mm,
                _ => return None,
            };
            Some(Physical {
                name: "amplitude".into(),
                unit: "µm".into(),
                value: amp,
                ci95: [amp - 1.96 * se, amp + 1.96 * se],
                plausible: (0.5..=100.0).contains(&period) && amp <= 20.0,
                expected: "periods 0.5–100 mm (leads 2–40 mm), amplitude up to ~8 µm".into(),
            })
        }
        Family::Thermal => match p.axis {
            Some(a) => lin(
                1000.0 / half(a),
                "cte",
                "µm/m/K",
                30.0,
                "|CTE| ≤ 30 µm/m/K (steel 11.5, cast iron 10, aluminium 23)",
            ),
            None => lin(1.0, "offset_per_kelvin", "µm/K", 20.0, "≤ 20 µm/K"),
        },
        Family::Reversal => lin(2.0, "backlash", "µm", 60.0, "backlash 1–50 µm"),
        Family::Abbe => {
            let scale = 1000.0;
            lin(scale, "angle", "µrad", 300.0, "angular errors 10–60 µrad")
        }
        Family::Drift => {
            // The mean rate over the session, (f(t_end) − f(t_start)) / span,
            // a linear combination of every power's coefficient (the linear
            // coefficient alone is not the rate once t² or t³ is in).
            let t_s = td.data.t_s.as_ref()?;
            let (lo, hi) = td
                .rows
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, &r| {
                    (a.0.min(t_s[r]), a.1.max(t_s[r]))
                });
            let (h0, h1) = (lo / 3600.0, hi / 3600.0);
            if h1 <= h0 {
                return None;
            }
            let g: Vec<f64> = (1..=beta.len())
                .map(|p| (h1.powi(p as i32) - h0.powi(p as i32)) / (h1 - h0))
                .collect();
            let v: f64 = g.iter().zip(beta).map(|(g, b)| g * b).sum();
            let var: f64 = (0..g.len())
                .flat_map(|i| (0..g.len()).map(move |j| (i, j)))
                .map(|(i, j)| g[i] * g[j] * cov(i, j))
                .sum();
            let se = var.max(0.0).sqrt();
            Some(Physical {
                name: "rate".into(),
                unit: "µm/h".into(),
                value: v,
                ci95: [v - 1.96 * se, v + 1.96 * se],
                plausible: v.abs() <= 30.0,
                expected: "≤ 30 µm/h (mean over the session)".into(),
            })
        }
        Family::Squareness => {
            let a = p.axis?;
            lin(
                1000.0 / half(a),
                "angle",
                "µrad",
                300.0,
                "squareness 20–40 µrad",
            )
        }
        Family::HigherOrder => {
            let n = td.rows.len() as f64;
            let comp: f64 = (0..td.rows.len())
                .map(|r| {
                    let v: f64 = ff.partialled.iter().zip(beta).map(|(c, b)| c[r] * b).sum();
                    v * v
                })
                .sum();
            let amp = (comp / n).sqrt();
            // amp² = βᵀ(XᵀX/n)β with X the partialled columns; by the delta
            // method var(amp) = σ²·βᵀXᵀX(XᵀX)⁻¹XᵀXβ/(n²·amp²) = σ²/n. (The
            // interval was [amp, amp] before: a zero-width interval is a
            // claim of certainty the data do not give.)
            let se = (sigma2.max(0.0) / n).sqrt();
            Some(Physical {
                name: "component_rms".into(),
                unit: "µm".into(),
                value: amp,
                ci95: [(amp - 1.96 * se).max(0.0), amp + 1.96 * se],
                plausible: true,
                expected: "any".into(),
            })
        }
    }
}

/// (XᵀX)⁻¹ of a lagged thermal candidate's coefficients with the lag's own
/// uncertainty in it: the lag is estimated from the same data, so the
/// coefficient covariance is the (β, β) block of σ²(JᵀJ)⁻¹ with J the
/// candidate's columns plus ∂(Σ β_k c_k)/∂lag (central difference), all with
/// the model partialled out. Taking the lag as known made the CTE interval
/// too narrow to cover the truth when the lag was a little off. None for
/// other candidates and lag 0 (at the edge of the search).
pub(super) fn lag_aware_xtx_inv(
    td: &TargetData,
    st: &State,
    spec: &str,
    ff: &FwlFit,
) -> Option<nalgebra::DMatrix<f64>> {
    let e = Effect::parse(spec).ok()?;
    // A multi-sensor effect has a lag per channel: the one-lag derivative
    // below does not apply (its intervals take the lags as known).
    if e.features.iter().any(|f| {
        matches!((f, e.features.first()), (Feature::Thermal { channel: a, .. }, Some(Feature::Thermal { channel: b, .. })) if a != b)
    }) {
        return None;
    }
    let lag = match e.features.first()? {
        Feature::Thermal { lag_s, .. } if *lag_s > 0.0 => *lag_s,
        _ => return None,
    };
    let h = (0.02 * lag).max(1.0);
    let cols_at = |l: f64| -> Option<Vec<Vec<f64>>> {
        e.features
            .iter()
            .map(|f| match f {
                Feature::Thermal {
                    channel,
                    t_ref_c,
                    exp,
                    ..
                } => td
                    .col(&Feature::Thermal {
                        channel: channel.clone(),
                        t_ref_c: *t_ref_c,
                        lag_s: l,
                        exp: *exp,
                    })
                    .ok(),
                _ => None,
            })
            .collect()
    };
    let (up, down) = (cols_at(lag + h)?, cols_at(lag - h)?);
    let n = td.rows.len();
    let d: Vec<f64> = (0..n)
        .map(|r| {
            ff.fit
                .beta
                .iter()
                .enumerate()
                .map(|(k, b)| b * (up[k][r] - down[k][r]) / (2.0 * h))
                .sum()
        })
        .collect();
    let mut aug = ff.partialled.clone();
    aug.push(st.basis.residual(&d));
    let full = small_fit(&aug, &st.resid);
    if full.rank < aug.len() {
        return None;
    }
    let k = ff.partialled.len();
    Some(full.xtx_inv.view((0, 0), (k, k)).into_owned())
}
