//! `trueaxis improve DATA --model cubic19 [-o MODEL.json] [--json]`: the
//! diagnosis loop run by itself — fit, diagnose, add the best significant
//! effect, refit — until the diagnosis says `at_noise_floor`, printing each
//! step. Every fit is written to MODEL.json and appended to its history, so
//! `trueaxis history MODEL.json` shows the same steps afterwards.

use std::path::PathBuf;

use anyhow::{Context, Result};
use trueaxis_engine::improve::{improve_with, ImproveStep, Improvement};

use crate::cmd::out::{self, outln};
use crate::input;
use crate::workflow::{model_output, model_spec};

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
    /// Keep outlying readings (beam breaks, bad readings) in; by default
    /// they are found, listed with their file line and left out of every fit.
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
        let (seed, adds) = model_spec(&self.model)?;
        if !adds.is_empty() {
            anyhow::bail!(
                "improve starts from a seed (cubic19 or kinematic), not from a model with effects"
            );
        }
        let limits = self.travel.limits()?;
        let out = model_output(&self.data, self.output.clone())?;
        let data = input::load_data(&self.data, None)?;
        let mut warnings = input::data_warnings(&data);
        // On stderr in both modes, before the steps (as fit's warnings).
        for w in &warnings {
            eprintln!("warning ({}): {}", w.code, w.detail);
        }
        let json = self.json;
        // Steps are printed as they complete; a failed write (stdout closed)
        // stops the printing, not the loop — the model file is the result —
        // and is returned once the loop is done.
        let mut write_err: Option<anyhow::Error> = None;
        // Progress on stderr in both modes (each step's fit and diagnosis).
        let progress = crate::cmd::progress::stderr(json);
        let r = improve_with(
            &data,
            seed,
            &out,
            self.keep_outliers,
            &limits,
            |s| {
                if json || write_err.is_some() {
                    return;
                }
                // Every effect the step added, each with its evidence (one
                // per target can be added in one step).
                let what = if s.added_effects.is_empty() {
                    format!("fit {seed}")
                } else {
                    s.added_effects
                        .iter()
                        .map(|a| format!("add {}", a.add))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
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
                for a in &s.added_effects {
                    text.push_str(&format!(
                        "  because ({}): {}\n",
                        crate::report::history::effect_words(&a.add),
                        a.evidence
                    ));
                }
                write_err = out::print(&text).err();
            },
            &progress,
        )
        .with_context(|| format!("{}: cannot improve {seed}", self.data.display()))?;
        // The data's warnings first, then the rows outside the travel,
        // then the last diagnosis' design warnings the engine carried.
        let design = r.warnings.clone();
        // Rows outside the travel, with the final model's miss at each:
        // said once the loop is done (on stderr, and in the JSON's
        // `warnings` and `outside_travel`).
        if let Some(s) =
            trueaxis_engine::travel::summary(&self.data.display().to_string(), &r.outside_travel)
        {
            let w = trueaxis_engine::warning::Warning::new(
                "outside_travel",
                format!(
                    "{s} — {} keeps them",
                    crate::cmd::travel_keeping(&r.outside_travel)
                ),
            );
            eprintln!("warning ({}): {}", w.code, w.detail);
            warnings.push(w);
        }
        let r = Improvement {
            warnings: warnings.into_iter().chain(design.iter().cloned()).collect(),
            ..r
        };
        if let Some(e) = write_err {
            return Err(e);
        }
        if json {
            let mut doc = serde_json::to_value(&r)?;
            input::add_skipped_count(&mut doc, &data);
            out::json_pretty(&doc)?;
        } else {
            if !r.outliers.is_empty() {
                let src = self.data.display().to_string();
                let mut text = format!(
                    "outliers ({}, left out; --keep-outliers keeps them):\n",
                    r.outliers.len()
                );
                for o in &r.outliers {
                    text.push_str(&format!("  {}\n", o.text(&src)));
                }
                out::print(&text)?;
            }
            for w in &design {
                outln!("warning ({}): {}", w.code, w.detail)?;
            }
            outln!(
                "{}: model {} written to {}",
                r.steps.last().map_or(String::new(), ImproveStep::outcome),
                r.model,
                r.model_file
            )?;
            // The history page shows the steps and proposes what follows
            // (the export at the noise floor, else the diagnosis).
            outln!(
                "next: trueaxis history {} --report history",
                crate::report::diagnose::shell_word(&r.model_file)
            )?;
        }
        Ok(())
    }
}
