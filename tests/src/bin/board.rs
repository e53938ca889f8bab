//! The end-to-end board image: the real application core (trueaxis-app's
//! link server, A/B table store and correction engine) and model-core on
//! QEMU's STM32F405, under embassy-executor with the SysTick time driver.
//!
//! What differs from the board binary is only what QEMU cannot emulate:
//! the link is USART1 through the PAC (QEMU puts it on a TCP socket), the
//! two table slots are a RAM-backed NOR flash (QEMU models no flash
//! controller; the slots are 6 KiB here instead of 128 KiB to fit RAM),
//! and the encoders and temperatures are constant fakes — positions reach
//! the engine through the link's `Inject` requests, which is how the
//! end-to-end test drives a trajectory.
#![no_std]
#![no_main]

#[path = "../rig.rs"]
#[allow(dead_code)] // each image uses part of it
mod rig;

use core::cell::RefCell;

use critical_section::Mutex;
use embassy_time::{Duration, Instant, Ticker};
use trueaxis_app::engine::Engine;
use trueaxis_app::hw::{Clock, Encoders, StepOutput, TemperatureSource};
use trueaxis_app::memflash::MemFlash;
use trueaxis_app::model::ModelBuf;
use trueaxis_app::server::{EngineAccess, Port, Server, ServerConfig};
use trueaxis_app::store::{Layout, TableStore};
use trueaxis_protocol::LINK_TEMPS;
use trueaxis_qemu::{executor::WfiExecutor, time_driver, usart::Usart1};

/// One table slot (header + table), bytes: three erase units. Small
/// because RAM is: the two RAM-resident models take 53 KiB and the stack
/// 48 KiB (qemu.x); a fitted cubic19 table is about 1 KiB.
const SLOT_BYTES: usize = 6 * 1024;
/// Erase unit of the fake (the real slots are one 128 KiB sector).
const ERASE_BYTES: usize = 2 * 1024;
/// The flash fake: slot A, then slot B.
type Flash = MemFlash<&'static mut [u8; 2 * SLOT_BYTES], 4, ERASE_BYTES>;

/// The correction loop's period: 10 ms, not the board's 50 µs. The
/// SysTick time driver has 1 ms granularity (an alarm fires up to 1 ms
/// late) and, while the guest idles, QEMU's virtual clock follows the
/// host's, so successive ticks of a 1 ms loop came 0–2.7 ms apart and the
/// engine counted a loop overrun (gap ≥ 2 periods) on about one tick in
/// five — a fault, which ramps the output to zero. At 10 ms that jitter is
/// far from the 20 ms threshold; the end-to-end check still clears and
/// counts the overruns a descheduled QEMU produces.
const PERIOD_US: u32 = 10_000;

/// The engine, shared by the correction loop and the link server.
static ENGINE: Mutex<RefCell<Option<Engine<'static>>>> = Mutex::new(RefCell::new(None));

/// [`EngineAccess`] through the critical-section mutex (both tasks run in
/// thread mode here; the mutex keeps the board's structure, where the loop
/// runs at interrupt priority).
struct SharedEngine;

impl EngineAccess<'static> for SharedEngine {
    fn with_engine<R>(&self, f: impl FnOnce(&mut Engine<'static>) -> R) -> R {
        critical_section::with(|cs| {
            let mut engine = ENGINE.borrow_ref_mut(cs);
            f(engine
                .as_mut()
                .expect("the engine is created before the tasks run"))
        })
    }
}

/// embassy-time as the engine's clock.
struct EmbassyClock;

impl Clock for EmbassyClock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
}

/// A machine at rest at the origin (injections override it).
struct RestingEncoders;

impl Encoders for RestingEncoders {
    fn read_counts(&mut self) -> [i32; 3] {
        [0; 3]
    }
}

/// A room at 20 °C.
struct ConstantTemps;

impl TemperatureSource for ConstantTemps {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        [20_000; LINK_TEMPS]
    }
}

/// Counts the pulses instead of driving pins.
struct CountingSteps {
    net: [i64; 3],
}

impl StepOutput for CountingSteps {
    fn pulses(&mut self, axis: usize, steps: i32) {
        self.net[axis] += i64::from(steps);
    }
}

#[embassy_executor::task]
async fn correction_loop() {
    let mut ticker = Ticker::every(Duration::from_micros(u64::from(PERIOD_US)));
    let mut enc = RestingEncoders;
    let mut temps = ConstantTemps;
    let mut steps = CountingSteps { net: [0; 3] };
    loop {
        SharedEngine.with_engine(|e| e.tick(&EmbassyClock, &mut enc, &mut temps, &mut steps));
        ticker.next().await;
    }
}

#[embassy_executor::task]
async fn link(mut uart: Usart1, mut server: Server<'static, 'static, Flash>) {
    let mut port = Port::new();
    let mut buf = [0u8; 64];
    loop {
        let n = uart.read(&mut buf).await;
        let now_us = Instant::now().as_micros();
        server.handle_bytes(&mut port, &buf[..n], now_us, &SharedEngine, |frame| {
            uart.write(frame)
        });
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let core = cortex_m::Peripherals::take().expect("first take");
    time_driver::start(core.SYST);

    let engine = match Engine::new(rig::engine_config(PERIOD_US)) {
        Ok(e) => e,
        Err(e) => defmt::panic!("engine config refused: {}", defmt::Debug2Format(&e)),
    };
    critical_section::with(|cs| *ENGINE.borrow_ref_mut(cs) = Some(engine));

    let mem = cortex_m::singleton!(: [u8; 2 * SLOT_BYTES] = [0xFF; 2 * SLOT_BYTES]).expect("once");
    let layout = Layout {
        slot_offset: [0, SLOT_BYTES as u32],
        slot_bytes: SLOT_BYTES as u32,
    };
    let store = match TableStore::new(Flash::new_erased(mem), layout) {
        Ok(s) => s,
        Err(e) => defmt::panic!("flash layout refused: {}", defmt::Debug2Format(&e)),
    };
    let stage = cortex_m::singleton!(: [u8; SLOT_BYTES] = [0; SLOT_BYTES]).expect("once");
    // Two RAM-resident models: the active one and the one a new table is
    // loaded into (the correction never waits for a load).
    let model_a = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
    let model_b = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
    let mut server = Server::new(
        store,
        &mut stage[..],
        [model_a, model_b],
        ServerConfig {
            firmware: trueaxis_app::FIRMWARE_VERSION,
            quiet_ms: 20,
            // The real board's loop budget (model_core::board).
            model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
        },
    );
    let booted = server.boot(&SharedEngine);
    defmt::info!("board: booted, active table: {}", booted.is_some());

    let uart = Usart1::new();
    defmt::info!("board: link on USART1");
    let executor = cortex_m::singleton!(: WfiExecutor = WfiExecutor::new()).expect("once");
    executor.run(|spawner| {
        spawner.spawn(correction_loop().expect("spawns once"));
        spawner.spawn(link(uart, server).expect("spawns once"));
    })
}
