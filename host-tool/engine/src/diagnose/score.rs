//! Scoring of proposed candidates against one target's model: identifiability
//! (the share outside the model's span), ΔBIC, the block-held-out gain, the
//! physical parameter, and the evidence text of each, as [`Candidate`]s.

use std::collections::BTreeMap;

use crate::data::{AXES, TARGETS};
use crate::effect::EffectSpec;
use crate::features::Feature;
use crate::model::Seed;

use super::physical::{lag_aware_xtx_inv, param_key, physical};
use super::search::Proposal;
use super::target::{
    block_rms, candidate_forward_rms, forward_blocks, forward_refit_rms, fwl_many, State,
    TargetData,
};
use super::{Candidate, CandidateSpec, HoldOutKind, Listed, Warning, IN_SPAN_SHARE};

/// The scored candidates of one target, with the columns needed for overlaps.
pub(super) struct Scored {
    pub(super) cand: Candidate,
    /// Its effect (`cand.add`), typed.
    pub(super) spec: EffectSpec,
    /// The effect it replaces (`cand.replaces`), typed.
    pub(super) replaces: Option<EffectSpec>,
    /// Its columns with the model partialled out, kept only for a plausible
    /// contender (identifiable, ΔBIC < 0: the overlaps among the contenders
    /// need them); empty otherwise — n rows each, 8 MB a column at a
    /// million rows (issue 29). [`Scored::partialled_or`] recomputes them.
    pub(super) partialled: Vec<Vec<f64>>,
    /// Its number of columns.
    pub(super) width: usize,
    /// On a time series where n_eff decides (`autocorr::decides`): the
    /// effective sample size of the residual with the candidate in, and
    /// its ΔBIC recomputed with it.
    pub(super) effective: Option<(f64, f64)>,
}

impl Scored {
    /// The candidate and its typed effect, for the target's list (the
    /// columns are not kept).
    pub(super) fn listed(self) -> Listed {
        let spec = CandidateSpec {
            add: self.spec,
            replaces: self.replaces,
        };
        (self.cand, spec)
    }

    /// Its partialled columns: the kept ones, else recomputed on the model
    /// `st` it was scored against (the same values: each column is
    /// projected on its own); None if they cannot be.
    pub(super) fn partialled_or(
        &self,
        td: &TargetData,
        st: &State,
    ) -> Option<std::borrow::Cow<'_, [Vec<f64>]>> {
        if !self.partialled.is_empty() || self.width == 0 {
            return Some(std::borrow::Cow::Borrowed(&self.partialled));
        }
        let ff = super::target::fwl(td, st, &self.spec, 0).ok()?;
        Some(std::borrow::Cow::Owned(ff.partialled))
    }

    /// [`Scored::listed`] of a copy.
    pub(super) fn to_listed(&self) -> Listed {
        let spec = CandidateSpec {
            add: self.spec.clone(),
            replaces: self.replaces.clone(),
        };
        (self.cand.clone(), spec)
    }
}

/// A replacement's comparison: `st` passed to `score` is the model without
/// the old effect; ΔBIC and gain are taken against the current model.
pub(super) struct Replacing<'a> {
    pub(super) current: &'a State,
    pub(super) old: EffectSpec,
    /// Columns of the old effect (its rank in the current model).
    pub(super) old_rank: usize,
}

/// Proposals projected on the model together (their columns, raw and
/// partialled, 8 MB each at a million rows, live while they are scored).
const SCORE_TOGETHER: usize = 4;

pub(super) fn score(
    td: &TargetData,
    st: &State,
    props: Vec<Proposal>,
    seed: &Seed,
    warnings: &mut Vec<Warning>,
    repl: Option<&Replacing>,
) -> Vec<Scored> {
    let n = td.rows.len();
    let tn = TARGETS[td.t];
    let decides = super::autocorr::decides(td);
    let mut out = Vec::new();
    // A few proposals at a time projected together (one pass over the
    // model's basis for all their columns), their columns kept only while
    // they are scored.
    let mut props = props.into_iter();
    loop {
        let chunk: Vec<Proposal> = props.by_ref().take(SCORE_TOGETHER).collect();
        if chunk.is_empty() {
            break;
        }
        let specs: Vec<(&EffectSpec, usize)> =
            chunk.iter().map(|p| (&p.spec, p.searched)).collect();
        let fits = fwl_many(td, st, &specs);
        for (p, ff) in chunk.into_iter().zip(fits) {
            let Ok(mut ff) = ff else {
                continue;
            };
            // Against the current model: the swap keeps the parameter count
            // (one lag for another), so only the change in columns is charged.
            let ref_held = match repl {
                Some(r) => {
                    let nf = n as f64;
                    ff.dbic = nf * (ff.fit.rss.max(1e-300) / r.current.rss.max(1e-300)).ln()
                        + (ff.fit.rank as f64 - r.old_rank as f64) * nf.ln();
                    r.current.held_out_rms
                }
                None => st.held_out_rms,
            };
            let params: BTreeMap<String, f64> = p
                .spec
                .searched_params()
                .into_iter()
                .map(|(k, v)| (k.to_string(), v))
                .collect();
            let base = Candidate {
                effect: p.family(),
                target: tn.to_string(),
                axis: p.axis().map(|a| AXES[a].to_string()),
                channel: p.spec.follows(),
                params,
                add: p.spec.to_string(),
                held_out_rms_um_after: None,
                held_out_rms_um_before: None,
                hold_out: HoldOutKind::Blocks,
                gain: None,
                identifiable: false,
                evidence: String::new(),
                delta_bic: None,
                rms_um_after: None,
                out_of_span_share: ff.share,
                significant: false,
                physical: None,
                confounded_with: Vec::new(),
                replaces: repl.map(|r| r.old.to_string()),
                step: None,
                aliasing: None,
                held_back: false,
            };
            if ff.share < IN_SPAN_SHARE || ff.fit.rank == 0 {
                if repl.is_some() {
                    continue;
                }
                let cols = p
                    .spec
                    .features()
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ");
                let detail = format!(
                    "{seed} already contains the column(s) {cols} for {tn} (up to a combination of its terms), so `{}` cannot be told from it{}",
                    p.spec,
                    p.family().info().in_span_hint
                );
                warnings.push(Warning {
                    code: "in_model_span".into(),
                    detail: detail.clone(),
                });
                out.push(Scored {
                    cand: Candidate {
                        evidence: detail,
                        ..base
                    },
                    spec: p.spec,
                    replaces: repl.map(|r| r.old.clone()),
                    width: ff.partialled.len(),
                    partialled: Vec::new(),
                    effective: None,
                });
                continue;
            }
            // Time-dependent families are judged by predicting later data from
            // earlier data (forward chaining): a polynomial in time interpolates
            // any smooth curve in a block hold-out, but cannot say where a
            // cool-down or the next day goes; a temperature that causes the
            // error can. The other families keep the block hold-out.
            let forward = p
                .family()
                .info()
                .time_dependent
                .then(|| forward_blocks(td))
                .flatten();
            let (ref_held, held, kind) = match &forward {
                Some(blocks) => {
                    let (before, after) =
                        candidate_forward_rms(td, st, blocks, &ff.cols, &ff.partialled);
                    let before = match repl {
                        // At one position: the current model refitted
                        // forward, as the candidate is.
                        Some(r) if decides => {
                            forward_refit_rms(blocks, &td.y, &r.current.basis, &[])
                        }
                        // Against the current model: its own residual, forward.
                        Some(r) => block_rms(&blocks[1..], |i| r.current.resid[i]),
                        None => before,
                    };
                    (before, Some(after), HoldOutKind::Forward)
                }
                None => (ref_held, st.holdout.rms(&ff.cols), HoldOutKind::Blocks),
            };
            let gain = held.map(|h| 1.0 - h / ref_held).filter(|g| g.is_finite());
            let dof = n.saturating_sub(st.basis.rank() + ff.fit.rank).max(1) as f64;
            let sigma2 = ff.fit.rss / dof;
            if let Some(inv) = lag_aware_xtx_inv(td, st, &p.spec, &ff) {
                ff.fit.xtx_inv = inv;
            }
            // Residuals correlated in time (the model plus this candidate's,
            // in time order): n readings count as n_eff, and every standard
            // error grows by √(n/n_eff) — σ² scaled by n/n_eff.
            let time_series =
                super::autocorr::in_time_after(td, &st.resid, &ff.partialled, &ff.fit.beta);
            let widen = time_series.map_or(1.0, |(_, ne)| super::autocorr::widening(n, ne));
            let phys = physical(td, &p, &ff, sigma2 * widen * widen);
            // The parameters the ΔBIC charged: the columns (and searched
            // parameters) added, or a replacement's change in columns.
            let charged = match repl {
                Some(r) => ff.fit.rank as f64 - r.old_rank as f64,
                None => (ff.fit.rank + p.searched) as f64,
            };
            let effective = time_series
                .filter(|_| decides)
                .map(|(_, ne)| (ne, super::autocorr::effective_dbic(ff.dbic, n, ne, charged)));
            let mut base = base;
            if let Some(ph) = &phys {
                base.params.insert(param_key(ph), ph.value);
            }
            let rms_after = (ff.fit.rss / n as f64).sqrt();
            let mut evidence = format!(
                "{}{}; ΔBIC {:.0}; {} RMS {} → {} µm (gain {})",
                p.note,
                repl.map_or(String::new(), |r| format!(
                    "; replaces `{}` (the same effect, its parameter searched again without it)",
                    r.old
                )),
                ff.dbic,
                match kind {
                    HoldOutKind::Forward => "forward-chained (earlier time predicts later)",
                    HoldOutKind::Blocks => "block-held-out",
                },
                if ref_held.is_finite() {
                    format!("{ref_held:.3}")
                } else {
                    "n/a".into()
                },
                held.filter(|h| h.is_finite())
                    .map_or("n/a".into(), |h| format!("{h:.3}")),
                gain.map_or("n/a: no block could be held out".into(), |g| format!(
                    "{:.0} %",
                    100.0 * g
                ))
            );
            if let Some(ph) = &phys {
                evidence.push_str(&format!(
                    "; {} {:.3} {} (95 % {:.3} … {:.3}){}",
                    ph.name,
                    ph.value,
                    ph.unit,
                    ph.ci95[0],
                    ph.ci95[1],
                    if ph.plausible {
                        String::new()
                    } else {
                        format!(" — NOT plausible (expected {})", ph.expected)
                    }
                ));
            }
            // A multi-sensor thermal effect: every sensor's µm/K (the physical
            // parameter above is the first one's).
            {
                let features = p.spec.features();
                let per: Vec<String> = features
                    .iter()
                    .zip(&ff.fit.beta)
                    .filter_map(|(f, b)| match f {
                        Feature::Thermal {
                            channel,
                            exp: [0, 0, 0],
                            ..
                        } => Some(format!("T_{channel}_C {b:.3} µm/K")),
                        _ => None,
                    })
                    .collect();
                if per.len() > 1 && per.len() == features.len() {
                    evidence.push_str(&format!("; per sensor: {}", per.join(", ")));
                }
            }
            if ff.share < 0.05 {
                evidence.push_str(&format!(
                    "; only {:.1} % of it lies outside the model's span",
                    100.0 * ff.share
                ));
            }
            out.push(Scored {
                cand: Candidate {
                    held_out_rms_um_after: held.filter(|h| h.is_finite()),
                    held_out_rms_um_before: ref_held.is_finite().then_some(ref_held),
                    hold_out: kind,
                    gain,
                    identifiable: true,
                    evidence,
                    delta_bic: Some(ff.dbic),
                    rms_um_after: Some(rms_after),
                    physical: phys,
                    ..base
                },
                spec: p.spec,
                replaces: repl.map(|r| r.old.clone()),
                width: ff.partialled.len(),
                partialled: if ff.dbic < 0.0 {
                    ff.partialled
                } else {
                    Vec::new()
                },
                effective,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::Norm;
    use crate::simulate::thermal_test::spindle_thermal;

    /// Only a plausible contender (identifiable, ΔBIC < 0) keeps its
    /// partialled columns; the others' are recomputed on demand, equal to
    /// the bit to what scoring (several proposals projected together) had.
    #[test]
    fn only_contenders_keep_their_columns_and_the_rest_are_recomputed_exactly() {
        let full = spindle_thermal(1).data;
        let day: Vec<usize> = (0..=16 * 60).collect();
        let data = crate::data::subset(&full, &day);
        let none = crate::progress::Sink::none();
        let (td, _) = TargetData::new(&data, Norm::from_data(&data), 2, &none);
        let st = State::new(&td, &Seed::Cubic19, &[]).unwrap();
        let props: Vec<Proposal> = [
            "drift:target=ez,order=3",
            "thermal:target=ez,channel=spindle_housing",
            "reversal:target=ez,axis=x",
            "drift:target=ez,order=1",
            "drift:target=ez,order=2",
            "thermal:target=ez,channel=bed",
            "periodic:target=ez,axis=x,period_mm=50",
            "thermal:target=ez,channel=spindle_housing,times=x",
        ]
        .iter()
        .map(|s| Proposal {
            spec: s.parse().unwrap(),
            searched: 0,
            note: String::new(),
        })
        .collect();
        let sc = score(&td, &st, props, &Seed::Cubic19, &mut Vec::new(), None);
        assert!(sc.len() >= 3, "{} scored", sc.len());
        let (mut kept, mut dropped) = (0, 0);
        for s in &sc {
            let contender = s.cand.identifiable && s.cand.delta_bic.is_some_and(|d| d < 0.0);
            assert_eq!(!s.partialled.is_empty(), contender, "{}", s.cand.add);
            assert_eq!(s.partialled.len(), if contender { s.width } else { 0 });
            let again = s.partialled_or(&td, &st).unwrap();
            let direct = super::super::target::fwl(&td, &st, &s.spec, 0).unwrap();
            assert_eq!(again.len(), s.width, "{}", s.cand.add);
            assert!(again.iter().zip(&direct.partialled).all(|(a, b)| a == b));
            if contender {
                kept += 1;
            } else {
                dropped += 1;
            }
        }
        let names: Vec<_> = sc.iter().map(|s| (&s.cand.add, s.cand.delta_bic)).collect();
        assert!(
            kept > 0 && dropped > 0,
            "kept {kept}, dropped {dropped}: {names:?}"
        );
    }
}
