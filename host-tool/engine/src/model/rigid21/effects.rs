//! The named effects on top of a rigid21 model (docs/volumetric.md §
//! Effects on top): a periodic lead error, a reversal, a thermal growth —
//! the `--add` effects of the linear models, with their columns
//! (`features.rs`) and their saved form ([`LinearModel`]) — added to the
//! error vector at the row's tool point. Their values come from the row's
//! data (positions, `dir_*`, `T_*_C`, `t_s`), not from a tool point alone,
//! so every prediction that includes them reads a data set.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::{Prediction, Rigid21Model, ToolPoint};
use crate::data::Dataset;
use crate::features::Norm;
use crate::model::linear::{check_linear_outputs, check_norm};
use crate::model::LinearModel;

impl Rigid21Model {
    /// The normalisation the effects' monomials use: per axis of the chain
    /// the centre and half-span of its measured travel (the table's input
    /// scaling, so a thermal monomial means the same number on the board);
    /// 0 ± 1 mm for an axis the machine lacks.
    pub fn travel_norm(&self) -> Norm {
        let mut norm = Norm {
            centre_mm: [0.0; 3],
            half_span_mm: [1.0; 3],
        };
        for a in 0..3 {
            if let Some([lo, hi]) = self.travel_mm[a] {
                norm.centre_mm[a] = 0.5 * (lo + hi);
                norm.half_span_mm[a] = (0.5 * (hi - lo)).max(1e-3);
            }
        }
        norm
    }

    /// The model at every row of `data`: the geometric errors at the row's
    /// tool point plus the effects on top, from the row's data. Err when
    /// the data lack a column an effect reads (`T_bed_C`, `dir_x`, …).
    pub fn predict_readings(&self, data: &Dataset) -> Result<Vec<Prediction>> {
        let mut out: Vec<Prediction> = (0..data.len())
            .map(|r| self.predict(&ToolPoint::of_row(data, r)))
            .collect();
        if let Some(fx) = &self.effects {
            for o in &fx.outputs {
                let v = o.predict(data, &fx.norm)?;
                for (p, v) in out.iter_mut().zip(v) {
                    p.e_um[o.target] += v;
                }
            }
        }
        Ok(out)
    }

    /// The error vector (µm) at every row of `data`, per component,
    /// effects included.
    pub fn predict_rows(&self, data: &Dataset) -> Result<[Vec<f64>; 3]> {
        let mut out: [Vec<f64>; 3] = Default::default();
        for p in self.predict_readings(data)? {
            for (col, v) in out.iter_mut().zip(p.e_um) {
                col.push(v);
            }
        }
        Ok(out)
    }

    /// The effects' fields: a normalisation and, per target, features with
    /// one finite coefficient each.
    pub(super) fn check_effects(&self) -> Result<(), String> {
        let Some(LinearModel { norm, outputs }) = &self.effects else {
            return Ok(());
        };
        check_norm(norm, "model.effects.norm")?;
        check_linear_outputs(outputs, "model.effects.outputs")
    }
}

/// A named effect's fitted coefficients (`fit --json` `effects`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectAnswer {
    /// The effect as recorded in `adds`.
    pub effect: String,
    /// Its columns (`sin(2π·1·x/100mm)`), in order.
    pub features: Vec<String>,
    /// One coefficient per column, µm per unit of the column.
    pub coef_um: Vec<f64>,
    /// Their standard uncertainties.
    pub coef_sd_um: Vec<f64>,
    /// Its physical parameter's name (`amplitude`, `backlash`, `cte`), when
    /// it is read off the coefficients directly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<String>,
    /// That parameter's value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// Its unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}
