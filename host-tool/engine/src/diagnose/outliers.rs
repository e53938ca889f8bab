//! Outliers: single readings far off the current model — a laser's beam
//! break, a probe that touched a chip — found before anything is fitted or
//! diagnosed, reported with the file line of their row, and left out
//! (`--keep-outliers` keeps them). Left in, a 0.5 % share of 20–40 µm
//! spikes pulls a least-squares fit, lifts the noise floor and tempts the
//! diagnosis to "explain" them with an effect.
//!
//! The rule is conservative: per target, fit the current model (the seed
//! and the effects already added — a linear seed; other seeds are screened
//! with cubic19), take the residual's robust scale s = 1.4826·MAD (the
//! median absolute deviation from the median, over the readings not yet
//! flagged) and flag a reading whose residual is more than [`OUTLIER_K`]·s
//! from the median *and* whose deviation from the median residual of the
//! readings just before and after it (two each side, same approach
//! directions, tool length and session) is more than [`OUTLIER_K`] times
//! the robust scale of those deviations and than [`OUTLIER_K`] times the
//! robust spread of those neighbours: a run of neighbouring readings off
//! together is shape the model lacks — a reversal, a bump — and a short
//! period sampled coarsely varies from reading to reading (its neighbours
//! spread about as widely as it lies off), while a beam break is far off
//! all three. The rule prefers keeping a bad reading to dropping a good
//! one. Then refit without the flagged readings and repeat until the set
//! no longer changes (at most [`MAX_ROUNDS`] rounds): the
//! first fit is pulled towards the spikes, the refit is not. The scale is
//! the model's residual, not the noise floor, so smooth shape the model has
//! not caught yet widens it instead of being flagged: only readings far off
//! everything around them go.

use std::borrow::Cow;

use anyhow::Result;
use serde::Serialize;

use crate::data::{Dataset, TARGETS};
use crate::effect::Effect;
use crate::features::Norm;
use crate::fit::linear::Design;
use crate::linalg::lsq::Gram;
use crate::model::Seed;

/// Residuals beyond this many robust σ from the median are outliers
/// (a normal reading is beyond 7σ once in 4·10¹¹).
pub const OUTLIER_K: f64 = 7.0;
/// Most fit → flag rounds.
pub const MAX_ROUNDS: usize = 5;
/// 1/Φ⁻¹(3/4): the MAD of a normal times this is its σ.
const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// One reading left out as an outlier.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outlier {
    /// Line of the row in the source file (1-based); null for data that did
    /// not come from a file (`simulate` in memory).
    pub line: Option<usize>,
    /// Data row (0-based, the order of the file's data rows).
    pub row: usize,
    /// `ex`, `ey` or `ez`.
    pub target: String,
    /// The measured error, µm.
    pub value_um: f64,
    /// Its residual from the model fitted without the outliers, µm.
    pub resid_um: f64,
    /// The residual's robust scale (1.4826·MAD), µm.
    pub scale_um: f64,
}

impl Outlier {
    /// Target index (0 = ex).
    fn target_index(&self) -> usize {
        TARGETS.iter().position(|t| *t == self.target).unwrap_or(0)
    }

    /// `data.csv:123: ex = 31.2 µm, 29.9 µm off the model (52× its robust scale 0.57 µm)`.
    pub fn text(&self, source: &str) -> String {
        let at = match self.line {
            Some(l) => format!("{source}:{l}"),
            None => format!("{source} row {}", self.row + 1),
        };
        format!(
            "{at}: {} = {:.3} µm, {:.3} µm off the model ({:.0}× its robust scale {:.3} µm)",
            self.target,
            self.value_um,
            self.resid_um,
            self.resid_um.abs() / self.scale_um,
            self.scale_um
        )
    }
}

/// The median (0 for none), by selection — O(n), not a sort: the screen
/// takes a few per target and round of a million readings. `v` is
/// reordered.
fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    let (below, &mut mid, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        mid
    } else {
        // The lower middle is the largest of the values below.
        let lower = below.iter().copied().max_by(f64::total_cmp).unwrap_or(mid);
        0.5 * (lower + mid)
    }
}

/// Readings on each side a reading is compared with.
const NEIGHBOURS: usize = 2;
/// How far (in rows) to look for them.
const NEIGHBOUR_WINDOW: usize = 10;

/// Per reading of `resid` (rows in file order, residuals), its deviation
/// from the median residual of the readings taken just before and after
/// it ([`NEIGHBOURS`] on each side within [`NEIGHBOUR_WINDOW`] rows) that
/// share its approach directions, tool length and session, and the robust
/// spread of those neighbours' residuals (1.4826·MAD: a spike among them
/// does not widen it); `None` without any. Consecutive readings are neighbours on the machine (a line, a run),
/// so shape cancels here and a lone bad reading does not.
fn local_deviation(data: &Dataset, resid: &[(usize, f64, f64)]) -> Vec<Option<(f64, f64)>> {
    let inputs = |row: usize| {
        (
            [0, 1, 2].map(|a| data.dir[a].as_ref().map_or(0, |d| d[row])),
            data.tool_mm.as_ref().map(|v| v[row].to_bits()),
            data.session_id.as_ref().map(|v| v[row]),
        )
    };
    // Each reading's inputs once (not once per window it falls in), and
    // the neighbours in a fixed buffer: no allocation per reading.
    let keys: Vec<_> = resid.iter().map(|x| inputs(x.0)).collect();
    (0..resid.len())
        .map(|i| {
            let own = &keys[i];
            let lo = i.saturating_sub(NEIGHBOUR_WINDOW);
            let hi = (i + NEIGHBOUR_WINDOW + 1).min(resid.len());
            let same = |j: &usize| keys[*j] == *own;
            let mut buf = [0.0; 2 * NEIGHBOURS];
            let mut n = 0;
            for j in (lo..i)
                .rev()
                .filter(same)
                .take(NEIGHBOURS)
                .chain((i + 1..hi).filter(same).take(NEIGHBOURS))
            {
                buf[n] = resid[j].2;
                n += 1;
            }
            let v = &mut buf[..n];
            (n > 0).then(|| {
                let m = median(v);
                let mut spread = [0.0; 2 * NEIGHBOURS];
                for (s, x) in spread.iter_mut().zip(v.iter()) {
                    *s = (x - m).abs();
                }
                (resid[i].2 - m, MAD_TO_SIGMA * median(&mut spread[..n]))
            })
        })
        .collect()
}

/// `data` with the outliers' error cells emptied ("not measured on this
/// row"), so that every fit and diagnosis leaves them out; the rest of the
/// row (its other targets) stays.
pub fn without(data: &Dataset, outliers: &[Outlier]) -> Dataset {
    let mut d = data.clone();
    for o in outliers {
        if let Some(col) = d.err_um[o.target_index()].as_mut() {
            col[o.row] = None;
        }
    }
    d
}

/// The outliers of `data` under the model `seed` + `adds` (see the module
/// doc), by target then row.
///
/// The rounds are solved from Gram sums over one design matrix
/// ([`Design`]): each target's Gram over all its readings is formed once
/// and a round takes its flagged readings out of it, so a round costs a
/// prediction pass, not a refit of the whole data set. Where the normal
/// equations are not to be trusted (an ill-conditioned or rank-deficient
/// design, too few points: [`lsq::solve_gram`](crate::linalg::lsq::solve_gram))
/// the screen refits the data set by QR every round, which also words
/// the errors.
pub fn find(data: &Dataset, seed: &Seed, adds: &[Effect]) -> Result<Vec<Outlier>> {
    let seed = match seed {
        s @ (Seed::Cubic19 | Seed::Kinematic) => *s,
        _ => Seed::Cubic19,
    };
    match find_by_gram(data, seed, adds) {
        Some(found) => Ok(found),
        None => find_by_refits(data, seed, adds),
    }
}

/// [`find`]'s rounds by refitting the data set less the flagged readings
/// (QR) each round — the screen where the normal equations are not to be
/// trusted, and the words of its errors.
fn find_by_refits(data: &Dataset, seed: Seed, adds: &[Effect]) -> Result<Vec<Outlier>> {
    let mut found: Vec<Outlier> = Vec::new();
    for _ in 0..MAX_ROUNDS {
        let clean = without(data, &found);
        // The screen needs the model only, not its held-out RMS (blocks 0).
        let (model, _) = crate::fit::linear::fit(&clean, seed, adds, 0)?;
        let pred = model.predict(data)?;
        let mut next = Vec::new();
        for t in data.targets() {
            let Some(p) = &pred[t] else { continue };
            let resid: Vec<(usize, f64, f64)> =
                data.measured(t).map(|(r, v)| (r, v, v - p[r])).collect();
            next.extend(flag(data, t, &resid, &found));
        }
        if settle(&mut found, next) {
            break;
        }
    }
    Ok(found)
}

/// [`find`]'s rounds from Gram sums; None when any round's normal
/// equations are not to be trusted (the caller then refits by QR).
fn find_by_gram(data: &Dataset, seed: Seed, adds: &[Effect]) -> Option<Vec<Outlier>> {
    let design = Design::new(data, &Norm::from_data(data), seed, adds).ok()?;
    if design.targets.is_empty() {
        return None;
    }
    let full: Vec<Gram> = (design.targets.iter().enumerate())
        .map(|(k, tg)| design.gram(&tg.cols, &[k], &tg.local))
        .collect();
    let mut found: Vec<Outlier> = Vec::new();
    for _ in 0..MAX_ROUNDS {
        let mut next = Vec::new();
        for (k, tg) in design.targets.iter().enumerate() {
            // `found` is by target then row, so `out` is ascending.
            let out: Vec<usize> = (found.iter())
                .filter(|o| o.target_index() == tg.target)
                .map(|o| design.local_of(o.row))
                .collect();
            let (kept, gram): (Cow<[usize]>, Cow<Gram>) = if out.is_empty() {
                (Cow::Borrowed(&tg.local), Cow::Borrowed(&full[k]))
            } else {
                let kept: Vec<usize> = (tg.local.iter().copied())
                    .filter(|i| out.binary_search(i).is_err())
                    .collect();
                // A few flagged readings are taken out of the full sums;
                // many (a quarter or more) are summed afresh, so that the
                // difference never cancels most of the total.
                let gram = if 4 * out.len() < tg.local.len() {
                    let mut g = full[k].clone();
                    let (a, b, w) = (&design.a, &design.b, design.w.as_ref());
                    g.add_rows(a, &tg.cols, b, &[k], w, &out, -1.0);
                    g
                } else {
                    design.gram(&tg.cols, &[k], &kept)
                };
                (Cow::Owned(kept), Cow::Owned(gram))
            };
            let (_, coef) = design.coefficients(&tg.cols, &[k], &kept, &gram)?;
            let pred = design.predict(&tg.cols, coef.as_slice(), &tg.local);
            let resid: Vec<(usize, f64, f64)> = (tg.local.iter().zip(pred))
                .map(|(&i, p)| {
                    let v = design.b[(i, k)];
                    (design.rows[i], v, v - p)
                })
                .collect();
            next.extend(flag(data, tg.target, &resid, &found));
        }
        if settle(&mut found, next) {
            break;
        }
    }
    Some(found)
}

/// Takes `next` as the flagged set; true when it is the one `found` held
/// (the screen has settled).
fn settle(found: &mut Vec<Outlier>, next: Vec<Outlier>) -> bool {
    let same = next.len() == found.len()
        && next
            .iter()
            .zip(found.iter())
            .all(|(a, b)| a.row == b.row && a.target == b.target);
    *found = next;
    same
}

/// The outliers of target `t` given its readings' residuals `resid`
/// (row, value, residual; rows ascending) and the readings flagged so far
/// (`found`: left out of the scale estimates).
fn flag(data: &Dataset, t: usize, resid: &[(usize, f64, f64)], found: &[Outlier]) -> Vec<Outlier> {
    let mut flagged_rows: Vec<usize> = (found.iter())
        .filter(|o| o.target_index() == t)
        .map(|o| o.row)
        .collect();
    flagged_rows.sort_unstable();
    let flagged = |r: usize| flagged_rows.binary_search(&r).is_ok();
    let mut kept: Vec<f64> = resid
        .iter()
        .filter(|(r, _, _)| !flagged(*r))
        .map(|x| x.2)
        .collect();
    let med = median(&mut kept);
    let mut dev: Vec<f64> = kept.iter().map(|v| (v - med).abs()).collect();
    let scale = MAD_TO_SIGMA * median(&mut dev);
    let mut out = Vec::new();
    if scale <= 0.0 {
        return out;
    }
    // Far off the model *and* off its neighbours, each against its
    // own robust scale: a run of neighbouring readings off together
    // is shape the model lacks (a reversal, a bump), and a short
    // period sampled coarsely varies from reading to reading — the
    // local scale widens for it — while a beam break is far off both.
    let local = local_deviation(data, resid);
    let mut dev: Vec<f64> = resid
        .iter()
        .zip(&local)
        .filter(|((r, _, _), _)| !flagged(*r))
        .filter_map(|(_, d)| d.map(|d| d.0.abs()))
        .collect();
    // Neither local scale below the reading quantum: on readings quantised
    // coarser than their noise most neighbours read the same value, both
    // scales were 0, and a smooth warm-up's every one-step change "was far
    // off its neighbours" — 15–24 cold-start readings of a spindle test
    // were dropped against a constant model (issue 24).
    let step = super::noise::quantum(resid.iter().map(|x| x.1)).unwrap_or(0.0);
    let local_scale = (MAD_TO_SIGMA * median(&mut dev)).max(step);
    for (&(r, v, e), d) in resid.iter().zip(&local) {
        if (e - med).abs() > OUTLIER_K * scale
            && d.is_none_or(|(d, spread)| {
                d.abs() > OUTLIER_K * local_scale && d.abs() > OUTLIER_K * spread.max(step)
            })
        {
            out.push(Outlier {
                line: data.line.get(r).copied(),
                row: r,
                target: TARGETS[t].to_string(),
                value_um: v,
                resid_um: e,
                scale_um: scale,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 15: the screen's rounds from Gram sums flag exactly what the
    /// rounds of refits flag (same rows, targets, residuals at round-off)
    /// on a 3-D grid with three targets, an `--add` effect on one, u_um
    /// weights and four spikes on two targets (a 3 µm one next to a 30 µm
    /// one), so that the second round takes flagged readings out of the
    /// Gram sums.
    #[test]
    fn the_gram_screen_flags_what_the_refits_flag() {
        let [x, y, z] = crate::data::grid_positions([17, 11, 11], [50.0; 3]);
        let n = x.len();
        let mut rng = trueaxis_test_support::SplitMix64::new(11);
        let mut err: [Vec<Option<f64>>; 3] = Default::default();
        for (t, e) in err.iter_mut().enumerate() {
            *e = (0..n)
                .map(|r| {
                    let u = [x[r] / 400.0 - 1.0, y[r] / 250.0 - 1.0, z[r] / 250.0 - 1.0];
                    Some(
                        2.0 * u[0] - u[1] * u[2]
                            + 0.5 * u[t].powi(3)
                            + if t == 1 {
                                0.8 * (y[r] / 30.0 * std::f64::consts::TAU).sin()
                            } else {
                                0.0
                            }
                            + 0.1 * rng.normal(),
                    )
                })
                .collect();
        }
        let spikes = [
            (0, 100, 40.0),
            (0, 1500, -25.0),
            (1, 700, 30.0),
            (1, 701, 3.0),
        ];
        for &(t, r, v) in &spikes {
            err[t][r] = err[t][r].map(|e| e + v);
        }
        let d = Dataset {
            source: "grid.csv".into(),
            pos_mm: [Some(x), Some(y), Some(z)],
            err_um: err.map(Some),
            u_um: Some((0..n).map(|r| 0.1 + 0.02 * (r % 3) as f64).collect()),
            line: (0..n).map(|r| r + 2).collect(),
            ..Dataset::default()
        };
        let adds = [Effect::parse("periodic:target=ey,axis=y,period_mm=30").unwrap()];
        let gram = find_by_gram(&d, Seed::Cubic19, &adds).expect("well conditioned");
        let refits = find_by_refits(&d, Seed::Cubic19, &adds).unwrap();
        let key = |o: &Outlier| (o.target.clone(), o.row);
        assert_eq!(
            gram.iter().map(key).collect::<Vec<_>>(),
            refits.iter().map(key).collect::<Vec<_>>()
        );
        for (a, b) in gram.iter().zip(&refits) {
            assert!((a.resid_um - b.resid_um).abs() < 1e-9, "{a:?} {b:?}");
            assert!((a.scale_um - b.scale_um).abs() < 1e-9, "{a:?} {b:?}");
        }
        let rows: Vec<(String, usize)> = gram.iter().map(key).collect();
        for (t, r, _) in spikes {
            assert!(rows.contains(&(TARGETS[t].to_string(), r)), "{rows:?}");
        }
        assert_eq!(find(&d, &Seed::Cubic19, &adds).unwrap(), gram);
    }

    #[test]
    fn a_spike_is_found_on_its_line_and_left_out() {
        // 200 points of a cubic along x with ±0.1 µm of pattern "noise" and
        // one 30 µm spike at row 57 (file line 60).
        let n = 200;
        let x: Vec<f64> = (0..n).map(|i| i as f64 * 4.0).collect();
        let e: Vec<Option<f64>> = (0..n)
            .map(|i| {
                let u = x[i] / 800.0;
                let noise = 0.1 * ((i * 7919 % 13) as f64 / 6.0 - 1.0);
                Some(3.0 * u * u * u - 2.0 * u + noise + if i == 57 { 30.0 } else { 0.0 })
            })
            .collect();
        let d = Dataset {
            source: "t.csv".into(),
            pos_mm: [Some(x), None, None],
            err_um: [Some(e), None, None],
            line: (0..n).map(|i| i + 3).collect(),
            ..Dataset::default()
        };
        let o = find(&d, &Seed::Cubic19, &[]).unwrap();
        assert_eq!(o.len(), 1, "{o:?}");
        assert_eq!(
            (o[0].row, o[0].line, o[0].target.as_str()),
            (57, Some(60), "ex")
        );
        assert!((o[0].resid_um - 30.0).abs() < 0.5, "{o:?}");
        assert!(o[0].text("t.csv").starts_with("t.csv:60: ex = "));
        let clean = without(&d, &o);
        assert_eq!(clean.measured(0).count(), n - 1);
    }
}
