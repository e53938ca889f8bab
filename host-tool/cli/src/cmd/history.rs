//! `trueaxis history MODEL.json [--json] [--report DIR]`: how the error fell,
//! fit by fit — the steps `fit` appended to `MODEL.history.json` (see
//! `trueaxis_engine::history`), as a table, one JSON document, or an HTML page with
//! the RMS and held-out RMS per target plotted against the step.

use std::path::PathBuf;

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

impl Args {
    pub fn run(self) -> Result<()> {
        let h = history::load(&self.model)?;
        if let Some(dir) = &self.report {
            // The data file the model was fitted to, for the next command
            // the page proposes (a placeholder when the model is unreadable:
            // the history is still worth its page).
            let data = ModelFile::load(&self.model)
                .map(|m| m.data.source)
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
