//! Chapter 7 of `trueaxis demo`: the 21 geometric errors (docs/volumetric.md).
//! The `mill800-21` machine — every error of ISO 230-1 and the spindle-axis
//! tilt at realistic sizes — is measured with laser lines at two tool
//! lengths; the rigid21 fit says which errors these lines cannot know, how
//! much that hides and what to measure; two tracker stations are added as
//! it proposes, and the volumetric error at tool points the fits never saw
//! (other places, lateral offsets and tool lengths, the machine's truth
//! known) falls. Files under `DIR/volumetric/`; the lines model's compare
//! page is the rigid21 page.

use std::fmt::Write as _;

use anyhow::{Context, Result};

use trueaxis_engine::data::Dataset;
use trueaxis_engine::fit::volumetric_check::{against_machine, ToolCheck};
use trueaxis_engine::fit::{self, FitOptions};
use trueaxis_engine::model::rigid21::Status;
use trueaxis_engine::model::{FittedModel, ModelFile};
use trueaxis_engine::simulate::instruments::measure;
use trueaxis_engine::simulate::volumetric::{lines_plan, tracker_plan, PRESET};
use trueaxis_engine::simulate::Machine;

use super::demo::{Demo, SEED};

/// Tool lengths the fits are checked at (neither was measured), mm.
pub const CHECK_TOOLS_MM: [f64; 2] = [60.0, 250.0];
/// Check points over the volume (each at both offsets and tool lengths).
const CHECK_POINTS: usize = 60;

impl Demo {
    /// Chapter 7 (module docs): returns the story and its numbers.
    pub fn volumetric(&self) -> Result<(String, serde_json::Value)> {
        let dir = self.out.join("volumetric");
        let m = Machine::preset(PRESET)?;
        let lines = measure(&m, &lines_plan(m.travel_mm), SEED, true);
        let mut both_plan = lines_plan(m.travel_mm);
        both_plan.extend(tracker_plan());
        let both = measure(&m, &both_plan, SEED, true);
        let (lines_model, lines_csv, lines_json) = fit_into(&dir, "lines", &lines)?;
        let (both_model, _, _) = fit_into(&dir, "lines_tracker", &both)?;
        let sources = crate::report::compare::Sources {
            data: &lines_csv,
            model: &lines_json,
        };
        let report = dir.join("report");
        crate::workflow::run_compare(&lines, &lines_model, Some(&report), Some(sources))?;
        let mut s = String::new();
        let mut json = serde_json::json!({ "dir": dir.display().to_string() });
        for (key, what, model, data) in [
            (
                "lines",
                "laser lines at tool lengths 0 and 150 mm",
                &lines_model,
                &lines,
            ),
            (
                "lines_tracker",
                "the lines and two tracker stations with lateral offsets of ±100 mm",
                &both_model,
                &both,
            ),
        ] {
            let FittedModel::Rigid21(r) = &model.model else {
                anyhow::bail!("the rigid21 fit returned a {} model", model.model.kind());
            };
            let id = model
                .stats
                .volumetric
                .as_ref()
                .context("the rigid21 fit has no identifiability answer")?;
            let unknown: Vec<&str> = id
                .errors
                .iter()
                .filter(|e| e.status == Status::CannotKnow)
                .map(|e| e.name.as_str())
                .collect();
            let checks = against_machine(&m, r, &CHECK_TOOLS_MM, CHECK_POINTS, SEED + 1);
            let _ = write!(s, "\n   {what} ({} readings): ", data.len());
            if unknown.is_empty() {
                let _ = write!(s, "all {} errors estimated", id.errors.len());
            } else {
                let _ = write!(
                    s,
                    "{} of {} errors cannot be known ({}), up to {:.1} µm unseen at tool length {} mm{}",
                    unknown.len(),
                    id.errors.len(),
                    unknown.join(", "),
                    id.hidden_um,
                    id.hidden_at_tool_mm,
                    id.measure
                        .as_ref()
                        .map_or(String::new(), |me| format!("; measure: {}", me.what))
                );
            }
            let _ = write!(
                s,
                "; at tool points never measured: {}",
                check_words(&checks)
            );
            json[key] = serde_json::json!({
                "rows": data.len(),
                "cannot_know": unknown,
                "hidden_um": id.hidden_um,
                "hidden_at_tool_mm": id.hidden_at_tool_mm,
                "measure": id.measure.as_ref().map(|me| me.what.clone()),
                "check": checks,
            });
        }
        json["report"] = report.join("index.html").display().to_string().into();
        let story = format!(
            "7. The 21 geometric errors ({}): the {PRESET} machine measured and fitted with rigid21 (the error at the tool point before → after compensation, max over the check points, after the one rigid frame the ISO gauge leaves free):{s}\n   the lines model's errors and what they cannot know: {}",
            dir.display(),
            report.join("index.html").display()
        );
        Ok((story, json))
    }
}

/// `data` written as `DIR/NAME.csv` and fitted with rigid21 to
/// `DIR/NAME.model.json`: (model, csv path, model path).
fn fit_into(
    dir: &std::path::Path,
    name: &str,
    data: &Dataset,
) -> Result<(ModelFile, std::path::PathBuf, std::path::PathBuf)> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let csv = dir.join(format!("{name}.csv"));
    trueaxis_engine::files::write_with(&csv, |w| trueaxis_engine::import::write_csv(data, w))?;
    let mut data = data.clone();
    data.source = csv.display().to_string();
    let model = fit::fit(&data, "rigid21", &[], &FitOptions::default())?;
    let json = dir.join(format!("{name}.model.json"));
    model.save(&json)?;
    Ok((model, csv, json))
}

/// "tool 60 mm 38.2 → 0.61 µm, tool 250 mm …".
fn check_words(checks: &[ToolCheck]) -> String {
    checks
        .iter()
        .map(|c| {
            format!(
                "tool {} mm {:.1} → {:.2} µm",
                c.tool_mm, c.before_max_um, c.after_max_um
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}
