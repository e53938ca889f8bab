//! Models linear in their features: the cubic19 and kinematic seeds plus
//! the `--add` effects — per target Σ coef_j · feature_j — with their
//! evaluation and the checks of their fields.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::check::{check_finite, check_index, check_len, nan_as_null, need, Check};
use crate::data::{Dataset, AXES, TARGETS};
use crate::features::{Feature, Norm};

/// A model linear in its features: per target, Σ coef_j · feature_j.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearModel {
    /// Position normalisation the monomials use.
    pub norm: Norm,
    /// One entry per target, in target order.
    pub outputs: Vec<LinearOutput>,
}

/// The linear model of one target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearOutput {
    /// Target index (0 = ex).
    pub target: usize,
    /// The columns, in order.
    pub features: Vec<Feature>,
    /// Coefficient per feature; the feature's value times it gives µm.
    pub coef_um: Vec<f64>,
    /// Standard deviation of each coefficient (null in JSON when the fit
    /// had no residual degrees of freedom).
    #[serde(with = "nan_as_null")]
    pub coef_sd_um: Vec<f64>,
}

impl LinearOutput {
    /// The model value per row of `data`, µm.
    pub fn predict(&self, data: &Dataset, norm: &Norm) -> Result<Vec<f64>> {
        let mut out = vec![0.0; data.len()];
        for (f, c) in self.features.iter().zip(&self.coef_um) {
            let col = f.column(data, norm)?;
            for (o, v) in out.iter_mut().zip(col) {
                *o += c * v;
            }
        }
        Ok(out)
    }
}

pub(crate) fn check_norm(n: &Norm, at: &str) -> Check {
    check_finite(&n.centre_mm, &format!("{at}.centre_mm"))?;
    for (a, &h) in n.half_span_mm.iter().enumerate() {
        need(
            h.is_finite() && h > 0.0,
            || format!("{at}.half_span_mm[{a}]"),
            || {
                format!(
                    "{h}, expected a positive number of mm (1 for an axis absent from the data, 0.001 for one held at one position)"
                )
            },
        )?;
    }
    Ok(())
}

pub(crate) fn check_feature(f: &Feature, at: &str) -> Check {
    match f {
        Feature::Monomial { .. } | Feature::Abbe { .. } => Ok(()),
        Feature::Periodic {
            axis,
            period_mm,
            harmonic,
            ..
        } => {
            check_index(*axis, &AXES, || format!("{at}.axis"))?;
            need(
                period_mm.is_finite() && *period_mm > 0.0,
                || format!("{at}.period_mm"),
                || format!("{period_mm}, expected a positive number of mm"),
            )?;
            need(
                *harmonic >= 1,
                || format!("{at}.harmonic"),
                || "0, expected ≥ 1".into(),
            )
        }
        Feature::Thermal {
            channel,
            t_ref_c,
            lag_s,
            ..
        } => {
            need(
                !channel.is_empty(),
                || format!("{at}.channel"),
                || "empty, expected a channel name (`bed` for T_bed_C)".into(),
            )?;
            need(
                t_ref_c.is_finite(),
                || format!("{at}.t_ref_c"),
                || format!("{t_ref_c}, expected a finite °C"),
            )?;
            need(
                lag_s.is_finite() && *lag_s >= 0.0,
                || format!("{at}.lag_s"),
                || format!("{lag_s}, expected a number of s ≥ 0"),
            )
        }
        Feature::Reversal { axis } => check_index(*axis, &AXES, || format!("{at}.axis")),
        Feature::Drift { power } => need(
            *power >= 1,
            || format!("{at}.power"),
            || "0, expected ≥ 1".into(),
        ),
    }
}

pub(crate) fn check_linear_outputs(outputs: &[LinearOutput], at: &str) -> Check {
    need(
        !outputs.is_empty(),
        || at.to_string(),
        || "empty, expected one entry per target the model predicts".into(),
    )?;
    let targets: Vec<usize> = outputs.iter().map(|o| o.target).collect();
    for (k, o) in outputs.iter().enumerate() {
        let at = format!("{at}[{k}]");
        check_index(o.target, &TARGETS, || format!("{at}.target"))?;
        need(
            !targets[..k].contains(&o.target),
            || format!("{at}.target"),
            || format!("{} ({}) appears twice", o.target, TARGETS[o.target]),
        )?;
        need(
            !o.features.is_empty(),
            || format!("{at}.features"),
            || "empty, expected at least one term".into(),
        )?;
        for (j, f) in o.features.iter().enumerate() {
            check_feature(f, &format!("{at}.features[{j}]"))?;
        }
        let n = o.features.len();
        check_len(
            o.coef_um.len(),
            n,
            &format!("{at}.coef_um"),
            "one per feature",
        )?;
        check_finite(&o.coef_um, &format!("{at}.coef_um"))?;
        check_len(
            o.coef_sd_um.len(),
            n,
            &format!("{at}.coef_sd_um"),
            "one per feature",
        )?;
    }
    Ok(())
}
