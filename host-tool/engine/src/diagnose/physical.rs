//! A candidate's physical parameter (CTE, backlash, amplitude, angle,
//! drift rate, …) with its 95 % interval and a plausibility check — read
//! off the fit as its family describes it (`effect::PhysicalParam`) — and
//! the covariance that takes a searched thermal lag's own uncertainty into
//! account.

use crate::effect::{EffectSpec, Reading, Scale};
use crate::features::Feature;

use super::search::Proposal;
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

/// The physical parameter of proposal `p` fitted as `ff` (residual
/// variance `sigma2`), as its family describes it
/// ([`crate::effect::PhysicalParam`]): the value, its 95 % interval and
/// whether it is plausible.
pub(super) fn physical(
    td: &TargetData,
    p: &Proposal,
    ff: &FwlFit,
    sigma2: f64,
) -> Option<Physical> {
    let param = p.spec.physical()?;
    let beta = &ff.fit.beta;
    let cov = |i: usize, j: usize| sigma2 * ff.fit.xtx_inv[(i, j)];
    let (value, ci95, plausible) = match param.reading {
        Reading::Linear { scale, max_abs } => {
            let scale = match scale {
                Scale::Fixed(k) => k,
                Scale::PerMetreAlong(a) => 1000.0 / td.norm.half_span_mm[a.index()],
            };
            let v = beta[0] * scale;
            let se = cov(0, 0).max(0.0).sqrt() * scale.abs();
            (v, [v - 1.96 * se, v + 1.96 * se], v.abs() <= max_abs)
        }
        Reading::Amplitude {
            period_mm,
            periods_mm,
            max_um,
        } => {
            let (a, b) = (beta[0], beta[1]);
            let amp = (a * a + b * b).sqrt();
            let se = if amp > 0.0 {
                ((a * a * cov(0, 0) + b * b * cov(1, 1) + 2.0 * a * b * cov(0, 1)) / (amp * amp))
                    .max(0.0)
                    .sqrt()
            } else {
                0.0
            };
            let plausible = (periods_mm[0]..=periods_mm[1]).contains(&period_mm) && amp <= max_um;
            (amp, [amp - 1.96 * se, amp + 1.96 * se], plausible)
        }
        Reading::MeanRate { max_abs } => {
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
            (v, [v - 1.96 * se, v + 1.96 * se], v.abs() <= max_abs)
        }
        Reading::ComponentRms => {
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
            (amp, [(amp - 1.96 * se).max(0.0), amp + 1.96 * se], true)
        }
    };
    Some(Physical {
        name: param.name.into(),
        unit: param.unit.into(),
        value,
        ci95,
        plausible,
        expected: param.expected.into(),
    })
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
    spec: &EffectSpec,
    ff: &FwlFit,
) -> Option<nalgebra::DMatrix<f64>> {
    let features = spec.features();
    // A multi-sensor effect has a lag per channel: the one-lag derivative
    // below does not apply (its intervals take the lags as known).
    if features.iter().any(|f| {
        matches!((f, features.first()), (Feature::Thermal { channel: a, .. }, Some(Feature::Thermal { channel: b, .. })) if a != b)
    }) {
        return None;
    }
    let lag = match features.first()? {
        Feature::Thermal { lag_s, .. } if *lag_s > 0.0 => *lag_s,
        _ => return None,
    };
    let h = (0.02 * lag).max(1.0);
    let cols_at = |l: f64| -> Option<Vec<Vec<f64>>> {
        features
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
