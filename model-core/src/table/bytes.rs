//! Little-endian field readers of the table bytes (`from_le_bytes`, so a
//! table may sit at any alignment, e.g. in flash). Callers have checked the
//! offsets: `validate` before a `Table` exists, the views after.

#[inline]
pub(super) fn arr<const N: usize>(b: &[u8], off: usize) -> [u8; N] {
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
pub(super) fn rd_u8(b: &[u8], off: usize) -> u8 {
    b.get(off).copied().unwrap_or(0)
}

pub(super) fn i32x3(b: &[u8], off: usize) -> [i32; 3] {
    [rd_i32(b, off), rd_i32(b, off + 4), rd_i32(b, off + 8)]
}

pub(super) fn i32x4(b: &[u8], off: usize) -> [i32; 4] {
    [
        rd_i32(b, off),
        rd_i32(b, off + 4),
        rd_i32(b, off + 8),
        rd_i32(b, off + 12),
    ]
}
