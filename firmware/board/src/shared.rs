//! Every static that more than one task touches, with who writes and who
//! reads it. Nothing else in the firmware is shared.
//!
//! | static | written by | read by |
//! | --- | --- | --- |
//! | [`ENGINE`] | correction task (every tick); link tasks through the server (model swap, injection, clear faults) | the same |
//! | [`SERVER`] | link tasks (USB and UART, one request at a time); watchdog task (confirms a table's trial) | the same |
//! | [`TEMPS_MC`] | thermistor task (10 Hz) | correction task |
//! | [`TICKS`] | correction task | watchdog task |
//!
//! The engine is behind a critical-section mutex: the correction task runs
//! at interrupt priority, so the link tasks' short accesses must not be
//! preempted by it half-way; each access is a few µs (the model swap is a
//! reference swap, see trueaxis_app::model). The server is behind an async
//! mutex on the thread executor (the two link tasks take turns); it owns
//! the flash and the staging buffer, so they need no lock of their own.

use core::cell::RefCell;
use core::sync::atomic::{AtomicI32, AtomicU32};

use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_sync::mutex::Mutex;
use static_cell::{ConstStaticCell, StaticCell};
use trueaxis_app::engine::Engine;
use trueaxis_app::model::ModelBuf;
use trueaxis_app::server::{EngineAccess, Server};
use trueaxis_protocol::LINK_TEMPS;

/// The engine, shared between the correction loop and the link server.
pub struct SharedEngine(pub BlockingMutex<CriticalSectionRawMutex, RefCell<Engine<'static>>>);

impl EngineAccess<'static> for SharedEngine {
    fn with_engine<R>(&self, f: impl FnOnce(&mut Engine<'static>) -> R) -> R {
        self.0.lock(|e| f(&mut e.borrow_mut()))
    }
}

/// The link server type of the board.
pub type BoardServer = Server<'static, 'static, crate::board::TableFlash>;

/// Largest table the board accepts over the link, bytes (the staging
/// buffer; a slot could hold 128 KiB, RAM cannot). Defined in model-core,
/// where the host checks tables against it.
pub const STAGE_BYTES: usize = model_core::board::STAGE_BYTES;

/// See the table above.
pub static ENGINE: StaticCell<SharedEngine> = StaticCell::new();
/// The server behind its async mutex.
pub type ServerMutex = Mutex<ThreadModeRawMutex, BoardServer>;

/// See the table above.
pub static SERVER: StaticCell<ServerMutex> = StaticCell::new();
/// See the table above. `i32::MIN` until the first reading (a sensor
/// fault for the engine, so the correction waits for real temperatures).
pub static TEMPS_MC: [AtomicI32; LINK_TEMPS] = [const { AtomicI32::new(i32::MIN) }; LINK_TEMPS];
/// See the table above.
pub static TICKS: AtomicU32 = AtomicU32::new(0);

/// The two model buffers (≈ 16.3 KiB each): one runs, one receives the next
/// table. Owned by the server and the engine in turn, never shared.
/// `ConstStaticCell`: initialised in place, never built on the stack.
pub static MODEL_A: ConstStaticCell<ModelBuf> = ConstStaticCell::new(ModelBuf::new());
/// See [`MODEL_A`].
pub static MODEL_B: ConstStaticCell<ModelBuf> = ConstStaticCell::new(ModelBuf::new());
/// Upload staging buffer (owned by the server).
pub static STAGE: ConstStaticCell<[u8; STAGE_BYTES]> = ConstStaticCell::new([0; STAGE_BYTES]);
