//! `higher_order`: a smooth shape along one axis that the seed's degree
//! cannot follow — not a named physical cause, the polynomial's next
//! degrees.
//!
//! `higher_order:target=ex,axis=y,degree=4..5` adds u_axis^4 …
//! u_axis^degree; its size is the RMS of the fitted component. Not
//! simulated as an effect (the machine's smooth errors, `mill800-wavy`,
//! make it).

use anyhow::Result;

use super::{
    along_words, exp_along, Axis, EffectParams, FamilyDef, Info, Pairs, PhysicalParam, Reading,
    Target,
};
use crate::features::Feature;

/// Polynomial terms of degree 4 to `degree` along `axis`.
#[derive(Clone, Debug, PartialEq)]
pub struct HigherOrder {
    /// The axis.
    pub axis: Axis,
    /// The highest degree, 4..=5.
    pub degree: u8,
}

impl FamilyDef for HigherOrder {
    const INFO: Info = Info::new(
        "higher_order",
        &["target", "axis", "degree"],
        "check the data",
    )
    .aliasable();

    fn parse(kv: &Pairs, _target: Target) -> Result<HigherOrder> {
        let axis = kv.need_axis("axis")?;
        let degree = kv
            .u8_in("degree", 4, 5)?
            .ok_or_else(|| anyhow::anyhow!("missing `degree=`"))?;
        Ok(HigherOrder { axis, degree })
    }
}

impl EffectParams for HigherOrder {
    fn features(&self, _target: Target) -> Vec<Feature> {
        (4..=self.degree)
            .map(|p| Feature::Monomial {
                exp: exp_along(Some(self.axis), p),
            })
            .collect()
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        vec![
            ("axis", self.axis.to_string()),
            ("degree", self.degree.to_string()),
        ]
    }

    fn axis(&self) -> Option<Axis> {
        Some(self.axis)
    }

    fn describe(&self, t: &str) -> String {
        format!(
            "a smooth shape of {t}{} the seed cannot follow (higher order, not a named physical effect)",
            along_words(Some(self.axis))
        )
    }

    fn searched_params(&self) -> Vec<(&'static str, f64)> {
        vec![("degree", f64::from(self.degree))]
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "component_rms",
            unit: "µm",
            expected: "any",
            reading: Reading::ComponentRms,
        })
    }
}
