//! Small models for the export tests: a model file around any fitted
//! model, and linear models of a few terms whose corrections are known by
//! hand.

use crate::features::{Feature, Norm};
use crate::model::MODEL_FORMAT;
use crate::model::{DataRef, FitStats, FittedModel, LinearModel, LinearOutput, ModelFile};

/// `model` as a model file (fitted data: no temperature channels).
pub(crate) fn file(model: FittedModel) -> ModelFile {
    ModelFile {
        format: MODEL_FORMAT.into(),
        seed: "test".into(),
        adds: vec![],
        data: DataRef {
            source: "test".into(),
            sha256: "ab".repeat(32),
            rows: 0,
            temp_range_c: Some(Default::default()),
            outside_travel: Vec::new(),
        },
        model,
        stats: FitStats::default(),
    }
}

/// A linear model of one output, `target`, with `terms` (feature,
/// coefficient µm), fitted on 0…200 mm of every axis: u = (pos − 100) /
/// 100.
pub(crate) fn linear(target: usize, terms: &[(Feature, f64)]) -> ModelFile {
    file(FittedModel::Linear(LinearModel {
        norm: Norm {
            centre_mm: [100.0; 3],
            half_span_mm: [100.0; 3],
        },
        outputs: vec![LinearOutput {
            target,
            features: terms.iter().map(|t| t.0.clone()).collect(),
            coef_um: terms.iter().map(|t| t.1).collect(),
            coef_sd_um: vec![0.0; terms.len()],
        }],
    }))
}

/// The monomial u_x^i·u_y^j·u_z^k.
pub(crate) fn mono(exp: [u8; 3]) -> Feature {
    Feature::Monomial { exp }
}
