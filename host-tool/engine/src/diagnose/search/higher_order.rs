//! How the search proposes `higher_order`: along each moving axis, degree
//! 4, or 5 when it buys ΔBIC < −10.

use crate::effect::higher_order::HigherOrder;
use crate::effect::{Axis, EffectSpec, Family};

use super::super::target::{fwl, TargetData};
use super::super::DBIC_SIGNIFICANT;
use super::{Proposal, Search};

/// The degree.
pub(super) fn researchable(_td: &TargetData) -> bool {
    true
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let (td, st) = (s.td, s.st);
    let tn = s.tn();
    let mut out = Vec::new();
    for &a in &s.moving {
        if !s.want(Family::HigherOrder, Some(a), None, None) {
            continue;
        }
        let axis = Axis::from_index(a).expect("an axis index");
        let spec_at = |degree: u8| EffectSpec::new(s.target(), HigherOrder { axis, degree });
        let d4 = fwl(td, st, &spec_at(4), 0).map_or(f64::INFINITY, |x| x.dbic);
        let d5 = fwl(td, st, &spec_at(5), 0).map_or(f64::INFINITY, |x| x.dbic);
        let d = if d5 < d4 + DBIC_SIGNIFICANT { 5 } else { 4 };
        out.push(Proposal {
            spec: spec_at(d),
            searched: 0,
            note: format!("the {tn} residual needs degree {d} along {axis}"),
        });
    }
    out
}
