//! How the board keeps a table in a flash slot (TABLE_A / TABLE_B of
//! `memory.x`). Defined here because two writers must agree on it: the
//! board's table store (after an upload over the link) and the host's
//! `trueaxis flash` (through a debug probe).
//!
//! ```text
//!  0..32   header: magic "TAXT", seq u32, len u32, crc32 u32 (of the table
//!          bytes), header_crc u32 (CRC-32 of the 16 bytes before), then
//!          0xFF padding; all little endian
//! 32..64   revoke marker: all 0xFF = live, anything else = revoked
//! 64..     the table (len bytes)
//! ```
//!
//! The valid, non-revoked slot with the highest `seq` is the one that boots.
//! A revoked slot also has its magic programmed to zero (the board's
//! rollback, trueaxis_app::store): its header is then invalid too, which a
//! torn erase of the slot cannot undo by restoring the marker alone.

use crate::{Slot, SlotInfo, FRAME_CRC};

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
    let word =
        |i: usize| -> Option<u32> { Some(u32::from_le_bytes(h.get(i..i + 4)?.try_into().ok()?)) };
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
        crc32: crate::table_id(table),
    };
    let mut v = std::vec::Vec::with_capacity(BODY_AT as usize + table.len());
    v.extend_from_slice(&encode_header(&info));
    v.extend_from_slice(&[0xFF; REVOKE_BYTES]);
    v.extend_from_slice(table);
    v
}
