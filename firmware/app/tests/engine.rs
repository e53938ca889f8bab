//! The correction engine with fake encoders, thermistors, step output and
//! clock: pulses never drift from the correction over a simulated hour,
//! the output follows model-core's fixed-point evaluation, the slew limit
//! holds, every fault ramps the output to zero and is reported.

mod common;

use std::cell::Cell;

use model_core::{DirTracker, Inputs, Model};
use trueaxis_app::engine::{round_div, Approach, ConfigError, Engine, EngineConfig, HomeSwitch};
use trueaxis_app::hw::Clock;
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_app::sim::{sample_spec, sample_table, sim_engine_config};
use trueaxis_protocol::{Faults, Injection, Slot, SlotInfo, LINK_TEMPS};
// Deterministic xorshift, so the random walk is the same on every run.
use trueaxis_test_support::XorShift64 as Rng;

use common::fake::{reference_at_zero, Fake, FakeClock};

fn info(table: &[u8]) -> SlotInfo {
    SlotInfo {
        slot: Slot::A,
        seq: 1,
        len: table.len() as u32,
        crc32: trueaxis_protocol::table_id(table),
    }
}

fn loaded(table: &[u8]) -> &'static mut ModelBuf {
    let m: &'static mut ModelBuf = Box::leak(Box::default());
    load_into(table, m).unwrap();
    m
}

/// The simulated engine with `table` loaded — referenced at zero first
/// when `referenced` — its clock at 0 and its I/O at rest.
fn rig(table: &[u8], referenced: bool) -> (Engine<'static>, FakeClock, Fake) {
    let mut e = Engine::new(sim_engine_config()).unwrap();
    if referenced {
        reference_at_zero(&mut e);
    }
    e.set_model(loaded(table), info(table));
    (e, FakeClock(Cell::new(0)), Fake::new())
}

/// Ticks `n` times at the nominal period.
fn run(e: &mut Engine<'_>, clock: &FakeClock, io: &mut Fake, n: u64) {
    let period = e.config().period_us as u64;
    for _ in 0..n {
        clock.0.set(clock.0.get() + period);
        let mut enc = Fake { ..*io };
        let mut t = Fake { ..*io };
        e.tick(clock, &mut enc, &mut t, io);
    }
}

#[test]
fn an_hour_of_random_motion_pulses_equal_the_rounded_correction_every_tick() {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, true);
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let pulse_nm = sim_engine_config().axes.map(|a| a.pulse_nm as i64);
    // One simulated hour at 1 kHz: 3.6 M ticks.
    let ticks = 3_600_000u64;
    let period = e.config().period_us as u64;
    let mut max_err = 0i64;
    for k in 0..ticks {
        // Axes wander (up to ±2 mm/s in 0.1 µm counts), temperature drifts.
        for c in io.counts.iter_mut() {
            *c = (*c as i64 + rng.range(-20, 20)).clamp(-3_000_000, 3_000_000) as i32;
        }
        if k % 1000 == 0 {
            io.temps[0] = (io.temps[0] as i64 + rng.range(-50, 50)).clamp(10_000, 40_000) as i32;
        }
        clock.0.set(clock.0.get() + period);
        let mut enc = Fake { ..io };
        let mut t = Fake { ..io };
        e.tick(&clock, &mut enc, &mut t, &mut io);
        let corr = e.corr_nm();
        for a in 0..3 {
            let want = round_div(corr[a] as i64, pulse_nm[a]);
            max_err = max_err.max((io.pulses[a] - want).abs());
        }
    }
    assert_eq!(max_err, 0, "pulses lagged the correction");
    assert_eq!(io.pulses, e.steps());
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    assert_eq!(e.telemetry().ticks, ticks);
    // And the correction is the model's at the final position once it
    // has settled.
    run(&mut e, &clock, &mut io, 500);
    assert_eq!(e.corr_nm(), e.telemetry().model_corr_nm);
}

#[test]
fn output_equals_model_core_fixed_point_and_tracks_reversal() {
    let table = sample_table(1);
    let m = Model::load(&model_core::parse(&table).unwrap()).unwrap();
    let (mut e, clock, mut io) = rig(&table, true);
    io.temps[0] = 31_000;
    let mut dir = DirTracker::new();
    let transition = m.reversal_transition_nm(0).unwrap();
    // Move x forward, then back, stopping at several points.
    for &target_counts in &[0, 1_000_000, 1_500_000, 1_200_000, -2_000_000] {
        while io.counts[0] != target_counts {
            let d = (target_counts - io.counts[0]).clamp(-2000, 2000);
            io.counts[0] += d;
            run(&mut e, &clock, &mut io, 1);
            dir.update(io.counts[0] * 100, transition);
        }
        run(&mut e, &clock, &mut io, 300);
        let mut temp_mc = [0; model_core::MAX_TEMPS];
        temp_mc.copy_from_slice(&io.temps[..model_core::MAX_TEMPS]);
        let rev = [dir.rev_q30(), 0, 0];
        let want = m.eval_fixed(&Inputs {
            pos_nm: [io.counts[0] * 100, 0, 0],
            rev_q30: rev,
            temp_mc,
            tool_nm: 0,
        });
        assert_eq!(
            e.telemetry().model_corr_nm,
            want.corr_nm,
            "at {target_counts}"
        );
        assert_eq!(e.corr_nm(), want.corr_nm);
    }
}

#[test]
fn slew_limit_holds_on_a_table_switch() {
    let (t1, t2) = (sample_table(0), sample_table(3));
    let (mut e, clock, mut io) = rig(&t1, true);
    io.counts = [3_000_000, -2_500_000, 1_000_000];
    run(&mut e, &clock, &mut io, 1000);
    let before = e.corr_nm();
    e.set_model(loaded(&t2), info(&t2));
    let slew = e.slew_nm_per_ms() as i64; // 500 nm/ms, 1 ms ticks
    assert_eq!(slew, 500);
    let mut prev = before;
    let mut moved = false;
    for _ in 0..1000 {
        run(&mut e, &clock, &mut io, 1);
        let now = e.corr_nm();
        for a in 0..3 {
            assert!(
                (now[a] - prev[a]).abs() as i64 <= slew + 1,
                "{prev:?} -> {now:?}"
            );
        }
        moved |= now != prev;
        prev = now;
    }
    assert!(moved);
    assert_eq!(e.corr_nm(), e.telemetry().model_corr_nm);
    assert!(io.max_pulses_per_call <= e.config().max_steps_per_tick);
}

/// Every slew a table may carry (1 … `MAX_SLEW_LIMIT_NM_PER_MS`, which
/// `parse` enforces since a slew above 306 783 378 nm/ms overflowed
/// `s * 7` and crashed the board on every tick: issue 14) is reduced to
/// what the pulses can follow; the reduction itself is done in 64 bits.
#[test]
fn every_table_slew_is_reduced_to_what_the_pulses_follow() {
    for slew in [
        1,
        500,
        65_000,
        1_000_000,
        model_core::table::MAX_SLEW_LIMIT_NM_PER_MS - 1,
        model_core::table::MAX_SLEW_LIMIT_NM_PER_MS,
    ] {
        let mut spec = sample_spec(0);
        spec.envelope.max_slew_nm_per_ms = slew;
        let table = spec.encode().unwrap();
        let mut e = Engine::new(sim_engine_config()).unwrap();
        reference_at_zero(&mut e);
        e.set_model(loaded(&table), info(&table));
        let applied = e.slew_nm_per_ms();
        assert!(applied > 0 && applied <= slew, "slew {slew} → {applied}");
        let clock = FakeClock(Cell::new(0));
        let mut io = Fake::new();
        io.counts = [3_000_000, -2_500_000, 1_000_000];
        let mut prev = e.corr_nm();
        for _ in 0..200 {
            run(&mut e, &clock, &mut io, 1);
            let now = e.corr_nm();
            for a in 0..3 {
                assert!(
                    (now[a] - prev[a]).abs() <= applied + 1,
                    "slew {slew}: {prev:?} -> {now:?}"
                );
            }
            prev = now;
        }
        assert!(e.faults().is_empty(), "slew {slew}: {:?}", e.faults());
        assert!(io.max_pulses_per_call <= e.config().max_steps_per_tick);
    }
}

/// Runs to a steady non-zero correction, injects a fault, checks the ramp
/// to zero (at the fault ramp rate, pulses following) and the report.
fn fault_ramps_to_zero(
    make_fault: impl FnOnce(&mut Engine<'_>, &FakeClock, &mut Fake),
    expect: Faults,
) -> (Engine<'static>, FakeClock, Fake) {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, false);
    io.counts = [3_900_000, 3_900_000, 3_900_000];
    // 3.9 M counts of 0.1 µm: the axes are at 390 mm.
    for axis in 0..3 {
        e.reference(axis, 390_000_000);
    }
    run(&mut e, &clock, &mut io, 1000);
    let start = e.corr_nm();
    assert!(start.iter().any(|&c| c.abs() > 5000), "{start:?}");
    make_fault(&mut e, &clock, &mut io);
    let ramp = e.config().fault_ramp_nm_per_ms as i64;
    let mut prev = e.corr_nm();
    for _ in 0..200 {
        run(&mut e, &clock, &mut io, 1);
        let now = e.corr_nm();
        for a in 0..3 {
            assert!((now[a] - prev[a]).abs() as i64 <= ramp + 1);
            assert!(now[a].abs() <= prev[a].abs());
        }
        prev = now;
    }
    assert_eq!(e.corr_nm(), [0; 3]);
    assert_eq!(e.steps(), [0; 3]);
    assert!(e.faults().contains(expect), "{:?}", e.faults());
    assert!(e.telemetry().faults_latched.contains(expect));
    (e, clock, io)
}

#[test]
fn sensor_out_of_range_ramps_to_zero_and_recovers_when_back() {
    let (mut e, clock, mut io) = fault_ramps_to_zero(
        |_, _, io| io.temps[1] = -100_000, // open thermistor
        Faults::SENSOR_RANGE,
    );
    io.temps[1] = 21_000;
    run(&mut e, &clock, &mut io, 300);
    assert!(e.faults().is_empty());
    assert_ne!(e.corr_nm(), [0; 3]);
    // Still latched for the operator until cleared.
    assert!(e.telemetry().faults_latched.contains(Faults::SENSOR_RANGE));
    e.clear_faults();
    assert!(e.telemetry().faults_latched.is_empty());
}

#[test]
fn loop_overrun_is_sticky_until_cleared() {
    let (mut e, clock, mut io) = fault_ramps_to_zero(
        |e, clock, io| {
            // The next tick comes three periods late.
            clock.0.set(clock.0.get() + 2 * e.config().period_us as u64);
            run(e, clock, io, 1);
        },
        Faults::LOOP_OVERRUN,
    );
    assert_eq!(e.telemetry().overruns, 1);
    assert_eq!(e.telemetry().worst_loop_us, 3 * e.config().period_us);
    e.clear_faults();
    run(&mut e, &clock, &mut io, 300);
    assert!(e.faults().is_empty());
    assert_ne!(e.corr_nm(), [0; 3]);
}

/// A clock for ticks on a fixed period that take `took_us` each: a tick
/// reads it at its start (the period's due time, or the end of the previous
/// tick if that ended later — what a ticker does) and at its end.
struct TickTimes {
    period_us: u64,
    took_us: Cell<u64>,
    due_us: Cell<u64>,
    start_us: Cell<u64>,
    at_start: Cell<bool>,
}
impl TickTimes {
    fn new(period_us: u64) -> Self {
        Self {
            period_us,
            took_us: Cell::new(0),
            due_us: Cell::new(0),
            start_us: Cell::new(0),
            at_start: Cell::new(true),
        }
    }
}
impl Clock for TickTimes {
    fn now_us(&self) -> u64 {
        if self.at_start.replace(false) {
            let start = self.due_us.get().max(self.start_us.get());
            self.start_us.set(start);
            start
        } else {
            self.at_start.set(true);
            self.due_us.set(self.due_us.get() + self.period_us);
            let end = self.start_us.get() + self.took_us.get();
            self.start_us.set(end);
            end
        }
    }
}

#[test]
fn a_tick_that_ends_past_the_next_deadline_is_an_overrun() {
    let table = sample_table(0);
    let mut e = Engine::new(sim_engine_config()).unwrap();
    reference_at_zero(&mut e);
    e.set_model(loaded(&table), info(&table));
    let period = e.config().period_us as u64;
    let clock = TickTimes::new(period);
    let mut io = Fake::new();
    let mut tick = |e: &mut Engine<'_>, took_us: u64| {
        clock.took_us.set(took_us);
        let mut enc = Fake { ..io };
        let mut t = Fake { ..io };
        e.tick(&clock, &mut enc, &mut t, &mut io)
    };
    // Ticks that end exactly when the next is due meet every deadline.
    for _ in 0..5 {
        tick(&mut e, period);
    }
    assert_eq!(e.telemetry().overruns, 0);
    assert!(e.faults().is_empty());
    assert_eq!(e.telemetry().worst_tick_us, period as u32);
    // One microsecond more and the tick ends after the next was due,
    // although the next starts far less than two periods after it: an
    // overrun, and the fault acts at once.
    let r = tick(&mut e, period + 1);
    assert!(r.faults.contains(Faults::LOOP_OVERRUN));
    assert_eq!(e.telemetry().overruns, 1);
    assert!(e.telemetry().worst_loop_us < 2 * period as u32);
    // A tick of 2.5 periods leaves a gap ≥ 2 periods before the next start:
    // still one overrun, not two.
    tick(&mut e, 5 * period / 2);
    assert_eq!(e.telemetry().overruns, 2);
    tick(&mut e, period / 2);
    assert_eq!(e.telemetry().overruns, 2);
    assert!(e.telemetry().worst_loop_us >= 2 * period as u32);
    e.clear_faults();
    for _ in 0..5 {
        tick(&mut e, period / 2);
    }
    assert_eq!(e.telemetry().overruns, 2);
    assert!(e.faults().is_empty());
}

/// A stall the server announces around a flash operation
/// (`begin_stall` … `end_stall`) is no overrun, whichever comes first
/// after the erase: the tick (the board, where the loop preempts the link
/// task as soon as the flash lets it) or `end_stall` (the simulation).
/// Outside it a gap is an overrun again.
#[test]
fn a_stall_announced_by_the_server_is_not_an_overrun() {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, true);
    run(&mut e, &clock, &mut io, 10);
    // The board's order: a normal tick, the 1.5 s erase, the first tick
    // after it, then the link task ends the stall.
    e.begin_stall();
    run(&mut e, &clock, &mut io, 1);
    clock.0.set(clock.0.get() + 1_500_000);
    run(&mut e, &clock, &mut io, 1);
    e.end_stall();
    run(&mut e, &clock, &mut io, 10);
    // The simulation's: the stall ends before the next tick.
    e.begin_stall();
    clock.0.set(clock.0.get() + 1_500_000);
    e.end_stall();
    run(&mut e, &clock, &mut io, 10);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    assert_eq!(e.telemetry().overruns, 0);
    // Over: the next long gap is an overrun.
    clock.0.set(clock.0.get() + 10_000);
    run(&mut e, &clock, &mut io, 1);
    assert_eq!(e.telemetry().overruns, 1);
    assert!(e.faults().contains(Faults::LOOP_OVERRUN));
}

#[test]
fn encoder_jump_is_a_fault() {
    let mut cfg = sim_engine_config();
    for a in cfg.axes.iter_mut() {
        a.max_speed_nm_per_ms = 100_000; // 100 mm/s
    }
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    reference_at_zero(&mut e);
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    run(&mut e, &clock, &mut io, 10);
    // 100 mm/s for 1 ms = 0.1 mm = 1000 counts: fine.
    io.counts[2] += 1000;
    run(&mut e, &clock, &mut io, 1);
    assert!(e.faults().is_empty());
    // 10 mm in one tick: a glitch.
    io.counts[2] += 100_000;
    run(&mut e, &clock, &mut io, 1);
    assert!(e.faults().contains(Faults::ENCODER_JUMP));
}

#[test]
fn without_a_table_the_output_is_zero_and_says_why() {
    let mut e = Engine::new(sim_engine_config()).unwrap();
    reference_at_zero(&mut e);
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    io.counts = [1_000_000; 3];
    run(&mut e, &clock, &mut io, 10);
    assert_eq!(e.corr_nm(), [0; 3]);
    assert!(e.faults().contains(Faults::NO_TABLE));
}

#[test]
fn configurations_the_pulse_budget_cannot_follow_are_refused() {
    let mut cfg: EngineConfig = sim_engine_config();
    cfg.fault_ramp_nm_per_ms = 1_000_000; // 1 mm/ms: 10 000 pulses per tick
    assert_eq!(
        Engine::new(cfg).err(),
        Some(ConfigError::RampTooFast { axis: 0 })
    );
    let mut cfg = sim_engine_config();
    cfg.axes[1].pulse_nm = 0;
    assert_eq!(Engine::new(cfg).err(), Some(ConfigError::NonPositive));
    // A table slew beyond the budget is reduced, not trusted.
    let mut cfg = sim_engine_config();
    cfg.max_steps_per_tick = 3; // 200 nm per 1 ms tick
    cfg.fault_ramp_nm_per_ms = 150;
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    reference_at_zero(&mut e);
    e.set_model(loaded(&table), info(&table));
    assert!(
        e.slew_nm_per_ms() < 500 && e.slew_nm_per_ms() > 100,
        "{}",
        e.slew_nm_per_ms()
    );
}

#[test]
fn a_fault_ramp_of_zero_or_less_is_refused() {
    // At 0 nm/ms a fault would hold the last correction forever instead of
    // ramping it to zero.
    for ramp in [0, -1] {
        let mut cfg = sim_engine_config();
        cfg.fault_ramp_nm_per_ms = ramp;
        assert_eq!(Engine::new(cfg).err(), Some(ConfigError::NonPositive));
    }
    let mut cfg = sim_engine_config();
    cfg.fault_ramp_nm_per_ms = 1;
    assert!(Engine::new(cfg).is_ok());
}

#[test]
fn positions_scale_exactly_for_whole_and_fractional_nm_per_count() {
    for pm in [100_000i64, 12_345, -25_000] {
        let mut cfg = sim_engine_config();
        cfg.axes[0].pm_per_count = pm;
        cfg.axes[0].origin_nm = -7;
        let mut e = Engine::new(cfg).unwrap();
        let clock = FakeClock(Cell::new(0));
        let mut io = Fake::new();
        for counts in [0, 1, 999, -123_457, 2_000_000] {
            io.counts[0] = counts;
            run(&mut e, &clock, &mut io, 1);
            let want = counts as i64 * pm / 1000 - 7;
            assert_eq!(
                e.telemetry().pos_nm[0] as i64,
                want,
                "pm {pm} counts {counts}"
            );
        }
    }
}

/// The model-core evaluation at `pos_nm`, axes at rest (reversal unknown),
/// 20 °C.
fn model_at(table: &[u8], pos_nm: [i32; 3]) -> [i32; 3] {
    let m = Model::load(&model_core::parse(table).unwrap()).unwrap();
    m.eval_fixed(&Inputs {
        pos_nm,
        rev_q30: [0; 3],
        temp_mc: [20_000; model_core::MAX_TEMPS],
        tool_nm: 0,
    })
    .corr_nm
}

#[test]
fn no_correction_until_every_axis_is_referenced_then_it_ramps_in_at_the_table_slew() {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, false);
    // Switched on somewhere: 100 mm, -50 mm, 20 mm of counts.
    io.counts = [1_000_000, -500_000, 200_000];
    run(&mut e, &clock, &mut io, 500);
    assert_eq!(e.corr_nm(), [0; 3]);
    assert_eq!(e.steps(), [0; 3]);
    assert_eq!(e.faults(), Faults::NOT_REFERENCED);
    let t = e.telemetry();
    assert_eq!((t.referenced, t.reference_needed), ([false; 3], [true; 3]));
    // Two of three axes are not enough.
    assert!(e.reference(0, 10_000_000));
    assert!(e.reference(1, -20_000_000));
    run(&mut e, &clock, &mut io, 100);
    assert_eq!(e.corr_nm(), [0; 3]);
    assert_eq!(e.telemetry().referenced, [true, true, false]);
    assert_eq!(e.faults(), Faults::NOT_REFERENCED);
    assert!(!e.reference(3, 0), "there is no fourth axis");
    // The third: the output ramps in at the table's slew, to the model at
    // the referenced positions (not at the positions counted from power-up).
    assert!(e.reference(2, 250_000_000));
    let pos = [10_000_000, -20_000_000, 250_000_000];
    let want = model_at(&table, pos);
    assert_ne!(
        want,
        model_at(&table, [100_000_000, -50_000_000, 20_000_000])
    );
    let step = e.slew_nm_per_ms() as i64 * e.config().period_us as i64 / 1000 + 1;
    let mut prev = e.corr_nm();
    let mut ticks = 0;
    while e.corr_nm() != want {
        run(&mut e, &clock, &mut io, 1);
        let now = e.corr_nm();
        for a in 0..3 {
            assert!(
                (now[a] - prev[a]).abs() as i64 <= step,
                "{prev:?} -> {now:?}"
            );
        }
        prev = now;
        ticks += 1;
        assert!(ticks < 1000, "never got there: {now:?}, want {want:?}");
    }
    assert!(ticks > 1, "ramped, not jumped: {ticks} ticks");
    assert_eq!(e.telemetry().pos_nm, pos);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
}

#[test]
fn an_encoder_jump_loses_the_reference_the_output_ramps_to_zero_until_referenced_again() {
    let mut cfg = sim_engine_config();
    for a in cfg.axes.iter_mut() {
        a.max_speed_nm_per_ms = 100_000;
    }
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    io.counts = [2_000_000; 3];
    for axis in 0..3 {
        e.reference(axis, 200_000_000);
    }
    run(&mut e, &clock, &mut io, 1000);
    let steady = e.corr_nm();
    assert_eq!(steady, model_at(&table, [200_000_000; 3]));
    // Y's counter glitches by 10 mm.
    io.counts[1] += 100_000;
    run(&mut e, &clock, &mut io, 1);
    assert_eq!(e.telemetry().referenced, [true, false, true]);
    assert!(e
        .faults()
        .contains(Faults::ENCODER_JUMP.union(Faults::NOT_REFERENCED)));
    let ramp = e.config().fault_ramp_nm_per_ms as i64;
    let mut prev = e.corr_nm();
    for _ in 0..200 {
        run(&mut e, &clock, &mut io, 1);
        let now = e.corr_nm();
        for a in 0..3 {
            assert!((now[a] - prev[a]).abs() as i64 <= ramp + 1);
            assert!(now[a].abs() <= prev[a].abs(), "grew: {prev:?} -> {now:?}");
        }
        prev = now;
    }
    assert_eq!(e.corr_nm(), [0; 3]);
    // Clearing the jump is not enough: Y has no reference.
    e.clear_faults();
    run(&mut e, &clock, &mut io, 200);
    assert_eq!(e.corr_nm(), [0; 3]);
    assert_eq!(e.faults(), Faults::NOT_REFERENCED);
    assert!(e
        .telemetry()
        .faults_latched
        .contains(Faults::NOT_REFERENCED));
    // Referenced again (Y is at 200 mm): the correction comes back.
    e.reference(1, 200_000_000);
    run(&mut e, &clock, &mut io, 1000);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    assert_eq!(e.corr_nm(), steady);
}

#[test]
fn an_axis_without_an_encoder_needs_no_reference() {
    // A two-axis machine: no Z encoder (pm_per_count 0), Z at its
    // configured origin.
    let mut cfg = sim_engine_config();
    cfg.axes[2].pm_per_count = 0;
    cfg.axes[2].origin_nm = 5_000_000;
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    e.reference(0, 0);
    e.reference(1, 0);
    run(&mut e, &clock, &mut io, 1000);
    let t = e.telemetry();
    assert_eq!(t.reference_needed, [true, true, false]);
    assert_eq!(t.referenced, [true, true, false]);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    assert_eq!(e.corr_nm(), model_at(&table, [0, 0, 5_000_000]));
}

#[test]
fn a_reference_keeps_the_reversal_state() {
    let table = sample_table(1);
    let (mut e, clock, mut io) = rig(&table, false);
    reference_at_zero(&mut e);
    run(&mut e, &clock, &mut io, 1);
    // X moves forward by 1 mm (past the reversal transition).
    for _ in 0..100 {
        io.counts[0] += 100;
        run(&mut e, &clock, &mut io, 1);
    }
    let before = e.telemetry();
    // Re-referenced 5 mm back: a shift of the position, not a motion
    // backwards (the reversal state stays "moved forward").
    e.reference(0, before.pos_nm[0] - 5_000_000);
    run(&mut e, &clock, &mut io, 1);
    let after = e.telemetry();
    assert_eq!(after.pos_nm[0], before.pos_nm[0] - 5_000_000);
    let m = Model::load(&model_core::parse(&table).unwrap()).unwrap();
    let forward = m.eval_fixed(&Inputs {
        pos_nm: after.pos_nm,
        rev_q30: [1 << 30, 0, 0],
        temp_mc: [20_000; model_core::MAX_TEMPS],
        tool_nm: 0,
    });
    assert_eq!(after.model_corr_nm, forward.corr_nm);
}

fn still_injection(pos_nm: [i32; 3], temp_c: i32) -> Injection {
    Injection {
        pos_nm,
        rev_q30: [0; 3],
        temp_mc: [temp_c * 1000; LINK_TEMPS],
        tool_nm: 0,
    }
}

#[test]
fn an_injection_ends_when_its_lease_runs_out_or_an_axis_moves() {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, false);
    reference_at_zero(&mut e);
    run(&mut e, &clock, &mut io, 10);
    let inj = still_injection([100_000_000, 0, 0], 20);
    e.set_injection(Some(inj), 50);
    run(&mut e, &clock, &mut io, 50);
    assert!(e.injecting());
    assert_eq!(e.telemetry().pos_nm, inj.pos_nm);
    run(&mut e, &clock, &mut io, 1);
    assert!(!e.injecting(), "the lease of 50 ticks ran out");
    assert_eq!(e.telemetry().pos_nm, [0; 3]);
    // Renewed; a servo's dither at rest (±1 µm here: 10 counts) is no
    // motion; leaving that band is, and the injection ends at once.
    e.set_injection(Some(inj), 50);
    run(&mut e, &clock, &mut io, 10);
    assert!(e.injecting());
    for d in [1, -1, 10, -10, 0] {
        io.counts[1] = d;
        run(&mut e, &clock, &mut io, 1);
    }
    assert!(e.injecting(), "dither ended the injection");
    io.counts[1] = 11;
    run(&mut e, &clock, &mut io, 1);
    assert!(!e.injecting(), "an axis moved");
    assert_eq!(e.telemetry().pos_nm, [0, 1100, 0]);
}

#[test]
fn sensor_checks_stay_on_while_injecting() {
    let table = sample_table(0);
    let (mut e, clock, mut io) = rig(&table, false);
    reference_at_zero(&mut e);
    run(&mut e, &clock, &mut io, 10);
    // A real thermistor open while plausible temperatures are injected.
    e.set_injection(Some(still_injection([0; 3], 20)), 1000);
    io.temps[1] = -100_000;
    run(&mut e, &clock, &mut io, 1);
    assert!(e.injecting());
    assert!(
        e.faults().contains(Faults::SENSOR_RANGE),
        "{:?}",
        e.faults()
    );
    // Real sensors fine, an injected temperature no sensor can read.
    io.temps[1] = 20_000;
    e.set_injection(Some(still_injection([0; 3], 150)), 1000);
    run(&mut e, &clock, &mut io, 1);
    assert!(
        e.faults().contains(Faults::SENSOR_RANGE),
        "{:?}",
        e.faults()
    );
    e.set_injection(Some(still_injection([0; 3], 20)), 1000);
    run(&mut e, &clock, &mut io, 1);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
}

/// X's home switch: at −5 mm, approached moving towards negative counts,
/// debounced over 3 ticks, 50 µm tolerance.
fn home_at_minus_5mm() -> HomeSwitch {
    HomeSwitch {
        pos_nm: -5_000_000,
        approach: Approach::Negative,
        debounce_ticks: 3,
        tolerance_nm: 50_000,
    }
}

#[test]
fn a_home_switch_references_its_axis_when_it_turns_on() {
    // X has a home switch at -5 mm; Y and Z have none.
    let mut cfg = sim_engine_config();
    cfg.axes[0].home = Some(home_at_minus_5mm());
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    // Switched on with every axis on its switch: that is no edge, no
    // reference (the switch turning on marks the position, not being on).
    io.counts = [5000, 0, 0];
    io.home = 0b111;
    run(&mut e, &clock, &mut io, 10);
    assert_eq!(e.telemetry().referenced, [false; 3]);
    // Off the switch (debounced), then X homes: moving towards negative
    // counts, the switch turns on at count 4321 and the axis moves on
    // while the input is debounced (a switch works while the axis moves,
    // unlike a reference over the link). Y's input does nothing: Y has no
    // switch configured.
    io.home = 0;
    run(&mut e, &clock, &mut io, 3);
    for c in (4322..4400).rev() {
        io.counts[0] = c;
        run(&mut e, &clock, &mut io, 1);
    }
    io.home = 0b011;
    for c in [4321, 4320, 4319] {
        io.counts[0] = c;
        run(&mut e, &clock, &mut io, 1);
    }
    let t = e.telemetry();
    assert_eq!(t.referenced, [true, false, false]);
    // Referenced at the count of the first tick on the switch: the
    // debounce costs no position.
    assert_eq!(t.pos_nm[0], -5_000_000 - 2 * 100);
    // Staying on the switch and moving on does not re-reference.
    io.counts[0] -= 10;
    run(&mut e, &clock, &mut io, 1);
    assert_eq!(e.telemetry().pos_nm[0], -5_000_000 - 12 * 100);
    // With Y and Z referenced over the link, the correction ramps in.
    e.reference(1, 0);
    e.reference(2, 0);
    run(&mut e, &clock, &mut io, 1000);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    // X last moved towards negative counts: the reversal state is −1.
    let m = Model::load(&model_core::parse(&table).unwrap()).unwrap();
    let want = m.eval_fixed(&Inputs {
        pos_nm: [-5_000_000 - 12 * 100, 0, 0],
        rev_q30: [-(1 << 30), 0, 0],
        temp_mc: [20_000; model_core::MAX_TEMPS],
        tool_nm: 0,
    });
    assert_eq!(e.corr_nm(), want.corr_nm);
}

/// Referencing by the switch needs the approach direction and a debounced
/// input: an edge reached moving the other way, or with the axis never
/// seen moving, references nothing, nor does an input on for fewer ticks
/// than the debounce.
#[test]
fn a_home_switch_references_only_from_its_side_and_debounced() {
    let mut cfg = sim_engine_config();
    cfg.axes[0].home = Some(home_at_minus_5mm());
    let mut e = Engine::new(cfg).unwrap();
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    run(&mut e, &clock, &mut io, 5);
    // On while X never moved: no direction, no reference.
    io.home = 1;
    run(&mut e, &clock, &mut io, 5);
    io.home = 0;
    run(&mut e, &clock, &mut io, 5);
    assert!(!e.referenced()[0]);
    // Reached moving towards positive counts: the wrong side.
    for c in 1..=10 {
        io.counts[0] = c;
        io.home = u8::from(c > 5);
        run(&mut e, &clock, &mut io, 1);
    }
    io.home = 0;
    run(&mut e, &clock, &mut io, 5);
    assert!(!e.referenced()[0]);
    // From the right side, but on for 2 ticks of the 3 the debounce
    // wants (a glitch), twice: nothing.
    for _ in 0..2 {
        for k in 0..6 {
            io.counts[0] -= 1;
            io.home = u8::from((2..4).contains(&k));
            run(&mut e, &clock, &mut io, 1);
        }
    }
    assert!(!e.referenced()[0]);
    // Three ticks on: referenced.
    for k in 0..6 {
        io.counts[0] -= 1;
        io.home = u8::from(k >= 2);
        run(&mut e, &clock, &mut io, 1);
    }
    assert!(e.referenced()[0]);
}

/// The plausible temperature range at its ends (the tick compares with a
/// window made in `Engine::new`): the configured minimum and maximum are
/// plausible, one m°C beyond either is a sensor fault, so are the i32
/// extremes (the thermistor's rail value is `i32::MIN`); a range whose
/// maximum is below its minimum refuses every reading, and the channels
/// beyond `temps_used` are not checked.
#[test]
fn temperature_range_holds_at_its_ends_and_one_past() {
    for (lo, hi) in [(-20_000, 80_000), (i32::MIN, i32::MAX), (5, 5), (0, -1)] {
        let cfg = EngineConfig {
            temp_min_mc: lo,
            temp_max_mc: hi,
            ..sim_engine_config()
        };
        let mut e = Engine::new(cfg).unwrap();
        let clock = FakeClock(Cell::new(0));
        let mut io = Fake::new();
        let mut faulted = |t: i32, ch: usize| {
            io.temps = [if lo <= hi { lo } else { 0 }; LINK_TEMPS];
            io.temps[ch] = t;
            run(&mut e, &clock, &mut io, 1);
            e.faults().contains(Faults::SENSOR_RANGE)
        };
        for t in [lo, hi, ((lo as i64 + hi as i64) / 2) as i32] {
            assert_eq!(faulted(t, 1), lo > hi, "{t} in [{lo}, {hi}]");
        }
        for t in [lo.wrapping_sub(1), hi.wrapping_add(1), i32::MIN, i32::MAX] {
            let inside = lo <= t && t <= hi;
            assert_eq!(faulted(t, 0), !inside, "{t} in [{lo}, {hi}]");
            // Channel 2 is beyond `temps_used` (2): never checked.
            assert_eq!(faulted(t, 2), lo > hi, "{t} on channel 2");
        }
    }
}

/// The home switch's tolerance at its limit and one past, and positions
/// at the ends of the i32 range: a referenced X whose switch turns on
/// exactly `tolerance_nm` from its position (either side) is fine, 1 nm
/// farther is a mismatch; an X referenced at i32::MAX or i32::MIN checks
/// without overflow (the check is in i64).
#[test]
fn the_home_tolerance_holds_to_the_nanometre() {
    let tol = 50_000;
    for (at, mismatch) in [
        (-5_000_000 + tol, false),
        (-5_000_000 - tol, false),
        (-5_000_000 + tol + 1, true),
        (-5_000_000 - tol - 1, true),
        (i32::MAX, true),
        (i32::MIN, true),
    ] {
        let mut cfg = sim_engine_config();
        cfg.axes[0].pm_per_count = 1000; // 1 nm per count
        cfg.axes[0].home = Some(home_at_minus_5mm());
        let mut e = Engine::new(cfg).unwrap();
        let clock = FakeClock(Cell::new(0));
        let mut io = Fake::new();
        io.counts[0] = 1000;
        run(&mut e, &clock, &mut io, 1);
        // Referenced so that the count where the switch will turn on
        // (one below this one) is at `at` (held at the i32 range).
        assert!(e.reference(0, at.saturating_add(1)));
        e.reference(1, 0);
        e.reference(2, 0);
        run(&mut e, &clock, &mut io, 1);
        io.counts[0] -= 1; // moving towards negative counts
        io.home = 1;
        run(&mut e, &clock, &mut io, 3); // the debounce: 3 ticks
        assert_eq!(
            e.faults().contains(Faults::HOME_MISMATCH),
            mismatch,
            "switch at {at} nm, home −5 mm ± {tol}"
        );
        assert_eq!(e.referenced()[0], !mismatch, "at {at}");
        if !mismatch {
            // Checked, not re-referenced: the position stays as tracked.
            assert_eq!(e.telemetry().pos_nm[0], at);
        }
    }
}

/// Issue 25, the home-switch hole: X is referenced at 300 mm and moving
/// towards its switch's side; its home switch (home position 0, 4-tick
/// debounce, 100 µm tolerance, the board's) glitches for one tick (50 µs
/// on the board): nothing happens. Then the axis passes over an input
/// that stays on for 20 ticks, 300 mm from where the switch is: no new
/// reference either — a fault (`HOME_MISMATCH`) that drops X's
/// reference, so the output ramps to zero; the next real homing (a
/// debounced edge at the switch, from its side) references X again, and
/// after `ClearFaults` the board corrects. Before issue 25 the glitch set
/// X to 0, still referenced, and ex jumped.
#[test]
fn a_home_switch_glitch_or_pass_never_re_references_a_referenced_axis() {
    let mut cfg = sim_engine_config();
    cfg.axes[0].home = Some(HomeSwitch {
        pos_nm: 0,
        approach: Approach::Negative,
        debounce_ticks: 4,
        tolerance_nm: 100_000,
    });
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    assert!(e.reference(0, 300_000_000));
    assert!(e.reference(1, 0));
    assert!(e.reference(2, 0));
    run(&mut e, &clock, &mut io, 500);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    let tracked = |io: &Fake| 300_000_000 + io.counts[0] * 100;
    let step = |e: &mut Engine<'_>, io: &mut Fake, home: u8| {
        io.counts[0] -= 20; // 2 µm per tick towards the switch's side
        io.home = home;
        run(e, &clock, io, 1);
    };
    for _ in 0..50 {
        step(&mut e, &mut io, 0);
    }
    let corr = e.corr_nm();
    // A one-tick glitch: debounced away, nothing else.
    step(&mut e, &mut io, 1);
    step(&mut e, &mut io, 0);
    assert_eq!(e.telemetry().pos_nm[0], tracked(&io), "a glitch moved X");
    assert_eq!(e.referenced(), [true; 3]);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    assert!((e.corr_nm()[0] - corr[0]).abs() < 50, "no jump");
    // A pass over an input that is on for 20 ticks, 300 mm from the switch.
    for _ in 0..20 {
        step(&mut e, &mut io, 1);
    }
    step(&mut e, &mut io, 0);
    assert_eq!(e.telemetry().pos_nm[0], tracked(&io), "a pass moved X");
    assert!(
        e.faults().contains(Faults::HOME_MISMATCH) && e.faults().contains(Faults::NOT_REFERENCED),
        "{:?}",
        e.faults()
    );
    assert_eq!(e.referenced(), [false, true, true]);
    // The mismatch came 4 ticks into the pass (the debounce); the output
    // ramped to zero at the fault ramp over the 16 after.
    assert_eq!(e.corr_nm(), [0; 3], "the output ramps to zero");
    // Real homing: the switch turns on (debounced, from its side) at the
    // count where X is 0 mm by the machine's own scale — the axis is
    // referenced there; `ClearFaults` lets the correction back in.
    for _ in 0..5 {
        step(&mut e, &mut io, 0);
    }
    // The count of the first tick on the switch.
    let at = io.counts[0] - 20;
    for _ in 0..4 {
        step(&mut e, &mut io, 1);
    }
    assert_eq!(e.referenced(), [true; 3]);
    assert_eq!(e.telemetry().pos_nm[0], (io.counts[0] - at) * 100);
    assert!(e.faults().contains(Faults::HOME_MISMATCH), "sticky");
    e.clear_faults();
    run(&mut e, &clock, &mut io, 1);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
}

/// Encoders as the board reads them: 16-bit hardware counters (the true
/// count modulo 2^16) widened by `Widen16` at every read.
struct Counters {
    true_counts: [i64; 3],
    wide: [trueaxis_app::sensors::Widen16; 3],
}

impl trueaxis_app::hw::Encoders for Counters {
    fn read_counts(&mut self) -> [i32; 3] {
        core::array::from_fn(|a| self.wide[a].update(self.true_counts[a] as u16))
    }
}

/// Issue 25, the stalled-erase hole: the board's geometry (25 nm per
/// count, 500 mm/s, 16-bit counters widened in software, 50 µs ticks);
/// the loop stalls for 1.5 s (a flash erase) while X moves 66 236 counts
/// (1.656 mm). The widened count then reads 700 counts (17.5 µm): the
/// position is 1.6384 mm wrong, and the jump check (2 000 counts a tick)
/// does not see it. The gap is longer than the widening can follow
/// (1 638 µs at 500 mm/s) and X moved: `POSITION_LOST`, X unreferenced,
/// the output ramps to zero. A stall without motion keeps the reference;
/// so does motion across a gap the widening covers.
#[test]
fn motion_during_a_long_stall_is_not_a_silent_position_error() {
    let mut cfg = sim_engine_config();
    cfg.period_us = 50;
    cfg.max_steps_per_tick = 2;
    for a in cfg.axes.iter_mut() {
        a.pm_per_count = 25_000;
        a.max_speed_nm_per_ms = 500_000;
        a.counter_bits = 16;
    }
    let table = sample_table(0);
    let mut e = Engine::new(cfg).unwrap();
    e.set_model(loaded(&table), info(&table));
    let clock = FakeClock(Cell::new(0));
    let mut enc = Counters {
        true_counts: [0; 3],
        wide: [trueaxis_app::sensors::Widen16::new(0); 3],
    };
    let mut io = Fake::new();
    reference_at_zero(&mut e);
    let mut tick = |e: &mut Engine<'_>, enc: &mut Counters, dt: u64| {
        clock.0.set(clock.0.get() + dt);
        let mut t = Fake { ..io };
        e.tick(&clock, enc, &mut t, &mut io);
    };
    for _ in 0..20_000 {
        tick(&mut e, &mut enc, 50);
    }
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    // A 1.5 s stall at rest (a commit's erase after the quiet time): the
    // reference stays.
    e.begin_stall();
    tick(&mut e, &mut enc, 1_500_000);
    e.end_stall();
    tick(&mut e, &mut enc, 50);
    assert!(e.faults().is_empty(), "{:?}", e.faults());
    // Motion across a gap the widening covers (1 600 µs; 25 µm, within
    // the jump check's 2 000 counts).
    enc.true_counts[1] += 1000;
    tick(&mut e, &mut enc, 1_600);
    tick(&mut e, &mut enc, 50);
    assert_eq!(e.referenced(), [true; 3]);
    e.clear_faults(); // the late tick's overrun
                      // The stall: 1.5 s, X moves 66 236 counts.
    e.begin_stall();
    enc.true_counts[0] += 66_236;
    tick(&mut e, &mut enc, 1_500_000);
    e.end_stall();
    let pos = e.telemetry().pos_nm[0];
    assert_eq!(pos, 700 * 25, "the widening aliased as the issue says");
    assert!(
        !e.referenced()[0]
            && e.faults().contains(Faults::NOT_REFERENCED)
            && e.faults().contains(Faults::POSITION_LOST),
        "X corrects from a position 1.6384 mm wrong: referenced {:?}, faults {:?}",
        e.referenced(),
        e.faults()
    );
    assert_eq!(e.referenced(), [false, true, true]);
    // Not an overrun (the stall was announced), and the output ramps to
    // zero until X is referenced again.
    assert!(!e.faults().contains(Faults::LOOP_OVERRUN));
    let before = e.corr_nm()[0].abs();
    tick(&mut e, &mut enc, 50);
    assert!(e.corr_nm()[0].abs() <= before);
}

/// The widening's safe gap at the ends of its range and one past, per
/// counter width: an axis that moved across a gap of exactly the longest
/// the widening covers keeps its reference, one µs more loses it; a
/// 32-bit count never does; and a widened counter without a top speed is
/// refused by the configuration check.
#[test]
fn the_widenings_safe_gap_holds_to_the_microsecond() {
    for bits in [8u8, 16, 31] {
        // 100 nm per count at 100 nm/µs: the safe gap is 2^(bits−1) − 1 µs.
        let safe = (1u64 << (bits - 1)) - 1;
        for (gap, keeps) in [(safe, true), (safe + 1, false)] {
            let mut cfg = sim_engine_config();
            cfg.period_us = 50;
            for a in cfg.axes.iter_mut() {
                a.pm_per_count = 100_000;
                a.max_speed_nm_per_ms = 100_000;
                a.counter_bits = bits;
            }
            let mut e = Engine::new(cfg).unwrap();
            let clock = FakeClock(Cell::new(0));
            let mut io = Fake::new();
            reference_at_zero(&mut e);
            run(&mut e, &clock, &mut io, 5);
            clock.0.set(clock.0.get() + gap - 50);
            // 5 µm: beyond the 1 µm still band, within a tick's jump limit.
            io.counts[2] += 50;
            run(&mut e, &clock, &mut io, 1);
            assert_eq!(e.referenced()[2], keeps, "{bits} bits, gap {gap} µs");
            assert_eq!(e.faults().contains(Faults::POSITION_LOST), !keeps);
        }
    }
    // The largest scale the configuration takes (±(2^31 − 1) pm per
    // count) with the slowest and fastest speeds: no overflow, and one
    // past the scale is refused.
    let mut cfg = sim_engine_config();
    cfg.axes[0].pm_per_count = i32::MAX as i64;
    cfg.axes[0].max_speed_nm_per_ms = 1;
    cfg.axes[0].counter_bits = 31;
    cfg.axes[1].pm_per_count = -(i32::MAX as i64);
    cfg.axes[1].max_speed_nm_per_ms = i32::MAX;
    cfg.axes[1].counter_bits = 1;
    let mut e = Engine::new(cfg).unwrap();
    let clock = FakeClock(Cell::new(0));
    let mut io = Fake::new();
    reference_at_zero(&mut e);
    run(&mut e, &clock, &mut io, 2);
    clock.0.set(u64::MAX / 2);
    run(&mut e, &clock, &mut io, 2);
    assert_eq!(e.referenced(), [true; 3], "no motion: no loss");
    for pm in [
        i32::MAX as i64 + 1,
        -(i32::MAX as i64) - 1,
        i64::MIN,
        i64::MAX,
    ] {
        let mut cfg = sim_engine_config();
        cfg.axes[2].pm_per_count = pm;
        assert_eq!(
            Engine::new(cfg).err(),
            Some(ConfigError::Scale { axis: 2 }),
            "{pm}"
        );
    }
    let mut cfg = sim_engine_config();
    cfg.axes[1].counter_bits = 16; // max speed 0: unbounded
    assert_eq!(
        Engine::new(cfg).err(),
        Some(ConfigError::CounterUnbounded { axis: 1 })
    );
    for bits in [0u8, 33] {
        let mut cfg = sim_engine_config();
        cfg.axes[2].counter_bits = bits;
        assert_eq!(
            Engine::new(cfg).err(),
            Some(ConfigError::CounterUnbounded { axis: 2 })
        );
    }
    let mut cfg = sim_engine_config();
    cfg.axes[0].home = Some(HomeSwitch {
        debounce_ticks: 0,
        ..home_at_minus_5mm()
    });
    assert_eq!(
        Engine::new(cfg).err(),
        Some(ConfigError::HomeSwitch { axis: 0 })
    );
}
