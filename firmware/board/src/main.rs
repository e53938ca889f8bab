//! trueaxis compensation board firmware (STM32F405RG). `main` only wires
//! things up: clocks and peripherals (board.rs), the shared state
//! (shared.rs), then one task per concern:
//!
//! - `correction` — on the high-priority interrupt executor, every 50 µs:
//!   encoders → model → envelope/slew → step pulses (trueaxis_app::engine);
//! - `usb_device`, `usb_link`, `uart_link` — the link protocol on USB
//!   CDC-ACM and USART1 (trueaxis_app::server);
//! - `thermistors` — ADC readings → m°C, 10 Hz;
//! - `watchdog` — pets the IWDG while the correction loop is alive.
//!
//! Boot: the table store scans both flash slots and the newest valid table
//! becomes the active model before the loop starts — unless it was on
//! trial when a fault reset the board (reset.rs, trueaxis_app::boot): then
//! it is revoked and the other slot's table runs. The watchdog task also
//! confirms a table once it has run its trial window.
#![no_std]
#![no_main]

mod board;
mod link;
mod reset;
mod shared;

use core::cell::RefCell;
use core::sync::atomic::Ordering;

use defmt::{info, unwrap};
use defmt_rtt as _;
use embassy_executor::Executor;
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, Ticker, Timer};
use static_cell::StaticCell;

use trueaxis_app::engine::Engine;
use trueaxis_app::hw::{Clock, TemperatureSource};
use trueaxis_app::server::{Server, ServerConfig};
use trueaxis_app::store::TableStore;
use trueaxis_protocol::LINK_TEMPS;

use crate::shared::SharedEngine;

/// How long the axes must stand still before a flash erase (see
/// trueaxis_app::server on the single-bank policy).
const QUIET_MS: u32 = 500;

#[cortex_m_rt::entry]
fn main() -> ! {
    // First: a stack overflow faults from here on (trueaxis_stack_guard).
    trueaxis_stack_guard::enable();
    let cause = reset::reset_cause();
    let record = reset::read_record();
    let p = embassy_stm32::init(board::clocks());
    info!("trueaxis board {}", trueaxis_app::FIRMWARE_VERSION);
    let parts = board::take(p);

    let engine = shared::ENGINE.init(SharedEngine(BlockingMutex::new(RefCell::new(unwrap!(
        Engine::new(board::ENGINE)
    )))));
    let store = unwrap!(TableStore::new(parts.flash, board::LAYOUT));
    let mut server = Server::new(
        store,
        shared::STAGE.take(),
        [shared::MODEL_A.take(), shared::MODEL_B.take()],
        ServerConfig {
            firmware: trueaxis_app::FIRMWARE_VERSION,
            quiet_ms: QUIET_MS,
            model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
        },
    );
    static RECORD_RAM: StaticCell<reset::RecordRam> = StaticCell::new();
    server.set_reset_record(RECORD_RAM.init(reset::RecordRam));
    let booted = server.boot_after_reset(engine, cause, record);
    if let Some(f) = booted.failed {
        defmt::warn!(
            "table seq {} failed its trial ({}): revoked, falling back",
            f.table.seq,
            f.fault
        );
    }
    match booted.active {
        Some(t) => info!(
            "active table: slot {} seq {} crc {=u32:#x}",
            t.slot, t.seq, t.crc32
        ),
        None => info!("no valid table: correction stays at zero"),
    }
    let server = shared::SERVER.init(Mutex::new(server));

    let high = board::start_high();
    high.spawn(unwrap!(correction(engine, parts.encoders, parts.steps)));

    static EXECUTOR: StaticCell<Executor> = StaticCell::new();
    EXECUTOR.init(Executor::new()).run(|spawner| {
        let (device, usb_class) = link::usb(parts.usb);
        spawner.spawn(unwrap!(link::usb_device(device)));
        spawner.spawn(unwrap!(link::usb_link(usb_class, server, engine)));
        spawner.spawn(unwrap!(link::uart_link(parts.uart, server, engine)));
        spawner.spawn(unwrap!(thermistors(parts.thermistors)));
        spawner.spawn(unwrap!(watchdog(parts.iwdg, server, engine)));
    })
}

/// embassy-time as the engine's clock.
struct BoardClock;

impl Clock for BoardClock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
}

/// The thermistor temperatures published by the thermistor task.
struct SharedTemps;

impl TemperatureSource for SharedTemps {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        core::array::from_fn(|i| shared::TEMPS_MC[i].load(Ordering::Relaxed))
    }
}

#[embassy_executor::task]
async fn correction(
    engine: &'static SharedEngine,
    mut encoders: board::BoardEncoders,
    mut steps: board::StepDir,
) {
    let mut ticker = Ticker::every(Duration::from_hz(board::LOOP_HZ));
    let mut temps = SharedTemps;
    loop {
        ticker.next().await;
        engine.0.lock(|e| {
            e.borrow_mut()
                .tick(&BoardClock, &mut encoders, &mut temps, &mut steps)
        });
        shared::TICKS.fetch_add(1, Ordering::Relaxed);
    }
}

#[embassy_executor::task]
async fn thermistors(mut t: board::Thermistors) {
    loop {
        let raw = t.read_raw();
        for (i, r) in raw.into_iter().enumerate() {
            shared::TEMPS_MC[i].store(board::NTC.temp_mc(r), Ordering::Relaxed);
        }
        Timer::after_millis(100).await;
    }
}

/// Pets the watchdog only while the correction loop makes progress: a
/// stuck loop (or a stuck thread executor, which runs this task) resets
/// the board. Also confirms the running table once its trial window has
/// passed (trueaxis_app::boot).
#[embassy_executor::task]
async fn watchdog(
    mut iwdg: embassy_stm32::wdg::IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    server: &'static shared::ServerMutex,
    engine: &'static SharedEngine,
) {
    iwdg.unleash();
    let mut last = shared::TICKS.load(Ordering::Relaxed);
    loop {
        Timer::after_millis(250).await;
        let now = shared::TICKS.load(Ordering::Relaxed);
        if now != last {
            iwdg.pet();
        }
        // Never wait for the server here (a link task may hold it): the
        // trial is confirmed at the next round instead.
        if let Ok(mut s) = server.try_lock() {
            s.poll_trial(engine);
        }
        last = now;
    }
}
