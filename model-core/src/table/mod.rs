//! Table format v1: the one definition of the binary coefficient table that
//! the host exports and the firmware runs (documented byte for byte in
//! `docs/table-format.md`). [`parse`] is zero-copy and validates everything —
//! length, magic, version, CRC32, every count, range and field — before it
//! returns a [`Table`], so the accessors of a `Table` never meet malformed
//! bytes. It never panics on any input (fuzzed under `fuzz/`, proptested in
//! `tests/format.rs`). All multi-byte fields are little-endian and read with
//! `from_le_bytes`, so the table may sit at any alignment (e.g. in flash).

use core::fmt;

mod bytes;
mod validate;
mod view;

use bytes::{arr, rd_i64, rd_u16, rd_u32, rd_u8};
pub(crate) use validate::MlpShape;
use validate::{envelope_at, scaling_at, validate_structure};
pub use view::{GridAxisRef, GridView, MlpInputRef, MlpView, PolyCoefs, TermRef, TermView, Terms};

pub use crate::limits::{
    MAX_DEGREE, MAX_HARMONICS, MAX_HIDDEN_LAYERS, MAX_HIDDEN_UNITS, MAX_MLP_INPUTS, MAX_MONOMIALS,
    MAX_TEMPS,
};

/// The four magic bytes at offset 0.
pub const MAGIC: [u8; 4] = *b"TXAX";
/// The only format version this code reads and writes.
pub const FORMAT_VERSION: u16 = 1;
/// Byte length of the fixed part before the term list (header, metadata,
/// envelope, input scaling, outputs).
pub const FIXED_LEN: usize = 228;
/// Bytes of the CRC32 trailer.
pub const CRC_LEN: usize = 4;
/// Largest table accepted: one flash slot (128 KiB).
pub const MAX_TABLE_LEN: usize = 128 * 1024;
/// Bytes per channel name (UTF-8, NUL padded).
pub const CHANNEL_NAME_LEN: usize = 16;
/// Byte length of a term header (kind, outputs, aux, reserved, body length).
pub const TERM_HEADER_LEN: usize = 8;
/// Most nodes along one grid axis.
pub const MAX_GRID_NODES_PER_AXIS: u16 = 1024;
/// Largest |max correction| an envelope may declare: 4 mm, below 2^22 nm so
/// the f32 evaluator rounds its outputs exactly with one add and subtract.
pub const MAX_CORR_LIMIT_NM: i32 = 4_000_000;
/// Largest `max_slew_nm_per_ms` a table may carry: 10 m/s, beyond any
/// correction's rate of change (a correction gradient of 1 µm/mm at a
/// feed of 100 m/min changes by 1.7 µm/ms). The engine reduces any slew to
/// what its pulses can follow; this bound refuses a slew that can only be
/// a unit or typing mistake, at export and on the board alike.
pub const MAX_SLEW_LIMIT_NM_PER_MS: i32 = 10_000_000;
/// Largest |T_ref| of a thermal term (200 °C).
pub const MAX_TREF_MC: i32 = 200_000;
/// The CRC used for the trailer: CRC-32/ISO-HDLC (the zlib/PNG CRC-32,
/// reflected polynomial 0xEDB88320, init and xorout 0xFFFFFFFF).
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Units code (metadata byte 15): v1 knows only "positions and corrections
/// in nm, temperatures in m°C, tool arm in nm".
pub const UNITS_NM_MC: u8 = 0;

/// Why a byte string is not a valid table. Offsets are byte offsets into the
/// table where the offending field starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TableError {
    /// Fewer bytes than the fixed part plus the CRC trailer.
    TooShort { len: u32 },
    /// The first four bytes are not `TXAX`.
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion { version: u16 },
    /// The header's total length differs from the number of bytes given.
    LengthMismatch { declared: u32, actual: u32 },
    /// The header's total length exceeds a flash slot.
    TooLong { declared: u32 },
    /// The CRC32 trailer does not match the bytes.
    CrcMismatch { stored: u32, computed: u32 },
    /// A reserved byte or field is not zero.
    ReservedNonZero { offset: u32 },
    /// The units code is not one this version knows.
    UnsupportedUnits { code: u8 },
    /// More temperature channels than `MAX_TEMPS`.
    BadChannelCount { count: u8 },
    /// A channel name is empty, not UTF-8, or not NUL padded (or an unused slot is not zero).
    BadChannelName { channel: u8 },
    /// An envelope field is out of range (min > max, negative max, slew ≤ 0 …).
    BadEnvelope { offset: u32 },
    /// An input scaling half-span is not positive.
    BadScaling { axis: u8 },
    /// The travel of an axis is not inside centre ± half-span (|u| ≤ 1 is required).
    TravelOutsideScaling { axis: u8 },
    /// The outputs byte has bits other than ex, ey, ez.
    BadOutputs { offset: u32 },
    /// A term kind this version does not know.
    UnknownTermKind { offset: u32, kind: u8 },
    /// A term header or body runs past the end of the term list.
    TermTruncated { offset: u32 },
    /// A term body's declared length differs from what its counts imply.
    TermLengthMismatch { offset: u32 },
    /// A term's output mask is empty, names an absent output, or (single-output kinds) has more than one bit.
    BadTermOutputs { offset: u32 },
    /// A field inside a term is out of range (count, axis, channel, degree, period, size …).
    BadTermField { offset: u32 },
    /// A polynomial lists the same monomial twice.
    DuplicateMonomial { offset: u32 },
    /// A floating-point field is NaN or infinite.
    NotFinite { offset: u32 },
    /// Bytes left over between the last term and the CRC trailer.
    TrailingBytes { offset: u32 },
    /// A reversal term's transition length differs from an earlier reversal term's on the same axis.
    ReversalTransitionMismatch { offset: u32 },
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooShort { len } => write!(f, "table too short ({len} bytes)"),
            Self::BadMagic => write!(f, "not a trueaxis table (bad magic)"),
            Self::UnsupportedVersion { version } => {
                write!(f, "unsupported table format version {version} (this build reads {FORMAT_VERSION})")
            }
            Self::LengthMismatch { declared, actual } => {
                write!(
                    f,
                    "table length mismatch: header says {declared} bytes, got {actual}"
                )
            }
            Self::TooLong { declared } => write!(f, "table too long ({declared} bytes)"),
            Self::CrcMismatch { stored, computed } => {
                write!(
                    f,
                    "CRC32 mismatch: stored {stored:#010x}, computed {computed:#010x}"
                )
            }
            Self::ReservedNonZero { offset } => {
                write!(f, "reserved field at offset {offset} is not zero")
            }
            Self::UnsupportedUnits { code } => write!(f, "unsupported units code {code}"),
            Self::BadChannelCount { count } => write!(f, "bad temperature channel count {count}"),
            Self::BadChannelName { channel } => {
                write!(f, "bad name for temperature channel {channel}")
            }
            Self::BadEnvelope { offset } => {
                write!(f, "envelope field at offset {offset} out of range")
            }
            Self::BadScaling { axis } => {
                write!(f, "input scaling of axis {axis}: half-span must be > 0")
            }
            Self::TravelOutsideScaling { axis } => {
                write!(f, "travel of axis {axis} is outside centre ± half-span")
            }
            Self::BadOutputs { offset } => write!(f, "bad outputs mask at offset {offset}"),
            Self::UnknownTermKind { offset, kind } => {
                write!(f, "unknown term kind {kind} at offset {offset}")
            }
            Self::TermTruncated { offset } => write!(f, "term at offset {offset} is truncated"),
            Self::TermLengthMismatch { offset } => {
                write!(f, "term at offset {offset} has a wrong body length")
            }
            Self::BadTermOutputs { offset } => {
                write!(f, "term at offset {offset} has a bad output mask")
            }
            Self::BadTermField { offset } => {
                write!(f, "term field at offset {offset} out of range")
            }
            Self::DuplicateMonomial { offset } => {
                write!(f, "duplicate monomial at offset {offset}")
            }
            Self::NotFinite { offset } => write!(f, "non-finite number at offset {offset}"),
            Self::TrailingBytes { offset } => {
                write!(f, "unexpected bytes after the last term at offset {offset}")
            }
            Self::ReversalTransitionMismatch { offset } => {
                write!(
                    f,
                    "reversal transition at offset {offset} differs from an earlier reversal term's on the same axis"
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for TableError {}

/// The envelope a table declares: where it is valid and how far the firmware
/// may move the machine with it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Envelope {
    /// Lower travel bound per axis (x, y, z), nm.
    pub travel_min_nm: [i32; 3],
    /// Upper travel bound per axis, nm.
    pub travel_max_nm: [i32; 3],
    /// Largest |correction| per output (ex, ey, ez), nm.
    pub max_corr_nm: [i32; 3],
    /// Largest change of any correction per millisecond, nm/ms (applied by the firmware engine).
    pub max_slew_nm_per_ms: i32,
    /// Lowest valid temperature per channel, m°C (unused channels: 0).
    pub temp_min_mc: [i32; MAX_TEMPS],
    /// Highest valid temperature per channel, m°C.
    pub temp_max_mc: [i32; MAX_TEMPS],
    /// Lowest valid tool arm (Abbe arm), nm.
    pub tool_min_nm: i32,
    /// Highest valid tool arm, nm.
    pub tool_max_nm: i32,
}

impl Envelope {
    /// The slew limit the firmware's engine applies, nm/ms.
    pub fn max_slew_nm_per_ms(&self) -> i32 {
        self.max_slew_nm_per_ms
    }
    /// Travel (min, max) of `axis` (0 = x), nm.
    pub fn travel_nm(&self, axis: usize) -> (i32, i32) {
        (
            self.travel_min_nm.get(axis).copied().unwrap_or(0),
            self.travel_max_nm.get(axis).copied().unwrap_or(0),
        )
    }
    /// Largest |correction| of `output` (0 = ex), nm.
    pub fn max_corr_nm(&self, output: usize) -> i32 {
        self.max_corr_nm.get(output).copied().unwrap_or(0)
    }
}

/// How positions are normalised for polynomials: u = (p − centre) / half-span.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InputScaling {
    /// Centre per axis, nm.
    pub centre_nm: [i32; 3],
    /// Half-span per axis, nm (> 0).
    pub half_span_nm: [i32; 3],
}

/// Term kind codes (byte 0 of a term header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum TermKind {
    /// Σ c·x^a y^b z^c in normalised positions.
    Poly = 1,
    /// Σ a_k sin + b_k cos of the phase along one axis.
    Periodic = 2,
    /// (T − T_ref) × polynomial (a single constant monomial = "alone").
    Thermal = 3,
    /// amplitude × reversal state of an axis.
    Reversal = 4,
    /// tool arm × polynomial (Abbe).
    Abbe = 5,
    /// tanh multilayer perceptron.
    Mlp = 6,
    /// Grid table on 1–3 axes with (bi/tri)linear interpolation.
    Grid = 7,
}

impl TermKind {
    /// The kind's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Self::Poly => "polynomial",
            Self::Periodic => "periodic",
            Self::Thermal => "thermal",
            Self::Reversal => "reversal",
            Self::Abbe => "Abbe",
            Self::Mlp => "MLP",
            Self::Grid => "grid",
        }
    }

    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            1 => Self::Poly,
            2 => Self::Periodic,
            3 => Self::Thermal,
            4 => Self::Reversal,
            5 => Self::Abbe,
            6 => Self::Mlp,
            7 => Self::Grid,
            _ => return None,
        })
    }
}

/// A monomial x^a y^b z^c as its exponents `[a, b, c]`.
pub type Monomial = [u8; 3];

// ---------------------------------------------------------------------------
// Little-endian readers that never panic: out of range reads yield 0 (only
// used on already-validated bytes, or after an explicit length check).

/// Byte offsets of the fixed part (see docs/table-format.md).
pub mod layout {
    /// Magic, 4 bytes.
    pub const MAGIC: usize = 0;
    /// Format version, u16.
    pub const VERSION: usize = 4;
    /// Reserved, u16 = 0.
    pub const RESERVED0: usize = 6;
    /// Total length including the CRC trailer, u32.
    pub const TOTAL_LEN: usize = 8;
    /// Number of terms, u16.
    pub const TERM_COUNT: usize = 12;
    /// Number of temperature channels, u8.
    pub const CHANNEL_COUNT: usize = 14;
    /// Units code, u8.
    pub const UNITS: usize = 15;
    /// Creation time, Unix seconds, i64.
    pub const CREATED: usize = 16;
    /// Hash of the source data, 32 bytes.
    pub const SOURCE_HASH: usize = 24;
    /// Channel names, MAX_TEMPS × 16 bytes.
    pub const CHANNEL_NAMES: usize = 56;
    /// Envelope: travel min [i32; 3].
    pub const TRAVEL_MIN: usize = 120;
    /// Envelope: travel max [i32; 3].
    pub const TRAVEL_MAX: usize = 132;
    /// Envelope: max |correction| [i32; 3].
    pub const MAX_CORR: usize = 144;
    /// Envelope: max slew nm/ms, i32.
    pub const MAX_SLEW: usize = 156;
    /// Envelope: temperature min [i32; 4].
    pub const TEMP_MIN: usize = 160;
    /// Envelope: temperature max [i32; 4].
    pub const TEMP_MAX: usize = 176;
    /// Envelope: tool min, i32.
    pub const TOOL_MIN: usize = 192;
    /// Envelope: tool max, i32.
    pub const TOOL_MAX: usize = 196;
    /// Scaling: centre [i32; 3].
    pub const CENTRE: usize = 200;
    /// Scaling: half-span [i32; 3].
    pub const HALF_SPAN: usize = 212;
    /// Outputs present mask, u8 (bit 0 ex, 1 ey, 2 ez).
    pub const OUTPUTS: usize = 224;
    /// Reserved, 3 bytes = 0.
    pub const RESERVED1: usize = 225;
    /// First term header.
    pub const TERMS: usize = 228;
}

/// A parsed, fully validated table borrowing its bytes.
#[derive(Clone, Copy, Debug)]
pub struct Table<'a> {
    bytes: &'a [u8],
}

/// Parse and validate a table that is exactly `bytes` long.
pub fn parse(bytes: &[u8]) -> Result<Table<'_>, TableError> {
    let len = bytes.len();
    if len < FIXED_LEN + CRC_LEN {
        return Err(TableError::TooShort {
            len: len.min(u32::MAX as usize) as u32,
        });
    }
    if bytes.get(0..4) != Some(&MAGIC[..]) {
        return Err(TableError::BadMagic);
    }
    let version = rd_u16(bytes, layout::VERSION);
    if version != FORMAT_VERSION {
        return Err(TableError::UnsupportedVersion { version });
    }
    let declared = rd_u32(bytes, layout::TOTAL_LEN);
    if declared as usize > MAX_TABLE_LEN {
        return Err(TableError::TooLong { declared });
    }
    if declared as usize != len {
        return Err(TableError::LengthMismatch {
            declared,
            actual: len.min(u32::MAX as usize) as u32,
        });
    }
    let body = &bytes[..len - CRC_LEN];
    let stored = rd_u32(bytes, len - CRC_LEN);
    let computed = CRC32.checksum(body);
    if stored != computed {
        return Err(TableError::CrcMismatch { stored, computed });
    }
    validate_structure(body)?;
    Ok(Table { bytes })
}

/// Parse a table at the start of a longer buffer (e.g. a whole flash slot):
/// the header's total length says where it ends; the rest is ignored.
pub fn parse_prefix(bytes: &[u8]) -> Result<Table<'_>, TableError> {
    if bytes.len() < FIXED_LEN + CRC_LEN {
        return Err(TableError::TooShort {
            len: bytes.len().min(u32::MAX as usize) as u32,
        });
    }
    let declared = rd_u32(bytes, layout::TOTAL_LEN) as usize;
    match bytes.get(..declared) {
        Some(b) => parse(b),
        None => parse(bytes),
    }
}

// ---------------------------------------------------------------------------
// Accessors of a validated table.

impl<'a> Table<'a> {
    /// The whole table, CRC trailer included.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }
    /// The CRC32 stored in (and verified against) the trailer.
    pub fn crc32(&self) -> u32 {
        rd_u32(self.bytes, self.bytes.len().saturating_sub(CRC_LEN))
    }
    /// Format version (always [`FORMAT_VERSION`] for a parsed table).
    pub fn version(&self) -> u16 {
        rd_u16(self.bytes, layout::VERSION)
    }
    /// Creation time, seconds since the Unix epoch.
    pub fn created_unix_s(&self) -> i64 {
        rd_i64(self.bytes, layout::CREATED)
    }
    /// Hash of the source data the model was fitted on (SHA-256 by the host tool's convention).
    pub fn source_hash(&self) -> [u8; 32] {
        arr(self.bytes, layout::SOURCE_HASH)
    }
    /// Number of temperature channels.
    pub fn channel_count(&self) -> usize {
        rd_u8(self.bytes, layout::CHANNEL_COUNT) as usize
    }
    /// Name of temperature channel `ch` (e.g. `bed`), `None` past the count.
    pub fn channel_name(&self, ch: usize) -> Option<&'a str> {
        if ch >= self.channel_count() {
            return None;
        }
        let off = layout::CHANNEL_NAMES + ch * CHANNEL_NAME_LEN;
        let raw = self.bytes.get(off..off + CHANNEL_NAME_LEN)?;
        let n = raw.iter().position(|&c| c == 0).unwrap_or(CHANNEL_NAME_LEN);
        core::str::from_utf8(&raw[..n]).ok()
    }
    /// The declared envelope.
    pub fn envelope(&self) -> Envelope {
        envelope_at(self.bytes)
    }
    /// The input scaling used by polynomials.
    pub fn scaling(&self) -> InputScaling {
        scaling_at(self.bytes)
    }
    /// Outputs present: bit 0 ex, bit 1 ey, bit 2 ez.
    pub fn outputs_mask(&self) -> u8 {
        rd_u8(self.bytes, layout::OUTPUTS)
    }
    /// Whether output `o` (0 = ex) is present.
    pub fn has_output(&self, o: usize) -> bool {
        o < 3 && self.outputs_mask() & (1 << o) != 0
    }
    /// Number of terms.
    pub fn term_count(&self) -> usize {
        rd_u16(self.bytes, layout::TERM_COUNT) as usize
    }
    /// Iterate over the terms in table order.
    pub fn terms(&self) -> Terms<'a> {
        Terms {
            bytes: self.bytes,
            off: layout::TERMS,
            left: self.term_count(),
        }
    }
}
