//! `reversal`: the reversal error (backlash) of an axis — the position
//! reached depends on the direction it was approached from.
//!
//! `reversal:target=ex,axis=x` adds dir_axis (±1); its coefficient is half
//! the backlash. Simulated as ±backlash_um/2 by the direction of the last
//! approach.

use std::fmt;

use anyhow::Result;

use super::{
    along_words, Axis, EffectParams, FamilyDef, Info, Limit, Pairs, PhysicalParam, Reading,
    Scale, SimForm, SimRows, Target,
};
use crate::data::{AXES, TARGETS};
use crate::features::Feature;

/// The reversal error of `axis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Reversal {
    /// The axis whose approach direction (`dir_*`) it follows.
    pub axis: Axis,
}

impl FamilyDef for Reversal {
    const INFO: Info = Info::new(
        "reversal",
        &["target", "axis"],
        "check the drive (a loose coupling or a worn nut) and the sign of the dir column",
    )
    .simulated(Sim::parse);

    fn parse(kv: &Pairs, _target: Target) -> Result<Reversal> {
        Ok(Reversal {
            axis: kv.need_axis("axis")?,
        })
    }
}

impl EffectParams for Reversal {
    fn features(&self, _target: Target) -> Vec<Feature> {
        vec![Feature::Reversal {
            axis: self.axis.index(),
        }]
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        vec![("axis", self.axis.to_string())]
    }

    fn axis(&self) -> Option<Axis> {
        Some(self.axis)
    }

    fn follows(&self) -> Option<String> {
        Some(format!("dir_{}", self.axis))
    }

    fn describe(&self, t: &str) -> String {
        format!(
            "a reversal error (backlash) of {t}{}",
            along_words(Some(self.axis))
        )
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "backlash",
            unit: "µm",
            expected: "backlash 1–50 µm",
            reading: Reading::Linear {
                scale: Scale::Fixed(2.0),
                max_abs: 60.0,
            },
        })
    }
}

/// Backlash (5–50 µm on worn machines).
const BACKLASH_UM: Limit = Limit::closed(-1000.0, 1000.0, "µm");

/// Simulated reversal (backlash) on `axis`: ±backlash_um/2 on `target` by
/// the direction of the last approach, so x̄↑ − x̄↓ = backlash_um.
#[derive(Clone, Debug, PartialEq)]
pub struct Sim {
    /// Target index (usually the axis itself).
    pub target: usize,
    /// Axis whose `dir_*` drives it.
    pub axis: usize,
    /// Full backlash, µm.
    pub backlash_um: f64,
}

impl Sim {
    /// `axis`, `backlash_um`, [`target`, the axis' own by default].
    fn parse(kv: &Pairs) -> Result<Box<dyn SimForm>> {
        let axis = kv.need_axis("axis")?.index();
        let e = Sim {
            target: kv.target()?.map_or(axis, Target::index),
            axis,
            backlash_um: kv.need_f64("backlash_um")?,
        };
        kv.finish("axis, backlash_um, target")?;
        Ok(Box::new(e))
    }
}

impl SimForm for Sim {
    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        BACKLASH_UM.check(&what("backlash_um"), self.backlash_um)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        for (r, &d) in rows.dir[self.axis].iter().enumerate() {
            truth[self.target][r] += f64::from(d) * self.backlash_um / 2.0;
        }
    }

    fn warning(&self, rows: &SimRows) -> Option<String> {
        let d = &rows.dir[self.axis];
        (!(d.contains(&1) && d.contains(&-1))).then(|| {
            format!(
                "reversal on {} but the plan approaches it from one direction only",
                AXES[self.axis]
            )
        })
    }
}

impl fmt::Display for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "reversal:axis={},backlash_um={},target={}",
            AXES[self.axis], self.backlash_um, TARGETS[self.target]
        )
    }
}
