//! How the search proposes `drift`: when the data has time, a polynomial
//! in it whose order (1 to 3) is raised while each step buys ΔBIC < −10.

use crate::effect::drift::Drift;
use crate::effect::{EffectSpec, Family};

use super::super::target::{fwl, TargetData};
use super::super::DBIC_SIGNIFICANT;
use super::{Proposal, Search};

/// The order.
pub(super) fn researchable(_td: &TargetData) -> bool {
    true
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let (td, st) = (s.td, s.st);
    if td.data.t_s.is_none() || !s.want(Family::Drift, None, None, None) {
        return Vec::new();
    }
    let tn = s.tn();
    let spec_at = |order: u8| EffectSpec::new(s.target(), Drift { order });
    let mut o = 1u8;
    let mut dbic = fwl(td, st, &spec_at(1), 0).map_or(f64::INFINITY, |x| x.dbic);
    while o < 3 {
        let next = fwl(td, st, &spec_at(o + 1), 0).map_or(f64::INFINITY, |x| x.dbic);
        if next < dbic + DBIC_SIGNIFICANT {
            o += 1;
            dbic = next;
        } else {
            break;
        }
    }
    vec![Proposal {
        spec: spec_at(o),
        searched: 0,
        note: format!("the {tn} residual follows time t_s (order {o})"),
    }]
}
