//! Lines and planes of a measurement plan. A line is the set of rows that
//! share the other axes' positions (a laser traverse along one axis), a
//! plane the rows that share one axis's position. `compare` draws the
//! residual along every line ([`dense_lines`]) and on every plane
//! ([`planes`]); `diagnose` looks for periods on the densest lines
//! ([`densest_lines`]) and warns when even they are too sparse. Both find
//! lines by grouping rows on the fixed positions; `compare`
//! ([`by_fixed_position`]) keys positions to 0.01 mm and needs
//! `min_points` distinct positions, `diagnose` keys them to 1 µm and keeps
//! only the densest.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use crate::data::{Dataset, AXES};

/// `rows` grouped by `key` of each row, in the key's order; rows keep
/// their order within a group.
pub fn group_rows<K: Ord>(rows: &[usize], key: impl Fn(usize) -> K) -> BTreeMap<K, Vec<usize>> {
    let mut groups: BTreeMap<K, Vec<usize>> = BTreeMap::new();
    for &r in rows {
        groups.entry(key(r)).or_default().push(r);
    }
    groups
}

/// `rows` grouped by where the axes other than `axis` stand (each
/// position keyed by `key`): the rows of each line along `axis`.
pub fn by_fixed_position<K: Ord>(
    data: &Dataset,
    axis: usize,
    rows: &[usize],
    key: impl Fn(f64) -> K,
) -> BTreeMap<Vec<K>, Vec<usize>> {
    let others: Vec<usize> = data.axes().into_iter().filter(|&a| a != axis).collect();
    group_rows(rows, |r| {
        others.iter().map(|&a| key(data.pos(a, r))).collect()
    })
}

/// A measured plane: rows sharing one coordinate on `normal`.
#[derive(Clone, Debug)]
pub struct Plane {
    /// The axis held constant (0 = x).
    pub normal: usize,
    /// Its value, mm.
    pub at_mm: f64,
    /// Rows on the plane.
    pub rows: Vec<usize>,
}

/// Snap tolerance for "the same nominal position", mm (positions in a plan
/// are written to 1 µm; 0.01 mm merges the two directions of one target).
pub const SNAP_MM: f64 = 0.01;

/// Planes of a 3-axis plan: for each axis used as a normal, groups of rows
/// with the same coordinate that span at least 3 × 3 distinct positions on
/// the other two axes. A 2-axis data set is one plane.
pub fn planes(data: &Dataset) -> Vec<Plane> {
    let axes = data.axes();
    let mut out = Vec::new();
    if axes.len() == 2 {
        let normal = (0..3).find(|a| !axes.contains(a)).unwrap_or(2);
        out.push(Plane {
            normal,
            at_mm: 0.0,
            rows: (0..data.len()).collect(),
        });
        return out;
    }
    if axes.len() != 3 {
        return out;
    }
    for normal in [2usize, 1, 0] {
        let others: Vec<usize> = (0..3).filter(|&a| a != normal).collect();
        let mut groups: Vec<(f64, Vec<usize>)> = Vec::new();
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.sort_by(|&a, &b| data.pos(normal, a).total_cmp(&data.pos(normal, b)));
        for r in order {
            let p = data.pos(normal, r);
            match groups.last_mut() {
                Some((at, rows)) if (p - *at).abs() <= SNAP_MM => rows.push(r),
                _ => groups.push((p, vec![r])),
            }
        }
        for (at, rows) in groups {
            // Keep the rows on the plane's grid: a position on one in-plane
            // axis counts only when it was measured at ≥ 3 positions of the
            // other, so a dense line through the plane does not turn the
            // map into thousands of empty columns.
            let snap = |v: f64| (v / SNAP_MM).round() as i64;
            // A set per position: a dense line's 16 000 positions in a
            // list searched per row made compare quadratic (37 % of
            // `compare --report` at 194k rows).
            let mut seen: BTreeMap<(usize, i64), BTreeSet<i64>> = BTreeMap::new();
            for &r in &rows {
                for (i, &a) in others.iter().enumerate() {
                    let b = others[1 - i];
                    seen.entry((a, snap(data.pos(a, r))))
                        .or_default()
                        .insert(snap(data.pos(b, r)));
                }
            }
            let rows: Vec<usize> = rows
                .into_iter()
                .filter(|&r| {
                    others
                        .iter()
                        .all(|&a| seen[&(a, snap(data.pos(a, r)))].len() >= 3)
                })
                .collect();
            let distinct = |a: usize| {
                let mut v: Vec<f64> = rows.iter().map(|&r| data.pos(a, r)).collect();
                v.sort_by(f64::total_cmp);
                v.dedup_by(|x, y| (*x - *y).abs() <= SNAP_MM);
                v.len()
            };
            if distinct(others[0]) >= 3 && distinct(others[1]) >= 3 {
                out.push(Plane {
                    normal,
                    at_mm: at,
                    rows,
                });
            }
        }
    }
    out
}

/// A dense line: rows of one traverse along one axis, the others fixed.
#[derive(Clone, Debug)]
pub struct Line {
    /// The axis moved along.
    pub axis: usize,
    /// Rows on the line, in position order.
    pub rows: Vec<usize>,
    /// Where the other axes stand, mm (`y=100, z=250`).
    pub label: String,
}

/// Lines with at least `min_points` distinct positions along one axis while
/// every other axis stays put (within [`SNAP_MM`]), for `compare`'s plots.
/// Grouped by `pass_id` when the data has it, otherwise by the fixed
/// coordinates to 0.01 mm.
pub fn dense_lines(data: &Dataset, min_points: usize) -> Vec<Line> {
    let axes = data.axes();
    let all: Vec<usize> = (0..data.len()).collect();
    let mut out = Vec::new();
    for &axis in &axes {
        let groups: Vec<Vec<usize>> = match &data.pass_id {
            Some(p) => group_rows(&all, |r| format!("pass{}", p[r]))
                .into_values()
                .collect(),
            None => by_fixed_position(data, axis, &all, |v| format!("{v:.2}"))
                .into_values()
                .collect(),
        };
        for mut rows in groups {
            let fixed_ok = axes.iter().filter(|&&a| a != axis).all(|&a| {
                let (l, h) = rows
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &r| {
                        (l.min(data.pos(a, r)), h.max(data.pos(a, r)))
                    });
                h - l <= SNAP_MM
            });
            if !fixed_ok {
                continue;
            }
            rows.sort_by(|&a, &b| data.pos(axis, a).total_cmp(&data.pos(axis, b)));
            let mut distinct: Vec<f64> = rows.iter().map(|&r| data.pos(axis, r)).collect();
            distinct.dedup_by(|x, y| (*x - *y).abs() <= SNAP_MM);
            if distinct.len() < min_points {
                continue;
            }
            let label = axes
                .iter()
                .filter(|&&a| a != axis)
                .map(|&a| format!("{}={}", AXES[a], plot_num(data.pos(a, rows[0]))))
                .collect::<Vec<_>>()
                .join(", ");
            out.push(Line { axis, rows, label });
        }
    }
    out
}

/// A position for a label: three decimals at most, trailing zeros cut
/// (`250`, `12.5`).
pub fn plot_num(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Rows of the densest lines along one axis.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseLines {
    /// Data row indices on those lines.
    pub rows: Vec<usize>,
    /// Median spacing between distinct positions on the densest line, mm.
    pub spacing_mm: f64,
    /// Longest extent of one of those lines along the axis, mm.
    pub span_mm: f64,
    /// Number of lines pooled.
    pub lines: usize,
    /// True when real lines (≥ 8 distinct positions at fixed other axes)
    /// were found; false when the rows are scattered and all were used.
    pub from_lines: bool,
}

fn key_mm(v: f64) -> i64 {
    // Nominal positions are commanded values: 1 µm resolution tells them apart.
    (v * 1000.0).round() as i64
}

fn spacing_of(mut pos: Vec<i64>) -> Option<(f64, f64, usize)> {
    pos.sort_unstable();
    pos.dedup();
    if pos.len() < 2 {
        return None;
    }
    let mut d: Vec<i64> = pos.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_unstable();
    let med = d[d.len() / 2] as f64 / 1000.0;
    let span = (pos[pos.len() - 1] - pos[0]) as f64 / 1000.0;
    Some((med, span, pos.len()))
}

/// The densest lines along `axis` among `rows`, for `diagnose`'s periodic
/// search: lines with at least 8 distinct positions (1 µm apart) at fixed
/// other axes, those with a spacing within 1.5× the densest pooled; when
/// there are none, every row (`from_lines` false). None when the axis is
/// not in the data or has fewer than two distinct positions.
pub fn densest_lines(data: &Dataset, axis: usize, rows: &[usize]) -> Option<DenseLines> {
    let pos = data.pos_mm[axis].as_ref()?;
    // The rows of each line, keyed by where the other (at most two) axes
    // stand: hash maps of fixed-size keys rather than
    // [`by_fixed_position`]'s ordered map of one `Vec` key per row, which
    // took ~30 ms of CPU a call at 180k rows (`diagnose` asks per target, axis and
    // step). Counted first: a dense line across the axis is thousands of
    // one- or two-row groups, and a group of fewer than 8 rows cannot have
    // 8 distinct positions, so only the others get a row list. The order
    // of the lines does not matter below (minimum, maximum, rows sorted at
    // the end).
    let others: Vec<usize> = data.axes().into_iter().filter(|&a| a != axis).collect();
    let key_of = |r: usize| {
        let mut key = [0i64; 2];
        for (k, &a) in key.iter_mut().zip(&others) {
            *k = key_mm(data.pos(a, r));
        }
        key
    };
    let mut sizes: HashMap<[i64; 2], usize> = HashMap::new();
    for &r in rows {
        *sizes.entry(key_of(r)).or_default() += 1;
    }
    let mut groups: HashMap<[i64; 2], Vec<usize>> = sizes
        .into_iter()
        .filter(|&(_, n)| n >= 8)
        .map(|(k, n)| (k, Vec::with_capacity(n)))
        .collect();
    for &r in rows {
        if let Some(g) = groups.get_mut(&key_of(r)) {
            g.push(r);
        }
    }
    let mut lines: Vec<(f64, f64, Vec<usize>)> = Vec::new();
    for g in groups.into_values() {
        let p: Vec<i64> = g.iter().map(|&r| key_mm(pos[r])).collect();
        if let Some((sp, span, distinct)) = spacing_of(p) {
            if distinct >= 8 && sp > 0.0 {
                lines.push((sp, span, g));
            }
        }
    }
    if lines.is_empty() {
        let p: Vec<i64> = rows.iter().map(|&r| key_mm(pos[r])).collect();
        let (sp, span, _) = spacing_of(p)?;
        return Some(DenseLines {
            rows: rows.to_vec(),
            spacing_mm: sp,
            span_mm: span,
            lines: 0,
            from_lines: false,
        });
    }
    let densest = lines.iter().map(|l| l.0).fold(f64::INFINITY, f64::min);
    let mut out_rows = Vec::new();
    let mut span_mm: f64 = 0.0;
    let mut count = 0;
    for (sp, span, g) in lines {
        if sp <= 1.5 * densest {
            out_rows.extend(g);
            span_mm = span_mm.max(span);
            count += 1;
        }
    }
    out_rows.sort_unstable();
    Some(DenseLines {
        rows: out_rows,
        spacing_mm: densest,
        span_mm,
        lines: count,
        from_lines: true,
    })
}

#[cfg(test)]
mod tests {
    use super::densest_lines as dense_lines;
    use crate::data::Dataset;

    #[test]
    fn lines_are_found_and_the_densest_kept() {
        let mut x = Vec::new();
        let mut y = Vec::new();
        // A coarse grid line at y = 0 (50 mm) and a dense line at y = 100 (1 mm).
        for i in 0..=16 {
            x.push(i as f64 * 50.0);
            y.push(0.0);
        }
        for i in 0..=800 {
            x.push(i as f64);
            y.push(100.0);
        }
        let d = Dataset {
            pos_mm: [Some(x), Some(y), None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..d.len()).collect();
        let l = dense_lines(&d, 0, &rows).unwrap();
        assert_eq!(l.lines, 1);
        assert_eq!(l.rows.len(), 801);
        assert!((l.spacing_mm - 1.0).abs() < 1e-9);
        // Along y there are no lines: every row is used, spacing 100 mm.
        let l = dense_lines(&d, 1, &rows).unwrap();
        assert!(!l.from_lines);
        assert!((l.spacing_mm - 100.0).abs() < 1e-9);
    }

    #[test]
    fn lines_crossing_the_axis_and_parallel_ones_are_told_apart() {
        // A 3-axis plan: a 100 mm grid, two bidirectional 0.5 mm lines
        // along x (at y = 100 and y = 200, z = 50) and one along y at
        // x = 300 (every y position its own one-row "line" along x), a
        // 2 mm line along x at z = 150, and a 7-point line (too short).
        let mut p: [Vec<f64>; 3] = Default::default();
        let mut push = |x: f64, y: f64, z: f64| {
            p[0].push(x);
            p[1].push(y);
            p[2].push(z);
        };
        for i in 0..=4 {
            for j in 0..=3 {
                for k in 0..=2 {
                    push(i as f64 * 100.0, j as f64 * 100.0, k as f64 * 100.0);
                }
            }
        }
        for y in [100.0, 200.0] {
            for i in (0..=800).chain((0..=800).rev()) {
                push(i as f64 * 0.5, y, 50.0);
            }
        }
        for i in 0..=600 {
            push(300.0, i as f64 * 0.5, 50.0);
        }
        for i in 0..=200 {
            push(i as f64 * 2.0, 0.0, 150.0);
        }
        for i in 0..7 {
            push(i as f64 * 0.1, 300.0, 250.0);
        }
        let [x, y, z] = p;
        let d = Dataset {
            pos_mm: [Some(x), Some(y), Some(z)],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..d.len()).collect();
        let l = dense_lines(&d, 0, &rows).unwrap();
        // The two 0.5 mm lines are pooled; the 2 mm one (4× coarser) and
        // the grid are not; the y line's points at y = 100 and 200 lie on
        // them.
        assert_eq!(l.lines, 2);
        assert_eq!(l.rows.len(), 2 * 1602 + 2);
        assert!(l.rows.windows(2).all(|w| w[0] < w[1]));
        assert!(l
            .rows
            .iter()
            .all(|&r| d.pos(2, r) == 50.0 && d.pos(1, r) != 50.0));
        assert!((l.spacing_mm - 0.5).abs() < 1e-9);
        assert!((l.span_mm - 400.0).abs() < 1e-9);
        // Along y: the line at x = 300 alone, with the x lines' two passes
        // through it at y = 100 and 200 (the rest of them are one-row
        // groups along y).
        let l = dense_lines(&d, 1, &rows).unwrap();
        assert_eq!((l.lines, l.rows.len()), (1, 601 + 4));
        assert!((l.span_mm - 300.0).abs() < 1e-9);
        // Along z only the grid's 3-point columns: no line, every row.
        let l = dense_lines(&d, 2, &rows).unwrap();
        assert!(!l.from_lines);
        assert_eq!(l.rows.len(), rows.len());
    }
}
