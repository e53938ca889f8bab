//! Can the sampling along a candidate's axis tell its wave from a lead's
//! alias? A wave of period P seen on points every s mm looks exactly like
//! any period p with |1/p − k/s| = 1/P for a whole k ≥ 1: on a 42 mm grid a
//! 5.08 mm lead looks like a ~300 mm wave, which `higher_order` then fits
//! "significantly" — and the model is worse between the measured points
//! than without it (issue 12). A `periodic` or `higher_order` candidate
//! along an axis whose densest sampling is coarser than
//! [`ALIASING_SPACING_MM`](super::ALIASING_SPACING_MM), and whose wave a
//! plausible lead period ([`LEAD_RANGE_MM`]) would alias to, is
//! *aliasing-suspect*: the path never adds it, and the diagnosis says which
//! periods would look the same and which dense line tells them apart.

use serde::Serialize;

use crate::data::{AXES, TARGETS};
use crate::lines::{densest_lines, group_rows};

use super::periodogram::periodogram;
use super::search::fmt_num;
use super::target::{State, TargetData};
use super::warnings::dense_line_text;
use super::{Candidate, ALIASING_SPACING_MM};

/// Periods a machine's periodic error plausibly has, mm: ball-screw leads
/// and pinion or scale pitches, 2–40 mm.
pub const LEAD_RANGE_MM: [f64; 2] = [2.0, 40.0];

/// Leads and pitches that are common (metric and inch screws), mm: the
/// aliases nearest them are the ones the text names first.
const COMMON_LEADS_MM: [f64; 18] = [
    2.0, 2.5, 3.0, 4.0, 5.0, 5.08, 6.0, 6.35, 8.0, 10.0, 12.0, 12.7, 16.0, 20.0, 25.0, 25.4, 32.0,
    40.0,
];

/// Alias periods the text names (the JSON has them all).
const NAMED_ALIASES: usize = 6;

/// Why a candidate may be an alias, and the measurement that settles it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Aliasing {
    /// The axis it varies along.
    pub axis: String,
    /// The densest sampling along that axis, mm (median spacing).
    pub sampling_mm: f64,
    /// The period of the wave the candidate fits, mm (a periodic
    /// candidate's own period; for `higher_order` the peak of the
    /// periodogram of the residual's mean per position along the axis).
    pub seen_period_mm: f64,
    /// Every period in [`LEAD_RANGE_MM`] that these points cannot tell from
    /// the seen wave, mm, ascending (written beside the object as the
    /// candidate's `alias_periods_mm`).
    #[serde(skip)]
    pub alias_periods_mm: Vec<f64>,
    /// The dense line that tells them apart (the `aliasing` warning's).
    pub measure: String,
    /// All of it in words.
    pub text: String,
}

/// The periods in [`LEAD_RANGE_MM`] that alias to a wave of `seen_mm` on
/// points every `spacing_mm`: 1/p = k/s ± 1/P for k ≥ 1 (k = 0 is the wave
/// itself), ascending.
pub fn alias_periods(seen_mm: f64, spacing_mm: f64) -> Vec<f64> {
    let f = 1.0 / seen_mm;
    let fs = 1.0 / spacing_mm;
    let (pmin, pmax) = (LEAD_RANGE_MM[0], LEAD_RANGE_MM[1]);
    let mut out = Vec::new();
    if !(f.is_finite() && fs.is_finite() && f >= 0.0 && fs > 0.0) {
        return out;
    }
    let mut k = 1.0;
    // 1/p ≤ 1/pmin ends the search: k/s − f already past it.
    while k * fs - f <= 1.0 / pmin {
        for inv in [k * fs - f, k * fs + f] {
            if inv > 0.0 {
                let p = 1.0 / inv;
                if (pmin..=pmax).contains(&p) {
                    out.push(p);
                }
            }
        }
        k += 1.0;
    }
    out.sort_by(f64::total_cmp);
    out.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    out
}

/// The aliases to name in words: those nearest a common lead (within 3 %),
/// closest first, at most [`NAMED_ALIASES`]; else the longest few.
fn named(aliases: &[f64]) -> Vec<f64> {
    let mut near: Vec<(f64, f64)> = aliases
        .iter()
        .filter_map(|&p| {
            let d = COMMON_LEADS_MM
                .iter()
                .map(|l| ((p - l) / l).abs())
                .fold(f64::INFINITY, f64::min);
            (d <= 0.03).then_some((d, p))
        })
        .collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<f64> = near.into_iter().map(|x| x.1).take(NAMED_ALIASES).collect();
    if out.is_empty() {
        out = aliases.iter().rev().take(NAMED_ALIASES).copied().collect();
    }
    out.sort_by(f64::total_cmp);
    out
}

/// A period for the text: 3 significant digits at most (`5.08`, `300`).
fn period_words(p: f64) -> String {
    let decimals = if p >= 100.0 {
        0
    } else if p >= 10.0 {
        1
    } else {
        2
    };
    fmt_num(p, decimals)
}

/// The wave the residual at `st` shows along axis `a`: the peak of the
/// periodogram of its mean per distinct position (the other axes' shape
/// and the noise averaged out), between twice the spacing and the span.
/// (The `higher_order` term's own component would say little: with the
/// cubic partialled out it is a Legendre-like shape whose period is fixed
/// by its degree, not by the data.)
fn seen_wave_mm(td: &TargetData, st: &State, a: usize, spacing_mm: f64) -> Option<f64> {
    let data = td.data;
    let idx: Vec<usize> = (0..td.rows.len()).collect();
    let means: Vec<(f64, f64)> =
        group_rows(&idx, |i| (data.pos(a, td.rows[i]) * 1000.0).round() as i64)
            .into_values()
            .map(|g| {
                let p = g.iter().map(|&i| data.pos(a, td.rows[i])).sum::<f64>() / g.len() as f64;
                let r = g.iter().map(|&i| st.resid[i]).sum::<f64>() / g.len() as f64;
                (p, r)
            })
            .collect();
    let (pos, res): (Vec<f64>, Vec<f64>) = means.into_iter().unzip();
    let span = pos.last()? - pos.first()?;
    let pg = periodogram(&pos, &res, 2.0 * spacing_mm, span);
    let k = pg.peak()?;
    Some(1.0 / pg.freq_per_mm[k])
}

/// Whether `cand` (scored at `st`) is aliasing-suspect, and why. Asked of
/// the contenders only (ΔBIC < 0): a term that explains nothing needs no
/// reason not to be added.
pub(super) fn check(td: &TargetData, st: &State, cand: &Candidate) -> Option<Aliasing> {
    if !cand.effect.info().aliasable
        || !cand.identifiable
        || cand.delta_bic.is_none_or(|d| d >= 0.0)
    {
        return None;
    }
    let a = AXES.iter().position(|x| Some(*x) == cand.axis.as_deref())?;
    let data = td.data;
    let dl = densest_lines(data, a, &td.rows)?;
    if dl.spacing_mm <= ALIASING_SPACING_MM {
        return None;
    }
    // A wave of its own period (periodic), or the one the residual shows
    // (higher_order).
    let own_period = cand.params.get("period_mm").copied();
    let seen = match own_period {
        Some(p) => p,
        None => seen_wave_mm(td, st, a, dl.spacing_mm)?,
    };
    let aliases = alias_periods(seen, dl.spacing_mm);
    if aliases.is_empty() {
        return None;
    }
    let ax = AXES[a];
    let tn = TARGETS[td.t];
    let s = fmt_num(dl.spacing_mm, 3);
    let measure = dense_line_text(data, a);
    let shown: Vec<String> = named(&aliases).into_iter().map(period_words).collect();
    let what = match own_period {
        Some(_) => format!(
            "{tn} varies along {ax} with a period of {} mm",
            period_words(seen)
        ),
        None => format!(
            "{tn} varies along {ax} like a {} mm wave",
            period_words(seen)
        ),
    };
    let text = format!(
        "{what}, but {ax} is sampled every {s} mm: a lead or pitch p of {}–{} mm with |1/p − k/{s}| = 1/{} for a whole k would look the same on these points ({} such periods, e.g. {} mm), and a term fitted to the alias is wrong between them — measure a dense line along {ax}: {measure}",
        fmt_num(LEAD_RANGE_MM[0], 0),
        fmt_num(LEAD_RANGE_MM[1], 0),
        period_words(seen),
        aliases.len(),
        shown.join(", "),
    );
    Some(Aliasing {
        axis: ax.to_string(),
        sampling_mm: dl.spacing_mm,
        seen_period_mm: seen,
        alias_periods_mm: aliases,
        measure,
        text,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5.08 mm lead sampled every 500/12 mm is seen as the alias the
    /// formula gives, and the lead is among the periods that would look
    /// the same; a 25 mm wave on 1.5 mm steps has no alias in 2–40 mm
    /// (only leads below 3 mm alias there, and not to 25 mm).
    #[test]
    fn the_true_lead_is_among_the_aliases_of_what_the_grid_shows() {
        let s: f64 = 500.0 / 12.0;
        let f_lead: f64 = 1.0 / 5.08;
        let k = (f_lead * s).round();
        let seen = 1.0 / (f_lead - k / s).abs();
        let a = alias_periods(seen, s);
        assert!(a.iter().any(|p| (p - 5.08).abs() < 1e-9), "{a:?}");
        assert!(a.iter().all(|p| (2.0..=40.0).contains(p)));
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        // The lead is named first: it sits on a common lead (5.08 mm).
        assert!(named(&a).contains(&a[a.iter().position(|p| (p - 5.08).abs() < 1e-9).unwrap()]));
        assert!(alias_periods(25.0, 1.5).is_empty());
        // On 2 mm steps a 2.17 mm lead is the one that looks like 25 mm.
        let a = alias_periods(25.0, 2.0);
        assert_eq!(a.len(), 1, "{a:?}");
        assert!((a[0] - 1.0 / 0.46).abs() < 1e-9);
    }
}
