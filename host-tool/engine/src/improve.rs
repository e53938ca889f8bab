//! The improve loop — fit, diagnose, add the best significant effect of
//! each target, refit — until the diagnosis finds nothing significant
//! (`at_noise_floor`, or `above_noise_floor` when the residual is not):
//! what `trueaxis improve` and the demo's diagnosis stage both run. Every
//! fit is written to the model file and appended to its history, so
//! `trueaxis history` shows the same steps afterwards. The loop reports
//! each step to a callback as it completes; it prints nothing itself.

use std::collections::BTreeMap;

use anyhow::Result;
use serde::Serialize;

use crate::data::Dataset;
use crate::diagnose::noise::NoiseMethod;
use crate::diagnose::outliers::{self, Outlier};
use crate::diagnose::{self, Options, Verdict};
use crate::effect::{Effect, EffectSpec};
use crate::fit::{self, FitOptions};
use crate::history;
use crate::model::Seed;
use crate::progress::{Event, ImproveStage, Sink};

/// Most effects `improve` adds before it stops anyway.
pub const MAX_STEPS: usize = 8;

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
    /// How each floor was estimated (`sparse_differences`: an upper bound).
    pub noise_method: BTreeMap<String, Option<NoiseMethod>>,
    /// The diagnosis of this fit.
    pub verdict: Verdict,
    /// Targets whose RMS is still more than `ABOVE_NOISE_RATIO` × their noise
    /// floor, with the ratio (the diagnosis' `unexplained`).
    pub above_noise_floor: BTreeMap<String, f64>,
    /// The same targets with RMS, floor and worst region, for the closing
    /// line (the JSON has the ratios above).
    #[serde(skip)]
    pub unexplained: Vec<diagnose::Unexplained>,
    /// Candidates the diagnosis of this fit held back as aliasing-suspect
    /// (`diagnose`'s `held_back`): not added, with why and what to measure.
    pub held_back: Vec<HeldBack>,
    /// Pairs of candidates that each pass on their own but that the data
    /// cannot tell apart (the diagnosis' `unresolved`), with the
    /// measurement that separates them.
    pub unresolved: Vec<diagnose::Unresolved>,
    /// The diagnosis' `rejected_candidate` warnings (a candidate ΔBIC
    /// alone would take, refused by the other rules), for the closing line.
    #[serde(skip)]
    pub rejected: Vec<String>,
}

/// A candidate the loop did not add because the sampling along its axis
/// cannot tell it from a lead's alias.
#[derive(Clone, Debug, Serialize)]
pub struct HeldBack {
    /// Target.
    pub target: String,
    /// The `fit --add` string it would have added.
    pub add: String,
    /// Why, in words, with the periods that would look the same.
    pub why: String,
    /// The dense line to measure.
    pub measure: String,
}

impl HeldBack {
    /// `not added: \`higher_order:…\` — ey varies along y like …`.
    pub fn text(&self) -> String {
        format!("not added: `{}` — {}", self.add, self.why)
    }
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
    /// What the step's verdict means, in words (for the closing line):
    /// "at the noise floor" only when the diagnosis says so — every target
    /// within `ABOVE_NOISE_RATIO`× its floor.
    pub fn outcome(&self) -> String {
        let mut s = self.verdict_words();
        if self.verdict != Verdict::MissingEffect && !self.rejected.is_empty() {
            s.push_str(&format!("; not accepted: {}", self.rejected.join("; ")));
        }
        // Why it stopped short of the wave the data seem to show, and the
        // measurement that settles it.
        for h in &self.held_back {
            s.push_str(&format!("; {}", h.text()));
        }
        s
    }

    fn verdict_words(&self) -> String {
        match self.verdict {
            Verdict::MissingEffect => "stopped after the step limit".into(),
            Verdict::AtNoiseFloor => {
                // Against an upper bound of the noise, "at the floor" says
                // less than it seems: say so, and what to measure.
                let bound: Vec<&str> = self
                    .noise_method
                    .iter()
                    .filter(|(_, m)| **m == Some(NoiseMethod::SparseDifferences))
                    .map(|(t, _)| t.as_str())
                    .collect();
                if bound.is_empty() {
                    "at the noise floor".into()
                } else {
                    format!(
                        "at the noise floor, but the noise floor of {} is an upper bound: re-probe points (repeat the map / these points) to measure repeatability",
                        bound.join(", ")
                    )
                }
            }
            Verdict::NoiseFloorUnknown => format!(
                "no significant candidate left; the noise floor of {} cannot be known from these data (see noise_floor_unknown: what to measure)",
                self.noise_method
                    .iter()
                    .filter(|(_, m)| m.is_none())
                    .map(|(t, _)| t.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Verdict::AboveNoiseFloor
                if self.unexplained.is_empty() && self.unresolved.is_empty() =>
            {
                "no significant candidate left, but one the sampling cannot support is held back"
                    .into()
            }
            Verdict::AboveNoiseFloor => format!(
                "no significant candidate left, but {}",
                self.unexplained
                    .iter()
                    .map(|u| format!("above the noise floor: {}", u.text()))
                    .chain(
                        self.unresolved
                            .iter()
                            .map(|u| format!("not attributable: {}", u.text()))
                    )
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        }
    }
}

/// The diagnosis' warnings about the measurement's design (what the data
/// cannot show, whatever the model), carried into [`Improvement::warnings`].
pub const DESIGN_WARNINGS: [&str; 7] = [
    "aliasing",
    "one_direction",
    "constant_temperature",
    "no_temperature",
    "noise_floor_upper_bound",
    "noise_floor_unknown",
    "reading_quantum",
];

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
    /// `aux_columns`) and the last diagnosis' design warnings
    /// ([`DESIGN_WARNINGS`]: `aliasing`, `no_temperature`, …), as
    /// diagnose's `warnings`.
    pub warnings: Vec<diagnose::Warning>,
    /// Readings left out of every fit as outliers, found with the final
    /// model (empty with `keep_outliers`).
    pub outliers: Vec<Outlier>,
    /// Rows left out of every fit because they lie outside the travel
    /// (`crate::travel`), with the final model's miss at each.
    pub outside_travel: Vec<crate::travel::OutsideRow>,
    /// What the last diagnosis held back as aliasing-suspect (the last
    /// step's `held_back`): why the loop stopped short of it and the dense
    /// line to measure.
    pub held_back: Vec<HeldBack>,
}

/// Runs the loop on `data`, writing each fit to `out` (and its history);
/// `on_step` sees each step as it completes (for printing). Outliers are
/// found with each step's model and left out of its fit and diagnosis
/// (`diagnose::outliers`) unless `keep_outliers`; rows outside the data's
/// bulk (`crate::travel`) are left out of everything.
pub fn improve(
    data: &Dataset,
    seed: Seed,
    out: &std::path::Path,
    keep_outliers: bool,
    on_step: impl FnMut(&ImproveStep),
) -> Result<Improvement> {
    improve_with(
        data,
        seed,
        out,
        keep_outliers,
        &[None; 3],
        on_step,
        &Sink::none(),
    )
}

/// [`improve`], telling `progress` what it is doing (each step's fit and
/// diagnosis, [`Event::Improve`], and the diagnosis' own events, as
/// [`diagnose::diagnose_with`] sends them). `on_step` is no progress: it
/// gets each step's result. `travel` is the travel given per axis (else
/// the data's bulk, `crate::travel`): rows outside it are left out of
/// every fit and diagnosis and recorded in each model.
pub fn improve_with(
    file_data: &Dataset,
    seed: Seed,
    out: &std::path::Path,
    keep_outliers: bool,
    travel: &crate::travel::Limits,
    mut on_step: impl FnMut(&ImproveStep),
    progress: &Sink,
) -> Result<Improvement> {
    let screen = crate::travel::screen(file_data, travel)?;
    let data = &*screen.inside(file_data);
    let mut adds: Vec<EffectSpec> = Vec::new();
    let mut steps = Vec::new();
    let mut added: Vec<AddedEffect> = Vec::new();
    // Every step's model was fitted to the measurement file, whichever
    // readings the screen left out at that step: the history follows the
    // file, whose hash is the same at every step.
    let sha256 = crate::import::content_hash(file_data);
    loop {
        let effects: Vec<Effect> = adds.iter().cloned().map(Effect::new).collect();
        let k = steps.len() + 1;
        progress.emit(&Event::Improve {
            step: k,
            stage: ImproveStage::Fitting {
                seed: seed.to_string(),
                adds: adds.iter().map(ToString::to_string).collect(),
                rows: data.len(),
            },
        });
        let found = if keep_outliers {
            Vec::new()
        } else {
            outliers::find(data, &seed, &effects)?
        };
        let clean = outliers::without(data, &found);
        // `fit` takes the `--model` text (it records it as given).
        let mut model = fit::fit_recorded(
            &clean,
            &seed.to_string(),
            &effects,
            &FitOptions::default(),
            || sha256.clone(),
        )?;
        fit::record_outside(&mut model, file_data, &screen);
        history::save_with_model(out, &model)?;
        progress.emit(&Event::Improve {
            step: k,
            stage: ImproveStage::Diagnosing,
        });
        let (d, specs) = diagnose::diagnose_specs(
            &clean,
            &Options {
                seed,
                adds: adds.clone(),
                follow_path: false,
                keep_outliers: true,
            },
            progress,
        )?;
        let above_noise_floor = d
            .unexplained
            .iter()
            .map(|u| (u.target.clone(), u.ratio))
            .collect();
        let step = ImproveStep {
            step: steps.len() + 1,
            added_effects: std::mem::take(&mut added),
            rms_um: model.stats.rms_um.clone(),
            held_out_rms_um: d.held_out_rms_um.clone(),
            fit_held_out_rms_um: model.stats.held_out_rms_um.clone(),
            noise_floor_um: d.noise_floor_um.clone(),
            noise_method: d.noise_method.clone(),
            verdict: d.verdict,
            above_noise_floor,
            unexplained: d.unexplained.clone(),
            held_back: d
                .held_back()
                .map(|(c, a)| HeldBack {
                    target: c.target.clone(),
                    add: c.add.clone(),
                    why: a.text.clone(),
                    measure: a.measure.clone(),
                })
                .collect(),
            unresolved: d.unresolved.clone(),
            rejected: d
                .warnings
                .iter()
                .filter(|w| w.code == "rejected_candidate")
                .map(|w| w.detail.clone())
                .collect(),
        };
        on_step(&step);
        steps.push(step);
        // The best significant candidate of each target (candidates are
        // sorted best first; without the path there is at most one per
        // target), added — or swapped in for the same effect — together.
        let mut seen = std::collections::BTreeSet::new();
        if steps.len() <= MAX_STEPS {
            for (c, s) in d
                .candidates
                .iter()
                .zip(&specs)
                .filter(|(c, _)| c.significant)
            {
                if !seen.insert(c.target.clone()) {
                    continue;
                }
                if diagnose::swap_in(&mut adds, &s.add, s.replaces.as_ref()) {
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
            let held_back = steps.last().map_or(Vec::new(), |s| s.held_back.clone());
            return Ok(Improvement {
                held_back,
                model: model.spec(),
                model_file: out.display().to_string(),
                steps,
                verdict: d.verdict,
                // What the measurement's design hides, as the last
                // diagnosis says it (issue 28: improve said "at the noise
                // floor" with `warnings: []` where diagnose warned that the
                // grid hides leads and no temperature was logged).
                warnings: d
                    .warnings
                    .iter()
                    .filter(|w| DESIGN_WARNINGS.contains(&w.code.as_str()))
                    .cloned()
                    .collect(),
                outliers: found
                    .into_iter()
                    .map(|o| Outlier {
                        row: screen.file_row(o.row),
                        ..o
                    })
                    .collect(),
                outside_travel: model.data.outside_travel.clone(),
            });
        }
    }
}
