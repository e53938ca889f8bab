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
    /// The measured range of each temperature channel, °C, by channel name
    /// (`{"bed": [20.0, 23.0]}`; `{}` for data without `T_*_C` columns).
    /// `export` makes it the table's default temperature envelope, so the
    /// thermal terms are not extrapolated. `None` (the key absent) in files
    /// written before it was recorded: export then falls back to 10…40 °C
    /// with the warning `temp_range_unknown`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temp_range_c: Option<BTreeMap<String, [f64; 2]>>,
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
        let value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a trueaxis model file (not JSON)", path.display()))?;
        // Another trueaxis file, or another command's output, given where a
        // model belongs: say which, not what serde missed in it.
        let format = value.get("format").and_then(|f| f.as_str());
        let other = match format {
            Some(MODEL_FORMAT) => None,
            Some(crate::history::HISTORY_FORMAT) => Some(
                "it is a fit history (MODEL.history.json); give the model file next to it"
                    .to_string(),
            ),
            Some(f) if f.starts_with("trueaxis-model/") => bail!(
                "{}: model format `{f}`, this trueaxis reads `{MODEL_FORMAT}`",
                path.display()
            ),
            Some(f) => Some(format!("its format is `{f}`")),
            None if value.get("candidates").is_some() => {
                Some("it looks like the output of `trueaxis diagnose --json`".into())
            }
            None if value.get("rms_um").is_some() => {
                Some("it looks like the output of `trueaxis compare` or `fit --json`".into())
            }
            None => Some(format!("no `\"format\": \"{MODEL_FORMAT}\"` field")),
        };
        if let Some(why) = other {
            bail!(
                "{}: not a trueaxis model file: {why} (a model file is what `trueaxis fit -o MODEL.json` writes)",
                path.display()
            );
        }
        let m: ModelFile = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a trueaxis model file", path.display()))?;
        m.validate().map_err(|e| {
            anyhow::anyhow!("{}: not a valid trueaxis model file: {e}", path.display())
        })?;
        Ok(m)
    }

    /// Checks everything the file's types do not: indices in range, every
    /// list as long as what it describes, every number finite, spans and
    /// steps positive, the seed and effect strings valid and agreeing with
    /// the model's kind. `Err` names the JSON path of the first bad field
    /// and what was expected. An axis the data did not have is written by
    /// `fit` as centre 0, half span 1 (`Norm`), one held at one position as
    /// that position, half span 0.001 mm, and neither is a grid or network
    /// axis — so those pass.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let seed =
            crate::fit::Seed::parse(self.seed.strip_suffix(" --local").unwrap_or(&self.seed))
                .map_err(|e| format!("seed: {e:#}"))?;
        for (i, a) in self.adds.iter().enumerate() {
            crate::features::Effect::parse(a).map_err(|e| format!("adds[{i}]: {e:#}"))?;
        }
        // Export's default temperature envelope: a range it cannot use
        // would fall back to 10…40 °C as if the file were from before it.
        for (name, [lo, hi]) in self.data.temp_range_c.iter().flatten() {
            need(
                lo.is_finite() && hi.is_finite() && lo <= hi,
                || format!("data.temp_range_c.{name}"),
                || format!("[{lo}, {hi}], expected finite °C, low ≤ high"),
            )?;
        }
        let local_seed = self.seed.ends_with(" --local");
        let kind_ok = match (&self.model, &seed) {
            (FittedModel::Linear(_), crate::fit::Seed::Poly(_)) => !local_seed,
            (FittedModel::Local(_), crate::fit::Seed::Poly(_)) => {
                local_seed && self.adds.is_empty()
            }
            (FittedModel::Nn(m), crate::fit::Seed::Nn(h)) => *h == m.hidden && self.adds.is_empty(),
            (FittedModel::Grid(m), crate::fit::Seed::Grid(s)) => {
                *s == m.step_mm && self.adds.is_empty()
            }
            _ => false,
        };
        if !kind_ok {
            return Err(format!(
                "seed `{}`{} does not describe the model of kind `{}` it holds",
                self.seed,
                if self.adds.is_empty() {
                    String::new()
                } else {
                    format!(" with {} --add effects", self.adds.len())
                },
                self.model.kind()
            ));
        }
        match &self.model {
            FittedModel::Linear(m) => {
                check_norm(&m.norm, "model.norm")?;
                check_linear_outputs(&m.outputs, "model.outputs")
            }
            FittedModel::Local(m) => check_local(m),
            FittedModel::Nn(m) => check_nn(m),
            FittedModel::Grid(m) => check_grid(m),
        }
    }

    /// Writes MODEL.json (pretty-printed).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(self)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write model file {}", path.display()))
    }

    /// The `fit --json` document (docs/cli.md): model, terms, rms_um,
    /// held_out_rms_um, max_abs_um, then more fields.
    pub fn summary_json(&self, model_path: Option<&Path>) -> serde_json::Value {
        let s = &self.stats;
        let mut v = serde_json::json!({
            "model": self.spec(),
            "terms": s.terms,
            "rms_um": s.rms_um,
            "held_out_rms_um": s.held_out_rms_um,
            "max_abs_um": s.max_abs_um,
            "kind": self.model.kind(),
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

impl FittedModel {
    /// The `kind` tag of MODEL.json.
    pub fn kind(&self) -> &'static str {
        match self {
            FittedModel::Linear(_) => "linear",
            FittedModel::Nn(_) => "nn",
            FittedModel::Grid(_) => "grid",
            FittedModel::Local(_) => "local",
        }
    }
}

type Check = std::result::Result<(), String>;

/// `Err("<at>: <value>, expected <want>")` unless `ok`.
fn need(ok: bool, at: impl FnOnce() -> String, what: impl FnOnce() -> String) -> Check {
    if ok {
        Ok(())
    } else {
        Err(format!("{}: {}", at(), what()))
    }
}

fn check_finite(v: &[f64], at: &str) -> Check {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(i) => Err(format!("{at}[{i}]: {}, expected a finite number", v[i])),
    }
}

fn check_len(len: usize, want: usize, at: &str, of: &str) -> Check {
    need(
        len == want,
        || at.to_string(),
        || format!("{len} entries, expected {want} ({of})"),
    )
}

/// An index into `names` (axes or targets).
fn check_index(i: usize, names: &[&str], at: impl FnOnce() -> String) -> Check {
    need(i < names.len(), at, || {
        let list: Vec<String> = names
            .iter()
            .enumerate()
            .map(|(k, n)| format!("{k} ({n})"))
            .collect();
        format!("{i}, expected {}", list.join(", "))
    })
}

/// Indices in range and none twice.
fn check_indices(v: &[usize], names: &[&str], at: &str) -> Check {
    for (k, &i) in v.iter().enumerate() {
        check_index(i, names, || format!("{at}[{k}]"))?;
        need(
            !v[..k].contains(&i),
            || format!("{at}[{k}]"),
            || format!("{} ({}) appears twice", i, names[i]),
        )?;
    }
    Ok(())
}

fn check_norm(n: &Norm, at: &str) -> Check {
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

fn check_feature(f: &Feature, at: &str) -> Check {
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

fn check_linear_outputs(outputs: &[LinearOutput], at: &str) -> Check {
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

fn check_local(m: &LocalModel) -> Check {
    check_norm(&m.norm, "model.norm")?;
    let n_patches = m.patches.len();
    match m.shape.as_str() {
        "cuboid" => {
            let s = m.stack_axis.ok_or_else(|| {
                "model.stack_axis: null, expected the axis the planes are stacked along (cuboid)"
                    .to_string()
            })?;
            check_index(s, &AXES, || "model.stack_axis".into())?;
            check_finite(&m.planes_mm, "model.planes_mm")?;
            need(
                m.planes_mm.len() >= 2 && m.planes_mm.windows(2).all(|w| w[0] < w[1]),
                || "model.planes_mm".into(),
                || format!("{:?}, expected at least 2 ascending positions", m.planes_mm),
            )?;
            check_len(
                n_patches,
                m.planes_mm.len() - 1,
                "model.patches",
                "one per pair of neighbouring planes",
            )?;
        }
        "plane" | "line" => {
            need(
                m.stack_axis.is_none(),
                || "model.stack_axis".into(),
                || format!("{:?}, expected null for shape `{}`", m.stack_axis, m.shape),
            )?;
            check_len(
                n_patches,
                1,
                "model.patches",
                "one patch for a plane or line",
            )?;
        }
        other => {
            return Err(format!(
                "model.shape: `{other}`, expected cuboid, plane or line"
            ))
        }
    }
    let mut first: Option<Vec<usize>> = None;
    for (i, p) in m.patches.iter().enumerate() {
        let at = format!("model.patches[{i}]");
        need(
            p.lo_mm.is_finite(),
            || format!("{at}.lo_mm"),
            || format!("{}, expected a finite number", p.lo_mm),
        )?;
        need(
            p.hi_mm.is_finite(),
            || format!("{at}.hi_mm"),
            || format!("{}, expected a finite number", p.hi_mm),
        )?;
        check_linear_outputs(&p.outputs, &format!("{at}.outputs"))?;
        let mut t: Vec<usize> = p.outputs.iter().map(|o| o.target).collect();
        t.sort_unstable();
        match &first {
            None => first = Some(t),
            Some(f) => need(
                *f == t,
                || format!("{at}.outputs"),
                || {
                    "targets differ from patch 0's, expected every patch to model the same targets"
                        .into()
                },
            )?,
        }
    }
    Ok(())
}

fn check_nn(m: &NnModel) -> Check {
    let (nin, nh, nout) = (m.inputs.len(), m.hidden, m.outputs.len());
    need(
        nin >= 1,
        || "model.inputs".into(),
        || "empty, expected at least one axis".into(),
    )?;
    need(
        nout >= 1,
        || "model.outputs".into(),
        || "empty, expected at least one target".into(),
    )?;
    need(
        nh >= 1,
        || "model.hidden".into(),
        || "0, expected at least 1 neuron".into(),
    )?;
    check_indices(&m.inputs, &AXES, "model.inputs")?;
    check_indices(&m.outputs, &TARGETS, "model.outputs")?;
    let ranges = [
        ("in_min_mm", &m.in_min_mm, nin, "one per input"),
        ("in_max_mm", &m.in_max_mm, nin, "one per input"),
        ("out_min_um", &m.out_min_um, nout, "one per output"),
        ("out_max_um", &m.out_max_um, nout, "one per output"),
        ("w1", &m.w1, nh * nin, "hidden × inputs"),
        ("b1", &m.b1, nh, "one per hidden neuron"),
        ("w2", &m.w2, nout * nh, "outputs × hidden"),
        ("b2", &m.b2, nout, "one per output"),
    ];
    for (name, v, want, of) in ranges {
        let at = format!("model.{name}");
        check_len(v.len(), want, &at, of)?;
        check_finite(v, &at)?;
    }
    for (k, (lo, hi)) in m.in_min_mm.iter().zip(&m.in_max_mm).enumerate() {
        need(
            lo <= hi,
            || format!("model.in_max_mm[{k}]"),
            || format!("{hi}, expected ≥ in_min_mm[{k}] = {lo}"),
        )?;
    }
    for (k, (lo, hi)) in m.out_min_um.iter().zip(&m.out_max_um).enumerate() {
        need(
            lo <= hi,
            || format!("model.out_max_um[{k}]"),
            || format!("{hi}, expected ≥ out_min_um[{k}] = {lo}"),
        )?;
    }
    Ok(())
}

fn check_grid(m: &GridModel) -> Check {
    let d = m.axes.len();
    need(
        (1..=3).contains(&d),
        || "model.axes".into(),
        || format!("{d} entries, expected 1 to 3 axes"),
    )?;
    check_indices(&m.axes, &AXES, "model.axes")?;
    check_len(m.origin_mm.len(), d, "model.origin_mm", "one per grid axis")?;
    check_finite(&m.origin_mm, "model.origin_mm")?;
    check_len(m.counts.len(), d, "model.counts", "one per grid axis")?;
    need(
        m.step_mm.is_finite() && m.step_mm > 0.0,
        || "model.step_mm".into(),
        || format!("{}, expected a positive number of mm", m.step_mm),
    )?;
    for (k, &n) in m.counts.iter().enumerate() {
        need(
            n >= 2,
            || format!("model.counts[{k}]"),
            || format!("{n}, expected at least 2 nodes"),
        )?;
    }
    let max = crate::fit::grid::MAX_NODES;
    let nodes = m
        .counts
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= max)
        .ok_or_else(|| {
            format!(
                "model.counts: {:?}, expected at most {max} nodes in all",
                m.counts
            )
        })?;
    need(
        !m.outputs.is_empty(),
        || "model.outputs".into(),
        || "empty, expected one entry per target the model predicts".into(),
    )?;
    let targets: Vec<usize> = m.outputs.iter().map(|o| o.target).collect();
    for (k, o) in m.outputs.iter().enumerate() {
        check_index(o.target, &TARGETS, || format!("model.outputs[{k}].target"))?;
        need(
            !targets[..k].contains(&o.target),
            || format!("model.outputs[{k}].target"),
            || format!("{} ({}) appears twice", o.target, TARGETS[o.target]),
        )?;
        let at = format!("model.outputs[{k}].values_um");
        check_len(
            o.values_um.len(),
            nodes,
            &at,
            "one per node: the product of counts",
        )?;
        check_finite(&o.values_um, &at)?;
    }
    Ok(())
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
