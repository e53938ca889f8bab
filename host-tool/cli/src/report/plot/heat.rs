//! Heat maps of a residual over a plane (points snapped to their grid, a
//! diverging colour scale symmetric about zero) and the before/after pair.

use super::*;

/// A heat map: values on a rectangular grid of cell centres (the measured
/// plane of a grid plan), coloured on a diverging scale symmetric about
/// zero so that the sign of a residual reads at a glance.
#[derive(Clone, Debug)]
pub struct HeatMap {
    /// Title above the map.
    pub title: String,
    /// Horizontal axis description (`x (mm)`).
    pub x_label: String,
    /// Vertical axis description (`y (mm)`).
    pub y_label: String,
    /// Unit of the values, shown on the colour bar (`µm`).
    pub unit: String,
    /// Cell centres along x, ascending.
    pub x: Vec<f64>,
    /// Cell centres along y, ascending.
    pub y: Vec<f64>,
    /// Values row by row: `values[iy * x.len() + ix]`; `None` = not measured.
    pub values: Vec<Option<f64>>,
    /// Colour range ±`limit`; `None` = the largest |value|. Set the same
    /// limit on two maps to compare them (before vs after).
    pub limit: Option<f64>,
    /// Size in pixels.
    pub size: (u32, u32),
    /// The reading with the largest |value|, (x, y, value): ringed on the
    /// map, so averaging into cells never hides where the model fails most.
    pub worst: Option<(f64, f64, f64)>,
    /// Readings averaged into the cells.
    pub readings: usize,
    /// Values are magnitudes (an RMS, ≥ 0): the colour bar runs from 0
    /// (white) to `limit` (red) only.
    pub magnitude: bool,
}

/// Cells per axis at most: past it the cells are even bins over the range
/// (a plane with a dense line at 0.05 mm made a column per reading).
pub const MAX_CELLS: usize = 60;
/// Cells per map at most (~100 bytes of SVG each): both axes are binned
/// more coarsely, in proportion, when their product is larger.
pub const MAX_MAP_CELLS: usize = 1600;

/// `centres` as they are, or `max` evenly spaced ones over their range.
fn cap_cells(centres: Vec<f64>, max: usize) -> Vec<f64> {
    if centres.len() <= max || max < 2 {
        return centres;
    }
    let (lo, hi) = (centres[0], centres[centres.len() - 1]);
    (0..max)
        .map(|i| lo + (hi - lo) * i as f64 / (max - 1) as f64)
        .collect()
}

impl HeatMap {
    /// Bins scattered (x, y, value) samples onto the grid of their distinct
    /// coordinates (coordinates closer than `snap` are the same grid line)
    /// and averages the values that fall on the same cell — repeats and
    /// both directions of a grid plan land on one cell.
    pub fn from_points(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        unit: impl Into<String>,
        points: &[(f64, f64, f64)],
        snap: f64,
    ) -> HeatMap {
        let finite: Vec<(f64, f64, f64)> = points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
            .collect();
        let xs = distinct(finite.iter().map(|p| p.0), snap);
        let ys = distinct(finite.iter().map(|p| p.1), snap);
        HeatMap::on_cells(title, x_label, y_label, unit, &finite, xs, ys)
    }

    /// Like [`HeatMap::from_points`], but the cells are the lines of the
    /// measured grid: along each axis, the positions that hold points at
    /// two or more positions of the other axis. A dense line (a reading
    /// every 0.5 mm at one y) then adds its readings to the grid's cells
    /// instead of making a column per reading — thousands of one-reading
    /// columns, grey everywhere else. Falls back to every position when
    /// fewer than two such lines exist.
    pub fn from_grid_points(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        unit: impl Into<String>,
        points: &[(f64, f64, f64)],
        snap: f64,
    ) -> HeatMap {
        let finite: Vec<(f64, f64, f64)> = points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
            .collect();
        let xs = distinct(finite.iter().map(|p| p.0), snap);
        let ys = distinct(finite.iter().map(|p| p.1), snap);
        // Positions along one axis that are grid lines: points there sit at
        // ≥ 2 distinct positions of the other.
        let lines = |along: &[f64], other: &[f64], a: fn(&(f64, f64, f64)) -> (f64, f64)| {
            let mut seen: Vec<Vec<usize>> = vec![Vec::new(); along.len()];
            for p in &finite {
                let (u, v) = a(p);
                let (i, j) = (nearest(along, u), nearest(other, v));
                if !seen[i].contains(&j) {
                    seen[i].push(j);
                }
            }
            let kept: Vec<f64> = along
                .iter()
                .zip(&seen)
                .filter(|(_, s)| s.len() >= 2)
                .map(|(c, _)| *c)
                .collect();
            if kept.len() >= 2 {
                kept
            } else {
                along.to_vec()
            }
        };
        let gx = lines(&xs, &ys, |p| (p.0, p.1));
        let gy = lines(&ys, &xs, |p| (p.1, p.0));
        HeatMap::on_cells(title, x_label, y_label, unit, &finite, gx, gy)
    }

    /// Averages finite (x, y, value) samples onto the cells centred at
    /// `xs` × `ys` (each sample to the nearest centre).
    fn on_cells(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        unit: impl Into<String>,
        finite: &[(f64, f64, f64)],
        xs: Vec<f64>,
        ys: Vec<f64>,
    ) -> HeatMap {
        let (mut xs, mut ys) = (cap_cells(xs, MAX_CELLS), cap_cells(ys, MAX_CELLS));
        if xs.len() * ys.len() > MAX_MAP_CELLS {
            let f = (MAX_MAP_CELLS as f64 / (xs.len() * ys.len()) as f64).sqrt();
            let (nx, ny) = (
                ((xs.len() as f64 * f) as usize).max(2),
                ((ys.len() as f64 * f) as usize).max(2),
            );
            xs = cap_cells(xs, nx);
            ys = cap_cells(ys, ny);
        }
        let mut sum = vec![0.0; xs.len() * ys.len()];
        let mut count = vec![0usize; xs.len() * ys.len()];
        for &(x, y, v) in finite {
            let ix = nearest(&xs, x);
            let iy = nearest(&ys, y);
            sum[iy * xs.len() + ix] += v;
            count[iy * xs.len() + ix] += 1;
        }
        let values = sum
            .iter()
            .zip(&count)
            .map(|(s, &n)| (n > 0).then(|| s / n as f64))
            .collect();
        HeatMap {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            unit: unit.into(),
            x: xs,
            y: ys,
            values,
            limit: None,
            size: SIZE,
            worst: finite
                .iter()
                .copied()
                .max_by(|a, b| a.2.abs().total_cmp(&b.2.abs())),
            readings: finite.len(),
            magnitude: false,
        }
    }

    /// A map of values already reduced per cell (an RMS per bin): centres
    /// ascending, `values[iy * xs.len() + ix]`, with the reading to ring and
    /// the number of readings behind the cells.
    #[allow(clippy::too_many_arguments)]
    pub fn from_cells(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        unit: impl Into<String>,
        xs: Vec<f64>,
        ys: Vec<f64>,
        values: Vec<Option<f64>>,
        worst: Option<(f64, f64, f64)>,
        readings: usize,
    ) -> HeatMap {
        HeatMap {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            unit: unit.into(),
            x: xs,
            y: ys,
            values,
            limit: None,
            size: SIZE,
            worst,
            readings,
            magnitude: true,
        }
    }

    /// What the map does not show by itself: how many readings were
    /// averaged into how many cells, and the worst reading (ringed).
    pub fn note(&self) -> Option<String> {
        let cells = self.values.iter().flatten().count();
        let (x, y, v) = self.worst?;
        (self.readings > cells).then(|| {
            format!(
                "{} readings on {} cells; ringed: the worst, {} {} at ({}, {})",
                decimate::group_digits(self.readings),
                decimate::group_digits(cells),
                format_value(v),
                self.unit,
                format_value(x),
                format_value(y)
            )
        })
    }

    /// The largest |value| on the map (0 for an empty map).
    pub fn max_abs(&self) -> f64 {
        self.values
            .iter()
            .flatten()
            .fold(0.0f64, |m, v| m.max(v.abs()))
    }

    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, plotters::coord::Shift>) -> Result<()>
    where
        DB::ErrorType: 'static,
    {
        let limit = self.limit.unwrap_or_else(|| self.max_abs()).max(1e-12);
        let area = match self.note() {
            Some(text) => {
                let h = area.dim_in_pixel().1;
                let (a, strip) = area.split_vertically(h.saturating_sub(NOTE_STRIP));
                draw_note(&strip, &text)?;
                a
            }
            None => area.clone(),
        };
        let (map_area, bar_area) =
            area.split_horizontally(area.dim_in_pixel().0.saturating_sub(86));
        let xe = edges(&self.x);
        let ye = edges(&self.y);
        let (x0, x1) = (xe[0], xe[xe.len() - 1]);
        let (y0, y1) = (ye[0], ye[ye.len() - 1]);
        // Ticked at both ends of the measured positions and at 0 when it
        // is inside, with round numbers between (issue 28: no 0 tick).
        let xt = KeyAxis::new(x0, x1, key_ticks(&self.x));
        let yt = KeyAxis::new(y0, y1, key_ticks(&self.y));
        let mut chart = ChartBuilder::on(&map_area)
            .caption(&self.title, ("sans-serif", 17))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(60)
            .build_cartesian_2d(xt, yt)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            // plotters sizes these from the area's height: a short map
            // (a stacked pair on a phone) got 6 px axis titles.
            .axis_desc_style(("sans-serif", 12))
            .label_style(("sans-serif", 12))
            .x_labels(6)
            .y_labels(8)
            .x_label_formatter(&|v| map_tick(*v, x1 - x0))
            .y_label_formatter(&|v| map_tick(*v, y1 - y0))
            .draw()
            .map_err(plot_err)?;
        let nx = self.x.len();
        let cells = self.values.iter().enumerate().map(|(k, v)| {
            let (ix, iy) = (k % nx.max(1), k / nx.max(1));
            let style = match v {
                Some(v) => diverging(*v / limit).filled(),
                // Not measured: light grey, so a gap is never read as zero.
                None => RGBColor(225, 225, 225).filled(),
            };
            Rectangle::new([(xe[ix], ye[iy]), (xe[ix + 1], ye[iy + 1])], style)
        });
        chart.draw_series(cells).map_err(plot_err)?;
        if let Some((x, y, _)) = self.worst {
            chart
                .draw_series([
                    Circle::new((x, y), 7, ShapeStyle::from(&BLACK).stroke_width(2)),
                    Circle::new((x, y), 9, ShapeStyle::from(&WHITE).stroke_width(1)),
                ])
                .map_err(plot_err)?;
        }
        // Colour bar: a vertical strip from −limit to +limit, labelled by
        // hand on its right (x 0..1 is the strip, 1..3 the labels), which
        // keeps the labels inside the chart whatever the font metrics.
        let bottom = if self.magnitude { 0.0 } else { -limit };
        let mut bar = ChartBuilder::on(&bar_area)
            .margin_top(40)
            .margin_bottom(54)
            .margin_right(4)
            .build_cartesian_2d(0.0..3.0, bottom * 1.04..limit * 1.04)
            .map_err(plot_err)?;
        let steps = 64;
        bar.draw_series((0..steps).map(|i| {
            let a = bottom + (limit - bottom) * i as f64 / steps as f64;
            let b = bottom + (limit - bottom) * (i + 1) as f64 / steps as f64;
            Rectangle::new(
                [(0.0, a), (1.0, b)],
                diverging(0.5 * (a + b) / limit).filled(),
            )
        }))
        .map_err(plot_err)?;
        let marks = if self.magnitude {
            [0.0, 0.25, 0.5, 0.75, 1.0]
        } else {
            [-1.0, -0.5, 0.0, 0.5, 1.0]
        };
        bar.draw_series(marks.map(|f| {
            Text::new(
                format_value(f * limit),
                (1.15, f * limit),
                ("sans-serif", 12).into_font(),
            )
        }))
        .map_err(plot_err)?;
        bar.draw_series(std::iter::once(Text::new(
            self.unit.clone(),
            (0.0, limit * 1.04),
            ("sans-serif", 12).into_font(),
        )))
        .map_err(plot_err)?;
        Ok(())
    }

    /// The drawing's size with the map at the machine's aspect ratio: a
    /// millimetre is as long across as up (issue 28: an 800 × 500 mm plane
    /// was drawn 289 × 262 px). The width given is kept and the height
    /// follows, unless the plane is so tall that it would pass 1.6 × the
    /// given height: then the height is capped and the width follows.
    pub fn fitted_size(&self) -> (u32, u32) {
        let xe = edges(&self.x);
        let ye = edges(&self.y);
        let (sx, sy) = (xe[xe.len() - 1] - xe[0], ye[ye.len() - 1] - ye[0]);
        if !(sx > 0.0 && sy > 0.0) {
            return self.size;
        }
        // Around the plotting area: colour bar, y labels, margins; caption,
        // x labels, margins and the note strip.
        let extra_w = 86 + 60 + 24;
        let extra_h = 42 + 30 + 24 + if self.note().is_some() { NOTE_STRIP } else { 0 };
        let w = f64::from(self.size.0.saturating_sub(extra_w).max(60));
        let h_max = f64::from(self.size.1) * 1.6 - f64::from(extra_h);
        let h = w * sy / sx;
        let (w, h) = if h > h_max {
            (h_max * sx / sy, h_max)
        } else {
            (w, h.max(40.0))
        };
        (w.round() as u32 + extra_w, h.round() as u32 + extra_h)
    }

    /// Renders the map with its colour bar as an SVG document.
    pub fn to_svg(&self) -> Result<String> {
        if self.x.is_empty() || self.y.is_empty() {
            return XyPlot::new(
                format!("{} (no data)", self.title),
                &self.x_label,
                &self.y_label,
            )
            .to_svg();
        }
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.fitted_size()).into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            self.draw(&root)?;
            root.present().map_err(plot_err)?;
        }
        Ok(responsive(buf))
    }
}

/// Two heat maps side by side on one colour scale (the larger of the two
/// ranges), so "after" is visibly smaller than "before" when it is.
pub fn heat_map_pair(before: &HeatMap, after: &HeatMap) -> Result<String> {
    let limit = before.max_abs().max(after.max_abs());
    // Both at the plane's aspect ratio, side by side.
    let (w, h) = before.fitted_size();
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (2 * w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (left, right) = root.split_horizontally(w);
        for (map, area) in [(before, &left), (after, &right)] {
            let mut m = map.clone();
            m.limit = Some(limit);
            if m.x.is_empty() || m.y.is_empty() {
                continue;
            }
            m.draw(area)?;
        }
        root.present().map_err(plot_err)?;
    }
    Ok(responsive(buf))
}

/// Two heat maps on one colour scale as a [`Drawing`]: side by side
/// ([`heat_map_pair`]), and on a phone one above the other, each
/// [`PHONE_WIDTH`] wide.
#[derive(Clone, Copy, Debug)]
pub struct MapPair<'a> {
    /// The map before compensation (left, or top).
    pub before: &'a HeatMap,
    /// The map after (right, or below).
    pub after: &'a HeatMap,
}

impl Drawing for MapPair<'_> {
    fn svg(&self) -> Result<String> {
        heat_map_pair(self.before, self.after)
    }
    fn phone_svg(&self) -> Result<Option<String>> {
        if 2 * self.before.fitted_size().0 <= PHONE_MAX {
            return Ok(None);
        }
        let limit = self.before.max_abs().max(self.after.max_abs());
        let narrow = |m: &HeatMap| HeatMap {
            size: (PHONE_WIDTH, m.size.1),
            limit: Some(limit),
            ..m.clone()
        };
        let (before, after) = (narrow(self.before), narrow(self.after));
        let (w, h) = before.fitted_size();
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, (w, 2 * h)).into_drawing_area();
            root.fill(&WHITE).map_err(plot_err)?;
            let (top, bottom) = root.split_vertically(h);
            for (m, area) in [(&before, &top), (&after, &bottom)] {
                if !(m.x.is_empty() || m.y.is_empty()) {
                    m.draw(area)?;
                }
            }
            root.present().map_err(plot_err)?;
        }
        Ok(Some(responsive(buf)))
    }
}

/// Diverging colour for t in [−1, 1]: blue (negative) – white – red
/// (positive); values beyond ±1 saturate.
pub fn diverging(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let (r, g, b) = if t >= 0.0 {
        // white → red (178, 24, 43)
        (
            255.0 + t * (178.0 - 255.0),
            255.0 + t * (24.0 - 255.0),
            255.0 + t * (43.0 - 255.0),
        )
    } else {
        let s = -t;
        // white → blue (33, 102, 172)
        (
            255.0 + s * (33.0 - 255.0),
            255.0 + s * (102.0 - 255.0),
            255.0 + s * (172.0 - 255.0),
        )
    };
    RGBColor(r.round() as u8, g.round() as u8, b.round() as u8)
}

/// Distinct values, ascending, merging values closer than `snap`.
pub(super) fn distinct(values: impl Iterator<Item = f64>, snap: f64) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    let mut out: Vec<(f64, usize)> = Vec::new();
    for x in v {
        match out.last_mut() {
            // Running mean of the cluster, so a jittered grid line stays centred.
            Some((c, n)) if (x - *c).abs() <= snap => {
                *c = (*c * *n as f64 + x) / (*n + 1) as f64;
                *n += 1;
            }
            _ => out.push((x, 1)),
        }
    }
    out.into_iter().map(|(c, _)| c).collect()
}

pub(super) fn nearest(sorted: &[f64], x: f64) -> usize {
    let i = sorted.partition_point(|&c| c < x);
    if i == 0 {
        0
    } else if i >= sorted.len() {
        sorted.len() - 1
    } else if (x - sorted[i - 1]).abs() <= (sorted[i] - x).abs() {
        i - 1
    } else {
        i
    }
}

/// Cell edges around centres: midpoints, ends extended by half a spacing.
/// A map's tick label: the position as written when it has at most 3
/// decimals (`247.47`), else rounded to what the axis span reads (a bin
/// centre `33.333333` → `33.3` on an 800 mm axis).
pub(crate) fn map_tick(v: f64, span: f64) -> String {
    let s = format_tick(v);
    if s.split('.').nth(1).map_or(0, str::len) <= 3 {
        return s;
    }
    let decimals = if span >= 100.0 {
        1
    } else if span >= 10.0 {
        2
    } else {
        3
    };
    let p = 10f64.powi(decimals);
    format_tick((v * p).round() / p)
}

/// A linear f64 axis ticked exactly at given values (plotters' own picks
/// round numbers only, so a bed probed from 25 to 225 mm had neither end
/// labelled).
struct KeyAxis {
    inner: plotters::coord::types::RangedCoordf64,
    keys: Vec<f64>,
}

impl KeyAxis {
    fn new(lo: f64, hi: f64, keys: Vec<f64>) -> KeyAxis {
        KeyAxis {
            inner: (lo..hi).into(),
            keys,
        }
    }
}

impl plotters::coord::ranged1d::Ranged for KeyAxis {
    type FormatOption = plotters::coord::ranged1d::DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }
    fn key_points<Hint: plotters::coord::ranged1d::KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.keys.clone()
        }
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// Tick positions for a map axis over the cell centres `c`: the first and last centre (the measured ends), 0 when the
/// measured positions straddle it, and round multiples of a 1-2-5 step between them that do
/// not crowd the ends.
pub(crate) fn key_ticks(c: &[f64]) -> Vec<f64> {
    let (Some(&first), Some(&last)) = (c.first(), c.last()) else {
        return Vec::new();
    };
    let span = (last - first).abs();
    let mut t = vec![first, last];
    // 0 when the measured positions straddle it (next to an end it would
    // only crowd that end's label).
    if first < 0.0 && 0.0 < last {
        t.push(0.0);
    }
    if span > 0.0 {
        let raw = span / 5.0;
        let mag = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|m| m * mag)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * mag);
        let mut v = (first / step).ceil() * step;
        while v < last {
            if t.iter().all(|k| (v - k).abs() > 0.45 * step) {
                t.push(v);
            }
            v += step;
        }
    }
    t.sort_by(f64::total_cmp);
    t.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    t
}

pub(super) fn edges(c: &[f64]) -> Vec<f64> {
    match c.len() {
        0 => vec![0.0, 1.0],
        1 => vec![c[0] - 0.5, c[0] + 0.5],
        n => {
            let mut e = Vec::with_capacity(n + 1);
            e.push(c[0] - 0.5 * (c[1] - c[0]));
            for k in 0..n - 1 {
                e.push(0.5 * (c[k] + c[k + 1]));
            }
            e.push(c[n - 1] + 0.5 * (c[n - 1] - c[n - 2]));
            e
        }
    }
}
