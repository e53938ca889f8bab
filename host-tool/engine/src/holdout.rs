//! Block hold-out: how well a model predicts measurements it was not fitted
//! to. Machine errors are smooth and neighbouring points share their noise
//! (drift, a pass's thermal state), so leaving out random single points
//! flatters every model — its neighbours are still in the fit. We leave out
//! whole blocks instead:
//!
//! - **Whole passes** when the data has `pass_id`: the sorted pass ids are
//!   dealt round-robin into `k` blocks (pass i → block i mod k), so every
//!   block holds complete traverses. A long pass (a dense line of 1600
//!   points) is first cut into segments of [`PASS_SEGMENT`] consecutive
//!   rows, each dealt like a pass: holding out a whole dense line would
//!   leave no row that sees a short-period effect (a 5 mm lead error), and
//!   the held-out RMS would measure an aliased extrapolation, not the model.
//!   This needs at least two passes or segments.
//! - **Spatial blocks** otherwise, along the axis with the longest travel:
//!   the distinct positions on that axis (a measured plane or line shares one)
//!   are cut, in order, into min(#positions, 4k) contiguous chunks of about
//!   equal row counts, and chunk c goes to block c mod k. Each block is thus
//!   a few contiguous slabs spread over the travel: whole planes are never
//!   split, and most held-out slabs are interpolated rather than
//!   extrapolated (holding out one end fifth of the travel would measure a
//!   cubic's extrapolation, not the model).
//!
//! The held-out RMS is the RMS over all rows of the prediction of each block
//! by the model refitted without it (unweighted: it is the error a user sees).

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use nalgebra::DVector;

use crate::data::{Dataset, AXES, TARGETS};
use crate::features::{Feature, Norm};
use crate::linalg::lsq;

/// Number of hold-out blocks unless the caller asks otherwise.
pub const DEFAULT_BLOCKS: usize = 5;

/// Rows of one pass beyond which the pass is cut into segments for hold-out.
pub const PASS_SEGMENT: usize = 100;

/// The hold-out unit of each of `rows` when the data has `pass_id`: (pass
/// id, segment), segment = (index of the row within its pass, in the order
/// of `rows`) / [`PASS_SEGMENT`]. None without `pass_id`.
pub fn pass_segments(data: &Dataset, rows: &[usize]) -> Option<Vec<(i64, usize)>> {
    let pass = data.pass_id.as_ref()?;
    let mut seen: BTreeMap<i64, usize> = BTreeMap::new();
    Some(
        rows.iter()
            .map(|&r| {
                let c = seen.entry(pass[r]).or_insert(0);
                *c += 1;
                (pass[r], (*c - 1) / PASS_SEGMENT)
            })
            .collect(),
    )
}

/// How the rows were split, for reports (`"5 blocks of whole passes"`).
pub fn describe(data: &Dataset, rows: &[usize], k: usize) -> String {
    describe_blocks(data, rows, &blocks(data, rows, k))
}

/// [`describe`] of the blocks `b` that [`blocks`] made of `rows`.
pub fn describe_blocks(data: &Dataset, rows: &[usize], b: &[Vec<usize>]) -> String {
    match block_kind(data, rows) {
        BlockKind::Passes => format!(
            "{} blocks of whole passes (pass_id; passes longer than {PASS_SEGMENT} points cut into segments)",
            b.len()
        ),
        BlockKind::Spatial(axis) => format!(
            "{} spatial blocks along {} (contiguous slabs dealt round-robin)",
            b.len(),
            AXES[axis]
        ),
        BlockKind::Time => format!(
            "{} blocks of contiguous time (t_s; a single position: contiguous stretches dealt round-robin)",
            b.len()
        ),
        BlockKind::None => "no hold-out possible (a single position)".into(),
    }
}

enum BlockKind {
    Passes,
    Spatial(usize),
    /// A time series at one position without passes: contiguous stretches
    /// of time, like the spatial slabs.
    Time,
    None,
}

/// The time order key of `row`: (session, t_s) — `t_s` restarts in each
/// session.
pub(crate) fn time_key(data: &Dataset, row: usize) -> (i64, f64) {
    (
        data.session_id.as_ref().map_or(0, |s| s[row]),
        data.t_s.as_ref().map_or(0.0, |t| t[row]),
    )
}

/// `rows` in time order (session, then t_s; ties keep their order).
pub fn time_order(data: &Dataset, rows: &[usize]) -> Vec<usize> {
    let mut out = rows.to_vec();
    out.sort_by(|&a, &b| {
        let (ka, kb) = (time_key(data, a), time_key(data, b));
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
    });
    out
}

fn block_kind(data: &Dataset, rows: &[usize]) -> BlockKind {
    if let Some(mut ids) = pass_segments(data, rows) {
        ids.sort_unstable();
        ids.dedup();
        if ids.len() >= 2 {
            return BlockKind::Passes;
        }
    }
    let span = |a: usize| -> f64 {
        data.pos_mm[a].as_ref().map_or(0.0, |col| {
            let (lo, hi) = rows
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &r| {
                    (lo.min(col[r]), hi.max(col[r]))
                });
            if rows.is_empty() {
                0.0
            } else {
                hi - lo
            }
        })
    };
    let best = (0..3).max_by(|&a, &b| span(a).total_cmp(&span(b)).then(b.cmp(&a)));
    match best {
        Some(a) if span(a) > 0.0 => BlockKind::Spatial(a),
        _ if rows.len() >= 2 && data.t_s.is_some() => BlockKind::Time,
        _ => BlockKind::None,
    }
}

/// Splits `rows` into at most `k` hold-out blocks (see the module docs):
/// whole passes when `pass_id` is present, else spatial slabs along the
/// longest axis — never random points. Empty blocks are dropped; a single
/// block comes back when nothing can be held out (one position, one pass).
pub fn blocks(data: &Dataset, rows: &[usize], k: usize) -> Vec<Vec<usize>> {
    let k = k.max(2);
    let mut out: Vec<Vec<usize>> = vec![Vec::new(); k];
    match block_kind(data, rows) {
        BlockKind::Passes => {
            let keys = pass_segments(data, rows).expect("checked by block_kind");
            let mut ids = keys.clone();
            ids.sort_unstable();
            ids.dedup();
            for (&r, key) in rows.iter().zip(&keys) {
                let i = ids.binary_search(key).expect("every key is in ids");
                out[i % k].push(r);
            }
        }
        BlockKind::Spatial(axis) => {
            let col = data.pos_mm[axis].as_ref().expect("checked by block_kind");
            // Group rows by position (to 1 nm: a plane measured twice is one plane).
            let mut groups: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
            for &r in rows {
                groups
                    .entry((col[r] * 1e6).round() as i64)
                    .or_default()
                    .push(r);
            }
            let n_chunks = groups.len().min(4 * k);
            let total = rows.len() as f64;
            let mut seen = 0usize;
            for g in groups.values() {
                // Chunk by the cumulative row count at the group's middle, so
                // chunks hold about equal numbers of rows.
                let mid = seen as f64 + 0.5 * g.len() as f64;
                let chunk = ((mid / total) * n_chunks as f64).floor() as usize;
                out[chunk.min(n_chunks - 1) % k].extend_from_slice(g);
                seen += g.len();
            }
        }
        BlockKind::Time => {
            let ordered = time_order(data, rows);
            let n_chunks = ordered.len().min(4 * k);
            let total = ordered.len();
            for (i, &r) in ordered.iter().enumerate() {
                out[(i * n_chunks / total) % k].push(r);
            }
        }
        BlockKind::None => out[0].extend_from_slice(rows),
    }
    out.retain(|b| !b.is_empty());
    out
}

/// Weights 1/u² for `rows`, or None when the data has no `u_um`.
pub fn weights(data: &Dataset, rows: &[usize]) -> Result<Option<DVector<f64>>> {
    let Some(u) = &data.u_um else { return Ok(None) };
    let mut w = DVector::zeros(rows.len());
    for (i, &r) in rows.iter().enumerate() {
        let ur = u[r];
        if !(ur.is_finite() && ur > 0.0) {
            let line = data
                .line
                .get(r)
                .map_or(String::new(), |l| format!(" (line {l})"));
            bail!(
                "{}: u_um = {ur} on row {}{line}: an uncertainty must be a positive number",
                data.source,
                r + 1
            );
        }
        w[i] = 1.0 / (ur * ur);
    }
    Ok(Some(w))
}

/// Held-out residuals (measured − predicted, µm) of the linear model
/// `features` for `target`, one per row of `rows` where the target is
/// measured, as (row, residual): each block predicted by the model refitted
/// on the other blocks (weighted by `u_um` like the fit itself).
pub fn held_out_residuals(
    data: &Dataset,
    rows: &[usize],
    features: &[Feature],
    target: usize,
    norm: &Norm,
    k: usize,
) -> Result<Vec<(usize, f64)>> {
    let Some(err) = &data.err_um[target] else {
        bail!("the data has no {}_um column", TARGETS[target]);
    };
    let rows: Vec<usize> = rows.iter().copied().filter(|&r| err[r].is_some()).collect();
    let bl = blocks(data, &rows, k);
    if bl.len() < 2 {
        bail!(
            "{}: cannot hold out blocks — every measured point lies at one position, in one pass and without t_s",
            TARGETS[target]
        );
    }
    let a = lsq::design_matrix(data, norm, features, &rows)?;
    let b = DVector::from_iterator(rows.len(), rows.iter().map(|&r| err[r].unwrap_or(0.0)));
    let w = weights(data, &rows)?;
    let index: BTreeMap<usize, usize> = rows.iter().enumerate().map(|(i, &r)| (r, i)).collect();
    let local: Vec<Vec<usize>> = bl
        .iter()
        .map(|block| block.iter().map(|r| index[r]).collect())
        .collect();
    if let Some(pred) = gram_predictions(&a, &b, w.as_ref(), &local) {
        let mut out: Vec<(usize, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| (r, b[i] - pred[i]))
            .collect();
        out.sort_by_key(|(r, _)| *r);
        return Ok(out);
    }
    let mut out = Vec::with_capacity(rows.len());
    for block in &bl {
        let held: std::collections::HashSet<usize> = block.iter().map(|r| index[r]).collect();
        let train: Vec<usize> = (0..rows.len()).filter(|i| !held.contains(i)).collect();
        let a_tr = a.select_rows(train.iter());
        let b_tr = b.select_rows(train.iter());
        let w_tr = w.as_ref().map(|w| w.select_rows(train.iter()));
        let sol = lsq::solve_min_norm(&a_tr, &b_tr, w_tr.as_ref())?;
        for &r in block {
            let i = index[&r];
            let pred = a.row(i).transpose().dot(&sol.coef);
            out.push((r, b[i] - pred));
        }
    }
    out.sort_by_key(|(r, _)| *r);
    Ok(out)
}

/// The coefficients of each hold-out block's training fit, solved from
/// per-block Gram sums (`grams[i]` over block i's rows): the training
/// system of block i is (G − Gᵢ) x = r − rᵢ with G = Σ Gᵢ, so k refits cost
/// one pass over the rows instead of k QR factorisations of (k−1)/k of
/// them. One p × right-hand-sides matrix per block; None when a training
/// system is not well conditioned enough for the normal equations
/// ([`lsq::GRAM_MAX_CONDITION`], or a column that is zero once its block
/// is left out): the caller then refits each block by QR.
pub fn block_refits(grams: &[lsq::Gram]) -> Option<Vec<nalgebra::DMatrix<f64>>> {
    let total = lsq::Gram::total(grams)?;
    grams
        .iter()
        .map(|gb| {
            let train = lsq::Gram {
                g: &total.g - &gb.g,
                r: &total.r - &gb.r,
            };
            lsq::solve_gram(&train).map(|s| s.coef)
        })
        .collect()
}

/// The held-out prediction of every row (indexed like `a`'s rows): each of
/// `blocks` (row indices into `a`) predicted by the weighted least-squares
/// fit on the other blocks ([`block_refits`]); None when the caller must
/// refit each block by QR.
fn gram_predictions(
    a: &nalgebra::DMatrix<f64>,
    b: &DVector<f64>,
    w: Option<&DVector<f64>>,
    blocks: &[Vec<usize>],
) -> Option<Vec<f64>> {
    let cols: Vec<usize> = (0..a.ncols()).collect();
    let b = nalgebra::DMatrix::from_column_slice(b.len(), 1, b.as_slice());
    let grams: Vec<lsq::Gram> = blocks
        .iter()
        .map(|block| lsq::Gram::over(a, &cols, &b, &[0], w, block))
        .collect();
    let coefs = block_refits(&grams)?;
    let mut pred = vec![0.0; a.nrows()];
    for (block, coef) in blocks.iter().zip(&coefs) {
        for &i in block {
            pred[i] = a.row(i).transpose().dot(&coef.column(0));
        }
    }
    Some(pred)
}

/// Block-held-out RMS (µm) of the linear model `features` for `target` on
/// `rows` (those without a value for the target are ignored), with
/// [`DEFAULT_BLOCKS`] blocks.
pub fn held_out_rms(
    data: &Dataset,
    rows: &[usize],
    features: &[Feature],
    target: usize,
    norm: &Norm,
) -> Result<f64> {
    held_out_rms_k(data, rows, features, target, norm, DEFAULT_BLOCKS)
}

/// [`held_out_rms`] with `k` blocks.
pub fn held_out_rms_k(
    data: &Dataset,
    rows: &[usize],
    features: &[Feature],
    target: usize,
    norm: &Norm,
    k: usize,
) -> Result<f64> {
    let res = held_out_residuals(data, rows, features, target, norm, k)?;
    Ok(rms(res.iter().map(|(_, e)| *e)))
}

/// Root mean square of the values (0 for none).
pub fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (n, ss) = values.fold((0usize, 0.0), |(n, ss), v| (n + 1, ss + v * v));
    if n == 0 {
        0.0
    } else {
        (ss / n as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::subset;

    fn line(n: usize, pass: Option<Vec<i64>>) -> Dataset {
        Dataset {
            source: "test".into(),
            pos_mm: [Some((0..n).map(|i| i as f64 * 10.0).collect()), None, None],
            err_um: [
                Some((0..n).map(|i| Some((i as f64 * 0.3).sin())).collect()),
                None,
                None,
            ],
            pass_id: pass,
            ..Default::default()
        }
    }

    #[test]
    fn blocks_are_whole_passes() {
        // 6 passes of 10 rows, interleaved in row order (serpentine-like).
        let pass: Vec<i64> = (0..60).map(|i| (i % 6) as i64 + 100).collect();
        let d = line(60, Some(pass.clone()));
        let rows: Vec<usize> = (0..60).collect();
        let b = blocks(&d, &rows, 4);
        assert_eq!(b.len(), 4);
        let mut all: Vec<usize> = b.concat();
        all.sort_unstable();
        assert_eq!(all, rows);
        for block in &b {
            // Every pass appearing in a block appears there completely.
            let ids: std::collections::BTreeSet<i64> = block.iter().map(|&r| pass[r]).collect();
            for id in ids {
                let whole = (0..60).filter(|&r| pass[r] == id).count();
                assert_eq!(block.iter().filter(|&&r| pass[r] == id).count(), whole);
            }
        }
        // 6 passes into 4 blocks: passes 0,4 | 1,5 | 2 | 3.
        assert_eq!(b[0].len(), 20);
        assert_eq!(b[2].len(), 10);
    }

    #[test]
    fn a_long_pass_is_cut_into_consecutive_segments() {
        // One dense pass of 450 rows plus a short pass of 30: the long pass
        // becomes segments of PASS_SEGMENT consecutive rows (0..100,
        // 100..200, …, 400..450), dealt round-robin with the short pass.
        let n = 480;
        let pass: Vec<i64> = (0..n).map(|i| if i < 450 { 1 } else { 2 }).collect();
        let d = line(n, Some(pass));
        let rows: Vec<usize> = (0..n).collect();
        let b = blocks(&d, &rows, 5);
        assert_eq!(b.len(), 5, "5 segments of pass 1 + pass 2 fill 5 blocks");
        let mut sizes: Vec<usize> = b.iter().map(Vec::len).collect();
        sizes.sort_unstable();
        // Keys sorted: (1,0) (1,1) (1,2) (1,3) (1,4) (2,0) → blocks 0..4, 0.
        assert_eq!(sizes, vec![50, 100, 100, 100, 130]);
        for block in &b {
            // Segments are consecutive rows: a held-out block of pass 1 is
            // one contiguous run of at most PASS_SEGMENT rows.
            let p1: Vec<usize> = block.iter().copied().filter(|&r| r < 450).collect();
            assert!(p1.len() <= PASS_SEGMENT);
            assert!(p1.windows(2).all(|w| w[1] == w[0] + 1), "{p1:?}");
            if let Some(&first) = p1.first() {
                assert_eq!(first % PASS_SEGMENT, 0);
            }
        }
        assert!(describe(&d, &rows, 5).contains("segments"));
    }

    #[test]
    fn spatial_blocks_keep_planes_whole_and_spread() {
        // A 3-D grid 9 × 3 × 2: x is the longest axis; blocks are x-planes.
        let [x, y, z] = crate::data::grid_positions([9, 3, 2], [100.0, 50.0, 50.0]);
        let n = x.len();
        let d = Dataset {
            source: "grid".into(),
            pos_mm: [Some(x.clone()), Some(y), Some(z)],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            ..Default::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let b = blocks(&d, &rows, 3);
        assert_eq!(b.len(), 3);
        for block in &b {
            let planes: std::collections::BTreeSet<i64> =
                block.iter().map(|&r| x[r] as i64).collect();
            // Planes i, i+3, i+6: spread over the travel, each plane whole (6 rows).
            assert_eq!(planes.len(), 3);
            assert_eq!(block.len(), 18);
        }
    }

    #[test]
    fn dense_line_gets_contiguous_chunks() {
        let d = line(1000, None);
        let rows: Vec<usize> = (0..1000).collect();
        let b = blocks(&d, &rows, 5);
        assert_eq!(b.len(), 5);
        // 20 chunks of 50 contiguous points, 4 per block.
        let mut runs = 1;
        for w in b[0].windows(2) {
            if w[1] != w[0] + 1 {
                runs += 1;
            }
        }
        assert_eq!(runs, 4);
        assert_eq!(b[0].len(), 200);
    }

    #[test]
    fn held_out_of_exact_model_is_zero_and_of_bad_model_is_not() {
        let n = 50;
        let mut d = line(n, None);
        d.err_um[0] = Some(
            (0..n)
                .map(|i| {
                    let u = -1.0 + 2.0 * i as f64 / (n - 1) as f64;
                    Some(1.0 + 2.0 * u - 0.5 * u * u * u)
                })
                .collect(),
        );
        let norm = Norm::from_data(&d);
        let rows: Vec<usize> = (0..n).collect();
        let cubic: Vec<Feature> = (0..4)
            .map(|p| Feature::Monomial { exp: [p, 0, 0] })
            .collect();
        let h = held_out_rms(&d, &rows, &cubic, 0, &norm).unwrap();
        assert!(h < 1e-9, "{h}");
        let h = held_out_rms(&d, &rows, &cubic[..2], 0, &norm).unwrap();
        assert!(h > 0.05, "{h}");
    }

    /// Issue 15: the hold-out refits from Gram sums give the held-out
    /// residuals of the QR refits (to 1e-9 µm on a 2-µm error), with and
    /// without weights; a rank-deficient training set (a block that holds
    /// every reading of one monomial's support) falls back to QR.
    #[test]
    fn gram_refits_equal_the_qr_refits() {
        let n = 600;
        let mut rng = trueaxis_test_support::SplitMix64::new(7);
        let x: Vec<f64> = (0..n).map(|_| 800.0 * rng.unit()).collect();
        let y: Vec<f64> = (0..n).map(|_| 500.0 * rng.unit()).collect();
        let e: Vec<Option<f64>> = (0..n)
            .map(|i| Some(2.0 * (x[i] / 130.0).sin() + 0.001 * y[i] + 0.2 * rng.normal()))
            .collect();
        let mut d = Dataset {
            source: "r".into(),
            pos_mm: [Some(x), Some(y), None],
            err_um: [Some(e), None, None],
            ..Default::default()
        };
        let norm = Norm::from_data(&d);
        let rows: Vec<usize> = (0..n).collect();
        let feats: Vec<Feature> = [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [2, 0, 0],
            [1, 1, 0],
            [3, 0, 0],
        ]
        .into_iter()
        .map(|exp| Feature::Monomial { exp })
        .collect();
        for weighted in [false, true] {
            if weighted {
                d.u_um = Some((0..n).map(|i| 0.1 + 0.001 * i as f64).collect());
            }
            let a = lsq::design_matrix(&d, &norm, &feats, &rows).unwrap();
            let b =
                DVector::from_iterator(n, d.err_um[0].as_ref().unwrap().iter().map(|v| v.unwrap()));
            let w = weights(&d, &rows).unwrap();
            let bl = blocks(&d, &rows, 5);
            let fast = gram_predictions(&a, &b, w.as_ref(), &bl).expect("well conditioned");
            for block in &bl {
                let train: Vec<usize> = (0..n).filter(|i| !block.contains(i)).collect();
                let sol = lsq::solve_min_norm(
                    &a.select_rows(train.iter()),
                    &b.select_rows(train.iter()),
                    w.as_ref().map(|w| w.select_rows(train.iter())).as_ref(),
                )
                .unwrap();
                for &i in block {
                    let qr = a.row(i).transpose().dot(&sol.coef);
                    assert!((fast[i] - qr).abs() < 1e-9, "row {i}: {} vs {qr}", fast[i]);
                }
            }
        }
        // A column that is zero once a block is left out: no Gram path.
        let a = nalgebra::DMatrix::from_fn(10, 2, |i, j| if j == 0 || i < 2 { 1.0 } else { 0.0 });
        let b = DVector::from_fn(10, |i, _| i as f64);
        assert!(gram_predictions(&a, &b, None, &[vec![0, 1], (2..10).collect()]).is_none());
    }

    #[test]
    fn subset_slices_every_column() {
        let d = line(10, Some((0..10).collect()));
        let s = subset(&d, &[2, 5]);
        assert_eq!(s.len(), 2);
        assert_eq!(s.pos_mm[0], Some(vec![20.0, 50.0]));
        assert_eq!(s.pass_id, Some(vec![2, 5]));
    }
}
