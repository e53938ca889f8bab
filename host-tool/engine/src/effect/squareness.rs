//! `squareness`: out-of-squareness of two axes — the error along one axis
//! growing linearly with the position along another.
//!
//! `squareness:target=ex,axis=y` adds u_axis (the linear cross term; the
//! axis must differ from the target's); its physical parameter is the
//! angle. Not simulated as an effect: the synthetic machine has its three
//! squarenesses among the 21 geometric errors.

use anyhow::{bail, Result};

use super::{
    along_words, exp_along, Axis, EffectParams, FamilyDef, Info, Pairs, PhysicalParam, Reading,
    Scale, Target,
};
use crate::features::Feature;

/// Out-of-squareness: the target growing along `axis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Squareness {
    /// The other axis.
    pub axis: Axis,
}

impl FamilyDef for Squareness {
    const INFO: Info = Info::new(
        "squareness",
        &["target", "axis"],
        "check that the error and position columns belong to the axes they name",
    )
    .in_span_hint("; use a seed without linear cross terms (kinematic) to estimate squareness");

    fn parse(kv: &Pairs, target: Target) -> Result<Squareness> {
        let axis = kv.need_axis("axis")?;
        if axis.index() == target.index() {
            bail!(
                "squareness of {axis} against itself: `axis` must differ from the target's axis"
            );
        }
        Ok(Squareness { axis })
    }
}

impl EffectParams for Squareness {
    fn features(&self, _target: Target) -> Vec<Feature> {
        vec![Feature::Monomial {
            exp: exp_along(Some(self.axis), 1),
        }]
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        vec![("axis", self.axis.to_string())]
    }

    fn axis(&self) -> Option<Axis> {
        Some(self.axis)
    }

    fn describe(&self, t: &str) -> String {
        format!(
            "out-of-squareness: {t} growing{}",
            along_words(Some(self.axis))
        )
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "angle",
            unit: "µrad",
            expected: "squareness 20–40 µrad",
            reading: Reading::Linear {
                scale: Scale::PerMetreAlong(self.axis),
                max_abs: 300.0,
            },
        })
    }
}
