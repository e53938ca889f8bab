//! The fitted model and its file, MODEL.json (`trueaxis-model/1`): what
//! `fit` writes and `compare`, `diagnose`, `export` and `history` read.
//!
//! A model file is self-contained: the model kind with everything needed to
//! evaluate it (normalisation, features and coefficients, network weights,
//! grid nodes, local patches), the spec it came from (seed and `--add`
//! effects, so a refit is one command away), the data it was fitted to
//! (path, SHA-256 of the canonical CSV, rows) and the fit statistics.
//! Every prediction is in µm, per target (ex, ey, ez) present in the model.
//!
//! Each model kind owns its type, its evaluation and the checks of its
//! fields (`linear`, `local`, `nn`, `grid`); `seed` is the typed `--model`
//! spec. Training (`fit`) builds on these and is never imported here.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

mod check;
pub mod grid;
pub mod linear;
pub mod local;
pub mod nn;
pub mod rigid21;
pub mod seed;

pub use grid::{GridModel, GridOutput};
pub use linear::{LinearModel, LinearOutput};
pub use local::{LocalModel, LocalPatch};
pub use nn::{NnModel, NnTraining};
pub use rigid21::Rigid21Model;
pub use seed::{ModelSeed, Seed};

use crate::data::{Dataset, TARGETS};
use check::need;
use grid::check_grid;
use linear::{check_linear_outputs, check_norm};
use local::check_local;
use nn::check_nn;

/// Format tag written into every MODEL.json; readers refuse other values.
pub const MODEL_FORMAT: &str = "trueaxis-model/1";

/// The key of MODEL.json's checksum, its last field: the SHA-256 of the
/// rest of the content ([`ModelFile::checksum`]), checked on every read.
pub const CHECKSUM_KEY: &str = "checksum_sha256";

/// Format tag of MODEL.history.json (the `history` module's file): known
/// here so that a history given where a model belongs is named as such.
pub const HISTORY_FORMAT: &str = "trueaxis-history/1";

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
    /// Rows of the file left out of the fit because they lie outside the
    /// travel (`crate::travel`: the travel given, or the data's bulk), each
    /// with the model's miss there; `export` names them again. Absent
    /// (empty) when every row was inside.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outside_travel: Vec<crate::travel::OutsideRow>,
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
    /// data, training stopped at the epoch limit, …); MODEL.json keeps
    /// their text (a list of strings).
    #[serde(default, with = "crate::warning::as_text")]
    pub warnings: Vec<crate::warning::Warning>,
    /// rigid21 only: which errors the data determine, what stays hidden and
    /// what to measure (docs/volumetric.md; `fit --json` `errors`,
    /// `hidden_um`, `measure`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volumetric: Option<rigid21::Identifiability>,
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
    /// The 21 geometric errors on a kinematic chain (docs/volumetric.md).
    Rigid21(Rigid21Model),
}

impl FittedModel {
    /// Targets the model predicts.
    pub fn targets(&self) -> Vec<usize> {
        let mut t: Vec<usize> = match self {
            FittedModel::Linear(m) => m.outputs.iter().map(|o| o.target).collect(),
            FittedModel::Nn(m) => m.outputs.clone(),
            FittedModel::Grid(m) => m.outputs.iter().map(|o| o.target).collect(),
            FittedModel::Local(m) => m.targets(),
            FittedModel::Rigid21(_) => vec![0, 1, 2],
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
                let pred = nn::predict(m, data)?;
                for (k, &t) in m.outputs.iter().enumerate() {
                    out[t] = Some(pred[k].clone());
                }
            }
            FittedModel::Grid(m) => {
                for o in &m.outputs {
                    out[o.target] = Some(grid::predict(m, o, data)?);
                }
            }
            FittedModel::Local(m) => out = m.predict(data)?,
            FittedModel::Rigid21(m) => out = m.predict_rows(data)?.map(Some),
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

    /// Reads and checks a MODEL.json ([`ModelFile::load_noting`] without
    /// its note).
    pub fn load(path: impl AsRef<Path>) -> Result<ModelFile> {
        Ok(Self::load_noting(path)?.0)
    }

    /// Reads and checks a MODEL.json: its format, every field
    /// ([`ModelFile::validate`]), then its checksum ([`CHECKSUM_KEY`]: a
    /// file whose content is not what trueaxis wrote — a flipped bit, a
    /// hand edit — is refused, naming the file). A file without a checksum
    /// (written before files had one, or with the line removed on purpose)
    /// loads, with the note returned beside the model for the caller to
    /// show.
    pub fn load_noting(path: impl AsRef<Path>) -> Result<(ModelFile, Option<String>)> {
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
            Some(HISTORY_FORMAT) => Some(
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
        // Checked after the fields, so that a damaged field is named by its
        // JSON path; what passes them and still differs is named here.
        let note = match value.get(CHECKSUM_KEY) {
            None => Some(format!(
                "note: {} has no checksum (written by an older trueaxis, or edited by hand): it loads unchecked — refit it to have one",
                path.display()
            )),
            Some(given) => {
                let content = m.checksum()?;
                if given.as_str() != Some(content.as_str()) {
                    bail!(
                        "{}: damaged: its content does not match its checksum ({CHECKSUM_KEY} {}, the content's {}) — the file was changed after trueaxis wrote it (a disk or copy error, or an edit); refit the model, or, for a deliberate edit, delete the `{CHECKSUM_KEY}` line to load it unchecked",
                        path.display(),
                        crate::import::shown(&given.to_string()),
                        &content[..16]
                    );
                }
                None
            }
        };
        Ok((m, note))
    }

    /// SHA-256 (hex) of the model's content: its compact JSON (serde_json,
    /// the fields in the file's order, no whitespace) without
    /// [`CHECKSUM_KEY`]. Floats are written in their shortest round-trip
    /// form and read back exactly, so a file read and checked gives the
    /// content it was written from, bit for bit.
    pub fn checksum(&self) -> Result<String> {
        use sha2::{Digest, Sha256};
        let bytes = serde_json::to_vec(self)?;
        Ok(Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect())
    }

    /// The text of MODEL.json: the model pretty-printed, with its
    /// checksum as the last field ([`CHECKSUM_KEY`]).
    pub fn to_json(&self) -> Result<String> {
        #[derive(Serialize)]
        struct Sealed<'a> {
            #[serde(flatten)]
            model: &'a ModelFile,
            checksum_sha256: String,
        }
        let sealed = Sealed {
            model: self,
            checksum_sha256: self.checksum()?,
        };
        Ok(serde_json::to_string_pretty(&sealed)? + "\n")
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
        let seed = ModelSeed::parse(&self.seed).map_err(|e| format!("seed: {e:#}"))?;
        for (i, a) in self.adds.iter().enumerate() {
            crate::effect::Effect::parse(a).map_err(|e| format!("adds[{i}]: {e:#}"))?;
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
        for (i, o) in self.data.outside_travel.iter().enumerate() {
            let [lo, hi] = o.travel_mm;
            need(
                crate::data::AXES.contains(&o.axis.as_str())
                    && o.position_mm.is_finite()
                    && lo.is_finite()
                    && hi.is_finite()
                    && lo <= hi
                    && o.resid_um.values().all(|r| r.is_finite()),
                || format!("data.outside_travel[{i}]"),
                || {
                    "expected an axis x, y or z, finite positions in mm (travel low ≤ high) and finite residuals".into()
                },
            )?;
        }
        let kind_ok = match (&self.model, &seed.seed) {
            (FittedModel::Linear(_), Seed::Cubic19 | Seed::Kinematic) => !seed.local,
            (FittedModel::Local(_), Seed::Cubic19 | Seed::Kinematic) => {
                seed.local && self.adds.is_empty()
            }
            (FittedModel::Nn(m), Seed::Nn { hidden }) => {
                *hidden == m.hidden && self.adds.is_empty()
            }
            (FittedModel::Grid(m), Seed::Grid { step_mm }) => {
                *step_mm == m.step_mm && self.adds.is_empty()
            }
            (FittedModel::Rigid21(m), Seed::Rigid21 { degree }) => {
                *degree == m.degree && !seed.local && self.adds.is_empty() == m.effects.is_none()
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
            FittedModel::Rigid21(m) => m.check(),
        }
    }

    /// Writes MODEL.json ([`ModelFile::to_json`]), atomically
    /// (`files::write`).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::files::write(path.as_ref(), self.to_json()?.as_bytes())
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
            "warnings": crate::warning::as_text::texts(&s.warnings),
            "data_sha256": self.data.sha256,
        });
        if let Some(id) = &s.volumetric {
            v["errors"] = serde_json::to_value(&id.errors).unwrap_or_default();
            v["hidden_um"] = serde_json::json!(id.hidden_um);
            v["hidden_from"] = serde_json::json!(id.hidden_from);
            v["hidden_at_tool_mm"] = serde_json::json!(id.hidden_at_tool_mm);
            v["measure"] = serde_json::to_value(&id.measure).unwrap_or_default();
        }
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
            FittedModel::Rigid21(_) => "rigid21",
        }
    }
}

/// Residuals (row, measured − model in µm) per target; `None` for a target
/// the model does not cover.
pub type Residuals = [Option<Vec<(usize, f64)>>; 3];

/// Target name for messages and JSON keys.
pub fn target_name(t: usize) -> &'static str {
    TARGETS[t]
}
