//! `trueaxis diagnose DATA --model SPEC|MODEL.json [--add EFFECT]…
//! [--report DIR] [--json]`: where the model fails and which physical
//! effect it is missing (the work is in `trueaxis_engine::diagnose`). With `--json`
//! one document in the shape of docs/cli.md; otherwise a readable
//! summary that ends with the `fit --add` command to run next.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::cmd::out::{self, outln};
use crate::input;
use crate::workflow::model_spec;
use trueaxis_engine::diagnose::{self, Diagnosis, Options, Verdict};
use trueaxis_engine::effect::{Effect, EffectSpec};

/// Arguments of `trueaxis diagnose`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The measurement file (contract CSV or Renishaw .rtl).
    pub data: PathBuf,
    /// Seed spec (cubic19, kinematic) or a MODEL.json written by `fit`
    /// (its seed and added effects are used).
    #[arg(long)]
    pub model: String,
    /// An effect already in the model (`fit --add` syntax); repeatable.
    #[arg(long = "add", value_name = "EFFECT")]
    pub add: Vec<String>,
    /// Write the evidence plots (SVG) and an index.html into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Keep outlying readings (beam breaks, bad readings) in; by default
    /// they are found, listed with their file line and left out.
    #[arg(long)]
    pub keep_outliers: bool,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// List every `in_model_span` warning in the text output (by default
    /// one line per model; `--json` always has them all).
    #[arg(long)]
    pub verbose: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        if let Some((degree, adds)) = rigid21_degree(&self.model)? {
            return self.run_rigid21(degree, adds);
        }
        let (seed, mut adds) = model_spec(&self.model)?;
        for a in &self.add {
            let spec: EffectSpec = a.parse()?;
            if !adds.contains(&spec) {
                adds.push(spec);
            }
        }
        let data = input::load_data(&self.data, None)?;
        // Progress on stderr (a million rows take a while; the lines say
        // which target and stage), in both modes.
        let mut d = diagnose::diagnose_with(
            &data,
            &Options {
                seed,
                adds,
                follow_path: true,
                keep_outliers: self.keep_outliers,
            },
            &crate::cmd::progress::stderr(self.json),
        )
        .with_context(|| format!("{}: cannot diagnose", self.data.display()))?;
        d.warnings.extend(input::data_warnings(&data));
        let model_out = next_model_path(&self.model, &self.data);
        if let Some(dir) = &self.report {
            // A model file's history (MODEL.history.json beside it), when
            // there is one: the report then shows the error falling too.
            let model_path = Path::new(&self.model);
            let history = model_path
                .is_file()
                .then(|| trueaxis_engine::history::load(model_path).ok())
                .flatten();
            // The card's next command is the text's `next:` line.
            let index = crate::report::diagnose::write_for(
                &d,
                &data,
                &self.data.display().to_string(),
                &model_out.display().to_string(),
                dir,
                history.as_ref(),
            )?;
            if !self.json {
                outln!("report: {}", index.display())?;
            }
        }
        if self.json {
            let mut doc = serde_json::to_value(&d)?;
            doc["next_command"] = next_command(&d, &self.data, &model_out).into();
            input::add_skipped_count(&mut doc, &data);
            out::json_pretty(&doc)?;
        } else {
            let mut t = text(&d, &self.data, &model_out, self.verbose);
            if data.is_probed_surface() {
                // A bed's next step is its mesh, whatever a cubic lacks.
                t = t
                    .lines()
                    .filter(|l| !l.starts_with("next: ") && !l.starts_with("measure first: "))
                    .map(|l| format!("{l}\n"))
                    .collect();
                t.push_str(&format!(
                    "next: {}\n",
                    crate::report::diagnose::bed_next(&data, &self.data.display().to_string())
                ));
            }
            crate::cmd::out::print(&t)?;
        }
        Ok(())
    }
}

impl Args {
    /// `diagnose` on a rigid21 model (docs/volumetric.md § Diagnose): the
    /// error function it is missing, in ISO 230-1 words.
    fn run_rigid21(self, degree: usize, mut adds: Vec<EffectSpec>) -> Result<()> {
        if self.report.is_some() {
            bail!("diagnose --model rigid21: --report is not supported yet; `compare DATA --model MODEL.json --report DIR` draws the model's error functions");
        }
        // The effects on top: the model file's and those given with --add.
        let in_file = adds.len();
        for a in &self.add {
            let spec: EffectSpec = a.parse()?;
            if !adds.contains(&spec) {
                adds.push(spec);
            }
        }
        let effects: Vec<Effect> = adds.iter().cloned().map(Effect::new).collect();
        let data = input::load_data(&self.data, None)?;
        let d = trueaxis_engine::diagnose::rigid21::diagnose_with(&data, degree, &effects)
            .with_context(|| format!("{}: cannot diagnose", self.data.display()))?;
        let model_out = next_model_path(&self.model, &self.data);
        // A higher degree holds a function's missing shape, a lead error is
        // a periodic effect on top: the next fit has both, with the
        // model's own effects kept. Nothing missing: the model goes to the
        // board (a model file as it is; a seed name is fitted first).
        use crate::report::diagnose::shell_word;
        let word = |p: &Path| shell_word(&p.display().to_string());
        let fit = |degree: usize, more: &[String]| {
            let add: String = adds
                .iter()
                .map(ToString::to_string)
                .chain(more.iter().cloned())
                .map(|a| format!(" --add {}", shell_word(&a)))
                .collect();
            format!(
                "trueaxis fit {} --model rigid21:{degree}{add} -o {}",
                word(&self.data),
                word(&model_out)
            )
        };
        let next = if !d.findings.is_empty() {
            let next_degree = if d.findings.iter().any(|f| f.period_mm.is_none()) {
                (degree + 2).min(trueaxis_engine::model::rigid21::MAX_DEGREE)
            } else {
                degree
            };
            let leads: Vec<String> = d.findings.iter().filter_map(|f| f.add.clone()).collect();
            Some(fit(next_degree, &leads))
        } else if Path::new(&self.model).is_file() && adds.len() == in_file {
            Some(format!("trueaxis export {} -o table.bin", word(&model_out)))
        } else {
            Some(fit(degree, &[]))
        };
        if self.json {
            let mut doc = serde_json::to_value(&d)?;
            doc["next_command"] = next.into();
            input::add_skipped_count(&mut doc, &data);
            out::json_pretty(&doc)?;
            return Ok(());
        }
        let mut t = format!(
            "{}: model {} ({} set-ups; hold-out by set-up)\n  residual {} σ of the readings (u_um), held-out {}\n",
            self.data.display(),
            d.model,
            d.setups,
            fmt3(d.rms_sigma),
            d.held_out_rms_sigma.map_or("n/a".into(), |v| format!("{} σ", fmt3(v)))
        );
        for f in &d.findings {
            t.push_str(&format!(
                "missing: {} (ΔBIC {}, held-out {})\n",
                f.text,
                f.delta_bic.map_or("n/a".into(), |v| format!("{v:.0}")),
                f.held_out_gain
                    .map_or("n/a".into(), |g| format!("−{:.0} %", 100.0 * g))
            ));
        }
        t.push_str(&format!("verdict: {}\n", d.verdict));
        for w in &d.warnings {
            t.push_str(&format!("warning: {w}\n"));
        }
        if let Some(n) = next {
            t.push_str(&format!("next: {n}\n"));
        }
        crate::cmd::out::print(&t)
    }
}

/// Three significant figures.
fn fmt3(v: f64) -> String {
    crate::report::plot::format_value(v)
}

/// The degree and the effects on top when `--model` is a rigid21 spec
/// (no effects) or a rigid21 MODEL.json (its `adds`).
fn rigid21_degree(model: &str) -> Result<Option<(usize, Vec<EffectSpec>)>> {
    let (seed, adds) = if model.ends_with(".json") || Path::new(model).is_file() {
        let m = input::load_model(Path::new(model))?;
        (m.seed, m.adds)
    } else {
        (model.to_string(), Vec::new())
    };
    if !seed.starts_with("rigid21") {
        return Ok(None);
    }
    match seed.parse::<trueaxis_engine::model::Seed>()? {
        trueaxis_engine::model::Seed::Rigid21 { degree } => {
            // The file's effects were checked when it was loaded.
            let adds = adds
                .iter()
                .map(|a| a.parse())
                .collect::<Result<Vec<EffectSpec>>>()?;
            Ok(Some((degree, adds)))
        }
        _ => Ok(None),
    }
}

/// Where the `next:` command writes its model: over the model file that
/// was diagnosed (so its history continues, docs/diagnose.md § History),
/// or `model.json` beside the data when a seed name was given.
fn next_model_path(model: &str, data_path: &Path) -> PathBuf {
    let m = Path::new(model);
    if m.is_file() {
        m.to_path_buf()
    } else {
        data_path
            .parent()
            .unwrap_or(Path::new(""))
            .join("model.json")
    }
}

/// The `fit` command that adds every effect the path found — the one
/// command to run next, the same on the report's verdict card — or `None`
/// when the path found nothing.
pub fn next_command(d: &Diagnosis, data_path: &Path, model_out: &Path) -> Option<String> {
    crate::report::diagnose::fit_command(
        d,
        &data_path.display().to_string(),
        &model_out.display().to_string(),
    )
}

/// The human summary; `model_out` is where the `next:` command writes;
/// `verbose` lists every `in_model_span` warning instead of one line per
/// model.
pub fn text(d: &Diagnosis, data_path: &Path, model_out: &Path, verbose: bool) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "{}: model {} (hold-out: {})\n",
        data_path.display(),
        d.model,
        d.hold_out
    ));
    s.push_str(&format!(
        "  {:<6} {:>10} {:>16} {:>14}\n",
        "target", "rms µm", "held-out rms µm", "noise floor µm"
    ));
    for (t, rms) in &d.rms_um {
        let nf = d
            .noise_floor_um
            .get(t)
            .copied()
            .flatten()
            .map_or("—".to_string(), |v| format!("{v:.4}"));
        let held = d
            .held_out_rms_um
            .get(t)
            .copied()
            .filter(|v| v.is_finite())
            .map_or_else(|| "n/a".to_string(), |v| format!("{v:.4}"));
        s.push_str(&format!(
            "  {:<6} {:>10.4} {:>16} {:>14}\n",
            t, rms, held, nf
        ));
    }
    if d.held_out_rms_um.values().any(|v| !v.is_finite()) {
        s.push_str(
            "  (held-out n/a: no block could be held out — one position, one pass and no t_s)\n",
        );
    }
    match d.verdict {
        Verdict::MissingEffect => s.push_str("verdict: missing_effect\n"),
        Verdict::AtNoiseFloor => {
            s.push_str(
                "verdict: at_noise_floor — no candidate is significant and every target is within 1.3× its noise floor\n",
            );
            for w in d.warnings.iter().filter(|w| w.code == "noise_floor_upper_bound") {
                s.push_str(&format!("  but {}\n", w.detail));
            }
        }
        Verdict::AboveNoiseFloor => {
            s.push_str("verdict: above_noise_floor — no candidate is significant, but systematic error is left:\n")
        }
        Verdict::NoiseFloorUnknown => {
            s.push_str("verdict: noise_floor_unknown — no candidate is significant, and these data cannot say how small the residual can get:\n");
            for w in d.warnings.iter().filter(|w| w.code == "noise_floor_unknown") {
                s.push_str(&format!("  {}\n", w.detail));
            }
        }
    }
    if d.verdict == Verdict::MissingEffect && !d.unexplained.is_empty() {
        s.push_str("left above the noise floor after the path:\n");
    }
    for u in &d.unexplained {
        s.push_str(&format!("  {}\n", u.text()));
    }
    // What the data seem to show and the sampling cannot support: named
    // with the verdict, not only among the warnings.
    for (c, a) in d.held_back() {
        s.push_str(&format!(
            "  held back (aliasing-suspect, not added): `{}` — {}\n",
            c.add, a.text
        ));
    }
    if !d.unresolved.is_empty() {
        s.push_str(
            "confounded, not attributed (each passes on its own; measure to separate them):\n",
        );
        for u in &d.unresolved {
            s.push_str(&format!("  {}\n", u.text()));
        }
    }
    s.push_str("candidates (best first):\n");
    for (i, c) in d
        .candidates
        .iter()
        .filter(|c| c.identifiable)
        .take(8)
        .enumerate()
    {
        s.push_str(&format!(
            "  {}. {}{}\n     {}\n",
            i + 1,
            match c.step {
                Some(k) => format!("[path step {k}] "),
                None if c.significant => "[significant] ".into(),
                None => String::new(),
            },
            match &c.replaces {
                Some(old) => format!("{} (replacing {old})", c.add),
                None => c.add.clone(),
            },
            c.evidence
        ));
        if let Some(a) = &c.aliasing {
            s.push_str(&format!("     aliasing: {}\n", a.text));
        }
    }
    if !d.path.is_empty() {
        s.push_str("path (BIC-ordered, until the held-out RMS stops improving):\n");
        for p in &d.path {
            s.push_str(&format!(
                "  {} + {}: rms {:.4} µm, held-out {:.4} µm\n",
                p.target, p.add, p.rms_um, p.held_out_rms_um
            ));
        }
    }
    if !d.worst_regions.is_empty() {
        s.push_str("worst regions:\n");
        for r in &d.worst_regions {
            s.push_str(&format!(
                "  {} {}: rms {:.3} µm ({} points)\n",
                r.target,
                r.place(),
                r.rms_um,
                r.points
            ));
        }
    }
    if !d.outliers.is_empty() {
        s.push_str(&format!(
            "outliers ({}, left out; --keep-outliers keeps them):\n",
            d.outliers.len()
        ));
        let src = data_path.display().to_string();
        for o in &d.outliers {
            s.push_str(&format!("  {}\n", o.text(&src)));
        }
    }
    if !d.warnings.is_empty() {
        s.push_str("warnings:\n");
        // `in_model_span` says the same thing for every candidate the seed
        // already contains (45 lines on a thermal test): one line per
        // model, naming them, unless --verbose.
        let in_span: Vec<&str> = d
            .warnings
            .iter()
            .filter(|w| w.code == "in_model_span")
            .filter_map(|w| w.detail.split('`').nth(1))
            .collect();
        let mut collapsed = false;
        for w in &d.warnings {
            if w.code == "in_model_span" && !verbose && in_span.len() > 1 {
                if !collapsed {
                    collapsed = true;
                    let seed = d.model.split(" + ").next().unwrap_or("the model");
                    s.push_str(&format!(
                        "  [in_model_span] {seed} already contains {} candidates' columns, so they cannot be told from it: {} (details: --verbose or --json)\n",
                        in_span.len(),
                        in_span.iter().map(|a| format!("`{a}`")).collect::<Vec<_>>().join(", ")
                    ));
                }
                continue;
            }
            s.push_str(&format!("  [{}] {}\n", w.code, w.detail));
        }
    }
    // The page's next command (a fit with what is missing; at the noise
    // floor the refit and its export), printed when it is one to run.
    if let Some(cmd) = next_command(d, data_path, model_out).or_else(|| {
        crate::report::diagnose::verdict(
            d,
            &data_path.display().to_string(),
            &model_out.display().to_string(),
        )
        .next
        .filter(|n| n.starts_with("trueaxis "))
    }) {
        s.push_str(&format!("next: {cmd}\n"));
    }
    let mut lines: Vec<&str> = d.held_back().map(|(_, a)| a.measure.as_str()).collect();
    lines.sort_unstable();
    lines.dedup();
    for m in lines {
        s.push_str(&format!("measure first: a dense line: {m}\n"));
    }
    s
}
