//! `trueaxis history MODEL.json [--json] [--report DIR]`: how the error fell,
//! fit by fit — the steps `fit` appended to `MODEL.history.json` (see
//! `trueaxis_engine::history`), as a table, one JSON document, or an HTML page with
//! the RMS and held-out RMS per target plotted against the step.

use std::path::{Path, PathBuf};

use anyhow::Result;

use trueaxis_engine::history;

use crate::cmd::out::outln;
use crate::report::history::write_report;
use trueaxis_engine::model::ModelFile;

/// Arguments of `trueaxis history`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The model file whose history to show (its `MODEL.history.json` beside it is read).
    pub model: PathBuf,
    /// Write the table and a plot of the error falling into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The data file a model was fitted to, as a path that reads from where
/// `history` runs: the model stores the path as typed at fit time, relative
/// to where `fit` ran; run from elsewhere (`history run1/model.json`), the
/// file is looked for beside the model as well. The stored path when
/// neither exists (or the source is no file, `simulate:…`).
pub fn data_path_from_here(source: &str, model: &Path) -> String {
    let stored = Path::new(source);
    if stored.is_file() || source.starts_with("simulate:") {
        return source.to_string();
    }
    let dir = model.parent().unwrap_or(Path::new(""));
    let beside = [
        (!stored.is_absolute()).then(|| dir.join(stored)),
        stored.file_name().map(|f| dir.join(f)),
    ];
    beside
        .into_iter()
        .flatten()
        .find(|p| p.is_file())
        .map_or_else(|| source.to_string(), |p| p.display().to_string())
}

impl Args {
    pub fn run(self) -> Result<()> {
        let h = history::load(&self.model)?;
        if let Some(dir) = &self.report {
            // The data file the model was fitted to, for the next command
            // the page proposes (a placeholder when the model is unreadable:
            // the history is still worth its page).
            let data = ModelFile::load(&self.model)
                .map(|m| data_path_from_here(&m.data.source, &self.model))
                .unwrap_or_else(|_| "DATA.csv".into());
            let index = write_report(
                &h,
                &self.model.display().to_string(),
                &data,
                dir,
                &Default::default(),
            )?;
            if !self.json {
                outln!("report: {}", index.display())?;
            }
        }
        if self.json {
            outln!("{}", serde_json::to_string_pretty(&h)?)?;
        } else {
            outln!("{}: {} step(s)", self.model.display(), h.steps.len())?;
            crate::cmd::out::print(&history::table(&h))?;
        }
        Ok(())
    }
}
