//! What the images and suites that run the application core share: the
//! engine configuration they start from, a clock they set by hand, the
//! link server's RAM flash and its upload, and the boot record's fault
//! path (record the fault, reset) with the recursion that overflows the
//! stack.
//!
//! Included by those images (`#[path]`), not a module of the library: the
//! bench image links the library, and code there (used or not) changed
//! how fat LTO compiled the bench's evaluators (`poly_deg5_f32` 793 →
//! 1159 instructions).

use core::cell::{Cell, RefCell};
use core::ptr::{read_volatile, write_volatile};

use trueaxis_app::boot::{BootRecord, Fault, RECORD_WORDS};
use trueaxis_app::engine::{AxisConfig, Engine, EngineConfig};
use trueaxis_app::hw::Clock;
use trueaxis_app::memflash::MemFlash;
use trueaxis_app::server::Server;
use trueaxis_protocol::{table_id, Request, Response, Slot, SlotInfo, MAX_CHUNK_BYTES};

use trueaxis_qemu::FaultKind;

/// The engine configuration the images start from: 25 nm per count
/// (0.1 µm scale in quadrature), 100 nm pulses, no jump check (injected
/// positions jump along the trajectory), 32-bit counts, no home switch,
/// 64 steps per tick, no thermistor, ticks every `period_us`.
pub fn engine_config(period_us: u32) -> EngineConfig {
    let axis = AxisConfig {
        pm_per_count: 25_000,
        origin_nm: 0,
        pulse_nm: 100,
        max_speed_nm_per_ms: 0,
        counter_bits: 32,
        home: None,
    };
    EngineConfig {
        axes: [axis; 3],
        period_us,
        max_steps_per_tick: 64,
        temps_used: 0,
        temp_min_mc: -20_000,
        temp_max_mc: 80_000,
        fault_ramp_nm_per_ms: 50,
        tool_nm: 0,
    }
}

/// A clock the test sets, µs.
pub struct FakeClock(pub Cell<u64>);

impl Clock for FakeClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

/// Where the suites say `table` runs: slot A, sequence 1.
pub fn info(table: &[u8]) -> SlotInfo {
    SlotInfo {
        slot: Slot::A,
        seq: 1,
        len: table.len() as u32,
        crc32: table_id(table),
    }
}

/// A flash slot of the link server's RAM flash.
pub const SLOT: usize = 6 * 1024;
/// The link server's RAM flash: two 6 KiB slots, 2 KiB erase units.
pub type Flash = MemFlash<&'static mut [u8; 2 * SLOT], 4, 2048>;

/// Uploads `table` through the server's request handler (each chunk
/// acknowledged) and commits it: the commit's answer.
pub fn upload_and_commit(
    server: &mut Server<'static, 'static, Flash>,
    engine: &RefCell<Engine<'static>>,
    now: u64,
    table: &[u8],
) -> Response {
    let size = table.len() as u32;
    let crc32 = table_id(table);
    let r = server.handle(Request::UploadBegin { size, crc32 }, now, engine);
    defmt::assert!(matches!(r, Response::UploadAck { .. }));
    for (i, data) in table.chunks(MAX_CHUNK_BYTES).enumerate() {
        let offset = (i * MAX_CHUNK_BYTES) as u32;
        let r = server.handle(Request::UploadChunk { offset, data }, now, engine);
        defmt::assert!(matches!(r, Response::UploadAck { .. }));
    }
    server.handle(Request::Commit, now, engine)
}

/// The board's fault handlers: records `kind` in the boot record at
/// `record` (RAM that survives the reset) and resets; `image` names the
/// image in the log.
///
/// # Safety
/// `record` points at the boot record's words, valid for reads and
/// writes, and nothing else runs (single-threaded, a fault path).
#[allow(unsafe_code)] // the boot record's `.uninit` words
pub unsafe fn record_and_reset(
    record: *mut [u32; RECORD_WORDS],
    image: &str,
    kind: FaultKind,
) -> ! {
    let fault = match kind {
        FaultKind::Panic => Fault::Panic,
        FaultKind::HardFault => Fault::HardFault,
    };
    // SAFETY: the caller's; any bit pattern is valid.
    let mut w = unsafe { read_volatile(record) };
    BootRecord::record_fault(&mut w, fault);
    unsafe { write_volatile(record, w) };
    defmt::info!("{=str}: {} recorded, resetting", image, kind);
    cortex_m::peripheral::SCB::sys_reset()
}

/// Recurses with 1 KiB frames until the stack runs out.
#[inline(never)]
#[allow(unconditional_recursion)] // the point of the images that call it
pub fn deeper(depth: u32) -> u32 {
    let frame = core::hint::black_box([depth as u8; 1024]);
    deeper(depth + 1).wrapping_add(u32::from(frame[1000]))
}
