//! ISO 230-2 (positioning accuracy and repeatability of linear axes) from
//! bidirectional runs, with coverage factor 2 as in ISO 230-2:2006/2014 and
//! the formulas of ARCHITECTURE.md:
//!
//! x_ij = measured − target (the error column of the axis); per target i
//! and direction, x̄↑_i, x̄↓_i (means) and s↑_i, s↓_i (standard deviations
//! with n − 1); x̄_i = (x̄↑_i + x̄↓_i)/2; B_i = x̄↑_i − x̄↓_i; R↑_i = 4s↑_i;
//! R_i = max(2s↑_i + 2s↓_i + |B_i|, R↑_i, R↓_i); B = max|B_i|, B̄ = mean B_i;
//! R = max R_i; E↑ = max x̄↑ − min x̄↑; E = max(x̄↑, x̄↓) − min(x̄↑, x̄↓);
//! M = max x̄_i − min x̄_i; A↑ = max(x̄↑ + 2s↑) − min(x̄↑ − 2s↑);
//! A = max(x̄↑ + 2s↑, x̄↓ + 2s↓) − min(x̄↑ − 2s↑, x̄↓ − 2s↓).
//!
//! Readings are grouped into targets by position (within 1 µm) and into
//! directions by `dir_<axis>`. The data must lie on one line: if the other
//! axes take several values, the line with the most readings is evaluated
//! and the others are counted as ignored (never silently).

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::data::{Dataset, AXES, TARGETS};

/// Statistics of one target position.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetStats {
    /// Target position, mm.
    pub pos_mm: f64,
    /// Readings approached in the positive direction.
    pub n_up: usize,
    /// Readings approached in the negative direction.
    pub n_down: usize,
    /// x̄↑_i, µm.
    pub mean_up_um: f64,
    /// x̄↓_i, µm.
    pub mean_down_um: f64,
    /// x̄_i, µm.
    pub mean_um: f64,
    /// s↑_i (n − 1), µm.
    pub s_up_um: f64,
    /// s↓_i (n − 1), µm.
    pub s_down_um: f64,
    /// B_i = x̄↑_i − x̄↓_i, µm.
    #[serde(rename = "B_um")]
    pub b_um: f64,
    /// R↑_i = 4 s↑_i, µm.
    #[serde(rename = "R_up_um")]
    pub r_up_um: f64,
    /// R↓_i = 4 s↓_i, µm.
    #[serde(rename = "R_down_um")]
    pub r_down_um: f64,
    /// R_i, µm.
    #[serde(rename = "R_um")]
    pub r_um: f64,
}

/// The ISO 230-2 result of one axis; serialises to the JSON of docs/cli.md.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Iso230 {
    /// Axis name (`x`).
    pub axis: String,
    /// Number of target positions.
    pub targets: usize,
    /// Bidirectional runs: the smallest number of readings per target and
    /// direction (5 in a complete ISO 230-2 test).
    pub runs: usize,
    /// B = max |B_i|, µm.
    #[serde(rename = "B_um")]
    pub b_um: f64,
    /// B̄ = mean B_i (signed), µm.
    #[serde(rename = "B_mean_um")]
    pub b_mean_um: f64,
    /// R↑ = max R↑_i, µm.
    #[serde(rename = "R_up_um")]
    pub r_up_um: f64,
    /// R↓ = max R↓_i, µm.
    #[serde(rename = "R_down_um")]
    pub r_down_um: f64,
    /// R = max R_i, µm.
    #[serde(rename = "R_um")]
    pub r_um: f64,
    /// E↑, µm.
    #[serde(rename = "E_up_um")]
    pub e_up_um: f64,
    /// E↓, µm.
    #[serde(rename = "E_down_um")]
    pub e_down_um: f64,
    /// E, µm.
    #[serde(rename = "E_um")]
    pub e_um: f64,
    /// M, µm.
    #[serde(rename = "M_um")]
    pub m_um: f64,
    /// A↑, µm.
    #[serde(rename = "A_up_um")]
    pub a_up_um: f64,
    /// A↓, µm.
    #[serde(rename = "A_down_um")]
    pub a_down_um: f64,
    /// A, µm.
    #[serde(rename = "A_um")]
    pub a_um: f64,
    /// Per-target statistics, ascending position.
    pub per_target: Vec<TargetStats>,
    /// Readings evaluated.
    pub rows_used: usize,
    /// Readings of the data set not evaluated (other lines, no value for
    /// this axis' error).
    pub rows_ignored: usize,
    /// Rows of the file left out on load, before any of this (an empty
    /// row, a row with no error value at all).
    pub skipped_count: usize,
    /// Readings far outside the others at their target and direction
    /// ([`bad_readings`]): kept in every figure above — the standard's
    /// figures are right with them — and named, with what A and R would be
    /// without each (issue 24).
    pub flags: Vec<BadReading>,
}

/// A reading far outside the others at its target and direction.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BadReading {
    /// Data row (0-based).
    pub row: usize,
    /// Its line in the source file, when it came from one.
    pub line: Option<usize>,
    /// Its run (`pass_id`), when the file tells.
    pub run: Option<i64>,
    /// The target position, mm.
    pub target_mm: f64,
    /// +1 approached from below, −1 from above.
    pub dir: i8,
    /// The reading, µm.
    pub value_um: f64,
    /// The mean of the other readings at that target and direction, µm.
    pub others_mean_um: f64,
    /// A without this reading, µm.
    #[serde(rename = "A_without_um")]
    pub a_without_um: f64,
    /// R without this reading, µm.
    #[serde(rename = "R_without_um")]
    pub r_without_um: f64,
}

impl BadReading {
    /// `run 1, target 250 mm ↑: +93.000 µm against a mean of -21.000 µm of the other readings there; without it A would be 35.2 µm (not 205.0) and R 8.1 µm (not 205.0)`.
    pub fn text(&self, res: &Iso230) -> String {
        format!(
            "{}target {} mm {}: {:+.3} µm against a mean of {:+.3} µm of the other readings there; the standard's figures keep it, without it A would be {:.3} µm (not {:.3}) and R {:.3} µm (not {:.3})",
            self.run.map_or(String::new(), |r| format!("run {r}, ")),
            self.target_mm,
            if self.dir > 0 { "↑" } else { "↓" },
            self.value_um,
            self.others_mean_um,
            self.a_without_um,
            res.a_um,
            self.r_without_um,
            res.r_um
        )
    }
}

/// A reading is flagged when it lies more than this many standard
/// deviations from the mean of the others at its target and direction —
/// both their own s and the typical s of the run's target-directions (the
/// median): ~8·10⁻⁶ for a normal reading among four others.
pub const BAD_READING_K: f64 = 5.0;

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sample standard deviation (n − 1), as ISO 230-2 defines s.
fn std_n1(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// The largest of the values (−∞ when there are none).
pub fn max(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::NEG_INFINITY, f64::max)
}

/// The smallest of the values (+∞ when there are none).
pub fn min(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::INFINITY, f64::min)
}

/// The axis to evaluate when none is named: the only axis with both a
/// position and an error column and a direction column whose position
/// moves (an axis held at one position — y and z of a run along x — has
/// no targets to evaluate).
pub fn default_axis(data: &Dataset) -> std::result::Result<usize, AxisChoice> {
    let cands: Vec<usize> = data
        .varying_axes()
        .into_iter()
        .filter(|&a| data.err_um[a].is_some() && data.dir[a].is_some())
        .collect();
    match cands.as_slice() {
        [a] => Ok(*a),
        [] => Err(AxisChoice::NoAxis {
            file: data.source.clone(),
        }),
        _ => Err(AxisChoice::Several {
            file: data.source.clone(),
            axes: cands,
        }),
    }
}

/// Why [`default_axis`] cannot choose (a caller names its own way of
/// choosing: the CLI, `--axis`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AxisChoice {
    /// No axis can be evaluated.
    #[error("{file}: no moving axis has a position, an error and a direction column (x_mm, ex_um, dir_x); ISO 230-2 needs all three")]
    NoAxis {
        /// The data's source.
        file: String,
    },
    /// Several can: the caller must name one.
    #[error(
        "{file}: several axes could be evaluated ({}); expected one named",
        axis_names(axes)
    )]
    Several {
        /// The data's source.
        file: String,
        /// The axes that could be evaluated (0 = x).
        axes: Vec<usize>,
    },
}

/// `x, y`.
pub fn axis_names(axes: &[usize]) -> String {
    axes.iter().map(|&a| AXES[a]).collect::<Vec<_>>().join(", ")
}

/// Evaluates `axis` (0 = x) of `data`.
pub fn evaluate(data: &Dataset, axis: usize) -> Result<Iso230> {
    let mut res = figures(data, axis)?;
    res.flags = bad_readings(data, axis, &res);
    Ok(res)
}

/// The columns an ISO 230-2 evaluation reads: positions (mm), errors (µm,
/// `None` where not measured) and approach directions.
pub type Columns<'a> = (&'a [f64], &'a [Option<f64>], &'a [i8]);

/// The columns an ISO 230-2 evaluation of `axis` reads: its positions, its
/// error and its approach directions; `None` when one is missing.
pub fn readings_of(data: &Dataset, axis: usize) -> Option<Columns<'_>> {
    Some((
        data.pos_mm[axis].as_deref()?,
        data.err_um[axis].as_deref()?,
        data.dir[axis].as_deref()?,
    ))
}

/// The readings far outside the others at their target and direction
/// ([`BAD_READING_K`]), each with A and R evaluated without it; a group
/// needs 3 readings (2 others to have an s).
pub fn bad_readings(data: &Dataset, axis: usize, res: &Iso230) -> Vec<BadReading> {
    let Some((pos, err, dir)) = readings_of(data, axis) else {
        return Vec::new();
    };
    let mut s: Vec<f64> = res
        .per_target
        .iter()
        .flat_map(|t| [t.s_up_um, t.s_down_um])
        .collect();
    s.sort_by(f64::total_cmp);
    // Never below the finest step between two readings (a reading quantum:
    // on coarse readings most groups repeat one value and their s is 0).
    let mut vals: Vec<f64> = err.iter().flatten().copied().collect();
    vals.sort_by(f64::total_cmp);
    let step = vals
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 1e-9)
        .fold(f64::INFINITY, f64::min);
    let typical = s
        .get(s.len() / 2)
        .copied()
        .unwrap_or(0.0)
        .max(if step.is_finite() { step } else { 0.0 });
    let mut out = Vec::new();
    for t in &res.per_target {
        for d in [1i8, -1] {
            let group: Vec<usize> = (0..data.len())
                .filter(|&r| err[r].is_some() && dir[r] == d && (pos[r] - t.pos_mm).abs() <= 1e-3)
                .collect();
            if group.len() < 3 {
                continue;
            }
            for &r in &group {
                let others: Vec<f64> = group
                    .iter()
                    .filter(|&&o| o != r)
                    .filter_map(|&o| err[o])
                    .collect();
                let (m, so) = (mean(&others), std_n1(&others));
                let v = err[r].unwrap_or(m);
                if (v - m).abs() <= BAD_READING_K * so.max(typical) || so.max(typical) <= 0.0 {
                    continue;
                }
                let mut without = data.clone();
                if let Some(c) = without.err_um[axis].as_mut() {
                    c[r] = None;
                }
                let Ok(w) = figures(&without, axis) else {
                    continue;
                };
                out.push(BadReading {
                    row: r,
                    line: data.line.get(r).copied(),
                    run: data.pass_id.as_ref().map(|p| p[r]),
                    target_mm: t.pos_mm,
                    dir: d,
                    value_um: v,
                    others_mean_um: m,
                    a_without_um: w.a_um,
                    r_without_um: w.r_um,
                });
            }
        }
    }
    out
}

/// The standard's figures of `axis` (every reading kept), without flags.
fn figures(data: &Dataset, axis: usize) -> Result<Iso230> {
    let name = AXES[axis];
    let pos = data.pos_mm[axis]
        .as_ref()
        .with_context(|| format!("{}: no {name}_mm column", data.source))?;
    let err = data.err_um[axis].as_ref().with_context(|| {
        format!(
            "{}: no {}_um column (the positioning error of {name})",
            data.source, TARGETS[axis]
        )
    })?;
    let dir = data.dir[axis].as_ref().with_context(|| {
        format!(
            "{}: no dir_{name} column; ISO 230-2 needs the approach direction of each reading",
            data.source
        )
    })?;
    // Pick the line: the most common position of the other axes (to 1 µm).
    let key = |r: usize| -> [i64; 3] {
        [0, 1, 2].map(|a| {
            if a == axis {
                0
            } else {
                (data.pos(a, r) * 1e3).round() as i64
            }
        })
    };
    let mut lines: Vec<([i64; 3], usize)> = Vec::new();
    for (r, _) in err.iter().enumerate().filter(|(_, v)| v.is_some()) {
        let k = key(r);
        match lines.iter_mut().find(|(l, _)| *l == k) {
            Some(l) => l.1 += 1,
            None => lines.push((k, 1)),
        }
    }
    let line = lines
        .iter()
        .max_by_key(|l| l.1)
        .map(|l| l.0)
        .with_context(|| format!("{}: no {}_um values", data.source, TARGETS[axis]))?;
    let rows: Vec<usize> = (0..data.len())
        .filter(|&r| err[r].is_some() && key(r) == line)
        .collect();
    let rows_ignored = data.len() - rows.len();

    // Group into targets (positions within 1 µm are the same target).
    let mut order = rows.clone();
    order.sort_by(|&a, &b| pos[a].total_cmp(&pos[b]));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for r in order {
        match groups.last_mut() {
            Some(g) if (pos[r] - pos[g[0]]).abs() <= 1e-3 => g.push(r),
            _ => groups.push(vec![r]),
        }
    }
    if groups.len() < 2 {
        bail!(
            "{}: {} target position(s) along {name}; ISO 230-2 needs at least 2 (5 per metre recommended)",
            data.source,
            groups.len()
        );
    }
    let mut per_target = Vec::with_capacity(groups.len());
    for g in &groups {
        let p = pos[g[0]];
        let up: Vec<f64> = g
            .iter()
            .filter(|&&r| dir[r] > 0)
            .filter_map(|&r| err[r])
            .collect();
        let down: Vec<f64> = g
            .iter()
            .filter(|&&r| dir[r] < 0)
            .filter_map(|&r| err[r])
            .collect();
        for (v, what) in [(&up, "positive"), (&down, "negative")] {
            if v.len() < 2 {
                bail!(
                    "{}: the target at {p} mm has {} reading(s) approached in the {what} direction; ISO 230-2 needs at least 2 per direction (5 in a full test)",
                    data.source,
                    v.len()
                );
            }
        }
        let (mu, md) = (mean(&up), mean(&down));
        let (su, sd) = (std_n1(&up), std_n1(&down));
        let b = mu - md;
        let (ru, rd) = (4.0 * su, 4.0 * sd);
        per_target.push(TargetStats {
            pos_mm: p,
            n_up: up.len(),
            n_down: down.len(),
            mean_up_um: mu,
            mean_down_um: md,
            mean_um: (mu + md) / 2.0,
            s_up_um: su,
            s_down_um: sd,
            b_um: b,
            r_up_um: ru,
            r_down_um: rd,
            r_um: (2.0 * su + 2.0 * sd + b.abs()).max(ru).max(rd),
        });
    }
    let t = &per_target;
    let it = || t.iter();
    Ok(Iso230 {
        axis: name.to_string(),
        targets: t.len(),
        runs: it().map(|s| s.n_up.min(s.n_down)).min().unwrap_or(0),
        b_um: max(it().map(|s| s.b_um.abs())),
        b_mean_um: mean(&it().map(|s| s.b_um).collect::<Vec<_>>()),
        r_up_um: max(it().map(|s| s.r_up_um)),
        r_down_um: max(it().map(|s| s.r_down_um)),
        r_um: max(it().map(|s| s.r_um)),
        e_up_um: max(it().map(|s| s.mean_up_um)) - min(it().map(|s| s.mean_up_um)),
        e_down_um: max(it().map(|s| s.mean_down_um)) - min(it().map(|s| s.mean_down_um)),
        e_um: max(it().map(|s| s.mean_up_um.max(s.mean_down_um)))
            - min(it().map(|s| s.mean_up_um.min(s.mean_down_um))),
        m_um: max(it().map(|s| s.mean_um)) - min(it().map(|s| s.mean_um)),
        a_up_um: max(it().map(|s| s.mean_up_um + 2.0 * s.s_up_um))
            - min(it().map(|s| s.mean_up_um - 2.0 * s.s_up_um)),
        a_down_um: max(it().map(|s| s.mean_down_um + 2.0 * s.s_down_um))
            - min(it().map(|s| s.mean_down_um - 2.0 * s.s_down_um)),
        a_um: max(
            it().map(|s| (s.mean_up_um + 2.0 * s.s_up_um).max(s.mean_down_um + 2.0 * s.s_down_um))
        ) - min(
            it().map(|s| (s.mean_up_um - 2.0 * s.s_up_um).min(s.mean_down_um - 2.0 * s.s_down_um))
        ),
        per_target,
        rows_used: rows.len(),
        rows_ignored,
        skipped_count: data.skipped.len(),
        flags: Vec::new(),
    })
}

impl Iso230 {
    /// The human-readable summary and per-target table.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "ISO 230-2, axis {}: {} targets, {} bidirectional runs (k = 2)",
            self.axis, self.targets, self.runs
        );
        let _ = writeln!(
            s,
            "  A  = {:8.3} µm   (A↑ {:.3}, A↓ {:.3})",
            self.a_um, self.a_up_um, self.a_down_um
        );
        let _ = writeln!(
            s,
            "  E  = {:8.3} µm   (E↑ {:.3}, E↓ {:.3})",
            self.e_um, self.e_up_um, self.e_down_um
        );
        let _ = writeln!(s, "  M  = {:8.3} µm", self.m_um);
        let _ = writeln!(
            s,
            "  R  = {:8.3} µm   (R↑ {:.3}, R↓ {:.3})",
            self.r_um, self.r_up_um, self.r_down_um
        );
        let _ = writeln!(s, "  B  = {:8.3} µm   (B̄ {:.3})", self.b_um, self.b_mean_um);
        for f in &self.flags {
            let _ = writeln!(s, "  flagged: {}", f.text(self));
        }
        if self.rows_ignored > 0 {
            let _ = writeln!(
                s,
                "  {} readings used, {} ignored (other lines or no {} value)",
                self.rows_used, self.rows_ignored, self.axis
            );
        }
        let _ = writeln!(
            s,
            "\n{:>10} {:>4} {:>4} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8}",
            "pos_mm", "n↑", "n↓", "x̄↑_um", "x̄↓_um", "x̄_um", "s↑_um", "s↓_um", "B_um", "R_um"
        );
        for t in &self.per_target {
            let _ = writeln!(
                s,
                "{:>10.3} {:>4} {:>4} {:>9.3} {:>9.3} {:>9.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
                t.pos_mm,
                t.n_up,
                t.n_down,
                t.mean_up_um,
                t.mean_down_um,
                t.mean_um,
                t.s_up_um,
                t.s_down_um,
                t.b_um,
                t.r_um
            );
        }
        s
    }
}
