//! The `history --report DIR` page: the table of steps and the plot of the
//! error falling (RMS and held-out RMS per target against the step); also
//! drawn on `diagnose --report` for a model that has a history.

use std::path::PathBuf;

use anyhow::Result;

use trueaxis_engine::history::History;

use crate::report::plot::{Series, XyPlot};
use crate::report::Page;

/// The plot of RMS and held-out RMS per target against the step.
pub fn plot(h: &History) -> XyPlot {
    let mut p = XyPlot::new("The error falling, step by step", "step", "µm");
    let targets: std::collections::BTreeSet<&String> =
        h.steps.iter().flat_map(|s| s.rms_um.keys()).collect();
    for t in targets {
        let rms: Vec<(f64, f64)> = h
            .steps
            .iter()
            .filter_map(|s| s.rms_um.get(t).map(|v| (s.step as f64, *v)))
            .collect();
        let held: Vec<(f64, f64)> = h
            .steps
            .iter()
            .filter_map(|s| s.held_out_rms_um.get(t).map(|v| (s.step as f64, *v)))
            .collect();
        p = p
            .with(Series::line(format!("{t} rms"), rms))
            .with(Series::line(format!("{t} held-out rms"), held));
    }
    p
}

/// Writes `DIR/index.html` with the table and the plot.
pub fn write_report(h: &History, name: &str, dir: &std::path::Path) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis history — {name}"));
    page.heading("History");
    add_to_page(&mut page, h)?;
    page.write(dir)
}

/// The history's table (one row per step and target) and the plot of the
/// error falling (`history.svg`) on `page`: this command's report, and
/// `diagnose --report` on a model that has a history.
pub fn add_to_page(page: &mut Page, h: &History) -> Result<()> {
    let rows = h
        .steps
        .iter()
        .flat_map(|s| {
            s.rms_um.iter().map(move |(t, r)| {
                vec![
                    s.step.to_string(),
                    t.clone(),
                    format!("{r:.4}"),
                    s.held_out_rms_um
                        .get(t)
                        .map_or("—".into(), |v| format!("{v:.4}")),
                    if s.added.is_empty() {
                        s.spec()
                    } else {
                        format!("+ {}", s.added.join(" + "))
                    },
                ]
            })
        })
        .collect();
    page.table(
        &["step", "target", "rms µm", "held-out rms µm", "added"],
        rows,
    );
    page.figure(
        "history",
        "RMS and block-held-out RMS per target after each fit",
        plot(h).to_svg()?,
    );
    Ok(())
}
