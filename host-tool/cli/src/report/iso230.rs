//! The `iso230 --report DIR` page and plot: a verdict card (accuracy A,
//! what compensation can remove — the systematic E, the reversal B — and
//! what it cannot, the repeatability R; the next command), then x̄↑ and x̄↓
//! against the target position with their ±2s bands, as SVG, and the
//! per-target table.

use std::path::{Path, PathBuf};

use anyhow::Result;

use trueaxis_engine::iso230::{max, min, Iso230, TargetStats};

use crate::report::plot::format_value;
use crate::report::{Page, Tone, Verdict};

/// ISO 230-2's runs per direction (5); fewer gives a wide ±2s.
const ISO_RUNS: usize = 5;

/// The page's verdict: A, and how it splits into what a model removes (E,
/// with B) and what it cannot (R); the `fit` command to run next.
pub fn verdict(res: &Iso230, data_path: &str) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    let ax = &res.axis;
    // The unidirectional repeatability is the floor: the bidirectional R
    // includes the reversal, which compensation does remove.
    let r_uni = res.r_up_um.max(res.r_down_um);
    let big_reversal = res.b_um.abs() >= 0.3 * res.e_um && res.b_um.abs() > 0.5 * r_uni;
    let mut details = vec![
        format!(
            "Systematic deviation E = {} (the mean paths of both directions): a fitted model removes it.",
            um(res.e_um)
        ),
        format!(
            "Reversal B = {} (mean {}): {}",
            um(res.b_um),
            um(res.b_mean_um),
            if big_reversal {
                "a large share of E — the model needs a reversal (backlash) term."
            } else {
                "small against E."
            }
        ),
        format!(
            "Repeatability in one direction R↑ = {}, R↓ = {}: the scatter from run to run; no compensation lowers it — after compensation A cannot fall much below it. (The bidirectional R = {} includes the reversal.)",
            um(res.r_up_um),
            um(res.r_down_um),
            um(res.r_um)
        ),
    ];
    details.push(format!(
        "{} targets, {} run(s) per direction.",
        res.targets, res.runs
    ));
    let warnings = if res.runs < ISO_RUNS {
        vec![format!(
            "{} run(s) per direction, ISO 230-2 asks for {ISO_RUNS}: s and the ±2s bands are uncertain",
            res.runs
        )]
    } else {
        Vec::new()
    };
    let removable = res.e_um > 1.5 * r_uni;
    let mut next = format!("trueaxis fit {data_path} --model cubic19");
    if big_reversal {
        next.push_str(&format!(" --add 'reversal:target=e{ax},axis={ax}'"));
    }
    next.push_str(" -o model.json");
    Verdict {
        headline: format!(
            "Axis {ax}: accuracy A = {}; compensation can remove most of the systematic E = {}{}, not the repeatability (one direction, up to {}).",
            um(res.a_um),
            um(res.e_um),
            if big_reversal {
                format!(" (reversal B = {})", um(res.b_um))
            } else {
                String::new()
            },
            um(r_uni)
        ),
        details: std::mem::take(&mut details),
        warnings,
        next: Some(next),
        tone: if removable { Tone::Action } else { Tone::Good },
    }
}

/// Writes `DIR/index.html` (verdict, plot, per-target table) and
/// `DIR/iso230_<axis>.svg`; returns the page's path.
pub fn write_page(res: &Iso230, data_path: &str, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new(format!(
        "trueaxis iso230 — axis {} of {data_path}",
        res.axis
    ));
    page.verdict(verdict(res, data_path));
    page.heading("Mean deviation by direction");
    page.figure(
        format!("iso230_{}", res.axis),
        "x̄↑ and x̄↓ (mean deviation approaching from below and from above) at each target, with ±2s bands.",
        svg(res)?,
    );
    let f = |v: f64| format!("{v:.3}");
    let rows = res
        .per_target
        .iter()
        .map(|t| {
            vec![
                f(t.pos_mm),
                t.n_up.to_string(),
                t.n_down.to_string(),
                f(t.mean_up_um),
                f(t.mean_down_um),
                f(t.s_up_um),
                f(t.s_down_um),
                f(t.b_um),
                f(t.r_um),
            ]
        })
        .collect();
    page.table(
        &[
            "target (mm)",
            "n↑",
            "n↓",
            "x̄↑ (µm)",
            "x̄↓ (µm)",
            "s↑ (µm)",
            "s↓ (µm)",
            "B (µm)",
            "R (µm)",
        ],
        rows,
    );
    page.write(dir)
}

/// Writes an SVG plot of x̄↑ and x̄↓ against position with the ±2s
/// bands to `path`. Text is plain SVG `<text>` (plotters without a font
/// library), so the file renders in any browser with no network.
pub fn plot_svg(res: &Iso230, path: &Path) -> Result<()> {
    trueaxis_engine::files::write(path, svg(res)?.as_bytes())
}

/// The plot of [`plot_svg`] as an SVG document.
pub fn svg(res: &Iso230) -> Result<String> {
    use plotters::prelude::*;
    let t = &res.per_target;
    let lo = min(t
        .iter()
        .map(|s| (s.mean_up_um - 2.0 * s.s_up_um).min(s.mean_down_um - 2.0 * s.s_down_um)));
    let hi = max(t
        .iter()
        .map(|s| (s.mean_up_um + 2.0 * s.s_up_um).max(s.mean_down_um + 2.0 * s.s_down_um)));
    let pad = ((hi - lo) * 0.1).max(0.05);
    let (x0, x1) = (t[0].pos_mm, t[t.len() - 1].pos_mm);
    let xpad = ((x1 - x0) * 0.03).max(1.0);
    let mut buf = String::new();
    let root = SVGBackend::with_string(&mut buf, (900, 520)).into_drawing_area();
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "ISO 230-2 axis {}: A = {:.2} µm, E = {:.2} µm, R = {:.2} µm, B = {:.2} µm",
                    res.axis, res.a_um, res.e_um, res.r_um, res.b_um
                ),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((x0 - xpad)..(x1 + xpad), (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc(format!("target position along {} (mm)", res.axis))
            .y_desc("deviation (µm)")
            .draw()?;
        let up = BLUE;
        let down = RED;
        for (color, f, label) in [
            (
                up,
                (|s: &TargetStats| (s.mean_up_um, s.s_up_um)) as fn(&TargetStats) -> (f64, f64),
                "x̄↑",
            ),
            (down, |s: &TargetStats| (s.mean_down_um, s.s_down_um), "x̄↓"),
        ] {
            let band: Vec<(f64, f64)> = t
                .iter()
                .map(|s| (s.pos_mm, f(s).0 + 2.0 * f(s).1))
                .chain(t.iter().rev().map(|s| (s.pos_mm, f(s).0 - 2.0 * f(s).1)))
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(
                band,
                color.mix(0.15).filled(),
            )))?;
            chart
                .draw_series(LineSeries::new(
                    t.iter().map(|s| (s.pos_mm, f(s).0)),
                    color.stroke_width(2),
                ))?
                .label(format!("{label} ± 2s"))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart.draw_series(
                t.iter()
                    .map(|s| Circle::new((s.pos_mm, f(s).0), 3, color.filled())),
            )?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing the ISO 230-2 plot: {e}"))?;
    drop(root);
    // Scales to the window like every report figure (viewBox, no width).
    Ok(crate::report::plot::responsive(buf))
}
