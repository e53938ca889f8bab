//! What a simulation is asked for: the machine preset, the plans, the
//! physical effects on top of the geometric errors, the timing of the
//! measurement, noise and seed — constructible from Rust and from the
//! CLI's spec strings (`spec.rs`).

use serde::{Deserialize, Serialize};

use super::machine::Machine;
use super::plan::Plan;
use crate::data::AXES;

/// A physical effect added to the geometric errors. Magnitudes as in
/// ARCHITECTURE.md ("Physical magnitudes for simulation").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "family", rename_all = "snake_case")]
pub enum Effect {
    /// Cyclic lead-screw / scale error along `axis`, added to `target`:
    /// Σ_{h=1..harmonics} (amp_um / h)·sin(2π·h·q/period_mm + h·phase).
    Periodic {
        /// Target index (0 = ex); usually the axis itself.
        target: usize,
        /// Axis whose position drives it.
        axis: usize,
        /// Screw lead or scale pitch, mm (any value, e.g. 5.08).
        period_mm: f64,
        /// Amplitude of the fundamental, µm.
        amp_um: f64,
        /// Number of harmonics (1 = a pure sine).
        harmonics: u8,
        /// Phase of the fundamental at q = 0, degrees.
        phase_deg: f64,
    },
    /// Thermal growth following a temperature that is recorded on the
    /// channel `T_<channel>_C`: the sensor follows
    /// start_c + rise_c·(1 − e^(−t/tau_s)) + swing_c·sin(2π·t/swing_period_s);
    /// the structure follows the sensor
    /// with a first-order lag `lag_s` (updated per reading, as
    /// `features::lagged` models it); the error on `target` is
    /// (T_struct − t_ref_c)·(cte_um_per_m_k·1e-3·q_times + offset_um_per_k).
    Thermal {
        /// Target index.
        target: usize,
        /// Sensor name (`bed` → column `T_bed_C`).
        channel: String,
        /// Axis whose position the growth is proportional to; `None` for a
        /// growth that does not depend on position (spindle growth in Z).
        times: Option<usize>,
        /// Expansion coefficient, µm/m/K (steel 11.5).
        cte_um_per_m_k: f64,
        /// Position-independent growth, µm/K.
        offset_um_per_k: f64,
        /// Temperature at which the error is zero, °C.
        t_ref_c: f64,
        /// Sensor temperature at t = 0, °C.
        start_c: f64,
        /// Sensor rise to its final value, K.
        rise_c: f64,
        /// Time constant of the sensor's rise, s (0 = a step at t = 0).
        tau_s: f64,
        /// Lag of the structure behind the sensor, s (0 = none).
        lag_s: f64,
        /// Amplitude of a periodic swing added to the sensor (an air
        /// conditioner's cycle), K; 0 = none. A swing lets drift (which
        /// follows time only) be told apart from a monotonic warm-up.
        swing_c: f64,
        /// Period of the swing, s.
        swing_period_s: f64,
    },
    /// Reversal (backlash) on `axis`: ±backlash_um/2 on `target` by the
    /// direction of the last approach, so x̄↑ − x̄↓ = backlash_um.
    Reversal {
        /// Target index (usually the axis itself).
        target: usize,
        /// Axis whose `dir_*` drives it.
        axis: usize,
        /// Full backlash, µm.
        backlash_um: f64,
    },
    /// A spindle tilt `angle_urad` that turns the tool length into an error
    /// on `target` (angle × arm); the tool length changes per pass, cycling
    /// through `tools_mm`, and is written to the `tool_mm` column.
    Abbe {
        /// Target index.
        target: usize,
        /// The tilt, µrad (48.5 µrad × 100 mm = 4.85 µm).
        angle_urad: f64,
        /// Tool lengths, one per pass in turn, mm.
        tools_mm: Vec<f64>,
    },
    /// A guide bump: a localized straightness error along `axis` (a dent
    /// or a proud spot of a guide rail, a bad scrape), a Gaussian of full
    /// width at half maximum `width_mm` centred at `at_mm` on that axis:
    /// amp_um·exp(−4 ln 2·((q − at_mm)/width_mm)²) added to `target`. No
    /// polynomial seed follows it, and neighbour differences along a
    /// 25–50 mm line count it as noise (issue 12).
    Bump {
        /// Target index (a straightness: usually not the axis' own).
        target: usize,
        /// Axis along which the bump sits.
        axis: usize,
        /// Centre of the bump on `axis`, mm.
        at_mm: f64,
        /// Full width at half maximum, mm.
        width_mm: f64,
        /// Height at the centre, µm.
        amp_um: f64,
    },
    /// Slow drift in time not explained by temperature: um_per_h·t_s/3600.
    Drift {
        /// Target index.
        target: usize,
        /// Drift rate, µm/h.
        um_per_h: f64,
    },
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

/// A sensible range for one simulation number: generous enough for any
/// real machine and instrument (ARCHITECTURE.md's magnitudes sit well
/// inside), tight enough that a typo (`1e300`, a NaN) is refused with its
/// name instead of silently producing a file of absurd or NaN errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// Smallest value allowed.
    pub min: f64,
    /// Largest value allowed.
    pub max: f64,
    /// `min` itself is allowed (false: strictly greater, e.g. a step).
    pub min_inclusive: bool,
    /// Unit for the message.
    pub unit: &'static str,
}

impl Limit {
    const fn closed(min: f64, max: f64, unit: &'static str) -> Limit {
        Limit {
            min,
            max,
            min_inclusive: true,
            unit,
        }
    }
    const fn above(min: f64, max: f64, unit: &'static str) -> Limit {
        Limit {
            min,
            max,
            min_inclusive: false,
            unit,
        }
    }
    /// Noise σ of the instrument: a laser reads to nm, a dial gauge to µm.
    pub const NOISE_UM: Limit = Limit::closed(0.0, 100.0, "µm");
    /// Share of error values with a spike.
    pub const SPIKE_FRAC: Limit = Limit::closed(0.0, 0.2, "");
    /// Smallest spike (the largest is twice it; ≤ 2000 µm stays inside the
    /// import's ±10 000 µm plausibility limit with the machine's errors).
    pub const SPIKE_UM: Limit = Limit::closed(0.0, 1000.0, "µm");
    /// Tool length / probe offset (and every Abbe tool length).
    pub const TOOL_MM: Limit = Limit::closed(-1000.0, 1000.0, "mm");
    /// Traverse feed: up to 120 m/min rapids.
    pub const FEED_MM_S: Limit = Limit::above(0.0, 2000.0, "mm/s");
    /// Time at each point.
    pub const DWELL_S: Limit = Limit::closed(0.0, 3600.0, "s");
    /// Raster spacing.
    pub const STEP_MM: Limit = Limit::above(0.0, 10_000.0, "mm");
    /// ISO 230-2 overrun (also < travel/2, checked with the plan).
    pub const OVERRUN_MM: Limit = Limit::closed(0.0, 10_000.0, "mm");
    /// A pause: up to ~4 months.
    pub const DURATION_S: Limit = Limit::closed(0.0, 1e7, "s");
    /// Lead or scale pitch (leads 2–40 mm; scales shorter).
    pub const PERIOD_MM: Limit = Limit::above(0.0, 10_000.0, "mm");
    /// Cyclic error amplitude (1–8 µm typical).
    pub const AMP_UM: Limit = Limit::closed(-100.0, 100.0, "µm");
    /// Harmonics of a cyclic error.
    pub const HARMONICS: Limit = Limit::closed(1.0, 50.0, "");
    /// A phase, degrees.
    pub const PHASE_DEG: Limit = Limit::closed(-3600.0, 3600.0, "°");
    /// Expansion coefficient (steel 11.5, aluminium 23, Invar ~1).
    pub const CTE: Limit = Limit::closed(-100.0, 100.0, "µm/m/K");
    /// Position-independent growth.
    pub const OFFSET_UM_PER_K: Limit = Limit::closed(-100.0, 100.0, "µm/K");
    /// A temperature of a machine shop.
    pub const TEMP_C: Limit = Limit::closed(-50.0, 100.0, "°C");
    /// A warm-up rise.
    pub const RISE_C: Limit = Limit::closed(-50.0, 50.0, "K");
    /// Time constants and lags.
    pub const TIME_CONST_S: Limit = Limit::closed(0.0, 1e7, "s");
    /// An air conditioner's swing.
    pub const SWING_C: Limit = Limit::closed(-20.0, 20.0, "K");
    /// Its period.
    pub const SWING_PERIOD_S: Limit = Limit::above(0.0, 1e7, "s");
    /// Backlash (5–50 µm on worn machines).
    pub const BACKLASH_UM: Limit = Limit::closed(-1000.0, 1000.0, "µm");
    /// A tilt (48.5 µrad typical; 10 mrad is a crash).
    pub const ANGLE_URAD: Limit = Limit::closed(-10_000.0, 10_000.0, "µrad");
    /// A position on an axis (a guide bump's centre).
    pub const POSITION_MM: Limit = Limit::closed(-10_000.0, 10_000.0, "mm");
    /// Drift rate.
    pub const DRIFT_UM_PER_H: Limit = Limit::closed(-1000.0, 1000.0, "µm/h");

    /// `Ok` when `v` is finite and inside; otherwise how it is not.
    pub fn test(&self, v: f64) -> Result<(), OutOfRange> {
        let low_ok = if self.min_inclusive {
            v >= self.min
        } else {
            v > self.min
        };
        if v.is_finite() && low_ok && v <= self.max {
            Ok(())
        } else {
            Err(OutOfRange {
                value: v,
                limit: *self,
            })
        }
    }

    /// `Ok` when `v` is finite and inside; otherwise an error naming `what`.
    pub fn check(&self, what: &str, v: f64) -> anyhow::Result<()> {
        self.test(v).map_err(|e| anyhow::anyhow!("{what} = {e}"))
    }
}

/// A number that is not finite or outside its [`Limit`]: `1e300: expected
/// a finite value ≥ 0 µm and ≤ 100 µm` (the caller names the number).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfRange {
    /// The number given.
    pub value: f64,
    /// Its range.
    pub limit: Limit,
}

impl std::fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let l = &self.limit;
        let lo = if l.min_inclusive { "≥" } else { ">" };
        let unit = if l.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", l.unit)
        };
        // `{:?}`: 1e300 prints as `1e300`, not as 301 digits.
        write!(
            f,
            "{:?}: expected a finite value {lo} {}{unit} and ≤ {}{unit}",
            self.value, l.min, l.max
        )
    }
}

impl std::error::Error for OutOfRange {}

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
            let ok = match e {
                Effect::Abbe { tools_mm, .. } => !tools_mm.is_empty(),
                Effect::Periodic {
                    period_mm,
                    harmonics,
                    ..
                } => *period_mm > 0.0 && *harmonics >= 1,
                Effect::Thermal {
                    tau_s,
                    lag_s,
                    swing_period_s,
                    ..
                } => *tau_s >= 0.0 && *lag_s >= 0.0 && *swing_period_s > 0.0,
                Effect::Bump { width_mm, .. } => *width_mm > 0.0,
                Effect::Reversal { .. } | Effect::Drift { .. } => true,
            };
            if !ok {
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
            match e {
                Effect::Periodic {
                    period_mm,
                    amp_um,
                    harmonics,
                    phase_deg,
                    ..
                } => {
                    Limit::PERIOD_MM.check(&what("period_mm"), *period_mm)?;
                    Limit::AMP_UM.check(&what("amp_um"), *amp_um)?;
                    Limit::HARMONICS.check(&what("harmonics"), f64::from(*harmonics))?;
                    Limit::PHASE_DEG.check(&what("phase_deg"), *phase_deg)?;
                }
                Effect::Thermal {
                    cte_um_per_m_k,
                    offset_um_per_k,
                    t_ref_c,
                    start_c,
                    rise_c,
                    tau_s,
                    lag_s,
                    swing_c,
                    swing_period_s,
                    ..
                } => {
                    Limit::CTE.check(&what("cte_um_per_m_k"), *cte_um_per_m_k)?;
                    Limit::OFFSET_UM_PER_K.check(&what("offset_um_per_k"), *offset_um_per_k)?;
                    Limit::TEMP_C.check(&what("t_ref_c"), *t_ref_c)?;
                    Limit::TEMP_C.check(&what("start_c"), *start_c)?;
                    Limit::RISE_C.check(&what("rise_c"), *rise_c)?;
                    Limit::TIME_CONST_S.check(&what("tau_s"), *tau_s)?;
                    Limit::TIME_CONST_S.check(&what("lag_s"), *lag_s)?;
                    Limit::SWING_C.check(&what("swing_c"), *swing_c)?;
                    Limit::SWING_PERIOD_S.check(&what("swing_period_s"), *swing_period_s)?;
                }
                Effect::Reversal { backlash_um, .. } => {
                    Limit::BACKLASH_UM.check(&what("backlash_um"), *backlash_um)?
                }
                Effect::Abbe {
                    angle_urad,
                    tools_mm,
                    ..
                } => {
                    Limit::ANGLE_URAD.check(&what("angle_urad"), *angle_urad)?;
                    for t in tools_mm {
                        Limit::TOOL_MM.check(&what("tools_mm"), *t)?;
                    }
                }
                Effect::Bump {
                    at_mm,
                    width_mm,
                    amp_um,
                    ..
                } => {
                    Limit::POSITION_MM.check(&what("at_mm"), *at_mm)?;
                    Limit::STEP_MM.check(&what("width_mm"), *width_mm)?;
                    Limit::AMP_UM.check(&what("amp_um"), *amp_um)?;
                }
                Effect::Drift { um_per_h, .. } => {
                    Limit::DRIFT_UM_PER_H.check(&what("um_per_h"), *um_per_h)?
                }
            }
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
