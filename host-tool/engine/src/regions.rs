//! Where a residual concentrates: the travel cut into equal cells per axis,
//! the residual RMS of each cell, and the worst of them as [`Region`]s.
//! One region type and one binning serve `compare` and `diagnose`, which
//! choose regions by two rules: [`worst_regions`] (`compare`: hot cells,
//! at least [`REGION_RATIO`]× the overall RMS, merged with their face
//! neighbours, boxes around their points) and [`worst_cells`] (`diagnose`:
//! the two worst cells of [`CELL_BINS`] per axis in the normalised
//! coordinates, with at least [`MIN_CELL_POINTS`] rows each, boxes of the
//! cells). `ratio` and `share` are compare's alone
//! (`None`, and absent from the JSON, for diagnose's cells).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::data::{Dataset, AXES, TARGETS};
use crate::features::Norm;

/// A box where the residual of one target concentrates.
#[derive(Clone, Debug, Serialize)]
pub struct Region {
    /// `ex`, `ey` or `ez`.
    pub target: String,
    /// Per axis present, mm: `[min, max]` of the points in the region
    /// (`compare`), or the cell's box (`diagnose`).
    pub bbox_mm: BTreeMap<String, [f64; 2]>,
    /// RMS of the residual inside the region, µm.
    pub rms_um: f64,
    /// That RMS over the target's overall residual RMS (`compare`'s
    /// regions; absent from `diagnose`'s cells).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio: Option<f64>,
    /// Points inside.
    pub points: usize,
    /// Share of the target's residual sum of squares that lies inside
    /// (0..1; `compare`'s regions only, like `ratio`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub share: Option<f64>,
    /// For a time series at one position (`diagnose`'s cells of data whose
    /// axes do not move): the time window `[from, to]` in s of `t_s`, the
    /// worst of [`TIME_WINDOWS`] equal ones — where it is worst is *when*
    /// (issue 24: "x 400…400, y 250…250" said nothing).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_s: Option<[f64; 2]>,
}

impl Region {
    /// Where the region is, in words: its box (`x 600…800, y 150…350`),
    /// or for a time window `t 3.0…6.0 h`.
    pub fn place(&self) -> String {
        match self.time_s {
            Some([lo, hi]) => format!("t {:.1}…{:.1} h", lo / 3600.0, hi / 3600.0),
            None => bbox_text(&self.bbox_mm),
        }
    }
}

/// Equal time windows a one-position time series is cut into to locate
/// the worst of its residual.
pub const TIME_WINDOWS: usize = 8;

/// A region's box as text, `x 600…800, y 150…350` (mm, whole numbers).
pub fn bbox_text(bbox_mm: &BTreeMap<String, [f64; 2]>) -> String {
    bbox_mm
        .iter()
        .map(|(a, [lo, hi])| format!("{a} {lo:.0}…{hi:.0}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The cell of `bins` equal slices that a position at fraction `frac` of
/// the travel (0 at its start, 1 at its end) falls in; outside the travel,
/// the first or last.
pub fn bin_index(frac: f64, bins: usize) -> usize {
    (frac * bins as f64)
        .floor()
        .clamp(0.0, bins.saturating_sub(1) as f64) as usize
}

/// The residual inside one cell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellSum {
    /// Rows inside.
    pub points: usize,
    /// Sum of the squared residuals inside, µm².
    pub ss: f64,
}

impl CellSum {
    /// Residual RMS inside, µm.
    pub fn rms(&self) -> f64 {
        (self.ss / self.points as f64).sqrt()
    }
}

/// Rows and residual sum of squares per cell, from (cell, residual) pairs.
pub fn cell_sums<K: Ord>(items: impl IntoIterator<Item = (K, f64)>) -> BTreeMap<K, CellSum> {
    let mut cells: BTreeMap<K, CellSum> = BTreeMap::new();
    for (k, v) in items {
        let e = cells.entry(k).or_default();
        e.points += 1;
        e.ss += v * v;
    }
    cells
}

/// Coarse grid of `compare`'s worst regions: bins per axis.
pub const REGION_BINS: usize = 4;
/// At most this many regions per target.
pub const MAX_REGIONS: usize = 3;
/// A cell counts as "worse" when its RMS is at least this many times the
/// target's overall residual RMS.
pub const REGION_RATIO: f64 = 1.25;

/// Where target `t`'s residual concentrates: the travel is cut into `bins`
/// equal slices per axis present, the residual RMS of each cell is
/// computed, cells at least `REGION_RATIO`× the overall RMS are merged with
/// their face neighbours, and each merged group is reported as the bounding
/// box of its points, worst first. When no cell stands out, the single worst
/// cell is returned with its (small) ratio, so the answer says "uniform"
/// rather than nothing.
pub fn worst_regions(
    data: &Dataset,
    t: usize,
    residual: &[Option<f64>],
    bins: usize,
    max_regions: usize,
) -> Vec<Region> {
    let bins = bins.max(1);
    let axes = data.axes();
    let rows: Vec<(usize, f64)> = residual
        .iter()
        .enumerate()
        .filter_map(|(r, v)| v.map(|v| (r, v)))
        .collect();
    if rows.is_empty() {
        return Vec::new();
    }
    let total_ss: f64 = rows.iter().map(|(_, v)| v * v).sum();
    let overall_rms = (total_ss / rows.len() as f64).sqrt();
    let mut lo = [0.0; 3];
    let mut span = [0.0; 3];
    for &a in &axes {
        let (l, h) = rows
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (r, _)| {
                let p = data.pos(a, *r);
                (l.min(p), h.max(p))
            });
        lo[a] = l;
        span[a] = h - l;
    }
    let cell_of = |r: usize| -> [usize; 3] {
        let mut c = [0; 3];
        for &a in &axes {
            if span[a] > 0.0 {
                c[a] = bin_index((data.pos(a, r) - lo[a]) / span[a], bins);
            }
        }
        c
    };
    let cells = cell_sums(rows.iter().map(|&(r, v)| (cell_of(r), v)));
    let cell_rms = |k: &[usize; 3]| -> f64 { cells[k].rms() };
    let hot: Vec<[usize; 3]> = cells
        .keys()
        .filter(|k| overall_rms > 0.0 && cell_rms(k) >= REGION_RATIO * overall_rms)
        .copied()
        .collect();
    // Connected components of hot cells (face neighbours).
    let mut groups: Vec<Vec<[usize; 3]>> = Vec::new();
    let mut seen: Vec<[usize; 3]> = Vec::new();
    for &start in &hot {
        if seen.contains(&start) {
            continue;
        }
        let mut group = vec![start];
        seen.push(start);
        let mut i = 0;
        while i < group.len() {
            let c = group[i];
            for &n in &hot {
                let dist: usize = (0..3).map(|a| c[a].abs_diff(n[a])).sum();
                if dist == 1 && !seen.contains(&n) {
                    seen.push(n);
                    group.push(n);
                }
            }
            i += 1;
        }
        groups.push(group);
    }
    if groups.is_empty() {
        if let Some(worst) = cells
            .keys()
            .copied()
            .max_by(|a, b| cell_rms(a).total_cmp(&cell_rms(b)))
        {
            groups.push(vec![worst]);
        }
    }
    let mut regions: Vec<Region> = groups
        .iter()
        .map(|g| {
            let members: Vec<(usize, f64)> = rows
                .iter()
                .copied()
                .filter(|(r, _)| g.contains(&cell_of(*r)))
                .collect();
            let ss: f64 = members.iter().map(|(_, v)| v * v).sum();
            let rms = (ss / members.len() as f64).sqrt();
            let mut bbox_mm = BTreeMap::new();
            for &a in &axes {
                let (l, h) =
                    members
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (r, _)| {
                            let p = data.pos(a, *r);
                            (l.min(p), h.max(p))
                        });
                bbox_mm.insert(AXES[a].to_string(), [l, h]);
            }
            Region {
                target: TARGETS[t].to_string(),
                bbox_mm,
                rms_um: rms,
                ratio: Some(ratio(rms, overall_rms)),
                points: members.len(),
                share: Some(ratio(ss, total_ss)),
                time_s: None,
            }
        })
        .collect();
    regions.sort_by(|a, b| b.rms_um.total_cmp(&a.rms_um));
    regions.truncate(max_regions);
    regions
}

/// `part / whole`, 0 when the whole is 0 (a region's ratio and share).
fn ratio(part: f64, whole: f64) -> f64 {
    if whole > 0.0 {
        part / whole
    } else {
        0.0
    }
}

/// Cells per axis of `diagnose`'s worst cells.
pub const CELL_BINS: usize = 4;
/// Fewest rows a cell needs to be one of `diagnose`'s worst cells.
pub const MIN_CELL_POINTS: usize = 5;
/// How many worst cells `diagnose` reports per target.
pub const TOP_CELLS: usize = 2;

/// `diagnose`'s worst cells of target `t`: the travel in the normalised
/// coordinates of `norm` cut into [`CELL_BINS`] slices per axis, the
/// residual RMS (`resid[i]` of data row `rows[i]`) of each cell with at
/// least [`MIN_CELL_POINTS`] rows, and the [`TOP_CELLS`] worst as the
/// cells' boxes.
pub fn worst_cells(
    data: &Dataset,
    norm: &Norm,
    t: usize,
    rows: &[usize],
    resid: &[f64],
) -> Vec<Region> {
    if let Some(w) = worst_windows(data, t, rows, resid) {
        return w;
    }
    let cells_f = CELL_BINS as f64;
    let axes = data.axes();
    let cells = cell_sums(rows.iter().zip(resid).map(|(&r, &v)| {
        let key: Vec<usize> = axes
            .iter()
            .map(|&a| bin_index((norm.u(a, data.pos(a, r)) + 1.0) / 2.0, CELL_BINS))
            .collect();
        (key, v)
    }));
    let mut v: Vec<(Vec<usize>, f64, CellSum)> = cells
        .into_iter()
        .filter(|(_, c)| c.points >= MIN_CELL_POINTS)
        .map(|(k, c)| (k, c.rms(), c))
        .collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1));
    v.into_iter()
        .take(TOP_CELLS)
        .map(|(k, rms, c)| {
            let bbox = axes
                .iter()
                .zip(&k)
                .map(|(&a, &c)| {
                    let lo =
                        norm.centre_mm[a] + norm.half_span_mm[a] * (2.0 * c as f64 / cells_f - 1.0);
                    let hi = lo + 2.0 * norm.half_span_mm[a] / cells_f;
                    (AXES[a].to_string(), [lo, hi])
                })
                .collect();
            Region {
                target: TARGETS[t].into(),
                bbox_mm: bbox,
                rms_um: rms,
                ratio: None,
                points: c.points,
                share: None,
                time_s: None,
            }
        })
        .collect()
}

/// [`worst_cells`] of a time series at one position: the worst
/// [`TOP_CELLS`] of [`TIME_WINDOWS`] equal windows of `t_s` (each with at
/// least [`MIN_CELL_POINTS`] readings); `None` when the data's axes move or
/// it has no `t_s`.
fn worst_windows(data: &Dataset, t: usize, rows: &[usize], resid: &[f64]) -> Option<Vec<Region>> {
    let ts = data.t_s.as_ref()?;
    if !data.varying_axes().is_empty() || rows.is_empty() {
        return None;
    }
    let (lo, hi) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &r| {
            (l.min(ts[r]), h.max(ts[r]))
        });
    let width = (hi - lo) / TIME_WINDOWS as f64;
    if width <= 0.0 {
        return None;
    }
    let cells = cell_sums(
        rows.iter()
            .zip(resid)
            .map(|(&r, &v)| (vec![bin_index((ts[r] - lo) / (hi - lo), TIME_WINDOWS)], v)),
    );
    let mut v: Vec<(usize, f64, CellSum)> = cells
        .into_iter()
        .filter(|(_, c)| c.points >= MIN_CELL_POINTS)
        .map(|(k, c)| (k[0], c.rms(), c))
        .collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1));
    let bbox: BTreeMap<String, [f64; 2]> = data
        .axes()
        .into_iter()
        .map(|a| {
            let p = data.pos(a, rows[0]);
            (AXES[a].to_string(), [p, p])
        })
        .collect();
    Some(
        v.into_iter()
            .take(TOP_CELLS)
            .map(|(k, rms, c)| Region {
                target: TARGETS[t].into(),
                bbox_mm: bbox.clone(),
                rms_um: rms,
                ratio: None,
                points: c.points,
                share: None,
                time_s: Some([lo + k as f64 * width, lo + (k + 1) as f64 * width]),
            })
            .collect(),
    )
}
