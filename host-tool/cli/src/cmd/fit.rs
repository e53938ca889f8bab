//! `trueaxis fit` — fit a compensation model to measurements and write
//! MODEL.json. The work is in `trueaxis_engine::fit`; this file maps the command line
//! onto it and prints the result (text, or docs/cli.md's JSON with `--json`).
//! Warnings (ill-conditioning, unmeasured grid nodes, epoch limit) go to
//! stderr in both modes and into the JSON's `warnings`.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::cmd::out::{self, outln};
use crate::input;
use crate::report::diagnose::shell_word;
use crate::workflow::model_output;
use trueaxis_engine::diagnose::outliers;
use trueaxis_engine::effect::Effect;
use trueaxis_engine::fit::{self, nn::NnOptions, FitOptions};
use trueaxis_engine::travel;
use trueaxis_engine::warning::Warning;

/// Arguments of `trueaxis fit`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The measurement file (contract CSV or Renishaw .rtl).
    pub data: PathBuf,
    /// Model spec: cubic19, kinematic, nn:<hidden>, grid:<step_mm> or
    /// rigid21[:<degree>] (docs/volumetric.md).
    #[arg(long)]
    pub model: String,
    /// Add a physical effect (`periodic:target=ey,axis=y,period_mm=5`, as
    /// printed by `diagnose`); repeatable.
    #[arg(long = "add", value_name = "EFFECT")]
    pub add: Vec<String>,
    /// Fit the seed's local polynomials (cuboid between measured planes,
    /// plane, or line) instead of one global polynomial.
    #[arg(long)]
    pub local: bool,
    /// Where to write the model (default: `<data>.model.json` beside the data).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Number of hold-out blocks (whole passes or spatial slabs) for the held-out RMS.
    #[arg(long, default_value_t = 5, allow_negative_numbers = true, value_parser = clap::value_parser!(u16).range(2..=100))]
    pub blocks: u16,
    /// Network training: maximum epochs (nn only; at least 1).
    #[arg(long, default_value_t = 1000, allow_negative_numbers = true,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_epochs: usize,
    /// Network training: RNG seed of the initial weights (nn only).
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// Keep outlying readings (beam breaks, bad readings) in; by default
    /// they are found with a linear screen (the seed, or cubic19 for nn and
    /// grid), listed with their file line and left out of the fit.
    #[arg(long)]
    pub keep_outliers: bool,
    #[command(flatten)]
    pub travel: crate::cmd::TravelArgs,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        // Parse everything that can be wrong with the command before reading data.
        let seed = trueaxis_engine::model::Seed::parse(&self.model)?;
        let adds = self
            .add
            .iter()
            .map(|s| Effect::parse(s))
            .collect::<Result<Vec<_>>>()?;
        let limits = self.travel.limits()?;
        let out = model_output(&self.data, self.output.clone())?;
        let data = input::load_data(&self.data, None)?;
        // The travel (given, or the data's bulk): rows outside it are left
        // out of the screen and the fit, and named below.
        let screen = travel::screen(&data, &limits)
            .with_context(|| format!("{}: cannot fit {}", self.data.display(), self.model))?;
        let inside = screen.inside(&data);
        let opts = FitOptions {
            blocks: usize::from(self.blocks),
            local: self.local,
            nn: NnOptions {
                max_epochs: self.max_epochs,
                seed: self.seed,
                ..NnOptions::default()
            },
            progress: crate::cmd::progress::stderr(self.json),
        };
        // Outliers: a screen that cannot run (too few points for its
        // linear model) is said, and the fit below then names the problem
        // itself when it has the same one.
        let mut screen_warning = None;
        // The outlier screen fits a linear model per target; a rigid21
        // fit's readings (set-ups, angles, beams) are not screened yet.
        let volumetric = matches!(seed, trueaxis_engine::model::Seed::Rigid21 { .. });
        let mut found = if self.keep_outliers || volumetric {
            Vec::new()
        } else {
            outliers::find(&inside, &seed, &adds).unwrap_or_else(|e| {
                screen_warning = Some(Warning::new(
                    "outliers_not_screened",
                    format!("outliers: not screened ({e:#})"),
                ));
                Vec::new()
            })
        };
        let clean = outliers::without(&inside, &found);
        // Rows as the file numbers them (the fitted data lacks the rows
        // outside the travel).
        for o in &mut found {
            o.row = screen.file_row(o.row);
        }
        // The fit's own messages name the target (`ex: 3 distinct points
        // but the model has 4 terms`); the file is named here.
        // Fitted to the file (less its outliers): the history follows the
        // file, so the model records the file's hash (not the cleaned copy's).
        let mut model = fit::fit_recorded(&clean, &self.model, &adds, &opts, || {
            trueaxis_engine::import::content_hash(&data)
        })
        .with_context(|| format!("{}: cannot fit {}", self.data.display(), self.model))?;
        model.stats.warnings.extend(screen_warning);
        fit::record_outside(&mut model, &data, &screen);
        if let Some(s) =
            travel::summary(&self.data.display().to_string(), &model.data.outside_travel)
        {
            let keep = crate::cmd::travel_keeping(&model.data.outside_travel);
            let them = if screen.outside_rows().len() == 1 {
                "it"
            } else {
                "them"
            };
            model.stats.warnings.push(Warning::new(
                "outside_travel",
                format!("outside_travel: {s} — {keep} keeps {them}"),
            ));
        }
        // Fit's warnings are kept as text (MODEL.json `stats.warnings`): a
        // data warning's text leads with its code, as `warning (code): …`
        // elsewhere.
        for w in input::data_warnings(&data) {
            let text = format!("{}: {}", w.code, w.detail);
            model.stats.warnings.push(Warning::new(&w.code, text));
        }
        trueaxis_engine::history::save_with_model(&out, &model)?;
        for w in &model.stats.warnings {
            eprintln!("warning: {w}");
        }
        if self.json {
            let mut doc = model.summary_json(Some(&out));
            input::add_skipped_count(&mut doc, &data);
            doc["outliers"] = serde_json::to_value(&found)?;
            doc["outside_travel"] = serde_json::to_value(&model.data.outside_travel)?;
            out::json(&doc)?;
            return Ok(());
        }
        let s = &model.stats;
        // One count when every target has it, else each target's (issue
        // 28: "21 terms per target" when two targets had 19).
        let counts: std::collections::BTreeSet<usize> =
            s.terms_per_target.values().copied().collect();
        let terms = match counts.len() {
            0 => format!("{} per target", crate::report::count(s.terms, "term")),
            1 => format!(
                "{} per target",
                crate::report::count(counts.into_iter().next().unwrap_or(s.terms), "term")
            ),
            _ => format!(
                "terms per target {}",
                s.terms_per_target
                    .iter()
                    .map(|(t, n)| format!("{t} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        outln!(
            "{}: {} on {}, {terms}",
            self.data.display(),
            model.spec(),
            crate::report::count(data.len(), "row"),
        )?;
        outln!(
            "  {:<4} {:>7} {:>12} {:>16} {:>12} {:>10}",
            "",
            "rows",
            "rms µm",
            "held-out rms µm",
            "max |e| µm",
            "cond"
        )?;
        for (t, rms) in &s.rms_um {
            let opt = |m: &std::collections::BTreeMap<String, f64>, prec: usize| {
                m.get(t).map_or("—".to_string(), |v| {
                    if prec == 0 {
                        format!("{v:.2e}")
                    } else {
                        format!("{v:.prec$}")
                    }
                })
            };
            outln!(
                "  {:<4} {:>7} {:>12.4} {:>16} {:>12.4} {:>10}",
                t,
                s.rows.get(t).copied().unwrap_or(0),
                rms,
                opt(&s.held_out_rms_um, 4),
                s.max_abs_um.get(t).copied().unwrap_or(0.0),
                opt(&s.condition_number, 0),
            )?;
        }
        outln!("  hold-out: {}", s.holdout)?;
        // A rigid21 model's effects on top, by their physical parameter.
        for e in s.volumetric.iter().flat_map(|v| &v.effects) {
            match (&e.physical, e.value, &e.unit) {
                (Some(name), Some(v), Some(unit)) => {
                    outln!("  on top: {}: {name} {v:.4} {unit}", e.effect)?
                }
                _ => outln!("  on top: {}", e.effect)?,
            }
        }
        if !found.is_empty() {
            outln!(
                "  outliers ({}, left out; --keep-outliers keeps them):",
                found.len()
            )?;
            let src = self.data.display().to_string();
            for o in &found {
                outln!("    {}", o.text(&src))?;
            }
        }
        outln!("  model written to {}", out.display())?;
        // Where the model fails, on a page (issue 28: every command that
        // writes something says what to run next).
        outln!(
            "next: trueaxis compare {} --model {} --report report",
            shell_word(&self.data.display().to_string()),
            shell_word(&out.display().to_string())
        )?;
        Ok(())
    }
}
