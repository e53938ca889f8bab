//! The correction engine: one `tick` per period of the fixed-rate loop.
//!
//! Each tick reads the encoders (counts → nm by a per-axis scale) and the
//! temperatures, tracks the approach direction of each axis, evaluates the
//! active model (fixed point: bit-exact with the host's evaluation of the
//! same table), limits the slew of the output, and turns the output into
//! step pulses.
//!
//! **No drift.** The output correction is kept as an integer in milli-nm
//! and the pulses as an integer count of steps emitted; each tick emits
//! `round(corr_nm / pulse_nm) − steps_emitted` pulses (bounded per tick).
//! Nothing is accumulated in floating point and nothing is incremental, so
//! after any number of ticks the pulses emitted equal
//! `round(corr_nm / pulse_nm)` exactly. The configuration is checked so
//! that the slew per tick never needs more pulses than one tick may emit,
//! which makes that equality hold at the end of *every* tick.
//!
//! **Faults ramp to zero.** No table, a temperature outside the plausible
//! range, an encoder jump, a model output that is not finite, or a missed
//! period: the target becomes zero and the output ramps there at the
//! configured fault ramp rate. Conditions that come and go (no table,
//! sensor range) are live; events (overrun, encoder jump, non-finite
//! output, bad table) stay active until the host clears them — a glitch
//! that was bad enough to happen once is worth a look by a person.
//!
//! **No correction before referencing.** An encoder counts from wherever
//! the board was switched on, so until an axis is referenced its position
//! is not the machine's, and a correction keyed to position would move the
//! machine the wrong way. Every axis with an encoder needs a reference
//! ([`Engine::reference`]: "the count read now is machine position P", or
//! its home switch turning on: the axis is at `AxisConfig::home_nm`);
//! until each has one, `NOT_REFERENCED` is active and the output is held
//! at (ramped to) zero like for any fault. The reference is lost on an
//! encoder jump (the count can no longer be trusted) and on reset (the
//! engine starts unreferenced). Once every axis is referenced the output
//! ramps in from zero at the table's slew.
//!
//! **Injection is a test mode with a lease.** Injected inputs replace the
//! sensors for a number of ticks (the lease, renewed by every injection);
//! the injection ends when the lease runs out, when the link server ends it
//! (its client went), or as soon as an encoder moves. The sensor checks
//! stay on while injecting (real temperatures and the injected ones).

use trueaxis_protocol::{Correction, Faults, Injection, SlotInfo, Telemetry, LINK_TEMPS};

use crate::hw::{Clock, Encoders, StepOutput, TemperatureSource};
use crate::model::{self, ModelBuf, ModelInputs};

/// Per-axis configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisConfig {
    /// Encoder scale, picometres per count (a 0.1 µm scale read in
    /// quadrature: 25 000 pm). Negative flips the direction; at most
    /// ±(2^31 − 1) (2.1 mm per count: count × scale stays in i64).
    pub pm_per_count: i64,
    /// Position at count 0 before the axis is referenced, nm (the
    /// correction waits for the reference, see the module doc). An axis
    /// with `pm_per_count == 0` has no encoder: its position is always
    /// `origin_nm` and it needs no reference.
    pub origin_nm: i32,
    /// Displacement of one correction step pulse at the drive, nm (> 0).
    pub pulse_nm: i32,
    /// Fastest the axis can travel, nm/ms (= mm/s · 1000); a larger jump
    /// between two ticks is an encoder fault. 0 disables the check (and is
    /// refused for a widened counter, see `counter_bits`).
    pub max_speed_nm_per_ms: i32,
    /// Width of the hardware counter the count is widened from, bits: 16
    /// for the board's timers (`sensors::Widen16`), 32 when the count is
    /// read whole. The widening follows the axis only while it moves less
    /// than half the counter's range between two reads; a longer gap
    /// between ticks (a stall) with motion loses the reference
    /// ([`Faults::POSITION_LOST`]).
    pub counter_bits: u8,
    /// The axis's home switch, or `None` (referenced over the link only).
    pub home: Option<HomeSwitch>,
}

/// A home (reference) switch ([`Encoders::home_switches`]) and what the
/// engine believes of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HomeSwitch {
    /// Machine position at which the switch trips when approached in
    /// `approach`, nm.
    pub pos_nm: i32,
    /// The direction the axis moves when it homes onto the switch: an edge
    /// reached moving the other way references nothing (a switch trips at
    /// another point from the other side).
    pub approach: Approach,
    /// Ticks the input must read the same in a row before the engine
    /// believes a change (≥ 1): a glitch shorter than that is no edge. The
    /// edge's position is the count at the first of those ticks, so the
    /// debounce adds no position error.
    pub debounce_ticks: u8,
    /// How far a referenced axis may be from `pos_nm` when its switch
    /// turns on, nm: farther is a fault ([`Faults::HOME_MISMATCH`]: the
    /// tracked position or the switch is wrong) that drops the reference,
    /// never a new reference.
    pub tolerance_nm: i32,
}

/// A direction of motion along an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Approach {
    /// Towards smaller counts.
    Negative,
    /// Towards larger counts.
    Positive,
}

impl Approach {
    fn sign(self) -> i8 {
        match self {
            Approach::Negative => -1,
            Approach::Positive => 1,
        }
    }
}

/// Engine configuration (from the board; fixed at build time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EngineConfig {
    /// X, Y, Z.
    pub axes: [AxisConfig; 3],
    /// Nominal tick period, µs.
    pub period_us: u32,
    /// Most pulses one tick emits per axis.
    pub max_steps_per_tick: i32,
    /// Temperature channels fitted (checked against the range below).
    pub temps_used: usize,
    /// Plausible temperature range, m°C; outside is a sensor fault (open or
    /// shorted thermistor).
    pub temp_min_mc: i32,
    /// See `temp_min_mc`.
    pub temp_max_mc: i32,
    /// Rate at which a fault ramps the correction to zero, nm/ms (> 0).
    pub fault_ramp_nm_per_ms: i32,
    /// Tool length used when nothing else sets it, nm.
    pub tool_nm: i32,
}

/// Why a configuration is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// A pulse size ≤ 0, period 0, steps per tick ≤ 0, or a fault ramp
    /// ≤ 0 (a fault must ramp the correction to zero: at 0 nm/ms it would
    /// hold the last correction forever).
    NonPositive,
    /// More temperature channels than the link carries.
    TooManyTemps,
    /// The fault ramp needs more pulses per tick than allowed on that axis
    /// (the pulse count would lag the correction).
    RampTooFast {
        /// Axis index.
        axis: usize,
    },
    /// An axis whose count is widened from a counter of fewer than 32 bits
    /// needs a top speed (> 0): without one no gap between two reads can
    /// be proven short enough for the widening. Also a counter of 0 or
    /// more than 32 bits.
    CounterUnbounded {
        /// Axis index.
        axis: usize,
    },
    /// An encoder scale beyond ±(2^31 − 1) pm per count (2.1 mm): the
    /// position (count × scale, in i64) would overflow.
    Scale {
        /// Axis index.
        axis: usize,
    },
    /// A home switch with a debounce of 0 ticks or a negative tolerance.
    HomeSwitch {
        /// Axis index.
        axis: usize,
    },
}

impl EngineConfig {
    /// Checks the invariants the no-drift guarantee rests on.
    pub fn check(&self) -> Result<(), ConfigError> {
        if self.period_us == 0 || self.max_steps_per_tick <= 0 || self.fault_ramp_nm_per_ms <= 0 {
            return Err(ConfigError::NonPositive);
        }
        if self.temps_used > LINK_TEMPS {
            return Err(ConfigError::TooManyTemps);
        }
        for (axis, a) in self.axes.iter().enumerate() {
            if a.pulse_nm <= 0 {
                return Err(ConfigError::NonPositive);
            }
            if self.max_step_nm_per_tick(self.fault_ramp_nm_per_ms) > self.step_budget_nm(axis) {
                return Err(ConfigError::RampTooFast { axis });
            }
            if a.pm_per_count.unsigned_abs() > i32::MAX as u64 {
                return Err(ConfigError::Scale { axis });
            }
            if !(1..=32).contains(&a.counter_bits)
                || (a.counter_bits < 32 && a.pm_per_count != 0 && a.max_speed_nm_per_ms <= 0)
            {
                return Err(ConfigError::CounterUnbounded { axis });
            }
            if a.home
                .is_some_and(|h| h.debounce_ticks == 0 || h.tolerance_nm < 0)
            {
                return Err(ConfigError::HomeSwitch { axis });
            }
        }
        Ok(())
    }

    /// Largest change of the output in one tick at `rate_nm_per_ms`, nm
    /// (rounded up: one nm more for the rounding of the output).
    fn max_step_nm_per_tick(&self, rate_nm_per_ms: i32) -> i64 {
        (rate_nm_per_ms as i64 * self.period_us as i64 + 999) / 1000 + 1
    }

    /// What the pulses of one tick can follow on `axis`, nm: one pulse is
    /// kept back for rounding.
    fn step_budget_nm(&self, axis: usize) -> i64 {
        (self.max_steps_per_tick as i64 - 1) * self.axes[axis].pulse_nm as i64
    }

    /// True when `axis` needs a reference before the board corrects: it
    /// has an encoder (`pm_per_count != 0`). Every such axis needs one,
    /// whether or not the active table reads its position: the board does
    /// not analyse which positions a table's terms read, and the state must
    /// not depend on the table (a table switch must never start correcting
    /// from an unreferenced axis).
    pub fn reference_needed(&self, axis: usize) -> bool {
        self.axes[axis].pm_per_count != 0
    }

    /// Slew limit actually applied for a table's `slew_nm_per_ms`: the
    /// table's, reduced if the pulse budget of an axis cannot follow it.
    fn effective_slew(&self, table_slew_nm_per_ms: i32) -> i32 {
        let mut s = table_slew_nm_per_ms.max(0);
        for axis in 0..3 {
            while s > 0 && self.max_step_nm_per_tick(s) > self.step_budget_nm(axis) {
                // Scale down rather than step by one: converges in a few
                // iterations for any budget. In i64: `s * 7` overflows i32
                // for any table slew above 306 783 378 nm/ms, which a valid
                // table may carry (issue 14).
                s = (i64::from(s) * 7 / 8) as i32;
            }
        }
        s
    }
}

/// How long no axis may have moved for the axes to count as at rest, µs:
/// referencing over the link and injection need it.
pub const STILL_US: u64 = 20_000;

/// Motion is a displacement of more than this from where an axis last
/// stood, nm: a servo holding position dithers by a count or two, which is
/// no motion (else an axis at rest under servo control could never be
/// referenced, injected or committed on). Smaller than anything a machine
/// is compensated for.
pub const STILL_BAND_NM: i64 = 1000;

/// Where an announced stall is ([`Engine::begin_stall`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stall {
    None,
    /// Between `begin_stall` and `end_stall`.
    Open,
    /// Ended: the next tick is still part of it (on the board the first
    /// tick after an erase may run before the link task ends the stall,
    /// in a simulation after).
    Closing,
}

/// What a tick did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickReport {
    /// Pulses emitted per axis this tick.
    pub steps: [i32; 3],
    /// Faults active after the tick.
    pub faults: Faults,
}

/// The correction engine. Holds the active model by reference to a
/// RAM buffer (the correction never reads flash, which matters while a
/// commit erases it; see `model` for why it is a reference).
#[derive(Debug)]
pub struct Engine<'m> {
    cfg: EngineConfig,
    /// Per axis: an encoder step of at least this many counts in one tick is
    /// a jump: twice the distance at full speed in one period, as margin for
    /// a late tick ([`jump_threshold_counts`]), held at `u32::MAX`: a
    /// step is at most 2^31 counts, so the held threshold (never reached)
    /// decides as the u64 one does, in a 32-bit compare.
    jump_threshold_counts: [u32; 3],
    /// The plausible temperature range as (minimum, span): t is inside
    /// when `(t − min) as u32 ≤ span` (one compare per channel); `None`
    /// when the range is empty (every reading is out of it).
    temp_window: Option<(i32, u32)>,
    /// Per axis: the scale in whole nm per count, when it is one.
    nm_per_count: [Option<i64>; 3],
    /// The same when it also fits i32: the tick's positions in 32 bits
    /// ([`positions_i32`]).
    nm_per_count_i32: [Option<i32>; 3],
    slew_nm_per_ms: i32,
    model: Option<&'m mut ModelBuf>,
    active: Option<SlotInfo>,
    dirs: model::DirTrackers,
    inject: Option<Injection>,
    /// Ticks the injection still runs without a renewal.
    inject_ticks_left: u32,
    /// Per axis: added to the unreferenced position (counts · scale +
    /// configured origin) once referenced, nm.
    ref_offset_nm: [i64; 3],
    /// `ref_offset_nm` when it fits i32 (set with it).
    ref_offset_i32: [Option<i32>; 3],
    /// Bit per axis: referenced since reset, and not lost since. (Bit
    /// masks, so that a tick with nothing to do checks one byte.)
    referenced: u8,
    /// Bit per axis: the axis needs a reference (it has an encoder).
    needs_ref: u8,
    /// Per axis: a reference asked for, applied at the next tick with the
    /// counts that tick reads.
    pending_ref: [Option<i32>; 3],
    /// Some `pending_ref` is set.
    ref_pending: bool,
    /// Bit per axis: the axis has a home switch.
    home_mask: u8,
    /// The home switches as the engine believes them (debounced; `None`
    /// before the first tick: an axis already on its switch at power-up
    /// is not referenced by it — only the switch turning on marks the
    /// position).
    home_stable: Option<u8>,
    /// Per axis: ticks in a row the switch input has differed from
    /// `home_stable`; and a bit per axis where that is not 0.
    home_run: [u8; 3],
    home_busy: u8,
    /// Per axis: the count and the direction of motion at the first tick
    /// of that run (where a confirmed edge is).
    home_edge: [(i32, i8); 3],
    /// Per axis: the last non-zero change of the count (its sign is the
    /// direction the axis last moved; 0 before any).
    last_move: [i32; 3],
    /// Per axis: the longest gap between two ticks over which the counter
    /// widening is proven right at the axis's top speed, µs (`u64::MAX`:
    /// the count is read whole, or there is no encoder); and the shortest
    /// of the three, so that a tick checks one number.
    safe_gap_us: [u64; 3],
    min_safe_gap_us: u64,
    /// A stall announced by [`begin_stall`](Self::begin_stall): its gap is
    /// no overrun (but is checked for motion like any gap).
    stall: Stall,

    last_counts: Option<[i32; 3]>,
    pos_nm: [i32; 3],
    rev_q30: [i32; 3],
    temp_mc: [i32; LINK_TEMPS],
    model_corr_nm: [i32; 3],
    model_flags: u16,
    /// Output correction, milli-nm (exact slew arithmetic: nm/ms × µs).
    out_mnm: [i64; 3],
    /// Net pulses emitted per axis (|steps| ≤ 2^22, see [`slew_axis`]).
    steps: [i32; 3],

    live: Faults,
    sticky: Faults,
    latched: Faults,

    last_tick_us: Option<u64>,
    /// The previous tick ended past the next deadline and was counted as
    /// an overrun: the gap it leaves is not counted a second time.
    late_end: bool,
    last_motion_us: Option<u64>,
    /// Per axis: the counts where the axes last stood (motion is leaving
    /// the band around them); `None` before the first tick.
    still_anchor: Option<[i32; 3]>,
    /// Per axis: the still band in counts (`u32::MAX`: no encoder).
    still_band_counts: [u32; 3],
    now_us: u64,
    ticks: u64,
    worst_loop_us: u32,
    worst_tick_us: u32,
    overruns: u32,
}

impl<'m> Engine<'m> {
    /// An engine without a table (it outputs zero and reports `NO_TABLE`).
    pub fn new(cfg: EngineConfig) -> Result<Self, ConfigError> {
        cfg.check()?;
        let jump_threshold_pm = cfg.axes.map(|a| {
            if a.max_speed_nm_per_ms <= 0 {
                return i64::MAX;
            }
            let max_nm = 2 * a.max_speed_nm_per_ms as i64 * cfg.period_us as i64 / 1000;
            (max_nm.max(1) + 1) * 1000
        });
        let jump_threshold_counts: [u32; 3] = core::array::from_fn(|i| {
            jump_threshold_counts(jump_threshold_pm[i], cfg.axes[i].pm_per_count)
                .min(u32::MAX as u64) as u32
        });
        let nm_per_count = cfg
            .axes
            .map(|a| (a.pm_per_count % 1000 == 0).then_some(a.pm_per_count / 1000));
        let safe_gap_us = cfg.axes.map(safe_gap_us);
        Ok(Self {
            cfg,
            jump_threshold_counts,
            temp_window: (cfg.temp_max_mc >= cfg.temp_min_mc).then(|| {
                (
                    cfg.temp_min_mc,
                    cfg.temp_max_mc.wrapping_sub(cfg.temp_min_mc) as u32,
                )
            }),
            nm_per_count,
            nm_per_count_i32: nm_per_count.map(|k| k.and_then(|k| i32::try_from(k).ok())),
            slew_nm_per_ms: 0,
            model: None,
            active: None,
            dirs: model::DirTrackers::default(),
            inject: None,
            inject_ticks_left: 0,
            ref_offset_nm: [0; 3],
            ref_offset_i32: [Some(0); 3],
            referenced: 0,
            needs_ref: (0..3)
                .filter(|&a| cfg.reference_needed(a))
                .fold(0, |m, a| m | 1 << a),
            pending_ref: [None; 3],
            ref_pending: false,
            home_mask: (0..3)
                .filter(|&a| cfg.axes[a].home.is_some())
                .fold(0, |m, a| m | 1 << a),
            home_stable: None,
            home_run: [0; 3],
            home_busy: 0,
            home_edge: [(0, 0); 3],
            last_move: [0; 3],
            safe_gap_us,
            min_safe_gap_us: safe_gap_us.into_iter().min().unwrap_or(u64::MAX),
            stall: Stall::None,
            last_counts: None,
            pos_nm: [0; 3],
            rev_q30: [0; 3],
            temp_mc: [0; LINK_TEMPS],
            model_corr_nm: [0; 3],
            model_flags: 0,
            out_mnm: [0; 3],
            steps: [0; 3],
            live: Faults::NO_TABLE,
            sticky: Faults::NONE,
            latched: Faults::NO_TABLE,
            last_tick_us: None,
            late_end: false,
            last_motion_us: None,
            still_anchor: None,
            still_band_counts: cfg.axes.map(|a| {
                if a.pm_per_count == 0 {
                    u32::MAX
                } else {
                    (STILL_BAND_NM as u64 * 1000 / a.pm_per_count.unsigned_abs())
                        .min(u32::MAX as u64) as u32
                }
            }),
            now_us: 0,
            ticks: 0,
            worst_loop_us: 0,
            worst_tick_us: 0,
            overruns: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &EngineConfig {
        &self.cfg
    }

    /// Switches to `model` (validated and loaded by the caller from the
    /// table in `info`) and hands back the buffer of the previous one. O(1):
    /// a reference swap. The output slews from where it is to the new
    /// model's correction, it does not jump. Clears `BAD_TABLE`.
    /// An empty `model` buffer is the same as [`clear_model`](Self::clear_model).
    pub fn set_model(
        &mut self,
        model: &'m mut ModelBuf,
        info: SlotInfo,
    ) -> Option<&'m mut ModelBuf> {
        let Some(m) = model.get() else {
            let old = self.clear_model(false);
            self.model = Some(model);
            return old;
        };
        self.slew_nm_per_ms = self.cfg.effective_slew(model::slew_nm_per_ms(m));
        // The reversal state is the machine's, not the table's: kept, with
        // the new table's transition lengths from now on.
        self.dirs.set_transitions(m);
        self.active = Some(info);
        self.sticky = Faults(self.sticky.0 & !Faults::BAD_TABLE.0);
        self.model.replace(model)
    }

    /// Drops the model (the output ramps to zero) and hands its buffer
    /// back; `bad` also raises `BAD_TABLE` (the stored table could not be
    /// loaded).
    pub fn clear_model(&mut self, bad: bool) -> Option<&'m mut ModelBuf> {
        self.active = None;
        if bad {
            self.sticky = self.sticky.union(Faults::BAD_TABLE);
            self.latched = self.latched.union(Faults::BAD_TABLE);
        }
        self.model.take()
    }

    /// The table the correction runs on.
    pub fn active(&self) -> Option<SlotInfo> {
        self.active
    }

    /// The slew limit in force, nm/ms (the table's, possibly reduced to
    /// what the pulse budget can follow).
    pub fn slew_nm_per_ms(&self) -> i32 {
        self.slew_nm_per_ms
    }

    /// Replaces the sensor readings by `inj` for the next `lease_ticks`
    /// ticks (or goes back to the sensors with `None`). The injection ends
    /// earlier if an encoder moves. The caller checks that the axes are at
    /// rest ([`is_still`](Self::is_still)).
    pub fn set_injection(&mut self, inj: Option<Injection>, lease_ticks: u32) {
        self.inject = inj;
        self.inject_ticks_left = if inj.is_some() { lease_ticks } else { 0 };
    }

    /// True while injected inputs replace the sensors.
    pub fn injecting(&self) -> bool {
        self.inject.is_some()
    }

    /// References `axis`: the encoder count read at the next tick is
    /// machine position `pos_nm` (the caller checks that the axes are at
    /// rest). False for an axis index above 2.
    pub fn reference(&mut self, axis: usize, pos_nm: i32) -> bool {
        match self.pending_ref.get_mut(axis) {
            Some(p) => {
                *p = Some(pos_nm);
                self.ref_pending = true;
                true
            }
            None => false,
        }
    }

    /// Per axis: referenced (since reset, and not lost since).
    pub fn referenced(&self) -> [bool; 3] {
        core::array::from_fn(|a| self.referenced & 1 << a != 0)
    }

    /// True when no axis has moved (left its [`STILL_BAND_NM`] band) for
    /// [`STILL_US`] at
    /// `now_us` (or never moved).
    pub fn is_still(&self, now_us: u64) -> bool {
        self.quiet_for_us(now_us) >= STILL_US
    }

    /// Clears the sticky and latched faults; live conditions come back at
    /// the next tick if their cause is still there.
    pub fn clear_faults(&mut self) {
        self.sticky = Faults::NONE;
        self.latched = self.live;
    }

    /// Latches `f` (shown in `faults_latched` until `ClearFaults`) without
    /// making it active: how the boot reports a fallback
    /// ([`Faults::TRIAL_FAILED`], crate::boot) while the correction runs.
    pub fn latch(&mut self, f: Faults) {
        self.latched = self.latched.union(f);
    }

    /// Faults active now.
    pub fn faults(&self) -> Faults {
        self.live.union(self.sticky)
    }

    /// How long the axes have stood still (no axis left its
    /// [`STILL_BAND_NM`] band) at
    /// `now_us`, µs; `u64::MAX` if they never moved since boot.
    pub fn quiet_for_us(&self, now_us: u64) -> u64 {
        match self.last_motion_us {
            None => u64::MAX,
            Some(t) => now_us.saturating_sub(t),
        }
    }

    /// Announces a stall the board causes on purpose (a flash erase or
    /// program, which stops every instruction fetch on the single-bank
    /// F405; allowed only while the axes stand still): until
    /// [`end_stall`](Self::end_stall) and for one tick after it, a gap
    /// between ticks is not a loop overrun. It is still checked like any
    /// gap: an axis that moved more than its counter's widening can follow
    /// loses its reference ([`Faults::POSITION_LOST`]).
    pub fn begin_stall(&mut self) {
        self.stall = Stall::Open;
    }

    /// Ends the stall [`begin_stall`](Self::begin_stall) announced (the
    /// next tick is still part of it).
    pub fn end_stall(&mut self) {
        if self.stall == Stall::Open {
            self.stall = Stall::Closing;
        }
    }

    /// The model's correction for `inj`, evaluated now (no slew limit), and
    /// the output as it is.
    pub fn evaluate_injection(&self, inj: &Injection) -> Correction {
        let (model_corr_nm, model_flags) = match self.model.as_deref().and_then(ModelBuf::get) {
            Some(m) => {
                let r = model::evaluate(m, &inputs_of(inj));
                (r.corr_nm, r.flags)
            }
            None => ([0; 3], 0),
        };
        Correction {
            pos_nm: inj.pos_nm,
            model_corr_nm,
            corr_nm: self.corr_nm(),
            model_flags,
            faults: self.faults(),
        }
    }

    /// The output correction now, nm.
    pub fn corr_nm(&self) -> [i32; 3] {
        self.out_mnm.map(round_mnm)
    }

    /// What [`Request::ReadCorrection`](trueaxis_protocol::Request) answers.
    pub fn correction(&self) -> Correction {
        Correction {
            pos_nm: self.pos_nm,
            model_corr_nm: self.model_corr_nm,
            corr_nm: self.corr_nm(),
            model_flags: self.model_flags,
            faults: self.faults(),
        }
    }

    /// Net pulses emitted per axis since boot.
    pub fn steps(&self) -> [i64; 3] {
        self.steps.map(i64::from)
    }

    /// Telemetry (the link server adds its own counters).
    pub fn telemetry(&self) -> Telemetry {
        Telemetry {
            uptime_us: self.now_us,
            ticks: self.ticks,
            period_us: self.cfg.period_us,
            worst_loop_us: self.worst_loop_us,
            worst_tick_us: self.worst_tick_us,
            overruns: self.overruns,
            pos_nm: self.pos_nm,
            temp_mc: self.temp_mc,
            model_corr_nm: self.model_corr_nm,
            corr_nm: self.corr_nm(),
            steps: self.steps(),
            model_flags: self.model_flags,
            faults: self.faults(),
            faults_latched: self.latched,
            injecting: self.inject.is_some(),
            referenced: self.referenced(),
            reference_needed: core::array::from_fn(|a| self.needs_ref & 1 << a != 0),
            active: self.active,
            rx_bad_frames: 0,
        }
    }

    /// The unreferenced position of `axis` at `count`, nm (i64, exact).
    fn raw_nm(&self, axis: usize, count: i32) -> i64 {
        let a = &self.cfg.axes[axis];
        raw_position_nm(count, a.pm_per_count, self.nm_per_count[axis], a.origin_nm)
    }

    /// A gap of `gap_us` between two ticks longer than some axis's counter
    /// widening can follow at its top speed (a stall): every such axis
    /// that moved (left the still band) between `prev` and `counts` lost
    /// its position — `POSITION_LOST`. Returns those axes.
    #[inline(never)]
    fn stalled(&self, gap_us: u64, counts: &[i32; 3], prev: &[i32; 3], events: &mut Faults) -> u8 {
        let mut lost = 0;
        for (i, (c, p)) in counts.iter().zip(prev).enumerate() {
            let d = c.wrapping_sub(*p).unsigned_abs();
            if gap_us > self.safe_gap_us[i] && d > self.still_band_counts[i] {
                *events = events.union(Faults::POSITION_LOST);
                lost |= 1 << i;
            }
        }
        lost
    }

    /// Makes `count` on `axis` the machine position `pos_nm`.
    fn set_reference(&mut self, axis: usize, count: i32, pos_nm: i32) {
        self.ref_offset_nm[axis] = pos_nm as i64 - self.raw_nm(axis, count);
        self.ref_offset_i32[axis] = i32::try_from(self.ref_offset_nm[axis]).ok();
        self.referenced |= 1 << axis;
    }

    /// The home switch inputs `raw` of one tick (bits of axes with a
    /// switch), at `counts`: debounced (a change believed after
    /// `debounce_ticks` ticks in a row, dated at the first of them); a
    /// switch turning on while the axis moves in its approach direction
    /// references an axis without a reference at the switch's position
    /// (at the count of that first tick), and checks one with a reference
    /// — farther than the tolerance from the switch is `HOME_MISMATCH`.
    /// Returns the axes whose reference that loses.
    #[inline(never)]
    fn home_switches(&mut self, raw: u8, counts: &[i32; 3], events: &mut Faults) -> u8 {
        let stable = *self.home_stable.get_or_insert(raw);
        let mut lost = 0;
        for (i, &count_now) in counts.iter().enumerate() {
            let bit = 1u8 << i;
            let Some(h) = self.cfg.axes[i].home else {
                continue;
            };
            if (raw ^ stable) & bit == 0 {
                self.home_run[i] = 0;
                self.home_busy &= !bit;
                continue;
            }
            if self.home_run[i] == 0 {
                self.home_edge[i] = (count_now, self.last_move[i].signum() as i8);
            }
            self.home_run[i] = self.home_run[i].saturating_add(1);
            self.home_busy |= bit;
            if self.home_run[i] < h.debounce_ticks {
                continue;
            }
            self.home_run[i] = 0;
            self.home_busy &= !bit;
            self.home_stable = Some(self.home_stable.unwrap_or(stable) ^ bit);
            let (count, dir) = self.home_edge[i];
            if raw & bit == 0 || dir != h.approach.sign() {
                // Off the switch, or on it from the other side (or with
                // no motion seen): no edge that marks the position.
                continue;
            }
            if self.referenced & bit == 0 {
                self.set_reference(i, count, h.pos_nm);
            } else {
                let at = self.raw_nm(i, count) + self.ref_offset_nm[i];
                if (at - h.pos_nm as i64).abs() > h.tolerance_nm as i64 {
                    *events = events.union(Faults::HOME_MISMATCH);
                    lost |= bit;
                }
            }
        }
        lost
    }

    /// One period of the correction loop.
    pub fn tick<C, E, T, S>(
        &mut self,
        clock: &C,
        enc: &mut E,
        temps: &mut T,
        out: &mut S,
    ) -> TickReport
    where
        C: Clock,
        E: Encoders,
        T: TemperatureSource,
        S: StepOutput,
    {
        let start_us = clock.now_us();
        self.now_us = start_us;
        let mut events = Faults::NONE;

        // Timing: the gap since the previous tick. Missing a whole period
        // (gap ≥ 2 periods) is an overrun; jitter below that is not. (A gap
        // left by a tick that already counted itself as late is not
        // counted again; see the end of the tick.)
        // (A gap in an announced stall is not an overrun, see begin_stall.)
        let gap = self.last_tick_us.map(|prev| start_us.saturating_sub(prev));
        if let Some(gap) = gap {
            self.worst_loop_us = self.worst_loop_us.max(gap.min(u32::MAX as u64) as u32);
            if gap >= 2 * self.cfg.period_us as u64 && !self.late_end && self.stall == Stall::None {
                self.overruns = self.overruns.saturating_add(1);
                events = events.union(Faults::LOOP_OVERRUN);
            }
        }
        if self.stall == Stall::Closing {
            self.stall = Stall::None;
        }
        self.last_tick_us = Some(start_us);
        self.late_end = false;
        self.ticks += 1;

        // Sensors (always read, so a stuck sensor shows in telemetry even
        // while injecting).
        let counts = enc.read_counts();
        let temps_mc = temps.read_temps_mc();
        let mut live = Faults::NONE;
        // Motion: an axis left the still band around where it last stood.
        let anchor = *self.still_anchor.get_or_insert(counts);
        let moved = (0..3)
            .any(|i| counts[i].wrapping_sub(anchor[i]).unsigned_abs() > self.still_band_counts[i]);
        if moved {
            self.still_anchor = Some(counts);
            self.last_motion_us = Some(start_us);
        }
        // Per axis, against the previous tick's counts: the direction of
        // motion, an encoder jump (counts lost or invented: the reference
        // is gone), and motion across a gap longer than the counter's
        // widening can follow (a stall: the count may be off by whole
        // counter turns — the reference is gone too).
        let mut lost = 0u8;
        if let Some(prev) = self.last_counts {
            for i in 0..3 {
                let d = counts[i].wrapping_sub(prev[i]);
                if d != 0 {
                    self.last_move[i] = d;
                }
                // |Δcounts| · |pm/count| ≥ threshold ⇔ the jump exceeds
                // the limit in whole nm, ⇔ |Δcounts| ≥ the threshold in
                // counts (precomputed: no 64-bit multiply per tick).
                if d.unsigned_abs() >= self.jump_threshold_counts[i] {
                    events = events.union(Faults::ENCODER_JUMP);
                    lost |= 1 << i;
                }
            }
            if let Some(g) = gap.filter(|&g| g > self.min_safe_gap_us) {
                lost |= self.stalled(g, &counts, &prev, &mut events);
            }
        }
        self.last_counts = Some(counts);
        // The home switches (debounced; an edge references an axis that
        // has no reference, and checks one that has).
        // (Out of line only when a switch changed or is being debounced.)
        let home = enc.home_switches() & self.home_mask;
        if self.home_mask != 0 && (self.home_stable != Some(home) || self.home_busy != 0) {
            lost |= self.home_switches(home, &counts, &mut events);
        }
        // Unreferenced positions: counts · scale + the configured origin.
        // A reference asked for since the last tick: the counts read now
        // are the position it names.
        if self.ref_pending {
            self.ref_pending = false;
            for (i, &count) in counts.iter().enumerate() {
                if let Some(pos) = self.pending_ref[i].take() {
                    self.set_reference(i, count, pos);
                }
            }
        }
        self.referenced &= !lost;
        // Per axis (unreferenced, referenced) position, each held to i32:
        // in 32 bits when every step fits (the usual case), else in i64.
        let both: [(i32, i32); 3] = core::array::from_fn(|i| {
            match positions_i32(
                counts[i],
                self.nm_per_count_i32[i],
                self.cfg.axes[i].origin_nm,
                self.ref_offset_i32[i],
            ) {
                Some(p) => p,
                None => positions_i64(self.raw_nm(i, counts[i]), self.ref_offset_nm[i]),
            }
        });
        let enc_pos_nm: [i32; 3] = both.map(|p| p.1);
        // The direction trackers see only differences, so they follow the
        // unreferenced position: a reference shifts the position but is no
        // motion, and keeps the reversal state.
        let rev_q30 = self.dirs.update(both.map(|p| p.0));
        if self.needs_ref & !self.referenced != 0 {
            live = live.union(Faults::NOT_REFERENCED);
        }
        // The real temperatures are checked whether or not an injection
        // replaces them: a sensor fault is a fault in test mode too.
        let out_of_range = |t: &[i32]| match self.temp_window {
            Some((lo, span)) => t.iter().any(|&t| t.wrapping_sub(lo) as u32 > span),
            None => !t.is_empty(),
        };
        if out_of_range(&temps_mc[..self.cfg.temps_used]) {
            live = live.union(Faults::SENSOR_RANGE);
        }
        // The injection's lease: it ends when it runs out or when an axis
        // moves (the injected position is no longer where the machine is).
        if self.inject.is_some() {
            if moved || self.inject_ticks_left == 0 {
                self.inject = None;
            } else {
                self.inject_ticks_left -= 1;
            }
        }

        let inputs = match &self.inject {
            Some(inj) => {
                if out_of_range(&inj.temp_mc[..self.cfg.temps_used]) {
                    live = live.union(Faults::SENSOR_RANGE);
                }
                self.pos_nm = inj.pos_nm;
                self.rev_q30 = inj.rev_q30;
                self.temp_mc = inj.temp_mc;
                model::inputs(&inputs_of(inj))
            }
            None => {
                self.pos_nm = enc_pos_nm;
                self.temp_mc = temps_mc;
                self.rev_q30 = rev_q30;
                model::sensor_inputs(enc_pos_nm, rev_q30, &temps_mc, self.cfg.tool_nm)
            }
        };

        // The model.
        match self.model.as_deref().and_then(ModelBuf::get) {
            Some(m) => {
                let r = model::evaluate_inputs(m, &inputs);
                self.model_flags = r.flags;
                if r.not_finite {
                    events = events.union(Faults::NOT_FINITE);
                    self.model_corr_nm = [0; 3];
                } else {
                    self.model_corr_nm = r.corr_nm;
                }
            }
            None => {
                live = live.union(Faults::NO_TABLE);
                self.model_flags = 0;
                self.model_corr_nm = [0; 3];
            }
        }

        self.live = live;
        self.sticky = self.sticky.union(events);
        self.latched = self.latched.union(live).union(events);
        let faults = self.faults();

        // Slew-limited output: towards the model, or to zero on a fault.
        let (target_nm, rate) = if faults.is_empty() {
            (self.model_corr_nm, self.slew_nm_per_ms)
        } else {
            ([0; 3], self.cfg.fault_ramp_nm_per_ms)
        };
        let max_d_mnm = rate as i64 * self.cfg.period_us as i64;
        let mut report = TickReport {
            steps: [0; 3],
            faults,
        };
        for (axis, &target) in target_nm.iter().enumerate() {
            let n = slew_axis(
                &mut self.out_mnm[axis],
                &mut self.steps[axis],
                target,
                max_d_mnm,
                self.cfg.axes[axis].pulse_nm,
                self.cfg.max_steps_per_tick,
            );
            if n != 0 {
                out.pulses(axis, n);
            }
            report.steps[axis] = n;
        }

        let took = clock.now_us().saturating_sub(start_us);
        self.worst_tick_us = self.worst_tick_us.max(took.min(u32::MAX as u64) as u32);
        // A tick that took longer than a period ended after the next tick
        // was due (it started at or after its own due time): a missed
        // deadline, even when the next tick then starts less than two
        // periods after this one. The fault acts from the next tick on.
        if took > self.cfg.period_us as u64 {
            self.overruns = self.overruns.saturating_add(1);
            self.sticky = self.sticky.union(Faults::LOOP_OVERRUN);
            self.latched = self.latched.union(Faults::LOOP_OVERRUN);
            self.late_end = true;
            report.faults = self.faults();
        }
        report
    }
}

/// The unreferenced position of an axis, nm: counts · scale + origin, in
/// i64 (exact for every i32 count and scale).
#[inline(always)]
fn raw_position_nm(
    count: i32,
    pm_per_count: i64,
    nm_per_count: Option<i64>,
    origin_nm: i32,
) -> i64 {
    // Whole nm per count (the usual scales): a multiply; else the exact
    // 64-bit division (a library call on the M4).
    let scaled = match nm_per_count {
        Some(k) => count as i64 * k,
        None => count as i64 * pm_per_count / 1000,
    };
    scaled + origin_nm as i64
}

/// (unreferenced, referenced) position from the i64 unreferenced one and
/// the reference offset, each held to the i32 range: the definition.
#[inline(always)]
fn positions_i64(raw_nm: i64, ref_offset_nm: i64) -> (i32, i32) {
    let clamp_i32 = |nm: i64| nm.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
    (clamp_i32(raw_nm), clamp_i32(raw_nm + ref_offset_nm))
}

/// [`positions_i64`] in 32-bit arithmetic, for a scale in whole nm per
/// count and a reference offset that fit i32: `None` when a product or a
/// sum leaves the i32 range (the caller then takes the i64 path) — when
/// every step fits, no hold could have changed anything, so the result is
/// the i64 one (test `positions_i32_are_the_i64_positions`).
#[inline(always)]
fn positions_i32(
    count: i32,
    nm_per_count: Option<i32>,
    origin_nm: i32,
    ref_offset_nm: Option<i32>,
) -> Option<(i32, i32)> {
    let raw = count.checked_mul(nm_per_count?)?.checked_add(origin_nm)?;
    Some((raw, raw.checked_add(ref_offset_nm?)?))
}

/// The longest gap between two reads of `a`'s counter over which its
/// widening is proven right, µs: the axis at its top speed moves less than
/// half the counter's range (2^(bits−1) counts) — gap · speed / |scale| <
/// 2^(bits−1). `u64::MAX` for a count read whole (32 bits) or no encoder.
fn safe_gap_us(a: AxisConfig) -> u64 {
    if a.counter_bits >= 32 || a.pm_per_count == 0 || a.max_speed_nm_per_ms <= 0 {
        return u64::MAX;
    }
    let half = 1u64 << (a.counter_bits.max(1) - 1);
    // speed is nm/ms = pm/µs: counts in a gap = gap · speed / |pm|. (A
    // product beyond u64 — a scale of more than 2^33 pm per count — holds
    // at u64::MAX: no gap of a running board is that long.)
    half.saturating_mul(a.pm_per_count.unsigned_abs())
        .saturating_sub(1)
        / a.max_speed_nm_per_ms as u64
}

/// The encoder-jump threshold in counts: the smallest |Δcounts| with
/// |Δcounts| · |pm/count| ≥ `threshold_pm` (the product saturating, as the
/// tick once computed it), i.e. ⌈threshold / |pm/count|⌉, and `u64::MAX`
/// (never) for a zero scale — so the tick compares instead of multiplying
/// in 64 bits.
fn jump_threshold_counts(threshold_pm: i64, pm_per_count: i64) -> u64 {
    let (t, p) = (threshold_pm.max(0) as u64, pm_per_count.unsigned_abs());
    if p == 0 {
        u64::MAX
    } else {
        t.div_ceil(p)
    }
}

/// The largest |target| the output follows, nm: 2^22 − 1, above any
/// table's max |correction| (`model_core::table::MAX_CORR_LIMIT_NM` = 4·10^6, so
/// holding the target here never changes it — one SSAT on the M4). It
/// bounds the output: |out_mnm| ≤ (2^22 − 1)·1000 < 2^32 − 500, and the
/// pulses: |steps| ≤ 2^22.
const TARGET_LIMIT_NM: i32 = (1 << 22) - 1;

/// One axis of the slew-limited output and its pulses: the output
/// `out_mnm` moves towards `target_nm`·1000 by at most `max_d_mnm`, and
/// `steps` (pulses emitted) towards round(round(out / 1000) / pulse) by at
/// most `lim`; returns the pulses to emit. Only the slew step is in i64
/// (the output in mnm reaches ±4.2·10^9); the roundings and the pulses are
/// 32-bit (UDIV) — exactly the i64 arithmetic the tick had before
/// (`slew_axis_is_the_i64_loop`), for `pulse_nm`, `lim` > 0 (checked by
/// `EngineConfig::check`), `max_d_mnm` ≥ 0 (the rates are ≥ 0) and every
/// state the loop reaches.
#[inline(always)]
fn slew_axis(
    out_mnm: &mut i64,
    steps: &mut i32,
    target_nm: i32,
    max_d_mnm: i64,
    pulse_nm: i32,
    lim: i32,
) -> i32 {
    let target = target_nm.clamp(-TARGET_LIMIT_NM - 1, TARGET_LIMIT_NM);
    // max then min: the clamp for 0 ≤ max_d and 0 < lim (the engine's
    // rates and `EngineConfig::check`), without `clamp`'s bounds assertion.
    let d = (target as i64 * 1000 - *out_mnm)
        .max(-max_d_mnm)
        .min(max_d_mnm);
    *out_mnm += d;
    // Pulses: absolute, so they can never drift from the output.
    let corr_nm = round_mnm(*out_mnm);
    let want = round_div_i32(corr_nm, pulse_nm);
    let n = want.wrapping_sub(*steps).max(-lim).min(lim);
    *steps = steps.wrapping_add(n);
    n
}

/// round(out / 1000), halves away from zero, for |out| ≤ 2^32 − 1 − 500
/// (the output's range, [`TARGET_LIMIT_NM`]): one UDIV on the magnitude.
#[inline(always)]
fn round_mnm(out_mnm: i64) -> i32 {
    let q = ((out_mnm.unsigned_abs() as u32).wrapping_add(500) / 1000) as i32;
    if out_mnm < 0 {
        -q
    } else {
        q
    }
}

/// round(a / b), halves away from zero, for b > 0 and |a| + b/2 < 2^32
/// (|a| ≤ 2^22, any positive i32 b): one UDIV on the magnitude.
#[inline(always)]
fn round_div_i32(a: i32, b: i32) -> i32 {
    let q = (a.unsigned_abs().wrapping_add(b as u32 / 2) / b as u32) as i32;
    if a < 0 {
        -q
    } else {
        q
    }
}

fn inputs_of(inj: &Injection) -> ModelInputs {
    ModelInputs {
        pos_nm: inj.pos_nm,
        rev_q30: inj.rev_q30,
        temp_mc: inj.temp_mc,
        tool_nm: inj.tool_nm,
    }
}

/// `a / b` rounded to nearest, halves away from zero (b > 0). The pulse
/// count's definition of "round".
pub fn round_div(a: i64, b: i64) -> i64 {
    let h = b / 2;
    // The tick's case (|a| + b/2 and b within u32: output in mnm ≤ 4·10^9,
    // corrections in nm): the M4's UDIV on the magnitude, the same result
    // as the i64 division below (a library call of ~60–100 instructions).
    let mag = a.unsigned_abs();
    if 0 < b && b <= u32::MAX as i64 && mag + (h as u64) <= u32::MAX as u64 {
        let q = ((mag + h as u64) as u32 / b as u32) as i64;
        return if a >= 0 { q } else { -q };
    }
    if a >= 0 {
        (a + h) / b
    } else {
        (a - h) / b
    }
}

#[cfg(test)]
mod tests {
    use super::{
        jump_threshold_counts, positions_i32, positions_i64, raw_position_nm, round_div,
        round_div_i32, round_mnm, slew_axis, TARGET_LIMIT_NM,
    };

    /// The 32-bit positions equal the i64 ones whenever they are taken, at
    /// the ends of the i32 range and one past (where they must give way:
    /// `None`), and on seeded values; the i64 path is the definition.
    #[test]
    fn positions_i32_are_the_i64_positions() {
        let ends = [
            0,
            1,
            -1,
            i32::MAX,
            i32::MIN,
            i32::MAX - 1,
            i32::MIN + 1,
            1 << 30,
            -(1 << 30),
        ];
        let mut rng = trueaxis_test_support::XorShift64(0x3c6e_f372_fe94_f82bu64);
        let (mut fast, mut slow) = (0u32, 0u32);
        for i in 0..400_000u32 {
            let pick = |r: &mut trueaxis_test_support::XorShift64, k: u32| -> i32 {
                match k % 4 {
                    0 => ends[(r.next_u64() % ends.len() as u64) as usize],
                    1 => r.next_u64() as i32,
                    2 => (r.next_u64() % 200_001) as i32 - 100_000,
                    _ => (r.next_u64() as i32) >> (r.next_u64() % 31),
                }
            };
            let count = pick(&mut rng, i);
            let k = match i % 5 {
                0 => 25,
                1 => -1,
                _ => pick(&mut rng, i / 5),
            };
            let origin = pick(&mut rng, i / 3);
            let off = pick(&mut rng, i / 7);
            let raw = raw_position_nm(count, k as i64 * 1000, Some(k as i64), origin);
            let want = positions_i64(raw, off as i64);
            match positions_i32(count, Some(k), origin, Some(off)) {
                Some(got) => {
                    fast += 1;
                    assert_eq!(got, want, "count {count} k {k} origin {origin} off {off}");
                }
                None => {
                    slow += 1;
                    // It gives way only when some step leaves i32.
                    let p = count as i64 * k as i64;
                    let r = p + origin as i64;
                    assert!(
                        [p, r, r + off as i64]
                            .iter()
                            .any(|&v| i32::try_from(v).is_err()),
                        "count {count} k {k} origin {origin} off {off}"
                    );
                }
            }
        }
        assert!(fast > 100_000 && slow > 10_000, "{fast} {slow}");
        // At the limit and one past.
        assert_eq!(
            positions_i32(i32::MAX, Some(1), 0, Some(0)),
            Some((i32::MAX, i32::MAX))
        );
        assert_eq!(positions_i32(i32::MAX, Some(1), 1, Some(0)), None);
        assert_eq!(positions_i32(i32::MAX, Some(1), 0, Some(1)), None);
        assert_eq!(positions_i32(i32::MIN, Some(-1), 0, Some(0)), None);
        assert_eq!(positions_i32(1, None, 0, Some(0)), None);
        assert_eq!(positions_i32(1, Some(1), 0, None), None);
        assert_eq!(positions_i64(i32::MAX as i64 + 1, -1), (i32::MAX, i32::MAX));
    }

    #[test]
    fn jump_threshold_in_counts_is_the_saturating_product_test() {
        let mut rng = trueaxis_test_support::XorShift64(0x9e37_79b9_7f4a_7c15u64);
        let mut next = || rng.next_u64();
        for i in 0..100_000 {
            let t = match i % 3 {
                0 => i64::MAX,
                _ => (next() % 10_000_000_000) as i64,
            };
            let p = match i % 5 {
                0 => 0,
                1 => -((next() % 100_000) as i64),
                _ => (next() % 100_000) as i64,
            };
            let k = jump_threshold_counts(t, p);
            // The engine holds k at u32::MAX: the same decision for every
            // step a tick can see (|Δcounts| ≤ 2^31).
            let held = k.min(u32::MAX as u64) as u32;
            for d in [0u32, 1 << 31, held.saturating_sub(1), held.min(1 << 31)] {
                assert_eq!(d as u64 >= k, d >= held, "d {d} k {k}");
            }
            let d = next() as u32 as i64;
            for d in [
                d,
                k.min(u32::MAX as u64) as i64,
                (k.min(u32::MAX as u64) as i64 - 1).max(0),
            ] {
                assert_eq!(
                    d.saturating_mul(p.abs()) >= t,
                    d as u64 >= k,
                    "d {d} p {p} t {t}"
                );
            }
        }
    }

    /// The i64 definition `round_div` had before its u32 fast path.
    fn reference(a: i64, b: i64) -> i64 {
        let h = b / 2;
        if a >= 0 {
            (a + h) / b
        } else {
            (a - h) / b
        }
    }

    #[test]
    fn round_div_fast_path_is_the_i64_division() {
        let mut rng = trueaxis_test_support::XorShift64(0x2545_f491_4f6c_dd1du64);
        let mut next = || rng.next_u64();
        let edges = [
            0,
            1,
            499,
            500,
            501,
            4_000_000_000,
            u32::MAX as i64 - 500,
            u32::MAX as i64 - 499,
            u32::MAX as i64,
            1 << 40,
        ];
        for b in [1i64, 2, 3, 100, 1000, 1001, u32::MAX as i64, 1 << 33] {
            for &e in &edges {
                for a in [e, -e, e + 1, -e - 1] {
                    assert_eq!(round_div(a, b), reference(a, b), "{a} / {b}");
                }
            }
        }
        for i in 0..100_000 {
            let a = (next() as i64) >> (i % 40);
            let b = (next() % 5000) as i64 + 1;
            assert_eq!(round_div(a, b), reference(a, b), "{a} / {b}");
        }
    }

    /// The slew/pulse step of one axis as the tick computed it in i64
    /// before [`slew_axis`] (the output, the pulses and the pulses to emit).
    fn reference_step(
        out_mnm: &mut i64,
        steps: &mut i64,
        target: i32,
        max_d_mnm: i64,
        pulse_nm: i32,
        lim: i32,
    ) -> i32 {
        let d = (target as i64 * 1000 - *out_mnm).clamp(-max_d_mnm, max_d_mnm);
        *out_mnm += d;
        let corr_nm = round_div(*out_mnm, 1000);
        let want = round_div(corr_nm, pulse_nm as i64);
        let n = (want - *steps).clamp(-(lim as i64), lim as i64) as i32;
        *steps += n as i64;
        n
    }

    /// The i32 slew/pulse step gives the i64 loop's output, pulses and
    /// emitted counts on every tick: seeded runs of targets up to the
    /// tables' limit (±`MAX_CORR_LIMIT_NM`, and up to the hold at
    /// ±2^22), jumps between the extremes, pulses from 1 nm to
    /// `i32::MAX`, per-tick limits from 1 to `i32::MAX` and slews from
    /// 1 mnm to beyond any distance (`i64::MAX`).
    #[test]
    fn slew_axis_is_the_i64_loop() {
        let max_corr = model_core::table::MAX_CORR_LIMIT_NM;
        assert!(
            max_corr <= TARGET_LIMIT_NM,
            "the hold must never change a target"
        );
        let mut rng = trueaxis_test_support::XorShift64(0x0dd_ba11_cafe_f00du64);
        let mut next = || rng.next_u64();
        let mut emitted_lim = 0;
        for run in 0..3_000 {
            let pulse_nm = match run % 4 {
                0 => 1,
                1 => i32::MAX,
                _ => (next() % 5_000) as i32 + 1,
            };
            let lim = match run % 5 {
                0 => 1,
                1 => i32::MAX,
                _ => (next() % 50) as i32 + 1,
            };
            let max_d = match run % 6 {
                0 => 1,
                1 => i64::MAX,
                2 => 2 * (TARGET_LIMIT_NM as i64 + 1) * 1000,
                _ => (next() % 10_000_000) as i64 + 1,
            };
            let (mut out, mut steps) = (0i64, 0i32);
            let (mut out_ref, mut steps_ref) = (0i64, 0i64);
            for tick in 0..300 {
                let target = match (next() % 8, tick % 40) {
                    (_, 0) => [max_corr, -max_corr, TARGET_LIMIT_NM, -TARGET_LIMIT_NM - 1]
                        [(next() % 4) as usize],
                    (0, _) => 0,
                    (1, _) => max_corr,
                    (2, _) => -max_corr,
                    _ => (next() % (2 * max_corr as u64 + 1)) as i32 - max_corr,
                };
                let n = slew_axis(&mut out, &mut steps, target, max_d, pulse_nm, lim);
                let n_ref =
                    reference_step(&mut out_ref, &mut steps_ref, target, max_d, pulse_nm, lim);
                assert_eq!(
                    (n, out, steps as i64),
                    (n_ref, out_ref, steps_ref),
                    "run {run} tick {tick} target {target} max_d {max_d} pulse {pulse_nm} lim {lim}"
                );
                emitted_lim += (n.abs() == lim) as u32;
            }
        }
        assert!(
            emitted_lim > 10_000,
            "the pulse limit bound {emitted_lim} times"
        );
        // One past the hold the target is held (the i64 loop would follow it).
        let (mut out, mut steps) = (0i64, 0i32);
        slew_axis(
            &mut out,
            &mut steps,
            TARGET_LIMIT_NM + 1,
            i64::MAX,
            1,
            i32::MAX,
        );
        assert_eq!(
            (out, steps),
            (TARGET_LIMIT_NM as i64 * 1000, TARGET_LIMIT_NM)
        );
        slew_axis(&mut out, &mut steps, i32::MIN, i64::MAX, 1, i32::MAX);
        assert_eq!(
            (out, steps),
            (-(TARGET_LIMIT_NM as i64 + 1) * 1000, -TARGET_LIMIT_NM - 1)
        );
    }

    /// The 32-bit roundings against `round_div` at the ends of their
    /// ranges and one past: `round_mnm` up to |out| = 2^32 − 1 − 500 (the
    /// output reaches 2^22·1000), `round_div_i32` for |a| ≤ 2^22 and every
    /// positive i32 divisor.
    #[test]
    fn round_mnm_and_round_div_i32_are_round_div_within_their_ranges() {
        let top = u32::MAX as i64 - 500;
        for e in [
            0i64,
            1,
            499,
            500,
            501,
            999,
            1000,
            1500,
            4_194_304_000,
            top - 1,
            top,
        ] {
            for a in [e, -e] {
                assert_eq!(round_mnm(a) as i64, round_div(a, 1000), "{a}");
            }
        }
        // One past the range the u32 sum wraps: outside the contract.
        assert_ne!(round_mnm(top + 1) as i64, round_div(top + 1, 1000));
        let mut rng = trueaxis_test_support::XorShift64(0x5eed_1234_5678_9abcu64);
        let mut next = || rng.next_u64();
        for i in 0..200_000 {
            let a = (next() % (2 * top as u64 + 1)) as i64 - top;
            let a = a >> (i % 33);
            assert_eq!(round_mnm(a) as i64, round_div(a, 1000), "{a}");
        }
        let lim = 1i32 << 22;
        for b in [
            1,
            2,
            3,
            999,
            1000,
            1001,
            lim - 1,
            lim,
            i32::MAX - 1,
            i32::MAX,
        ] {
            for a in [
                0,
                1,
                -1,
                b / 2,
                -(b / 2),
                b / 2 + 1,
                lim - 1,
                lim,
                -lim,
                1 - lim,
            ] {
                assert_eq!(
                    round_div_i32(a, b) as i64,
                    round_div(a as i64, b as i64),
                    "{a} / {b}"
                );
            }
        }
        for i in 0..200_000 {
            let a = (next() % (2 * lim as u64 + 1)) as i32 - lim;
            let b = match i % 3 {
                0 => (next() % 10_000) as i32 + 1,
                _ => (next() % i32::MAX as u64) as i32 + 1,
            };
            assert_eq!(
                round_div_i32(a, b) as i64,
                round_div(a as i64, b as i64),
                "{a} / {b}"
            );
        }
    }
}
