//! Fewer SVG elements than data rows, the worst ones kept. A report of a
//! million readings must stay a few megabytes and open in a browser in
//! seconds (issue 15: 214k rows made two 39 MB SVGs), yet a user reads a
//! residual plot for where the model fails — an even thinning (every k-th
//! reading) would drop exactly the spikes and the worst stretch.
//!
//! - A line (a profile along a dense line, a periodogram, a time series)
//!   keeps, per pixel-wide x bin and per run of consecutive points in it,
//!   the first, the lowest, the highest and the last point, in their order:
//!   the drawn envelope is the one the full polyline would draw at that
//!   width, peaks included.
//! - A scatter keeps the lowest and the highest point of every x bin, and
//!   fills up to its cap with an even thinning of the rest.
//!
//! Plots say on themselves when they were reduced (see
//! [`Reduction::note`]), so nobody counts dots and takes them for readings.

/// Pixel columns a line is reduced to (the plots are ≤ 720 px wide).
pub const LINE_BINS: usize = 600;
/// A line with at most this many points is drawn as it is.
pub const MAX_LINE_POINTS: usize = 2 * LINE_BINS;
/// Most points a scatter series draws.
pub const MAX_SCATTER_POINTS: usize = 400;
/// x bins whose lowest and highest point a scatter always keeps.
pub const SCATTER_BINS: usize = 100;

/// What the reduction of one plot did: points given and points drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reduction {
    /// Finite points the plot was given.
    pub given: usize,
    /// Points drawn.
    pub drawn: usize,
}

impl Reduction {
    /// Adds one series' counts.
    pub fn add(&mut self, given: usize, drawn: usize) {
        self.given += given;
        self.drawn += drawn;
    }

    /// The note a reduced plot carries, `None` when nothing was left out:
    /// "194 069 points shown as 2 398 (lowest and highest per x bin kept)".
    pub fn note(&self) -> Option<String> {
        (self.drawn < self.given).then(|| {
            format!(
                "{} points shown as {} (lowest and highest per x bin kept)",
                group_digits(self.given),
                group_digits(self.drawn)
            )
        })
    }
}

/// `194069` → "194 069" (a thin space would not survive every font).
pub fn group_digits(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::with_capacity(s.len() + s.len() / 3);
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(c);
    }
    out
}

/// The SVG without repeated `<circle …/>` elements: plotters writes
/// whole-pixel coordinates, so two dots of one series on the same pixel are
/// the same text — drawing it once looks the same and a dense scatter
/// shrinks by its overlap. The dots also lose the attributes that say
/// SVG's defaults (`opacity="1"`, `stroke="none" stroke-width="1"`):
/// 90 bytes a dot become 50.
pub fn drop_repeated_dots(svg: String) -> String {
    let mut seen = std::collections::HashSet::new();
    let mut out = String::with_capacity(svg.len());
    for line in svg.split_inclusive('\n') {
        if line.trim_start().starts_with("<circle") {
            let short = line
                .replace(" opacity=\"1\"", "")
                .replace(" stroke=\"none\" stroke-width=\"1\"", "");
            if seen.insert(short.clone()) {
                out.push_str(&short);
            }
            continue;
        }
        out.push_str(line);
    }
    out
}

/// The bin of `x` among `bins` equal bins over [lo, hi].
fn bin_of(x: f64, lo: f64, hi: f64, bins: usize) -> usize {
    if hi <= lo {
        return 0;
    }
    (((x - lo) / (hi - lo) * bins as f64) as usize).min(bins - 1)
}

fn x_range(points: &[(f64, f64)]) -> (f64, f64) {
    points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        })
}

/// A line (finite points, in drawing order) reduced to first, lowest,
/// highest and last point of every run of consecutive points in one of
/// `bins` x bins; unchanged when it has at most `2 × bins` points. A line
/// that sweeps the range many times (repeated runs of a dense line) would
/// still keep 4 points per bin per sweep: then the points are taken in x
/// order, one run per bin — the envelope the sweeps draw together.
pub fn line(points: &[(f64, f64)], bins: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * bins || bins == 0 {
        return points.to_vec();
    }
    let out = runs(points, bins);
    if out.len() <= 4 * bins {
        return out;
    }
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    runs(&sorted, bins)
}

/// First, lowest, highest and last point of every run of consecutive
/// points in one x bin.
fn runs(points: &[(f64, f64)], bins: usize) -> Vec<(f64, f64)> {
    let (lo, hi) = x_range(points);
    let mut out = Vec::with_capacity(4 * bins);
    let mut start = 0;
    while start < points.len() {
        let b = bin_of(points[start].0, lo, hi, bins);
        let mut end = start + 1;
        while end < points.len() && bin_of(points[end].0, lo, hi, bins) == b {
            end += 1;
        }
        let run = &points[start..end];
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in run.iter().enumerate() {
            if p.1 < run[imin].1 {
                imin = i;
            }
            if p.1 > run[imax].1 {
                imax = i;
            }
        }
        let mut keep = [0, imin.min(imax), imin.max(imax), run.len() - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(run[k]);
                last = k;
            }
        }
        start = end;
    }
    out
}

/// A scatter (finite points) reduced to at most about `max` points: the
/// lowest and highest of each of `bins` x bins, then every k-th of the
/// rest, in their original order; unchanged when it has at most `max`.
pub fn scatter(points: &[(f64, f64)], max: usize, bins: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || bins == 0 {
        return points.to_vec();
    }
    let (lo, hi) = x_range(points);
    let mut low: Vec<Option<usize>> = vec![None; bins];
    let mut high: Vec<Option<usize>> = vec![None; bins];
    for (i, p) in points.iter().enumerate() {
        let b = bin_of(p.0, lo, hi, bins);
        if low[b].is_none_or(|j| p.1 < points[j].1) {
            low[b] = Some(i);
        }
        if high[b].is_none_or(|j| p.1 > points[j].1) {
            high[b] = Some(i);
        }
    }
    let mut keep = vec![false; points.len()];
    let mut kept = 0;
    for i in low.into_iter().chain(high).flatten() {
        if !keep[i] {
            keep[i] = true;
            kept += 1;
        }
    }
    let room = max.saturating_sub(kept);
    if room > 0 {
        let k = points.len().div_ceil(room);
        for i in (0..points.len()).step_by(k) {
            keep[i] = true;
        }
    }
    points
        .iter()
        .zip(keep)
        .filter_map(|(p, k)| k.then_some(*p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_line_keeps_its_envelope_and_its_spike() {
        // 100 000 points of a 5 mm sine along 800 mm, one spike at x = 400.
        let mut pts: Vec<(f64, f64)> = (0..100_000)
            .map(|i| {
                let x = i as f64 * 0.008;
                (x, (std::f64::consts::TAU * x / 5.0).sin())
            })
            .collect();
        pts[50_000].1 = 9.0;
        let out = line(&pts, LINE_BINS);
        assert!(out.len() <= 4 * LINE_BINS, "{}", out.len());
        assert!(out.contains(&pts[50_000]), "the spike is drawn");
        let top = out.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let bottom = out.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert_eq!(top, 9.0);
        assert!(bottom < -0.999);
        // In order: x never goes back.
        assert!(out.windows(2).all(|w| w[1].0 >= w[0].0));
        // Twelve sweeps back and forth: still at most 4 points per bin.
        let sweeps: Vec<(f64, f64)> = (0..12)
            .flat_map(|k| {
                pts.iter()
                    .step_by(10)
                    .map(move |p| (if k % 2 == 0 { p.0 } else { 800.0 - p.0 }, p.1))
            })
            .collect();
        let out = line(&sweeps, LINE_BINS);
        assert!(out.len() <= 4 * LINE_BINS, "{}", out.len());
        assert!(out.iter().any(|p| p.1 == 9.0));
        // A short line is drawn as it is.
        assert_eq!(line(&pts[..100], LINE_BINS), pts[..100].to_vec());
    }

    #[test]
    fn a_big_scatter_is_capped_and_keeps_its_worst_points() {
        let mut pts: Vec<(f64, f64)> = (0..200_000)
            .map(|i| ((i % 1000) as f64, ((i * 7919) % 101) as f64 / 100.0 - 0.5))
            .collect();
        pts[123_457] = (457.0, -6.0);
        pts[7] = (7.0, 5.0);
        let out = scatter(&pts, MAX_SCATTER_POINTS, SCATTER_BINS);
        assert!(
            out.len() <= MAX_SCATTER_POINTS + 2 * SCATTER_BINS,
            "{}",
            out.len()
        );
        assert!(out.contains(&(457.0, -6.0)) && out.contains(&(7.0, 5.0)));
        assert_eq!(scatter(&pts[..50], 100, 10), pts[..50].to_vec());
    }

    #[test]
    fn a_dot_on_a_pixel_already_drawn_is_left_out() {
        let svg = "<svg>\n<circle cx=\"1\" cy=\"2\"/>\n<circle cx=\"1\" cy=\"2\" opacity=\"1\"/>\n<circle cx=\"2\" cy=\"2\"/>\n</svg>\n";
        assert_eq!(
            drop_repeated_dots(svg.to_string()),
            "<svg>\n<circle cx=\"1\" cy=\"2\"/>\n<circle cx=\"2\" cy=\"2\"/>\n</svg>\n"
        );
    }

    #[test]
    fn the_note_counts_with_grouped_digits() {
        let mut r = Reduction::default();
        r.add(194_069, 2_398);
        assert_eq!(
            r.note().unwrap(),
            "194 069 points shown as 2 398 (lowest and highest per x bin kept)"
        );
        assert_eq!(Reduction { given: 5, drawn: 5 }.note(), None);
    }
}
