//! The building blocks several commands share — where a model is written,
//! which seed and effects `--model` names, a comparison with its report, a
//! checked table export — so that no subcommand calls another (`demo` runs
//! the same blocks as `compare`, `improve` and `export`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use trueaxis_engine::compare::{self, Comparison, Warning};
use trueaxis_engine::data::Dataset;
use trueaxis_engine::effect::EffectSpec;
use trueaxis_engine::export::table::{self, TableExport, TableOptions};
use trueaxis_engine::history::history_path;
use trueaxis_engine::model::{ModelFile, Seed};

use crate::input;

/// `<data>.model.json` beside the data file.
pub fn default_model_path(data: &std::path::Path) -> PathBuf {
    let mut name = data
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".model.json");
    data.with_file_name(name)
}

/// Where `fit` and `improve` write the model (`-o`, else
/// [`default_model_path`]), refused when it or its history file is the
/// data file.
pub fn model_output(data: &std::path::Path, output: Option<PathBuf>) -> Result<PathBuf> {
    let out = output.unwrap_or_else(|| default_model_path(data));
    input::refuse_overwrite(
        &[("the data file", data)],
        &[("-o", &out), ("the history file", &history_path(&out))],
    )?;
    Ok(out)
}

/// Seed and effects of `--model`: a seed spec, or the `seed` and `adds` of
/// a MODEL.json. Only linear seeds can be diagnosed: the candidates are
/// scored by partialling the model's columns out of theirs.
pub fn model_spec(model: &str) -> Result<(Seed, Vec<EffectSpec>)> {
    let (seed, adds) = if model.ends_with(".json") || Path::new(model).is_file() {
        // Read and checked as every command reads a MODEL.json: a damaged
        // file is refused here too, not half-used.
        let m = ModelFile::load(model)?;
        (m.seed, m.adds)
    } else {
        (model.to_string(), Vec::new())
    };
    if seed != "cubic19" && seed != "kinematic" {
        bail!(
            "diagnose works on linear seeds (cubic19, kinematic); the model is `{seed}` — fit a cubic19 or kinematic model to find missing effects"
        );
    }
    // The file's effects were checked when it was loaded.
    let adds = adds
        .iter()
        .map(|a| a.parse())
        .collect::<Result<Vec<EffectSpec>>>()?;
    Ok((seed.parse()?, adds))
}

/// Runs the comparison of `data` with `model` (and writes the report when
/// `report` is given; `sources` names the data and model files for the
/// command its verdict card proposes). The building block `compare` and
/// `demo` share.
pub fn run_compare(
    data: &Dataset,
    model: &ModelFile,
    report: Option<&std::path::Path>,
    sources: Option<crate::report::compare::Sources>,
) -> Result<Comparison> {
    let predicted = model
        .model
        .predict(data)
        .with_context(|| format!("{}: the model cannot be evaluated on it", data.source))?;
    let held_out = [0, 1, 2].map(|t| {
        model
            .stats
            .held_out_rms_um
            .get(trueaxis_engine::data::TARGETS[t])
            .copied()
    });
    let mut c = compare::compare(data, &model.spec(), &predicted, held_out);
    let hash = trueaxis_engine::import::content_hash(data);
    if !model.data.sha256.is_empty() && hash != model.data.sha256 {
        c.warnings.push(Warning {
            code: "data_hash_mismatch".into(),
            detail: format!(
                "the data ({}, sha256 {}…) are not the data the model was fitted to ({}, sha256 {}…): the statistics describe a validation, not the fit",
                data.source,
                &hash[..12.min(hash.len())],
                model.data.source,
                &model.data.sha256[..12.min(model.data.sha256.len())]
            ),
        });
    }
    if let Some(dir) = report {
        let index = crate::report::compare::write_report_from(dir, data, &predicted, &c, sources)?;
        c.report = Some(index.display().to_string());
    }
    Ok(c)
}

/// Exports `model` as a firmware table to `output` and fails when the
/// accuracy check is above `allow_error_nm` (the file is not written then).
/// The building block `export` and `demo` share.
pub fn export_table(
    model: &ModelFile,
    output: &Path,
    opts: &TableOptions,
    allow_error_nm: f64,
) -> Result<TableExport> {
    if !(allow_error_nm.is_finite() && allow_error_nm >= 0.0) {
        bail!("--allow-error-nm must be a finite number ≥ 0, got {allow_error_nm}");
    }
    let e = table::export(model, opts)?;
    let worst = e.max_f32_error_nm.max(e.max_fixed_error_nm);
    if worst.is_nan() || worst > allow_error_nm {
        bail!(
            "accuracy check failed: the firmware's evaluation differs from the model by up to {worst:.3} nm (f32 {:.3}, fixed {:.3}) over {} sweep points, above the {allow_error_nm} nm allowed (--allow-error-nm); {} was not written",
            e.max_f32_error_nm,
            e.max_fixed_error_nm,
            e.sweep_points,
            output.display()
        );
    }
    write_file(output, &e.table)?;
    Ok(e)
}

pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}
