//! One target's data and its fitted current model: the rows, values and
//! hold-out blocks of `ex`, `ey` or `ez` ([`TargetData`]), the model's least-squares
//! fit and block-held-out RMS ([`State`]), and a candidate's fit with the
//! model partialled out (Frisch–Waugh–Lovell, [`fwl`]). Everything the
//! candidate search, the scoring and the path work on.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use crate::data::{Dataset, TARGETS};
use crate::effect::{Effect, EffectSpec};
use crate::features::{Feature, Norm};
use crate::fit::linear::terms_for;
use crate::model::Seed;
use crate::regions::bin_index;

use crate::linalg::basis::{self, small_fit, Basis, HoldOut};

/// One target's rows, values and hold-out blocks.
pub(super) struct TargetData<'a> {
    pub(super) data: &'a Dataset,
    pub(super) norm: Norm,
    pub(super) t: usize,
    pub(super) rows: Vec<usize>,
    pub(super) y: Vec<f64>,
    pub(super) fold: Vec<usize>,
    pub(super) nfolds: usize,
    /// Where progress events go (`diagnose_with`).
    pub(super) progress: &'a crate::progress::Sink,
    /// [`forward_blocks`], made once.
    pub(super) forward: std::sync::OnceLock<Option<Vec<Vec<usize>>>>,
    /// `autocorr::time_positions`, made once.
    pub(super) time_order: std::sync::OnceLock<Option<Vec<usize>>>,
}

impl<'a> TargetData<'a> {
    /// Target `t` of `data`: the rows where it is measured, their values
    /// and hold-out blocks ([`hold_out_blocks`]), with the blocks'
    /// description.
    pub(super) fn new(
        data: &'a Dataset,
        norm: Norm,
        t: usize,
        progress: &'a crate::progress::Sink,
    ) -> (TargetData<'a>, String) {
        let (rows, y): (Vec<usize>, Vec<f64>) = data.measured(t).unzip();
        let (fold, nfolds, how) = hold_out_blocks(data, &rows, &norm);
        let td = TargetData {
            data,
            norm,
            t,
            rows,
            y,
            fold,
            nfolds,
            progress,
            forward: Default::default(),
            time_order: Default::default(),
        };
        (td, how)
    }

    pub(super) fn col(&self, f: &Feature) -> Result<Vec<f64>> {
        let full = f.column(self.data, &self.norm)?;
        Ok(self.rows.iter().map(|&r| full[r]).collect())
    }
}

/// The fitted current model of one target.
pub(super) struct State {
    /// The effects in the model (on every target).
    pub(super) adds: Vec<EffectSpec>,
    /// The model's columns, and the effect (index into `adds`) each
    /// belongs to (None for the seed's): for the fitted component of each
    /// effect in the report.
    pub(super) cols: std::sync::Arc<Vec<Vec<f64>>>,
    pub(super) owner: Vec<Option<usize>>,
    pub(super) basis: Basis,
    pub(super) resid: Vec<f64>,
    pub(super) rss: f64,
    pub(super) holdout: HoldOut,
    pub(super) held_out_rms: f64,
}

impl State {
    /// The model `seed` plus `effects` fitted to the target.
    pub(super) fn new(td: &TargetData, seed: &Seed, effects: &[Effect]) -> Result<State> {
        // The terms as `fit`'s design has them, on the data's own moving
        // axes.
        let axes = td.data.varying_axes();
        let mut cols = Vec::new();
        let mut owner = Vec::new();
        for (f, o) in terms_for(*seed, effects, td.t, &axes)? {
            cols.push(td.col(&f)?);
            owner.push(o);
        }
        let n = td.rows.len();
        let basis = Basis::new(&cols, n);
        if n < basis.rank() + 3 {
            // The caller names the file (`cmd::diagnose`: "DATA: cannot
            // diagnose: …").
            bail!(
                "{} has {} measured rows, too few for a model with {} independent terms",
                TARGETS[td.t],
                n,
                basis.rank()
            );
        }
        let resid = basis.residual(&td.y);
        let rss = basis::dot(&resid, &resid);
        let cols = std::sync::Arc::new(cols);
        let holdout = HoldOut::new(cols.clone(), &td.y, &td.fold, td.nfolds);
        let held_out_rms = holdout.rms(&[]).unwrap_or(f64::NAN);
        Ok(State {
            adds: effects.iter().map(|e| e.spec.clone()).collect(),
            cols,
            owner,
            basis,
            resid,
            rss,
            holdout,
            held_out_rms,
        })
    }

    pub(super) fn rms(&self) -> f64 {
        (self.rss / self.resid.len() as f64).sqrt()
    }

    /// The effects in the model, with their columns.
    pub(super) fn effects(&self) -> Vec<Effect> {
        self.adds.iter().cloned().map(Effect::new).collect()
    }

    /// The fitted component of effect `add` in this model (its columns times
    /// their coefficients in `fit`, the model's full least-squares fit), per
    /// row.
    pub(super) fn component(&self, fit: &basis::SmallFit, add: &EffectSpec) -> Option<Vec<f64>> {
        let idx: Vec<usize> = (0..self.cols.len())
            .filter(|&i| self.owner[i].is_some_and(|k| self.adds[k] == *add))
            .collect();
        if idx.is_empty() {
            return None;
        }
        Some(
            (0..self.resid.len())
                .map(|r| idx.iter().map(|&i| fit.beta[i] * self.cols[i][r]).sum())
                .collect(),
        )
    }
}

/// A candidate's in-sample FWL fit.
pub(super) struct FwlFit {
    pub(super) cols: Vec<Vec<f64>>,
    pub(super) partialled: Vec<Vec<f64>>,
    pub(super) share: f64,
    pub(super) fit: basis::SmallFit,
    pub(super) dbic: f64,
}

pub(super) fn fwl(
    td: &TargetData,
    st: &State,
    spec: &EffectSpec,
    searched: usize,
) -> Result<FwlFit> {
    fwl_many(td, st, &[(spec, searched)])
        .pop()
        .expect("one result per spec")
}

/// [`fwl`] of each `(spec, searched)`, all columns projected on the model
/// together: the basis is read twice in all instead of twice per spec.
pub(super) fn fwl_many(
    td: &TargetData,
    st: &State,
    specs: &[(&EffectSpec, usize)],
) -> Vec<Result<FwlFit>> {
    let cols: Vec<Result<Vec<Vec<f64>>>> = specs
        .iter()
        .map(|(spec, _)| spec.features().iter().map(|f| td.col(f)).collect())
        .collect();
    let refs: Vec<&[f64]> = cols.iter().flatten().flatten().map(Vec::as_slice).collect();
    let mut parts = st.basis.residuals(&refs).into_iter();
    let n = td.rows.len() as f64;
    cols.into_iter()
        .zip(specs)
        .map(|(cols, &(_, searched))| {
            let cols = cols?;
            let partialled: Vec<Vec<f64>> = parts.by_ref().take(cols.len()).collect();
            let share = cols
                .iter()
                .zip(&partialled)
                .map(|(c, p)| {
                    let cc = basis::dot(c, c);
                    if cc > 0.0 {
                        basis::dot(p, p) / cc
                    } else {
                        0.0
                    }
                })
                .fold(f64::INFINITY, f64::min);
            let fit = small_fit(&partialled, &st.resid);
            let k = (fit.rank + searched) as f64;
            let dbic = n * (fit.rss.max(1e-300) / st.rss.max(1e-300)).ln() + k * n.ln();
            Ok(FwlFit {
                cols,
                partialled,
                share,
                fit,
                dbic,
            })
        })
        .collect()
}

/// Most columns projected together by [`rss_many`]: the basis is read once
/// per group, and a group's columns (raw and projected, 16 MB at a million
/// rows each) stay few.
const RSS_GROUP_COLS: usize = 6;

/// The in-sample residual sum of squares of the model plus each of `specs`
/// (as [`fwl`]'s `fit.rss`), their columns projected on the model in
/// groups — one pass over the basis per group instead of one per spec;
/// +∞ for a spec whose columns the data cannot give.
pub(super) fn rss_many(td: &TargetData, st: &State, specs: &[EffectSpec]) -> Vec<f64> {
    let mut out = Vec::with_capacity(specs.len());
    let mut i = 0;
    while i < specs.len() {
        let mut group: Vec<Option<Vec<Vec<f64>>>> = Vec::new();
        let mut ncols = 0;
        while i < specs.len() && (group.is_empty() || ncols < RSS_GROUP_COLS) {
            let cols = specs[i]
                .features()
                .iter()
                .map(|f| td.col(f).ok())
                .collect::<Option<Vec<_>>>();
            ncols += cols.as_ref().map_or(0, Vec::len);
            group.push(cols);
            i += 1;
        }
        let refs: Vec<&[f64]> = group
            .iter()
            .flatten()
            .flatten()
            .map(Vec::as_slice)
            .collect();
        let mut parts = st.basis.residuals(&refs).into_iter();
        for cols in &group {
            out.push(match cols {
                Some(c) => {
                    let p: Vec<Vec<f64>> = parts.by_ref().take(c.len()).collect();
                    small_fit(&p, &st.resid).rss
                }
                None => f64::INFINITY,
            });
        }
    }
    out
}

fn hold_out_blocks(data: &Dataset, rows: &[usize], norm: &Norm) -> (Vec<usize>, usize, String) {
    const K: usize = 5;
    // Whole passes, but a long pass (a dense line of 1600 points) is cut
    // into segments (holdout::PASS_SEGMENT consecutive rows): holding out a
    // whole dense line would leave no row that can see a short period, and
    // the periodic candidate would be judged on an aliased fit.
    if let Some(keys) = crate::holdout::pass_segments(data, rows) {
        let mut ids = keys.clone();
        ids.sort_unstable();
        ids.dedup();
        if ids.len() >= K {
            let fold = keys
                .iter()
                .map(|k| ids.binary_search(k).unwrap_or(0) % K)
                .collect();
            return (
                fold,
                K,
                format!(
                    "whole passes (pass_id; passes longer than {} points cut into segments), {} blocks in {K} folds",
                    crate::holdout::PASS_SEGMENT,
                    ids.len()
                ),
            );
        }
    }
    // A time series at one position (a thermal test): every row is in one
    // spatial cell, so the folds are contiguous stretches of time, dealt
    // round-robin (20 stretches in 5 folds).
    if data.varying_axes().is_empty() && data.t_s.is_some() && rows.len() >= 2 * K {
        let ordered = crate::holdout::time_order(data, rows);
        let chunks = (4 * K).min(rows.len());
        let mut fold = vec![0; rows.len()];
        let index: std::collections::HashMap<usize, usize> =
            rows.iter().enumerate().map(|(i, &r)| (r, i)).collect();
        for (i, r) in ordered.iter().enumerate() {
            fold[index[r]] = (i * chunks / rows.len()) % K;
        }
        return (
            fold,
            K,
            format!("contiguous time blocks (t_s; one position: {chunks} stretches in {K} folds)"),
        );
    }
    // Spatial cells, 6 per axis, assigned to folds by a pattern that keeps
    // neighbouring cells in different folds.
    const CELLS: usize = 6;
    let fold = rows
        .iter()
        .map(|&r| {
            let mut id = 0usize;
            for (i, a) in data.axes().into_iter().enumerate() {
                let u = norm.u(a, data.pos(a, r));
                let c = bin_index((u + 1.0) / 2.0, CELLS);
                id += c * [1, 2, 3][i];
            }
            id % K
        })
        .collect();
    (fold, K, "spatial cells (6 per axis) in 5 folds".into())
}

/// Contiguous time blocks for the forward-chaining hold-out.
pub(super) const FORWARD_BLOCKS: usize = 6;

/// The forward-chaining hold-out of one target: its rows (local indices)
/// in time order (session, then `t_s`), cut into [`FORWARD_BLOCKS`]
/// contiguous blocks of equal *time* (the sessions laid end to end). Block
/// i is predicted from blocks 0..i only — what a user asks of a
/// time-dependent term: does it predict *later* data from earlier data?
///
/// Equal time, not equal row counts: a campaign whose warm-up is sampled
/// by a 100 mm grid (324 readings over 9 h) and whose last hour is dense
/// lines (180 000 readings at a steady temperature) put the whole warm-up
/// into the first of six equal-count blocks, and the thermal growth —
/// ΔBIC −49 300 — was "predicted" only on later data where the temperature
/// no longer moved (gain 0 %, rejected). Blocks empty of readings (a pause)
/// are dropped. Without time spread (every reading at one `t_s` in one
/// session) the blocks are equal in count. None without `t_s`, or with
/// fewer than two rows per block.
pub(super) fn forward_blocks<'a>(td: &'a TargetData) -> Option<&'a [Vec<usize>]> {
    td.forward
        .get_or_init(|| make_forward_blocks(td))
        .as_deref()
}

fn make_forward_blocks(td: &TargetData) -> Option<Vec<Vec<usize>>> {
    let t_s = td.data.t_s.as_ref()?;
    let n = td.rows.len();
    if n < 2 * FORWARD_BLOCKS {
        return None;
    }
    let first = t_s[td.rows[0]];
    if td.rows.iter().all(|&r| t_s[r] == first) && td.data.session_id.is_none() {
        return None;
    }
    let index: std::collections::HashMap<usize, usize> =
        td.rows.iter().enumerate().map(|(i, &r)| (r, i)).collect();
    let ordered = crate::holdout::time_order(td.data, &td.rows);
    // The clock: time since the first reading, each session starting where
    // the previous one ended.
    let session = |r: usize| td.data.session_id.as_ref().map_or(0, |s| s[r]);
    let mut clock = Vec::with_capacity(n);
    let mut c = 0.0f64;
    for (k, &r) in ordered.iter().enumerate() {
        if k > 0 {
            let p = ordered[k - 1];
            if session(p) == session(r) {
                c += (t_s[r] - t_s[p]).max(0.0);
            }
        }
        clock.push(c);
    }
    let total = c;
    let mut blocks = vec![Vec::new(); FORWARD_BLOCKS];
    for (i, r) in ordered.iter().enumerate() {
        let b = if total > 0.0 {
            ((clock[i] / total * FORWARD_BLOCKS as f64) as usize).min(FORWARD_BLOCKS - 1)
        } else {
            i * FORWARD_BLOCKS / n
        };
        blocks[b].push(index[r]);
    }
    blocks.retain(|b| !b.is_empty());
    (blocks.len() >= 2).then_some(blocks)
}

/// RMS over `blocks` of `v`, each block weighing the same whatever its
/// number of readings (an hour sampled 500 times more densely is not 500
/// times more of a test of what happens later): √(mean over blocks of the
/// block's mean square).
pub(super) fn block_rms(blocks: &[Vec<usize>], v: impl Fn(usize) -> f64) -> f64 {
    let per: Vec<f64> = blocks
        .iter()
        .filter(|b| !b.is_empty())
        .map(|b| b.iter().map(|&i| v(i).powi(2)).sum::<f64>() / b.len() as f64)
        .collect();
    (per.iter().sum::<f64>() / per.len().max(1) as f64).sqrt()
}

/// Forward-chained RMS (µm) over blocks 1.. of `blocks` of the model's
/// residual `resid` (the model fitted on all rows, as in the ΔBIC) before
/// and after adding the candidate's columns `partialled` (the model
/// partialled out), whose coefficients are fitted on the earlier blocks
/// only: (before, after), each block weighing the same ([`block_rms`]).
pub(super) fn forward_rms(
    blocks: &[Vec<usize>],
    resid: &[f64],
    partialled: &[Vec<f64>],
) -> (f64, f64) {
    let sums = block_sums(blocks, resid, partialled);
    let (mut g, mut cr) = (sums[0].0.clone(), sums[0].1.clone());
    // Each block weighs the same (as `block_rms`): the mean of the blocks'
    // mean squares.
    let (mut before, mut after, mut count) = (0.0, 0.0, 0usize);
    for (block, (gb, crb, rrb)) in blocks.iter().zip(&sums).skip(1) {
        if !block.is_empty() {
            let beta = basis::pinv_solve(&g, &cr);
            let err = rrb - 2.0 * beta.dot(crb) + beta.dot(&(gb * &beta));
            let m = block.len() as f64;
            before += rrb / m;
            after += err.max(0.0) / m;
            count += 1;
        }
        g += gb;
        cr += crb;
    }
    let c = count.max(1) as f64;
    ((before / c).sqrt(), (after / c).sqrt())
}

/// A block's Σccᵀ, Σcr and Σr² ([`block_sums`]).
type BlockSums = (DMatrix<f64>, DVector<f64>, f64);

/// Per-block sums Σcᵢcⱼ, Σcᵢr, Σr² of the columns `cols` and the values
/// `r` (one pass over each block's rows): the fit to blocks 0..b is the
/// running total of their sums, and the squared error of its prediction
/// of a block is Σr² − 2βᵀΣcr + βᵀ(Σccᵀ)β over that block's rows — no
/// copies of the training rows per block.
fn block_sums(blocks: &[Vec<usize>], r: &[f64], cols: &[Vec<f64>]) -> Vec<BlockSums> {
    let k = cols.len();
    blocks
        .iter()
        .map(|block| {
            let g = DMatrix::from_fn(k, k, |a, b| {
                block.iter().map(|&i| cols[a][i] * cols[b][i]).sum()
            });
            let cr = DVector::from_fn(k, |a, _| block.iter().map(|&i| cols[a][i] * r[i]).sum());
            let rr = block.iter().map(|&i| r[i] * r[i]).sum();
            (g, cr, rr)
        })
        .collect()
}

/// Forward-chained RMS (µm) of the readings `y` with the whole model — the
/// span of `model` and the columns `extra` — refitted on the earlier blocks
/// only (the level too), predicting *every* later block: from each origin
/// i = 1 … the model fitted on blocks 0..i predicts blocks i, i+1, …, each
/// (origin, block) pair weighing the same. What a user who measured the
/// first hours asks: will it predict the rest — the next block and the
/// last? A sensor that only wandered with the error on one day follows
/// the next few hours and strays over a longer horizon (issue 24's control
/// seed 2: next block 1.30 → 0.91 µm, every later block 1.37 → 5.2); a
/// sensor that causes the growth holds at every horizon. Used for a time series
/// at one position (`autocorr::decides`), where the model is a constant and
/// the effects already added: there is no spatial seed to extrapolate, and
/// the constant fitted on all rows (as [`forward_rms`] takes it) tells the
/// earlier blocks where the later ones lie — a wandering error's later
/// level (issue 24's AR(1) control: a two-sensor "thermal" gained 26 %
/// with the level known, and predicted worse than the earlier mean
/// without it).
pub(super) fn forward_refit_rms(
    blocks: &[Vec<usize>],
    y: &[f64],
    model: &Basis,
    extra: &[Vec<f64>],
) -> f64 {
    let cols: Vec<Vec<f64>> = model.columns().iter().chain(extra).cloned().collect();
    let sums = block_sums(blocks, y, &cols);
    let (mut total, mut count) = (0.0, 0usize);
    for i in 1..blocks.len() {
        // Fitted on blocks 0..i, predicting each of blocks i.. .
        let (mut g, mut cr) = (sums[0].0.clone(), sums[0].1.clone());
        for (gb, crb, _) in &sums[1..i] {
            g += gb;
            cr += crb;
        }
        let beta = basis::pinv_solve(&g, &cr);
        for (block, (gb, crb, rrb)) in blocks.iter().zip(&sums).skip(i) {
            if !block.is_empty() {
                let err = rrb - 2.0 * beta.dot(crb) + beta.dot(&(gb * &beta));
                total += err.max(0.0) / block.len() as f64;
                count += 1;
            }
        }
    }
    (total / count.max(1) as f64).sqrt()
}

/// A candidate's forward-chained RMS before and after it (µm): its `raw`
/// columns with the whole model refitted on the earlier blocks for a time
/// series at one position ([`forward_refit_rms`]), elsewhere its
/// `partialled` columns alone refitted against the model's residual
/// ([`forward_rms`]).
pub(super) fn candidate_forward_rms(
    td: &TargetData,
    st: &State,
    blocks: &[Vec<usize>],
    raw: &[Vec<f64>],
    partialled: &[Vec<f64>],
) -> (f64, f64) {
    if super::autocorr::decides(td) {
        (
            forward_refit_rms(blocks, &td.y, &st.basis, &[]),
            forward_refit_rms(blocks, &td.y, &st.basis, raw),
        )
    } else {
        forward_rms(blocks, &st.resid, partialled)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::thermal_test::spindle_thermal;

    /// The spindle thermal test at one point: a cubic in time follows the
    /// whole 48 h when each block of time is predicted from the others on
    /// both sides of it, but not when the later blocks are predicted from
    /// the earlier ones — the cool-down and the second day are not where a
    /// polynomial fitted to the warm-up goes. A temperature predicts them.
    #[test]
    fn forward_chaining_rejects_a_drift_the_block_hold_out_accepts() {
        // The first day to the evening: an hour cold, 8 h of warm-up to a
        // steady state, 7 h of cool-down — one smooth hump.
        let full = spindle_thermal(1).data;
        let day: Vec<usize> = (0..=16 * 60).collect();
        let data = crate::data::subset(&full, &day);
        let none = crate::progress::Sink::none();
        let (td, how) = TargetData::new(&data, Norm::from_data(&data), 2, &none);
        assert!(how.contains("time"), "{how}");
        let st = State::new(&td, &Seed::Cubic19, &[]).unwrap();
        assert!(st.held_out_rms.is_finite());
        let blocks = forward_blocks(&td).unwrap();
        let gains = |spec: &str| {
            let ff = fwl(&td, &st, &spec.parse().unwrap(), 0).unwrap();
            let block = 1.0 - st.holdout.rms(&ff.cols).unwrap() / st.held_out_rms;
            let (before, after) = forward_rms(blocks, &st.resid, &ff.partialled);
            (block, 1.0 - after / before)
        };
        let (block, forward) = gains("drift:target=ez,order=3");
        assert!(block >= 0.10, "block hold-out gain of t³ {block}");
        assert!(forward < 0.10, "forward gain of t³ {forward}");
        let (_, forward) = gains("thermal:target=ez,channel=spindle_housing");
        assert!(
            forward > 0.5,
            "forward gain of the housing sensor {forward}"
        );
    }
    /// The one-position forward check refits the level on the earlier
    /// blocks only and predicts every later block from each origin: a
    /// level that jumps in the last block is missed from all three
    /// origins (3 of the 6 origin–block pairs at 36 µm²), not only from
    /// the last (next block only: 1 of 3), and never known in advance.
    #[test]
    fn the_refitted_forward_check_predicts_every_later_block_from_earlier_ones() {
        let blocks: Vec<Vec<usize>> = (0..4).map(|b| vec![2 * b, 2 * b + 1]).collect();
        let y = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 6.0, 6.0];
        let level = Basis::new(&[vec![1.0; 8]], 8);
        let got = forward_refit_rms(&blocks, &y, &level, &[]);
        assert!((got - 18f64.sqrt()).abs() < 1e-9, "{got}");
        // A column that carries the jump predicts it once it has been
        // seen... and here it never is before the last block: no better.
        let step = vec![vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0]];
        let with = forward_refit_rms(&blocks, &y, &level, &step);
        assert!((with - got).abs() < 1e-9, "{with}");
        // A column seen to move with y on the earliest block already does.
        let ramp = vec![(0..8).map(|i| 0.5 * i as f64).collect::<Vec<f64>>()];
        let y2: Vec<f64> = ramp[0].iter().map(|r| 2.0 * r).collect();
        assert!(forward_refit_rms(&blocks, &y2, &level, &ramp) < 1e-6);
        assert!(forward_refit_rms(&blocks, &y2, &level, &[]) > 2.0);
    }
}
