//! `trueaxis compare` — how well does a fitted model match measurements, and
//! where does it fail? Statistics per target, worst regions, residual
//! against every axis and channel (`trueaxis_engine::compare`), an optional HTML
//! report, and a warning when the data are not the data the model was
//! fitted to.

use std::path::PathBuf;

use anyhow::Result;

use crate::cmd::out::{self, outln};
use crate::input;
use crate::workflow::run_compare;
use trueaxis_engine::compare::{self, Comparison};

/// Arguments of `trueaxis compare`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Measurement data (.csv or .rtl).
    pub data: PathBuf,
    /// The fitted model (MODEL.json written by `trueaxis fit`).
    #[arg(long)]
    pub model: PathBuf,
    /// Write an HTML report with SVG plots to this directory (index.html).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The comparison as readable text.
pub fn text(c: &Comparison) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} vs {} ({})",
        c.data,
        c.model,
        crate::report::count(c.rows, "row")
    );
    let _ = writeln!(
        s,
        "{:<6} {:>7} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "target",
        "points",
        "before µm",
        "RMS µm",
        "held-out",
        "max|e| µm",
        "PV µm",
        "p95 µm",
        "better"
    );
    for (name, r) in &c.targets {
        let _ = writeln!(
            s,
            "{:<6} {:>7} {:>10.3} {:>10.3} {:>10} {:>10.3} {:>10.3} {:>10.3} {:>9.1}×",
            name,
            r.after.points,
            r.before.rms_um,
            r.after.rms_um,
            r.held_out_rms_um
                .map_or("—".to_string(), |v| format!("{v:.3}")),
            r.after.max_abs_um,
            r.after.pv_um,
            r.after.p95_abs_um,
            r.improvement
        );
    }
    if !c.worst_regions.is_empty() {
        let _ = writeln!(s, "worst regions:");
        for r in &c.worst_regions {
            let bbox = compare::bbox_text(&r.bbox_mm);
            let _ = writeln!(
                s,
                "  {} {bbox}: RMS {:.3} µm ({:.2}× the overall), {:.0} % of the squared residual",
                r.target,
                r.rms_um,
                r.ratio.unwrap_or(f64::NAN),
                100.0 * r.share.unwrap_or(f64::NAN)
            );
        }
    }
    // What the residual follows beyond position, ranked by the share of
    // the residual each channel explains (docs/cli.md § compare).
    let mut head = false;
    for t in c.rms_um.keys() {
        for p in compare::ranked_channels(c, t, compare::RANK_MIN_SHARE) {
            if !head {
                let _ = writeln!(
                    s,
                    "what the residual follows once position is accounted for (share of the residual explained):"
                );
                head = true;
            }
            let _ = writeln!(
                s,
                "  {} vs {}: {:.0} % (r = {:+.2}), slope {:+.4} {}",
                p.target,
                p.channel,
                100.0 * p.explains_share.unwrap_or(0.0),
                p.partial_corr.unwrap_or(0.0),
                p.partial_slope.unwrap_or(0.0),
                p.slope_unit
            );
        }
    }
    let along: Vec<_> = c
        .channels
        .iter()
        .filter(|p| compare::is_position(&p.channel) && p.corr.is_some_and(|r| r.abs() >= 0.3))
        .collect();
    if !along.is_empty() {
        let _ = writeln!(s, "residual trend along an axis (|r| ≥ 0.3):");
        for p in along {
            let _ = writeln!(
                s,
                "  {} vs {}: r = {:+.2}, slope {:+.4} {}",
                p.target,
                p.channel,
                p.corr.unwrap_or(0.0),
                p.slope_um_per_unit.unwrap_or(0.0),
                p.slope_unit
            );
        }
    }
    for w in &c.warnings {
        let _ = writeln!(s, "warning ({}): {}", w.code, w.detail);
    }
    if let Some(r) = &c.report {
        let _ = writeln!(s, "report: {r}");
    }
    s
}

impl Args {
    pub fn run(self) -> Result<()> {
        let data = input::load_data(&self.data, None)?;
        let model = crate::input::load_model(&self.model)?;
        let sources = crate::report::compare::Sources {
            data: &self.data,
            model: &self.model,
        };
        let c = run_compare(&data, &model, self.report.as_deref(), Some(sources))?;
        if self.json {
            // In the JSON too, but also on stderr so a script's log shows them.
            for w in &c.warnings {
                eprintln!("warning ({}): {}", w.code, w.detail);
            }
            out::json(&c)?;
        } else {
            out::print(&text(&c))?;
            // Which effect is missing: diagnose (issue 28: every command
            // that writes something says what to run next).
            outln!(
                "next: {}",
                crate::report::compare::next_command(
                    &c.model,
                    &self.data,
                    &self.model,
                    self.report.as_deref(),
                    data.is_probed_surface()
                )
            )?;
        }
        Ok(())
    }
}
