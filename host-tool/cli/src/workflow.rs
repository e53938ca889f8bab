//! The building blocks several commands share — where a model is written,
//! which seed and effects `--model` names, a comparison with its report, a
//! checked table export and the words of export's refusals — so that no
//! subcommand calls another (`demo` runs the same blocks as `compare`,
//! `improve` and `export`).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use model_core::table::MAX_SLEW_LIMIT_NM_PER_MS;
use trueaxis_engine::compare::{self, Comparison, Warning};
use trueaxis_engine::data::{Dataset, TARGETS};
use trueaxis_engine::effect::EffectSpec;
use trueaxis_engine::export::checks::{MaxCorrError, TinyCorrections, MAX_CORR_LIMIT_UM};
use trueaxis_engine::export::table::{self, TableError, TableExport, TableOptions};
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
        let m = input::load_model(Path::new(model))?;
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
    // A rigid21 model is compared with each reading after its set-up's own
    // zeros, alignment and frame (docs/volumetric.md).
    let (predicted, readings) = match &model.model {
        trueaxis_engine::model::FittedModel::Rigid21(m) => {
            let (fitted, kinds) = trueaxis_engine::fit::rigid21::reading_residuals(m, data)
                .with_context(|| format!("{}: the model cannot be evaluated on it", data.source))?;
            (fitted, Some(kinds))
        }
        _ => (predicted, None),
    };
    let mut c = compare::compare(data, &model.spec(), &predicted, held_out);
    c.readings = readings;
    if let trueaxis_engine::model::FittedModel::Rigid21(m) = &model.model {
        // "Before" is the machine's error the readings show once their
        // set-ups are placed (a model of zeros), not the raw readings,
        // whose arbitrary zeros and frames no compensation is about.
        let (placed, _) = trueaxis_engine::fit::rigid21::reading_residuals(&m.zeroed(), data)
            .with_context(|| format!("{}: the model cannot be evaluated on it", data.source))?;
        for t in data.targets() {
            let (Some(p), Some(r)) = (
                placed[t].as_ref(),
                c.targets.get_mut(trueaxis_engine::data::TARGETS[t]),
            ) else {
                continue;
            };
            let v: Vec<f64> = data.measured(t).map(|(row, v)| v - p[row]).collect();
            if let Some(stats) = compare::ErrorStats::of(&v) {
                r.before = stats;
                r.improvement = if r.after.rms_um > 0.0 {
                    stats.rms_um / r.after.rms_um
                } else {
                    f64::INFINITY
                };
            }
        }
    }
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
        let index = match &model.model {
            trueaxis_engine::model::FittedModel::Rigid21(m) => {
                crate::report::compare::write_report_rigid21(
                    dir,
                    data,
                    &predicted,
                    &c,
                    sources,
                    m,
                    model.stats.volumetric.as_ref(),
                )?
            }
            _ => crate::report::compare::write_report_from(dir, data, &predicted, &c, sources)?,
        };
        c.report = Some(index.display().to_string());
    }
    Ok(c)
}

/// Exports `model` as a firmware table to `output`; refused when the
/// accuracy check is above `allow_error_nm` (the file is not written then).
/// The building block `export` and `demo` share. The engine words its
/// refusals and warnings in the options' terms; here they name the flags
/// that change them, as users have always read them.
pub fn export_table(
    model: &ModelFile,
    output: &Path,
    opts: &TableOptions,
    allow_error_nm: f64,
) -> Result<TableExport> {
    let opts = TableOptions {
        allow_error_nm,
        ..opts.clone()
    };
    let mut e = table::export(model, &opts).map_err(|e| table_refusal(e, output))?;
    let mut clamped = e.clamped.iter();
    for w in &mut e.warnings {
        match w.code.as_str() {
            "max_corr_below_model" => {
                if let Some(c) = clamped.next() {
                    w.detail = format!(
                        "{}: --max-corr-um {} is below the model's {:.3} µm: the firmware will clamp",
                        TARGETS[c.target],
                        c.limit_nm / 1000.0,
                        c.model_max_nm / 1000.0
                    );
                }
            }
            // The engine ends it with "or give the measured range".
            "temp_range_unknown" => w.detail.push_str(" with --temp-range-c"),
            _ => {}
        }
    }
    write_file(output, &e.table)?;
    Ok(e)
}

/// A refused table export in the words of `trueaxis export` (flags named;
/// `output` was not written).
fn table_refusal(e: TableError, output: &Path) -> anyhow::Error {
    let msg = match e {
        TableError::BadAllowance { allowed_nm } => {
            format!("--allow-error-nm must be a finite number ≥ 0, got {allowed_nm}")
        }
        TableError::BadReversalTransition { .. } => "--reversal-transition-um must be ≥ 0".into(),
        TableError::Lag {
            target,
            term,
            lag_s,
        } => format!(
            "{}: the thermal term {term} has a lag of {lag_s} s, which the firmware table cannot represent (it applies the coefficient to the sensor reading at once); refit without lag_s, or export with --drop-lag to use its steady state",
            TARGETS[target]
        ),
        TableError::LocalModel => "local (piecewise) models cannot be exported as a table: the firmware evaluates one global model; fit a global seed (cubic19 with --add …) or grid:<step_mm>".into(),
        TableError::Tiny(t) => tiny_refusal(&t),
        TableError::MaxCorr(m) => max_corr_refusal(&m),
        TableError::SlewBelowOne { .. } => "--max-slew-nm-per-ms must be ≥ 1".into(),
        TableError::SlewAboveTableLimit { given_nm_per_ms } => format!(
            "--max-slew-nm-per-ms {given_nm_per_ms}: a table holds at most {MAX_SLEW_LIMIT_NM_PER_MS} nm/ms (10 m/s; the format's and the board's limit) — check the unit (nm per ms)"
        ),
        TableError::BadFeed { .. } => "--max-feed-mm-per-min must be positive".into(),
        e @ TableError::Accuracy { .. } => {
            format!("{e} (--allow-error-nm); {} was not written", output.display())
        }
        TableError::Other(e) => return e,
    };
    anyhow!(msg)
}

/// [`TinyCorrections`] naming `--accept-tiny-corrections`.
pub fn tiny_refusal(e: &TinyCorrections) -> String {
    format!(
        "{}; --accept-tiny-corrections exports it anyway",
        e.finding()
    )
}

/// A refused max |correction| limit naming `--max-corr-um`.
pub fn max_corr_refusal(e: &MaxCorrError) -> String {
    let cap = MAX_CORR_LIMIT_UM;
    match e {
        MaxCorrError::NotPositive { given_um } => {
            format!("--max-corr-um must be positive, got {given_um}")
        }
        MaxCorrError::AboveTableLimit { target, given_um } => format!(
            "{}: --max-corr-um {given_um} exceeds the table's limit of {cap} µm",
            TARGETS[*target]
        ),
        MaxCorrError::DefaultAboveTableLimit { .. } => {
            let way_out = if e.model_above_table_limit() {
                format!("--max-corr-um (at most {cap}) would clamp it")
            } else {
                format!(
                    "give the limit yourself with --max-corr-um (at most {cap}; at or above the model's {} µm nothing is clamped)",
                    e.model_max_um()
                )
            };
            format!("{}; {}{way_out}", e.finding(), e.suspect())
        }
    }
}

/// Writes an output file whole or not at all (`files::write`: a
/// temporary file beside it, synced, then renamed; the directory made when
/// missing) — every command's `-o` and report goes through here or
/// `files::write_with`.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    trueaxis_engine::files::write(path, bytes)
}

/// What to run on a data file just written (`simulate`, `import`), as it
/// runs when pasted where the command ran: an ISO 230-2 run (one axis
/// moving, approached from both sides) is evaluated by `iso230`; a probed
/// surface (a bed) is fitted with a grid on its probe spacing (a bed wants
/// a mesh, not a machine's polynomial); anything else with the cubic seed.
pub fn next_for_data(data: &Dataset, path: &Path) -> String {
    let p = crate::report::diagnose::shell_word(&path.display().to_string());
    // Readings relative to their own set-ups (laser lines, trackers,
    // diagonals): only the volumetric model knows their unknowns.
    if data.setup_id.is_some() {
        return format!("trueaxis fit {p} --model rigid21 -o model.json");
    }
    let moving: Vec<usize> = (0..3).filter(|&a| spacing_mm(data, a).is_some()).collect();
    if let [a] = moving[..] {
        if data.dir[a].is_some() {
            return format!("trueaxis iso230 {p} --report iso230");
        }
    }
    if data.is_probed_surface() {
        let step = [0, 1]
            .iter()
            .filter_map(|&a| spacing_mm(data, a))
            .fold(f64::INFINITY, f64::min);
        return format!(
            "trueaxis fit {p} --model grid:{} -o bed.json",
            trueaxis_engine::lines::plot_num(step)
        );
    }
    format!("trueaxis fit {p} --model cubic19 -o model.json")
}

/// The median gap between the distinct positions along `axis` (µm-rounded);
/// None when the axis is absent or does not move.
fn spacing_mm(data: &Dataset, axis: usize) -> Option<f64> {
    let col = data.pos_mm[axis].as_ref()?;
    let mut p: Vec<i64> = col.iter().map(|v| (v * 1000.0).round() as i64).collect();
    p.sort_unstable();
    p.dedup();
    let mut gaps: Vec<i64> = p.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_unstable();
    gaps.get(gaps.len() / 2).map(|g| *g as f64 / 1000.0)
}
