//! The `iso230 --report DIR` plot: x̄↑ and x̄↓ against the target position
//! with their ±2s bands, as SVG.

use std::path::Path;

use anyhow::Result;

use trueaxis_engine::iso230::{max, min, Iso230, TargetStats};

/// Writes an SVG plot of x̄↑ and x̄↓ against position with the ±2s
/// bands to `path`. Text is plain SVG `<text>` (plotters without a font
/// library), so the file renders in any browser with no network.
pub fn plot_svg(res: &Iso230, path: &Path) -> Result<()> {
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
    draw().map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    drop(root);
    // Scales to the window like every report figure (viewBox, no width).
    std::fs::write(path, crate::report::plot::responsive(buf))
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}
