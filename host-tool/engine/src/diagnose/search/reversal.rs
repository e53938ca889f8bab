//! How the search proposes `reversal`: each axis of the data approached
//! from both sides (its `dir_*` column has both signs), with the mean
//! residual of either side as the evidence.

use crate::effect::reversal::Reversal;
use crate::effect::{Axis, EffectSpec, Family};

use super::super::target::TargetData;
use super::{Proposal, Search};

/// No nonlinear parameter to search again.
pub(super) fn researchable(_td: &TargetData) -> bool {
    false
}

/// The proposals for the target at the model.
pub(super) fn propose(s: &mut Search) -> Vec<Proposal> {
    let (td, st) = (s.td, s.st);
    let data = td.data;
    let mut out = Vec::new();
    for a in data.axes() {
        if !s.want(Family::Reversal, Some(a), None, None) {
            continue;
        }
        let Some(d) = &data.dir[a] else { continue };
        let (mut up, mut down) = (0, 0);
        for &r in &td.rows {
            if d[r] > 0 {
                up += 1;
            } else {
                down += 1;
            }
        }
        if up == 0 || down == 0 {
            continue;
        }
        let (mut su, mut sd) = (0.0, 0.0);
        for (i, &r) in td.rows.iter().enumerate() {
            if d[r] > 0 {
                su += st.resid[i];
            } else {
                sd += st.resid[i];
            }
        }
        let axis = Axis::from_index(a).expect("an axis index");
        out.push(Proposal {
            spec: EffectSpec::new(s.target(), Reversal { axis }),
            searched: 0,
            note: format!(
                "forward/backward split on {axis}: mean residual {:+.2} µm ({up} points approached from −) vs {:+.2} µm ({down} from +)",
                su / up as f64,
                sd / down as f64
            ),
        });
    }
    out
}
