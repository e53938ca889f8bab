//! The engine's output limits as properties (issue 14), over random tables
//! (slew from 1 nm/ms to the format's limit of 10 000 000 nm/ms, max |correction| 0.1–100 µm), random
//! motion, late ticks, table switches, temperature faults and their
//! clearing, referencing (over the link and by X's home switch, which
//! references an unreferenced X and faults on a referenced one far from
//! it) and references lost (encoder jumps, home-switch mismatches):
//! - the output changes per tick by at most the rate in force (the table's
//!   slew as the engine applies it, or the fault ramp while a fault is
//!   active) plus 1 nm of rounding;
//! - during a fault the output never grows;
//! - above the active table's max |correction| the output never grows;
//! - the pulses equal the rounded output every tick;
//! - the output is zero until every axis has been referenced, and never
//!   grows while an axis is not referenced (never referenced, or its
//!   reference lost);
//! - no tick panics.

mod common;

use std::cell::Cell;

use proptest::prelude::*;
use trueaxis_app::engine::{round_div, Approach, Engine, HomeSwitch};
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_app::sim::{sample_spec, sim_engine_config};
use trueaxis_protocol::{Faults, Slot, SlotInfo};

use common::fake::{Fake, FakeClock};

/// A table: the sample polynomial (variant `v`) with the given envelope.
#[derive(Clone, Debug)]
struct TableCase {
    variant: u32,
    slew: i32,
    max_corr_nm: i32,
}

fn table_case() -> impl Strategy<Value = TableCase> {
    (
        0u32..6,
        prop_oneof![
            1i32..3000,
            3000i32..=model_core::table::MAX_SLEW_LIMIT_NM_PER_MS
        ],
        100i32..100_000,
    )
        .prop_map(|(variant, slew, max_corr_nm)| TableCase {
            variant,
            slew,
            max_corr_nm,
        })
}

fn build(t: &TableCase) -> (&'static mut ModelBuf, SlotInfo) {
    let mut spec = sample_spec(t.variant);
    spec.envelope.max_slew_nm_per_ms = t.slew;
    spec.envelope.max_corr_nm = [t.max_corr_nm; 3];
    let bytes = spec.encode().expect("encodes");
    let m: &'static mut ModelBuf = Box::leak(Box::default());
    load_into(&bytes, m).expect("loads");
    let info = SlotInfo {
        slot: Slot::A,
        seq: 1,
        len: bytes.len() as u32,
        crc32: trueaxis_protocol::table_id(&bytes),
    };
    (m, info)
}

#[derive(Clone, Debug)]
enum Op {
    /// Move the axes by these counts (0.1 µm) over one tick.
    Move([i32; 3]),
    /// The next tick comes this many µs late.
    Late(u32),
    /// Activate table `i` of the case's list.
    Switch(usize),
    /// Bed temperature out of the table's range (a fault) or back.
    Temp(bool),
    /// Clear latched faults.
    Clear,
    /// Reference an axis at a position, nm.
    Reference(usize, i32),
    /// An axis's counter jumps (a glitch): its reference is lost.
    Jump(usize),
    /// An axis's home switch turns on or off (X has one at 12 mm).
    Home(usize, bool),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => prop::array::uniform3(-20_000i32..20_000).prop_map(Op::Move),
        1 => (0u32..20_000).prop_map(Op::Late),
        1 => (0usize..3).prop_map(Op::Switch),
        1 => any::<bool>().prop_map(Op::Temp),
        1 => Just(Op::Clear),
        2 => (0usize..3, -400_000_000i32..400_000_000).prop_map(|(a, p)| Op::Reference(a, p)),
        1 => (0usize..3).prop_map(Op::Jump),
        1 => (0usize..3, any::<bool>()).prop_map(|(a, on)| Op::Home(a, on)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn the_output_never_exceeds_the_rate_in_force_nor_grows_when_it_must_not(
        tables in prop::collection::vec(table_case(), 3),
        ops in prop::collection::vec(op(), 1..250),
    ) {
        let mut cfg = sim_engine_config();
        // 1.5 m/s: a Move (≤ 2 mm per tick) is motion, a Jump (5 mm) a glitch.
        for a in cfg.axes.iter_mut() {
            a.max_speed_nm_per_ms = 1_500_000;
        }
        // X's switch at 12 mm, approached towards positive counts, believed
        // at once (a debounce of 1: the debounce has its own tests), 1 mm
        // tolerance — a referenced X far from 12 mm faults on an edge.
        cfg.axes[0].home = Some(HomeSwitch {
            pos_nm: 12_000_000,
            approach: Approach::Positive,
            debounce_ticks: 1,
            tolerance_nm: 1_000_000,
        });
        let pulse_nm = cfg.axes.map(|a| a.pulse_nm as i64);
        let period = cfg.period_us as i64;
        let fault_ramp = cfg.fault_ramp_nm_per_ms as i64;
        let mut e = Engine::new(cfg).unwrap();
        let (m, info) = build(&tables[0]);
        e.set_model(m, info);
        let mut active = 0usize;
        let clock = FakeClock(Cell::new(0));
        let mut io = Fake::new();
        let mut prev = e.corr_nm();
        // The test's own account of the references, and whether all three
        // were ever referenced together.
        let mut referenced = [false; 3];
        let mut ever_all = false;
        let mut last_home: Option<u8> = None;
        // X's reference offset (nm at count 0: positions are counts · 100)
        // and the direction it last moved, as the engine sees them.
        let mut offset_x = 0i64;
        let mut dir_x = 0i64;
        for op in ops {
            let mut dt = period as u64;
            let x_before = io.counts[0];
            match op {
                Op::Move(d) => {
                    for (c, d) in io.counts.iter_mut().zip(d) {
                        *c = (*c as i64 + d as i64).clamp(-3_000_000, 3_000_000) as i32;
                    }
                }
                Op::Late(us) => dt += us as u64,
                Op::Switch(i) => {
                    let (m, info) = build(&tables[i]);
                    e.set_model(m, info);
                    active = i;
                }
                Op::Temp(hot) => io.temps[0] = if hot { 95_000 } else { 20_000 },
                Op::Clear => e.clear_faults(),
                Op::Reference(axis, pos) => {
                    prop_assert!(e.reference(axis, pos));
                    referenced[axis] = true;
                    if axis == 0 {
                        offset_x = pos as i64 - io.counts[0] as i64 * 100;
                    }
                }
                Op::Home(axis, on) => {
                    if on {
                        io.home |= 1 << axis;
                    } else {
                        io.home &= !(1 << axis);
                    }
                }
                Op::Jump(axis) => {
                    // Towards 0, so the counts stay within the ±3 M a Move keeps.
                    io.counts[axis] += if io.counts[axis] > 0 { -50_000 } else { 50_000 };
                    referenced[axis] = false;
                }
            }
            // X's switch turning on (the only axis with one; on at the
            // first tick is no edge), reached moving towards positive
            // counts: it references X without a reference, and checks a
            // referenced X — more than 1 mm from 12 mm loses the
            // reference (a fault). Reached the other way, or before X ever
            // moved: nothing.
            // (The engine sees motion between two reads: none at its first.)
            let dx = io.counts[0] as i64 - x_before as i64;
            if dx != 0 && last_home.is_some() {
                dir_x = dx.signum();
            }
            if last_home.is_some_and(|h| io.home & !h & 1 != 0) && dir_x > 0 {
                if !referenced[0] {
                    referenced[0] = true;
                    offset_x = 12_000_000 - io.counts[0] as i64 * 100;
                } else if (io.counts[0] as i64 * 100 + offset_x - 12_000_000).abs() > 1_000_000 {
                    referenced[0] = false;
                }
            }
            last_home = Some(io.home);
            clock.0.set(clock.0.get() + dt);
            let (mut enc, mut t) = (io, io);
            let report = e.tick(&clock, &mut enc, &mut t, &mut io);
            let now = e.corr_nm();
            let faulted = !report.faults.is_empty();
            let rate = if faulted { fault_ramp } else { e.slew_nm_per_ms() as i64 };
            let max_corr = tables[active].max_corr_nm as i64;
            prop_assert_eq!(e.telemetry().referenced, referenced);
            let all = referenced.iter().all(|&r| r);
            ever_all |= all;
            if !ever_all {
                prop_assert_eq!(now, [0; 3], "output before every axis was referenced");
                prop_assert_eq!(io.pulses, [0; 3]);
            }
            if !all {
                prop_assert!(report.faults.contains(Faults::NOT_REFERENCED));
            }
            for a in 0..3 {
                let (p, n) = (prev[a] as i64, now[a] as i64);
                let step = (n - p).abs();
                prop_assert!(
                    step <= rate * period / 1000 + 1,
                    "axis {a}: {p} -> {n} at {rate} nm/ms (faults {:?})", report.faults
                );
                if faulted {
                    prop_assert!(n.abs() <= p.abs(), "axis {a}: grew during a fault: {p} -> {n}");
                }
                if !all {
                    prop_assert!(n.abs() <= p.abs(), "axis {a}: grew while not referenced: {p} -> {n}");
                }
                if n.abs() > max_corr {
                    prop_assert!(
                        n.abs() <= p.abs(),
                        "axis {a}: grew above the table's max |correction| {max_corr}: {p} -> {n}"
                    );
                }
                prop_assert_eq!(io.pulses[a], round_div(n, pulse_nm[a]), "axis {}", a);
            }
            prop_assert_eq!(io.pulses, e.steps());
            prev = now;
        }
    }
}
