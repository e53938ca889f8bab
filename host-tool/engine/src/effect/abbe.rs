//! `abbe`: the Abbe error — an angular error of the spindle or a slide
//! times the tool length, the arm from the measuring line.
//!
//! `abbe:target=ez[,times=x]` adds tool_mm, or tool_mm·u_axis for an angle
//! that varies along the axis; its physical parameter is the angle.
//! Simulated as a tilt times a tool length that changes per pass.

use std::fmt;

use anyhow::{anyhow, Result};

use super::{
    along_words, exp_along, Axis, EffectParams, FamilyDef, Info, Limit, Pairs, PhysicalParam,
    Reading, Scale, SimForm, SimRows, Target,
};
use crate::data::TARGETS;
use crate::features::Feature;

/// The Abbe error through the tool length.
#[derive(Clone, Debug, PartialEq)]
pub struct Abbe {
    /// The axis the angle varies along (`times=`), if any.
    pub times: Option<Axis>,
}

impl FamilyDef for Abbe {
    const INFO: Info = Info::new(
        "abbe",
        &["target", "times"],
        "check tool_mm (unit mm, the arm from the measuring line) and whether the tool length changed between passes for another reason",
    )
    .in_span_hint("; measure with two or more tool lengths (tool_mm) to separate an Abbe error")
    .simulated(Sim::parse);

    fn parse(kv: &Pairs, _target: Target) -> Result<Abbe> {
        Ok(Abbe {
            times: kv.axis("times")?,
        })
    }
}

impl EffectParams for Abbe {
    fn features(&self, _target: Target) -> Vec<Feature> {
        vec![Feature::Abbe {
            exp: exp_along(self.times, 1),
        }]
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        self.times
            .map(|a| ("times", a.to_string()))
            .into_iter()
            .collect()
    }

    fn times(&self) -> Option<Axis> {
        self.times
    }

    fn follows(&self) -> Option<String> {
        Some("tool_mm".into())
    }

    fn describe(&self, t: &str) -> String {
        format!(
            "an Abbe error of {t} (a tilt times the tool length){}",
            along_words(self.times)
        )
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "angle",
            unit: "µrad",
            expected: "angular errors 10–60 µrad",
            reading: Reading::Linear {
                scale: Scale::Fixed(1000.0),
                max_abs: 300.0,
            },
        })
    }
}

/// A tilt (48.5 µrad typical; 10 mrad is a crash).
const ANGLE_URAD: Limit = Limit::closed(-10_000.0, 10_000.0, "µrad");

/// A simulated spindle tilt `angle_urad` that turns the tool length into
/// an error on `target` (angle × arm); the tool length changes per pass,
/// cycling through `tools_mm`, and is written to the `tool_mm` column.
#[derive(Clone, Debug, PartialEq)]
pub struct Sim {
    /// Target index.
    pub target: usize,
    /// The tilt, µrad (48.5 µrad × 100 mm = 4.85 µm).
    pub angle_urad: f64,
    /// Tool lengths, one per pass in turn, mm.
    pub tools_mm: Vec<f64>,
}

impl Sim {
    /// `angle_urad`, `tools_mm` (numbers separated by /), [`target`, ex by
    /// default].
    fn parse(kv: &Pairs) -> Result<Box<dyn SimForm>> {
        let tools = kv
            .get("tools_mm")?
            .ok_or_else(|| anyhow!("missing `tools_mm=` (e.g. 0/50/100)"))?;
        let tools_mm = tools
            .split(['/', ';', '|'])
            .map(|t| {
                t.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| anyhow!("`tools_mm={tools}`: expected numbers separated by /"))
            })
            .collect::<Result<Vec<f64>>>()?;
        let e = Sim {
            target: kv.target()?.map_or(0, Target::index),
            angle_urad: kv.need_f64("angle_urad")?,
            tools_mm,
        };
        kv.finish("angle_urad, tools_mm, target")?;
        Ok(Box::new(e))
    }
}

impl SimForm for Sim {
    fn valid(&self) -> bool {
        !self.tools_mm.is_empty()
    }

    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        ANGLE_URAD.check(&what("angle_urad"), self.angle_urad)?;
        for t in &self.tools_mm {
            Limit::TOOL_MM.check(&what("tools_mm"), *t)?;
        }
        Ok(())
    }

    fn tools_mm(&self) -> Option<&[f64]> {
        Some(&self.tools_mm)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        for (r, tool) in rows.tool_mm.iter().enumerate() {
            truth[self.target][r] += self.angle_urad * tool * 1e-3;
        }
    }
}

impl fmt::Display for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let tools: Vec<String> = self.tools_mm.iter().map(f64::to_string).collect();
        write!(
            f,
            "abbe:angle_urad={},tools_mm={},target={}",
            self.angle_urad,
            tools.join("/"),
            TARGETS[self.target]
        )
    }
}
