//! The link protocol between the host tool and the compensation board,
//! defined once here so both sides serialise the very same types.
//!
//! **Wire format.** Every message is a [`Packet`] (a 16-bit sequence number
//! plus a [`Request`] or [`Response`]) serialised with postcard, followed by
//! the CRC-32 (ISO-HDLC, little endian) of those postcard bytes, the whole
//! COBS-encoded and terminated by one `0x00` delimiter:
//!
//! ```text
//! COBS( postcard(Packet) ++ crc32_le(postcard(Packet)) ) ++ 0x00
//! ```
//!
//! COBS guarantees that `0x00` only ever appears as a delimiter, so a
//! receiver that sees garbage or a frame cut in the middle throws away what
//! it has at the next `0x00` and is in sync again with the following frame —
//! the parser can never get stuck. Senders put one extra `0x00` *before*
//! every frame to flush a half-received frame on the other side; empty
//! frames are ignored. The CRC catches what COBS cannot (flipped bits).
//!
//! **Conversation.** The host sends requests, the board answers each with
//! exactly one response carrying the same `seq`. A frame that fails its CRC
//! or does not decode gets no answer (the sender cannot be trusted to be
//! who it claims); the host retries after a timeout. Requests are
//! idempotent where it matters for retries: `UploadBegin` with the size and
//! CRC of the upload already in progress resumes it and answers with the
//! next offset the board wants; a chunk at an offset already received is
//! acknowledged again without rewriting.
//!
//! **Upload.** `UploadBegin{size, crc32}` → `UploadAck{next_offset}`;
//! `UploadChunk{offset, data}` (at most [`MAX_CHUNK_BYTES`]) →
//! `UploadAck{next_offset}`; `Commit` (the board validates the whole table,
//! writes it to the free flash slot with a higher sequence number,
//! verifies it and runs it) → `Committed`; `Activate` (the running
//! correction switches to the newest committed table; after a `Commit`
//! nothing changes) → `Activated`. `Rollback` revokes the
//! newest slot and goes back to the other one. A `Commit` or `Rollback`
//! repeated after its answer was lost gets the same answer and writes
//! nothing (the board remembers the last one until the next upload).

use serde::{Deserialize, Serialize};

/// Version of this protocol; bumped on any incompatible change of the types
/// below (postcard is not self-describing, so both sides must agree).
pub const PROTOCOL_VERSION: u16 = 1;

/// Largest payload of one [`Request::UploadChunk`]. Small enough that a
/// frame fits comfortably in a USB full-speed burst and a UART FIFO-less
/// receive buffer, large enough that a 16 KiB table takes 64 round trips.
pub const MAX_CHUNK_BYTES: usize = 256;

/// Number of temperature channels carried in injections and telemetry.
pub const LINK_TEMPS: usize = 8;

/// Upper bound of a serialised [`Packet`] of any request or response
/// (postcard; the largest is an upload chunk: 256 data bytes plus at most
/// 16 bytes of header and lengths).
pub const MAX_MESSAGE_BYTES: usize = MAX_CHUNK_BYTES + 64;

/// CRC appended to every message.
const CRC_BYTES: usize = 4;

/// Largest frame on the wire, delimiters included: COBS adds one byte per
/// 254 bytes plus one, we add the leading and trailing `0x00`.
pub const MAX_FRAME_BYTES: usize =
    (MAX_MESSAGE_BYTES + CRC_BYTES) + (MAX_MESSAGE_BYTES + CRC_BYTES) / 254 + 1 + 2;

/// The CRC used by the frames (and by the table format: CRC-32/ISO-HDLC,
/// the zlib/PNG one).
pub const FRAME_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The identity of a table on the link and in the flash slots (upload
/// begin, slot headers, status): the table's own CRC-32/ISO-HDLC, i.e. the
/// CRC of every byte before the 4-byte trailer — for a valid table exactly
/// the value in its trailer, the `crc32` that `trueaxis export` prints, so a
/// user can match what the board reports with the file they exported.
///
/// Not the CRC-32 of the whole file: a table ends with the CRC of the bytes
/// before it, so that is the algorithm's constant residue (0x2144DF1C) for
/// every valid table and could not tell two tables apart. The trailer is not
/// covered by the identity, but nothing is used without `table::parse`,
/// which checks it: a table whose trailer was corrupted is refused at
/// commit, at boot and at load.
pub fn table_id(table: &[u8]) -> u32 {
    let body = table.len().saturating_sub(4);
    FRAME_CRC.checksum(&table[..body])
}

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
        /// At most [`MAX_CHUNK_BYTES`].
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
        const NAMES: [&str; 6] = [
            "no_table",
            "bad_table",
            "sensor_range",
            "loop_overrun",
            "not_finite",
            "encoder_jump",
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
    /// Done (answer to [`Request::ClearFaults`] and [`Request::EndInject`]).
    Ok,
    /// The request was refused.
    Error(LinkError),
}

/// Answer to [`Request::Identify`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Firmware version (major, minor, patch).
    pub firmware: [u16; 3],
    /// [`PROTOCOL_VERSION`] of the board.
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
    /// A chunk longer than [`MAX_CHUNK_BYTES`] or past the announced size.
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
    /// fixed-point evaluation is estimated ([`crate::cost::estimate`]) above
    /// what a tick leaves for the model ([`crate::board`]). Refused at
    /// commit; the active table stays. (Appended last, so the messages of
    /// every other variant encode as before.)
    TooSlow {
        /// The table's estimate, instructions per evaluation.
        estimate_instr: u32,
        /// The most the board accepts, instructions.
        budget_instr: u32,
    },
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
        }
    }
}

/// What can go wrong turning bytes into messages and back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The message does not fit the output buffer.
    BufferTooSmall,
    /// More bytes than [`MAX_FRAME_BYTES`] without a delimiter; dropped up
    /// to the next delimiter.
    Overflow,
    /// Invalid COBS encoding.
    Cobs,
    /// Shorter than a CRC.
    TooShort,
    /// CRC mismatch.
    Crc,
    /// CRC fine but postcard could not decode the message (another
    /// protocol version?).
    Decode,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::BufferTooSmall => "message does not fit the frame buffer",
            FrameError::Overflow => "frame longer than the maximum, dropped",
            FrameError::Cobs => "invalid COBS encoding",
            FrameError::TooShort => "frame shorter than its CRC",
            FrameError::Crc => "frame CRC mismatch",
            FrameError::Decode => "frame does not decode as a message",
        })
    }
}

/// Serialises `packet` into one complete frame in `out` (leading and
/// trailing delimiter included) and returns its length.
pub fn encode_frame<T: Serialize>(packet: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_MESSAGE_BYTES + CRC_BYTES];
    let n = postcard::to_slice(packet, &mut raw[..MAX_MESSAGE_BYTES])
        .map_err(|_| FrameError::BufferTooSmall)?
        .len();
    let crc = FRAME_CRC.checksum(&raw[..n]);
    raw[n..n + CRC_BYTES].copy_from_slice(&crc.to_le_bytes());
    let body = n + CRC_BYTES;
    if out.len() < 2 {
        return Err(FrameError::BufferTooSmall);
    }
    out[0] = 0;
    let last = out.len() - 1;
    let enc = cobs::try_encode(&raw[..body], &mut out[1..last])
        .map_err(|_| FrameError::BufferTooSmall)?;
    out[1 + enc] = 0;
    Ok(enc + 2)
}

/// Decodes one message from the payload returned by
/// [`FrameDecoder::feed`] (CRC already checked and stripped).
pub fn decode_message<'a, T: Deserialize<'a>>(payload: &'a [u8]) -> Result<T, FrameError> {
    postcard::from_bytes(payload).map_err(|_| FrameError::Decode)
}

/// Streaming frame receiver: bytes in, checked payloads out. It holds at
/// most one frame (`N` bytes, at least [`MAX_FRAME_BYTES`] to accept every
/// message of this protocol) and always resynchronises at the next `0x00`,
/// whatever came before.
#[derive(Debug)]
pub struct FrameDecoder<const N: usize = MAX_FRAME_BYTES> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
        }
    }

    /// Drops a partial frame (e.g. after a receive timeout).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// Consumes bytes from `input` up to and including the end of the next
    /// complete frame, and returns its checked payload (postcard bytes
    /// without the CRC) or why it was dropped. `None` once `input` is used
    /// up without completing a frame (the partial frame is kept for the
    /// next call). Empty frames (two delimiters in a row) are skipped.
    pub fn feed<'s>(&'s mut self, input: &mut &[u8]) -> Option<Result<&'s [u8], FrameError>> {
        while let Some((&byte, rest)) = input.split_first() {
            *input = rest;
            if byte != 0 {
                if self.len < N {
                    self.buf[self.len] = byte;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                continue;
            }
            // A delimiter: whatever we have is one frame.
            let len = core::mem::replace(&mut self.len, 0);
            if core::mem::replace(&mut self.overflow, false) {
                return Some(Err(FrameError::Overflow));
            }
            if len == 0 {
                continue;
            }
            return Some(check_frame(&mut self.buf[..len]));
        }
        None
    }
}

/// COBS-decodes one frame (without delimiters) in place and checks its CRC;
/// returns the payload.
pub fn check_frame(frame: &mut [u8]) -> Result<&[u8], FrameError> {
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
    if n < CRC_BYTES {
        return Err(FrameError::TooShort);
    }
    let (payload, crc) = frame[..n].split_at(n - CRC_BYTES);
    let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if FRAME_CRC.checksum(payload) != want {
        return Err(FrameError::Crc);
    }
    Ok(payload)
}

/// How the board keeps a table in a flash slot (TABLE_A / TABLE_B of
/// `memory.x`). Defined here because two writers must agree on it: the
/// board's table store (after an upload over the link) and the host's
/// `trueaxis flash` (through a debug probe).
///
/// ```text
///  0..32   header: magic "TAXT", seq u32, len u32, crc32 u32 (of the table
///          bytes), header_crc u32 (CRC-32 of the 16 bytes before), then
///          0xFF padding; all little endian
/// 32..64   revoke marker: all 0xFF = live, anything else = revoked
/// 64..     the table (len bytes)
/// ```
///
/// The valid, non-revoked slot with the highest `seq` is the one that boots.
pub mod slot {
    use super::{Slot, SlotInfo, FRAME_CRC};

    /// "TAXT".
    pub const MAGIC: u32 = u32::from_le_bytes(*b"TAXT");
    /// Offset and size of the header.
    pub const HEADER_AT: u32 = 0;
    /// See [`HEADER_AT`].
    pub const HEADER_BYTES: usize = 32;
    /// Offset and size of the revoke marker.
    pub const REVOKE_AT: u32 = 32;
    /// See [`REVOKE_AT`].
    pub const REVOKE_BYTES: usize = 32;
    /// Offset of the table bytes.
    pub const BODY_AT: u32 = 64;

    /// The header for a table described by `info` (`info.slot` is not
    /// stored: a slot knows where it is).
    pub fn encode_header(info: &SlotInfo) -> [u8; HEADER_BYTES] {
        let mut h = [0xFFu8; HEADER_BYTES];
        h[0..4].copy_from_slice(&MAGIC.to_le_bytes());
        h[4..8].copy_from_slice(&info.seq.to_le_bytes());
        h[8..12].copy_from_slice(&info.len.to_le_bytes());
        h[12..16].copy_from_slice(&info.crc32.to_le_bytes());
        let c = FRAME_CRC.checksum(&h[0..16]);
        h[16..20].copy_from_slice(&c.to_le_bytes());
        h
    }

    /// Decodes a header read from `slot`; `None` unless magic and header
    /// CRC are right (erased, half-written or foreign contents).
    pub fn decode_header(h: &[u8], slot: Slot) -> Option<SlotInfo> {
        let word = |i: usize| -> Option<u32> {
            Some(u32::from_le_bytes(h.get(i..i + 4)?.try_into().ok()?))
        };
        if word(0)? != MAGIC || word(16)? != FRAME_CRC.checksum(h.get(0..16)?) {
            return None;
        }
        Some(SlotInfo {
            slot,
            seq: word(4)?,
            len: word(8)?,
            crc32: word(12)?,
        })
    }

    /// True when a revoke marker read from flash says "live".
    pub fn is_live(marker: &[u8]) -> bool {
        marker.iter().all(|&b| b == 0xFF)
    }

    /// The whole slot image (header, live marker, table) for `table` with
    /// sequence number `seq` — what `trueaxis flash` writes.
    #[cfg(feature = "std")]
    pub fn image(table: &[u8], slot: Slot, seq: u32) -> std::vec::Vec<u8> {
        let info = SlotInfo {
            slot,
            seq,
            len: table.len() as u32,
            crc32: super::table_id(table),
        };
        let mut v = std::vec::Vec::with_capacity(BODY_AT as usize + table.len());
        v.extend_from_slice(&encode_header(&info));
        v.extend_from_slice(&[0xFF; REVOKE_BYTES]);
        v.extend_from_slice(table);
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame_of<T: Serialize>(p: &T) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME_BYTES];
        let n = encode_frame(p, &mut out).unwrap();
        out[..n].to_vec()
    }

    fn decode_all(bytes: &[u8]) -> (Vec<Packet<Request<'static>>>, usize) {
        // Chunks are leaked to get 'static borrows; fine in tests.
        let mut dec: FrameDecoder = FrameDecoder::new();
        let mut input = bytes;
        let mut ok = Vec::new();
        let mut bad = 0;
        while let Some(r) = dec.feed(&mut input) {
            match r.and_then(|p| {
                let owned: &'static [u8] = Box::leak(p.to_vec().into_boxed_slice());
                decode_message::<Packet<Request<'static>>>(owned)
            }) {
                Ok(p) => ok.push(p),
                Err(_) => bad += 1,
            }
        }
        (ok, bad)
    }

    fn biggest_chunk() -> Packet<Request<'static>> {
        static DATA: [u8; MAX_CHUNK_BYTES] = [0xAB; MAX_CHUNK_BYTES];
        Packet {
            seq: u16::MAX,
            msg: Request::UploadChunk {
                offset: u32::MAX,
                data: &DATA,
            },
        }
    }

    #[test]
    fn largest_messages_fit_the_frame() {
        let f = frame_of(&biggest_chunk());
        assert!(
            f.len() <= MAX_FRAME_BYTES,
            "{} > {}",
            f.len(),
            MAX_FRAME_BYTES
        );
        let t = Telemetry {
            uptime_us: u64::MAX,
            ticks: u64::MAX,
            period_us: u32::MAX,
            worst_loop_us: u32::MAX,
            worst_tick_us: u32::MAX,
            overruns: u32::MAX,
            pos_nm: [i32::MIN; 3],
            temp_mc: [i32::MIN; LINK_TEMPS],
            model_corr_nm: [i32::MIN; 3],
            corr_nm: [i32::MIN; 3],
            steps: [i64::MIN; 3],
            model_flags: u16::MAX,
            faults: Faults(u16::MAX),
            faults_latched: Faults(u16::MAX),
            injecting: true,
            active: Some(SlotInfo {
                slot: Slot::B,
                seq: u32::MAX,
                len: u32::MAX,
                crc32: u32::MAX,
            }),
            rx_bad_frames: u32::MAX,
        };
        let f = frame_of(&Packet {
            seq: u16::MAX,
            msg: Response::Status(t),
        });
        assert!(f.len() <= MAX_FRAME_BYTES);
    }

    #[test]
    fn slot_header_round_trip_and_torn_headers() {
        let info = SlotInfo {
            slot: Slot::B,
            seq: 42,
            len: 1000,
            crc32: 0x1234_5678,
        };
        let h = slot::encode_header(&info);
        assert_eq!(slot::decode_header(&h, Slot::B), Some(info));
        // Any prefix written over erased flash is not a header.
        for n in 0..20 {
            let mut torn = [0xFFu8; slot::HEADER_BYTES];
            torn[..n].copy_from_slice(&h[..n]);
            assert_eq!(slot::decode_header(&torn, Slot::B), None, "{n}");
        }
        assert_eq!(slot::decode_header(&h[..10], Slot::B), None);
    }

    #[test]
    fn round_trip_and_delimiters() {
        let p = biggest_chunk();
        let f = frame_of(&p);
        assert_eq!(f[0], 0);
        assert_eq!(*f.last().unwrap(), 0);
        assert!(!f[1..f.len() - 1].contains(&0));
        let (got, bad) = decode_all(&f);
        assert_eq!((got, bad), (vec![p], 0));
    }

    #[test]
    fn flipped_bit_is_caught_by_the_crc() {
        let p = Packet {
            seq: 7,
            msg: Request::UploadBegin {
                size: 1234,
                crc32: 0xDEAD_BEEF,
            },
        };
        let f = frame_of(&p);
        for i in 1..f.len() - 1 {
            for bit in 0..8 {
                let mut g = f.clone();
                g[i] ^= 1 << bit;
                let (got, _) = decode_all(&g);
                assert!(got.is_empty(), "byte {i} bit {bit} got through");
            }
        }
    }

    #[test]
    fn overflow_is_reported_then_next_frame_decodes() {
        let mut bytes = vec![0x55u8; MAX_FRAME_BYTES * 3];
        let p = Packet {
            seq: 1,
            msg: Request::Identify,
        };
        bytes.extend(frame_of(&p));
        let (got, bad) = decode_all(&bytes);
        assert_eq!(got, vec![p]);
        assert_eq!(bad, 1);
    }

    fn any_request() -> impl Strategy<Value = Packet<Request<'static>>> {
        let data = proptest::collection::vec(any::<u8>(), 0..=MAX_CHUNK_BYTES)
            .prop_map(|v| &*Box::leak(v.into_boxed_slice()));
        let msg = prop_oneof![
            Just(Request::Identify),
            Just(Request::Status),
            (any::<u32>(), any::<u32>())
                .prop_map(|(size, crc32)| Request::UploadBegin { size, crc32 }),
            (any::<u32>(), data).prop_map(|(offset, data)| Request::UploadChunk { offset, data }),
            Just(Request::Commit),
            (any::<[i32; 3]>(), any::<[i32; LINK_TEMPS]>(), any::<i32>()).prop_map(
                |(pos_nm, temp_mc, tool_nm)| Request::Inject(Injection {
                    pos_nm,
                    rev_q30: [1 << 30, -(1 << 30), 0],
                    temp_mc,
                    tool_nm
                })
            ),
        ];
        (any::<u16>(), msg).prop_map(|(seq, msg)| Packet { seq, msg })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 512, rng_seed: proptest::test_runner::RngSeed::Fixed(0x7a11), ..ProptestConfig::default() })]

        /// Any byte soup: the decoder never panics and never returns a frame
        /// longer than its buffer.
        #[test]
        fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
            let mut dec: FrameDecoder<64> = FrameDecoder::new();
            let mut input = &bytes[..];
            while let Some(r) = dec.feed(&mut input) {
                if let Ok(p) = r { prop_assert!(p.len() <= 64); }
            }
        }

        /// Valid frames separated by garbage (that may itself contain
        /// delimiters) and by cut frames: every intact frame comes out, in
        /// order, and nothing else does.
        #[test]
        fn frames_survive_garbage_and_cuts(
            msgs in proptest::collection::vec(any_request(), 1..8),
            junk in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 8),
            cut_at in proptest::collection::vec(any::<prop::sample::Index>(), 8),
        ) {
            let mut stream = Vec::new();
            for (i, m) in msgs.iter().enumerate() {
                // Garbage, then a frame cut short at a random point.
                stream.extend(&junk[i]);
                let cut = frame_of(&msgs[(i + 1) % msgs.len()]);
                let k = cut_at[i].index(cut.len() - 1);
                stream.extend(&cut[..k]);
                // The intact frame (its leading delimiter flushes the rest).
                stream.extend(frame_of(m));
            }
            let (got, _bad) = decode_all(&stream);
            // Every intact frame is decoded; junk may (with negligible
            // probability, CRC-32) also contain something, and a cut frame
            // whose cut point is the trailing delimiter... is excluded above.
            let mut it = got.iter();
            for m in &msgs {
                prop_assert!(it.any(|g| g == m), "lost {:?}", m);
            }
        }
    }
}

#[cfg(test)]
mod table_id_tests {
    use super::{table_id, FRAME_CRC};

    /// Two different byte strings that each end with their own CRC-32, as
    /// every table does: the whole-file CRC-32 is the same residue for both,
    /// the table identity is not, and it equals each one's trailer.
    #[test]
    fn table_id_tells_self_checked_files_apart() {
        let seal = |body: &[u8]| {
            let mut v = body.to_vec();
            v.extend_from_slice(&FRAME_CRC.checksum(body).to_le_bytes());
            v
        };
        let (a, b) = (seal(b"table one"), seal(b"another table"));
        assert_eq!(FRAME_CRC.checksum(&a), FRAME_CRC.checksum(&b));
        assert_ne!(table_id(&a), table_id(&b));
        for t in [&a, &b] {
            let trailer = u32::from_le_bytes(t[t.len() - 4..].try_into().unwrap());
            assert_eq!(table_id(t), trailer);
        }
        // Shorter than a trailer: no panic, still a checksum of something.
        assert_eq!(table_id(b"abc"), FRAME_CRC.checksum(b""));
    }
}
