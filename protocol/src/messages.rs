//! The messages of the link: the [`Packet`] envelope pairing a response with
//! its request, every [`Request`] the host sends and every [`Response`] the
//! board answers, and the values they carry (injected sensor inputs,
//! telemetry, corrections, the slots' state, the board's faults and
//! identity, and the typed [`LinkError`] a refused request answers with).
//! postcard is not self-describing: changing any of these types changes the
//! wire and needs a new [`crate::PROTOCOL_VERSION`]; variants are only ever
//! appended.

use serde::{Deserialize, Serialize};

use crate::LINK_TEMPS;

/// One message on the wire: the sequence number that pairs a response with
/// its request, and the message.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct Packet<T> {
    /// Chosen by the host, echoed by the board.
    pub seq: u16,
    /// The request or response.
    pub msg: T,
}

/// A request from the host to the board.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub enum Request<'a> {
    /// Who are you? → [`Response::Identity`].
    Identify,
    /// Current telemetry → [`Response::Status`].
    Status,
    /// Start (or resume, when size and CRC equal the upload in progress)
    /// an upload of a table of `size` bytes whose CRC-32 is `crc32`.
    UploadBegin {
        /// Table length in bytes.
        size: u32,
        /// CRC-32 (ISO-HDLC) of the whole table.
        crc32: u32,
    },
    /// Bytes `offset..offset + data.len()` of the table being uploaded.
    UploadChunk {
        /// Byte offset in the table.
        offset: u32,
        /// At most [`MAX_CHUNK_BYTES`](crate::MAX_CHUNK_BYTES).
        #[serde(borrow)]
        data: &'a [u8],
    },
    /// Validate the uploaded table, write it to the free slot and run it.
    Commit,
    /// Switch the running correction to the newest committed table.
    Activate,
    /// Revoke the newest table and fall back to the other slot (a repeat
    /// after a lost answer gets the same answer).
    Rollback,
    /// Clear latched faults whose cause is gone.
    ClearFaults,
    /// Bring-up and tests: replace the sensor readings by these values until
    /// [`Request::EndInject`]; the answer is [`Response::Correction`] with
    /// the model's correction for exactly these inputs.
    Inject(Injection),
    /// Go back to the real sensors.
    EndInject,
    /// The correction currently output → [`Response::Correction`].
    ReadCorrection,
    /// Reference (home) `axis` (0 = X): the encoder count it reads now is
    /// machine position `pos_nm`. The board corrects only from referenced
    /// axes; refused while the axes move ([`LinkError::NotStill`]). Takes
    /// effect at the next tick (see [`Telemetry::referenced`]) → [`Response::Ok`].
    /// (Appended: the other requests encode as before.)
    Reference {
        /// Axis index: 0 = X, 1 = Y, 2 = Z.
        axis: u8,
        /// The machine position the axis is at now, nm.
        pos_nm: i32,
    },
}

/// Sensor values forced by [`Request::Inject`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Injection {
    /// Machine position per axis (X, Y, Z), nm.
    pub pos_nm: [i32; 3],
    /// Reversal state per axis (model-core's `DirTracker` output, Q30:
    /// −2^30 = last moved negative … +2^30 = positive), given explicitly so
    /// the answer is a pure function of the injection.
    pub rev_q30: [i32; 3],
    /// Temperatures, milli-degrees Celsius; channels the table does not use
    /// are ignored.
    pub temp_mc: [i32; LINK_TEMPS],
    /// Tool length (Abbe arm), nm.
    pub tool_nm: i32,
}

/// Which flash slot of `memory.x` (TABLE_A / TABLE_B).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Slot {
    /// TABLE_A.
    A,
    /// TABLE_B.
    B,
}

/// A table stored in a slot.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlotInfo {
    /// Where it is.
    pub slot: Slot,
    /// Commit sequence number; the valid slot with the highest one boots.
    pub seq: u32,
    /// Table length in bytes.
    pub len: u32,
    /// CRC-32 of the table bytes.
    pub crc32: u32,
}

/// Fault bits (a set; [`Faults::NONE`] when healthy). Any active fault ramps
/// the correction to zero.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Faults(pub u16);

impl Faults {
    /// No fault.
    pub const NONE: Faults = Faults(0);
    /// No valid table in either slot (or none loaded yet).
    pub const NO_TABLE: Faults = Faults(1 << 0);
    /// The stored table failed validation or could not be loaded.
    pub const BAD_TABLE: Faults = Faults(1 << 1);
    /// A temperature reading outside the plausible range (sensor open or
    /// shorted).
    pub const SENSOR_RANGE: Faults = Faults(1 << 2);
    /// The correction loop missed its period.
    pub const LOOP_OVERRUN: Faults = Faults(1 << 3);
    /// The model produced a non-finite or overflowing value.
    pub const NOT_FINITE: Faults = Faults(1 << 4);
    /// An encoder jumped further in one tick than the axis can move
    /// (counter glitch or lost cable).
    pub const ENCODER_JUMP: Faults = Faults(1 << 5);
    /// An axis that needs a reference has none: never referenced since
    /// power-up or reset, or its reference was lost (an encoder jump). Live:
    /// it clears when the axis is referenced again.
    pub const NOT_REFERENCED: Faults = Faults(1 << 6);
    /// Boot fallback (latched only, never active: the correction runs on
    /// the previous table): the newest table was still in its trial window
    /// when a fault reset the board, so the boot revoked it and activated
    /// the other slot (or none, when there was no other). One of the three
    /// `RESET_BY_*` bits below says which fault.
    pub const TRIAL_FAILED: Faults = Faults(1 << 7);
    /// With [`TRIAL_FAILED`](Self::TRIAL_FAILED): the fault was a panic.
    pub const RESET_BY_PANIC: Faults = Faults(1 << 8);
    /// With [`TRIAL_FAILED`](Self::TRIAL_FAILED): a HardFault (bus, memory
    /// or usage fault).
    pub const RESET_BY_HARDFAULT: Faults = Faults(1 << 9);
    /// With [`TRIAL_FAILED`](Self::TRIAL_FAILED): the watchdog (the
    /// correction loop stopped).
    pub const RESET_BY_WATCHDOG: Faults = Faults(1 << 10);
    /// A referenced axis's home switch turned on (debounced, approached
    /// from its side) farther from the switch's position than the axis's
    /// tolerance: the tracked position or the switch is wrong. The axis's
    /// reference is dropped ([`NOT_REFERENCED`](Self::NOT_REFERENCED));
    /// stays active until `ClearFaults`.
    pub const HOME_MISMATCH: Faults = Faults(1 << 11);
    /// The encoders were not read for longer than the counters' widening
    /// can follow at the axis's top speed (a stall: a flash erase, a halt)
    /// and the axis moved meanwhile: its count may be off by whole turns of
    /// the hardware counter. The axis's reference is dropped; stays active
    /// until `ClearFaults`.
    pub const POSITION_LOST: Faults = Faults(1 << 12);

    /// True when no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// True when every bit of `other` is set in `self`.
    pub const fn contains(self, other: Faults) -> bool {
        self.0 & other.0 == other.0
    }
    /// Union.
    pub const fn union(self, other: Faults) -> Faults {
        Faults(self.0 | other.0)
    }
    /// Names of the set bits, for humans.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [&str; 13] = [
            "no_table",
            "bad_table",
            "sensor_range",
            "loop_overrun",
            "not_finite",
            "encoder_jump",
            "not_referenced",
            "trial_failed",
            "reset_by_panic",
            "reset_by_hardfault",
            "reset_by_watchdog",
            "home_mismatch",
            "position_lost",
        ];
        NAMES
            .into_iter()
            .enumerate()
            .filter(move |(i, _)| self.0 & (1 << i) != 0)
            .map(|(_, n)| n)
    }
}

/// Live state of the board, answered to [`Request::Status`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Telemetry {
    /// Time since boot, µs.
    pub uptime_us: u64,
    /// Correction ticks run since boot.
    pub ticks: u64,
    /// Nominal tick period, µs.
    pub period_us: u32,
    /// Longest time between two consecutive ticks seen, µs.
    pub worst_loop_us: u32,
    /// Longest time spent inside one tick, µs.
    pub worst_tick_us: u32,
    /// Ticks that started later than one period after the previous one.
    pub overruns: u32,
    /// Positions, nm (from the encoders, or injected).
    pub pos_nm: [i32; 3],
    /// Temperatures, m°C.
    pub temp_mc: [i32; LINK_TEMPS],
    /// What the model asks for at this position, nm.
    pub model_corr_nm: [i32; 3],
    /// What is output (after slew limit and fault ramp), nm.
    pub corr_nm: [i32; 3],
    /// Net step pulses emitted per axis since boot.
    pub steps: [i64; 3],
    /// Model output flags (see model-core's `Flags`), raw bits.
    pub model_flags: u16,
    /// Faults active now.
    pub faults: Faults,
    /// Faults seen since the last [`Request::ClearFaults`].
    pub faults_latched: Faults,
    /// True while [`Request::Inject`] overrides the sensors.
    pub injecting: bool,
    /// Per axis (X, Y, Z): the axis is referenced (its encoder count has a
    /// known machine position since [`Request::Reference`]).
    pub referenced: [bool; 3],
    /// Per axis: the board corrects only once this axis is referenced (an
    /// axis with an encoder; one without needs no reference).
    pub reference_needed: [bool; 3],
    /// The table the correction runs on.
    pub active: Option<SlotInfo>,
    /// Frames dropped for a bad CRC, bad COBS or overflow.
    pub rx_bad_frames: u32,
}

/// The correction for given inputs, answered to [`Request::Inject`] and
/// [`Request::ReadCorrection`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Correction {
    /// The inputs, nm.
    pub pos_nm: [i32; 3],
    /// The model's correction for them (envelope applied by the model), nm.
    pub model_corr_nm: [i32; 3],
    /// The correction output now (after slew limit and fault ramp), nm.
    pub corr_nm: [i32; 3],
    /// Model output flags, raw bits.
    pub model_flags: u16,
    /// Faults active now.
    pub faults: Faults,
}

/// A response from the board.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub enum Response {
    /// Answer to [`Request::Identify`].
    Identity(Identity),
    /// Answer to [`Request::Status`].
    Status(Telemetry),
    /// Upload progress: the next byte offset the board wants.
    UploadAck {
        /// Bytes received so far (contiguous from 0).
        next_offset: u32,
    },
    /// The uploaded table is in flash, verified.
    Committed(SlotInfo),
    /// The correction now runs on this table.
    Activated(SlotInfo),
    /// The newest table was revoked; the correction runs on this one.
    RolledBack(SlotInfo),
    /// Answer to [`Request::Inject`] and [`Request::ReadCorrection`].
    Correction(Correction),
    /// Done (answer to [`Request::ClearFaults`], [`Request::EndInject`] and
    /// [`Request::Reference`]).
    Ok,
    /// The request was refused.
    Error(LinkError),
}

/// Answer to [`Request::Identify`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Firmware version (major, minor, patch).
    pub firmware: [u16; 3],
    /// [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION) of the board.
    pub protocol: u16,
    /// Table format version the board reads.
    pub table_format: u16,
    /// Largest table the board accepts, bytes.
    pub max_table_bytes: u32,
    /// The table the correction runs on.
    pub active: Option<SlotInfo>,
    /// The other slot's table, if valid (the rollback target).
    pub standby: Option<SlotInfo>,
}

/// Why a request was refused. Small and `Copy` (it crosses the link).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError {
    /// A chunk, commit or resume without an `UploadBegin`.
    NoUpload,
    /// The announced table does not fit the board's buffer or slot.
    TooLarge {
        /// Largest accepted size, bytes.
        max_bytes: u32,
    },
    /// A chunk not at the offset the board expects (the host resumes from
    /// `expected`).
    BadOffset {
        /// The next offset the board wants.
        expected: u32,
    },
    /// A chunk longer than [`MAX_CHUNK_BYTES`](crate::MAX_CHUNK_BYTES) or past the announced size.
    BadChunk,
    /// Commit before every byte arrived.
    Incomplete {
        /// Bytes received.
        received: u32,
        /// Bytes announced.
        size: u32,
    },
    /// The received bytes do not have the CRC announced in `UploadBegin`.
    CrcMismatch,
    /// The table failed model-core's validation (format, version, CRC,
    /// envelope) or cannot be loaded as a model.
    InvalidTable,
    /// Single-bank flash: an erase stalls the CPU, so a commit or rollback
    /// is refused while an axis moved within the last `quiet_ms`.
    AxesMoving {
        /// How long the axes must stand still, ms.
        quiet_ms: u32,
    },
    /// Erase or write failed.
    FlashWrite,
    /// Read-back after writing differs from what was written.
    FlashVerify,
    /// Activate without a committed table.
    NothingToActivate,
    /// Rollback without a valid table in the other slot.
    NothingToRollBackTo,
    /// An injection carries a value no sensor can produce (a reversal
    /// state beyond ±2^30). Positions, temperatures and tool lengths outside
    /// the table's envelope are accepted: the model holds them at the edge
    /// and flags it, exactly as for real sensors.
    BadInjection,
    /// The table is valid but too slow for the correction loop: its
    /// fixed-point evaluation is estimated (`model_core::cost::estimate`) above
    /// what a tick leaves for the model (`model_core::board`). Refused at
    /// commit; the active table stays. (Appended last, so the messages of
    /// every other variant encode as before.)
    TooSlow {
        /// The table's estimate, instructions per evaluation.
        estimate_instr: u32,
        /// The most the board accepts, instructions.
        budget_instr: u32,
    },
    /// Referencing over the link and injection need the axes at rest: an
    /// axis moved (more than the board's 1 µm still band) within the last
    /// `still_ms`.
    NotStill {
        /// How long the encoders must not have changed, ms.
        still_ms: u32,
    },
    /// An axis index other than 0, 1, 2 (X, Y, Z).
    BadAxis,
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            LinkError::NoUpload => write!(f, "no upload in progress"),
            LinkError::TooLarge { max_bytes } => {
                write!(
                    f,
                    "table too large (the board takes at most {max_bytes} bytes)"
                )
            }
            LinkError::BadOffset { expected } => {
                write!(f, "chunk at the wrong offset (board expects {expected})")
            }
            LinkError::BadChunk => write!(f, "chunk too long or past the announced size"),
            LinkError::Incomplete { received, size } => {
                write!(f, "upload incomplete: {received} of {size} bytes received")
            }
            LinkError::CrcMismatch => write!(f, "uploaded bytes do not match the announced CRC"),
            LinkError::InvalidTable => write!(f, "the board rejected the table as invalid"),
            LinkError::AxesMoving { quiet_ms } => write!(
                f,
                "axes are moving: a flash erase stalls the correction, so the board \
                 commits only after all axes stood still for {quiet_ms} ms"
            ),
            LinkError::FlashWrite => write!(f, "flash erase/write failed"),
            LinkError::FlashVerify => write!(f, "flash read-back differs from the table"),
            LinkError::NothingToActivate => write!(f, "no committed table to activate"),
            LinkError::NothingToRollBackTo => write!(f, "no valid table in the other slot"),
            LinkError::BadInjection => write!(f, "injected value out of range"),
            LinkError::TooSlow {
                estimate_instr,
                budget_instr,
            } => write!(
                f,
                "the table is too slow for the correction loop: its evaluation is estimated \
                 at {estimate_instr} instructions, the board allows {budget_instr}"
            ),
            LinkError::NotStill { still_ms } => write!(
                f,
                "the axes are moving: referencing and injection need every axis at rest \
                 (within 1 µm) for {still_ms} ms"
            ),
            LinkError::BadAxis => write!(f, "no such axis (X, Y or Z)"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes<T: Serialize>(v: &T) -> std::vec::Vec<u8> {
        let mut buf = [0u8; 64];
        postcard::to_slice(v, &mut buf).unwrap().to_vec()
    }

    /// Version 2 only appended: every request of version 1 keeps its
    /// variant index (so a version-1 host's `Identify` reaches a version-2
    /// board and learns the version), `Reference` is the next one, and the
    /// new errors and fault bit come after the old ones.
    #[test]
    fn version_2_appends_reference_and_keeps_the_old_encodings() {
        assert_eq!(bytes(&Request::Identify), [0]);
        assert_eq!(bytes(&Request::Status), [1]);
        assert_eq!(bytes(&Request::ReadCorrection), [10]);
        // Variant 11, axis 2, pos -1 (zigzag varint 1).
        assert_eq!(
            bytes(&Request::Reference {
                axis: 2,
                pos_nm: -1
            }),
            [11, 2, 1]
        );
        assert_eq!(bytes(&LinkError::BadInjection), [12]);
        assert_eq!(bytes(&LinkError::NotStill { still_ms: 20 }), [14, 20]);
        assert_eq!(bytes(&LinkError::BadAxis), [15]);
        assert_eq!(Faults::NOT_REFERENCED.0, 1 << 6);
        assert!(Faults::NOT_REFERENCED.names().eq(["not_referenced"]));
        // The boot fallback's bits (latched only), named as the host's
        // JSON shows them.
        let fallback = Faults::TRIAL_FAILED
            .union(Faults::RESET_BY_PANIC)
            .union(Faults::RESET_BY_HARDFAULT)
            .union(Faults::RESET_BY_WATCHDOG);
        assert_eq!(fallback.0, 0b1111 << 7);
        assert!(fallback.names().eq([
            "trial_failed",
            "reset_by_panic",
            "reset_by_hardfault",
            "reset_by_watchdog"
        ]));
        assert_eq!(crate::PROTOCOL_VERSION, 2);
    }

    /// Issue 25's fault bits come after the old ones; the field is a bit
    /// set, so its encoding (a u16) is the same for every value.
    #[test]
    fn the_position_fault_bits_are_appended() {
        assert_eq!(Faults::HOME_MISMATCH.0, 1 << 11);
        assert_eq!(Faults::POSITION_LOST.0, 1 << 12);
        assert!(Faults::HOME_MISMATCH
            .union(Faults::POSITION_LOST)
            .names()
            .eq(["home_mismatch", "position_lost"]));
        assert_eq!(bytes(&Faults(1 << 12)), bytes(&(1u16 << 12)));
    }
}
