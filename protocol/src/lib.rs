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
//!
//! The crate holds nothing but the protocol, so that both sides depend on
//! one small `no_std` definition: the messages ([`Request`], [`Response`]
//! and what they carry) in `messages`, the framing ([`encode_frame`],
//! [`FrameDecoder`], [`check_frame`]) in `frame`, and the flash slot layout
//! both writers of a slot share in [`slot`]. Feature `std` adds
//! `slot::image` for the host; feature `defmt` derives `defmt::Format`
//! for the board's logs.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

mod frame;
mod messages;
pub mod slot;

pub use frame::{
    check_frame, decode_message, encode_frame, FrameDecoder, FrameError, FRAME_CRC, MAX_FRAME_BYTES,
};
pub use messages::{
    Correction, Faults, Identity, Injection, LinkError, Packet, Request, Response, Slot, SlotInfo,
    Telemetry,
};

/// Version of this protocol; bumped on any incompatible change of the types
/// below (postcard is not self-describing, so both sides must agree).
pub const PROTOCOL_VERSION: u16 = 2;

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
