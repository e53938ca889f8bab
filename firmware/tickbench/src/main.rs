//! How many instructions one tick of the correction engine costs on the
//! Cortex-M4F, measured under `qemu-system-arm -M netduinoplus2 -icount
//! shift=0` (one instruction = 1 ns of virtual time, so TIM2 at prescaler 0
//! counts instructions exactly — the method of the QEMU bench image).
//! Instructions, not cycles: a lower bound for the real chip.
//!
//! Run: `cargo build --release -p trueaxis-tickbench`, then
//! `qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial null
//! -semihosting-config enable=on,target=native -icount shift=0 -kernel
//! $CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/tickbench`.
//!
//! Cases: the engine without a table (its own overhead: sensors,
//! direction tracking, slew, pulse accumulator), then with each table while
//! the axes move: the simulated board's sample table (polynomials,
//! reversal, thermal) and model-core's golden tables — `all_kinds` (every
//! term kind in one table, a two-layer 4-16-16-3 network among them) is
//! the worst realistic case — and the engine's export of a fitted rigid21
//! model (tests/golden/rigid21.bin, with a 150 mm tool). Step pulses are counted, not bit-banged (the
//! board's bit-banging costs 2 µs per pulse by construction).
//!
//! Output (semihosting stdout): `BUDGET period=… tick=… engine=… model=…`
//! (model-core's `board` constants) and one `TICK name min=… mean=… max=…
//! faults=… est_fixed=…` line per case, `est_fixed` being model-core's
//! static estimate of the table's fixed-point evaluation (the one the
//! board's admission at commit uses). `cargo xtask test` runs this image
//! and checks every tick against them.
#![no_std]
#![no_main]

use core::cell::Cell;
use core::hint::black_box;

use model_core::board;
use semihosting::println;
use stm32_metapac::TIM2;
use trueaxis_app::engine::{Approach, AxisConfig, Engine, EngineConfig, HomeSwitch};
use trueaxis_app::hw::{Clock, Encoders, StepOutput, TemperatureSource};
use trueaxis_app::model::{load_into, ModelBuf};
use trueaxis_protocol::{Slot, SlotInfo, LINK_TEMPS};

// The QEMU crate's TIM2 set-up (one copy), included by path: linking that
// crate would bring its defmt logger and handlers into this image.
#[path = "../../../tests/src/tim2.rs"]
mod tim2;

/// The tables, by name.
static TABLES: [(&str, &[u8]); 7] = [
    (
        "sample_table",
        include_bytes!(concat!(env!("OUT_DIR"), "/sample.bin")),
    ),
    (
        "cubic19",
        include_bytes!("../../../model-core/tests/golden/cubic19.bin"),
    ),
    (
        "full",
        include_bytes!("../../../model-core/tests/golden/full.bin"),
    ),
    (
        "nn_3x16x3",
        include_bytes!("../../../model-core/tests/golden/nn_3x16x3.bin"),
    ),
    (
        "grid_17x11",
        include_bytes!("../../../model-core/tests/golden/grid_17x11.bin"),
    ),
    (
        "all_kinds",
        include_bytes!("../../../model-core/tests/golden/all_kinds.bin"),
    ),
    // The engine's export of a fitted rigid21:4 model (issue 26): ticked
    // with a 150 mm tool (`RIGID21_TOOL_NM`), so its Abbe blocks carry an arm.
    (
        "rigid21",
        include_bytes!("../../../tests/golden/rigid21.bin"),
    ),
];

/// The tool length the rigid21 case ticks with, nm.
const RIGID21_TOOL_NM: i32 = 150_000_000;

/// The board's home switch (firmware/board/src/board.rs).
const HOME: HomeSwitch = HomeSwitch {
    pos_nm: 0,
    approach: Approach::Negative,
    debounce_ticks: 4,
    tolerance_nm: 100_000,
};

/// The board's configuration (firmware/board/src/board.rs).
const CONFIG: EngineConfig = EngineConfig {
    axes: [AxisConfig {
        pm_per_count: 25_000,
        origin_nm: 0,
        pulse_nm: 100,
        max_speed_nm_per_ms: 500_000,
        counter_bits: 16,
        home: Some(HOME),
    }; 3],
    period_us: 50,
    max_steps_per_tick: 2,
    temps_used: 4,
    temp_min_mc: -20_000,
    temp_max_mc: 80_000,
    fault_ramp_nm_per_ms: 1_000,
    tool_nm: 0,
};

struct Fake {
    counts: [i32; 3],
    pulses: i64,
}

impl Encoders for Fake {
    fn read_counts(&mut self) -> [i32; 3] {
        // Every axis moving, X fastest: 20 counts per tick = 10 mm/s.
        self.counts[0] += 20;
        self.counts[1] -= 7;
        self.counts[2] += 3;
        black_box(self.counts)
    }
}

struct Temps;

impl TemperatureSource for Temps {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        black_box([21_500; LINK_TEMPS])
    }
}

impl StepOutput for Fake {
    fn pulses(&mut self, _axis: usize, steps: i32) {
        self.pulses += black_box(steps) as i64;
    }
}

struct TickClock(Cell<u64>);

impl Clock for TickClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

fn counter() -> u32 {
    TIM2.cnt().read()
}

/// Runs `n` ticks and reports min / mean / max instructions per tick, with
/// the table's estimate.
fn run(name: &str, engine: &mut Engine<'_>, n: u32, est_fixed: u32) {
    let clock = TickClock(Cell::new(0));
    let mut io = Fake {
        counts: [0; 3],
        pulses: 0,
    };
    let mut temps = Temps;
    // Overhead of two counter reads.
    let a = counter();
    let b = counter();
    let overhead = b.wrapping_sub(a);
    let (mut min, mut max, mut total) = (u32::MAX, 0u32, 0u64);
    for k in 0..n + 16 {
        clock.0.set(clock.0.get() + 50);
        let t0 = counter();
        engine.tick(
            &clock,
            &mut io,
            &mut temps,
            &mut Fake {
                counts: [0; 3],
                pulses: 0,
            },
        );
        let t1 = counter();
        if k >= 16 {
            let d = t1.wrapping_sub(t0).wrapping_sub(overhead);
            min = min.min(d);
            max = max.max(d);
            total += d as u64;
        }
    }
    let faults = engine.faults().0;
    println!(
        "TICK {} min={} mean={} max={} faults={:#x} est_fixed={}",
        name,
        min,
        total / n as u64,
        max,
        faults,
        est_fixed
    );
}

#[cortex_m_rt::entry]
fn main() -> ! {
    tim2::start_free_running();

    println!(
        "BUDGET period={} tick={} engine={} model={}",
        board::PERIOD_INSTR,
        board::TICK_BUDGET_INSTR,
        board::ENGINE_TICK_INSTR,
        board::MODEL_BUDGET_INSTR
    );
    let Ok(mut engine) = Engine::new(CONFIG) else {
        panic!("board configuration refused")
    };
    run("no_table", &mut engine, 256, 0);

    let mut buf = ModelBuf::new();
    for (name, table) in TABLES {
        let Ok(parsed) = model_core::parse(table) else {
            panic!("table {} does not parse", name);
        };
        let est = model_core::cost::estimate(&parsed).fixed_instr;
        if load_into(table, &mut buf).is_err() {
            panic!("table {} does not load", name);
        }
        let info = SlotInfo {
            slot: Slot::A,
            seq: 1,
            len: table.len() as u32,
            crc32: trueaxis_protocol::table_id(table),
        };
        let cfg = EngineConfig {
            tool_nm: if name == "rigid21" {
                RIGID21_TOOL_NM
            } else {
                0
            },
            ..CONFIG
        };
        let mut engine = match Engine::new(cfg) {
            Ok(e) => e,
            Err(_) => panic!("board configuration refused"),
        };
        engine.set_model(&mut buf, info);
        // Referenced, so the ticks measured run the correcting path (an
        // unreferenced board holds the output at zero: faults=0x40).
        for axis in 0..3 {
            engine.reference(axis, 0);
        }
        run(name, &mut engine, 1024, est);
    }
    semihosting::process::exit(0)
}

/// A panic ends the run with status 1 (QEMU exits instead of hanging).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("panicked: {}", info);
    semihosting::process::exit(1)
}
