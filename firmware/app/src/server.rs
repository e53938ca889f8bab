//! The link server: bytes in, bytes out, whatever the transport (USB
//! CDC-ACM and USART on the board, a TCP socket in QEMU and in the host's
//! end-to-end tests). Frames and messages are the `trueaxis-protocol` crate;
//! this file is what the board *does* with each request.
//!
//! One [`Server`] owns the table store and the upload staging buffer; each
//! transport has its own [`Port`] (a frame decoder) so two links can be
//! served at once without mixing their bytes. The engine is reached through
//! [`EngineAccess`] because on the board it lives behind a critical-section
//! mutex shared with the high-priority correction loop; the server never
//! holds that lock across a flash operation.
//!
//! **Single-bank flash policy.** The STM32F405 has one flash bank: while a
//! sector is erased (a 128 KiB slot: 1–2 s) every instruction fetch from
//! flash stalls, the correction loop included. The active model lives in
//! RAM, but the code does not, so the loop *does* stop for the erase. A
//! commit (and a rollback, whose one-word program stalls too) is therefore
//! refused with [`LinkError::AxesMoving`] unless no axis moved (beyond
//! the engine's 1 µm still band, `engine::STILL_BAND_NM`) for `quiet_ms`;
//! a machine at rest needs no new correction while
//! the CPU waits. After the flash operation the engine's clock is resynced
//! so the stall is not reported as a loop overrun.
//!
//! **Referencing and injection need the axes at rest.** A `Reference`
//! names the position of the count the encoder reads at the next tick, so
//! it is refused while an encoder moves ([`LinkError::NotStill`]); so is an
//! `Inject`. An injection is a lease of [`INJECT_LEASE_MS`] (counted in
//! the engine's ticks, so it means the same under an emulator whose
//! virtual time is not the wall clock), renewed by each `Inject`; it also
//! ends when the port that started it closes ([`Server::port_closed`]).
//!
//! **Boot fallback.** Every table that starts running (boot, commit,
//! rollback) is on trial for [`CONFIRM_MS`](crate::boot::CONFIRM_MS); the
//! server keeps the trial's [`BootRecord`] in the board's reset-surviving
//! RAM through a [`ResetRecord`], and [`Server::boot_after_reset`] falls
//! back to the other slot when a fault reset the board during a trial
//! (crate::boot says why the record lives in RAM).
//!
//! **Loop budget.** A commit is also refused (`LinkError::TooSlow`) when
//! the table's fixed-point evaluation is estimated (`model_core::cost`)
//! above `ServerConfig::model_budget_instr`: a table valid in every other
//! way that the correction loop could not evaluate every period.

use core::cell::RefCell;

use trueaxis_protocol::{
    decode_message, encode_frame, Faults, FrameDecoder, Identity, LinkError, Packet, Request,
    Response, SlotInfo, MAX_CHUNK_BYTES, MAX_FRAME_BYTES, PROTOCOL_VERSION,
};

use embedded_storage::nor_flash::{MultiwriteNorFlash, ReadNorFlash};
use model_core::board::{check_cost, LimitError};

use crate::boot::{self, BootRecord, ResetCause, TrialFailed, RECORD_WORDS};
use crate::engine::{Engine, STILL_US};
use crate::model::{self, ModelBuf};
use crate::store::{StoreError, TableStore};

/// How long an injection lasts without a renewing `Inject`, ms (turned
/// into engine ticks at the configured period).
pub const INJECT_LEASE_MS: u32 = 2000;

/// Access to the engine shared with the correction loop.
pub trait EngineAccess<'m> {
    /// Runs `f` with exclusive access to the engine (keep it short: the
    /// correction loop waits).
    fn with_engine<R>(&self, f: impl FnOnce(&mut Engine<'m>) -> R) -> R;
}

impl<'m> EngineAccess<'m> for RefCell<Engine<'m>> {
    fn with_engine<R>(&self, f: impl FnOnce(&mut Engine<'m>) -> R) -> R {
        f(&mut self.borrow_mut())
    }
}

/// Where the server keeps the [`BootRecord`] (`Send`: the simulated board
/// is served from a thread): RAM that survives a reset
/// (a `.uninit` static on the board and in QEMU), written at once so that
/// a table that crashes on its first tick is already on record.
pub trait ResetRecord {
    /// Stores the record's words.
    fn write(&mut self, words: [u32; RECORD_WORDS]);
}

/// The record sink, or none (host tests and the simulated board).
struct Sink<'b>(Option<&'b mut (dyn ResetRecord + Send)>);

impl core::fmt::Debug for Sink<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Sink(..)"
        } else {
            "Sink(none)"
        })
    }
}

/// What [`Server::boot_after_reset`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BootReport {
    /// The table the correction runs on.
    pub active: Option<SlotInfo>,
    /// The newest table's trial failed: it was revoked (when another table
    /// was there to take over) and is not running.
    pub failed: Option<TrialFailed>,
}

/// Server settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ServerConfig {
    /// Firmware version reported by `Identify`.
    pub firmware: [u16; 3],
    /// How long the axes must stand still before a flash erase, ms.
    pub quiet_ms: u32,
    /// The most instructions a table's fixed-point evaluation may be
    /// estimated to take (`model_core::cost`) for a commit to be accepted:
    /// what a loop period leaves for the model
    /// (`model_core::board::MODEL_BUDGET_INSTR` on the board).
    pub model_budget_instr: u32,
}

/// One transport's receive state.
#[derive(Debug, Default)]
pub struct Port {
    decoder: FrameDecoder<MAX_FRAME_BYTES>,
    /// The server's injection generation when this port last injected
    /// (0: never): the injection is this port's while the two agree.
    inject_gen: u32,
}

impl Port {
    /// A port with an empty decoder.
    pub const fn new() -> Self {
        Self {
            decoder: FrameDecoder::new(),
            inject_gen: 0,
        }
    }

    /// Drops a half-received frame (after a link reset or timeout).
    pub fn reset(&mut self) {
        self.decoder.reset();
    }
}

#[derive(Debug, Clone, Copy)]
struct Upload {
    size: u32,
    crc32: u32,
    received: u32,
}

/// A commit or rollback that took effect, with the table it left active.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Done {
    Committed(SlotInfo),
    RolledBack(SlotInfo),
}

/// The link server.
#[derive(Debug)]
pub struct Server<'b, 'm, F> {
    store: TableStore<F>,
    stage: &'b mut [u8],
    /// Model buffers not in use by the engine (at least one once booted).
    spares: [Option<&'m mut ModelBuf>; 2],
    upload: Option<Upload>,
    /// What the last `Commit` or `Rollback` did, kept so that the host's
    /// retry after the answer was lost gets the same success instead of
    /// `NoUpload` (the upload a commit refers to is spent) or
    /// `NothingToRollBackTo` (the revoked table is gone), and nothing is
    /// written twice. Forgotten at the next `UploadBegin`; replaced by the
    /// next commit or rollback.
    last_done: Option<Done>,
    cfg: ServerConfig,
    rx_bad_frames: u32,
    /// Bumped each time a port other than the last injecting one injects.
    inject_gen: u32,
    /// The running table's trial (crate::boot), mirrored to `sink`.
    record: BootRecord,
    /// Engine tick at which the running table's trial started.
    trial_start_tick: u64,
    sink: Sink<'b>,
}

impl<'b, 'm, F: MultiwriteNorFlash + ReadNorFlash> Server<'b, 'm, F> {
    /// A server over `store`, staging uploads in `stage` (its length is the
    /// largest table accepted), with two model buffers: one for the engine,
    /// one to load the next table into.
    pub fn new(
        store: TableStore<F>,
        stage: &'b mut [u8],
        models: [&'m mut ModelBuf; 2],
        cfg: ServerConfig,
    ) -> Self {
        let [a, b] = models;
        Self {
            store,
            stage,
            spares: [Some(a), Some(b)],
            upload: None,
            last_done: None,
            cfg,
            rx_bad_frames: 0,
            inject_gen: 0,
            record: BootRecord::trial(None),
            trial_start_tick: 0,
            sink: Sink(None),
        }
    }

    /// Keeps the boot record in `sink` from now on (call before booting).
    pub fn set_reset_record(&mut self, sink: &'b mut (dyn ResetRecord + Send)) {
        self.sink = Sink(Some(sink));
    }

    /// Boot after a power-up: scans both slots and activates the newest
    /// valid table (or leaves the engine without one: it reports
    /// `NO_TABLE`).
    pub fn boot(&mut self, engine: &impl EngineAccess<'m>) -> Option<SlotInfo> {
        self.boot_after_reset(engine, ResetCause::PowerOn, None)
            .active
    }

    /// Boot after a reset of cause `reset`, with the record that survived
    /// it (`None` after a power cut or when RAM held none): scans both
    /// slots; when the newest table failed its trial (crate::boot), revokes
    /// it, latches `TRIAL_FAILED` and the fault's bit, and activates the
    /// other one — or none, if there is none; otherwise activates the
    /// newest. The table activated starts its own trial.
    pub fn boot_after_reset(
        &mut self,
        engine: &impl EngineAccess<'m>,
        reset: ResetCause,
        record: Option<BootRecord>,
    ) -> BootReport {
        let spare = spare(&mut self.spares);
        // A table is booted only if it passes what a commit checks
        // (`trueaxis flash` writes slots without the board seeing them).
        self.store
            .scan(self.stage, |b| model::load_checked(b, spare).is_ok());
        let failed = boot::failed_trial(record, reset, self.store.active());
        if let Some(f) = failed {
            engine.with_engine(|e| e.latch(Faults::TRIAL_FAILED.union(f.fault.bit())));
            if self.store.rollback().is_err() {
                // Nothing to fall back to (or the revoke failed): run no
                // table rather than the one that crashed the board. The
                // record stays, so another fault reset keeps it so; a
                // power-up gives the table a new trial.
                if let Some(r) = record {
                    self.record = r;
                }
                return BootReport {
                    active: None,
                    failed,
                };
            }
        }
        BootReport {
            active: self.activate_newest(engine).ok(),
            failed,
        }
    }

    /// Confirms the running table once it has run
    /// [`CONFIRM_MS`](boot::CONFIRM_MS) of engine ticks since its trial
    /// began; call it periodically (the board's watchdog task). Returns
    /// whether the record changed.
    pub fn poll_trial(&mut self, engine: &impl EngineAccess<'m>) -> bool {
        if self.record.confirmed || self.record.table.is_none() {
            return false;
        }
        let (ticks, period) = engine.with_engine(|e| (e.telemetry().ticks, e.config().period_us));
        let need = u64::from(boot::CONFIRM_MS) * 1000 / u64::from(period.max(1));
        if ticks.saturating_sub(self.trial_start_tick) < need.max(1) {
            return false;
        }
        self.record.confirmed = true;
        self.write_record();
        true
    }

    /// The boot record as the server keeps it.
    pub fn boot_record(&self) -> BootRecord {
        self.record
    }

    fn start_trial(&mut self, table: Option<SlotInfo>, engine: &impl EngineAccess<'m>) {
        self.record = BootRecord::trial(table);
        self.trial_start_tick = engine.with_engine(|e| e.telemetry().ticks);
        self.write_record();
    }

    fn write_record(&mut self) {
        if let Some(s) = self.sink.0.as_mut() {
            s.write(self.record.encode());
        }
    }

    fn give_back(&mut self, m: Option<&'m mut ModelBuf>) {
        if let Some(m) = m {
            if let Some(free) = self.spares.iter_mut().find(|s| s.is_none()) {
                *free = Some(m);
            }
        }
    }

    /// The store (tests inspect it).
    pub fn store(&self) -> &TableStore<F> {
        &self.store
    }

    /// Gives the store back.
    pub fn into_store(self) -> TableStore<F> {
        self.store
    }

    /// Largest table accepted, bytes.
    pub fn max_table_bytes(&self) -> u32 {
        (self.stage.len() as u32).min(self.store.layout().max_table_bytes())
    }

    /// Frames dropped so far.
    pub fn rx_bad_frames(&self) -> u32 {
        self.rx_bad_frames
    }

    /// Feeds received bytes; every complete request is answered through
    /// `send` (one call per response frame). `now_us` is the board clock.
    pub fn handle_bytes(
        &mut self,
        port: &mut Port,
        mut input: &[u8],
        now_us: u64,
        engine: &impl EngineAccess<'m>,
        mut send: impl FnMut(&[u8]),
    ) {
        while let Some(frame) = port.decoder.feed(&mut input) {
            let packet = frame.and_then(decode_message::<Packet<Request<'_>>>);
            let Ok(packet) = packet else {
                self.rx_bad_frames = self.rx_bad_frames.saturating_add(1);
                continue;
            };
            let inject = matches!(packet.msg, Request::Inject(_));
            let msg = self.handle(packet.msg, now_us, engine);
            if inject
                && matches!(msg, Response::Correction(_))
                && (port.inject_gen == 0 || port.inject_gen != self.inject_gen)
            {
                // An accepted injection from a new owner (a refused one
                // takes nothing over). The generation is only compared,
                // never a count that matters: wrapping is fine.
                self.inject_gen = self.inject_gen.wrapping_add(1).max(1);
                port.inject_gen = self.inject_gen;
            }
            let mut out = [0u8; MAX_FRAME_BYTES];
            // Every response fits a frame (tested in model-core); if one
            // ever did not, dropping it makes the host retry rather than
            // the board panic.
            if let Ok(n) = encode_frame(
                &Packet {
                    seq: packet.seq,
                    msg,
                },
                &mut out,
            ) {
                send(&out[..n]);
            }
        }
    }

    /// The transport behind `port` went away (a TCP client closed): an
    /// injection it started ends now instead of outliving its client.
    pub fn port_closed(&mut self, port: &mut Port, engine: &impl EngineAccess<'m>) {
        if port.inject_gen != 0 && port.inject_gen == self.inject_gen {
            engine.with_engine(|e| e.set_injection(None, 0));
        }
        port.inject_gen = 0;
        port.reset();
    }

    /// Answers one request.
    pub fn handle(
        &mut self,
        req: Request<'_>,
        now_us: u64,
        engine: &impl EngineAccess<'m>,
    ) -> Response {
        match self.dispatch(req, now_us, engine) {
            Ok(r) => r,
            Err(e) => Response::Error(e),
        }
    }

    fn dispatch(
        &mut self,
        req: Request<'_>,
        now_us: u64,
        engine: &impl EngineAccess<'m>,
    ) -> Result<Response, LinkError> {
        Ok(match req {
            Request::Identify => {
                let active = engine.with_engine(|e| e.active());
                let standby = self
                    .store
                    .valid_slots()
                    .into_iter()
                    .flatten()
                    .find(|s| Some(s.slot) != active.map(|a| a.slot));
                Response::Identity(Identity {
                    firmware: self.cfg.firmware,
                    protocol: PROTOCOL_VERSION,
                    table_format: model::FORMAT_VERSION,
                    max_table_bytes: self.max_table_bytes(),
                    active,
                    standby,
                })
            }
            Request::Status => {
                let mut t = engine.with_engine(|e| e.telemetry());
                t.rx_bad_frames = self.rx_bad_frames;
                Response::Status(t)
            }
            Request::UploadBegin { size, crc32 } => {
                let max = self.max_table_bytes();
                if size > max {
                    return Err(LinkError::TooLarge { max_bytes: max });
                }
                if size == 0 {
                    return Err(LinkError::BadChunk);
                }
                self.last_done = None;
                match self.upload {
                    // Same table: resume where we are.
                    Some(u) if u.size == size && u.crc32 == crc32 => {}
                    _ => {
                        self.upload = Some(Upload {
                            size,
                            crc32,
                            received: 0,
                        })
                    }
                }
                Response::UploadAck {
                    next_offset: self.upload.map_or(0, |u| u.received),
                }
            }
            Request::UploadChunk { offset, data } => {
                let u = self.upload.as_mut().ok_or(LinkError::NoUpload)?;
                let end = offset as u64 + data.len() as u64;
                if data.len() > MAX_CHUNK_BYTES || end > u.size as u64 || data.is_empty() {
                    return Err(LinkError::BadChunk);
                }
                if end <= u.received as u64 {
                    // A retry of a chunk we have: acknowledge again.
                } else if offset != u.received {
                    return Err(LinkError::BadOffset {
                        expected: u.received,
                    });
                } else {
                    self.stage[offset as usize..end as usize].copy_from_slice(data);
                    u.received = end as u32;
                }
                Response::UploadAck {
                    next_offset: u.received,
                }
            }
            Request::Commit => {
                let Some(u) = self.upload else {
                    // Idempotent: a commit repeated after its answer was
                    // lost (no upload since) gets the same answer, as long
                    // as that table is still the newest stored one.
                    return match self.last_done {
                        Some(Done::Committed(info)) if self.store.active() == Some(info) => {
                            Ok(Response::Committed(info))
                        }
                        _ => Err(LinkError::NoUpload),
                    };
                };
                if u.received < u.size {
                    return Err(LinkError::Incomplete {
                        received: u.received,
                        size: u.size,
                    });
                }
                if trueaxis_protocol::table_id(&self.stage[..u.size as usize]) != u.crc32 {
                    // The staged bytes are wrong: forget them, or the next
                    // UploadBegin of the same table would "resume" them.
                    self.upload = None;
                    return Err(LinkError::CrcMismatch);
                }
                // Refused before anything is written (and before waiting
                // for the axes to stop), the active table staying, in the
                // order of `model_core::board::check` — what `trueaxis
                // export`, `upload` and `flash` refuse with: a table that
                // does not load into the board's model (format, capacity,
                // ranges), then one the loop cannot evaluate every period,
                // then one whose evaluation departs from its own
                // definition (the dearest check, last).
                let staged = &self.stage[..u.size as usize];
                if model::load_into(staged, spare(&mut self.spares)).is_err() {
                    self.upload = None;
                    return Err(LinkError::InvalidTable);
                }
                if let Ok(t) = model_core::parse(staged) {
                    if let Err(LimitError::TooSlow { estimate, budget }) =
                        check_cost(&t, self.cfg.model_budget_instr)
                    {
                        self.upload = None;
                        return Err(LinkError::TooSlow {
                            estimate_instr: estimate,
                            budget_instr: budget,
                        });
                    }
                }
                if model::check_loaded(staged, spare(&mut self.spares)).is_err() {
                    self.upload = None;
                    return Err(LinkError::InvalidTable);
                }
                self.require_quiet(now_us, engine)?;
                let spare = spare(&mut self.spares);
                let table = &self.stage[..u.size as usize];
                engine.with_engine(|e| e.begin_stall());
                let r = self
                    .store
                    .commit(table, |b| model::load_into(b, spare).is_ok());
                engine.with_engine(|e| e.end_stall());
                // Committed or refused by the store (an invalid table): either
                // way the staged upload is spent; a new upload starts from
                // byte 0, a repeated commit gets the same answer (above).
                self.upload = None;
                r.map_err(store_error)?;
                // The committed table (now the newest) runs at once. Boot runs the newest
                // table, and the slot not running is the one the next
                // commit erases: a committed table left waiting for an
                // `Activate` that a dropped link never delivers would be
                // started by the next reset or rollback, while the next
                // upload erased the table actually running.
                let info = self.activate_newest(engine)?;
                self.last_done = Some(Done::Committed(info));
                Response::Committed(info)
            }
            Request::Activate => {
                // Under the commit's quiet rule: a table switch while an
                // axis moves changes the correction under a moving machine
                // (and the table runs at once after a commit anyway).
                self.require_quiet(now_us, engine)?;
                Response::Activated(self.activate_newest(engine)?)
            }
            Request::Rollback => {
                // Idempotent: a rollback repeated after its answer was lost
                // (no upload or commit since) gets the same answer while
                // that table is still the active one — it revokes nothing
                // more (with two slots there is nothing left to revoke).
                if let Some(Done::RolledBack(info)) = self.last_done {
                    if self.store.active() == Some(info) {
                        return Ok(Response::RolledBack(info));
                    }
                }
                self.require_quiet(now_us, engine)?;
                self.last_done = None;
                engine.with_engine(|e| e.begin_stall());
                let r = self.store.rollback();
                engine.with_engine(|e| e.end_stall());
                r.map_err(store_error)?;
                let info = self.activate_newest(engine)?;
                self.last_done = Some(Done::RolledBack(info));
                Response::RolledBack(info)
            }
            Request::ClearFaults => {
                engine.with_engine(|e| e.clear_faults());
                Response::Ok
            }
            Request::Inject(inj) => {
                // A reversal state beyond ±1 (Q30) is not a state a
                // DirTracker can be in: the host built it wrong.
                if inj.rev_q30.iter().any(|r| r.unsigned_abs() > 1 << 30) {
                    return Err(LinkError::BadInjection);
                }
                let r = engine.with_engine(|e| {
                    if !e.is_still(now_us) {
                        return Err(not_still());
                    }
                    let period = u64::from(e.config().period_us.max(1));
                    let lease =
                        (u64::from(INJECT_LEASE_MS) * 1000 / period).clamp(1, u32::MAX.into());
                    e.set_injection(Some(inj), lease as u32);
                    Ok(e.evaluate_injection(&inj))
                })?;
                Response::Correction(r)
            }
            Request::EndInject => {
                engine.with_engine(|e| e.set_injection(None, 0));
                Response::Ok
            }
            Request::Reference { axis, pos_nm } => {
                if axis > 2 {
                    return Err(LinkError::BadAxis);
                }
                engine.with_engine(|e| {
                    if !e.is_still(now_us) {
                        return Err(not_still());
                    }
                    e.reference(usize::from(axis), pos_nm);
                    Ok(())
                })?;
                Response::Ok
            }
            Request::ReadCorrection => Response::Correction(engine.with_engine(|e| e.correction())),
        })
    }

    fn require_quiet(&self, now_us: u64, engine: &impl EngineAccess<'m>) -> Result<(), LinkError> {
        let quiet_us = engine.with_engine(|e| e.quiet_for_us(now_us));
        if quiet_us < self.cfg.quiet_ms as u64 * 1000 {
            return Err(LinkError::AxesMoving {
                quiet_ms: self.cfg.quiet_ms,
            });
        }
        Ok(())
    }

    /// Loads the newest valid stored table into the engine. Uses the
    /// staging buffer, so an upload in progress is dropped.
    fn activate_newest(&mut self, engine: &impl EngineAccess<'m>) -> Result<SlotInfo, LinkError> {
        let Some(info) = self.store.active() else {
            let old = engine.with_engine(|e| e.clear_model(false));
            self.give_back(old);
            return Err(LinkError::NothingToActivate);
        };
        self.upload = None;
        let slot = self
            .spares
            .iter()
            .position(|s| s.is_some())
            .unwrap_or_default();
        let loaded = match (
            self.store.read_table(info, self.stage),
            &mut self.spares[slot],
        ) {
            (Ok(bytes), Some(m)) => model::load_into(bytes, m).map_err(|_| LinkError::InvalidTable),
            (Err(e), _) => Err(store_error(e)),
            (_, None) => Err(LinkError::InvalidTable),
        };
        match loaded {
            Ok(()) => {
                if self.record.table != Some(info) {
                    // On record before its first tick runs.
                    self.start_trial(Some(info), engine);
                }
                let m = self.spares[slot].take();
                if let Some(m) = m {
                    let old = engine.with_engine(|e| e.set_model(m, info));
                    self.give_back(old);
                }
                Ok(info)
            }
            Err(e) => {
                // A running model stays (it was valid when loaded, and it is
                // in RAM); only a board without one reports the bad table.
                let old = engine.with_engine(|en| {
                    if en.active().is_none() {
                        en.clear_model(true)
                    } else {
                        None
                    }
                });
                self.give_back(old);
                Err(e)
            }
        }
    }
}

/// A model buffer the engine does not use: there are two and the engine
/// holds at most one.
fn spare<'a>(spares: &'a mut [Option<&mut ModelBuf>; 2]) -> &'a mut ModelBuf {
    match spares {
        [Some(m), _] | [None, Some(m)] => m,
        [None, None] => unreachable!("both model buffers in use"),
    }
}

fn not_still() -> LinkError {
    LinkError::NotStill {
        still_ms: (STILL_US / 1000) as u32,
    }
}

fn store_error(e: StoreError) -> LinkError {
    match e {
        StoreError::Flash | StoreError::BadLayout => LinkError::FlashWrite,
        StoreError::Verify => LinkError::FlashVerify,
        StoreError::TooLarge => LinkError::TooLarge { max_bytes: 0 },
        StoreError::InvalidTable => LinkError::InvalidTable,
        StoreError::NothingToRollBackTo | StoreError::Empty => LinkError::NothingToRollBackTo,
    }
}
