//! How the search proposes `squareness`: the target linear in each other
//! moving axis (a linear cross term; the seed may already hold it, which
//! scoring reports as `in_model_span`).

use crate::effect::squareness::Squareness;
use crate::effect::{Axis, EffectSpec, Family};

use super::super::target::TargetData;
use super::{Proposal, Search};

/// No nonlinear parameter to search again.
pub(super) fn researchable(_td: &TargetData) -> bool {
    false
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let tn = s.tn();
    let mut out = Vec::new();
    for &a in &s.moving {
        if a == s.td.t || !s.want(Family::Squareness, Some(a), None, None) {
            continue;
        }
        let axis = Axis::from_index(a).expect("an axis index");
        out.push(Proposal {
            spec: EffectSpec::new(s.target(), Squareness { axis }),
            searched: 0,
            note: format!("the {tn} residual is linear in {axis}"),
        });
    }
    out
}
