//! What a simulation is asked for: the machine preset, the plans, the
//! physical effects on top of the geometric errors, the timing of the
//! measurement, noise and seed — constructible from Rust and from the
//! CLI's spec strings (`spec.rs`).

use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::machine::Machine;
use super::plan::Plan;
use crate::data::AXES;
pub use crate::effect::sim::OutOfRange;
pub use crate::effect::Limit;
use crate::effect::SimForm;

/// A physical effect added to the geometric errors: a family's simulated
/// form (`effect::<family>::Sim`, e.g. [`crate::effect::periodic::Sim`]) or
/// a guide bump ([`Bump`]). Magnitudes as in ARCHITECTURE.md ("Physical
/// magnitudes for simulation"). Written and compared as its spec (`Display`
/// gives every parameter; parsing it gives the same effect back).
#[derive(Clone)]
pub struct Effect(Arc<dyn SimForm>);

impl Effect {
    /// The effect of a simulated form.
    pub fn new(form: impl SimForm + 'static) -> Effect {
        Effect(Arc::new(form))
    }

    /// The form, for the simulator.
    pub fn form(&self) -> &dyn SimForm {
        self.0.as_ref()
    }
}

impl From<Box<dyn SimForm>> for Effect {
    fn from(form: Box<dyn SimForm>) -> Effect {
        Effect(Arc::from(form))
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl fmt::Debug for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Effect({self})")
    }
}

impl PartialEq for Effect {
    fn eq(&self, o: &Effect) -> bool {
        self.to_string() == o.to_string()
    }
}

impl Serialize for Effect {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Effect {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Effect, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Going back to a reference point between passes (to see drift).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RefReturn {
    /// The reference point, mm.
    pub pos_mm: [f64; 3],
    /// Visit it after every this many passes (and before the first).
    pub every_passes: usize,
}

/// How time advances: each move takes the longest axis distance / feed,
/// then the reading takes `dwell_s` (settling plus averaging).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Traverse feed, mm/s.
    pub feed_mm_s: f64,
    /// Time at each point, s.
    pub dwell_s: f64,
}

impl Default for Timing {
    fn default() -> Self {
        Timing {
            feed_mm_s: 25.0,
            dwell_s: 3.0,
        }
    }
}

impl Limit {
    /// Noise σ of the instrument: a laser reads to nm, a dial gauge to µm.
    pub const NOISE_UM: Limit = Limit::closed(0.0, 100.0, "µm");
    /// Share of error values with a spike.
    pub const SPIKE_FRAC: Limit = Limit::closed(0.0, 0.2, "");
    /// Smallest spike (the largest is twice it; ≤ 2000 µm stays inside the
    /// import's ±10 000 µm plausibility limit with the machine's errors).
    pub const SPIKE_UM: Limit = Limit::closed(0.0, 1000.0, "µm");
    /// Traverse feed: up to 120 m/min rapids.
    pub const FEED_MM_S: Limit = Limit::above(0.0, 2000.0, "mm/s");
    /// Time at each point.
    pub const DWELL_S: Limit = Limit::closed(0.0, 3600.0, "s");
    /// Raster spacing (and a guide bump's width).
    pub const STEP_MM: Limit = Limit::above(0.0, 10_000.0, "mm");
    /// ISO 230-2 overrun (also < travel/2, checked with the plan).
    pub const OVERRUN_MM: Limit = Limit::closed(0.0, 10_000.0, "mm");
    /// A pause: up to ~4 months.
    pub const DURATION_S: Limit = Limit::closed(0.0, 1e7, "s");
    /// A position on an axis (a guide bump's centre).
    pub const POSITION_MM: Limit = Limit::closed(-10_000.0, 10_000.0, "mm");
}

/// One of [`SimConfig`]'s own numbers (beside the plans' and effects').
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Setting {
    /// `noise_um`.
    NoiseUm,
    /// `tool_mm`.
    ToolMm,
    /// `timing.feed_mm_s`.
    FeedMmS,
    /// `timing.dwell_s`.
    DwellS,
    /// `spikes.frac`.
    SpikeFrac,
    /// `spikes.amp_um`.
    SpikeAmpUm,
}

impl std::fmt::Display for Setting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Setting::NoiseUm => "noise_um",
            Setting::ToolMm => "tool_mm",
            Setting::FeedMmS => "feed_mm_s",
            Setting::DwellS => "dwell_s",
            Setting::SpikeFrac => "spikes frac",
            Setting::SpikeAmpUm => "spikes amp_um",
        })
    }
}

/// What [`SimConfig::check`] refuses that a caller names in its own words
/// (the CLI: `--plan`, `--noise-um`, …, cmd/flags.rs); the plans' and
/// effects' own numbers are refused with their spec's names.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// No measurement plan.
    #[error("no measurement plan (expected at least one plan, e.g. grid:50)")]
    NoPlan,
    /// A setting outside its range.
    #[error("{setting} = {range}")]
    Setting {
        /// Which.
        setting: Setting,
        /// The value and its range.
        range: OutOfRange,
    },
}

/// A `FRAC,AMP_UM` text that is not two numbers (the caller names what it
/// parsed).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("`{0}`: expected FRAC,AMP_UM, e.g. 0.005,20")]
pub struct BadSpikes(pub String);

/// Everything `simulate` needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    /// The machine's geometry.
    pub machine: Machine,
    /// Plans, run one after the other (line → plane → volume).
    pub plans: Vec<Plan>,
    /// Effects added to the geometric errors.
    pub effects: Vec<Effect>,
    /// Standard deviation of the Gaussian noise on each error value, µm.
    pub noise_um: f64,
    /// Seed of the random stream (noise, ISO 230-2 targets).
    pub seed: u64,
    /// Optional returns to a reference point.
    pub reference: Option<RefReturn>,
    /// Motion timing.
    pub timing: Timing,
    /// Tool length when no Abbe effect varies it, mm.
    pub tool_mm: f64,
    /// Spikes (beam breaks, bad readings) on top of the noise; none by default.
    #[serde(default)]
    pub spikes: Option<Spikes>,
}

/// Spikes: each error value (row × target) independently, with probability
/// `frac`, gets ±`amp_um`·(1 + u), u uniform in [0, 1) — 20–40 µm for
/// `amp_um` 20, the size of a laser's beam break — from a random stream of
/// its own, so the data without spikes is the same value for value.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spikes {
    /// Share of the error values that get a spike, 0…0.2.
    pub frac: f64,
    /// Smallest spike, µm (the largest is twice it), 0…1000.
    pub amp_um: f64,
}

impl std::str::FromStr for Spikes {
    type Err = BadSpikes;
    /// `FRAC,AMP_UM`, e.g. `0.005,20`.
    fn from_str(s: &str) -> Result<Spikes, BadSpikes> {
        let v: Vec<f64> = s
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 2)
            .ok_or_else(|| BadSpikes(s.to_string()))?;
        Ok(Spikes {
            frac: v[0],
            amp_um: v[1],
        })
    }
}

impl std::fmt::Display for Spikes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "frac={},amp_um={}", self.frac, self.amp_um)
    }
}

impl SimConfig {
    /// The preset machine with no plans, effects or noise, seed 1.
    pub fn preset(name: &str) -> anyhow::Result<SimConfig> {
        Ok(SimConfig {
            machine: Machine::preset(name)?,
            plans: Vec::new(),
            effects: Vec::new(),
            noise_um: 0.0,
            seed: 1,
            reference: None,
            timing: Timing::default(),
            tool_mm: 0.0,
            spikes: None,
        })
    }

    /// Checks what `simulate` cannot do anything sensible with: no plan,
    /// non-positive steps, positions outside the travel, and every number
    /// (noise, tool length, timing, plan and effect parameters) that is not
    /// finite or outside the physically sensible range of [`Limit`] — a
    /// NaN tool length would otherwise give a file of NaN errors that
    /// `import` refuses, and 1e300 mm a file of 2e300 µm errors.
    pub fn check(&self) -> anyhow::Result<()> {
        use anyhow::bail;
        if self.plans.is_empty() {
            return Err(ConfigError::NoPlan.into());
        }
        self.check_numbers()?;
        let tr = self.machine.travel_mm;
        let inside = |p: &[Option<f64>; 3], what: &str| -> anyhow::Result<()> {
            for a in 0..3 {
                if let Some(v) = p[a] {
                    if !(0.0..=tr[a]).contains(&v) {
                        bail!(
                            "{what}: {}={v} mm is outside the travel 0..{}",
                            AXES[a],
                            tr[a]
                        );
                    }
                }
            }
            Ok(())
        };
        for p in &self.plans {
            match p {
                Plan::Raster {
                    step_mm,
                    at_mm,
                    runs,
                    axes,
                    ..
                } => {
                    if step_mm.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                        || *runs == 0
                        || axes.is_empty()
                    {
                        bail!("plan `{p}`: expected a positive step, runs ≥ 1 and a moving axis");
                    }
                    if axes.iter().any(|&a| tr[a] / step_mm > 1e6) {
                        bail!("plan `{p}`: more than a million points per line");
                    }
                    inside(at_mm, &format!("plan `{p}`"))?;
                }
                Plan::Iso230 {
                    targets,
                    runs,
                    overrun_mm,
                    at_mm,
                    axis,
                } => {
                    if *targets < 2
                        || *runs == 0
                        || overrun_mm.is_nan()
                        || *overrun_mm < 0.0
                        || 2.0 * overrun_mm >= tr[*axis]
                    {
                        bail!(
                            "plan `{p}`: expected targets ≥ 2, runs ≥ 1 and 0 ≤ overrun < travel/2"
                        );
                    }
                    inside(at_mm, &format!("plan `{p}`"))?;
                }
                Plan::Pause { duration_s, .. } => {
                    if !(duration_s.is_finite() && *duration_s >= 0.0) {
                        bail!("plan `{p}`: expected a duration ≥ 0 s");
                    }
                }
                Plan::Point { pos_mm, repeats } => {
                    if *repeats == 0 {
                        bail!("plan `{p}`: expected repeats ≥ 1");
                    }
                    inside(&pos_mm.map(Some), &format!("plan `{p}`"))?;
                }
            }
        }
        if let Some(r) = &self.reference {
            inside(&r.pos_mm.map(Some), "reference point")?;
            if r.every_passes == 0 {
                bail!("reference every 0 passes: expected ≥ 1");
            }
        }
        if !(tr.iter().all(|t| t.is_finite() && *t > 0.0)) {
            bail!("machine travels {tr:?} mm: expected positive values");
        }
        // Rows the plans would generate: refuse sizes that would only
        // exhaust memory (a 1 mm grid of the preset is 2·10⁸ points).
        let mut rows = 0.0f64;
        for p in &self.plans {
            rows += match p {
                Plan::Raster {
                    axes,
                    step_mm,
                    bidir,
                    runs,
                    ..
                } => {
                    let per: f64 = axes
                        .iter()
                        .map(|&a| (tr[a] / step_mm).floor() + 1.0)
                        .product();
                    per * *runs as f64 * if *bidir { 2.0 } else { 1.0 }
                }
                Plan::Iso230 { targets, runs, .. } => (*targets * *runs * 2) as f64,
                Plan::Point { repeats, .. } => *repeats as f64,
                Plan::Pause { .. } => 0.0,
            };
        }
        if rows > 5e6 {
            bail!("the plans would make {rows:.0} rows; expected at most 5 000 000 (use a coarser step)");
        }
        for e in &self.effects {
            if !e.form().valid() {
                bail!("effect `{e}`: expected tools_mm not empty, period_mm > 0, harmonics ≥ 1, tau_s and lag_s ≥ 0, swing_period_s > 0, width_mm > 0");
            }
        }
        Ok(())
    }

    /// The numeric half of [`SimConfig::check`]: every number finite and
    /// inside its [`Limit`], named as [`Setting`] and the spec strings name
    /// it (the CLI names its flags instead).
    fn check_numbers(&self) -> anyhow::Result<()> {
        let setting = |setting: Setting, limit: Limit, v: f64| {
            limit
                .test(v)
                .map_err(|range| ConfigError::Setting { setting, range })
        };
        setting(Setting::NoiseUm, Limit::NOISE_UM, self.noise_um)?;
        setting(Setting::ToolMm, Limit::TOOL_MM, self.tool_mm)?;
        setting(Setting::FeedMmS, Limit::FEED_MM_S, self.timing.feed_mm_s)?;
        setting(Setting::DwellS, Limit::DWELL_S, self.timing.dwell_s)?;
        if let Some(sp) = &self.spikes {
            setting(Setting::SpikeFrac, Limit::SPIKE_FRAC, sp.frac)?;
            setting(Setting::SpikeAmpUm, Limit::SPIKE_UM, sp.amp_um)?;
        }
        for p in &self.plans {
            // The kind only: the full spec would repeat the bad number.
            let kind = p.to_string();
            let kind = kind.split(':').next().unwrap_or_default();
            let what = |k: &str| format!("plan `{kind}`: {k}");
            match p {
                Plan::Raster { step_mm, .. } => Limit::STEP_MM.check(&what("step"), *step_mm)?,
                Plan::Iso230 { overrun_mm, .. } => {
                    Limit::OVERRUN_MM.check(&what("overrun_mm"), *overrun_mm)?
                }
                Plan::Pause { duration_s, .. } => {
                    Limit::DURATION_S.check(&what("duration"), *duration_s)?
                }
                Plan::Point { .. } => {}
            }
        }
        for e in &self.effects {
            let family = e.to_string();
            let family = family.split(':').next().unwrap_or_default();
            let what = |k: &str| format!("effect `{family}`: {k}");
            e.form().check_numbers(&what)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_are_refused_by_name_in_the_engines_words() {
        let mut cfg = SimConfig::preset("mill800").unwrap();
        let e = cfg.check().unwrap_err();
        assert_eq!(e.downcast_ref(), Some(&ConfigError::NoPlan));
        cfg.plans = vec!["grid:100".parse().unwrap()];
        cfg.check().unwrap();
        cfg.noise_um = 1e9;
        let e = cfg.check().unwrap_err();
        match e.downcast_ref::<ConfigError>() {
            Some(ConfigError::Setting { setting, range }) => {
                assert_eq!(*setting, Setting::NoiseUm);
                assert_eq!(range.value, 1e9);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            e.to_string(),
            "noise_um = 1000000000.0: expected a finite value ≥ 0 µm and ≤ 100 µm"
        );
        assert_eq!(
            "0.1".parse::<Spikes>().unwrap_err().to_string(),
            "`0.1`: expected FRAC,AMP_UM, e.g. 0.005,20"
        );
    }
}
