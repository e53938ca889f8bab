//! `trueaxis improve DATA --model cubic19 [-o MODEL.json] [--json]`: the
//! diagnosis loop run by itself — fit, diagnose, add the best significant
//! effect, refit — until the diagnosis says `at_noise_floor`, printing each
//! step. Every fit is written to MODEL.json and appended to its history, so
//! `trueaxis history MODEL.json` shows the same steps afterwards.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;

use crate::cmd::fit::model_output;
use crate::cmd::input;
use crate::cmd::out::{self, outln};
use trueaxis_engine::data::Dataset;
use trueaxis_engine::diagnose::{self, Options, Verdict};
use trueaxis_engine::features::Effect;
use trueaxis_engine::fit::{self, FitOptions};
use trueaxis_engine::history;

/// Most effects `improve` adds before it stops anyway.
pub const MAX_STEPS: usize = 8;

/// Arguments of `trueaxis improve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The measurement file (contract CSV or Renishaw .rtl).
    pub data: PathBuf,
    /// Seed model to start from (cubic19 or kinematic).
    #[arg(long)]
    pub model: String,
    /// Where to write the final model (default: `<data>.model.json`).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One effect added (or swapped in) at a step.
#[derive(Clone, Debug, Serialize)]
pub struct AddedEffect {
    /// Target.
    pub target: String,
    /// The `fit --add` string.
    pub add: String,
    /// The effect it replaced (the same effect with another lag, period,
    /// order or degree), if any.
    pub replaces: Option<String>,
    /// Its evidence, as diagnose gave it.
    pub evidence: String,
}

/// One step of the loop.
#[derive(Clone, Debug, Serialize)]
pub struct ImproveStep {
    /// 1-based.
    pub step: usize,
    /// Every effect added at this step: the best significant candidate of
    /// each target (targets are fitted independently, so one step can
    /// serve all of them), best first; none for the seed. The JSON also
    /// has the first one's `add` and `evidence` as `added` and `evidence`
    /// (null for the seed).
    #[serde(flatten, serialize_with = "ser_added")]
    pub added_effects: Vec<AddedEffect>,
    /// In-sample RMS per target after the fit, µm.
    pub rms_um: BTreeMap<String, f64>,
    /// Block-held-out RMS per target after the fit, µm, with the
    /// diagnosis' blocks (long passes cut into segments).
    pub held_out_rms_um: BTreeMap<String, f64>,
    /// The held-out RMS `fit` reports (its own blocks), µm.
    pub fit_held_out_rms_um: BTreeMap<String, f64>,
    /// Noise floor per target from the diagnosis of this fit, µm.
    pub noise_floor_um: BTreeMap<String, Option<f64>>,
    /// The diagnosis of this fit.
    pub verdict: Verdict,
    /// Targets whose RMS is still more than `ABOVE_NOISE_RATIO` × their noise
    /// floor, with the ratio: `at_noise_floor` says no candidate is
    /// significant, this says whether the data is really explained.
    pub above_noise_floor: BTreeMap<String, f64>,
}

/// `"added"`, `"evidence"` (the best effect's, or null) and
/// `"added_effects"` — kept in one field so that they cannot disagree.
fn ser_added<S: serde::Serializer>(
    added: &[AddedEffect],
    ser: S,
) -> std::result::Result<S::Ok, S::Error> {
    #[derive(Serialize)]
    struct Added<'a> {
        added: Option<&'a str>,
        evidence: Option<&'a str>,
        added_effects: &'a [AddedEffect],
    }
    let best = added.first();
    Added {
        added: best.map(|a| a.add.as_str()),
        evidence: best.map(|a| a.evidence.as_str()),
        added_effects: added,
    }
    .serialize(ser)
}

impl ImproveStep {
    /// What the step's verdict means, in words (for the closing line).
    pub fn outcome(&self) -> String {
        match self.verdict {
            Verdict::MissingEffect => "stopped after the step limit".into(),
            Verdict::AtNoiseFloor if self.above_noise_floor.is_empty() => {
                "at the noise floor".into()
            }
            Verdict::AtNoiseFloor => format!(
                "no significant candidate left, but above the noise floor ({})",
                self.above_noise_floor
                    .iter()
                    .map(|(t, r)| format!("{t} {r:.1}×"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// The whole run.
#[derive(Clone, Debug, Serialize)]
pub struct Improvement {
    /// Final model spec (`cubic19 --add …`).
    pub model: String,
    /// Where the final model was written.
    pub model_file: String,
    /// Steps, first fit first.
    pub steps: Vec<ImproveStep>,
    /// The last diagnosis' verdict.
    pub verdict: Verdict,
    /// What the user should know about the data (`aux_misspelled`,
    /// `aux_columns`), as diagnose's `warnings`.
    pub warnings: Vec<diagnose::Warning>,
}

/// Runs the loop on `data`, writing each fit to `out` (and its history);
/// `on_step` sees each step as it completes (for printing).
pub fn improve(
    data: &Dataset,
    seed: &str,
    out: &std::path::Path,
    mut on_step: impl FnMut(&ImproveStep),
) -> Result<Improvement> {
    let mut adds: Vec<String> = Vec::new();
    let mut steps = Vec::new();
    let mut added: Vec<AddedEffect> = Vec::new();
    loop {
        let effects = adds
            .iter()
            .map(|a| Effect::parse(a))
            .collect::<Result<Vec<_>>>()?;
        let model = fit::fit(data, seed, &effects, &FitOptions::default())?;
        history::save_with_model(out, &model)?;
        let d = diagnose::diagnose(
            data,
            &Options {
                seed: seed.to_string(),
                adds: adds.clone(),
                follow_path: false,
            },
        )?;
        let above_noise_floor = model
            .stats
            .rms_um
            .iter()
            .filter_map(|(t, rms)| {
                let nf = d.noise_floor_um.get(t).copied().flatten()?;
                Some((t.clone(), diagnose::above_noise(*rms, nf)?))
            })
            .collect();
        let step = ImproveStep {
            step: steps.len() + 1,
            added_effects: std::mem::take(&mut added),
            rms_um: model.stats.rms_um.clone(),
            held_out_rms_um: d.held_out_rms_um.clone(),
            fit_held_out_rms_um: model.stats.held_out_rms_um.clone(),
            noise_floor_um: d.noise_floor_um.clone(),
            verdict: d.verdict,
            above_noise_floor,
        };
        on_step(&step);
        steps.push(step);
        // The best significant candidate of each target (candidates are
        // sorted best first; without the path there is at most one per
        // target), added — or swapped in for the same effect — together.
        let mut seen = std::collections::BTreeSet::new();
        if steps.len() <= MAX_STEPS {
            for c in d.candidates.iter().filter(|c| c.significant) {
                if !seen.insert(c.target.clone()) {
                    continue;
                }
                if diagnose::swap_in(&mut adds, &c.add, c.replaces.as_deref()) {
                    added.push(AddedEffect {
                        target: c.target.clone(),
                        add: c.add.clone(),
                        replaces: c.replaces.clone(),
                        evidence: c.evidence.clone(),
                    });
                }
            }
        }
        if added.is_empty() {
            return Ok(Improvement {
                model: model.spec(),
                model_file: out.display().to_string(),
                steps,
                verdict: d.verdict,
                warnings: Vec::new(),
            });
        }
    }
}

/// The diagnosis stage of `trueaxis demo`: where the seed model fails, the
/// missing effect named, added and refitted until the noise floor, the
/// error falling step by step. Writes every fit to `model_path` (with its
/// history) and, with `report_dir`, the diagnosis of the seed model and the
/// history plot under `report_dir/diagnose` and `report_dir/history`.
/// Returns the final model, the story told and the steps.
pub fn demo_stage(
    data: &Dataset,
    seed: &str,
    model_path: &std::path::Path,
    report_dir: Option<&std::path::Path>,
) -> Result<(trueaxis_engine::model::ModelFile, String, Improvement)> {
    use std::fmt::Write as _;
    let mut s = String::new();
    let first = diagnose::diagnose(data, &Options::seed(seed))?;
    let _ = writeln!(s, "Diagnose {seed} — which physical effect is missing?");
    let mut worst: Vec<&diagnose::Region> = first.worst_regions.iter().collect();
    worst.sort_by(|a, b| b.rms_um.total_cmp(&a.rms_um));
    if let Some(r) = worst.first() {
        let _ = writeln!(
            s,
            "   the model fails most on {} in {} mm (residual RMS {:.2} µm)",
            r.target,
            trueaxis_engine::compare::bbox_text(&r.bbox_mm),
            r.rms_um
        );
    }
    if let Some(dir) = report_dir {
        let p = crate::report::diagnose::write(&first, data, &dir.join("diagnose"))?;
        let _ = writeln!(s, "   evidence: {}", p.display());
    }
    let fmt = |m: &BTreeMap<String, f64>| {
        m.iter()
            .map(|(k, v)| format!("{k} {v:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let r = improve(data, seed, model_path, |st| {
        match st.added_effects.as_slice() {
            [] => {
                let _ = writeln!(
                    s,
                    "   step {}: {seed} alone: RMS µm {}; held out {}",
                    st.step,
                    fmt(&st.rms_um),
                    fmt(&st.held_out_rms_um)
                );
            }
            added => {
                for a in added {
                    match &a.replaces {
                        Some(old) => {
                            let _ = writeln!(
                                s,
                                "   step {}: named `{}`, replacing `{old}`",
                                st.step, a.add
                            );
                        }
                        None => {
                            let _ = writeln!(s, "   step {}: named and added `{}`", st.step, a.add);
                        }
                    }
                    let _ = writeln!(s, "      because {}", a.evidence);
                }
                let _ = writeln!(
                    s,
                    "      refit: RMS µm {}; held out {}",
                    fmt(&st.rms_um),
                    fmt(&st.held_out_rms_um)
                );
            }
        }
        if st.verdict == Verdict::AtNoiseFloor {
            let nf: Vec<String> = st
                .noise_floor_um
                .iter()
                .filter_map(|(k, v)| v.map(|v| format!("{k} {v:.2}")))
                .collect();
            let _ = writeln!(
                s,
                "   {} — noise floor µm: {}; no candidate is significant any more",
                st.outcome(),
                nf.join(", ")
            );
        }
    })?;
    if let Some(dir) = report_dir {
        let h = history::load(model_path)?;
        let p = crate::report::history::write_report(
            &h,
            &model_path.display().to_string(),
            &dir.join("history"),
        )?;
        let _ = writeln!(s, "   the error falling: {}", p.display());
    }
    let _ = write!(s, "   model: {} → {}", r.model, r.model_file);
    Ok((trueaxis_engine::model::ModelFile::load(model_path)?, s, r))
}

impl Args {
    pub fn run(self) -> Result<()> {
        let (seed, adds) = crate::cmd::diagnose::model_spec(&self.model)?;
        if !adds.is_empty() {
            anyhow::bail!(
                "improve starts from a seed (cubic19 or kinematic), not from a model with effects"
            );
        }
        let out = model_output(&self.data, self.output.clone())?;
        let data = input::load_data(&self.data, None)?;
        let warnings: Vec<diagnose::Warning> = input::aux_warnings(&data)
            .into_iter()
            .map(|(code, detail)| diagnose::Warning {
                code: code.into(),
                detail,
            })
            .collect();
        // On stderr in both modes, before the steps (as fit's warnings).
        for w in &warnings {
            eprintln!("warning ({}): {}", w.code, w.detail);
        }
        let json = self.json;
        // Steps are printed as they complete; a failed write (stdout closed)
        // stops the printing, not the loop — the model file is the result —
        // and is returned once the loop is done.
        let mut write_err: Option<anyhow::Error> = None;
        let r = improve(&data, &seed, &out, |s| {
            if json || write_err.is_some() {
                return;
            }
            let best = s.added_effects.first();
            let what = best.map_or(format!("fit {seed}"), |a| format!("add {}", a.add));
            let mut text = format!("step {}: {what}\n", s.step);
            for (t, rms) in &s.rms_um {
                text.push_str(&format!(
                    "  {t}: rms {rms:.4} µm, held-out {} µm, noise floor {} µm\n",
                    s.held_out_rms_um
                        .get(t)
                        .map_or("—".into(), |v| format!("{v:.4}")),
                    s.noise_floor_um
                        .get(t)
                        .copied()
                        .flatten()
                        .map_or("—".into(), |v| format!("{v:.4}"))
                ));
            }
            if let Some(a) = best {
                text.push_str(&format!("  because: {}\n", a.evidence));
            }
            write_err = out::print(&text).err();
        })
        .with_context(|| format!("{}: cannot improve {seed}", self.data.display()))?;
        let r = Improvement { warnings, ..r };
        if let Some(e) = write_err {
            return Err(e);
        }
        if json {
            let mut doc = serde_json::to_value(&r)?;
            input::add_skipped_count(&mut doc, &data);
            out::json_pretty(&doc)?;
        } else {
            outln!(
                "{}: model {} written to {}",
                r.steps.last().map_or(String::new(), ImproveStep::outcome),
                r.model,
                r.model_file
            )?;
        }
        Ok(())
    }
}
