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
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub mod decimate;
pub(crate) mod heat;

pub use decimate::Reduction;
pub use heat::{diverging, heat_map_pair, HeatMap, MapPair};

/// Default plot size in pixels (SVG user units).
pub const SIZE: (u32, u32) = (720, 420);

/// The width a plot is drawn again at for a phone: a 390 px window less
/// the page's margins. Drawn at that width its text is at its own size; a
/// 720 px drawing scaled into a phone had 5 px text (issue 28).
pub const PHONE_WIDTH: u32 = 360;
/// Drawings at most this wide need no phone drawing.
pub const PHONE_MAX: u32 = 480;
/// Below this width a plot's legend goes under the plot, not beside it.
pub const LEGEND_BELOW: u32 = 500;

/// A plot drawn at its own size and, when that is wider than a phone,
/// again at [`PHONE_WIDTH`] (the page shows that one in a narrow window:
/// `report::Figure::plot`).
pub trait Drawing {
    /// The SVG at the plot's own size.
    fn svg(&self) -> Result<String>;
    /// The SVG for a phone; `None` when [`Drawing::svg`] is narrow enough.
    fn phone_svg(&self) -> Result<Option<String>>;
}

/// A plot's size for a phone: [`PHONE_WIDTH`] wide, a little less tall
/// than designed but never flatter than 3 : 4; `None` when it is narrow
/// enough already.
pub fn phone_size(size: (u32, u32)) -> Option<(u32, u32)> {
    (size.0 > PHONE_MAX).then(|| (PHONE_WIDTH, (size.1 * 4 / 5).max(PHONE_WIDTH * 3 / 4)))
}

impl Drawing for XyPlot {
    fn svg(&self) -> Result<String> {
        self.to_svg()
    }
    fn phone_svg(&self) -> Result<Option<String>> {
        phone_size(self.size)
            .map(|size| {
                XyPlot {
                    size,
                    ..self.clone()
                }
                .to_svg()
            })
            .transpose()
    }
}

impl Drawing for BarPlot {
    fn svg(&self) -> Result<String> {
        self.to_svg()
    }
    fn phone_svg(&self) -> Result<Option<String>> {
        phone_size(self.size)
            .map(|size| {
                BarPlot {
                    size,
                    ..self.clone()
                }
                .to_svg()
            })
            .transpose()
    }
}

impl Drawing for HeatMap {
    fn svg(&self) -> Result<String> {
        self.to_svg()
    }
    fn phone_svg(&self) -> Result<Option<String>> {
        (self.fitted_size().0 > PHONE_MAX)
            .then(|| {
                HeatMap {
                    size: (PHONE_WIDTH, self.size.1),
                    ..self.clone()
                }
                .to_svg()
            })
            .transpose()
    }
}

/// Series colours, chosen to stay distinct for colour-blind readers
/// (Okabe–Ito palette). The first three are the targets' and the next two
/// the approach directions' ([`TARGET_COLOURS`], [`DIRECTION_COLOURS`]):
/// a series that is neither takes its colour from [`OTHER_COLOURS`], so a
/// green cloud is ez on every plot of every page (issue 28: ey was
/// vermillion on one plot and green on the next).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue: ex
    RGBColor(213, 94, 0),    // vermillion: ey
    RGBColor(0, 158, 115),   // bluish green: ez
    RGBColor(230, 159, 0),   // orange: approach from below (dir +1)
    RGBColor(86, 180, 233),  // sky blue: approach from above (dir −1)
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(0, 0, 0),       // black
];

/// A marker that is a finding (a periodogram peak above its false-alarm
/// level).
pub const FINDING: RGBColor = RGBColor(200, 0, 0);
/// A marker or level that is no finding (a peak below the false-alarm
/// level, the level itself).
pub const NO_FINDING: RGBColor = RGBColor(110, 110, 110);

/// ex, ey, ez: one colour each on every plot and page.
pub const TARGET_COLOURS: [RGBColor; 3] = [PALETTE[0], PALETTE[1], PALETTE[2]];
/// Approach direction +1 and −1.
pub const DIRECTION_COLOURS: [RGBColor; 2] = [PALETTE[3], PALETTE[4]];
/// Series that are no target and no direction (a fit, a reference line,
/// the on-machine pages' profiles), in turn.
pub const OTHER_COLOURS: [RGBColor; 4] = [
    RGBColor(0, 0, 0),       // black
    PALETTE[5],              // reddish purple
    RGBColor(120, 120, 120), // grey
    RGBColor(170, 140, 0),   // dark yellow
];

/// The target a series is of, by its name's first word (`ex`, `ex model`,
/// `ex RMS`, `ez held-out`): 0, 1, 2 for ex, ey, ez.
pub fn target_of(name: &str) -> Option<usize> {
    let first = name.split([' ', '_', ':']).next()?;
    ["ex", "ey", "ez"].iter().position(|t| *t == first)
}

/// The approach direction a series is of (`dir_x = +1` → 0, `… −1` → 1).
fn direction_of(name: &str) -> Option<usize> {
    let t = name.trim_end();
    if !t.starts_with("dir") {
        return None;
    }
    if t.ends_with("+1") {
        Some(0)
    } else if t.ends_with("-1") || t.ends_with("−1") {
        Some(1)
    } else {
        None
    }
}

/// The colour of target `t` (0 ex, 1 ey, 2 ez).
pub fn target_colour(t: usize) -> RGBColor {
    TARGET_COLOURS[t % 3]
}

/// A colour `f` of the way to black (a model line over its measured dots).
pub fn darker(c: RGBColor, f: f64) -> RGBColor {
    let d = |v: u8| (f64::from(v) * (1.0 - f)).round() as u8;
    RGBColor(d(c.0), d(c.1), d(c.2))
}

/// A colour `f` of the way to white (a "before" bar beside its "after").
pub fn lighter(c: RGBColor, f: f64) -> RGBColor {
    let l = |v: u8| (f64::from(v) + (255.0 - f64::from(v)) * f).round() as u8;
    RGBColor(l(c.0), l(c.1), l(c.2))
}

/// A band's colour: its target's (by name), else grey.
fn band_colour(b: &Band) -> RGBColor {
    target_of(&b.name).map_or(RGBColor(120, 120, 120), target_colour)
}

/// The colours of a plot's series in order: a given colour, else the
/// target's (a model darker than its measurement), else the direction's,
/// else the next of [`OTHER_COLOURS`].
fn series_colours(series: &[Series]) -> Vec<RGBColor> {
    let mut other = 0;
    series
        .iter()
        .map(|s| {
            if let Some(c) = s.colour {
                return c;
            }
            if let Some(t) = target_of(&s.name) {
                let c = target_colour(t);
                // A model, a fit or a mean over its measurement: darker.
                return if ["model", "mean", "fit"].iter().any(|w| s.name.contains(w)) {
                    darker(c, 0.45)
                } else {
                    c
                };
            }
            if let Some(d) = direction_of(&s.name) {
                return DIRECTION_COLOURS[d];
            }
            let c = OTHER_COLOURS[other % OTHER_COLOURS.len()];
            other += 1;
            c
        })
        .collect()
}

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
    /// A dashed line with dots (a held-out figure beside its in-sample
    /// one, in the same colour).
    DashedPoints,
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
    /// Its colour; None: by its name ([`series_colours`]).
    pub colour: Option<RGBColor>,
}

impl Series {
    /// A series drawn as a line.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style: Style::Line,
            colour: None,
        }
    }

    /// A series drawn as dots.
    pub fn points(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style: Style::Points,
            colour: None,
        }
    }

    /// A series drawn with a given style.
    pub fn styled(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Series {
        Series {
            name: name.into(),
            points,
            style,
            colour: None,
        }
    }

    /// The series in a given colour (a target's periodogram, say, whose
    /// name does not start with the target).
    pub fn coloured(mut self, c: RGBColor) -> Series {
        self.colour = Some(c);
        self
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
    /// Vertical marker lines with a label and colour (a periodogram's
    /// peak: [`FINDING`] red, [`NO_FINDING`] grey).
    pub vlines: Vec<(f64, String, RGBColor)>,
    /// Horizontal marker lines with a label (a noise floor, a limit).
    pub hlines: Vec<(f64, String)>,
    /// Horizontal dashed lines with a label, drawn in a colour
    /// `(y, label, colour)` (a target's noise floor in the target's).
    pub dashed: Vec<(f64, String, RGBColor)>,
    /// Text labels at data coordinates (what each fit step added).
    pub notes: Vec<(f64, f64, String)>,
    /// Grey dotted vertical marks with a label at the foot (the sampling
    /// comb of a plan on a periodogram).
    pub vmarks: Vec<(f64, String)>,
    /// How the x axis is ticked.
    pub x_ticks: Ticks,
    /// The y axis on a log10 scale ([`XyPlot::with_log_y`]).
    pub log_y: bool,
    /// A fixed y range (small multiples compared by height share one:
    /// [`XyPlot::with_y_range`]); None: the data's, padded.
    pub y_range: Option<(f64, f64)>,
    /// Size in pixels.
    pub size: (u32, u32),
}

/// How an axis is ticked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ticks {
    /// plotters' own round numbers.
    Auto,
    /// Whole numbers only (fit steps): the range is widened by ½ on both
    /// sides and nothing between two integers gets a label.
    Integer,
    /// A categorical ±1 axis (`dir_x`): ticks at −1 and +1 only.
    Direction,
    /// A frequency axis (cycles/mm) labelled with the period 1/f in mm at
    /// each tick: a user knows a lead as "5 mm", not "0.2 cycles/mm".
    Period,
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
            dashed: Vec::new(),
            notes: Vec::new(),
            vmarks: Vec::new(),
            x_ticks: Ticks::Auto,
            log_y: false,
            y_range: None,
            size: SIZE,
        }
    }

    /// Draws the y axis from `lo` to `hi` whatever the data (plots compared
    /// side by side: issue 28's generatrices each had a scale of their own,
    /// so a 2 µm wave looked as tall as a 20 µm one).
    pub fn with_y_range(mut self, lo: f64, hi: f64) -> XyPlot {
        if lo.is_finite() && hi.is_finite() && hi > lo {
            self.y_range = Some((lo, hi));
        }
        self
    }

    /// Draws the y axis on a log10 scale, ticked at 1, 2 and 5 × 10ᵏ in the
    /// data's unit: an error falling over decades stays readable at every
    /// step. Values ≤ 0 have no place on it and are left out.
    pub fn with_log_y(mut self) -> XyPlot {
        self.log_y = true;
        self
    }

    /// The plot with every y replaced by its log10 (what
    /// [`XyPlot::with_log_y`] draws on a linear chart); values ≤ 0 dropped.
    fn log10_of_y(&self) -> XyPlot {
        let lg = |y: f64| if y > 0.0 { y.log10() } else { f64::NAN };
        let mut p = self.clone();
        for s in &mut p.series {
            s.points = s
                .points
                .iter()
                .map(|&(x, y)| (x, lg(y)))
                .filter(|q| q.1.is_finite())
                .collect();
        }
        for b in &mut p.bands {
            b.points = b
                .points
                .iter()
                .map(|&(x, lo, hi)| (x, lg(lo), lg(hi)))
                .filter(|q| q.1.is_finite() && q.2.is_finite())
                .collect();
        }
        p.hlines.retain(|h| h.0 > 0.0);
        p.hlines.iter_mut().for_each(|h| h.0 = h.0.log10());
        p.dashed.retain(|d| d.0 > 0.0);
        p.dashed.iter_mut().for_each(|d| d.0 = d.0.log10());
        p.notes.retain(|n| n.1 > 0.0);
        p.notes.iter_mut().for_each(|n| n.1 = n.1.log10());
        p
    }

    /// Sets how the x axis is ticked.
    pub fn with_x_ticks(mut self, t: Ticks) -> XyPlot {
        self.x_ticks = t;
        self
    }

    /// Adds a dashed horizontal line in `colour`.
    pub fn with_dashed(mut self, y: f64, label: impl Into<String>, colour: RGBColor) -> XyPlot {
        self.dashed.push((y, label.into(), colour));
        self
    }

    /// Adds a text label at (x, y) in data coordinates.
    pub fn with_note(mut self, x: f64, y: f64, text: impl Into<String>) -> XyPlot {
        self.notes.push((x, y, text.into()));
        self
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

    /// Adds a vertical marker line in [`FINDING`] red.
    pub fn with_vline(self, x: f64, label: impl Into<String>) -> XyPlot {
        self.with_vline_coloured(x, label, FINDING)
    }

    /// Adds a vertical marker line in a colour.
    pub fn with_vline_coloured(
        mut self,
        x: f64,
        label: impl Into<String>,
        colour: RGBColor,
    ) -> XyPlot {
        self.vlines.push((x, label.into(), colour));
        self
    }

    /// Adds a grey dotted vertical mark, labelled at its foot.
    pub fn with_vmark(mut self, x: f64, label: impl Into<String>) -> XyPlot {
        self.vmarks.push((x, label.into()));
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
        xs.extend(self.vmarks.iter().map(|v| v.0).filter(|v| v.is_finite()));
        ys.extend(self.hlines.iter().map(|v| v.0).filter(|v| v.is_finite()));
        ys.extend(self.dashed.iter().map(|v| v.0).filter(|v| v.is_finite()));
        ys.extend(self.notes.iter().map(|v| v.1).filter(|v| v.is_finite()));
        // A note stands where it is put, even on a plot with no data (a
        // rigid21 function that cannot be known: its travel, a label).
        xs.extend(self.notes.iter().map(|v| v.0).filter(|v| v.is_finite()));
        let x = match self.x_ticks {
            Ticks::Auto | Ticks::Period => padded_range(&xs, 0.02),
            // Half a step beyond the first and last: a single fit is a
            // point in the middle, not an empty axis from 1.0 to 1.0.
            Ticks::Integer => {
                let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                if lo.is_finite() {
                    (lo.floor() - 0.5, hi.ceil() + 0.5)
                } else {
                    (0.5, 1.5)
                }
            }
            Ticks::Direction => (-1.6, 1.6),
        };
        (x, self.y_range.unwrap_or_else(|| padded_range(&ys, 0.08)))
    }

    /// Legend entries: (text, colour, is a band, is points only).
    fn legend_entries(&self) -> Vec<(String, RGBColor, LegendMark)> {
        let mut v = Vec::new();
        for b in &self.bands {
            if !b.name.is_empty() {
                v.push((b.name.clone(), band_colour(b), LegendMark::Area));
            }
        }
        let colours = series_colours(&self.series);
        for (s, colour) in self.series.iter().zip(colours) {
            if !s.name.is_empty() {
                let mark = match s.style {
                    Style::Points => LegendMark::Dot,
                    Style::LinePoints => LegendMark::LineDot,
                    Style::DashedPoints => LegendMark::Dashed,
                    Style::Line | Style::Step => LegendMark::Line,
                };
                v.push((s.name.clone(), colour, mark));
            }
        }
        for (_, label, c) in &self.dashed {
            if !label.is_empty() {
                v.push((label.clone(), *c, LegendMark::Dashed));
            }
        }
        v
    }

    /// The plot with every series reduced to what its pixels can show
    /// ([`decimate`]: a line's envelope per pixel column, a scatter capped
    /// with the lowest and highest point of every x bin kept), and how many
    /// points that left out.
    pub fn reduced(&self) -> (XyPlot, Reduction) {
        let mut r = Reduction::default();
        let mut plot = self.clone();
        // A narrower drawing (a phone's) has fewer pixel columns to fill.
        let k = (f64::from(self.size.0) / f64::from(SIZE.0)).min(1.0);
        // A phone-sized drawing (half the width, a quarter of the area)
        // keeps a quarter of the dots and a line's envelope on bins two
        // pixels wide.
        let scaled = |n: usize| ((n as f64 * k * k).round() as usize).max(n / 4);
        for s in &mut plot.series {
            let finite: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            let kept = match s.style {
                Style::Points => decimate::scatter(
                    &finite,
                    scaled(decimate::MAX_SCATTER_POINTS),
                    scaled(decimate::SCATTER_BINS),
                ),
                Style::Line | Style::Step | Style::LinePoints | Style::DashedPoints => {
                    decimate::line(&finite, scaled(decimate::LINE_BINS))
                }
            };
            r.add(finite.len(), kept.len());
            s.points = kept;
        }
        (plot, r)
    }

    /// Renders the plot as an SVG document. A series with more points than
    /// the plot has pixels is reduced first ([`XyPlot::reduced`]) and the
    /// plot says so in a line under it: the SVG's size is bounded whatever
    /// the number of rows.
    pub fn to_svg(&self) -> Result<String> {
        let (plot, reduction) = if self.log_y {
            self.log10_of_y().reduced()
        } else {
            self.reduced()
        };
        Ok(decimate::drop_repeated_dots(
            plot.draw_svg(reduction.note())?,
        ))
    }

    fn draw_svg(&self, note: Option<String>) -> Result<String> {
        let mut buf = String::new();
        {
            let entries = self.legend_entries();
            let below = legend_below_height(&entries, self.size.0);
            let size = match note {
                Some(_) => (self.size.0, self.size.1 + below + NOTE_STRIP),
                None => (self.size.0, self.size.1 + below),
            };
            let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            let root = match &note {
                Some(text) => {
                    let (plot, strip) = root.split_vertically(self.size.1 + below);
                    draw_note(&strip, text)?;
                    plot
                }
                None => root,
            };
            // The legend gets a strip of its own right of the plot (under
            // it on a phone-wide drawing), so it never covers data (a
            // legend in a corner sat on the hottest points).
            let plot_area = legend_strip(&root, &entries, self.size)?;
            let ((x0, x1), (y0, y1)) = self.ranges();
            let mut chart = ChartBuilder::on(&plot_area)
                .caption(&self.title, ("sans-serif", 17))
                .margin(12)
                .x_label_area_size(42)
                .y_label_area_size(64)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(plot_err)?;
            let ticks = self.x_ticks;
            let x_fmt = move |v: &f64| -> String {
                match ticks {
                    Ticks::Auto => format_tick(*v),
                    Ticks::Period => {
                        if *v > 1e-12 {
                            format_value(1.0 / v)
                        } else {
                            String::new()
                        }
                    }
                    Ticks::Integer => {
                        if (v - v.round()).abs() < 1e-9 {
                            format!("{}", v.round() as i64)
                        } else {
                            String::new()
                        }
                    }
                    Ticks::Direction => {
                        if (v + 1.0).abs() < 1e-9 {
                            "−1".into()
                        } else if (v - 1.0).abs() < 1e-9 {
                            "+1".into()
                        } else {
                            String::new()
                        }
                    }
                }
            };
            let n_x = match ticks {
                Ticks::Auto | Ticks::Period => 10,
                Ticks::Integer => ((x1 - x0).round() as usize).clamp(1, 30),
                Ticks::Direction => 3,
            };
            // On a log axis (y holds log10 of the value) only the ticks
            // that land on 1, 2 or 5 × 10ᵏ are labelled, with the value.
            let log_y = self.log_y;
            let y_fmt = move |v: &f64| -> String {
                let value = 10f64.powf(*v);
                let decade = 10f64.powf(v.floor());
                match [1.0, 2.0, 5.0, 10.0]
                    .iter()
                    .find(|m| (value / (decade * *m) - 1.0).abs() < 0.03)
                {
                    Some(m) => format_tick(decade * m),
                    None => String::new(),
                }
            };
            let mut mesh = chart.configure_mesh();
            if self.size.0 < LEGEND_BELOW {
                // A phone-wide drawing: plotters' light lines would fall
                // every 3 px (and weigh more than the data).
                mesh.max_light_lines(1);
            }
            mesh.x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .x_labels(n_x)
                .x_label_formatter(&x_fmt)
                .light_line_style(RGBColor(235, 235, 235));
            if log_y {
                mesh.y_label_formatter(&y_fmt).y_labels(30);
            }
            if !matches!(ticks, Ticks::Auto | Ticks::Period) {
                mesh.disable_x_mesh();
            }
            mesh.draw().map_err(plot_err)?;
            for b in &self.bands {
                let colour = band_colour(b);
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
                    .map_err(plot_err)?;
            }
            for (y, label) in &self.hlines {
                let style = ShapeStyle::from(&RGBColor(120, 120, 120)).stroke_width(1);
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0, *y), (x1, *y)],
                        style,
                    )))
                    .map_err(plot_err)?;
                if !label.is_empty() {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            label.clone(),
                            (x0 + 0.01 * (x1 - x0), *y),
                            ("sans-serif", 12).into_font().color(&RGBColor(90, 90, 90)),
                        )))
                        .map_err(plot_err)?;
                }
            }
            for (x, label) in &self.vmarks {
                let style = ShapeStyle::from(&RGBColor(110, 110, 110)).stroke_width(1);
                let n = 40;
                let dots = (0..n).step_by(2).map(|k| {
                    let a = y0 + (y1 - y0) * k as f64 / n as f64;
                    let b = y0 + (y1 - y0) * (k + 1) as f64 / n as f64;
                    PathElement::new(vec![(*x, a), (*x, b)], style)
                });
                chart.draw_series(dots).map_err(plot_err)?;
                if !label.is_empty() {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            label.clone(),
                            // At the foot: the top holds the peak's label.
                            (*x, y0 + 0.02 * (y1 - y0)),
                            ("sans-serif", 11)
                                .into_font()
                                .color(&RGBColor(90, 90, 90))
                                .pos(Pos::new(HPos::Left, VPos::Bottom)),
                        )))
                        .map_err(plot_err)?;
                }
            }
            for (y, _, c) in &self.dashed {
                let colour = *c;
                let style = ShapeStyle::from(&colour).stroke_width(2);
                let n = 48;
                let dashes = (0..n).step_by(2).map(|k| {
                    let a = x0 + (x1 - x0) * k as f64 / n as f64;
                    let b = x0 + (x1 - x0) * (k + 1) as f64 / n as f64;
                    PathElement::new(vec![(a, *y), (b, *y)], style)
                });
                chart.draw_series(dashes).map_err(plot_err)?;
            }
            let colours = series_colours(&self.series);
            for (s, &colour) in self.series.iter().zip(&colours) {
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .collect();
                let line_style = ShapeStyle::from(&colour).stroke_width(2);
                match s.style {
                    Style::Line => {
                        chart
                            .draw_series(LineSeries::new(pts, line_style))
                            .map_err(plot_err)?;
                    }
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
                            .map_err(plot_err)?;
                    }
                    Style::Points => {
                        chart
                            .draw_series(pts.iter().map(|p| Circle::new(*p, 2, colour.filled())))
                            .map_err(plot_err)?;
                    }
                    Style::LinePoints => {
                        chart
                            .draw_series(LineSeries::new(pts.clone(), line_style))
                            .map_err(plot_err)?;
                        chart
                            .draw_series(pts.iter().map(|p| Circle::new(*p, 4, colour.filled())))
                            .map_err(plot_err)?;
                    }
                    Style::DashedPoints => {
                        chart
                            .draw_series(DashedLineSeries::new(pts.clone(), 8, 5, line_style))
                            .map_err(plot_err)?;
                        chart
                            .draw_series(
                                pts.iter()
                                    .map(|p| Circle::new(*p, 4, colour.stroke_width(2))),
                            )
                            .map_err(plot_err)?;
                    }
                }
            }
            for (x, label, colour) in &self.vlines {
                let style = ShapeStyle::from(colour).stroke_width(1);
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
                        ("sans-serif", 12).into_font().color(colour),
                    )))
                    .map_err(plot_err)?;
            }
            for (x, y, text) in &self.notes {
                chart
                    .draw_series(std::iter::once(Text::new(
                        text.clone(),
                        (*x, *y),
                        ("sans-serif", 12)
                            .into_font()
                            .color(&RGBColor(40, 40, 40))
                            .pos(Pos::new(HPos::Center, VPos::Bottom)),
                    )))
                    .map_err(plot_err)?;
            }
            root.present().map_err(plot_err)?;
        }
        Ok(responsive(buf))
    }
}

/// Pixels of the strip under a plot that says how it was reduced.
pub const NOTE_STRIP: u32 = 18;

/// The reduction note, grey, left-aligned in its strip.
pub(crate) fn draw_note<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.draw(&Text::new(
        text.to_string(),
        (12, 2),
        ("sans-serif", 12)
            .into_font()
            .color(&RGBColor(90, 90, 90))
            .pos(Pos::new(HPos::Left, VPos::Top)),
    ))
    .map_err(plot_err)
}

/// How a legend entry is drawn.
#[derive(Clone, Copy, Debug)]
pub(crate) enum LegendMark {
    Line,
    Dot,
    LineDot,
    Area,
    Bar,
    Dashed,
}

/// Pixels for a legend strip holding `entries` (the built-in font's
/// metrics are not known here: ~6.6 px per character at 12 px).
pub(crate) fn legend_width(entries: &[(String, RGBColor, LegendMark)]) -> u32 {
    let chars = entries
        .iter()
        .map(|e| e.0.chars().count())
        .max()
        .unwrap_or(0);
    ((chars as f64 * 6.6) as u32 + 40).clamp(90, 260)
}

/// The height of a legend strip under a plot `width` wide: 0 when the
/// legend goes beside it (at least [`LEGEND_BELOW`] wide, or no entries).
pub(crate) fn legend_below_height(entries: &[(String, RGBColor, LegendMark)], width: u32) -> u32 {
    if entries.is_empty() || width >= LEGEND_BELOW {
        0
    } else {
        8 + 20 * entries.len() as u32
    }
}

/// Draws the legend of a plot of `size` in a strip of `root` — right of
/// the plot, or under it when the drawing is narrower than
/// [`LEGEND_BELOW`] (`root` is then `size.1` + [`legend_below_height`]
/// tall) — and returns the plot's area.
pub(crate) fn legend_strip<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, RGBColor, LegendMark)],
    size: (u32, u32),
) -> Result<DrawingArea<DB, plotters::coord::Shift>>
where
    DB::ErrorType: 'static,
{
    if entries.is_empty() {
        return Ok(root.clone());
    }
    if legend_below_height(entries, size.0) > 0 {
        let (p, l) = root.split_vertically(size.1);
        draw_legend_from(&l, entries, 10)?;
        return Ok(p);
    }
    let (p, l) = root.split_horizontally(size.0.saturating_sub(legend_width(entries)));
    draw_legend(&l, entries)?;
    Ok(p)
}

/// Draws the legend entries top-down in `area` (a strip right of the plot).
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, RGBColor, LegendMark)],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    draw_legend_from(area, entries, 48)
}

/// [`draw_legend`] with the first entry at `top` px.
fn draw_legend_from<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, RGBColor, LegendMark)],
    top: i32,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let font = ("sans-serif", 12).into_font();
    for (k, (name, colour, mark)) in entries.iter().enumerate() {
        let y = top + 20 * k as i32;
        let c = *colour;
        match mark {
            LegendMark::Line => area
                .draw(&PathElement::new(vec![(4, y), (24, y)], c.stroke_width(3)))
                .map_err(plot_err)?,
            LegendMark::Dot => area
                .draw(&Circle::new((14, y), 3, c.filled()))
                .map_err(plot_err)?,
            LegendMark::LineDot => {
                area.draw(&PathElement::new(vec![(4, y), (24, y)], c.stroke_width(2)))
                    .map_err(plot_err)?;
                area.draw(&Circle::new((14, y), 4, c.filled()))
                    .map_err(plot_err)?
            }
            LegendMark::Area => area
                .draw(&Rectangle::new(
                    [(4, y - 5), (24, y + 5)],
                    c.mix(0.3).filled(),
                ))
                .map_err(plot_err)?,
            LegendMark::Bar => area
                .draw(&Rectangle::new([(4, y - 5), (24, y + 5)], c.filled()))
                .map_err(plot_err)?,
            LegendMark::Dashed => {
                for x in [4, 12, 20] {
                    area.draw(&PathElement::new(
                        vec![(x, y), (x + 5, y)],
                        c.stroke_width(2),
                    ))
                    .map_err(plot_err)?;
                }
            }
        }
        area.draw(&Text::new(
            name.clone(),
            (30, y),
            font.clone()
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(plot_err)?;
    }
    Ok(())
}

/// An axis title in words with its unit for a data column name: `x_mm` →
/// "x (mm)", `t_s` → "time (s)", `T_bed_C` → "bed temperature (°C)",
/// `dir_x` → "approach direction along x", `tool_mm` → "tool length (mm)",
/// `ex_um` → "ex error (µm)"; an auxiliary column with a unit suffix the
/// contract knows (`humidity_pct`) → "humidity (%)", any other name as it is.
pub fn axis_title(column: &str) -> String {
    if let Some(a) = column.strip_prefix("dir_") {
        return format!("approach direction along {a}");
    }
    if let Some(name) = column.strip_prefix("T_").and_then(|c| c.strip_suffix("_C")) {
        return format!("{} temperature (°C)", name.replace('_', " "));
    }
    match column {
        "t_s" => return "time (s)".into(),
        "tool_mm" => return "tool length (mm)".into(),
        "x_mm" | "y_mm" | "z_mm" => return format!("{} (mm)", &column[..1]),
        "ex_um" | "ey_um" | "ez_um" => return format!("{} error (µm)", &column[..2]),
        _ => {}
    }
    for (suffix, unit) in [
        ("_pct", "%"),
        ("_mm", "mm"),
        ("_um", "µm"),
        ("_s", "s"),
        ("_C", "°C"),
        ("_K", "K"),
    ] {
        if let Some(name) = column.strip_suffix(suffix).filter(|n| !n.is_empty()) {
            return format!("{} ({unit})", name.replace('_', " "));
        }
    }
    column.to_string()
}

/// How to tick a data column on the x axis: direction columns are the
/// categories −1 and +1, not a number line from −0.8 to 0.8.
pub fn ticks_for(column: &str) -> Ticks {
    if column.starts_with("dir_") {
        Ticks::Direction
    } else {
        Ticks::Auto
    }
}

/// `head` without its attribute ` name="…"` (unchanged when absent).
fn drop_attr(head: &str, name: &str) -> String {
    let key = format!(" {name}=\"");
    match head.find(&key) {
        Some(i) => match head[i + key.len()..].find('"') {
            Some(j) => format!("{}{}", &head[..i], &head[i + key.len() + j + 1..]),
            None => head.to_string(),
        },
        None => head.to_string(),
    }
}

/// Tick text for a round number: no `-0.0`, at most 6 decimals.
pub(crate) fn format_tick(v: f64) -> String {
    let v = if v.abs() < 1e-12 { 0.0 } else { v };
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.replace('-', "−")
}

/// The SVG scaled to its container: plotters writes a fixed `width` and
/// `height` in pixels (1440 px for a before/after pair, cut off in a 1400 px
/// window); without them the `viewBox` makes the browser scale the drawing
/// to the width it is given, keeping its proportions.
///
/// It also drops plotters' `opacity="1"` from every element (the default;
/// 12 bytes on each of tens of thousands of elements in a large report).
pub fn responsive(svg: String) -> String {
    let svg = if svg.contains(" opacity=\"1\"") {
        svg.replace(" opacity=\"1\"", "")
    } else {
        svg
    };
    let Some(start) = svg.find("<svg ") else {
        return svg;
    };
    let Some(end) = svg[start..].find('>').map(|e| start + e) else {
        return svg;
    };
    let head = &svg[start..end];
    if !head.contains("viewBox=") {
        return svg;
    }
    // Drop ` width="…"` and ` height="…"` of the root element only.
    let head = drop_attr(&drop_attr(head, "width"), "height");
    let mut out = String::with_capacity(svg.len());
    out.push_str(&svg[..start]);
    out.push_str(&head);
    out.push_str(" preserveAspectRatio=\"xMidYMid meet\"");
    out.push_str(&svg[end..]);
    out
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
    /// The colour of group `k`'s bar in category `cat` (None: its legend
    /// swatch). When every category is a target each target's bars are in
    /// its colour, the groups told apart by lightness (the first, "before",
    /// palest; the legend in greys of the same lightness); otherwise each
    /// group has a colour of its own.
    fn colour_fn(&self) -> impl Fn(usize, Option<usize>) -> RGBColor {
        let targets: Option<Vec<usize>> = self.categories.iter().map(|c| target_of(c)).collect();
        let g = self.groups.len();
        move |k: usize, cat: Option<usize>| {
            // Lightness: the last group full, the first 60 % to white.
            let light = if g > 1 {
                0.6 * (g - 1 - k.min(g - 1)) as f64 / (g - 1) as f64
            } else {
                0.0
            };
            match &targets {
                Some(t) => {
                    let base = cat
                        .and_then(|i| t.get(i))
                        .map_or(RGBColor(80, 80, 80), |&t| target_colour(t));
                    lighter(base, light)
                }
                None => OTHER_COLOURS[k % OTHER_COLOURS.len()],
            }
        }
    }

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
            let colour = self.colour_fn();
            let entries: Vec<(String, RGBColor, LegendMark)> = self
                .groups
                .iter()
                .enumerate()
                .map(|(k, (name, _))| (name.clone(), colour(k, None), LegendMark::Bar))
                .collect();
            let below = legend_below_height(&entries, self.size.0);
            let root = SVGBackend::with_string(&mut buf, (self.size.0, self.size.1 + below))
                .into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            let root = legend_strip(&root, &entries, self.size)?;
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
                .max_light_lines(if self.size.0 < LEGEND_BELOW { 1 } else { 10 })
                .x_labels(n * 2 + 1)
                .x_label_formatter(&fmt)
                .y_desc(&self.y_label)
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            let width = 0.8 / g as f64;
            for (k, (_, values)) in self.groups.iter().enumerate() {
                let colour = &colour;
                let bars = values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite())
                    .map(move |(i, v)| {
                        let x0 = i as f64 + 0.1 + k as f64 * width;
                        let c = colour(k, Some(i));
                        Rectangle::new([(x0, 0.0), (x0 + width * 0.92, *v)], c.filled())
                    });
                chart.draw_series(bars).map_err(plot_err)?;
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
            root.present().map_err(plot_err)?;
        }
        Ok(responsive(buf))
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

/// The text of every `<text>` element of an SVG (tests read labels).
#[cfg(test)]
pub(crate) fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .map(|t| {
            let t = &t[t.find('>').unwrap() + 1..];
            t[..t.find("</text>").unwrap()].trim().to_string()
        })
        .collect()
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

    /// The root `<svg …>` element of a document.
    fn root(svg: &str) -> &str {
        &svg[..svg.find('>').unwrap()]
    }

    #[test]
    fn svgs_scale_to_the_window_and_keep_legends_off_the_data() {
        let p = XyPlot::new("t", "x (mm)", "e (µm)").with(Series::line(
            "a long legend entry",
            vec![(0.0, 0.0), (1.0, 1.0)],
        ));
        let svg = p.to_svg().unwrap();
        let head = root(&svg);
        assert!(head.contains("viewBox=\"0 0 720 420\""), "{head}");
        assert!(
            !head.contains(" width=") && !head.contains(" height="),
            "{head}"
        );
        // The legend text sits right of the plot area, which ends before
        // the legend strip (x of the text > the last x tick's position).
        let at = svg.find("a long legend entry").unwrap();
        let text = &svg[svg[..at].rfind("<text").unwrap()..at];
        let x: f64 = text
            .split("x=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(
            x > 720.0 - legend_width(&p.legend_entries()) as f64,
            "{text}"
        );
        let m = HeatMap::from_points(
            "m",
            "x",
            "y",
            "µm",
            &[(0.0, 0.0, 1.0), (1.0, 1.0, -1.0)],
            0.1,
        );
        let pair = heat_map_pair(&m, &m).unwrap();
        let (w, h) = m.fitted_size();
        assert!(!root(&pair).contains(" width="), "{}", root(&pair));
        assert!(
            root(&pair).contains(&format!("viewBox=\"0 0 {} {h}\"", 2 * w)),
            "{}",
            root(&pair)
        );
    }

    #[test]
    fn axis_titles_are_words_with_units() {
        assert_eq!(axis_title("T_bed_C"), "bed temperature (°C)");
        assert_eq!(axis_title("t_s"), "time (s)");
        assert_eq!(axis_title("x_mm"), "x (mm)");
        assert_eq!(axis_title("tool_mm"), "tool length (mm)");
        assert_eq!(axis_title("dir_x"), "approach direction along x");
        assert_eq!(axis_title("humidity_pct"), "humidity (%)");
        assert_eq!(axis_title("operator"), "operator");
        assert_eq!(ticks_for("dir_y"), Ticks::Direction);
        assert_eq!(ticks_for("T_bed_C"), Ticks::Auto);
    }

    use super::svg_texts as texts;

    #[test]
    fn direction_axes_are_ticked_minus_one_and_plus_one_only() {
        let pts = vec![(-1.0, 0.3), (1.0, -0.2), (-1.0, 0.1), (1.0, 0.0)];
        let svg = XyPlot::new("r", "approach direction along x", "µm")
            .with(Series::points("", pts))
            .with_x_ticks(Ticks::Direction)
            .to_svg()
            .unwrap();
        let t = texts(&svg);
        assert!(
            t.contains(&"−1".to_string()) && t.contains(&"+1".to_string()),
            "{t:?}"
        );
        for bad in ["0.8", "-0.8", "−0.8", "0.5", "0"] {
            assert!(!t.contains(&bad.to_string()), "{bad} in {t:?}");
        }
    }

    #[test]
    fn integer_ticks_and_a_single_step_is_a_point() {
        let svg = XyPlot::new("h", "fit step", "µm")
            // y in whole hundreds, so every fractional tick would be x's.
            .with(Series::styled(
                "ex RMS",
                vec![(1.0, 200.0), (2.0, 100.0), (3.0, 20.0)],
                Style::LinePoints,
            ))
            .with_x_ticks(Ticks::Integer)
            .to_svg()
            .unwrap();
        let t = texts(&svg);
        for k in ["1", "2", "3"] {
            assert!(t.contains(&k.to_string()), "{k} in {t:?}");
        }
        assert!(
            !t.iter()
                .any(|s| s.parse::<f64>().is_ok_and(|v| v.fract() != 0.0)),
            "fractional step ticks: {t:?}"
        );
        let one = XyPlot::new("h", "fit step", "µm")
            .with(Series::styled(
                "ex RMS",
                vec![(1.0, 2.0)],
                Style::LinePoints,
            ))
            .with_x_ticks(Ticks::Integer)
            .to_svg()
            .unwrap();
        assert!(one.contains("<circle"), "one fit is drawn as a point");
        assert!(texts(&one).contains(&"1".to_string()));
    }

    /// The fill colours of the circles (dots: legend and data) in an SVG,
    /// each once, in the order they first appear.
    fn dot_colours(svg: &str) -> Vec<String> {
        let mut v: Vec<String> = Vec::new();
        for c in svg.split("<circle").skip(1) {
            let c = &c[..c.find("/>").unwrap_or(c.len())];
            if let Some(f) = c.split("fill=\"").nth(1).map(|f| f[..7].to_string()) {
                if !v.contains(&f) {
                    v.push(f);
                }
            }
        }
        v
    }

    fn hex(c: RGBColor) -> String {
        format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
    }

    #[test]
    fn a_target_has_one_colour_whatever_the_order_of_the_series() {
        // ey first on one plot, third on the next: the same vermillion
        // (issue 28: ey was vermillion on one plot and green on another).
        let one = XyPlot::new("a", "x", "y")
            .with(Series::points("ey", vec![(0.0, 1.0)]))
            .to_svg()
            .unwrap();
        let two = XyPlot::new("b", "x", "y")
            .with(Series::points("ex measured", vec![(0.0, 1.0)]))
            .with(Series::points("dir_x = +1", vec![(0.0, 2.0)]))
            .with(Series::points("ey", vec![(0.0, 3.0)]))
            .to_svg()
            .unwrap();
        let ey = hex(TARGET_COLOURS[1]);
        assert_eq!(dot_colours(&one), vec![ey.clone()]);
        let c = dot_colours(&two);
        assert_eq!(
            c,
            vec![hex(TARGET_COLOURS[0]), hex(DIRECTION_COLOURS[0]), ey]
        );
        // A model is its target's darker shade; other series never take a
        // target's or a direction's colour.
        let s = [
            Series::line("ex model", vec![]),
            Series::line("y = x", vec![]),
            Series::line("fitted form", vec![]),
            Series::line("dir_y = −1", vec![]),
        ];
        let c = series_colours(&s);
        assert_eq!(c[0], darker(TARGET_COLOURS[0], 0.45));
        for other in [c[1], c[2]] {
            assert!(!TARGET_COLOURS.contains(&other) && !DIRECTION_COLOURS.contains(&other));
        }
        assert_eq!(c[3], DIRECTION_COLOURS[1]);
        // Bars of targets: each target's bars in its colour.
        let bars = before_after(
            "r",
            "µm",
            &["ex".into(), "ez".into()],
            &[2.0, 1.0],
            &[1.0, 0.5],
        );
        let f = bars.colour_fn();
        assert_eq!(f(1, Some(0)), TARGET_COLOURS[0]);
        assert_eq!(f(1, Some(1)), TARGET_COLOURS[2]);
        assert_eq!(f(0, Some(1)), lighter(TARGET_COLOURS[2], 0.6));
    }

    #[test]
    fn a_peak_below_the_false_alarm_level_is_not_red() {
        let svg = XyPlot::new("p", "f", "power")
            .with(Series::line(
                "Lomb–Scargle power",
                vec![(0.1, 0.1), (0.2, 0.05)],
            ))
            .with_vline_coloured(0.1, "10 mm", NO_FINDING)
            .to_svg()
            .unwrap();
        assert!(!svg.contains(&hex(FINDING)), "red on a no-finding plot");
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
    fn a_dense_line_is_averaged_into_the_grid_cells() {
        // A 3 × 3 grid every 50 mm and a dense line at y = 50 every 0.5 mm.
        let mut pts = Vec::new();
        for iy in 0..3 {
            for ix in 0..3 {
                pts.push((50.0 * f64::from(ix), 50.0 * f64::from(iy), 1.0));
            }
        }
        for i in 0..=200 {
            pts.push((0.5 * f64::from(i), 50.0, 3.0));
        }
        let m = HeatMap::from_grid_points("t", "x", "y", "µm", &pts, 1e-3);
        assert_eq!(m.x, vec![0.0, 50.0, 100.0]);
        assert_eq!(m.y, vec![0.0, 50.0, 100.0]);
        assert!(m.values.iter().all(|v| v.is_some()), "no grey columns");
        // The middle row holds the line's readings; the others the grid's.
        assert_eq!(m.values[0], Some(1.0));
        assert!(m.values[4].unwrap() > 2.9);
        // Without it, one cell per reading — up to MAX_CELLS even bins.
        assert_eq!(
            HeatMap::from_points("t", "x", "y", "µm", &pts, 1e-3)
                .x
                .len(),
            heat::MAX_CELLS
        );
    }

    #[test]
    fn maps_are_drawn_at_the_machines_aspect_ratio_and_ticked_at_their_ends() {
        // An 800 × 500 mm plane every 100 mm (issue 28: drawn 289 × 262).
        let mut pts = Vec::new();
        for iy in 0..6 {
            for ix in 0..9 {
                pts.push((100.0 * f64::from(ix), 100.0 * f64::from(iy), 1.0));
            }
        }
        let m = HeatMap::from_points("m", "x (mm)", "y (mm)", "µm", &pts, 1e-3);
        let (w, h) = m.fitted_size();
        // The plotting area (the size less colour bar, labels, margins).
        let (pw, ph) = (f64::from(w - 170), f64::from(h - 96));
        let ratio = (pw / ph) / (900.0 / 600.0);
        assert!((ratio - 1.0).abs() < 0.02, "{w} × {h}: {ratio}");
        // A bed probed from 25 to 225 mm: both ends ticked; 0 when the
        // positions straddle it.
        let t = heat::key_ticks(&[25.0, 75.0, 125.0, 175.0, 225.0]);
        assert_eq!(t.first(), Some(&25.0));
        assert!(t.contains(&225.0), "{t:?}");
        assert_eq!(heat::map_tick(33.333333, 800.0), "33.3");
        assert_eq!(heat::map_tick(247.47, 200.0), "247.47");
        let t = heat::key_ticks(&[-150.0, -50.0, 50.0, 150.0]);
        assert!(
            t.contains(&0.0) && t.contains(&-150.0) && t.contains(&150.0),
            "{t:?}"
        );
        let svg = m.to_svg().unwrap();
        let labels = svg_texts(&svg);
        for end in ["0", "800", "500"] {
            assert!(labels.contains(&end.to_string()), "{end}: {labels:?}");
        }
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
