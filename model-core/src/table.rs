//! Table format v1: the one definition of the binary coefficient table that
//! the host exports and the firmware runs (documented byte for byte in
//! `docs/table-format.md`). [`parse`] is zero-copy and validates everything —
//! length, magic, version, CRC32, every count, range and field — before it
//! returns a [`Table`], so the accessors of a `Table` never meet malformed
//! bytes. It never panics on any input (fuzzed under `fuzz/`, proptested in
//! `tests/format.rs`). All multi-byte fields are little-endian and read with
//! `from_le_bytes`, so the table may sit at any alignment (e.g. in flash).

use core::fmt;

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

#[inline]
fn arr<const N: usize>(b: &[u8], off: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(s) = off.checked_add(N).and_then(|end| b.get(off..end)) {
        out.copy_from_slice(s);
    }
    out
}
#[inline]
pub(crate) fn rd_u16(b: &[u8], off: usize) -> u16 {
    u16::from_le_bytes(arr(b, off))
}
#[inline]
pub(crate) fn rd_u32(b: &[u8], off: usize) -> u32 {
    u32::from_le_bytes(arr(b, off))
}
#[inline]
pub(crate) fn rd_i32(b: &[u8], off: usize) -> i32 {
    i32::from_le_bytes(arr(b, off))
}
#[inline]
pub(crate) fn rd_i64(b: &[u8], off: usize) -> i64 {
    i64::from_le_bytes(arr(b, off))
}
#[inline]
pub(crate) fn rd_f64(b: &[u8], off: usize) -> f64 {
    f64::from_le_bytes(arr(b, off))
}
#[inline]
fn rd_u8(b: &[u8], off: usize) -> u8 {
    b.get(off).copied().unwrap_or(0)
}

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

fn i32x3(b: &[u8], off: usize) -> [i32; 3] {
    [rd_i32(b, off), rd_i32(b, off + 4), rd_i32(b, off + 8)]
}
fn i32x4(b: &[u8], off: usize) -> [i32; 4] {
    [
        rd_i32(b, off),
        rd_i32(b, off + 4),
        rd_i32(b, off + 8),
        rd_i32(b, off + 12),
    ]
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

fn check_reserved(b: &[u8], off: usize, n: usize) -> Result<(), TableError> {
    for i in off..off + n {
        if rd_u8(b, i) != 0 {
            return Err(TableError::ReservedNonZero { offset: i as u32 });
        }
    }
    Ok(())
}

fn finite(b: &[u8], off: usize) -> Result<f64, TableError> {
    let v = rd_f64(b, off);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(TableError::NotFinite { offset: off as u32 })
    }
}

fn validate_structure(b: &[u8]) -> Result<(), TableError> {
    use layout as l;
    check_reserved(b, l::RESERVED0, 2)?;
    let units = rd_u8(b, l::UNITS);
    if units != UNITS_NM_MC {
        return Err(TableError::UnsupportedUnits { code: units });
    }
    let nch = rd_u8(b, l::CHANNEL_COUNT);
    if nch as usize > MAX_TEMPS {
        return Err(TableError::BadChannelCount { count: nch });
    }
    for ch in 0..MAX_TEMPS {
        let off = l::CHANNEL_NAMES + ch * CHANNEL_NAME_LEN;
        let raw = &b[off..off + CHANNEL_NAME_LEN];
        let bad = TableError::BadChannelName { channel: ch as u8 };
        if ch < nch as usize {
            let n = raw.iter().position(|&c| c == 0).unwrap_or(CHANNEL_NAME_LEN);
            if n == 0
                || raw[n..].iter().any(|&c| c != 0)
                || core::str::from_utf8(&raw[..n]).is_err()
            {
                return Err(bad);
            }
        } else if raw.iter().any(|&c| c != 0) {
            return Err(bad);
        }
    }
    // Envelope.
    let env = envelope_at(b);
    for a in 0..3 {
        if env.travel_min_nm[a] > env.travel_max_nm[a] {
            return Err(TableError::BadEnvelope {
                offset: (l::TRAVEL_MIN + 4 * a) as u32,
            });
        }
        if !(0..=MAX_CORR_LIMIT_NM).contains(&env.max_corr_nm[a]) {
            return Err(TableError::BadEnvelope {
                offset: (l::MAX_CORR + 4 * a) as u32,
            });
        }
    }
    if env.max_slew_nm_per_ms <= 0 {
        return Err(TableError::BadEnvelope {
            offset: l::MAX_SLEW as u32,
        });
    }
    for ch in 0..MAX_TEMPS {
        let (lo, hi) = (env.temp_min_mc[ch], env.temp_max_mc[ch]);
        let ok = if ch < nch as usize {
            lo <= hi && lo >= -MAX_TREF_MC && hi <= MAX_TREF_MC
        } else {
            lo == 0 && hi == 0
        };
        if !ok {
            return Err(TableError::BadEnvelope {
                offset: (l::TEMP_MIN + 4 * ch) as u32,
            });
        }
    }
    if env.tool_min_nm > env.tool_max_nm {
        return Err(TableError::BadEnvelope {
            offset: l::TOOL_MIN as u32,
        });
    }
    // Scaling: the travel must map into |u| ≤ 1 so that every monomial stays
    // within ±1 (the fixed-point evaluator's range analysis relies on it).
    let sc = scaling_at(b);
    for a in 0..3 {
        let h = sc.half_span_nm[a];
        if h <= 0 {
            return Err(TableError::BadScaling { axis: a as u8 });
        }
        let c = sc.centre_nm[a] as i64;
        if (env.travel_min_nm[a] as i64) < c - h as i64
            || (env.travel_max_nm[a] as i64) > c + h as i64
        {
            return Err(TableError::TravelOutsideScaling { axis: a as u8 });
        }
    }
    let outputs = rd_u8(b, l::OUTPUTS);
    if outputs & !0b111 != 0 {
        return Err(TableError::BadOutputs {
            offset: l::OUTPUTS as u32,
        });
    }
    check_reserved(b, l::RESERVED1, 3)?;
    // Terms.
    let count = rd_u16(b, l::TERM_COUNT);
    let mut off = l::TERMS;
    // Reversal terms of one axis must share one transition length. The
    // evaluator reads one reversal state per axis (`Inputs::rev_q30`), which
    // the firmware's single `DirTracker` per axis produces with one
    // transition length (`Model::reversal_transition_nm`); a second term
    // with another length would run on the first one's ramp, its own length
    // silently ignored. Refusing the table is the safe choice: one state per
    // axis is what the inputs, the link and the firmware carry, trackers
    // per term would change all three for a table no exporter writes (the
    // host exports one length for every reversal term). 0 = no term yet
    // (a valid length is > 0).
    let mut transition_nm = [0i32; 3];
    for _ in 0..count {
        let hdr_end = off + TERM_HEADER_LEN;
        if hdr_end > b.len() {
            return Err(TableError::TermTruncated { offset: off as u32 });
        }
        let body_len = rd_u32(b, off + 4) as usize;
        let end = match hdr_end.checked_add(body_len) {
            Some(e) if e <= b.len() => e,
            _ => return Err(TableError::TermTruncated { offset: off as u32 }),
        };
        validate_term(b, off, end, outputs, nch)?;
        if rd_u8(b, off) == TermKind::Reversal as u8 {
            // Validated: the axis is < 3, the length > 0.
            let axis = rd_u8(b, off + 2) as usize % 3;
            let t = rd_i32(b, off + TERM_HEADER_LEN);
            if transition_nm[axis] == 0 {
                transition_nm[axis] = t;
            } else if transition_nm[axis] != t {
                return Err(TableError::ReversalTransitionMismatch {
                    offset: (off + TERM_HEADER_LEN) as u32,
                });
            }
        }
        off = end;
    }
    if off != b.len() {
        return Err(TableError::TrailingBytes { offset: off as u32 });
    }
    Ok(())
}

fn envelope_at(b: &[u8]) -> Envelope {
    use layout as l;
    Envelope {
        travel_min_nm: i32x3(b, l::TRAVEL_MIN),
        travel_max_nm: i32x3(b, l::TRAVEL_MAX),
        max_corr_nm: i32x3(b, l::MAX_CORR),
        max_slew_nm_per_ms: rd_i32(b, l::MAX_SLEW),
        temp_min_mc: i32x4(b, l::TEMP_MIN),
        temp_max_mc: i32x4(b, l::TEMP_MAX),
        tool_min_nm: rd_i32(b, l::TOOL_MIN),
        tool_max_nm: rd_i32(b, l::TOOL_MAX),
    }
}

fn scaling_at(b: &[u8]) -> InputScaling {
    InputScaling {
        centre_nm: i32x3(b, layout::CENTRE),
        half_span_nm: i32x3(b, layout::HALF_SPAN),
    }
}

/// Validate a polynomial body (count, entries) starting at `off`, ending exactly at `end`.
fn validate_poly(b: &[u8], off: usize, end: usize) -> Result<(), TableError> {
    if off + 4 > end {
        return Err(TableError::TermLengthMismatch { offset: off as u32 });
    }
    let n = rd_u16(b, off) as usize;
    check_reserved(b, off + 2, 2)?;
    if n == 0 || n > MAX_MONOMIALS {
        return Err(TableError::BadTermField { offset: off as u32 });
    }
    if off + 4 + 12 * n != end {
        return Err(TableError::TermLengthMismatch { offset: off as u32 });
    }
    for i in 0..n {
        let e = off + 4 + 12 * i;
        let m = [rd_u8(b, e), rd_u8(b, e + 1), rd_u8(b, e + 2)];
        check_reserved(b, e + 3, 1)?;
        if m.iter().map(|&v| v as u32).sum::<u32>() > MAX_DEGREE as u32 {
            return Err(TableError::BadTermField { offset: e as u32 });
        }
        for j in 0..i {
            let e2 = off + 4 + 12 * j;
            if [rd_u8(b, e2), rd_u8(b, e2 + 1), rd_u8(b, e2 + 2)] == m {
                return Err(TableError::DuplicateMonomial { offset: e as u32 });
            }
        }
        finite(b, e + 4)?;
    }
    Ok(())
}

fn validate_term(b: &[u8], off: usize, end: usize, present: u8, nch: u8) -> Result<(), TableError> {
    let kind_raw = rd_u8(b, off);
    let kind = TermKind::from_u8(kind_raw).ok_or(TableError::UnknownTermKind {
        offset: off as u32,
        kind: kind_raw,
    })?;
    let outs = rd_u8(b, off + 1);
    let aux = rd_u8(b, off + 2);
    check_reserved(b, off + 3, 1)?;
    let bad_outs = TableError::BadTermOutputs {
        offset: (off + 1) as u32,
    };
    if outs == 0 || outs & !present != 0 {
        return Err(bad_outs);
    }
    if kind != TermKind::Mlp && outs.count_ones() != 1 {
        return Err(bad_outs);
    }
    let bad_aux = TableError::BadTermField {
        offset: (off + 2) as u32,
    };
    let body = off + TERM_HEADER_LEN;
    let mismatch = TableError::TermLengthMismatch { offset: off as u32 };
    match kind {
        TermKind::Poly => {
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_poly(b, body, end)
        }
        TermKind::Abbe => {
            // aux: the arm input; 0 = the tool arm (the only one in v1).
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_poly(b, body, end)
        }
        TermKind::Thermal => {
            if aux >= nch {
                return Err(bad_aux);
            }
            if body + 8 > end {
                return Err(mismatch);
            }
            let tref = rd_i32(b, body);
            if !(-MAX_TREF_MC..=MAX_TREF_MC).contains(&tref) {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            check_reserved(b, body + 4, 4)?;
            validate_poly(b, body + 8, end)
        }
        TermKind::Periodic => {
            if aux >= 3 {
                return Err(bad_aux);
            }
            if body + 8 > end {
                return Err(mismatch);
            }
            if rd_i32(b, body) <= 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            let h = rd_u8(b, body + 4) as usize;
            if h == 0 || h > MAX_HARMONICS {
                return Err(TableError::BadTermField {
                    offset: (body + 4) as u32,
                });
            }
            check_reserved(b, body + 5, 3)?;
            if body + 8 + 16 * h != end {
                return Err(mismatch);
            }
            for i in 0..2 * h {
                finite(b, body + 8 + 8 * i)?;
            }
            Ok(())
        }
        TermKind::Reversal => {
            if aux >= 3 {
                return Err(bad_aux);
            }
            if body + 16 != end {
                return Err(mismatch);
            }
            if rd_i32(b, body) <= 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            check_reserved(b, body + 4, 4)?;
            finite(b, body + 8).map(|_| ())
        }
        TermKind::Mlp => {
            if aux != 0 {
                return Err(bad_aux);
            }
            validate_mlp(b, body, end, outs.count_ones() as usize, nch)
        }
        TermKind::Grid => {
            if aux != 0 {
                return Err(bad_aux);
            }
            if body + 36 > end {
                return Err(mismatch);
            }
            let mut total: usize = 1;
            let mut used = 0;
            for a in 0..3 {
                let e = body + 12 * a;
                let nodes = rd_u16(b, e);
                check_reserved(b, e + 2, 2)?;
                if nodes == 0 || nodes > MAX_GRID_NODES_PER_AXIS {
                    return Err(TableError::BadTermField { offset: e as u32 });
                }
                if rd_i32(b, e + 8) <= 0 {
                    return Err(TableError::BadTermField {
                        offset: (e + 8) as u32,
                    });
                }
                // The last node must stay representable in i32 nm.
                let last = rd_i32(b, e + 4) as i64 + (nodes as i64 - 1) * rd_i32(b, e + 8) as i64;
                if last > i32::MAX as i64 {
                    return Err(TableError::BadTermField {
                        offset: (e + 8) as u32,
                    });
                }
                if nodes >= 2 {
                    used += 1;
                }
                total *= nodes as usize;
            }
            if used == 0 {
                return Err(TableError::BadTermField {
                    offset: body as u32,
                });
            }
            match total.checked_mul(8).and_then(|v| v.checked_add(body + 36)) {
                Some(e) if e == end => {}
                _ => return Err(mismatch),
            }
            for i in 0..total {
                finite(b, body + 36 + 8 * i)?;
            }
            Ok(())
        }
    }
}

/// Byte sizes of an MLP body's parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct MlpShape {
    pub n_in: usize,
    pub hidden: [usize; MAX_HIDDEN_LAYERS],
    pub n_layers: usize,
    pub n_out: usize,
}

impl MlpShape {
    /// Number of f64 weights and biases.
    pub fn n_params(&self) -> usize {
        let mut prev = self.n_in;
        let mut n = 0;
        for &h in &self.hidden[..self.n_layers] {
            n += h * prev + h;
            prev = h;
        }
        n + self.n_out * prev + self.n_out
    }
    /// Body length in bytes.
    pub fn body_len(&self) -> usize {
        4 + 20 * self.n_in + 16 * self.n_out + 8 * self.n_params()
    }
}

fn mlp_shape(b: &[u8], body: usize, n_out: usize) -> MlpShape {
    MlpShape {
        n_in: rd_u8(b, body) as usize,
        n_layers: rd_u8(b, body + 1) as usize,
        hidden: [rd_u8(b, body + 2) as usize, rd_u8(b, body + 3) as usize],
        n_out,
    }
}

fn validate_mlp(
    b: &[u8],
    body: usize,
    end: usize,
    n_out: usize,
    nch: u8,
) -> Result<(), TableError> {
    if body + 4 > end {
        return Err(TableError::TermLengthMismatch {
            offset: body as u32,
        });
    }
    let s = mlp_shape(b, body, n_out);
    if s.n_in == 0 || s.n_in > MAX_MLP_INPUTS {
        return Err(TableError::BadTermField {
            offset: body as u32,
        });
    }
    if s.n_layers == 0 || s.n_layers > MAX_HIDDEN_LAYERS {
        return Err(TableError::BadTermField {
            offset: (body + 1) as u32,
        });
    }
    for i in 0..MAX_HIDDEN_LAYERS {
        let h = s.hidden[i];
        let ok = if i < s.n_layers {
            (1..=MAX_HIDDEN_UNITS).contains(&h)
        } else {
            h == 0
        };
        if !ok {
            return Err(TableError::BadTermField {
                offset: (body + 2 + i) as u32,
            });
        }
    }
    if body + s.body_len() != end {
        return Err(TableError::TermLengthMismatch {
            offset: body as u32,
        });
    }
    let mut off = body + 4;
    for _ in 0..s.n_in {
        let src = rd_u8(b, off);
        if src as usize >= 3 + nch as usize {
            return Err(TableError::BadTermField { offset: off as u32 });
        }
        check_reserved(b, off + 1, 3)?;
        let lo = finite(b, off + 4)?;
        let hi = finite(b, off + 12)?;
        if lo >= hi || hi - lo < 1e-3 || lo.abs() > 1e10 || hi.abs() > 1e10 {
            return Err(TableError::BadTermField {
                offset: (off + 4) as u32,
            });
        }
        off += 20;
    }
    for _ in 0..s.n_out {
        let lo = finite(b, off)?;
        let hi = finite(b, off + 8)?;
        if lo > hi {
            return Err(TableError::BadTermField { offset: off as u32 });
        }
        off += 16;
    }
    for _ in 0..s.n_params() {
        finite(b, off)?;
        off += 8;
    }
    Ok(())
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

/// Iterator over the terms of a table.
#[derive(Clone, Debug)]
pub struct Terms<'a> {
    bytes: &'a [u8],
    off: usize,
    left: usize,
}

impl<'a> Iterator for Terms<'a> {
    type Item = TermRef<'a>;
    fn next(&mut self) -> Option<TermRef<'a>> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        let off = self.off;
        let body_len = rd_u32(self.bytes, off + 4) as usize;
        let end = (off + TERM_HEADER_LEN).checked_add(body_len)?;
        let body = self.bytes.get(off + TERM_HEADER_LEN..end)?;
        self.off = end;
        Some(TermRef {
            kind: TermKind::from_u8(rd_u8(self.bytes, off))?,
            outputs: rd_u8(self.bytes, off + 1),
            aux: rd_u8(self.bytes, off + 2),
            offset: off,
            body,
        })
    }
}

/// One term of a validated table.
#[derive(Clone, Copy, Debug)]
pub struct TermRef<'a> {
    /// What kind of term.
    pub kind: TermKind,
    /// Output mask (bit 0 ex …); exactly one bit except for MLPs.
    pub outputs: u8,
    /// Kind-specific: axis (periodic, reversal), channel (thermal), 0 otherwise.
    pub aux: u8,
    /// Byte offset of the term header in the table.
    pub offset: usize,
    body: &'a [u8],
}

/// Coefficients of a polynomial: (monomial, coefficient) pairs.
#[derive(Clone, Copy, Debug)]
pub struct PolyCoefs<'a> {
    entries: &'a [u8],
}

impl<'a> PolyCoefs<'a> {
    /// Number of monomials.
    pub fn len(&self) -> usize {
        self.entries.len() / 12
    }
    /// Whether there are none (never for a parsed table).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The i-th (monomial, coefficient).
    pub fn get(&self, i: usize) -> (Monomial, f64) {
        let e = 12 * i;
        (
            [
                rd_u8(self.entries, e),
                rd_u8(self.entries, e + 1),
                rd_u8(self.entries, e + 2),
            ],
            rd_f64(self.entries, e + 4),
        )
    }
    /// Iterate over (monomial, coefficient).
    pub fn iter(&self) -> impl Iterator<Item = (Monomial, f64)> + 'a {
        let c = *self;
        (0..c.len()).map(move |i| c.get(i))
    }
}

fn poly_at(body: &[u8], off: usize) -> PolyCoefs<'_> {
    PolyCoefs {
        entries: body.get(off + 4..).unwrap_or(&[]),
    }
}

/// An input of an MLP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MlpInputRef {
    /// 0..=2: position x/y/z (nm); 3 + ch: temperature channel ch (m°C).
    pub source: u8,
    /// Training minimum (maps to −1).
    pub min: f64,
    /// Training maximum (maps to +1).
    pub max: f64,
}

/// A view of an MLP term.
#[derive(Clone, Copy, Debug)]
pub struct MlpView<'a> {
    shape: MlpShape,
    body: &'a [u8],
}

impl<'a> MlpView<'a> {
    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.shape.n_in
    }
    /// Widths of the hidden layers.
    pub fn hidden(&self) -> &[usize] {
        &self.shape.hidden[..self.shape.n_layers]
    }
    /// Number of outputs (= bits in the term's output mask, assigned in ascending order).
    pub fn n_outputs(&self) -> usize {
        self.shape.n_out
    }
    /// Input i.
    pub fn input(&self, i: usize) -> MlpInputRef {
        let o = 4 + 20 * i;
        MlpInputRef {
            source: rd_u8(self.body, o),
            min: rd_f64(self.body, o + 4),
            max: rd_f64(self.body, o + 12),
        }
    }
    /// Output scaling (min, max) of net output j, nm.
    pub fn output_range(&self, j: usize) -> (f64, f64) {
        let o = 4 + 20 * self.shape.n_in + 16 * j;
        (rd_f64(self.body, o), rd_f64(self.body, o + 8))
    }
    /// The k-th parameter in the order L1 W (row-major, rows = units), L1 b, [L2 W, L2 b], out W, out b.
    pub fn param(&self, k: usize) -> f64 {
        rd_f64(
            self.body,
            4 + 20 * self.shape.n_in + 16 * self.shape.n_out + 8 * k,
        )
    }
    pub(crate) fn shape(&self) -> MlpShape {
        self.shape
    }
}

/// One axis of a grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridAxisRef {
    /// Number of nodes (1 = the grid does not vary along this axis).
    pub nodes: u16,
    /// Position of node 0, nm.
    pub origin_nm: i32,
    /// Node spacing, nm.
    pub step_nm: i32,
}

/// A view of a grid term.
#[derive(Clone, Copy, Debug)]
pub struct GridView<'a> {
    body: &'a [u8],
}

impl<'a> GridView<'a> {
    /// Axis a (0 = x).
    pub fn axis(&self, a: usize) -> GridAxisRef {
        let e = 12 * a;
        GridAxisRef {
            nodes: rd_u16(self.body, e),
            origin_nm: rd_i32(self.body, e + 4),
            step_nm: rd_i32(self.body, e + 8),
        }
    }
    /// Number of values.
    pub fn len(&self) -> usize {
        self.body.len().saturating_sub(36) / 8
    }
    /// Whether there are none (never for a parsed table).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Value i (x fastest, then y, then z), nm.
    pub fn value(&self, i: usize) -> f64 {
        rd_f64(self.body, 36 + 8 * i)
    }
}

/// A decoded term.
#[derive(Clone, Copy, Debug)]
pub enum TermView<'a> {
    /// Polynomial in normalised positions.
    Poly { output: usize, coefs: PolyCoefs<'a> },
    /// Periodic along an axis; `coefs[k-1] = (a_k sin, b_k cos)`, nm.
    Periodic {
        output: usize,
        axis: usize,
        period_nm: i32,
        harmonics: usize,
        body: &'a [u8],
    },
    /// (T − T_ref) × polynomial, coefficients in nm/K.
    Thermal {
        output: usize,
        channel: usize,
        t_ref_mc: i32,
        coefs: PolyCoefs<'a>,
    },
    /// amplitude × reversal state.
    Reversal {
        output: usize,
        axis: usize,
        transition_nm: i32,
        amplitude_nm: f64,
    },
    /// tool arm × polynomial (coefficients in nm per nm of arm).
    Abbe { output: usize, coefs: PolyCoefs<'a> },
    /// MLP with outputs in the mask.
    Mlp { outputs: u8, net: MlpView<'a> },
    /// Grid table.
    Grid { output: usize, grid: GridView<'a> },
}

impl<'a> TermView<'a> {
    /// Harmonic k (1-based) of a periodic term: (sin amplitude, cos amplitude) in nm.
    /// (0, 0) for k = 0, for k beyond the term's harmonics and for other
    /// kinds: a public accessor must not panic for any argument.
    pub fn harmonic(&self, k: usize) -> (f64, f64) {
        match self {
            // k ≤ harmonics ≤ MAX_HARMONICS (validated), so the offsets are small.
            TermView::Periodic {
                body, harmonics, ..
            } if (1..=*harmonics).contains(&k) => (rd_f64(body, 16 * k - 8), rd_f64(body, 16 * k)),
            _ => (0.0, 0.0),
        }
    }
}

impl<'a> TermRef<'a> {
    /// Decode the body.
    pub fn view(&self) -> TermView<'a> {
        let output = self.outputs.trailing_zeros() as usize;
        let b = self.body;
        match self.kind {
            TermKind::Poly => TermView::Poly {
                output,
                coefs: poly_at(b, 0),
            },
            TermKind::Abbe => TermView::Abbe {
                output,
                coefs: poly_at(b, 0),
            },
            TermKind::Thermal => TermView::Thermal {
                output,
                channel: self.aux as usize,
                t_ref_mc: rd_i32(b, 0),
                coefs: poly_at(b, 8),
            },
            TermKind::Periodic => TermView::Periodic {
                output,
                axis: self.aux as usize,
                period_nm: rd_i32(b, 0),
                harmonics: rd_u8(b, 4) as usize,
                body: b,
            },
            TermKind::Reversal => TermView::Reversal {
                output,
                axis: self.aux as usize,
                transition_nm: rd_i32(b, 0),
                amplitude_nm: rd_f64(b, 8),
            },
            TermKind::Mlp => TermView::Mlp {
                outputs: self.outputs,
                net: MlpView {
                    shape: mlp_shape(b, 0, self.outputs.count_ones() as usize),
                    body: b,
                },
            },
            TermKind::Grid => TermView::Grid {
                output,
                grid: GridView { body: b },
            },
        }
    }
}
