//! The fitted model and its file, MODEL.json (`trueaxis-model/1`): what
//! `fit` writes and `compare`, `diagnose`, `export` and `history` read.
//!
//! A model file is self-contained: the model kind with everything needed to
//! evaluate it (normalisation, features and coefficients, network weights,
//! grid nodes, local patches), the spec it came from (seed and `--add`
//! effects, so a refit is one command away), the data it was fitted to
//! (path, SHA-256 of the canonical CSV, rows) and the fit statistics.
//! Every prediction is in µm, per target (ex, ey, ez) present in the model.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::data::{Dataset, AXES, TARGETS};
use crate::features::{Feature, Norm};

/// Format tag written into every MODEL.json; readers refuse other values.
pub const MODEL_FORMAT: &str = "trueaxis-model/1";

/// MODEL.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always [`MODEL_FORMAT`].
    pub format: String,
    /// The seed spec: `cubic19`, `kinematic`, `nn:16`, `grid:50`, `cubic19 --local`.
    pub seed: String,
    /// `--add` effect specs, in order (canonical form from `Effect::parse`).
    pub adds: Vec<String>,
    /// The data the model was fitted to.
    pub data: DataRef,
    /// The model itself.
    pub model: FittedModel,
    /// Fit statistics.
    pub stats: FitStats,
}

/// Which data a model was fitted to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataRef {
    /// The data set's source (path as given, or `simulate:<preset>`).
    pub source: String,
    /// SHA-256 (hex) of the data set's canonical CSV (`Dataset::content_hash`).
    pub sha256: String,
    /// Number of rows.
    pub rows: usize,
}

/// Statistics of a fit. Maps are keyed by target name (`ex`, `ey`, `ez`) and
/// hold only the targets present; values are µm unless named otherwise.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FitStats {
    /// Number of coefficients per target of the largest per-target model
    /// (19 for cubic19; grid nodes for a grid; network weights for nn).
    pub terms: usize,
    /// Coefficients per target.
    #[serde(default)]
    pub terms_per_target: BTreeMap<String, usize>,
    /// Rows used per target (where the target is measured).
    #[serde(default)]
    pub rows: BTreeMap<String, usize>,
    /// RMS of the fit residual (measured − model) over the fitted rows.
    pub rms_um: BTreeMap<String, f64>,
    /// RMS of the block-held-out residual (see `holdout`); absent for a
    /// target where nothing can be held out.
    pub held_out_rms_um: BTreeMap<String, f64>,
    /// Largest |residual| over the fitted rows.
    pub max_abs_um: BTreeMap<String, f64>,
    /// σ_max/σ_min of the weighted, column-scaled design matrix (linear and
    /// local models; for local, the worst patch).
    #[serde(default)]
    pub condition_number: BTreeMap<String, f64>,
    /// How the hold-out blocks were formed.
    #[serde(default)]
    pub holdout: String,
    /// Things the user should know (ill-conditioning, grid nodes without
    /// data, training stopped at the epoch limit, …).
    #[serde(default)]
    pub warnings: Vec<String>,
}

/// The model, by kind (`"kind": "linear" | "nn" | "grid" | "local"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FittedModel {
    /// Linear in its features (cubic19, kinematic, plus effects).
    Linear(LinearModel),
    /// tanh MLP.
    Nn(NnModel),
    /// Table with (bi/tri)linear interpolation.
    Grid(GridModel),
    /// Piecewise local polynomials (`--local`).
    Local(LocalModel),
}

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

/// A tanh MLP, one network for all targets: inputs are the axes in
/// `inputs`, min-max scaled to [−1, 1]; outputs are the targets in
/// `outputs`, scaled back from [−1, 1]. y = W2·tanh(W1·x + b1) + b2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NnModel {
    /// Axis index per input.
    pub inputs: Vec<usize>,
    /// Target index per output.
    pub outputs: Vec<usize>,
    /// Input range per input (mm) mapped to [−1, 1].
    pub in_min_mm: Vec<f64>,
    /// Upper end of each input range (mm).
    pub in_max_mm: Vec<f64>,
    /// Output range per output (µm) mapped to [−1, 1].
    pub out_min_um: Vec<f64>,
    /// Upper end of each output range (µm).
    pub out_max_um: Vec<f64>,
    /// Hidden neurons.
    pub hidden: usize,
    /// Hidden weights, row-major hidden × inputs.
    pub w1: Vec<f64>,
    /// Hidden biases.
    pub b1: Vec<f64>,
    /// Output weights, row-major outputs × hidden.
    pub w2: Vec<f64>,
    /// Output biases.
    pub b2: Vec<f64>,
    /// Training summary.
    pub training: NnTraining,
}

/// How a network was trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NnTraining {
    /// Epochs run.
    pub epochs: usize,
    /// Epoch whose weights were kept (best validation error).
    pub best_epoch: usize,
    /// Why training stopped (`validation` after 6 failures, `max_epochs`, `mu_max`, `min_grad`).
    pub stop: String,
    /// RNG seed of the Nguyen–Widrow initialisation and the split.
    pub seed: u64,
    /// Rows used for training / validation (early stopping) / test (held-out RMS).
    pub split_rows: [usize; 3],
}

/// A grid table over `axes` with (bi/tri)linear interpolation; outside the
/// grid the value is held at the edge (as a controller's table does).
/// Node (i0, i1, …) is at origin + i·step; values are stored with the first
/// listed axis varying fastest: index = i0 + n0·(i1 + n1·i2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridModel {
    /// Axis index per grid dimension (the axes that vary in the data).
    pub axes: Vec<usize>,
    /// First node per dimension, mm.
    pub origin_mm: Vec<f64>,
    /// Node spacing, mm (same on every axis).
    pub step_mm: f64,
    /// Nodes per dimension.
    pub counts: Vec<usize>,
    /// Node values per target.
    pub outputs: Vec<GridOutput>,
}

/// Grid node values of one target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridOutput {
    /// Target index.
    pub target: usize,
    /// One value per node, µm.
    pub values_um: Vec<f64>,
}

/// Local polynomials (SEEDS.md: "for a point, fit locally on the cuboid
/// between two measured planes, or on the plane, or on the line"). With a
/// stacking axis, `patches[i]` covers planes i and i+1 of `planes_mm` along
/// it, and a point uses the patch whose bracket contains it (clamped to the
/// first / last patch outside). Without one (plane or line data), a single
/// patch covers everything.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalModel {
    /// `cuboid`, `plane` or `line`.
    pub shape: String,
    /// Position normalisation the monomials use.
    pub norm: Norm,
    /// The axis the measured planes are stacked along (cuboid only).
    pub stack_axis: Option<usize>,
    /// Positions of the measured planes along `stack_axis`, ascending, mm.
    pub planes_mm: Vec<f64>,
    /// One local fit per pair of neighbouring planes (or one in total).
    pub patches: Vec<LocalPatch>,
}

/// One local fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalPatch {
    /// Lower bracketing plane, mm (0 when there is no stacking axis).
    pub lo_mm: f64,
    /// Upper bracketing plane, mm.
    pub hi_mm: f64,
    /// The patch's polynomial per target.
    pub outputs: Vec<LinearOutput>,
}

impl LocalModel {
    /// Index of the patch used for a position `p_mm` on the stacking axis.
    pub fn patch_index(&self, p_mm: f64) -> usize {
        if self.patches.len() <= 1 || self.planes_mm.len() < 2 {
            return 0;
        }
        // Planes are ascending; patch i spans planes i..i+1.
        let i = self.planes_mm.partition_point(|&c| c <= p_mm);
        i.saturating_sub(1).min(self.patches.len() - 1)
    }
}

impl FittedModel {
    /// Targets the model predicts.
    pub fn targets(&self) -> Vec<usize> {
        let mut t: Vec<usize> = match self {
            FittedModel::Linear(m) => m.outputs.iter().map(|o| o.target).collect(),
            FittedModel::Nn(m) => m.outputs.clone(),
            FittedModel::Grid(m) => m.outputs.iter().map(|o| o.target).collect(),
            FittedModel::Local(m) => m
                .patches
                .iter()
                .flat_map(|p| p.outputs.iter().map(|o| o.target))
                .collect(),
        };
        t.sort_unstable();
        t.dedup();
        t
    }

    /// The model's value (µm) at every row of `data`, per target the model
    /// has (`None` for targets it does not model). Fails when the data lacks
    /// a position axis or channel the model needs.
    pub fn predict(&self, data: &Dataset) -> Result<[Option<Vec<f64>>; 3]> {
        let mut out: [Option<Vec<f64>>; 3] = [None, None, None];
        match self {
            FittedModel::Linear(m) => {
                for o in &m.outputs {
                    out[o.target] = Some(o.predict(data, &m.norm)?);
                }
            }
            FittedModel::Nn(m) => {
                let pred = crate::fit::nn::predict(m, data)?;
                for (k, &t) in m.outputs.iter().enumerate() {
                    out[t] = Some(pred[k].clone());
                }
            }
            FittedModel::Grid(m) => {
                for o in &m.outputs {
                    out[o.target] = Some(crate::fit::grid::predict(m, o, data)?);
                }
            }
            FittedModel::Local(m) => {
                let n = data.len();
                let patch_of: Vec<usize> = match m.stack_axis {
                    Some(a) => {
                        let col = data.pos_mm[a]
                            .as_ref()
                            .with_context(|| format!("the local model needs {}_mm", AXES[a]))?;
                        col.iter().map(|&p| m.patch_index(p)).collect()
                    }
                    None => vec![0; n],
                };
                for t in self.targets() {
                    let mut v = vec![0.0; n];
                    for (pi, patch) in m.patches.iter().enumerate() {
                        let Some(o) = patch.outputs.iter().find(|o| o.target == t) else {
                            continue;
                        };
                        let rows: Vec<usize> = (0..n).filter(|&r| patch_of[r] == pi).collect();
                        if rows.is_empty() {
                            continue;
                        }
                        // Evaluate only the rows of this patch.
                        let sub = crate::holdout::subset(data, &rows);
                        let pv = o.predict(&sub, &m.norm)?;
                        for (r, p) in rows.iter().zip(pv) {
                            v[*r] = p;
                        }
                    }
                    out[t] = Some(v);
                }
            }
        }
        Ok(out)
    }

    /// Residuals measured − model (µm) on the rows where each target is
    /// measured, as (row, residual) per target.
    pub fn residuals(&self, data: &Dataset) -> Result<Residuals> {
        let pred = self.predict(data)?;
        let mut out: Residuals = [None, None, None];
        for t in 0..3 {
            if let Some(p) = &pred[t] {
                out[t] = Some(data.measured(t).map(|(r, e)| (r, e - p[r])).collect());
            }
        }
        Ok(out)
    }
}

impl ModelFile {
    /// The model spec as a command line fragment: the seed, then
    /// ` --add <effect>` per effect (the `model` field of `fit --json`).
    pub fn spec(&self) -> String {
        let mut s = self.seed.clone();
        for a in &self.adds {
            s.push_str(" --add ");
            s.push_str(a);
        }
        s
    }

    /// Reads and checks a MODEL.json.
    pub fn load(path: impl AsRef<Path>) -> Result<ModelFile> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read model file {}", path.display()))?;
        let m: ModelFile = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a trueaxis model file", path.display()))?;
        if m.format != MODEL_FORMAT {
            bail!(
                "{}: model format `{}`, this trueaxis reads `{MODEL_FORMAT}`",
                path.display(),
                m.format
            );
        }
        Ok(m)
    }

    /// Writes MODEL.json (pretty-printed).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(self)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write model file {}", path.display()))
    }

    /// The `fit --json` document (CONTRACT §2): model, terms, rms_um,
    /// held_out_rms_um, max_abs_um, then more fields.
    pub fn summary_json(&self, model_path: Option<&Path>) -> serde_json::Value {
        let s = &self.stats;
        let mut v = serde_json::json!({
            "model": self.spec(),
            "terms": s.terms,
            "rms_um": s.rms_um,
            "held_out_rms_um": s.held_out_rms_um,
            "max_abs_um": s.max_abs_um,
            "kind": match self.model {
                FittedModel::Linear(_) => "linear",
                FittedModel::Nn(_) => "nn",
                FittedModel::Grid(_) => "grid",
                FittedModel::Local(_) => "local",
            },
            "terms_per_target": s.terms_per_target,
            "rows": s.rows,
            "condition_number": s.condition_number,
            "holdout": s.holdout,
            "warnings": s.warnings,
            "data_sha256": self.data.sha256,
        });
        if let Some(p) = model_path {
            v["model_file"] = serde_json::Value::String(p.display().to_string());
        }
        v
    }
}

/// Residuals (row, measured − model in µm) per target; `None` for a target
/// the model does not cover.
pub type Residuals = [Option<Vec<(usize, f64)>>; 3];

/// Target name for messages and JSON keys.
pub fn target_name(t: usize) -> &'static str {
    TARGETS[t]
}

/// `Vec<f64>` with NaN written as JSON null and read back as NaN (serde_json
/// writes non-finite floats as null but cannot read null into an f64).
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let o: Vec<Option<f64>> = v.iter().map(|x| x.is_finite().then_some(*x)).collect();
        o.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let o: Vec<Option<f64>> = Vec::deserialize(d)?;
        Ok(o.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
    }
}
