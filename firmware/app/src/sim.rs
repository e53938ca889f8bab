//! The simulated board (feature `std`): the application core with fake
//! encoders, thermistors, step outputs, clock and a RAM flash, served over
//! TCP or any byte stream (a pseudo-terminal, for the serial-port path).
//! The host tool's end-to-end tests run `trueaxis upload/status/monitor`
//! against it (`--port tcp://127.0.0.1:PORT`, and a pseudo-terminal), and
//! the `sim-board` binary runs it by hand. Also the sample tables the tests
//! upload.
//!
//! Time is simulated: the board ticks at its configured period, as many
//! ticks as wall-clock time has passed (capped per poll, so a slow test
//! machine is not reported as loop overruns — the engine sees simulated
//! time only).

use std::boxed::Box;
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use std::vec;
use std::vec::Vec;

use core::cell::{Cell, RefCell};

use model_core::spec::{GridAxisSpec, GridSpec, PolyCoef, TableSpec, TermSpec};
use model_core::{Envelope, InputScaling};
use trueaxis_protocol::LINK_TEMPS;

use crate::boot::{BootRecord, Fault, ResetCause, RECORD_WORDS};
use crate::engine::{AxisConfig, Engine, EngineConfig};
use crate::hw::{Clock, Encoders, StepOutput, TemperatureSource};
use crate::memflash::MemFlash;
use crate::model::ModelBuf;
use crate::server::{Port, ResetRecord, Server, ServerConfig};
use crate::store::{Layout, TableStore};

/// The RAM flash of the simulated board: two 64 KiB slots, 4-byte writes,
/// 4 KiB erase units.
pub type SimFlash = MemFlash<Vec<u8>, 4, 4096>;

/// Slot size of the simulated board.
pub const SIM_SLOT_BYTES: u32 = 64 * 1024;

/// Layout of [`SimFlash`].
pub const SIM_LAYOUT: Layout = Layout {
    slot_offset: [0, SIM_SLOT_BYTES],
    slot_bytes: SIM_SLOT_BYTES,
};

/// A plausible configuration: 1 kHz ticks (the simulation does not need
/// 20 kHz), 0.1 µm quadrature scales, 100 nm correction pulses.
pub fn sim_engine_config() -> EngineConfig {
    let axis = AxisConfig {
        pm_per_count: 100_000,
        origin_nm: 0,
        pulse_nm: 100,
        max_speed_nm_per_ms: 0,
        // The fake encoders are i32 counts: nothing to widen.
        counter_bits: 32,
        home: None,
    };
    EngineConfig {
        axes: [axis; 3],
        period_us: 1000,
        max_steps_per_tick: 64,
        temps_used: 2,
        temp_min_mc: -20_000,
        temp_max_mc: 80_000,
        fault_ramp_nm_per_ms: 1000,
        tool_nm: 0,
    }
}

/// A sample table: a cubic-ish polynomial in x, y and z on each output, a
/// reversal on x and a thermal term on channel 0; `variant` changes the
/// coefficients (so two uploads differ). Travel ±400 mm, |corr| ≤ 60 µm,
/// slew 500 nm/ms.
pub fn sample_table(variant: u32) -> Vec<u8> {
    sample_spec(variant).encode().expect("sample table encodes")
}

/// [`sample_spec`]`(0)` with one `n` × `n` grid on ex over the travel
/// (x and y, values `(i mod 97) · 10` nm) for its terms: the table the
/// limit tests grow past the board's capacity.
pub fn sample_grid_spec(n: u16) -> TableSpec {
    let mut spec = sample_spec(0);
    let ax = GridAxisSpec {
        nodes: n,
        origin_nm: -400_000_000,
        step_nm: 800_000_000 / (i32::from(n) - 1),
    };
    let one = GridAxisSpec {
        nodes: 1,
        origin_nm: 0,
        step_nm: 1,
    };
    spec.terms = vec![TermSpec::Grid(GridSpec {
        output: 0,
        axes: [ax, ax, one],
        values_nm: (0..usize::from(n) * usize::from(n))
            .map(|i| (i % 97) as f64 * 10.0)
            .collect(),
    })];
    spec
}

/// The [`TableSpec`] behind [`sample_table`].
pub fn sample_spec(variant: u32) -> TableSpec {
    let k = 1.0 + variant as f64 * 0.25;
    let poly = |output: u8, c: [f64; 4]| {
        let coefs: Vec<PolyCoef> = vec![
            ([0, 0, 0], c[0] * k),
            ([1, 0, 0], c[1] * k),
            ([0, 1, 0], c[2] * k),
            ([1, 1, 0], c[3]),
            ([3, 0, 0], -c[1] * 0.5),
            ([0, 0, 1], c[3] * 0.5),
        ];
        TermSpec::Poly { output, coefs }
    };
    let travel = 400_000_000;
    TableSpec {
        created_unix_s: 1_700_000_000 + variant as i64,
        source_hash: [variant as u8; 32],
        channels: vec!["bed".into(), "air".into()],
        envelope: Envelope {
            travel_min_nm: [-travel; 3],
            travel_max_nm: [travel; 3],
            max_corr_nm: [60_000; 3],
            max_slew_nm_per_ms: 500,
            temp_min_mc: [0, 0, 0, 0],
            temp_max_mc: [50_000, 50_000, 0, 0],
            tool_min_nm: 0,
            tool_max_nm: 300_000_000,
        },
        scaling: InputScaling {
            centre_nm: [0; 3],
            half_span_nm: [travel; 3],
        },
        outputs: [true, true, true],
        terms: vec![
            poly(0, [1500.0, 8000.0, -2000.0, 1200.0]),
            poly(1, [-700.0, 3000.0, 6000.0, -900.0]),
            poly(2, [300.0, -2500.0, 1000.0, 700.0]),
            TermSpec::Reversal {
                output: 0,
                axis: 0,
                transition_nm: 20_000,
                amplitude_nm: 2500.0,
            },
            TermSpec::Thermal {
                output: 1,
                channel: 0,
                t_ref_mc: 20_000,
                coefs_nm_per_k: vec![([0, 0, 0], 900.0), ([0, 1, 0], 400.0)],
            },
        ],
    }
}

/// Sensor values and emitted pulses of the simulated board, shared with
/// the test that drives it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimIo {
    /// Encoder counts per axis.
    pub counts: [i32; 3],
    /// Thermistor readings, m°C.
    pub temps_mc: [i32; LINK_TEMPS],
    /// Net pulses emitted per axis.
    pub pulses: [i64; 3],
}

impl SimIo {
    /// Room temperature everywhere, axes at 0.
    pub fn at_rest() -> Self {
        Self {
            temps_mc: [20_000; LINK_TEMPS],
            ..Self::default()
        }
    }
}

struct SharedIo(Arc<Mutex<SimIo>>);

impl Encoders for SharedIo {
    fn read_counts(&mut self) -> [i32; 3] {
        self.0.lock().map(|io| io.counts).unwrap_or_default()
    }
}

impl TemperatureSource for SharedIo {
    fn read_temps_mc(&mut self) -> [i32; LINK_TEMPS] {
        self.0.lock().map(|io| io.temps_mc).unwrap_or_default()
    }
}

impl StepOutput for SharedIo {
    fn pulses(&mut self, axis: usize, steps: i32) {
        if let Ok(mut io) = self.0.lock() {
            io.pulses[axis] += steps as i64;
        }
    }
}

/// A clock the simulation advances by hand.
#[derive(Debug, Default)]
pub struct SimClock(pub Cell<u64>);

impl Clock for SimClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

/// The board's RAM that survives a reset (not a power cut): where the
/// server keeps the boot record (crate::boot).
#[derive(Debug, Clone, Default)]
pub struct SimResetRam(Arc<Mutex<[u32; RECORD_WORDS]>>);

impl ResetRecord for SimResetRam {
    fn write(&mut self, words: [u32; RECORD_WORDS]) {
        *self.0.lock().unwrap() = words;
    }
}

/// The simulated board: application core + fakes, served over TCP by
/// [`SimBoard::serve`]. Its flash survives [`SimBoard::into_flash`] for a
/// "reboot" on the same contents; [`SimBoard::fault_reset`] resets it
/// keeping its RAM record too.
pub struct SimBoard {
    /// Sensor values and pulses.
    pub io: Arc<Mutex<SimIo>>,
    engine: Box<RefCell<Engine<'static>>>,
    server: Server<'static, 'static, SimFlash>,
    clock: SimClock,
    ram: SimResetRam,
}

impl core::fmt::Debug for SimBoard {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SimBoard").finish_non_exhaustive()
    }
}

impl SimBoard {
    /// A board with erased flash (no table).
    pub fn new() -> Self {
        Self::with_flash(SimFlash::new_erased(vec![0; 2 * SIM_SLOT_BYTES as usize]))
    }

    /// A board booting from `flash`. The model buffers and the staging
    /// buffer are leaked (≈ 100 KiB per board; test processes create a
    /// few hundred at most).
    pub fn with_flash(flash: SimFlash) -> Self {
        Self::boot(flash, SimResetRam::default(), ResetCause::PowerOn)
    }

    /// A fault resets the board: the fault's handler records it in the RAM
    /// that survives the reset (a watchdog reset records nothing: the
    /// reset flags say it), then the board boots on the same flash and RAM.
    pub fn fault_reset(self, fault: Fault) -> Self {
        let ram = self.ram.clone();
        let cause = match fault {
            Fault::Watchdog => ResetCause::Watchdog,
            f => {
                BootRecord::record_fault(&mut ram.0.lock().unwrap(), f);
                ResetCause::Other
            }
        };
        Self::boot(self.into_flash(), ram, cause)
    }

    /// A reset with no fault (the reset pin): flash and RAM kept.
    pub fn plain_reset(self) -> Self {
        let ram = self.ram.clone();
        Self::boot(self.into_flash(), ram, ResetCause::Other)
    }

    fn boot(flash: SimFlash, ram: SimResetRam, cause: ResetCause) -> Self {
        let record = BootRecord::decode(&ram.0.lock().unwrap());
        let sink: &'static mut SimResetRam = Box::leak(Box::new(ram.clone()));
        let store = TableStore::new(flash, SIM_LAYOUT).expect("sim layout fits");
        // The board's staging buffer: the sim accepts the uploads the board
        // accepts (48 KiB here once let a 28 KB table reach the model load).
        let stage: &'static mut [u8] =
            Box::leak(vec![0u8; model_core::board::STAGE_BYTES].into_boxed_slice());
        let m1: &'static mut ModelBuf = Box::leak(Box::default());
        let m2: &'static mut ModelBuf = Box::leak(Box::default());
        let engine = Box::new(RefCell::new(
            Engine::new(sim_engine_config()).expect("sim config is valid"),
        ));
        let mut server = Server::new(
            store,
            stage,
            [m1, m2],
            ServerConfig {
                firmware: crate::FIRMWARE_VERSION,
                quiet_ms: 200,
                // The real board's loop budget (model_core::board).
                model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
            },
        );
        server.set_reset_record(sink);
        server.boot_after_reset(&*engine, cause, record);
        Self {
            io: Arc::new(Mutex::new(SimIo::at_rest())),
            engine,
            server,
            clock: SimClock::default(),
            ram,
        }
    }

    /// Simulated time, µs.
    pub fn now_us(&self) -> u64 {
        self.clock.0.get()
    }

    /// Runs `n` ticks of the correction loop.
    pub fn tick(&mut self, n: u64) {
        let period = self.engine.borrow().config().period_us as u64;
        let mut io = SharedIo(self.io.clone());
        let mut io2 = SharedIo(self.io.clone());
        let mut io3 = SharedIo(self.io.clone());
        for _ in 0..n {
            self.clock.0.set(self.clock.0.get() + period);
            self.engine
                .borrow_mut()
                .tick(&self.clock, &mut io, &mut io2, &mut io3);
            self.server.poll_trial(&*self.engine);
        }
    }

    /// Feeds bytes from a link; returns the response bytes.
    pub fn receive(&mut self, port: &mut Port, bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let now = self.now_us();
        self.server
            .handle_bytes(port, bytes, now, &*self.engine, |f| {
                out.extend_from_slice(f)
            });
        out
    }

    /// The client behind `port` went away (see [`Server::port_closed`]).
    pub fn close(&mut self, port: &mut Port) {
        self.server.port_closed(port, &*self.engine);
    }

    /// The engine (for assertions).
    pub fn engine(&self) -> std::cell::Ref<'_, Engine<'static>> {
        self.engine.borrow()
    }

    /// Flash erase/write operations since the board was made (to assert
    /// that a request wrote nothing).
    pub fn flash_ops(&self) -> usize {
        self.server.store().flash().ops()
    }

    /// Power off: the flash contents, to boot another board on.
    pub fn into_flash(self) -> SimFlash {
        self.server.into_store().into_flash()
    }

    /// Serves TCP connections on `listener` until `stop` is set, ticking in
    /// step with wall-clock time: every client that connects is served,
    /// each with its own frame receiver (a second `trueaxis status` while a
    /// `monitor` runs gets its answer, not silence). Nothing blocks: each
    /// client's answers wait in its own queue and are written as its
    /// socket takes them, and a client with more than [`OUTBOX_BYTES`]
    /// unread is not read from until it catches up — one that sends and
    /// never reads stalls itself (TCP's back-pressure), not the board nor
    /// the other clients. Returns the board.
    pub fn serve(mut self, listener: TcpListener, stop: Arc<AtomicBool>) -> Self {
        let _ = listener.set_nonblocking(true);
        let mut clock = WallClock::new(&self);
        let mut conns: Vec<Conn> = Vec::new();
        let mut buf = [0u8; 1024];
        while !stop.load(Ordering::Relaxed) {
            while let Ok((s, _)) = listener.accept() {
                let _ = s.set_nonblocking(true);
                let _ = s.set_nodelay(true);
                conns.push(Conn {
                    stream: s,
                    port: Port::new(),
                    outbox: Vec::new(),
                });
            }
            let mut idle = true;
            conns.retain_mut(|c| {
                let mut open = c.flush();
                if open && c.outbox.len() < OUTBOX_BYTES {
                    open = match c.stream.read(&mut buf) {
                        Ok(0) => false,
                        Ok(n) => {
                            idle = false;
                            let out = self.receive(&mut c.port, &buf[..n]);
                            c.outbox.extend_from_slice(&out);
                            c.flush()
                        }
                        Err(e) => matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut),
                    };
                }
                if !open {
                    // An injection ends with the client that started it.
                    self.server.port_closed(&mut c.port, &*self.engine);
                }
                open
            });
            if idle {
                std::thread::sleep(Duration::from_millis(1));
            }
            clock.catch_up(&mut self);
        }
        self
    }

    /// Serves one byte stream — the board end of a serial line, e.g. the
    /// master side of a pseudo-terminal whose other side the host tool
    /// opens as a serial port — until `stop` is set, ticking in step with
    /// wall-clock time. Reads should time out after a millisecond or so.
    /// A serial line has no connection to lose: end of file and read
    /// errors (a pty's master reads EIO while no one has the other side
    /// open) are waited out. Returns the board.
    pub fn serve_stream<S: Read + Write>(mut self, mut io: S, stop: Arc<AtomicBool>) -> Self {
        let mut clock = WallClock::new(&self);
        let mut port = Port::new();
        let mut buf = [0u8; 1024];
        while !stop.load(Ordering::Relaxed) {
            match io.read(&mut buf) {
                Ok(n) if n > 0 => {
                    let out = self.receive(&mut port, &buf[..n]);
                    let _ = io.write_all(&out).and_then(|()| io.flush());
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
            clock.catch_up(&mut self);
        }
        self
    }
}

/// Unread answers a TCP client may have queued before the board stops
/// reading its requests, bytes.
pub const OUTBOX_BYTES: usize = 4096;

/// A TCP client of [`SimBoard::serve`]: its socket (non-blocking), frame
/// receiver and the answers its socket has not taken yet.
struct Conn {
    stream: TcpStream,
    port: Port,
    outbox: Vec<u8>,
}

impl Conn {
    /// Writes what the socket takes of the queued answers without waiting;
    /// false when the connection is gone.
    fn flush(&mut self) -> bool {
        while !self.outbox.is_empty() {
            match self.stream.write(&self.outbox) {
                Ok(0) => return false,
                Ok(n) => {
                    self.outbox.drain(..n);
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return true
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => return false,
            }
        }
        true
    }
}

/// Simulated time following the wall clock, at most 50 ticks per poll.
struct WallClock {
    period: Duration,
    last: Instant,
}

impl WallClock {
    fn new(board: &SimBoard) -> Self {
        Self {
            period: Duration::from_micros(board.engine.borrow().config().period_us as u64),
            last: Instant::now(),
        }
    }

    fn catch_up(&mut self, board: &mut SimBoard) {
        let due = (self.last.elapsed().as_micros() / self.period.as_micros().max(1)) as u64;
        if due > 0 {
            board.tick(due.min(50));
            self.last += self.period * due as u32;
        }
    }
}

impl Default for SimBoard {
    fn default() -> Self {
        Self::new()
    }
}
