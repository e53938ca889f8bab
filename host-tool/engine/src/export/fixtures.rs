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

/// A rigid21:D model of the default chain over 800 × 500 × 400 mm
/// with every coefficient a fixed pseudo-random value of a few µm/µrad.
pub(crate) fn rigid21(degree: usize) -> crate::model::Rigid21Model {
    use crate::model::rigid21::{Chain, Rigid21Model};
    let chain = Chain::default();
    let mut errors = Rigid21Model::layout(&chain, degree);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for e in &mut errors {
        let c = (0..e.degrees.len())
            .map(|_| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 8.0
            })
            .collect();
        e.coef = Some(c);
    }
    Rigid21Model {
        degree,
        chain,
        travel_mm: [Some([0.0, 800.0]), Some([0.0, 500.0]), Some([0.0, 400.0])],
        errors,
        effects: None,
    }
}
