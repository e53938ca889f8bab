//! `trueaxis import` — validate a measurement file (the contract CSV,
//! Renishaw .rtl, ecmc ISO 230-2 .dat, a RepRapFirmware or Klipper bed
//! map) and write it as the trueaxis CSV (docs/cli.md § Measurement CSV). Bad input
//! exits 1 with `file:line:column: what was expected`; rows left out are
//! listed, never dropped silently.

use std::path::PathBuf;

use anyhow::Result;
use serde_json::json;

use crate::cmd::out::outln;
use trueaxis_engine::data::AXES;
use trueaxis_engine::import;

/// Arguments of `trueaxis import`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The measurement file: `.csv` (or a RepRapFirmware heightmap.csv),
    /// `.rtl` (Renishaw linear laser), `.dat` (ecmc ISO 230-2 run) or `.cfg`
    /// (a Klipper config with a saved bed mesh).
    pub file: PathBuf,
    /// Where to write the contract CSV (omit to only validate).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// The machine axis of a one-axis run: an .rtl file whose USER-TEXT::
    /// has no `Axis:` line, an ecmc .dat file (required there).
    #[arg(long, value_parser = ["x", "y", "z"])]
    pub axis: Option<String>,
    /// The Klipper bed mesh profile to read when the .cfg saves several.
    #[arg(long)]
    pub profile: Option<String>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let axis = self
            .axis
            .as_deref()
            .and_then(|a| AXES.iter().position(|x| *x == a));
        if let Some(out) = &self.output {
            crate::input::refuse_overwrite(&[("the input file", &self.file)], &[("-o", out)])?;
        }
        let data = import::load_with(
            &self.file,
            &import::LoadOptions {
                axis,
                profile: self.profile.clone(),
            },
        )?;
        if let Some(note) = crate::input::encoding_note(&data) {
            eprintln!("{note}");
        }
        if let Some(out) = &self.output {
            trueaxis_engine::files::write_with(out, |w| import::write_csv(&data, w))?;
        }
        let columns = import::column_names(&data);
        let line = |r: usize| data.line.get(r).copied().unwrap_or(r + 1);
        let duplicates: Vec<serde_json::Value> = data
            .duplicate_rows()
            .into_iter()
            .map(|(r, of)| json!({"line": line(r), "of_line": line(of)}))
            .collect();
        if self.json {
            let doc = json!({
                "input": self.file.display().to_string(),
                "output": self.output.as_ref().map(|p| p.display().to_string()),
                "rows": data.len(),
                "columns": columns,
                "aux": data.aux.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
                "metadata": data.metadata.iter().map(|(k, v)| json!({"key": k, "value": v})).collect::<Vec<_>>(),
                "skipped_count": data.skipped.len(),
                "skipped": data.skipped.iter().map(|s| json!({"line": s.line, "reason": s.reason})).collect::<Vec<_>>(),
                "sha256": trueaxis_engine::import::content_hash(&data),
                "duplicate_rows": duplicates,
            });
            outln!("{doc}")?;
        } else {
            outln!(
                "{}: {}, columns {}",
                self.file.display(),
                crate::report::count(data.len(), "row"),
                columns.join(", ")
            )?;
            // Input echoed on the terminal: escaped and cut (import::shown).
            for (k, v) in &data.metadata {
                outln!("  # {}: {}", import::shown(k), import::shown(v))?;
            }
            if !data.aux.is_empty() {
                let names: Vec<String> = data.aux.iter().map(|c| import::shown(&c.name)).collect();
                outln!("  auxiliary channels kept: {}", names.join(", "))?;
            }
            if !data.skipped.is_empty() {
                outln!(
                    "  {} left out:",
                    crate::report::count(data.skipped.len(), "row")
                )?;
                for s in &data.skipped {
                    outln!("    line {}: {}", s.line, s.reason)?;
                }
            }
            if let Some(w) = crate::input::duplicate_warning(&data) {
                outln!("  warning ({}): {}", w.code, w.detail)?;
            }
            if let Some(out) = &self.output {
                outln!("wrote {}", out.display())?;
                outln!("next: {}", crate::workflow::next_for_data(&data, out))?;
            }
        }
        Ok(())
    }
}
