//! Where does a model fail? Statistics of the residual (measured error −
//! model) per target, the regions where it concentrates, and how it depends
//! on every position axis and channel. The HTML page that shows them is the
//! CLI's (`trueaxis::report::compare`).
//!
//! Everything here works on a [`Dataset`] and the model's predictions as
//! plain vectors (`[Option<Vec<f64>>; 3]`, µm per row), not on a model type:
//! `compare` feeds it `FittedModel::predict`, `diagnose` and `improve` can
//! feed it any intermediate fit, and the tests feed it hand-made numbers.
//!
//! Percentiles are of |residual| with linear interpolation between order
//! statistics (Hyndman–Fan type 7, what numpy and R use by default), so a
//! reader can reproduce them. "Before" is the raw measured error (no
//! compensation), "after" the residual (what is left once the model's
//! correction is applied).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::data::{Dataset, AXES, TARGETS};

pub use crate::lines::{dense_lines, planes, plot_num, Line, Plane, SNAP_MM};
pub use crate::regions::{
    bbox_text, worst_regions, Region, MAX_REGIONS, REGION_BINS, REGION_RATIO,
};

/// Summary statistics of a set of errors or residuals, µm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Number of values.
    pub points: usize,
    /// Root mean square.
    pub rms_um: f64,
    /// Mean (signed).
    pub mean_um: f64,
    /// Largest |value|.
    pub max_abs_um: f64,
    /// Peak to valley: max − min.
    pub pv_um: f64,
    /// Median of |value|.
    pub p50_abs_um: f64,
    /// 95th percentile of |value|.
    pub p95_abs_um: f64,
    /// 99th percentile of |value|.
    pub p99_abs_um: f64,
}

impl ErrorStats {
    /// Statistics of `values`; `None` when there are none. Non-finite
    /// values are not expected (the data set is validated) and are skipped.
    pub fn of(values: &[f64]) -> Option<ErrorStats> {
        let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut abs: Vec<f64> = v.iter().map(|x| x.abs()).collect();
        abs.sort_by(f64::total_cmp);
        Some(ErrorStats {
            points: v.len(),
            rms_um: rms,
            mean_um: mean,
            max_abs_um: abs[abs.len() - 1],
            pv_um: max - min,
            p50_abs_um: percentile(&abs, 50.0),
            p95_abs_um: percentile(&abs, 95.0),
            p99_abs_um: percentile(&abs, 99.0),
        })
    }
}

/// The `p`-th percentile (0..=100) of ascending `sorted` values, linear
/// between order statistics (type 7). NaN for an empty slice.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let h = (n - 1) as f64 * (p / 100.0).clamp(0.0, 1.0);
            let lo = h.floor() as usize;
            let hi = (lo + 1).min(n - 1);
            sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
        }
    }
}

/// Per-target result of a comparison.
#[derive(Clone, Debug, Serialize)]
pub struct TargetResult {
    /// The residual (measured − model).
    #[serde(flatten)]
    pub after: ErrorStats,
    /// Held-out RMS from the model's own fit statistics (block hold-out), µm.
    pub held_out_rms_um: Option<f64>,
    /// The raw measured error, before compensation.
    pub before: ErrorStats,
    /// RMS before / RMS after (how many times smaller the error became).
    pub improvement: f64,
}

/// One bin of a residual profile along a channel.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Bin {
    /// Lower edge of the bin, in the channel's unit.
    pub lo: f64,
    /// Upper edge.
    pub hi: f64,
    /// Points in the bin.
    pub points: usize,
    /// Mean residual, µm.
    pub mean_um: f64,
    /// RMS residual, µm.
    pub rms_um: f64,
}

/// How the residual of one target depends on one channel (a position axis,
/// a temperature, the tool length, time, a direction).
#[derive(Clone, Debug, Serialize)]
pub struct ChannelProfile {
    /// The column name (`x_mm`, `T_bed_C`, `tool_mm`, `t_s`, `dir_x`).
    pub channel: String,
    /// `ex`, `ey` or `ez`.
    pub target: String,
    /// Pearson correlation of the residual with the channel (NaN → null
    /// when the channel is constant).
    pub corr: Option<f64>,
    /// Least-squares slope of the residual against the channel, µm per
    /// channel unit.
    pub slope_um_per_unit: Option<f64>,
    /// The unit of the slopes in words: `µm/mm` (a position, the tool
    /// length), `µm/K` (a temperature), `µm/s` (time), `µm per direction
    /// change` (a direction: the step from −1 to +1), `µm per unit` (an
    /// auxiliary column).
    pub slope_unit: String,
    /// Once position is accounted for (the residual and the channel both
    /// regressed on a cubic in the moving axes, cross terms included), the
    /// correlation of what is left of each. `None` for a position axis
    /// itself, and for a channel that position explains entirely (a
    /// temperature that only follows x cannot be told from x).
    pub partial_corr: Option<f64>,
    /// The slope of the residual against the channel once position is
    /// accounted for, in `slope_unit` (for a direction: the step from −1 to
    /// +1, twice the slope per unit).
    pub partial_slope: Option<f64>,
    /// The share of the residual's variance that the channel explains
    /// beyond position (0…1): what `compare` ranks channels by.
    pub explains_share: Option<f64>,
    /// The residual in up to 10 equal-width bins (2 for a direction).
    pub bins: Vec<Bin>,
}

/// A warning about the comparison itself (`data_hash_mismatch`, …): the
/// engine's one warning type.
pub use crate::warning::Warning;

/// Everything `compare` finds, serialised as its `--json` document.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// The data set's source.
    pub data: String,
    /// The model's spec (`cubic19`, `cubic19+periodic:…`).
    pub model: String,
    /// Rows in the data set.
    pub rows: usize,
    /// Rows of the file left out on load (empty, no error value; docs/cli.md
    /// § Measurement CSV: counted and said, never silently skipped).
    pub skipped_count: usize,
    /// Residual RMS per target, µm (same key as `fit --json`).
    pub rms_um: BTreeMap<String, f64>,
    /// Largest |residual| per target, µm.
    pub max_abs_um: BTreeMap<String, f64>,
    /// Residual peak to valley per target, µm.
    pub pv_um: BTreeMap<String, f64>,
    /// Held-out RMS per target from the model file, µm.
    pub held_out_rms_um: BTreeMap<String, f64>,
    /// Full statistics per target.
    pub targets: BTreeMap<String, TargetResult>,
    /// Where the residual concentrates, worst first within each target.
    pub worst_regions: Vec<Region>,
    /// Residual against every position axis and channel.
    pub channels: Vec<ChannelProfile>,
    /// Problems with the comparison (the data differ from the fitted data, …).
    pub warnings: Vec<Warning>,
    /// Path of the HTML report when one was written.
    pub report: Option<String>,
    /// rigid21 models: the residual per reading kind (ex … ez, angle and
    /// beam readings) after each set-up's own unknowns (docs/volumetric.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub readings: Option<Vec<crate::model::rigid21::ReadingResidual>>,
}

/// Residual (measured − predicted) per row for target `t`; `None` where the
/// target was not measured on the row or the model has no prediction.
pub fn residuals(data: &Dataset, predicted: &[Option<Vec<f64>>; 3], t: usize) -> Vec<Option<f64>> {
    let mut out = vec![None; data.len()];
    if let Some(pred) = &predicted[t] {
        for (row, v) in data.measured(t) {
            if let Some(p) = pred.get(row) {
                if p.is_finite() {
                    out[row] = Some(v - p);
                }
            }
        }
    }
    out
}

/// Compares the data with the predictions. `held_out_rms_um` comes from the
/// model's fit statistics (the held-out RMS cannot be recomputed from
/// predictions alone).
pub fn compare(
    data: &Dataset,
    model: &str,
    predicted: &[Option<Vec<f64>>; 3],
    held_out_rms_um: [Option<f64>; 3],
) -> Comparison {
    let mut c = Comparison {
        data: data.source.clone(),
        model: model.to_string(),
        rows: data.len(),
        skipped_count: data.skipped.len(),
        rms_um: BTreeMap::new(),
        max_abs_um: BTreeMap::new(),
        pv_um: BTreeMap::new(),
        held_out_rms_um: BTreeMap::new(),
        targets: BTreeMap::new(),
        worst_regions: Vec::new(),
        channels: Vec::new(),
        warnings: Vec::new(),
        report: None,
        readings: None,
    };
    for t in data.targets() {
        let name = TARGETS[t].to_string();
        let res = residuals(data, predicted, t);
        let after_v: Vec<f64> = res.iter().flatten().copied().collect();
        let before_v: Vec<f64> = data.measured(t).map(|(_, v)| v).collect();
        let (Some(after), Some(before)) = (ErrorStats::of(&after_v), ErrorStats::of(&before_v))
        else {
            c.warnings.push(Warning {
                code: "no_prediction".into(),
                detail: format!("the model predicts nothing for {name}, which the data measure"),
            });
            continue;
        };
        c.rms_um.insert(name.clone(), after.rms_um);
        c.max_abs_um.insert(name.clone(), after.max_abs_um);
        c.pv_um.insert(name.clone(), after.pv_um);
        if let Some(h) = held_out_rms_um[t] {
            c.held_out_rms_um.insert(name.clone(), h);
        }
        c.targets.insert(
            name.clone(),
            TargetResult {
                after,
                held_out_rms_um: held_out_rms_um[t],
                before,
                improvement: if after.rms_um > 0.0 {
                    before.rms_um / after.rms_um
                } else {
                    f64::INFINITY
                },
            },
        );
        c.worst_regions
            .extend(worst_regions(data, t, &res, REGION_BINS, MAX_REGIONS));
        let basis = PositionBasis::new(data, &res);
        for (channel, values) in channels(data) {
            let binary = channel.starts_with("dir_");
            let mut p = channel_profile(&channel, &name, &values, &res, binary);
            if !is_position(&channel) {
                basis.partial(&mut p, &values, &res);
            }
            c.channels.push(p);
        }
    }
    c
}

/// The smallest share of the residual a channel must explain beyond
/// position to be listed by `compare` (5 %).
pub const RANK_MIN_SHARE: f64 = 0.05;

/// The channels of target `target` that explain a share of its residual
/// beyond position, most first (`explains_share` ≥ `min_share`): the
/// ranking `compare` prints.
pub fn ranked_channels<'a>(
    c: &'a Comparison,
    target: &str,
    min_share: f64,
) -> Vec<&'a ChannelProfile> {
    let mut v: Vec<&ChannelProfile> = c
        .channels
        .iter()
        .filter(|p| p.target == target && p.explains_share.is_some_and(|s| s >= min_share))
        .collect();
    v.sort_by(|a, b| {
        b.explains_share
            .unwrap_or(0.0)
            .total_cmp(&a.explains_share.unwrap_or(0.0))
    });
    v
}

/// `x_mm`, `y_mm`, `z_mm`: a position axis.
pub fn is_position(channel: &str) -> bool {
    matches!(channel, "x_mm" | "y_mm" | "z_mm")
}

/// The unit of a slope against `channel`.
fn slope_unit(channel: &str) -> &'static str {
    if channel.starts_with("T_") && channel.ends_with("_C") {
        "µm/K"
    } else if channel.ends_with("_mm") {
        "µm/mm"
    } else if channel == "t_s" {
        "µm/s"
    } else if channel.starts_with("dir_") {
        "µm per direction change"
    } else {
        "µm per unit"
    }
}

/// An orthonormal basis (over the rows where the residual is known) of a
/// cubic in the moving axes with cross terms: what "position" can explain.
struct PositionBasis {
    /// Row indices the basis is over.
    rows: Vec<usize>,
    /// Orthonormal columns over `rows`.
    q: Vec<Vec<f64>>,
}

impl PositionBasis {
    fn new(data: &Dataset, residual: &[Option<f64>]) -> PositionBasis {
        let rows: Vec<usize> = (0..residual.len())
            .filter(|&i| residual[i].is_some_and(f64::is_finite))
            .collect();
        // Each moving axis scaled to −1…1 (conditioning), then its powers
        // and the pairwise products of the first powers.
        let mut cols: Vec<Vec<f64>> = vec![vec![1.0; rows.len()]];
        let mut firsts = Vec::new();
        for a in data.varying_axes() {
            let p = data.pos_mm[a].as_ref().expect("a varying axis is present");
            let (lo, hi) = rows
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &i| {
                    (l.min(p[i]), h.max(p[i]))
                });
            if hi <= lo || hi.is_nan() {
                continue;
            }
            let u: Vec<f64> = rows
                .iter()
                .map(|&i| (2.0 * p[i] - lo - hi) / (hi - lo))
                .collect();
            for k in 1..=3 {
                cols.push(u.iter().map(|v| v.powi(k)).collect());
            }
            firsts.push(u);
        }
        for i in 0..firsts.len() {
            for j in i + 1..firsts.len() {
                cols.push(
                    firsts[i]
                        .iter()
                        .zip(&firsts[j])
                        .map(|(a, b)| a * b)
                        .collect(),
                );
            }
        }
        // Modified Gram–Schmidt; a column that is (nearly) a combination of
        // the others (a grid with two levels on an axis) is dropped.
        let mut q: Vec<Vec<f64>> = Vec::new();
        for mut c in cols {
            let norm0 = dot(&c, &c).sqrt();
            for e in &q {
                let d = dot(&c, e);
                c.iter_mut().zip(e).for_each(|(v, w)| *v -= d * w);
            }
            let norm = dot(&c, &c).sqrt();
            if norm0 > 0.0 && norm > 1e-8 * norm0 {
                c.iter_mut().for_each(|v| *v /= norm);
                q.push(c);
            }
        }
        PositionBasis { rows, q }
    }

    /// `v` on the basis rows with its projection on the basis removed.
    fn residual_of(&self, v: &[f64]) -> Vec<f64> {
        let mut r: Vec<f64> = self.rows.iter().map(|&i| v[i]).collect();
        for e in &self.q {
            let d = dot(&r, e);
            r.iter_mut().zip(e).for_each(|(x, w)| *x -= d * w);
        }
        r
    }

    /// Fills `partial_corr`, `partial_slope` and `explains_share` of `p`.
    fn partial(&self, p: &mut ChannelProfile, channel: &[f64], residual: &[Option<f64>]) {
        // A row without a channel value (an empty auxiliary cell) leaves
        // the basis's rows: such a channel keeps only its raw statistics.
        if self.rows.iter().any(|&i| !channel[i].is_finite()) || self.rows.len() <= self.q.len() + 2
        {
            return;
        }
        let res: Vec<f64> = residual.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
        let r = self.residual_of(&res);
        let c = self.residual_of(channel);
        let c_all: Vec<f64> = self.rows.iter().map(|&i| channel[i]).collect();
        let mean = c_all.iter().sum::<f64>() / c_all.len() as f64;
        let var_c: f64 = c_all.iter().map(|v| (v - mean).powi(2)).sum();
        let (scc, srr, src) = (dot(&c, &c), dot(&r, &r), dot(&r, &c));
        let res_all: Vec<f64> = self.rows.iter().map(|&i| res[i]).collect();
        let rmean = res_all.iter().sum::<f64>() / res_all.len() as f64;
        let var_r: f64 = res_all.iter().map(|v| (v - rmean).powi(2)).sum();
        // Position explains the channel (all but 1e-6 of its variance):
        // nothing is left to tell it from position.
        if var_c <= 0.0 || scc <= 1e-6 * var_c || srr <= 0.0 || var_r <= 0.0 {
            return;
        }
        let slope = src / scc;
        p.partial_corr = Some(src / (scc * srr).sqrt());
        p.partial_slope = Some(if p.channel.starts_with("dir_") {
            2.0 * slope
        } else {
            slope
        });
        p.explains_share = Some(src * src / scc / var_r);
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Every column the residual can be plotted against, with its values:
/// position axes, temperatures, tool length, time, directions, and every
/// numeric auxiliary column (`humidity_pct`, a second laser's reading…:
/// docs/cli.md § Measurement CSV keeps a column it does not know as an auxiliary channel and
/// reports it — a residual that follows humidity is exactly what compare
/// should show). An auxiliary column counts as numeric when every
/// non-empty cell is a finite number and at least one is; empty cells are
/// left out of its profile.
pub fn channels(data: &Dataset) -> Vec<(String, Vec<f64>)> {
    let mut out = Vec::new();
    for a in data.axes() {
        if let Some(p) = &data.pos_mm[a] {
            out.push((format!("{}_mm", AXES[a]), p.clone()));
        }
    }
    for ch in &data.temps {
        out.push((format!("T_{}_C", ch.name), ch.temp_c.clone()));
    }
    if let Some(v) = &data.tool_mm {
        out.push(("tool_mm".into(), v.clone()));
    }
    if let Some(v) = &data.t_s {
        out.push(("t_s".into(), v.clone()));
    }
    for (name, dir) in AXES.iter().zip(&data.dir) {
        if let Some(d) = dir {
            out.push((
                format!("dir_{name}"),
                d.iter().map(|&v| f64::from(v)).collect(),
            ));
        }
    }
    for ch in &data.aux {
        if let Some(values) = numeric_cells(&ch.cells) {
            out.push((ch.name.clone(), values));
        }
    }
    out
}

/// The cells as numbers (NaN for an empty cell), or `None` when a
/// non-empty cell is not a finite number or no cell has a value.
fn numeric_cells(cells: &[String]) -> Option<Vec<f64>> {
    let mut any = false;
    let values = cells
        .iter()
        .map(|c| {
            let c = c.trim();
            if c.is_empty() {
                return Some(f64::NAN);
            }
            any = true;
            c.parse::<f64>().ok().filter(|v| v.is_finite())
        })
        .collect::<Option<Vec<f64>>>()?;
    any.then_some(values)
}

/// The residual of one target against one channel: correlation, slope and
/// binned mean/RMS (10 equal-width bins; for a direction, the −1 and +1
/// groups).
pub fn channel_profile(
    channel: &str,
    target: &str,
    values: &[f64],
    residual: &[Option<f64>],
    binary: bool,
) -> ChannelProfile {
    let pairs: Vec<(f64, f64)> = residual
        .iter()
        .zip(values)
        .filter_map(|(r, x)| r.map(|r| (*x, r)))
        .filter(|(x, r)| x.is_finite() && r.is_finite())
        .collect();
    let n = pairs.len() as f64;
    let (mut corr, mut slope) = (None, None);
    if pairs.len() >= 2 {
        let mx = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let my = pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let syy: f64 = pairs.iter().map(|p| (p.1 - my).powi(2)).sum();
        let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        if sxx > 0.0 {
            slope = Some(sxy / sxx);
            if syy > 0.0 {
                corr = Some(sxy / (sxx * syy).sqrt());
            }
        }
    }
    let lo = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let hi = pairs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let mut bins = Vec::new();
    if lo.is_finite() && hi.is_finite() {
        let edges: Vec<(f64, f64)> = if binary {
            vec![(-1.0, -1.0), (1.0, 1.0)]
        } else if hi > lo {
            let k = 10;
            (0..k)
                .map(|i| {
                    (
                        lo + (hi - lo) * i as f64 / k as f64,
                        lo + (hi - lo) * (i + 1) as f64 / k as f64,
                    )
                })
                .collect()
        } else {
            vec![(lo, hi)]
        };
        let last = edges.len() - 1;
        for (i, &(a, b)) in edges.iter().enumerate() {
            let inside: Vec<f64> = pairs
                .iter()
                .filter(|(x, _)| {
                    if binary {
                        *x == a
                    } else {
                        *x >= a && (*x < b || (i == last && *x <= b))
                    }
                })
                .map(|p| p.1)
                .collect();
            if inside.is_empty() {
                continue;
            }
            let m = inside.len() as f64;
            bins.push(Bin {
                lo: a,
                hi: b,
                points: inside.len(),
                mean_um: inside.iter().sum::<f64>() / m,
                rms_um: (inside.iter().map(|v| v * v).sum::<f64>() / m).sqrt(),
            });
        }
    }
    ChannelProfile {
        channel: channel.to_string(),
        target: target.to_string(),
        corr,
        slope_um_per_unit: slope,
        slope_unit: slope_unit(channel).to_string(),
        partial_corr: None,
        partial_slope: None,
        explains_share: None,
        bins,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{AuxChannel, TempChannel};

    /// A bidirectional line along x measured 6 times while the machine
    /// warms: the residual is a cubic shape along x plus 1.5 µm/K of the
    /// bed temperature. A humidity column that follows x correlates with
    /// the residual far more than the temperature does — raw correlation
    /// ranks it first, although it explains nothing position does not.
    #[test]
    fn channels_are_ranked_by_what_they_explain_beyond_position() {
        let (mut x, mut t, mut temp, mut dir, mut hum, mut e) =
            (vec![], vec![], vec![], vec![], vec![], vec![]);
        let mut time = 0.0f64;
        for pass in 0..6 {
            for k in 0..=100 {
                let xi = if pass % 2 == 0 {
                    5.0 * k as f64
                } else {
                    500.0 - 5.0 * k as f64
                };
                time += 3.0;
                // Warm-up: 20 → 23 °C, with a small wobble.
                let tc = 20.0 + 3.0 * (1.0 - (-time / 900.0).exp()) + 0.05 * (time / 37.0).sin();
                let u = (xi - 250.0) / 250.0;
                x.push(xi);
                t.push(time);
                temp.push(tc);
                dir.push(if pass % 2 == 0 { 1 } else { -1 });
                hum.push(format!(
                    "{}",
                    40.0 + xi / 50.0 + 0.01 * (k as f64 * 1.7).sin()
                ));
                e.push(Some(15.0 * u * u * u - 3.0 * u + 1.5 * (tc - 21.5)));
            }
        }
        let data = Dataset {
            source: "test".into(),
            pos_mm: [Some(x), None, None],
            err_um: [Some(e), None, None],
            t_s: Some(t),
            dir: [Some(dir), None, None],
            temps: vec![TempChannel {
                name: "bed".into(),
                temp_c: temp,
            }],
            aux: vec![AuxChannel {
                name: "humidity_pct".into(),
                cells: hum,
            }],
            ..Dataset::default()
        };
        let n = data.len();
        let c = compare(&data, "none", &[Some(vec![0.0; n]), None, None], [None; 3]);
        let get = |ch: &str| c.channels.iter().find(|p| p.channel == ch).unwrap();
        let (hum, bed) = (get("humidity_pct"), get("T_bed_C"));
        assert!(
            hum.corr.unwrap().abs() > 2.0 * bed.corr.unwrap().abs(),
            "{hum:?} {bed:?}"
        );
        let ranked = ranked_channels(&c, "ex", RANK_MIN_SHARE);
        assert_eq!(ranked[0].channel, "T_bed_C", "{ranked:?}");
        assert_eq!(bed.slope_unit, "µm/K");
        let slope = bed.partial_slope.unwrap();
        assert!((slope - 1.5).abs() < 0.05, "{slope}");
        assert!(hum.explains_share.unwrap() < 0.01, "{hum:?}");
        assert!(!ranked
            .iter()
            .any(|p| p.channel == "humidity_pct" || p.channel == "dir_x"));
        // Position itself is not ranked against itself.
        assert!(get("x_mm").partial_corr.is_none());
        assert_eq!(get("dir_x").slope_unit, "µm per direction change");
    }

    #[test]
    fn numeric_aux_cells() {
        let s = |v: &[&str]| v.iter().map(|c| c.to_string()).collect::<Vec<_>>();
        let v = numeric_cells(&s(&["41.5", "", " 43 "])).unwrap();
        assert_eq!(v[0], 41.5);
        assert!(v[1].is_nan());
        assert_eq!(v[2], 43.0);
        assert_eq!(numeric_cells(&s(&["41.5", "Anna"])), None);
        assert_eq!(numeric_cells(&s(&["1", "NaN"])), None);
        assert_eq!(numeric_cells(&s(&["", ""])), None);
    }

    #[test]
    fn stats_match_hand_computation() {
        let s = ErrorStats::of(&[1.0, -2.0, 3.0, -4.0]).unwrap();
        assert_eq!(s.points, 4);
        assert!((s.rms_um - (30.0f64 / 4.0).sqrt()).abs() < 1e-12);
        assert!((s.mean_um + 0.5).abs() < 1e-12);
        assert_eq!(s.max_abs_um, 4.0);
        assert_eq!(s.pv_um, 7.0);
        // |e| sorted 1 2 3 4: p50 = 2.5, p95 = 3 + 0.85·1 = 3.85 (type 7).
        assert!((s.p50_abs_um - 2.5).abs() < 1e-12);
        assert!((s.p95_abs_um - 3.85).abs() < 1e-12);
        assert!(ErrorStats::of(&[]).is_none());
    }

    #[test]
    fn percentile_edges() {
        assert!(percentile(&[], 50.0).is_nan());
        assert_eq!(percentile(&[7.0], 99.0), 7.0);
        assert_eq!(percentile(&[0.0, 10.0], 0.0), 0.0);
        assert_eq!(percentile(&[0.0, 10.0], 100.0), 10.0);
        assert_eq!(percentile(&[0.0, 10.0], 30.0), 3.0);
    }

    fn grid_data(f: impl Fn(f64, f64) -> f64) -> Dataset {
        let mut x = Vec::new();
        let mut y = Vec::new();
        let mut e = Vec::new();
        for iy in 0..11 {
            for ix in 0..17 {
                let (px, py) = (50.0 * f64::from(ix), 50.0 * f64::from(iy));
                x.push(px);
                y.push(py);
                e.push(Some(f(px, py)));
            }
        }
        Dataset {
            source: "test".into(),
            pos_mm: [Some(x), Some(y), None],
            err_um: [Some(e), None, None],
            ..Dataset::default()
        }
    }

    #[test]
    fn worst_region_finds_the_hot_corner() {
        // Small noise-like pattern everywhere, a bump in x ≥ 600, y ≥ 375.
        let d = grid_data(|x, y| {
            let base = 0.1 * ((x * 0.37 + y * 0.11).sin());
            if x >= 600.0 && y >= 375.0 {
                base + 2.0
            } else {
                base
            }
        });
        let pred = [Some(vec![0.0; d.len()]), None, None];
        let res = residuals(&d, &pred, 0);
        let r = worst_regions(&d, 0, &res, 4, 3);
        assert!(!r.is_empty());
        let top = &r[0];
        assert_eq!(top.target, "ex");
        assert!(top.bbox_mm["x"][0] >= 600.0, "{top:?}");
        assert!(top.bbox_mm["y"][0] >= 375.0, "{top:?}");
        assert!(top.ratio.unwrap() > 2.0);
        assert!(top.share.unwrap() > 0.9);
    }

    #[test]
    fn uniform_residual_gives_one_region_near_ratio_one() {
        let d = grid_data(|x, y| {
            if ((x + y) / 50.0) as i64 % 2 == 0 {
                1.0
            } else {
                -1.0
            }
        });
        let pred = [Some(vec![0.0; d.len()]), None, None];
        let res = residuals(&d, &pred, 0);
        let r = worst_regions(&d, 0, &res, 4, 3);
        assert_eq!(r.len(), 1);
        assert!((r[0].ratio.unwrap() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn channel_profile_sees_a_slope_and_a_step() {
        let x: Vec<f64> = (0..100).map(f64::from).collect();
        let res: Vec<Option<f64>> = x.iter().map(|v| Some(0.5 * v)).collect();
        let p = channel_profile("x_mm", "ex", &x, &res, false);
        assert!((p.corr.unwrap() - 1.0).abs() < 1e-12);
        assert!((p.slope_um_per_unit.unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(p.bins.len(), 10);
        assert_eq!(p.bins.iter().map(|b| b.points).sum::<usize>(), 100);
        let dir: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let res: Vec<Option<f64>> = dir.iter().map(|d| Some(2.0 * d)).collect();
        let p = channel_profile("dir_x", "ex", &dir, &res, true);
        assert_eq!(p.bins.len(), 2);
        assert_eq!(p.bins[0].mean_um, -2.0);
        assert_eq!(p.bins[1].mean_um, 2.0);
        // A constant channel has no correlation.
        let c = vec![20.0; 100];
        assert!(channel_profile("T_bed_C", "ex", &c, &res, false)
            .corr
            .is_none());
    }

    #[test]
    fn compare_reports_before_and_after() {
        let d = grid_data(|x, _| 0.01 * x);
        let pred: Vec<f64> = d.pos_mm[0]
            .as_ref()
            .unwrap()
            .iter()
            .map(|x| 0.01 * x - 0.5)
            .collect();
        let c = compare(
            &d,
            "cubic19",
            &[Some(pred), None, None],
            [Some(0.6), None, None],
        );
        let ex = &c.targets["ex"];
        assert!((ex.after.rms_um - 0.5).abs() < 1e-9);
        assert!((ex.after.pv_um).abs() < 1e-9);
        assert!(ex.before.rms_um > 4.0);
        assert_eq!(c.held_out_rms_um["ex"], 0.6);
        assert_eq!(c.rms_um.len(), 1);
        let json = serde_json::to_value(&c).unwrap();
        assert!(json["targets"]["ex"]["p95_abs_um"].is_number());
        assert!(json["targets"]["ex"]["before"]["rms_um"].is_number());
    }
}
