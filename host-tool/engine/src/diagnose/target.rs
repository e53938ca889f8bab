//! One target's data and its fitted current model: the rows, values and
//! hold-out blocks of `ex`, `ey` or `ez` ([`TargetData`]), the model's least-squares
//! fit and block-held-out RMS ([`State`]), and a candidate's fit with the
//! model partialled out (Frisch–Waugh–Lovell, [`fwl`]). Everything the
//! candidate search, the scoring and the path work on.

use anyhow::{bail, Result};

use crate::data::{Dataset, TARGETS};
use crate::effect::Effect;
use crate::features::{seed_monomials, Feature, Norm};
use crate::regions::bin_index;

use super::linalg::{self, small_fit, Basis, HoldOut};

/// One target's rows, values and hold-out blocks.
pub(super) struct TargetData<'a> {
    pub(super) data: &'a Dataset,
    pub(super) norm: Norm,
    pub(super) t: usize,
    pub(super) rows: Vec<usize>,
    pub(super) y: Vec<f64>,
    pub(super) fold: Vec<usize>,
    pub(super) nfolds: usize,
}

impl TargetData<'_> {
    pub(super) fn col(&self, f: &Feature) -> Result<Vec<f64>> {
        let full = f.column(self.data, &self.norm)?;
        Ok(self.rows.iter().map(|&r| full[r]).collect())
    }
}

/// The fitted current model of one target.
pub(super) struct State {
    pub(super) adds: Vec<String>,
    /// The model's columns, and the `add` string each belongs to (None for
    /// the seed's): for the fitted component of each effect in the report.
    pub(super) cols: Vec<Vec<f64>>,
    pub(super) owner: Vec<Option<String>>,
    pub(super) basis: Basis,
    pub(super) resid: Vec<f64>,
    pub(super) rss: f64,
    pub(super) holdout: HoldOut,
    pub(super) held_out_rms: f64,
}

impl State {
    pub(super) fn new(td: &TargetData, seed: &str, adds: &[String]) -> Result<State> {
        // The seed's terms as `fit` has them: none in an axis held at one
        // position (those would be zero columns).
        let axes = td.data.varying_axes();
        let mut cols = Vec::new();
        let mut owner = Vec::new();
        for exp in seed_monomials(seed, td.t, &axes)? {
            cols.push(td.col(&Feature::Monomial { exp })?);
            owner.push(None);
        }
        for a in adds {
            let e = Effect::parse(a)?;
            if e.target == td.t {
                for f in &e.features {
                    cols.push(td.col(f)?);
                    owner.push(Some(a.clone()));
                }
            }
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
        let rss = linalg::dot(&resid, &resid);
        let holdout = HoldOut::new(&cols, &td.y, &td.fold, td.nfolds);
        let held_out_rms = holdout.rms(&[]).unwrap_or(f64::NAN);
        Ok(State {
            adds: adds.to_vec(),
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

    /// The fitted component of effect `add` in this model (its columns times
    /// their coefficients in `fit`, the model's full least-squares fit), per
    /// row.
    pub(super) fn component(&self, fit: &linalg::SmallFit, add: &str) -> Option<Vec<f64>> {
        let idx: Vec<usize> = (0..self.cols.len())
            .filter(|&i| self.owner[i].as_deref() == Some(add))
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
    pub(super) fit: linalg::SmallFit,
    pub(super) dbic: f64,
}

pub(super) fn fwl(td: &TargetData, st: &State, spec: &str, searched: usize) -> Result<FwlFit> {
    let e = Effect::parse(spec)?;
    let cols: Vec<Vec<f64>> = e
        .features
        .iter()
        .map(|f| td.col(f))
        .collect::<Result<_>>()?;
    let partialled: Vec<Vec<f64>> = cols.iter().map(|c| st.basis.residual(c)).collect();
    let share = cols
        .iter()
        .zip(&partialled)
        .map(|(c, p)| {
            let cc = linalg::dot(c, c);
            if cc > 0.0 {
                linalg::dot(p, p) / cc
            } else {
                0.0
            }
        })
        .fold(f64::INFINITY, f64::min);
    let fit = small_fit(&partialled, &st.resid);
    let n = td.rows.len() as f64;
    let k = (fit.rank + searched) as f64;
    let dbic = n * (fit.rss.max(1e-300) / st.rss.max(1e-300)).ln() + k * n.ln();
    Ok(FwlFit {
        cols,
        partialled,
        share,
        fit,
        dbic,
    })
}

pub(super) fn hold_out_blocks(
    data: &Dataset,
    rows: &[usize],
    norm: &Norm,
) -> (Vec<usize>, usize, String) {
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
