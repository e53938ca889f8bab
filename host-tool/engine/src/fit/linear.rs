//! Linear models: per target present, weighted least squares of the seed's
//! monomials plus the `--add` effects' columns on the rows where that target
//! is measured. The checks a user needs happen here, in their words:
//! too few distinct points for the terms (docs/cli.md § Measurement CSV), collinear columns
//! named by feature, an ill-conditioned design reported with its number.

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use crate::data::{Dataset, AXES, TARGETS};
use crate::effect::Effect;
use crate::features::{feature_uses_axis, Feature, Norm};
use crate::holdout;
use crate::linalg::lsq::{self, Gram, LsqError, LsqSolution, ILL_CONDITIONED};
use crate::model::{FitStats, FittedModel, LinearModel, LinearOutput, Seed};
use crate::warning::Warning;

/// The terms of `seed` + `adds` for target `target` on data with the
/// given axes: the seed's monomials (none in an axis not among `axes`:
/// those would be zero columns), then the columns of each effect on
/// `target` in the order of `adds`, each with the index into `adds` of
/// the effect it belongs to (None for the seed's). The one list both the
/// fit's [`Design`] and the diagnosis' model of a target build their
/// columns from.
pub fn terms_for(
    seed: Seed,
    adds: &[Effect],
    target: usize,
    axes: &[usize],
) -> Result<Vec<(Feature, Option<usize>)>> {
    let mut f: Vec<(Feature, Option<usize>)> = seed
        .monomials(target, axes)?
        .into_iter()
        .map(|exp| (Feature::Monomial { exp }, None))
        .collect();
    for (i, e) in adds.iter().enumerate() {
        if e.target() == target {
            f.extend(e.features.iter().map(|x| (x.clone(), Some(i))));
        }
    }
    Ok(f)
}

/// The features of `seed` (+ the effects for `target`) for target `target`
/// on data with the given axes ([`terms_for`] without their owners).
pub fn features_for(
    seed: Seed,
    adds: &[Effect],
    target: usize,
    axes: &[usize],
) -> Result<Vec<Feature>> {
    Ok(terms_for(seed, adds, target, axes)?
        .into_iter()
        .map(|(f, _)| f)
        .collect())
}

/// One target's fit with its statistics.
#[derive(Clone, Debug)]
pub struct TargetFit {
    /// The fitted output.
    pub output: LinearOutput,
    /// Rows used.
    pub rows: Vec<usize>,
    /// Residual (measured − model) per used row, µm.
    pub residual_um: Vec<f64>,
    /// Condition number of the weighted, column-scaled design.
    pub condition_number: f64,
    /// Solved by the normal equations from Gram sums (false: by QR).
    pub by_gram: bool,
}

/// Fits `features` to target `target` on the rows of `rows` where it is
/// measured. `label` prefixes messages (`ex`, `ex, patch z 0…50 mm`).
pub fn fit_target(
    data: &Dataset,
    norm: &Norm,
    features: &[Feature],
    target: usize,
    rows: &[usize],
    label: &str,
) -> Result<TargetFit> {
    let Some(err) = &data.err_um[target] else {
        bail!("the data has no {}_um column", TARGETS[target]);
    };
    let rows: Vec<usize> = rows.iter().copied().filter(|&r| err[r].is_some()).collect();
    Ok(fit_targets(data, norm, features, &[target], &rows, label)?.remove(0))
}

/// Fits `features` to each of `targets` on `rows`, where every one of them
/// is measured: one design matrix, one QR and one SVD for all (the three
/// targets of a seed model on a full grid). `label` prefixes messages.
fn fit_targets(
    data: &Dataset,
    norm: &Norm,
    features: &[Feature],
    targets: &[usize],
    rows: &[usize],
    label: &str,
) -> Result<Vec<TargetFit>> {
    let a = lsq::design_matrix(data, norm, features, rows)?;
    let distinct = lsq::distinct_rows_up_to(&a, features.len());
    if distinct < features.len() {
        bail!(
            "{label}: {distinct} distinct points but the model has {} terms — measure more points or choose a smaller model",
            features.len()
        );
    }
    let mut b = DMatrix::zeros(rows.len(), targets.len());
    for (c, &t) in targets.iter().enumerate() {
        let err = data.err_um[t].as_ref();
        for (i, &r) in rows.iter().enumerate() {
            b[(i, c)] = err.and_then(|col| col[r]).unwrap_or(0.0);
        }
    }
    let w = holdout::weights(data, rows)?;
    let sols = match lsq::solve_multi(&a, &b, w.as_ref()) {
        Ok(s) => s,
        Err(e) => {
            if let Some(LsqError::RankDeficient { groups, rank, cols }) =
                e.downcast_ref::<LsqError>()
            {
                let named: Vec<String> = groups
                    .iter()
                    .map(|g| {
                        let names: Vec<String> =
                            g.iter().map(|&j| features[j].to_string()).collect();
                        if g.len() == 1 {
                            // A term in an axis held at one position is a
                            // zero column (u = 0 there), not a zero position.
                            let held = (0..3).find_map(|a| {
                                feature_uses_axis(&features[g[0]], a)
                                    .then(|| data.constant_position(a).map(|p| (a, p)))
                                    .flatten()
                            });
                            match held {
                                Some((a, p)) => format!(
                                    "{} cannot be fitted: {} is {p} mm at every measured point",
                                    names[0], AXES[a]
                                ),
                                None => format!("{} is zero at every measured point", names[0]),
                            }
                        } else {
                            format!("{{{}}} are collinear", names.join(", "))
                        }
                    })
                    .collect();
                bail!(
                    "{label}: the model's columns are linearly dependent on these data (rank {rank} of {cols}): {} — drop one of each group, or measure where they differ",
                    named.join("; ")
                );
            }
            return Err(e.context(format!("{label}: least squares failed")));
        }
    };
    Ok(sols
        .into_iter()
        .zip(targets)
        .enumerate()
        .map(|(c, (sol, &target))| {
            let pred = &a * &sol.coef;
            TargetFit {
                output: LinearOutput {
                    target,
                    features: features.to_vec(),
                    coef_um: sol.coef.iter().copied().collect(),
                    coef_sd_um: sol.coef_sd.iter().copied().collect(),
                },
                rows: rows.to_vec(),
                residual_um: (0..rows.len()).map(|i| b[(i, c)] - pred[i]).collect(),
                condition_number: sol.condition_number,
                by_gram: false,
            }
        })
        .collect())
}

/// The design of a linear fit, built once: the columns of every target's
/// features (their union — the seed's monomials once, each target's
/// `--add` columns after) over the rows where any target is measured, the
/// rows' weights and the targets' values. The fit, its block hold-out and
/// the outlier screen's rounds all read it and none copies it: each target
/// is a set of its columns and of its rows. Only the QR fallback (an
/// ill-conditioned or rank-deficient design) builds its own matrix.
#[derive(Debug)]
pub struct Design {
    /// The union of the targets' features, in the order first met.
    pub features: Vec<Feature>,
    /// Data rows where any target is measured, ascending.
    pub rows: Vec<usize>,
    /// |rows| × |features|, in the units [`Feature::column`] gives.
    pub a: DMatrix<f64>,
    /// Weights 1/u² per entry of `rows` (None without `u_um`).
    pub w: Option<DVector<f64>>,
    /// Measured values (µm), one column per entry of `targets`; 0 on a row
    /// where that target is not measured (never read there).
    pub b: DMatrix<f64>,
    /// The targets with values, in target order.
    pub targets: Vec<DesignTarget>,
}

/// One target of a [`Design`].
#[derive(Debug)]
pub struct DesignTarget {
    /// Target index (0 = ex).
    pub target: usize,
    /// Its features (`seed` + its `--add` effects), in model order.
    pub features: Vec<Feature>,
    /// The columns of [`Design::a`] holding them, in the same order.
    pub cols: Vec<usize>,
    /// Indices into [`Design::rows`] where the target is measured, ascending.
    pub local: Vec<usize>,
}

impl Design {
    /// The design of `seed` + `adds` for every target of `data` with at
    /// least one value, on `data`'s own moving axes (as [`fit`] chooses).
    pub fn new(data: &Dataset, norm: &Norm, seed: Seed, adds: &[Effect]) -> Result<Design> {
        let axes = data.varying_axes();
        let mut features: Vec<Feature> = Vec::new();
        let mut targets = Vec::new();
        let mut measured = vec![false; data.len()];
        for t in data.targets() {
            let mut any = false;
            for (r, _) in data.measured(t) {
                measured[r] = true;
                any = true;
            }
            if !any {
                continue;
            }
            let f = features_for(seed, adds, t, &axes)?;
            let cols = f
                .iter()
                .map(|x| match features.iter().position(|y| y == x) {
                    Some(j) => j,
                    None => {
                        features.push(x.clone());
                        features.len() - 1
                    }
                })
                .collect();
            targets.push(DesignTarget {
                target: t,
                features: f,
                cols,
                local: Vec::new(),
            });
        }
        let rows: Vec<usize> = (0..data.len()).filter(|&r| measured[r]).collect();
        drop(measured);
        for tg in &mut targets {
            tg.local = data
                .measured(tg.target)
                .map(|(r, _)| rows.binary_search(&r).expect("a measured row is in rows"))
                .collect();
        }
        let a = lsq::design_matrix(data, norm, &features, &rows)?;
        let w = holdout::weights(data, &rows)?;
        let b = DMatrix::from_fn(rows.len(), targets.len(), |i, k| {
            data.err_um[targets[k].target]
                .as_ref()
                .and_then(|col| col[rows[i]])
                .unwrap_or(0.0)
        });
        Ok(Design {
            features,
            rows,
            a,
            w,
            b,
            targets,
        })
    }

    /// The index into [`Design::rows`] of data row `r` (which must be one).
    pub fn local_of(&self, r: usize) -> usize {
        self.rows
            .binary_search(&r)
            .expect("the row is in the design")
    }

    /// The Gram sums of columns `cols` and the values of targets `ks`
    /// (indices into [`Design::targets`]) over `local`.
    pub fn gram(&self, cols: &[usize], ks: &[usize], local: &[usize]) -> Gram {
        Gram::over(&self.a, cols, &self.b, ks, self.w.as_ref(), local)
    }

    /// The model Σⱼ coefⱼ·a[i, colsⱼ] at each of `local`, summed in
    /// feature order as [`LinearOutput::predict`] sums.
    pub fn predict(&self, cols: &[usize], coef: &[f64], local: &[usize]) -> Vec<f64> {
        let n = self.a.nrows();
        let a = self.a.as_slice();
        let mut out = vec![0.0; local.len()];
        // A chunk of rows at a time, so that the partial sums stay in cache
        // while every column is added to them; a chunk of consecutive rows
        // (most of them: a target measured on every row but a few
        // outliers) reads the columns as slices, without the gather.
        for (oc, lc) in out.chunks_mut(1024).zip(local.chunks(1024)) {
            let first = lc[0];
            let consecutive = lsq::consecutive(lc);
            for (&j, &c) in cols.iter().zip(coef) {
                let col = &a[j * n..(j + 1) * n];
                if consecutive {
                    for (o, v) in oc.iter_mut().zip(&col[first..first + lc.len()]) {
                        *o += c * v;
                    }
                } else {
                    for (o, &i) in oc.iter_mut().zip(lc) {
                        *o += c * col[i];
                    }
                }
            }
        }
        out
    }

    /// The coefficients (p × targets) of the targets `ks` on the columns
    /// `cols` and the rows `local`, from their Gram sums `gram` by the
    /// normal equations, with the decomposition they came from. When the
    /// Gram's condition number is [`REFINE_ABOVE`] or more, one step of
    /// iterative refinement (x += G⁻¹·AᵀW(b − Ax)) brings them to a QR
    /// solution's at round-off. None when the normal equations are not to
    /// be trusted ([`lsq::solve_gram`]) or leave no degree of freedom: the
    /// caller takes the QR path.
    pub fn coefficients(
        &self,
        cols: &[usize],
        ks: &[usize],
        local: &[usize],
        gram: &Gram,
    ) -> Option<(lsq::GramSolution, DMatrix<f64>)> {
        if local.len() <= cols.len() {
            return None;
        }
        let sol = lsq::solve_gram(gram)?;
        if sol.condition_number.powi(2) < REFINE_ABOVE {
            let coef = sol.coef.clone();
            return Some((sol, coef));
        }
        // Residuals on all of `rows` (0 off `local`) so that AᵀWr is one
        // more chunked pass over the same rows.
        let mut r = DMatrix::zeros(self.rows.len(), ks.len());
        for (c, &k) in ks.iter().enumerate() {
            let pred = self.predict(cols, sol.coef.column(c).as_slice(), local);
            for (&i, pv) in local.iter().zip(pred) {
                r[(i, c)] = self.b[(i, k)] - pv;
            }
        }
        let all: Vec<usize> = (0..ks.len()).collect();
        let atr = Gram::rhs_over(&self.a, cols, &r, &all, self.w.as_ref(), local);
        let coef = &sol.coef + sol.apply(&atr);
        Some((sol, coef))
    }

    /// The weighted least-squares solutions of the targets `ks` on the
    /// columns `cols` and the rows `local` from their Gram sums
    /// ([`Design::coefficients`]), with their residuals and statistics as
    /// the QR path gives them.
    pub fn solve(
        &self,
        cols: &[usize],
        ks: &[usize],
        local: &[usize],
        gram: &Gram,
    ) -> Option<Vec<DesignFit>> {
        let (sol, coef) = self.coefficients(cols, ks, local, gram)?;
        let dof = local.len() - cols.len();
        Some(
            ks.iter()
                .enumerate()
                .map(|(c, &k)| {
                    let pred = self.predict(cols, coef.column(c).as_slice(), local);
                    let residual_um: Vec<f64> = (local.iter().zip(pred))
                        .map(|(&i, p)| self.b[(i, k)] - p)
                        .collect();
                    let rss: f64 = (local.iter().zip(&residual_um))
                        .map(|(&i, e)| self.w.as_ref().map_or(1.0, |w| w[i]) * e * e)
                        .sum();
                    let sigma2 = rss / dof as f64;
                    DesignFit {
                        sol: LsqSolution {
                            coef: coef.column(c).into_owned(),
                            coef_sd: sol.inv_diag.map(|v| (sigma2 * v).sqrt()),
                            rss,
                            dof,
                            rank: cols.len(),
                            condition_number: sol.condition_number,
                        },
                        residual_um,
                    }
                })
                .collect(),
        )
    }
}

/// The condition number of the column-scaled Gram from which
/// [`Design::coefficients`] refines its solution once: below it the
/// normal equations' error (~ε·condition ≤ 10⁻¹² relative) is already at
/// the level by which two QR implementations differ (nalgebra's and
/// LAPACK's, 7·10⁻¹² on the 180k-row benchmark), and the refinement's two
/// passes over the rows would buy nothing.
pub const REFINE_ABOVE: f64 = 1e4;

/// One target's solution from a [`Design`] with its residuals.
#[derive(Debug)]
pub struct DesignFit {
    /// The least-squares solution.
    pub sol: LsqSolution,
    /// Measured − model (µm, unweighted) at each of the rows solved on.
    pub residual_um: Vec<f64>,
}

/// One group's fits with their held-out RMS and hold-out description.
struct GroupFit {
    fits: Vec<(TargetFit, Option<Result<f64>>)>,
    holdout: String,
}

/// Fits the targets `ks` of `design` (same columns, same rows) from one
/// Gram — the sum of their hold-out blocks' when `blocks` > 0, so that the
/// fit and its k refits take one pass over the rows — or, when the normal
/// equations are not to be trusted, by QR ([`fit_targets`]) as before.
fn fit_group(
    data: &Dataset,
    norm: &Norm,
    design: &Design,
    ks: &[usize],
    blocks: usize,
) -> Result<GroupFit> {
    let first = &design.targets[ks[0]];
    let (cols, local) = (&first.cols, &first.local);
    let rows: Vec<usize> = local.iter().map(|&i| design.rows[i]).collect();
    let bl = if blocks > 0 {
        holdout::blocks(data, &rows, blocks)
    } else {
        Vec::new()
    };
    let holdout_text = if blocks > 0 {
        holdout::describe_blocks(data, &rows, &bl)
    } else {
        String::new()
    };
    let grams: Vec<Gram> = if bl.len() >= 2 {
        bl.iter()
            .map(|b| {
                let lb: Vec<usize> = b.iter().map(|&r| design.local_of(r)).collect();
                design.gram(cols, ks, &lb)
            })
            .collect()
    } else {
        vec![design.gram(cols, ks, local)]
    };
    let total = Gram::total(&grams).expect("at least one Gram");
    // A held-out RMS the Gram path cannot give is asked of the QR path
    // (which also words the errors: one block, a rank-deficient refit).
    let qr_held_out =
        |t: usize, f: &[Feature]| holdout::held_out_rms_k(data, &rows, f, t, norm, blocks);
    let Some(sols) = design.solve(cols, ks, local, &total) else {
        let targets: Vec<usize> = ks.iter().map(|&k| design.targets[k].target).collect();
        let label: Vec<&str> = targets.iter().map(|&t| TARGETS[t]).collect();
        let tfs = match fit_targets(
            data,
            norm,
            &first.features,
            &targets,
            &rows,
            &label.join(", "),
        ) {
            Ok(tfs) => tfs,
            // Name the first target that fails on its own, as a lone fit would.
            Err(_) if targets.len() > 1 => targets
                .iter()
                .map(|&t| fit_target(data, norm, &first.features, t, &rows, TARGETS[t]))
                .collect::<Result<_>>()?,
            Err(e) => return Err(e),
        };
        return Ok(GroupFit {
            fits: tfs
                .into_iter()
                .map(|tf| {
                    let h = (blocks > 0).then(|| qr_held_out(tf.output.target, &first.features));
                    (tf, h)
                })
                .collect(),
            holdout: holdout_text,
        });
    };
    let refits = if bl.len() >= 2 {
        holdout::block_refits(&grams)
    } else {
        None
    };
    let mut fits = Vec::new();
    for (c, (&k, DesignFit { sol, residual_um })) in ks.iter().zip(sols).enumerate() {
        let tg = &design.targets[k];
        let held = match &refits {
            Some(coefs) => {
                let mut ss = 0.0;
                for (b, coef) in bl.iter().zip(coefs) {
                    let lb: Vec<usize> = b.iter().map(|&r| design.local_of(r)).collect();
                    let pred = design.predict(cols, coef.column(c).as_slice(), &lb);
                    ss += lb
                        .iter()
                        .zip(pred)
                        .map(|(&i, p)| (design.b[(i, k)] - p).powi(2))
                        .sum::<f64>();
                }
                Some(Ok((ss / local.len() as f64).sqrt()))
            }
            None => (blocks > 0).then(|| qr_held_out(tg.target, &tg.features)),
        };
        fits.push((
            TargetFit {
                output: LinearOutput {
                    target: tg.target,
                    features: tg.features.clone(),
                    coef_um: sol.coef.iter().copied().collect(),
                    coef_sd_um: sol.coef_sd.iter().copied().collect(),
                },
                rows: rows.clone(),
                residual_um,
                condition_number: sol.condition_number,
                by_gram: true,
            },
            held,
        ));
    }
    Ok(GroupFit {
        fits,
        holdout: holdout_text,
    })
}

/// Fits the linear model `seed` + `adds` to every target present, with the
/// held-out RMS over `blocks` hold-out blocks (none with `blocks` = 0).
pub fn fit(
    data: &Dataset,
    seed: Seed,
    adds: &[Effect],
    blocks: usize,
) -> Result<(FittedModel, FitStats)> {
    let norm = Norm::from_data(data);
    // An axis held at one position is treated like an absent one (its
    // monomials would be zero columns); `fit::fit` says so in a warning.
    let axes = data.varying_axes();
    let mut stats = FitStats::default();
    if axes.is_empty() {
        // A time series at one point (an ISO 230-3 thermal test): no
        // position term can be fitted, so the seed leaves its constant per
        // target, and the `--add` effects (temperatures, time) carry what
        // changes.
        stats.warnings.push(Warning::new("no_travel", format!(
            "{}: every measured point lies at one position; {seed} is reduced to a constant per target (no travel to fit a polynomial to) — the --add effects (thermal, drift) model what changes over time",
            data.source
        )));
    }
    for t in data.targets() {
        if data.measured(t).next().is_none() {
            stats.warnings.push(Warning::new(
                "empty_target",
                format!("{}: the column has no values; not modelled", TARGETS[t]),
            ));
        }
    }
    let design = Design::new(data, &norm, seed, adds)?;
    // Targets with the same features measured on the same rows (a seed
    // model on a full grid) share one Gram and one solve; the rest are
    // fitted alone — all from the one design matrix.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (k, tg) in design.targets.iter().enumerate() {
        match groups.iter_mut().find(|g| {
            let other = &design.targets[g[0]];
            other.cols == tg.cols && other.local == tg.local
        }) {
            Some(g) => g.push(k),
            None => groups.push(vec![k]),
        }
    }
    let mut fits: Vec<(TargetFit, Option<Result<f64>>, String)> = Vec::new();
    for ks in &groups {
        let g = fit_group(data, &norm, &design, ks, blocks)?;
        fits.extend(g.fits.into_iter().map(|(tf, h)| (tf, h, g.holdout.clone())));
    }
    drop(design);
    fits.sort_by_key(|(tf, _, _)| tf.output.target);
    let mut outputs = Vec::new();
    for (tf, held, holdout_text) in fits {
        let (t, features) = (tf.output.target, &tf.output.features);
        let name = TARGETS[t].to_string();
        stats.terms = stats.terms.max(features.len());
        stats.terms_per_target.insert(name.clone(), features.len());
        stats.rows.insert(name.clone(), tf.rows.len());
        stats
            .rms_um
            .insert(name.clone(), holdout::rms(tf.residual_um.iter().copied()));
        stats.max_abs_um.insert(
            name.clone(),
            tf.residual_um.iter().fold(0.0, |m, e| f64::max(m, e.abs())),
        );
        if tf.condition_number.is_finite() {
            stats
                .condition_number
                .insert(name.clone(), tf.condition_number);
        }
        if tf.condition_number > ILL_CONDITIONED {
            stats.warnings.push(Warning::new("ill_conditioned", format!(
                "{name}: ill-conditioned design (condition number {:.3e} > {ILL_CONDITIONED:.0e}): some terms nearly repeat each other on these points; coefficients are uncertain (see coef_sd_um) and extrapolation is unreliable",
                tf.condition_number
            )));
        }
        // blocks = 0: the caller wants the fit only, not its held-out RMS.
        match held {
            None => {}
            Some(Ok(h)) => {
                stats.held_out_rms_um.insert(name.clone(), h);
            }
            Some(Err(e)) => stats.warnings.push(Warning::new(
                "no_held_out",
                format!("{name}: no held-out RMS: {e:#}"),
            )),
        }
        if blocks > 0 && stats.holdout.is_empty() {
            stats.holdout = holdout_text;
        }
        outputs.push(tf.output);
    }
    if outputs.is_empty() {
        bail!("{}: no error values to fit", data.source);
    }
    Ok((FittedModel::Linear(LinearModel { norm, outputs }), stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::CUBIC19;

    /// The seed's 17 × 11 × 11 grid on 800 × 500 × 500 mm.
    pub(crate) fn mill_grid() -> Dataset {
        let [x, y, z] = crate::data::grid_positions([17, 11, 11], [50.0; 3]);
        let n = x.len();
        Dataset {
            source: "mill".into(),
            pos_mm: [Some(x), Some(y), Some(z)],
            err_um: [
                Some(vec![None; n]),
                Some(vec![None; n]),
                Some(vec![None; n]),
            ],
            ..Default::default()
        }
    }

    fn set_target(d: &mut Dataset, t: usize, f: impl Fn(usize, [f64; 3]) -> f64) {
        let norm = Norm::from_data(d);
        let v = (0..d.len())
            .map(|r| {
                let u = [0, 1, 2].map(|a| norm.u(a, d.pos(a, r)));
                Some(f(r, u))
            })
            .collect();
        d.err_um[t] = Some(v);
    }

    #[test]
    fn cubic19_recovers_known_coefficients_exactly() {
        let mut d = mill_grid();
        let coef: Vec<f64> = (0..19).map(|j| (j as f64 * 0.7).sin() * 5.0).collect();
        for t in 0..3 {
            let c = coef.clone();
            set_target(&mut d, t, move |_, u| {
                CUBIC19
                    .iter()
                    .zip(&c)
                    .map(|(e, c)| {
                        c * (t as f64 + 1.0)
                            * (0..3).map(|a| u[a].powi(e[a] as i32)).product::<f64>()
                    })
                    .sum()
            });
        }
        let (m, s) = fit(&d, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(m) = m else { panic!() };
        for o in &m.outputs {
            for (j, c) in o.coef_um.iter().enumerate() {
                assert!(
                    (c - coef[j] * (o.target as f64 + 1.0)).abs() < 1e-9,
                    "{} {j}",
                    o.target
                );
            }
        }
        assert_eq!(s.terms, 19);
        for t in ["ex", "ey", "ez"] {
            assert!(s.rms_um[t] < 1e-9);
            assert!(s.held_out_rms_um[t] < 1e-8, "{}", s.held_out_rms_um[t]);
            assert!(s.condition_number[t] < 100.0);
        }
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    }

    #[test]
    fn effects_are_recovered_with_the_seed() {
        let mut d = mill_grid();
        // A 30 mm periodic term along y on ey (a 5 mm or 20 mm period would
        // alias to zero at the 50 mm grid: sin(2π·50j/20) = sin(5πj) = 0;
        // 30 mm repeats every 3 planes and is identifiable) plus reversal on x.
        let n = d.len();
        d.dir[0] = Some((0..n).map(|r| if r % 2 == 0 { 1 } else { -1 }).collect());
        let y = d.pos_mm[1].clone().unwrap();
        let dir = d.dir[0].clone().unwrap();
        set_target(&mut d, 1, |r, u| {
            1.0 + 2.0 * u[0] - 0.5 * u[1] * u[1]
                + 0.8 * (std::f64::consts::TAU * y[r] / 30.0).sin()
                + 0.3 * (std::f64::consts::TAU * y[r] / 30.0).cos()
                + 1.5 * f64::from(dir[r])
        });
        let adds = [
            Effect::parse("periodic:target=ey,axis=y,period_mm=30").unwrap(),
            Effect::parse("reversal:target=ey,axis=x").unwrap(),
        ];
        let (m, s) = fit(&d, Seed::Cubic19, &adds, 5).unwrap();
        let FittedModel::Linear(m) = m else { panic!() };
        let o = &m.outputs[0];
        assert_eq!(o.target, 1);
        assert_eq!(o.features.len(), 22);
        let c = &o.coef_um;
        assert!(
            (c[19] - 0.8).abs() < 1e-9 && (c[20] - 0.3).abs() < 1e-9 && (c[21] - 1.5).abs() < 1e-9,
            "{c:?}"
        );
        assert!(
            (c[0] - 1.0).abs() < 1e-9 && (c[1] - 2.0).abs() < 1e-9 && (c[5] + 0.5).abs() < 1e-9
        );
        assert_eq!(s.terms, 22);
        assert!(s.rms_um["ey"] < 1e-9);
        assert!(!s.rms_um.contains_key("ex"));
    }

    #[test]
    fn u_um_weights_silence_a_row_with_huge_uncertainty() {
        let mut d = mill_grid();
        set_target(&mut d, 0, |_, u| 1.0 + u[0] - u[1] * u[2]);
        d.err_um[1] = None;
        d.err_um[2] = None;
        let n = d.len();
        if let Some(c) = d.err_um[0].as_mut() {
            c[100] = c[100].map(|v| v + 500.0);
        }
        let mut u = vec![0.1; n];
        u[100] = 1e8;
        d.u_um = Some(u);
        let (m, s) = fit(&d, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(m) = m else { panic!() };
        let c = &m.outputs[0].coef_um;
        assert!(
            (c[0] - 1.0).abs() < 1e-6 && (c[1] - 1.0).abs() < 1e-6,
            "{c:?}"
        );
        // The outlier still shows in the (unweighted) residual statistics.
        assert!(s.max_abs_um["ex"] > 499.0);
        d.u_um = Some(vec![0.1; n]);
        let (m, _) = fit(&d, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(m) = m else { panic!() };
        assert!((m.outputs[0].coef_um[0] - 1.0).abs() > 0.01);
        // u ≤ 0 is bad input.
        d.u_um = Some(vec![0.0; n]);
        let e = fit(&d, Seed::Cubic19, &[], 5).unwrap_err().to_string();
        assert!(e.contains("positive"), "{e}");
    }

    #[test]
    fn nearly_collinear_terms_warn_with_the_condition_number() {
        let mut d = mill_grid();
        set_target(&mut d, 0, |_, u| u[0]);
        d.err_um[1] = None;
        d.err_um[2] = None;
        // A tool length that barely changes along x: `abbe` is almost the
        // constant column (ill-conditioned, yet above the rank threshold).
        let x = d.pos_mm[0].clone().unwrap();
        d.tool_mm = Some(x.iter().map(|p| 100.0 + 1e-5 * (p / 37.0).sin()).collect());
        let adds = [Effect::parse("abbe:target=ex").unwrap()];
        let (_, s) = fit(&d, Seed::Kinematic, &adds, 5).unwrap();
        assert!(
            s.condition_number["ex"] > ILL_CONDITIONED,
            "{:?}",
            s.condition_number
        );
        assert!(
            s.warnings.iter().any(|w| w.code == "ill_conditioned"
                && w.detail.starts_with("ex: ill-conditioned")),
            "{:?}",
            s.warnings
        );
    }

    #[test]
    fn too_few_distinct_points_is_an_error() {
        let d = mill_grid();
        // Keep only 3 × 3 × 1 positions (9 distinct points, measured twice each).
        let keep: Vec<usize> = (0..d.len())
            .filter(|&r| d.pos(0, r) <= 100.0 && d.pos(1, r) <= 100.0 && d.pos(2, r) == 0.0)
            .collect();
        let mut keep2 = keep.clone();
        keep2.extend(&keep);
        let mut d = crate::data::subset(&d, &keep2);
        // z is held at 0 mm: treated like an absent axis, so cubic19 keeps
        // its 10 terms in x and y — still more than the 9 points.
        set_target(&mut d, 0, |_, u| u[0]);
        d.err_um[1] = None;
        d.err_um[2] = None;
        let e = fit(&d, Seed::Cubic19, &[], 5).unwrap_err().to_string();
        assert!(
            e.contains("9 distinct points") && e.contains("10 terms"),
            "{e}"
        );
    }

    #[test]
    fn a_failed_shared_solve_names_the_target_as_a_lone_fit_would() {
        // ex, ey and ez measured on the same 9 distinct points share one
        // solve; when it fails, the message names the first target alone
        // (the lone fit's "ex: …"), not the group ("ex, ey, ez: …").
        let d = mill_grid();
        let keep: Vec<usize> = (0..d.len())
            .filter(|&r| d.pos(0, r) <= 100.0 && d.pos(1, r) <= 100.0 && d.pos(2, r) == 0.0)
            .collect();
        let mut d = crate::data::subset(&d, &keep);
        for t in 0..3 {
            set_target(&mut d, t, |_, u| u[0] + u[1]);
        }
        let e = fit(&d, Seed::Cubic19, &[], 5).unwrap_err().to_string();
        assert!(
            e.starts_with("ex: 9 distinct points but the model has 10 terms"),
            "{e}"
        );
    }

    #[test]
    fn an_axis_held_at_one_position_is_left_out_like_an_absent_one() {
        // The x line of the mill grid at y = z = 250 mm: cubic19 is the
        // cubic in x (the y and z monomials would be zero columns), exactly
        // the fit of the same data without the y and z columns.
        let g = mill_grid();
        let keep: Vec<usize> = (0..g.len())
            .filter(|&r| g.pos(1, r) == 250.0 && g.pos(2, r) == 250.0)
            .collect();
        let mut d = crate::data::subset(&g, &keep);
        set_target(&mut d, 0, |_, u| 1.0 + 2.0 * u[0] - 0.5 * u[0].powi(3));
        d.err_um[1] = None;
        d.err_um[2] = None;
        assert_eq!(d.varying_axes(), vec![0]);
        let (m, s) = fit(&d, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(m) = m else { panic!() };
        let mut absent = d.clone();
        absent.pos_mm[1] = None;
        absent.pos_mm[2] = None;
        let (ma, _) = fit(&absent, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(ma) = ma else {
            panic!()
        };
        assert_eq!(m.outputs[0].features, ma.outputs[0].features);
        assert_eq!(m.outputs[0].features.len(), 4);
        for (a, b) in m.outputs[0].coef_um.iter().zip(&ma.outputs[0].coef_um) {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
        assert_eq!(s.terms, 4);
        // The held axis' normalisation stays finite: u = 0 on the data.
        assert_eq!(m.norm.centre_mm[1], 250.0);
        assert!(m.norm.half_span_mm[1] > 0.0);
        // A data set at one position (a time series at one point) is fitted
        // by the seed's constant per target, and says so.
        let one = crate::data::subset(&d, &[3, 3, 5]);
        let mut one = one;
        for a in 0..3 {
            if let Some(c) = one.pos_mm[a].as_mut() {
                let p = c[0];
                c.iter_mut().for_each(|v| *v = p);
            }
        }
        let (m1, s1) = fit(&one, Seed::Cubic19, &[], 5).unwrap();
        let FittedModel::Linear(m1) = m1 else {
            panic!()
        };
        assert_eq!(s1.terms, 1);
        let ex = one.err_um[0].as_ref().unwrap();
        let mean = ex.iter().map(|v| v.unwrap()).sum::<f64>() / 3.0;
        assert!((m1.outputs[0].coef_um[0] - mean).abs() < 1e-9);
        assert!(
            s1.warnings.iter().any(|w| w.code == "no_travel"
                && w.detail
                    .contains("every measured point lies at one position")),
            "{:?}",
            s1.warnings
        );
    }

    #[test]
    fn collinear_effect_is_named() {
        let mut d = mill_grid();
        set_target(&mut d, 0, |_, u| u[1]);
        d.err_um[1] = None;
        d.err_um[2] = None;
        // cubic19 already has y; squareness adds y again for ex.
        let adds = [Effect::parse("squareness:target=ex,axis=y").unwrap()];
        let e = format!("{:#}", fit(&d, Seed::Cubic19, &adds, 5).unwrap_err());
        assert!(e.contains("{y, y} are collinear"), "{e}");
    }

    /// The mill grid with three targets from a fixed seed: a smooth error,
    /// noise, a periodic term along x of `period_mm` on ex (its `--add`)
    /// and, with `gaps`, ez missing on every 7th row (its own rows, so its
    /// own group), with per-row uncertainties (weights).
    fn noisy_grid(period_mm: f64, gaps: bool) -> (Dataset, Vec<Effect>) {
        let mut d = mill_grid();
        let mut rng = trueaxis_test_support::SplitMix64::new(15);
        let x = d.pos_mm[0].clone().unwrap();
        let noise: Vec<[f64; 3]> = (0..d.len())
            .map(|_| [rng.normal(), rng.normal(), rng.normal()])
            .collect();
        for t in 0..3 {
            let (x, noise) = (x.clone(), noise.clone());
            set_target(&mut d, t, move |r, u| {
                2.0 * u[0] - u[1] * u[2]
                    + 0.7 * u[t].powi(3)
                    + 0.4 * (std::f64::consts::TAU * x[r] / period_mm).sin()
                    + 0.05 * noise[r][t]
            });
        }
        if gaps {
            if let Some(c) = d.err_um[2].as_mut() {
                c.iter_mut().step_by(7).for_each(|v| *v = None);
            }
        }
        d.u_um = Some((0..d.len()).map(|r| 0.05 + 0.01 * (r % 5) as f64).collect());
        let adds = vec![
            Effect::parse(&format!("periodic:target=ex,axis=x,period_mm={period_mm}")).unwrap(),
        ];
        (d, adds)
    }

    /// Every target of `d` fitted by [`fit_group`] (one group per target,
    /// as after an outlier screen) and by the QR path [`fit_targets`].
    fn gram_and_qr(d: &Dataset, adds: &[Effect]) -> Vec<(TargetFit, Option<f64>, TargetFit, f64)> {
        let norm = Norm::from_data(d);
        let design = Design::new(d, &norm, Seed::Cubic19, adds).unwrap();
        (0..design.targets.len())
            .map(|k| {
                let tg = &design.targets[k];
                let g = fit_group(d, &norm, &design, &[k], 5).unwrap();
                let (tf, held) = g.fits.into_iter().next().unwrap();
                let rows: Vec<usize> = tg.local.iter().map(|&i| design.rows[i]).collect();
                let qr = fit_targets(d, &norm, &tg.features, &[tg.target], &rows, "t")
                    .unwrap()
                    .remove(0);
                assert!(!qr.by_gram);
                let qr_held =
                    holdout::held_out_rms_k(d, &rows, &tg.features, tg.target, &norm, 5).unwrap();
                (tf, held.map(|h| h.unwrap()), qr, qr_held)
            })
            .collect()
    }

    /// [`Design::predict`] in any row order (a hold-out block's rows are
    /// not ascending) equals the row-by-row sum.
    #[test]
    fn design_predictions_follow_the_given_rows() {
        let (d, adds) = noisy_grid(130.0, false);
        let design = Design::new(&d, &Norm::from_data(&d), Seed::Cubic19, &adds).unwrap();
        let tg = &design.targets[0];
        let coef: Vec<f64> = (0..tg.cols.len()).map(|j| 1.0 + j as f64).collect();
        let local = [3, 5, 4, 6];
        let got = design.predict(&tg.cols, &coef, &local);
        for (k, &i) in local.iter().enumerate() {
            let want: f64 = (tg.cols.iter().zip(&coef))
                .map(|(&j, c)| c * design.a[(i, j)])
                .sum();
            assert!((got[k] - want).abs() < 1e-12 * want.abs().max(1.0), "{i}");
        }
    }

    fn max_rel(a: &[f64], b: &[f64]) -> f64 {
        let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .fold(0.0, |m, (x, y)| m.max((x - y).abs() / scale))
    }

    /// Issue 15: the fit from Gram sums (normal equations) gives the QR
    /// path's coefficients, standard deviations, residuals, condition
    /// number and held-out RMS at round-off — with weights, `--add`
    /// columns on one target and a target measured on fewer rows (three
    /// groups, one design matrix).
    #[test]
    fn the_gram_fit_equals_the_qr_fit() {
        let (d, adds) = noisy_grid(130.0, true);
        let fits = gram_and_qr(&d, &adds);
        assert_eq!(fits.len(), 3);
        for (tf, held, qr, qr_held) in &fits {
            assert!(tf.by_gram, "{}", tf.output.target);
            assert_eq!(tf.output.features, qr.output.features);
            assert_eq!(tf.rows, qr.rows);
            // 7·10⁻¹³ of the largest coefficient at most here: QR's own
            // rounding (the refined normal equations move by less).
            assert!(max_rel(&tf.output.coef_um, &qr.output.coef_um) < 1e-11);
            assert!(max_rel(&tf.output.coef_sd_um, &qr.output.coef_sd_um) < 1e-12);
            let worst = (tf.residual_um.iter().zip(&qr.residual_um))
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(worst < 1e-10, "{worst:e} µm");
            assert!((tf.condition_number / qr.condition_number - 1.0).abs() < 1e-12);
            assert!((held.unwrap() / qr_held - 1.0).abs() < 1e-10);
        }
        assert_eq!(fits[0].0.output.features.len(), 21);
        assert_eq!(fits[2].0.rows.len(), d.len() - d.len().div_ceil(7));
    }

    /// A design whose Gram is too ill-conditioned for the normal equations
    /// (a 5 m period on 800 mm of x is nearly a cubic in x: κ(A) ≈ 10⁵,
    /// κ(G) ≈ 10¹⁰ > GRAM_MAX_CONDITION) takes the QR path and gives its
    /// coefficients; one between REFINE_ABOVE and GRAM_MAX_CONDITION (a 2 m
    /// period, κ(G) ≈ 3·10⁶) is solved from the Gram with a refinement
    /// step and agrees with QR to 10⁻¹² (2.4·10⁻¹⁰ without the step).
    #[test]
    fn an_ill_conditioned_design_takes_the_qr_path() {
        let (d, adds) = noisy_grid(5_000.0, false);
        let fits = gram_and_qr(&d, &adds);
        let (tf, held, qr, qr_held) = &fits[0];
        assert!(
            tf.condition_number.powi(2) > lsq::GRAM_MAX_CONDITION,
            "{}",
            tf.condition_number
        );
        assert!(!tf.by_gram);
        assert_eq!(tf.output.coef_um, qr.output.coef_um);
        assert_eq!(held.unwrap(), *qr_held);
        // The other targets (cubic19 alone) are well conditioned.
        assert!(fits[1].0.by_gram && fits[2].0.by_gram);
        let (d, adds) = noisy_grid(2_000.0, false);
        let (tf, _, qr, _) = &gram_and_qr(&d, &adds)[0];
        let k2 = tf.condition_number.powi(2);
        assert!(k2 > REFINE_ABOVE && k2 < lsq::GRAM_MAX_CONDITION, "{k2:e}");
        assert!(tf.by_gram);
        let rel = max_rel(&tf.output.coef_um, &qr.output.coef_um);
        assert!(rel < 1e-12, "{rel:e}");
    }

    #[test]
    fn effect_on_missing_target_is_an_error() {
        let mut d = mill_grid();
        set_target(&mut d, 0, |_, u| u[1]);
        d.err_um[1] = None;
        d.err_um[2] = None;
        let adds = [Effect::parse("reversal:target=ez,axis=x").unwrap()];
        let e = crate::fit::fit(&d, "cubic19", &adds, &Default::default()).unwrap_err();
        assert!(e.to_string().contains("no ez_um"), "{e}");
    }
}
