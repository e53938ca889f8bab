//! Never correct from a wrong position (issue 25), on the Cortex-M4F: the
//! application core with the board's geometry (50 µs ticks, 25 nm per
//! count, 500 mm/s, 16-bit encoder counters widened by `Widen16`, a home
//! switch on X at 0) and its link server over a RAM flash.
//!
//! - a home-switch glitch, or a pass over the switch, on a referenced axis
//!   far from home never moves its position;
//! - motion during a long stall (a flash erase: 1.5 s, 66 236 counts) is
//!   not a silent 1.6384 mm position error;
//! - a table whose fixed point departs from its own definition is refused
//!   at commit, and the table that ran keeps running;
//! - `Activate` while an axis moves does not reset the reversal state.
#![no_std]
#![no_main]

#[path = "../src/rig.rs"]
#[allow(dead_code)] // each suite uses part of it
mod rig;

use core::cell::{Cell, RefCell};

use rig::{engine_config, info, upload_and_commit, FakeClock, Flash, SLOT};
use trueaxis_app::engine::{Approach, Engine, EngineConfig, HomeSwitch};
use trueaxis_app::hw::{Encoders, StepOutput, TemperatureSource};
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_app::sensors::Widen16;
use trueaxis_app::server::{Server, ServerConfig};
use trueaxis_app::store::{Layout, TableStore};
use trueaxis_protocol::{table_id, Faults, LinkError, Request, Response, LINK_TEMPS};

static FULL: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/full.bin"));
static CUBIC19: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.bin"));
static OFF_DEFINITION: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/off_definition.bin"));

const PERIOD_US: u64 = 50;

/// The board's encoders: 16-bit counters (the true count modulo 2^16)
/// widened at every read, and the home switches.
struct Counters {
    true_counts: [i64; 3],
    wide: [Widen16; 3],
    home: u8,
}

impl Encoders for Counters {
    fn read_counts(&mut self) -> [i32; 3] {
        core::array::from_fn(|a| self.wide[a].update(self.true_counts[a] as u16))
    }
    fn home_switches(&mut self) -> u8 {
        self.home
    }
}

struct Room;
impl TemperatureSource for Room {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        [20_000; LINK_TEMPS]
    }
}

struct Pulses;
impl StepOutput for Pulses {
    fn pulses(&mut self, _axis: usize, _steps: i32) {}
}

/// The board's engine configuration (board/src/board.rs), X's home switch
/// at 0.
fn config() -> EngineConfig {
    let mut c = EngineConfig {
        max_steps_per_tick: 2,
        temps_used: 1,
        fault_ramp_nm_per_ms: 1000,
        ..engine_config(PERIOD_US as u32)
    };
    for axis in &mut c.axes {
        axis.max_speed_nm_per_ms = 500_000;
        axis.counter_bits = 16;
    }
    c.axes[0].home = Some(HomeSwitch {
        pos_nm: 0,
        approach: Approach::Negative,
        debounce_ticks: 4,
        tolerance_nm: 100_000,
    });
    c
}

struct Rig {
    clock: FakeClock,
    enc: Counters,
}

impl Rig {
    fn new() -> Self {
        Rig {
            clock: FakeClock(Cell::new(0)),
            enc: Counters {
                true_counts: [0; 3],
                wide: [Widen16::new(0); 3],
                home: 0,
            },
        }
    }

    /// One tick `dt_us` after the previous one.
    fn tick(&mut self, e: &mut Engine<'_>, dt_us: u64) {
        self.clock.0.set(self.clock.0.get() + dt_us);
        e.tick(&self.clock, &mut self.enc, &mut Room, &mut Pulses);
    }
}

fn engine<'m>() -> Engine<'m> {
    match Engine::new(config()) {
        Ok(e) => e,
        Err(e) => defmt::panic!("config: {}", e),
    }
}

/// An engine running `table`, loaded into `buf`.
fn engine_running<'m>(buf: &'m mut ModelBuf, table: &[u8]) -> Engine<'m> {
    if load_into(table, buf).is_err() {
        defmt::panic!("load");
    }
    let mut e = engine();
    let _ = e.set_model(buf, info(table));
    e
}

type TestServer = Server<'static, 'static, Flash>;

struct State {
    server: Option<TestServer>,
    /// The server's engine (it holds one of the server's two models).
    engine: RefCell<Engine<'static>>,
}

#[defmt_test::tests]
mod tests {
    use super::*;

    #[init]
    fn init() -> State {
        let mem = cortex_m::singleton!(: [u8; 2 * SLOT] = [0xFF; 2 * SLOT]).expect("once");
        let layout = Layout {
            slot_offset: [0, SLOT as u32],
            slot_bytes: SLOT as u32,
        };
        let store = match TableStore::new(Flash::new_erased(mem), layout) {
            Ok(s) => s,
            Err(e) => defmt::panic!("layout: {}", e),
        };
        let stage = cortex_m::singleton!(: [u8; SLOT] = [0; SLOT]).expect("once");
        let a = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
        let b = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
        let server = Server::new(
            store,
            &mut stage[..],
            [a, b],
            ServerConfig {
                firmware: trueaxis_app::FIRMWARE_VERSION,
                quiet_ms: 500,
                model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
            },
        );
        State {
            server: Some(server),
            engine: RefCell::new(engine()),
        }
    }

    /// X referenced at 300 mm and moving 2 µm per tick towards its
    /// switch's side; a one-tick glitch of its home input (home at 0, the
    /// board's 4-tick debounce and 100 µm tolerance) changes nothing; a
    /// pass over an input that stays on for 20 ticks does not move X
    /// either — it faults (`HOME_MISMATCH`) and drops X's reference, so the
    /// output ramps to zero.
    #[test]
    fn a_home_switch_glitch_or_pass_never_moves_a_referenced_axis() {
        // On the stack (the statics' RAM holds the server's two).
        let mut buf = ModelBuf::new();
        let mut e = engine_running(&mut buf, CUBIC19);
        let mut rig = Rig::new();
        defmt::assert!(e.reference(0, 300_000_000) && e.reference(1, 0) && e.reference(2, 0));
        for _ in 0..100 {
            rig.tick(&mut e, PERIOD_US);
        }
        let tracked = |rig: &Rig| 300_000_000 + rig.enc.true_counts[0] as i32 * 25;
        let step = |rig: &mut Rig, e: &mut Engine<'_>, home: u8| {
            rig.enc.true_counts[0] -= 80; // 2 µm per 50 µs: 40 mm/s
            rig.enc.home = home;
            rig.tick(e, PERIOD_US);
        };
        for _ in 0..50 {
            step(&mut rig, &mut e, 0);
        }
        step(&mut rig, &mut e, 1);
        step(&mut rig, &mut e, 0);
        defmt::assert_eq!(e.telemetry().pos_nm[0], tracked(&rig), "a glitch moved X");
        defmt::assert!(e.faults().is_empty(), "faults {}", e.faults().0);
        for _ in 0..20 {
            step(&mut rig, &mut e, 1);
        }
        step(&mut rig, &mut e, 0);
        defmt::assert_eq!(e.telemetry().pos_nm[0], tracked(&rig), "a pass moved X");
        defmt::assert!(
            e.faults().contains(Faults::HOME_MISMATCH) && !e.referenced()[0],
            "faults {}",
            e.faults().0
        );
        for _ in 0..200 {
            step(&mut rig, &mut e, 0);
        }
        defmt::assert_eq!(e.corr_nm(), [0; 3]);
        defmt::info!("a glitch and a pass over the home input 300 mm from home: X kept its position, the pass faulted");
    }

    /// A 1.5 s stall (a flash erase) during which X moves 66 236 counts
    /// (1.656 mm): the widened count reads 700 counts. X loses its
    /// reference (`POSITION_LOST`) instead of staying referenced at a
    /// position 1.6384 mm wrong; the same stall at rest keeps it.
    #[test]
    fn motion_during_a_stall_is_not_a_silent_position_error() {
        let mut buf = ModelBuf::new();
        let mut e = engine_running(&mut buf, CUBIC19);
        let mut rig = Rig::new();
        for axis in 0..3 {
            defmt::assert!(e.reference(axis, 0));
        }
        for _ in 0..20_000 {
            rig.tick(&mut e, PERIOD_US);
        }
        defmt::assert!(e.faults().is_empty(), "faults {}", e.faults().0);
        e.begin_stall();
        rig.tick(&mut e, 1_500_000);
        e.end_stall();
        defmt::assert!(
            e.faults().is_empty(),
            "a stall at rest: faults {}",
            e.faults().0
        );
        e.begin_stall();
        rig.enc.true_counts[0] += 66_236;
        rig.tick(&mut e, 1_500_000);
        e.end_stall();
        defmt::assert_eq!(e.telemetry().pos_nm[0], 700 * 25);
        defmt::assert!(
            !e.referenced()[0]
                && e.faults().contains(Faults::NOT_REFERENCED)
                && e.faults().contains(Faults::POSITION_LOST),
            "X corrects from a position 1.6384 mm wrong (faults {})",
            e.faults().0
        );
        defmt::info!("1.656 mm of motion during a 1.5 s stall: X's reference lost, position_lost");
    }

    /// A table whose fixed point departs from its own definition by tens
    /// of µm (an Abbe term near the coefficient limit, an arm of up to
    /// 2^31 nm) is refused at commit; the running table stays.
    #[test]
    fn an_off_definition_table_is_refused_and_the_old_one_runs(st: &mut State) {
        let server = st.server.as_mut().expect("server");
        let engine = &st.engine;
        server.boot(engine);
        let r = upload_and_commit(server, engine, 0, FULL);
        defmt::assert!(
            matches!(r, Response::Committed(_)),
            "{}",
            defmt::Debug2Format(&r)
        );
        let r = upload_and_commit(server, engine, 0, OFF_DEFINITION);
        defmt::assert!(
            r == Response::Error(LinkError::InvalidTable),
            "commit answered {}",
            defmt::Debug2Format(&r)
        );
        defmt::assert_eq!(
            engine.borrow().active().map(|a| a.crc32),
            Some(table_id(FULL))
        );
        defmt::info!("the off-definition table was refused at commit; the old one runs");
    }

    /// `Activate` while X moves is refused (the commit's quiet rule) and
    /// changes nothing: the reversal state is not reset (ex would drop by
    /// the reversal amplitude until X travels 20 µm); at rest it goes
    /// through and keeps the reversal state.
    #[test]
    fn activate_while_moving_keeps_the_reversal_state(st: &mut State) {
        let server = st.server.as_mut().expect("server");
        let engine = &st.engine;
        defmt::assert_eq!(
            engine.borrow().active().map(|a| a.crc32),
            Some(table_id(FULL))
        );
        let mut rig = Rig::new();
        for axis in 0..3 {
            defmt::assert!(engine.borrow_mut().reference(axis, 400_000_000));
        }
        // X forward 1 µm per tick for 200 ticks: reversal state +1.
        for _ in 0..200 {
            rig.enc.true_counts[0] += 40;
            rig.tick(&mut engine.borrow_mut(), PERIOD_US);
        }
        let before = engine.borrow().telemetry().model_corr_nm;
        let now = rig.clock.0.get();
        let r = server.handle(Request::Activate, now, engine);
        defmt::assert!(
            r == Response::Error(LinkError::AxesMoving { quiet_ms: 500 }),
            "{}",
            defmt::Debug2Format(&r)
        );
        rig.enc.true_counts[0] += 40;
        rig.tick(&mut engine.borrow_mut(), PERIOD_US);
        let after = engine.borrow().telemetry().model_corr_nm;
        defmt::assert!(
            (after[0] - before[0]).abs() < 100,
            "Activate while moving ({}) changed ex {} -> {}",
            defmt::Debug2Format(&r),
            before[0],
            after[0]
        );
        // 600 ms at rest: Activate goes through, the reversal state stays.
        for _ in 0..12_000 {
            rig.tick(&mut engine.borrow_mut(), PERIOD_US);
        }
        let before = engine.borrow().telemetry().model_corr_nm;
        let r = server.handle(Request::Activate, rig.clock.0.get(), engine);
        defmt::assert!(
            matches!(r, Response::Activated(_)),
            "{}",
            defmt::Debug2Format(&r)
        );
        rig.tick(&mut engine.borrow_mut(), PERIOD_US);
        defmt::assert_eq!(engine.borrow().telemetry().model_corr_nm, before);
        defmt::info!("Activate: refused while X moves, at rest it keeps the reversal state");
    }
}
