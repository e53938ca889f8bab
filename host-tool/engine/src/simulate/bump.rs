//! The one simulated effect that is no fitted family: a guide bump, a
//! localized straightness error that no seed or `--add` effect models
//! (`simulate --effect bump:…`; it tests what the diagnosis says of error
//! it has no name for, issue 12).

use std::fmt;

use anyhow::{bail, Result};

use super::config::Limit;
use crate::data::{AXES, TARGETS};
use crate::effect::{Pairs, SimForm, SimRows, Target};

/// A guide bump: a localized straightness error along `axis` (a dent
/// or a proud spot of a guide rail, a bad scrape), a Gaussian of full
/// width at half maximum `width_mm` centred at `at_mm` on that axis:
/// amp_um·exp(−4 ln 2·((q − at_mm)/width_mm)²) added to `target`. No
/// polynomial seed follows it, and neighbour differences along a
/// 25–50 mm line count it as noise (issue 12).
#[derive(Clone, Debug, PartialEq)]
pub struct Bump {
    /// Target index (a straightness: usually not the axis' own).
    pub target: usize,
    /// Axis along which the bump sits.
    pub axis: usize,
    /// Centre of the bump on `axis`, mm.
    pub at_mm: f64,
    /// Full width at half maximum, mm.
    pub width_mm: f64,
    /// Height at the centre, µm.
    pub amp_um: f64,
}

impl Bump {
    /// `axis`, `at_mm`, `width_mm`, `amp_um`, [`target`, the axis' own by
    /// default].
    pub(super) fn parse(kv: &Pairs) -> Result<Bump> {
        let axis = kv.need_axis("axis")?.index();
        let width_mm = kv.need_f64("width_mm")?;
        if width_mm <= 0.0 {
            bail!("`width_mm={width_mm}`: expected a positive width");
        }
        let e = Bump {
            target: kv.target()?.map_or(axis, Target::index),
            axis,
            at_mm: kv.need_f64("at_mm")?,
            width_mm,
            amp_um: kv.need_f64("amp_um")?,
        };
        kv.finish("axis, at_mm, width_mm, amp_um, target")?;
        Ok(e)
    }
}

impl SimForm for Bump {
    fn valid(&self) -> bool {
        self.width_mm > 0.0
    }

    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        Limit::POSITION_MM.check(&what("at_mm"), self.at_mm)?;
        Limit::STEP_MM.check(&what("width_mm"), self.width_mm)?;
        Limit::AMP_UM.check(&what("amp_um"), self.amp_um)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        for (r, q) in rows.pos_mm[self.axis].iter().enumerate() {
            let u = (q - self.at_mm) / self.width_mm;
            truth[self.target][r] += self.amp_um * (-4.0 * std::f64::consts::LN_2 * u * u).exp();
        }
    }
}

impl fmt::Display for Bump {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "bump:axis={},at_mm={},width_mm={},amp_um={},target={}",
            AXES[self.axis], self.at_mm, self.width_mm, self.amp_um, TARGETS[self.target]
        )
    }
}
