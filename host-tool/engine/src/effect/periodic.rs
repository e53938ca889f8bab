//! `periodic`: the cyclic error of a lead screw (its lead) or of a scale
//! (its pitch) along one axis.
//!
//! `periodic:target=ey,axis=y,period_mm=5.08[,harmonics=1..4]` adds
//! sin, cos(2π·k·p/period), k = 1..harmonics, of the axis' position p.
//! Its physical parameter is the amplitude of the fundamental. Simulated
//! as Σ_{h=1..harmonics} (amp_um / h)·sin(2π·h·q/period_mm + h·phase).

use std::f64::consts::TAU;
use std::fmt;

use anyhow::{bail, Result};

use super::{
    along_words, Axis, EffectParams, FamilyDef, Info, Limit, Pairs, PhysicalParam, Reading,
    SimForm, SimRows, Target,
};
use crate::data::{AXES, TARGETS};
use crate::features::{Feature, Phase};

/// A periodic error along `axis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Periodic {
    /// The axis whose position it follows.
    pub axis: Axis,
    /// The period, mm (the screw lead, or the scale's pitch).
    pub period_mm: f64,
    /// Harmonics fitted, 1..=4.
    pub harmonics: u8,
}

impl FamilyDef for Periodic {
    const INFO: Info = Info::new(
        "periodic",
        &["target", "axis", "period_mm", "harmonics"],
        "check the period against the screw lead and the scale pitch, and the amplitude against the screw's class",
    )
    .aliasable()
    .simulated(Sim::parse);

    fn parse(kv: &Pairs, _target: Target) -> Result<Periodic> {
        let axis = kv.need_axis("axis")?;
        let period_mm = kv.need_f64("period_mm")?;
        if period_mm <= 0.0 {
            bail!("`period_mm={period_mm}`: expected a positive period");
        }
        let harmonics = kv.u8_in("harmonics", 1, 4)?.unwrap_or(1);
        Ok(Periodic {
            axis,
            period_mm,
            harmonics,
        })
    }
}

impl EffectParams for Periodic {
    fn features(&self, _target: Target) -> Vec<Feature> {
        (1..=self.harmonics)
            .flat_map(|k| {
                [Phase::Sin, Phase::Cos].map(|phase| Feature::Periodic {
                    axis: self.axis.index(),
                    period_mm: self.period_mm,
                    harmonic: k,
                    phase,
                })
            })
            .collect()
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        let mut p = vec![
            ("axis", self.axis.to_string()),
            ("period_mm", self.period_mm.to_string()),
        ];
        if self.harmonics > 1 {
            p.push(("harmonics", self.harmonics.to_string()));
        }
        p
    }

    fn axis(&self) -> Option<Axis> {
        Some(self.axis)
    }

    fn period_mm(&self) -> Option<f64> {
        Some(self.period_mm)
    }

    fn describe(&self, t: &str) -> String {
        format!(
            "a periodic error of {t}{} (lead screw or scale pitch)",
            along_words(Some(self.axis))
        )
    }

    fn searched_params(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("period_mm", self.period_mm),
            ("harmonics", f64::from(self.harmonics)),
        ]
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(PhysicalParam {
            name: "amplitude",
            unit: "µm",
            expected: "periods 0.5–100 mm (leads 2–40 mm), amplitude up to ~8 µm",
            reading: Reading::Amplitude {
                period_mm: self.period_mm,
                periods_mm: [0.5, 100.0],
                max_um: 20.0,
            },
        })
    }
}

/// Lead or scale pitch (leads 2–40 mm; scales shorter).
const PERIOD_MM: Limit = Limit::above(0.0, 10_000.0, "mm");
/// Harmonics of a cyclic error.
const HARMONICS: Limit = Limit::closed(1.0, 50.0, "");
/// A phase, degrees.
const PHASE_DEG: Limit = Limit::closed(-3600.0, 3600.0, "°");

/// The simulated cyclic error along `axis`, added to `target`:
/// Σ_{h=1..harmonics} (amp_um / h)·sin(2π·h·q/period_mm + h·phase).
#[derive(Clone, Debug, PartialEq)]
pub struct Sim {
    /// Target index (0 = ex); usually the axis itself.
    pub target: usize,
    /// Axis whose position drives it.
    pub axis: usize,
    /// Screw lead or scale pitch, mm (any value, e.g. 5.08).
    pub period_mm: f64,
    /// Amplitude of the fundamental, µm.
    pub amp_um: f64,
    /// Number of harmonics (1 = a pure sine).
    pub harmonics: u8,
    /// Phase of the fundamental at q = 0, degrees.
    pub phase_deg: f64,
}

impl Sim {
    /// `axis`, `period_mm`, `amp_um`, [`harmonics` 1..=16], [`target`, the
    /// axis' own by default], [`phase_deg`].
    fn parse(kv: &Pairs) -> Result<Box<dyn SimForm>> {
        let axis = kv.need_axis("axis")?.index();
        let period_mm = kv.need_f64("period_mm")?;
        if period_mm <= 0.0 {
            bail!("`period_mm={period_mm}`: expected a positive period");
        }
        let e = Sim {
            target: kv.target()?.map_or(axis, Target::index),
            axis,
            period_mm,
            amp_um: kv.need_f64("amp_um")?,
            harmonics: match kv.usize("harmonics")?.unwrap_or(1) {
                h @ 1..=16 => h as u8,
                h => bail!("`harmonics={h}`: expected 1..=16"),
            },
            phase_deg: kv.f64("phase_deg")?.unwrap_or(0.0),
        };
        kv.finish("axis, period_mm, amp_um, harmonics, target, phase_deg")?;
        Ok(Box::new(e))
    }
}

impl SimForm for Sim {
    fn valid(&self) -> bool {
        self.period_mm > 0.0 && self.harmonics >= 1
    }

    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        PERIOD_MM.check(&what("period_mm"), self.period_mm)?;
        Limit::AMP_UM.check(&what("amp_um"), self.amp_um)?;
        HARMONICS.check(&what("harmonics"), f64::from(self.harmonics))?;
        PHASE_DEG.check(&what("phase_deg"), self.phase_deg)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        let ph = self.phase_deg.to_radians();
        for (r, &q) in rows.pos_mm[self.axis].iter().enumerate() {
            let v: f64 = (1..=self.harmonics)
                .map(|h| {
                    let h = f64::from(h);
                    self.amp_um / h * (TAU * h * q / self.period_mm + h * ph).sin()
                })
                .sum();
            truth[self.target][r] += v;
        }
    }
}

impl fmt::Display for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "periodic:axis={},period_mm={},amp_um={},harmonics={},target={},phase_deg={}",
            AXES[self.axis],
            self.period_mm,
            self.amp_um,
            self.harmonics,
            TARGETS[self.target],
            self.phase_deg
        )
    }
}
