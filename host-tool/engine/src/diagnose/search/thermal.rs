//! How the search proposes `thermal`: per temperature channel that
//! varies, alone and times each moving axis, the lag searched on a grid
//! (extended while the best is its longest, up to half the test) and
//! refined between the best point's neighbours by Brent's method; and,
//! when no one sensor follows the growth, a multi-sensor effect by forward
//! selection with swaps over every channel and lag.

use rayon::prelude::*;

use crate::effect::thermal::Thermal;
use crate::data::AXES;
use crate::effect::{Axis, EffectSpec, Family, Target, T_REF_C};
use crate::features::Feature;
use crate::linalg::basis::small_fit;
use crate::linalg::brent::brent_min;

use super::super::target::{
    forward_blocks, forward_refit_rms, forward_rms, rss_many, State, TargetData,
};
use super::super::{CONSTANT_TEMPERATURE_K, DBIC_SIGNIFICANT, MIN_HELD_OUT_GAIN};
use super::{fmt_num, shown, Proposal, Search};

/// The lag, when the data has time to search it on.
pub(super) fn researchable(td: &TargetData) -> bool {
    td.data.t_s.is_some()
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let (td, st) = (s.td, s.st);
    let target = s.target();
    let tn = target.name();
    // thermal: per channel that varies, alone or times each axis; lag searched.
    let duration = duration_s(td);
    let (data, only, moving) = (td.data, s.only, &s.moving);
    let want = |channel: &str, times: Option<usize>| {
        only.is_none_or(|k| {
            k.admits(
                Family::Thermal,
                None,
                Some(channel),
                times.and_then(Axis::from_index),
            )
        })
    };
    let mut out = Vec::new();
    for ch in &data.temps {
        let lo = ch.temp_c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ch.temp_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi - lo < CONSTANT_TEMPERATURE_K {
            continue;
        }
        let times: Vec<Option<usize>> = std::iter::once(None)
            .chain(moving.iter().map(|&a| Some(a)))
            .collect();
        // Each variant (alone, times each axis) searches its lag on its
        // own: in parallel, joined in order.
        let found: Vec<Option<Proposal>> = times
            .par_iter()
            .map(|&tm| {
                if !want(&ch.name, tm) {
                    return None;
                }
                // The lag as the spec writes it (to 1 s): the columns scored
                // are those of the string proposed.
                let spec_at = |lag: f64| {
                    EffectSpec::new(
                        target,
                        Thermal::new(&ch.name, tm.and_then(Axis::from_index), vec![shown(lag, 0)]),
                    )
                };
                let rss_at = |lag: f64| rss_many(td, st, &[spec_at(lag)])[0];
                let mut lags: Vec<f64> = if data.t_s.is_some() {
                    LAGS_S.to_vec()
                } else {
                    vec![0.0]
                };
                let specs: Vec<EffectSpec> = lags.iter().map(|&lag| spec_at(lag)).collect();
                let mut grid = rss_many(td, st, &specs);
                let argmin = |g: &[f64]| {
                    g.iter()
                        .enumerate()
                        .fold((0, f64::INFINITY), |b, (i, &r)| if r < b.1 { (i, r) } else { b })
                };
                // A best lag at the grid's longest: search further out, by
                // half again each time, up to half the test's duration (a
                // longer lag is a slope the test cannot tell from a smaller
                // growth: the test is shorter than the time constant).
                while lags.len() > 1 && argmin(&grid).0 == lags.len() - 1 {
                    let next = lags[lags.len() - 1] * LAG_EXTEND;
                    if next > 0.5 * duration {
                        break;
                    }
                    lags.push(next);
                    grid.push(rss_at(next));
                }
                let (best_i, best_rss) = argmin(&grid);
                if !best_rss.is_finite() {
                    return None;
                }
                let mut best = (best_rss, lags[best_i]);
                let unidentified = lags.len() > 1 && best_i == lags.len() - 1;
                // The grid only brackets the lag (a true 1000 s was reported as
                // 900 s, and the CTE's interval, which takes the lag as known,
                // then missed the truth): refine between the grid neighbours of
                // the best point by Brent's method to 1 s.
                // Not when the best is the longest lag tried: the sum still
                // falls there, the refinement would only walk to the edge.
                if lags.len() > 1 && !unidentified {
                    let lo = lags[best_i.saturating_sub(1)];
                    let hi = lags[(best_i + 1).min(lags.len() - 1)];
                    let (lag, rss) = brent_min(rss_at, lo, hi, 1.0);
                    if rss < best.0 {
                        best = (rss, lag.round());
                    }
                }
                let flag = if unidentified {
                    format!(
                        "; lag not identified: the best is the longest lag tried ({} s, half the {:.1} h the readings span) — the test is shorter than the time constant; measure at least 3× as long to identify it",
                        fmt_num(lags[lags.len() - 1], 0),
                        duration / 3600.0
                    )
                } else {
                    String::new()
                };
                let note = if data.t_s.is_some() {
                    format!(
                        "the {tn} residual follows T_{}_C{} (range {:.2} K), lag {} s found by search{flag}",
                        ch.name,
                        tm.map_or(String::new(), |a| format!(" × {}", AXES[a])),
                        hi - lo,
                        fmt_num(best.1, 0)
                    )
                } else {
                    format!(
                        "the {tn} residual follows T_{}_C{} (range {:.2} K)",
                        ch.name,
                        tm.map_or(String::new(), |a| format!(" × {}", AXES[a])),
                        hi - lo
                    )
                };
                Some(Proposal {
                    spec: spec_at(best.1),
                    searched: usize::from(data.t_s.is_some()),
                    note,
                })
            })
            .collect();
        out.extend(found.into_iter().flatten());
    }
    // thermal, several sensors: when no one sensor follows the growth.
    let multi_wanted = only.is_none_or(|k| {
        k.family() == Family::Thermal
            && k.times().is_none()
            && k.channel().is_some_and(|c| c.contains('+'))
    });
    if multi_wanted && data.t_s.is_some() {
        out.extend(multi_sensor(td, st, target));
    }
    out
}

/// The longest lag a single-sensor search of `td` tries: the grid's
/// longest, extended by [`LAG_EXTEND`] while it stays within half the
/// test's duration (a best lag there is the edge, not a found lag).
fn longest_lag_s(td: &TargetData) -> f64 {
    let half = 0.5 * duration_s(td);
    let mut lag = LAGS_S[LAGS_S.len() - 1];
    while lag * LAG_EXTEND <= half {
        lag *= LAG_EXTEND;
    }
    lag
}

/// The channels of a thermal effect whose lag sits at the longest lag its
/// search tries (`(channel, lag_s)`): the sum of squares was still falling
/// there, so the data do not identify the lag — only that it is at least
/// that long. A multi-sensor effect searches the grid [`LAGS_S`] only; a
/// single sensor's grid is extended up to half the test (`longest_lag_s`).
pub(in crate::diagnose) fn unidentified_lags(
    td: &TargetData,
    spec: &EffectSpec,
) -> Vec<(String, f64)> {
    let crate::effect::Params::Thermal(th) = spec.params() else {
        return Vec::new();
    };
    if td.data.t_s.is_none() {
        return Vec::new();
    }
    let channels: Vec<&str> = th.channels().collect();
    let edge = if channels.len() > 1 {
        LAGS_S[LAGS_S.len() - 1]
    } else {
        longest_lag_s(td)
    };
    channels
        .iter()
        .enumerate()
        .filter_map(|(i, ch)| {
            let lag = *th.lags_s.get(i).or(th.lags_s.first())?;
            ((lag - edge).abs() < 0.5 && lag > 0.0).then(|| (ch.to_string(), lag))
        })
        .collect()
}

/// Thermal lags tried, s (then refined between neighbours).
const LAGS_S: [f64; 11] = [
    0.0, 120.0, 300.0, 600.0, 900.0, 1200.0, 1800.0, 2400.0, 3600.0, 5400.0, 7200.0,
];
/// Beyond the grid's longest lag, each further lag is this much longer.
const LAG_EXTEND: f64 = 1.5;

/// Time the readings of `td` span, s: each session's first to last reading,
/// summed over the sessions (0 without `t_s`).
fn duration_s(td: &TargetData) -> f64 {
    let Some(t_s) = &td.data.t_s else {
        return 0.0;
    };
    let mut span: std::collections::BTreeMap<i64, (f64, f64)> = Default::default();
    for &r in &td.rows {
        let s = td.data.session_id.as_ref().map_or(0, |v| v[r]);
        let e = span.entry(s).or_insert((f64::INFINITY, f64::NEG_INFINITY));
        e.0 = e.0.min(t_s[r]);
        e.1 = e.1.max(t_s[r]);
    }
    span.values().map(|(lo, hi)| hi - lo).sum()
}

/// Most sensors in a multi-sensor thermal candidate.
const MAX_SENSORS: usize = 3;

/// A multi-sensor thermal candidate for the target (growth independent of
/// position, each sensor with its own lag), or None when one sensor does as
/// well. Sensors are chosen by forward selection over every varying `T_*`
/// channel and the lag grid, each addition followed by one pass of swaps
/// (every member's channel and lag tried again with the others held):
/// correlated sensors make the greedy first choice a proxy of the true
/// pair (the rear bearing, a lagged mix of the housing and the column),
/// and the swap pass replaces it. An addition is kept only with ΔBIC < −10
/// (a channel and a lag charged for it).
fn multi_sensor(td: &TargetData, st: &State, target: Target) -> Option<Proposal> {
    let data = td.data;
    let tn = target.name();
    let chans: Vec<&str> = data
        .temps
        .iter()
        .filter(|ch| {
            let lo = ch.temp_c.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = ch.temp_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            hi - lo >= CONSTANT_TEMPERATURE_K
        })
        .map(|ch| ch.name.as_str())
        .collect();
    if chans.len() < 2 {
        return None;
    }
    // Every (channel, lag) column with the model partialled out (and, at
    // one position, as it is: the forward check refits the whole model).
    let refit = super::super::autocorr::decides(td);
    let mut raws: Vec<Vec<Vec<f64>>> = Vec::new();
    let mut cols: Vec<Vec<Vec<f64>>> = Vec::with_capacity(chans.len());
    for ch in &chans {
        let mut raw = Vec::with_capacity(LAGS_S.len());
        for &lag_s in &LAGS_S {
            let f = Feature::Thermal {
                channel: (*ch).to_string(),
                t_ref_c: T_REF_C,
                lag_s,
                exp: [0, 0, 0],
            };
            raw.push(td.col(&f).ok()?);
        }
        let refs: Vec<&[f64]> = raw.iter().map(Vec::as_slice).collect();
        cols.push(st.basis.residuals(&refs));
        if refit {
            raws.push(raw);
        }
    }
    let rss_of = |set: &[(usize, usize)]| -> f64 {
        let cs: Vec<Vec<f64>> = set.iter().map(|&(c, l)| cols[c][l].clone()).collect();
        small_fit(&cs, &st.resid).rss
    };
    let all: Vec<(usize, usize)> = (0..chans.len())
        .flat_map(|c| (0..LAGS_S.len()).map(move |l| (c, l)))
        .collect();
    let single = all
        .iter()
        .map(|&cl| (rss_of(&[cl]), cl))
        .min_by(|a, b| a.0.total_cmp(&b.0))?;
    let n = td.rows.len() as f64;
    let forward = forward_blocks(td);
    // Whether `big` (rss `r_big`) earns its extra sensor over `small`:
    // ΔBIC < −10 with a channel and a lag charged, and — the acceptance
    // rule's 10 % — a better forward-chained prediction of later data (with
    // thousands of readings ΔBIC alone takes a sensor for a few nm).
    let earns = |big: &[(usize, usize)], r_big: f64, small: &[(usize, usize)], r_small: f64| {
        let forward_ok = forward.as_ref().is_none_or(|b| {
            let f = |set: &[(usize, usize)]| {
                if refit {
                    let cs: Vec<Vec<f64>> =
                        set.iter().map(|&(c, l)| raws[c][l].clone()).collect();
                    return forward_refit_rms(b, &td.y, &st.basis, &cs);
                }
                let cs: Vec<Vec<f64>> = set.iter().map(|&(c, l)| cols[c][l].clone()).collect();
                forward_rms(b, &st.resid, &cs).1
            };
            f(big) <= (1.0 - MIN_HELD_OUT_GAIN) * f(small)
        });
        forward_ok
            && n * (r_big.max(1e-300) / r_small.max(1e-300)).ln() + 2.0 * n.ln() < DBIC_SIGNIFICANT
    };
    let mut set = vec![single.1];
    let mut cur = single.0;
    while set.len() < MAX_SENSORS {
        let mut best: Option<(f64, Vec<(usize, usize)>)> = None;
        for &(c, l) in &all {
            if set.iter().any(|m| m.0 == c) {
                continue;
            }
            let mut t = set.clone();
            t.push((c, l));
            let r = rss_of(&t);
            if best.as_ref().is_none_or(|b| r < b.0) {
                best = Some((r, t));
            }
        }
        let Some((mut r, mut t)) = best else { break };
        // One pass of swaps: each member's channel and lag searched again.
        for i in 0..t.len() {
            for &(c, l) in &all {
                if t.iter().enumerate().any(|(j, m)| j != i && m.0 == c) {
                    continue;
                }
                let mut u = t.clone();
                u[i] = (c, l);
                let ru = rss_of(&u);
                if ru < r {
                    r = ru;
                    t = u;
                }
            }
        }
        // And the addition must predict later data better by the
        // acceptance rule's 10 % (forward chaining): with thousands of
        // readings ΔBIC alone takes a third sensor for a few nm.
        if earns(&t, r, &set, cur) {
            set = t;
            cur = r;
        } else {
            break;
        }
    }
    // Backward: a member chosen early that the later ones made redundant
    // (a proxy of them) is dropped, the least useful first.
    while set.len() > 1 {
        let weakest = (0..set.len())
            .map(|i| {
                let mut u = set.clone();
                u.remove(i);
                let ru = rss_of(&u);
                (ru, u)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        if earns(&set, cur, &weakest.1, weakest.0) {
            break;
        }
        set = weakest.1;
        cur = weakest.0;
    }
    if set.len() < 2 {
        return None;
    }
    let names: Vec<&str> = set.iter().map(|&(c, _)| chans[c]).collect();
    let lags: Vec<f64> = set.iter().map(|&(_, l)| LAGS_S[l]).collect();
    let spec = EffectSpec::new(target, Thermal::new(&names.join("+"), None, lags));
    let listed: Vec<String> = set
        .iter()
        .map(|&(c, l)| format!("T_{}_C (lag {} s)", chans[c], fmt_num(LAGS_S[l], 0)))
        .collect();
    let edge: Vec<String> = set
        .iter()
        .filter(|&&(_, l)| l == LAGS_S.len() - 1)
        .map(|&(c, _)| format!("T_{}_C", chans[c]))
        .collect();
    let flag = if edge.is_empty() {
        String::new()
    } else {
        format!(
            "; lag not identified for {}: the longest lag tried ({} s) — the data say only that it is at least that long",
            edge.join(", "),
            fmt_num(LAGS_S[LAGS_S.len() - 1], 0)
        )
    };
    Some(Proposal {
        spec,
        // A channel and a lag chosen per sensor.
        searched: 2 * set.len(),
        note: format!(
            "no one sensor follows the {tn} residual: a multi-sensor model of {} (forward selection with swaps over {} channels and their lags: RMS {:.3} µm, the best single sensor T_{}_C leaves {:.3} µm)",
            listed.join(", "),
            chans.len(),
            (cur / n).sqrt(),
            chans[single.1 .0],
            (single.0 / n).sqrt()
        ) + &flag,
    })
}

