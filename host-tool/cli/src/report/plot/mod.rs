//! SVG plot helpers on plotters, shared by every command that draws
//! (`compare`, `diagnose`, `iso230`, `history`): x–y plots (lines, points,
//! steps, shaded bands, marker lines), heat maps of a residual over a
//! measured plane, grouped bar plots, and the "before vs after" pair.
//!
//! Each plot is a plain data struct that renders to an SVG string with
//! `to_svg()`, so callers build plots from numbers without touching plotters,
//! and tests can check the output without a browser. Text uses plotters'
//! built-in font metrics (no `ttf` feature): the SVG names a generic
//! `sans-serif` family and the browser draws it, so no system font library
//! is needed at build or run time. Non-finite values are dropped, never drawn.

use std::fmt::Write as _;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

mod heat;

pub use heat::{diverging, heat_map_pair, HeatMap};

/// Default plot size in pixels (SVG user units).
pub const SIZE: (u32, u32) = (720, 420);

/// Series colours, chosen to stay distinct for colour-blind readers
/// (Okabe–Ito palette).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(230, 159, 0),   // orange
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(0, 0, 0),       // black
];

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Straight segments between points in the given order.
    Line,
    /// A dot per point.
    Points,
    /// Segments and dots.
    LinePoints,
    /// A staircase: each value holds until the next x (history of fits).
    Step,
}

/// One named series of (x, y) points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// The points; non-finite ones are skipped.
    pub points: Vec<(f64, f64)>,
    /// How to draw them.
    pub style: Style,
}

impl Series {
    /// A series drawn as a line.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style: Style::Line,
        }
    }

    /// A series drawn as dots.
    pub fn points(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style: Style::Points,
        }
    }

    /// A series drawn with a given style.
    pub fn styled(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Series {
        Series {
            name: name.into(),
            points,
            style,
        }
    }
}

/// A shaded band between a lower and an upper curve sharing the same x
/// values (ISO 230-2's x̄ ± 2s, a confidence band).
#[derive(Clone, Debug)]
pub struct Band {
    /// Legend text.
    pub name: String,
    /// (x, lower, upper) triples, in x order.
    pub points: Vec<(f64, f64, f64)>,
}

/// An x–y plot: any number of series, optional bands and marker lines.
#[derive(Clone, Debug)]
pub struct XyPlot {
    /// Title above the plot.
    pub title: String,
    /// x-axis description with its unit (`x (mm)`).
    pub x_label: String,
    /// y-axis description with its unit (`residual (µm)`).
    pub y_label: String,
    /// The series, drawn in order, coloured from `PALETTE`.
    pub series: Vec<Series>,
    /// Shaded bands, drawn first (under the series).
    pub bands: Vec<Band>,
    /// Vertical marker lines with a label (a periodogram's peak).
    pub vlines: Vec<(f64, String)>,
    /// Horizontal marker lines with a label (a noise floor, a limit).
    pub hlines: Vec<(f64, String)>,
    /// Size in pixels.
    pub size: (u32, u32),
}

impl XyPlot {
    /// An empty plot with a title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> XyPlot {
        XyPlot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            bands: Vec::new(),
            vlines: Vec::new(),
            hlines: Vec::new(),
            size: SIZE,
        }
    }

    /// Adds a series.
    pub fn with(mut self, s: Series) -> XyPlot {
        self.series.push(s);
        self
    }

    /// Adds a band.
    pub fn with_band(mut self, b: Band) -> XyPlot {
        self.bands.push(b);
        self
    }

    /// Adds a vertical marker line.
    pub fn with_vline(mut self, x: f64, label: impl Into<String>) -> XyPlot {
        self.vlines.push((x, label.into()));
        self
    }

    /// Adds a horizontal marker line.
    pub fn with_hline(mut self, y: f64, label: impl Into<String>) -> XyPlot {
        self.hlines.push((y, label.into()));
        self
    }

    /// The x and y ranges covering every finite value, padded by 5 %.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for s in &self.series {
            for &(x, y) in &s.points {
                if x.is_finite() && y.is_finite() {
                    xs.push(x);
                    ys.push(y);
                }
            }
        }
        for b in &self.bands {
            for &(x, lo, hi) in &b.points {
                if x.is_finite() && lo.is_finite() && hi.is_finite() {
                    xs.push(x);
                    ys.push(lo);
                    ys.push(hi);
                }
            }
        }
        xs.extend(self.vlines.iter().map(|v| v.0).filter(|v| v.is_finite()));
        ys.extend(self.hlines.iter().map(|v| v.0).filter(|v| v.is_finite()));
        (padded_range(&xs, 0.02), padded_range(&ys, 0.08))
    }

    /// Renders the plot as an SVG document.
    pub fn to_svg(&self) -> Result<String> {
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            let ((x0, x1), (y0, y1)) = self.ranges();
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 17))
                .margin(12)
                .x_label_area_size(42)
                .y_label_area_size(64)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            let mut legend = false;
            for (i, b) in self.bands.iter().enumerate() {
                let colour = PALETTE[i % PALETTE.len()];
                let pts: Vec<_> = b
                    .points
                    .iter()
                    .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
                    .collect();
                if pts.len() < 2 {
                    continue;
                }
                let mut poly: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.2)).collect();
                poly.extend(pts.iter().rev().map(|p| (p.0, p.1)));
                chart
                    .draw_series(std::iter::once(Polygon::new(
                        poly,
                        colour.mix(0.18).filled(),
                    )))
                    .map_err(plot_err)?
                    .label(&b.name)
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.mix(0.25).filled())
                    });
                legend |= !b.name.is_empty();
            }
            for (y, label) in &self.hlines {
                let style = ShapeStyle::from(&RGBColor(120, 120, 120)).stroke_width(1);
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0, *y), (x1, *y)],
                        style,
                    )))
                    .map_err(plot_err)?;
                chart
                    .draw_series(std::iter::once(Text::new(
                        label.clone(),
                        (x0 + 0.01 * (x1 - x0), *y),
                        ("sans-serif", 12).into_font().color(&RGBColor(90, 90, 90)),
                    )))
                    .map_err(plot_err)?;
            }
            for (i, s) in self.series.iter().enumerate() {
                let colour = PALETTE[i % PALETTE.len()];
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .collect();
                let line_style = ShapeStyle::from(&colour).stroke_width(2);
                let anno = match s.style {
                    Style::Line => chart
                        .draw_series(LineSeries::new(pts, line_style))
                        .map_err(plot_err)?,
                    Style::Step => {
                        let mut steps = Vec::with_capacity(pts.len() * 2);
                        for (k, p) in pts.iter().enumerate() {
                            if k > 0 {
                                steps.push((p.0, pts[k - 1].1));
                            }
                            steps.push(*p);
                        }
                        chart
                            .draw_series(LineSeries::new(steps, line_style))
                            .map_err(plot_err)?
                    }
                    Style::Points => chart
                        .draw_series(pts.iter().map(|p| Circle::new(*p, 2, colour.filled())))
                        .map_err(plot_err)?,
                    Style::LinePoints => {
                        chart
                            .draw_series(LineSeries::new(pts.clone(), line_style))
                            .map_err(plot_err)?;
                        chart
                            .draw_series(pts.iter().map(|p| Circle::new(*p, 3, colour.filled())))
                            .map_err(plot_err)?
                    }
                };
                if !s.name.is_empty() {
                    anno.label(&s.name).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3))
                    });
                    legend = true;
                }
            }
            for (x, label) in &self.vlines {
                let style = ShapeStyle::from(&RGBColor(200, 0, 0)).stroke_width(1);
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(*x, y0), (*x, y1)],
                        style,
                    )))
                    .map_err(plot_err)?;
                chart
                    .draw_series(std::iter::once(Text::new(
                        label.clone(),
                        (*x, y1 - 0.04 * (y1 - y0)),
                        ("sans-serif", 12).into_font().color(&RGBColor(200, 0, 0)),
                    )))
                    .map_err(plot_err)?;
            }
            if legend {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .background_style(WHITE.mix(0.85))
                    .border_style(RGBColor(180, 180, 180))
                    .label_font(("sans-serif", 12))
                    .draw()
                    .map_err(plot_err)?;
            }
            root.present().map_err(plot_err)?;
        }
        Ok(buf)
    }
}

/// A grouped bar plot: one group of bars per category (a target, a fit
/// step), one bar per named value set (before / after, RMS / held-out).
#[derive(Clone, Debug)]
pub struct BarPlot {
    /// Title above the plot.
    pub title: String,
    /// y-axis description with its unit.
    pub y_label: String,
    /// Category names along x.
    pub categories: Vec<String>,
    /// (legend name, one value per category).
    pub groups: Vec<(String, Vec<f64>)>,
    /// Size in pixels.
    pub size: (u32, u32),
}

impl BarPlot {
    /// Renders the plot as an SVG document.
    pub fn to_svg(&self) -> Result<String> {
        let n = self.categories.len().max(1);
        let g = self.groups.len().max(1);
        let top = self
            .groups
            .iter()
            .flat_map(|(_, v)| v.iter())
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let bottom = self
            .groups
            .iter()
            .flat_map(|(_, v)| v.iter())
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::min);
        let span = (top - bottom).max(1e-12);
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            let cats = self.categories.clone();
            let fmt = move |x: &f64| -> String {
                let i = x.floor();
                // Label only at the centre of each group.
                if (x - i - 0.5).abs() < 1e-6 && i >= 0.0 {
                    cats.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            };
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 17))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(64)
                .build_cartesian_2d(0.0..n as f64, (bottom - 0.02 * span)..(top + 0.12 * span))
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(n * 2 + 1)
                .x_label_formatter(&fmt)
                .y_desc(&self.y_label)
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            let width = 0.8 / g as f64;
            for (k, (name, values)) in self.groups.iter().enumerate() {
                let colour = PALETTE[k % PALETTE.len()];
                let bars = values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite())
                    .map(move |(i, v)| {
                        let x0 = i as f64 + 0.1 + k as f64 * width;
                        Rectangle::new([(x0, 0.0), (x0 + width * 0.92, *v)], colour.filled())
                    });
                chart
                    .draw_series(bars)
                    .map_err(plot_err)?
                    .label(name)
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 14, y + 5)], colour.filled())
                    });
                // The value on top of each bar: a report is read for numbers.
                let labels = values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite())
                    .map(move |(i, v)| {
                        let x0 = i as f64 + 0.1 + k as f64 * width;
                        Text::new(
                            format_value(*v),
                            (x0, v.max(0.0) + 0.04 * span),
                            ("sans-serif", 11).into_font(),
                        )
                    });
                chart.draw_series(labels).map_err(plot_err)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .label_font(("sans-serif", 12))
                .draw()
                .map_err(plot_err)?;
            root.present().map_err(plot_err)?;
        }
        Ok(buf)
    }
}

/// "Before vs after" as a grouped bar plot: per category (target), the
/// value before (raw error) and after (residual) compensation.
pub fn before_after(
    title: impl Into<String>,
    y_label: impl Into<String>,
    categories: &[String],
    before: &[f64],
    after: &[f64],
) -> BarPlot {
    BarPlot {
        title: title.into(),
        y_label: y_label.into(),
        categories: categories.to_vec(),
        groups: vec![
            ("before (raw error)".into(), before.to_vec()),
            ("after (residual)".into(), after.to_vec()),
        ],
        size: SIZE,
    }
}

/// A value with 3 significant digits for labels (`4.35`, `0.0123`, `1250`).
pub fn format_value(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
    let mut s = String::new();
    let _ = write!(s, "{v:.digits$}");
    s
}

fn plot_err<E: std::error::Error + Send + Sync + 'static>(
    e: plotters::drawing::DrawingAreaErrorKind<E>,
) -> anyhow::Error {
    anyhow!("drawing a plot: {e}")
}

/// (lo, hi) of the values, padded by `pad` of the span; a degenerate or
/// empty range becomes a unit-wide one so plotters always gets a valid axis.
fn padded_range(v: &[f64], pad: f64) -> (f64, f64) {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(1.0) {
        let w = 0.5 * lo.abs().max(1.0);
        return (lo - w, hi + w);
    }
    (lo - pad * span, hi + pad * span)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xy_plot_renders_titles_and_skips_non_finite() {
        let svg = XyPlot::new("residual along x", "x (mm)", "ex (µm)")
            .with(Series::line(
                "ex",
                vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, -1.0)],
            ))
            .with(Series::points("measured", vec![(0.5, 0.2)]))
            .with_vline(1.0, "peak")
            .with_band(Band {
                name: "±2s".into(),
                points: vec![(0.0, -1.0, 1.0), (2.0, -2.0, 2.0)],
            })
            .to_svg()
            .unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        assert!(svg.contains("residual along x"));
        assert!(svg.contains("x (mm)"));
        assert!(!svg.contains("NaN"));
    }

    #[test]
    fn empty_plot_still_renders() {
        let svg = XyPlot::new("nothing", "x", "y").to_svg().unwrap();
        assert!(svg.contains("nothing"));
    }

    #[test]
    fn heat_map_bins_points_onto_grid() {
        let mut pts = Vec::new();
        for iy in 0..3 {
            for ix in 0..4 {
                // Two readings per cell (forward and backward) with jitter.
                let (x, y) = (50.0 * f64::from(ix), 50.0 * f64::from(iy));
                pts.push((x + 0.01, y, 1.0));
                pts.push((x - 0.01, y, 3.0));
            }
        }
        pts.pop(); // one reading missing: the cell keeps the other one
        let m = HeatMap::from_points("ex", "x (mm)", "y (mm)", "µm", &pts, 1.0);
        assert_eq!(m.x.len(), 4);
        assert_eq!(m.y.len(), 3);
        assert_eq!(m.values[0], Some(2.0));
        assert_eq!(m.values[11], Some(1.0));
        assert!(m.to_svg().unwrap().contains("µm"));
    }

    #[test]
    fn heat_map_marks_gaps() {
        let pts = [(0.0, 0.0, 1.0), (1.0, 1.0, -1.0)];
        let m = HeatMap::from_points("t", "x", "y", "µm", &pts, 0.1);
        assert_eq!(m.values, vec![Some(1.0), None, None, Some(-1.0)]);
        let pair = heat_map_pair(&m, &m).unwrap();
        assert!(pair.starts_with("<svg"));
    }

    #[test]
    fn bars_and_labels() {
        let p = before_after(
            "RMS before and after",
            "RMS (µm)",
            &["ex".to_string(), "ey".to_string()],
            &[4.35, 2.0],
            &[0.15, 0.1],
        );
        let svg = p.to_svg().unwrap();
        assert!(svg.contains("4.35"));
        assert!(svg.contains("ex"));
        assert!(svg.contains("after (residual)"));
    }

    #[test]
    fn diverging_scale_ends() {
        assert_eq!(diverging(0.0), RGBColor(255, 255, 255));
        assert_eq!(diverging(1.0), RGBColor(178, 24, 43));
        assert_eq!(diverging(-5.0), RGBColor(33, 102, 172));
        assert_eq!(diverging(f64::NAN), RGBColor(255, 255, 255));
    }

    #[test]
    fn value_format() {
        assert_eq!(format_value(4.3512), "4.35");
        assert_eq!(format_value(0.012345), "0.0123");
        assert_eq!(format_value(1250.0), "1250");
    }
}
