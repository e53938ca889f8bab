//! The boot fallback on the emulated STM32F405 (trueaxis_app::boot): a
//! table that faults the board during its trial window is left by the
//! next boot for the previous table, by itself — through a real reset.
//!
//! QEMU's netduinoplus2 keeps RAM through `SCB::sys_reset` (measured:
//! cortex-m-rt zeroes `.bss` and reloads `.data`, a `.uninit` section
//! keeps its words; docs/qemu.md), so this image runs the whole story in
//! one QEMU run over three boots, with the RAM flash (two 6 KiB slots,
//! 2 KiB erase units) and the boot record both in `.uninit`:
//!
//! 1. cold boot: commit table A (cubic19) through the link server, run
//!    its trial window until the server confirms it, commit table B
//!    (full) — the server runs it at once, on trial — and fault while it
//!    runs: a **panic injected by this image** 50 ticks into B (no table
//!    that passes the checks can crash the engine, so the test supplies
//!    the crash); the fault hook records it and resets;
//! 2. the boot finds B on trial with a panic recorded: B revoked, A runs,
//!    `TRIAL_FAILED | RESET_BY_PANIC` latched. Commit B again and fault
//!    with a HardFault (`udf`) this time;
//! 3. the same fallback, `RESET_BY_HARDFAULT`; A is confirmed again and
//!    the image exits 0.
//!
//! What QEMU does not model is the reset flags (RCC_CSR): the image tells
//! a cold boot from a reset by its own `.uninit` magic, which is what the
//! board's reset flags say on hardware (reset.rs in the board crate).
#![no_std]
#![no_main]
#![allow(unsafe_code)] // `.uninit` statics: RAM that survives the reset

#[path = "../rig.rs"]
#[allow(dead_code)] // each image uses part of it
mod rig;

use core::cell::{Cell, RefCell};
use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use rig::{FakeClock, Flash, SLOT};
use trueaxis_app::boot::{BootRecord, Fault, ResetCause, RECORD_WORDS};
use trueaxis_app::engine::Engine;
use trueaxis_app::hw::{Encoders, StepOutput, TemperatureSource};
use trueaxis_app::model::ModelBuf;
use trueaxis_app::server::{ResetRecord, Server, ServerConfig};
use trueaxis_app::store::{Layout, TableStore};
use trueaxis_protocol::{table_id, Faults, Response, LINK_TEMPS};
use trueaxis_qemu::{exit, set_fault_hook, FaultKind};

static TABLE_A: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.bin"));
static TABLE_B: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/full.bin"));

const PERIOD_US: u32 = 10_000;
/// Ticks into table B at which the image injects its fault.
const FAULT_AT_TICK: u32 = 50;
/// Marks the image's own `.uninit` words as written (not a cold boot).
const MAGIC: u32 = 0xFA11_BAC6;

#[unsafe(link_section = ".uninit.fallback_flash")]
static mut FLASH_MEM: MaybeUninit<[u8; 2 * SLOT]> = MaybeUninit::uninit();
#[unsafe(link_section = ".uninit.fallback_record")]
static mut RECORD: MaybeUninit<[u32; RECORD_WORDS]> = MaybeUninit::uninit();
/// [MAGIC, boot number]: which step of the story this boot is.
#[unsafe(link_section = ".uninit.fallback_step")]
static mut STEP: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

fn record_ptr() -> *mut [u32; RECORD_WORDS] {
    addr_of_mut!(RECORD).cast()
}

fn step_ptr() -> *mut [u32; 2] {
    addr_of_mut!(STEP).cast()
}

/// The server's boot record, in `.uninit` RAM.
struct RecordRam;

impl ResetRecord for RecordRam {
    fn write(&mut self, words: [u32; RECORD_WORDS]) {
        // SAFETY: single-threaded, volatile, any bit pattern is valid.
        unsafe { write_volatile(record_ptr(), words) }
    }
}

/// The board's fault handlers: record the fault, reset.
fn record_and_reset(kind: FaultKind) -> ! {
    // SAFETY: as in `RecordRam`; nothing runs after this.
    unsafe { rig::record_and_reset(record_ptr(), "fallback", kind) }
}

struct Resting;

impl Encoders for Resting {
    fn read_counts(&mut self) -> [i32; 3] {
        [0; 3]
    }
}

impl TemperatureSource for Resting {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        [20_000; LINK_TEMPS]
    }
}

impl StepOutput for Resting {
    fn pulses(&mut self, _axis: usize, _steps: i32) {}
}

type BoardServer = Server<'static, 'static, Flash>;

/// Uploads and commits `table` through the server's request handler.
fn install(server: &mut BoardServer, engine: &RefCell<Engine<'static>>, now: u64, table: &[u8]) {
    match rig::upload_and_commit(server, engine, now, table) {
        Response::Committed(info) => defmt::info!("fallback: committed seq {}", info.seq),
        r => defmt::panic!("commit refused: {}", defmt::Debug2Format(&r)),
    }
}

fn active_crc(engine: &RefCell<Engine<'static>>) -> Option<u32> {
    engine.borrow().active().map(|a| a.crc32)
}

#[cortex_m_rt::entry]
fn main() -> ! {
    // SAFETY: single-threaded; the `.uninit` words are plain integers.
    let step = unsafe { read_volatile(step_ptr()) };
    let (boot, cause) = if step[0] == MAGIC {
        (step[1], ResetCause::Other)
    } else {
        (0, ResetCause::PowerOn)
    };
    // SAFETY: the only reference to FLASH_MEM, made once.
    let mem: &'static mut [u8; 2 * SLOT] = unsafe { &mut *addr_of_mut!(FLASH_MEM).cast() };
    let flash = if boot == 0 {
        Flash::new_erased(mem)
    } else {
        Flash::from_contents(mem)
    };
    unsafe { write_volatile(step_ptr(), [MAGIC, boot + 1]) };
    defmt::info!("fallback: boot {} ({})", boot, cause);

    let engine = RefCell::new(Engine::new(rig::engine_config(PERIOD_US)).expect("valid config"));
    let layout = Layout {
        slot_offset: [0, SLOT as u32],
        slot_bytes: SLOT as u32,
    };
    let store = TableStore::new(flash, layout).expect("layout fits");
    let stage = cortex_m::singleton!(: [u8; SLOT] = [0; SLOT]).expect("once");
    let model_a = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
    let model_b = cortex_m::singleton!(: ModelBuf = ModelBuf::new()).expect("once");
    let sink = cortex_m::singleton!(: RecordRam = RecordRam).expect("once");
    let mut server: BoardServer = Server::new(
        store,
        &mut stage[..],
        [model_a, model_b],
        ServerConfig {
            firmware: trueaxis_app::FIRMWARE_VERSION,
            quiet_ms: 0,
            model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
        },
    );
    server.set_reset_record(sink);
    // SAFETY: as in `RecordRam`.
    let record = BootRecord::decode(&unsafe { read_volatile(record_ptr()) });
    let report = server.boot_after_reset(&engine, cause, record);

    let clock = FakeClock(Cell::new(0));
    let mut io = (Resting, Resting, Resting);
    let mut tick = |server: &mut BoardServer| {
        clock.0.set(clock.0.get() + u64::from(PERIOD_US));
        engine
            .borrow_mut()
            .tick(&clock, &mut io.0, &mut io.1, &mut io.2);
        server.poll_trial(&engine)
    };
    let (a, b) = (table_id(TABLE_A), table_id(TABLE_B));

    match boot {
        0 => {
            defmt::assert!(report.active.is_none() && report.failed.is_none());
            install(&mut server, &engine, clock.0.get(), TABLE_A);
            let mut n = 0u32;
            while !tick(&mut server) {
                n += 1;
            }
            defmt::info!("fallback: table A confirmed after {} ticks", n + 1);
            install(&mut server, &engine, clock.0.get(), TABLE_B);
            defmt::assert_eq!(active_crc(&engine), Some(b));
            for _ in 0..FAULT_AT_TICK {
                tick(&mut server);
            }
            // From here a fault resets, as on the board; before, a failed
            // check ends the run with exit 1 (never a reset loop).
            set_fault_hook(record_and_reset);
            defmt::panic!("injected fault: table B crashes the correction loop");
        }
        1 | 2 => {
            let fault = if boot == 1 {
                Fault::Panic
            } else {
                Fault::HardFault
            };
            let failed = report.failed.expect("table B's trial failed");
            defmt::assert_eq!(failed.table.crc32, b);
            defmt::assert_eq!(failed.fault, fault);
            defmt::assert_eq!(report.active.map(|t| t.crc32), Some(a));
            defmt::assert_eq!(active_crc(&engine), Some(a));
            let latched = engine.borrow().telemetry().faults_latched;
            defmt::assert!(latched.contains(Faults::TRIAL_FAILED.union(fault.bit())));
            defmt::assert!(!engine.borrow().faults().contains(Faults::TRIAL_FAILED));
            let standby = server.store().standby();
            defmt::assert!(standby.is_none(), "table B is revoked");
            defmt::info!(
                "fallback: boot {} runs table A again, table B revoked ({})",
                boot,
                failed.fault
            );
            if boot == 1 {
                install(&mut server, &engine, clock.0.get(), TABLE_B);
                for _ in 0..FAULT_AT_TICK {
                    tick(&mut server);
                }
                defmt::info!("fallback: injecting a HardFault under table B");
                set_fault_hook(record_and_reset);
                cortex_m::asm::udf()
            }
            let mut n = 0u32;
            while !tick(&mut server) {
                n += 1;
            }
            defmt::info!("fallback: table A confirmed again after {} ticks", n + 1);
            defmt::info!("fallback: a crashing table was left by itself, twice");
            exit(0)
        }
        n => defmt::panic!("boot {}: the story has three boots", n),
    }
}
