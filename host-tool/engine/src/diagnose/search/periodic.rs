//! How the search proposes `periodic`: along each moving axis, a
//! Lomb–Scargle periodogram of the residual on the densest lines (the
//! rows that can see a short period), its peak refined on those rows, and
//! harmonics kept while the residual of the lower ones still has power at
//! the next.

use std::f64::consts::TAU;

use crate::effect::periodic::Periodic;
use crate::effect::{Axis, EffectSpec, Family};
use crate::linalg::basis::small_fit;
use crate::lines::densest_lines;

use super::super::periodogram::{self, periodogram};
use super::super::target::TargetData;
use super::super::{PeriodogramEvidence, PERIODIC_MAX_PERIOD_MM};
use super::{fmt_num, shown, Proposal, Search};

pub(super) fn researchable(_td: &TargetData) -> bool {
    true
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let (td, st) = (s.td, s.st);
    let data = td.data;
    let tn = s.tn();
    let mut out = Vec::new();
    // Local index of each data row, for the periodogram's subset.
    let mut local = vec![usize::MAX; data.len()];
    for (i, &r) in td.rows.iter().enumerate() {
        local[r] = i;
    }
    // Lomb–Scargle along each axis on the densest lines.
    for &a in &s.moving {
        if !s.want(Family::Periodic, Some(a), None, None) {
            continue;
        }
        let Some(dl) = densest_lines(data, a, &td.rows) else {
            continue;
        };
        let min_p = (2.0 * dl.spacing_mm).max(0.5);
        // Periods longer than 100 mm are smooth shape, the polynomial's and
        // `higher_order`'s domain: no lead or scale pitch is that long.
        let max_p = (dl.span_mm / 2.0).min(PERIODIC_MAX_PERIOD_MM);
        if max_p <= 2.0 * min_p || dl.rows.len() < 16 {
            continue;
        }
        let pos: Vec<f64> = dl.rows.iter().map(|&r| data.pos(a, r)).collect();
        let res: Vec<f64> = dl.rows.iter().map(|&r| st.resid[local[r]]).collect();
        let pg = periodogram(&pos, &res, min_p, max_p);
        let Some(k) = pg.peak() else { continue };
        let f0 = pg.freq_per_mm[k];
        let df = 1.0 / (5.0 * dl.span_mm.max(1e-9));
        // Refine the peak on the dense rows only (two passes of 41 points):
        // on all rows, grid points that alias the period would pull it
        // towards whatever long wave fits their residual best.
        let mut best = (pg.power[k], f0);
        for width in [df, df / 20.0] {
            let centre = best.1;
            // One scan of the 41 frequencies (a phase recurrence per sample).
            let powers =
                periodogram::gls_power_scan(&pos, &res, centre - width, width / 20.0, 41);
            for (i, &p) in powers.iter().enumerate() {
                let f = centre + width * (i as f64 - 20.0) / 20.0;
                if f <= 0.0 {
                    continue;
                }
                if p > best.0 {
                    best = (p, f);
                }
            }
        }
        let f = best.1;
        // Harmonics, tested on the dense rows only (on grid rows a harmonic
        // aliases to a long wave that fits anything smooth): harmonic h is
        // kept while the residual of the lower ones has power at h·f above
        // N·p/2 = 15 (a chance of ~3e-7 for noise, about ΔBIC −10).
        let mut h = 1u8;
        let mut r_dense = res.clone();
        let remove = |r: &mut Vec<f64>, f: f64| {
            let c: Vec<f64> = pos.iter().map(|p| (TAU * f * p).cos()).collect();
            let s_: Vec<f64> = pos.iter().map(|p| (TAU * f * p).sin()).collect();
            let one = vec![1.0; pos.len()];
            let fit = small_fit(&[one.clone(), s_.clone(), c.clone()], r);
            for i in 0..r.len() {
                r[i] -= fit.beta[0] + fit.beta[1] * s_[i] + fit.beta[2] * c[i];
            }
        };
        remove(&mut r_dense, f);
        while h < 4 && 2.0 * (f64::from(h) + 1.0) * f <= 1.0 / dl.spacing_mm {
            let fh = (f64::from(h) + 1.0) * f;
            let p = periodogram::gls_power(&pos, &r_dense, fh);
            if pos.len() as f64 * p / 2.0 > 15.0 {
                h += 1;
                remove(&mut r_dense, fh);
            } else {
                break;
            }
        }
        let ratio = pg.power[k] / pg.median_power().max(1e-12);
        let axis = Axis::from_index(a).expect("an axis index");
        let note = format!(
            "periodogram of the {tn} residual along {axis} ({} points on {} line(s), spacing {} mm): peak at {} mm, {:.0}x the median power{}",
            dl.rows.len(),
            dl.lines.max(1),
            fmt_num(dl.spacing_mm, 3),
            fmt_num(1.0 / f, 3),
            ratio,
            if h > 1 { format!(", {h} harmonics") } else { String::new() }
        );
        s.ev.periodograms.push(PeriodogramEvidence {
            target: td.t,
            axis: a,
            step: 1,
            pg,
        });
        let spec = EffectSpec::new(
            s.target(),
            Periodic {
                axis,
                period_mm: shown(1.0 / f, 5),
                harmonics: h,
            },
        );
        out.push(Proposal {
            spec,
            searched: 1,
            note,
        });
    }
    out
}
