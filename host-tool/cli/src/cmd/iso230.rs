//! `trueaxis iso230` — ISO 230-2 evaluation of bidirectional positioning
//! runs (docs/cli.md): the summary values, the per-target table, and with
//! `--report DIR` an SVG plot of x̄↑ and x̄↓ with their ±2s bands.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::cmd::out::outln;
use crate::input;
use trueaxis_engine::data::AXES;
use trueaxis_engine::iso230;

/// Arguments of `trueaxis iso230`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Measurement data (.csv or .rtl) with bidirectional runs along one axis.
    pub data: PathBuf,
    /// The axis to evaluate (default: the only axis with position, error and
    /// direction columns); for an .rtl file, the axis of its runs (overrides
    /// the file's `Axis:` line, needed when it has none).
    #[arg(long, value_parser = ["x", "y", "z"])]
    pub axis: Option<String>,
    /// Directory for the plot (`iso230_<axis>.svg`); created if missing.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

impl Args {
    pub fn run(self) -> Result<()> {
        let named = match self.axis.as_deref() {
            Some(a) => Some(AXES.iter().position(|x| *x == a).context("axis")?),
            None => None,
        };
        // `--axis` also tells an .rtl file's reader the axis (its
        // USER-TEXT:: may have no `Axis:` line, or name another one).
        let data = input::load_data(&self.data, named)?;
        let axis = match named {
            Some(a) => a,
            None => iso230::default_axis(&data)?,
        };
        let res = iso230::evaluate(&data, axis)?;
        let mut plot = None;
        let mut page = None;
        if let Some(dir) = &self.report {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            // The page writes the plot beside it as iso230_<axis>.svg.
            page = Some(crate::report::iso230::write_page(
                &res,
                &data,
                &self.data.display().to_string(),
                dir,
            )?);
            plot = Some(dir.join(format!("iso230_{}.svg", res.axis)));
        }
        if self.json {
            let mut v = serde_json::to_value(&res)?;
            if let (Some(p), Some(obj)) = (&plot, v.as_object_mut()) {
                obj.insert("plot".into(), p.display().to_string().into());
            }
            if let (Some(p), Some(obj)) = (&page, v.as_object_mut()) {
                obj.insert("report".into(), p.display().to_string().into());
            }
            outln!("{v}")?;
        } else {
            crate::cmd::out::print(&res.table())?;
            if let Some(p) = plot {
                outln!("\nplot: {}", p.display())?;
            }
            if let Some(p) = page {
                outln!("report: {}", p.display())?;
            }
        }
        Ok(())
    }
}
