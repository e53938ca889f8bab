//! `drift`: slow drift with time that no temperature explains.
//!
//! `drift:target=ex[,order=1..3]` adds (t/1 h)^p, p = 1..order; its
//! physical parameter is the mean rate over the session. Simulated as a
//! constant rate.

use std::fmt;

use anyhow::Result;

use super::{
    EffectParams, FamilyDef, Info, Limit, Pairs, PhysicalParam, Reading, SimForm, SimRows, Target,
};
use crate::data::TARGETS;
use crate::features::Feature;

/// A drift of the target with time.
#[derive(Clone, Debug, PartialEq)]
pub struct Drift {
    /// The polynomial's order in time, 1..=3.
    pub order: u8,
}

impl FamilyDef for Drift {
    const INFO: Info = Info::new(
        "drift",
        &["target", "order"],
        "check that t_s is in seconds and whether a temperature channel explains the drift",
    )
    .time_dependent()
    .simulated(Sim::parse);

    fn parse(kv: &Pairs, _target: Target) -> Result<Drift> {
        Ok(Drift {
            order: kv.u8_in("order", 1, 3)?.unwrap_or(1),
        })
    }
}

impl EffectParams for Drift {
    fn features(&self, _target: Target) -> Vec<Feature> {
        (1..=self.order)
            .map(|power| Feature::Drift { power })
            .collect()
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        if self.order > 1 {
            vec![("order", self.order.to_string())]
        } else {
            Vec::new()
        }
    }

    fn follows(&self) -> Option<String> {
        Some("t_s".into())
    }

    fn describe(&self, t: &str) -> String {
        format!("a drift of {t} with time")
    }

    fn searched_params(&self) -> Vec<(&'static str, f64)> {
        vec![("order", f64::from(self.order))]
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "rate",
            unit: "µm/h",
            expected: "≤ 30 µm/h (mean over the session)",
            reading: Reading::MeanRate { max_abs: 30.0 },
        })
    }
}

/// Drift rate.
const DRIFT_UM_PER_H: Limit = Limit::closed(-1000.0, 1000.0, "µm/h");

/// Simulated slow drift in time not explained by temperature:
/// um_per_h·t_s/3600.
#[derive(Clone, Debug, PartialEq)]
pub struct Sim {
    /// Target index.
    pub target: usize,
    /// Drift rate, µm/h.
    pub um_per_h: f64,
}

impl Sim {
    /// `um_per_h`, [`target`, ex by default].
    fn parse(kv: &Pairs) -> Result<Box<dyn SimForm>> {
        let e = Sim {
            target: kv.target()?.map_or(0, Target::index),
            um_per_h: kv.need_f64("um_per_h")?,
        };
        kv.finish("um_per_h, target")?;
        Ok(Box::new(e))
    }
}

impl SimForm for Sim {
    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        DRIFT_UM_PER_H.check(&what("um_per_h"), self.um_per_h)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        for (r, t) in rows.t_s.iter().enumerate() {
            truth[self.target][r] += self.um_per_h * t / 3600.0;
        }
    }
}

impl fmt::Display for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "drift:um_per_h={},target={}",
            self.um_per_h, TARGETS[self.target]
        )
    }
}
