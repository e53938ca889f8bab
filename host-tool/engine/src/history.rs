//! The history of a model: every fit appends a step (the spec, the effect
//! added, RMS and block-held-out RMS per target) to a file kept beside the
//! model — `MODEL.json` → `MODEL.history.json` — so that `trueaxis history`
//! and the reports can show the error falling step by step as effects are
//! added (issue 4, "watch the error fall").
//!
//! A step continues the history when it refits the same data with the same
//! seed and keeps every effect of the last step, or the same effect with a
//! new nonlinear parameter (a lag, period, order or degree searched again —
//! `diagnose`'s `replaces`) (the diagnose → add → refit loop); refitting the same spec replaces the last step (so running a
//! command twice does not add a step); anything else — other data, another
//! seed, effects taken away — starts a new history.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::effect::EffectSpec;
use crate::files::{self, Lock, LOCK_WAIT};

/// Format tag of a history file.
pub const HISTORY_FORMAT: &str = "trueaxis-history/1";

/// One fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// 1-based step number.
    pub step: usize,
    /// Seed spec (`cubic19`, …).
    pub seed: String,
    /// Every `--add` effect of this fit, in order.
    pub adds: Vec<String>,
    /// Effects added since the previous step (empty for the first).
    pub added: Vec<String>,
    /// Coefficients per target (largest).
    pub terms: usize,
    /// In-sample RMS per target, µm.
    pub rms_um: BTreeMap<String, f64>,
    /// Block-held-out RMS per target, µm.
    pub held_out_rms_um: BTreeMap<String, f64>,
    /// SHA-256 of the data the step was fitted to.
    pub data_sha256: String,
}

impl Step {
    /// The model spec as a command-line fragment.
    pub fn spec(&self) -> String {
        let mut s = self.seed.clone();
        for a in &self.adds {
            s.push_str(" --add ");
            s.push_str(a);
        }
        s
    }
}

/// `MODEL.history.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct History {
    /// Always [`HISTORY_FORMAT`].
    pub format: String,
    /// The steps, oldest first.
    pub steps: Vec<Step>,
}

/// Where the history of `model_path` lives: `X.json` → `X.history.json`
/// (`X` → `X.history.json` when the name has no `.json`).
pub fn history_path(model_path: &Path) -> PathBuf {
    let name = model_path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let stem = name.strip_suffix(".json").unwrap_or(&name);
    model_path.with_file_name(format!("{stem}.history.json"))
}

/// Reads the history of `model_path`.
pub fn load(model_path: &Path) -> Result<History> {
    let p = history_path(model_path);
    let text = std::fs::read_to_string(&p).with_context(|| {
        format!(
            "cannot read {} (each `trueaxis fit -o {}` adds a step to it)",
            p.display(),
            model_path.display()
        )
    })?;
    let h: History = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a trueaxis history file", p.display()))?;
    if h.format != HISTORY_FORMAT {
        bail!(
            "{}: history format `{}`, this trueaxis reads `{HISTORY_FORMAT}`",
            p.display(),
            h.format
        );
    }
    Ok(h)
}

/// Appends `step` (its `step` and `added` fields are filled in here) to the
/// history of `model_path` by the rules at the top of this module, writes
/// it, and returns it.
pub fn record_step(model_path: &Path, step: Step) -> Result<History> {
    let _lock = Lock::acquire(model_path, LOCK_WAIT)?;
    let h = next(model_path, step)?;
    let text = serde_json::to_string_pretty(&h)?;
    files::write(&history_path(model_path), (text + "\n").as_bytes())?;
    Ok(h)
}

/// The history of `model_path` with `step` appended (nothing written). No
/// history file starts a new one; a file that is there but not a history
/// this trueaxis reads (damaged, or another format) is an error — it is
/// never replaced silently.
fn next(model_path: &Path, mut step: Step) -> Result<History> {
    let p = history_path(model_path);
    let mut h = if p.exists() {
        load(model_path).with_context(|| {
            format!(
                "the history beside {} cannot be continued; move {} away (a new history then starts) or choose another -o — nothing was written",
                model_path.display(),
                p.display()
            )
        })?
    } else {
        History {
            format: HISTORY_FORMAT.into(),
            steps: Vec::new(),
        }
    };
    // The step's effects as the file and the model write them; one that
    // does not parse is the same as nothing but itself.
    let specs = |adds: &[String]| -> Vec<Option<EffectSpec>> {
        adds.iter().map(|a| a.parse().ok()).collect()
    };
    let continues = h.steps.last().is_some_and(|last| {
        let new = specs(&step.adds);
        last.seed == step.seed
            && last.data_sha256 == step.data_sha256
            && last.adds.iter().zip(specs(&last.adds)).all(|(a, sa)| {
                step.adds.iter().zip(&new).any(|(b, sb)| {
                    a == b
                        || sa
                            .as_ref()
                            .zip(sb.as_ref())
                            .is_some_and(|(x, y)| x.same_effect(y))
                })
            })
    });
    if !continues {
        h.steps.clear();
    }
    if h.steps.last().is_some_and(|last| last.adds == step.adds) {
        h.steps.pop();
    }
    step.added = match h.steps.last() {
        Some(last) => step
            .adds
            .iter()
            .filter(|a| !last.adds.contains(a))
            .cloned()
            .collect(),
        None => Vec::new(),
    };
    step.step = h.steps.len() + 1;
    h.steps.push(step);
    Ok(h)
}

/// Writes `model` to `model_path` and appends its fit to the history beside
/// it — the one call `fit` and `improve` make. Both or neither: the new
/// history is worked out first (a damaged history file stops here, before
/// anything is written), both files are written in full to temporary files
/// beside them, and only then renamed over the old ones, so a failed write
/// leaves the old model and history as they were (`files::write_all`).
/// One writer at a time: the model's lock (`files::Lock`) is held from
/// reading the history to the last rename, so two fits to one model at
/// once record both their steps, one after the other.
pub fn save_with_model(model_path: &Path, model: &crate::model::ModelFile) -> Result<History> {
    let _lock = Lock::acquire(model_path, LOCK_WAIT)?;
    let h = next(
        model_path,
        Step {
            step: 0,
            seed: model.seed.clone(),
            adds: model.adds.clone(),
            added: Vec::new(),
            terms: model.stats.terms,
            rms_um: model.stats.rms_um.clone(),
            held_out_rms_um: model.stats.held_out_rms_um.clone(),
            data_sha256: model.data.sha256.clone(),
        },
    )?;
    let model_text = model.to_json()?;
    let history_text = serde_json::to_string_pretty(&h)? + "\n";
    files::write_all(&[
        (model_path, model_text.as_bytes()),
        (&history_path(model_path), history_text.as_bytes()),
    ])?;
    Ok(h)
}

/// The history as a text table: one row per step and target.
pub fn table(h: &History) -> String {
    let mut out = String::new();
    out.push_str(&format!(
        "{:>4}  {:<6} {:>10} {:>16}  {}\n",
        "step", "target", "rms µm", "held-out rms µm", "added"
    ));
    for s in &h.steps {
        let added = if s.step == 1 || s.added.is_empty() {
            if s.step == 1 {
                s.spec()
            } else {
                "(refit)".into()
            }
        } else {
            format!("+ {}", s.added.join(" + "))
        };
        for (i, (t, rms)) in s.rms_um.iter().enumerate() {
            let held = s
                .held_out_rms_um
                .get(t)
                .map_or("—".to_string(), |v| format!("{v:.4}"));
            out.push_str(&format!(
                "{:>4}  {:<6} {:>10.4} {:>16}  {}\n",
                if i == 0 {
                    s.step.to_string()
                } else {
                    String::new()
                },
                t,
                rms,
                held,
                if i == 0 { added.as_str() } else { "" }
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(adds: &[&str], rms: f64, sha: &str) -> Step {
        Step {
            step: 0,
            seed: "cubic19".into(),
            adds: adds.iter().map(|s| s.to_string()).collect(),
            added: Vec::new(),
            terms: 19 + adds.len(),
            rms_um: [("ex".to_string(), rms)].into(),
            held_out_rms_um: [("ex".to_string(), rms * 1.1)].into(),
            data_sha256: sha.into(),
        }
    }

    /// A small fitted model (cubic19 on a line).
    fn model() -> crate::model::ModelFile {
        let n = 20;
        let data = crate::data::Dataset {
            source: "line.csv".into(),
            pos_mm: [Some((0..n).map(|i| i as f64 * 10.0).collect()), None, None],
            err_um: [
                Some((0..n).map(|i| Some((i as f64 * 0.3).sin())).collect()),
                None,
                None,
            ],
            ..Default::default()
        };
        crate::fit::fit(&data, "cubic19", &[], &Default::default()).unwrap()
    }

    #[test]
    fn concurrent_saves_to_one_model_lose_no_step() {
        // Every save keeps all effects of any other (the same eight, each
        // in its own order), so each appends a step whatever the order:
        // one writer at a time, 8 threads × 6 saves give 48 steps. Without
        // the lock two saves read the same history and the later rename
        // loses the earlier's step (1 of 40 `fit -o` pairs in the issue).
        let dir =
            std::env::temp_dir().join(format!("trueaxis-history-race-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let m = dir.join("model.json");
        let base = model();
        let effects: Vec<String> = (1..=8)
            .map(|p| format!("periodic:target=ex,axis=x,period_mm={p}"))
            .collect();
        let (threads, saves) = (8, 6);
        std::thread::scope(|s| {
            for t in 0..threads {
                let (m, base, effects) = (&m, &base, &effects);
                s.spawn(move || {
                    for j in 0..saves {
                        let mut mf = base.clone();
                        // A distinct order per save: rotate by t, swap j.
                        let mut adds = effects.clone();
                        adds.rotate_left(t);
                        adds.swap(0, 1 + j);
                        mf.adds = adds;
                        save_with_model(m, &mf).unwrap();
                    }
                });
            }
        });
        let h = load(&m).unwrap();
        assert_eq!(h.steps.len(), threads * saves);
        let saved = crate::model::ModelFile::load(&m).unwrap();
        assert_eq!(saved.adds, h.steps.last().unwrap().adds);
        // Nothing left behind: no temporary file, no lock.
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["model.history.json", "model.json"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn path_of_history_file() {
        assert_eq!(
            history_path(Path::new("out/m.json")),
            PathBuf::from("out/m.history.json")
        );
        assert_eq!(
            history_path(Path::new("m")),
            PathBuf::from("m.history.json")
        );
    }

    #[test]
    fn steps_append_replace_and_restart() {
        let dir = std::env::temp_dir().join(format!("trueaxis-history-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let m = dir.join("model.json");
        let _ = std::fs::remove_file(history_path(&m));
        record_step(&m, step(&[], 4.0, "a")).unwrap();
        record_step(
            &m,
            step(&["periodic:target=ex,axis=x,period_mm=5"], 1.0, "a"),
        )
        .unwrap();
        // The same spec again replaces the last step.
        let h = record_step(
            &m,
            step(&["periodic:target=ex,axis=x,period_mm=5"], 0.9, "a"),
        )
        .unwrap();
        assert_eq!(h.steps.len(), 2);
        assert_eq!(
            h.steps[1].added,
            vec!["periodic:target=ex,axis=x,period_mm=5".to_string()]
        );
        let back = load(&m).unwrap();
        assert_eq!(back.steps.len(), 2);
        assert_eq!(back.steps[1].adds, h.steps[1].adds);
        let t = table(&h);
        assert!(t.contains("+ periodic:target=ex"), "{t}");
        // The same effect with its parameter searched again (diagnose's
        // `replaces`) continues the history; taking an effect away does not.
        let h = record_step(
            &m,
            step(&["periodic:target=ex,axis=x,period_mm=5.08"], 0.5, "a"),
        )
        .unwrap();
        assert_eq!(h.steps.len(), 3);
        let h = record_step(
            &m,
            step(&["periodic:target=ex,axis=y,period_mm=5.08"], 0.5, "a"),
        )
        .unwrap();
        assert_eq!(h.steps.len(), 1);
        // Other data starts again.
        let h = record_step(&m, step(&[], 4.0, "b")).unwrap();
        assert_eq!(h.steps.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
