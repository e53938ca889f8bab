//! How the search proposes `abbe`: when the data has a `tool_mm` column,
//! the tool length times a constant angle and times an angle varying along
//! each moving axis.

use crate::effect::abbe::Abbe;
use crate::effect::{Axis, EffectSpec, Family};

use super::super::target::TargetData;
use super::{fmt_num, Proposal, Search};

/// No nonlinear parameter to search again.
pub(super) fn researchable(_td: &TargetData) -> bool {
    false
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let tn = s.tn();
    let mut out = Vec::new();
    let Some(tool) = &s.td.data.tool_mm else {
        return out;
    };
    let lo = tool.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = tool.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    for tm in std::iter::once(None).chain(s.moving.iter().map(|&a| Some(a))) {
        if !s.want(Family::Abbe, None, None, tm) {
            continue;
        }
        let times = tm.and_then(Axis::from_index);
        out.push(Proposal {
            spec: EffectSpec::new(s.target(), Abbe { times }),
            searched: 0,
            note: format!(
                "the {tn} residual grows with the Abbe arm tool_mm ({} to {} mm){}",
                fmt_num(lo, 1),
                fmt_num(hi, 1),
                times.map_or(String::new(), |a| format!(", angle varying along {a}"))
            ),
        });
    }
    out
}
