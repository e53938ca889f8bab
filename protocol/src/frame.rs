//! Framing: a message serialised with postcard, its CRC-32 appended, the
//! whole COBS-encoded between `0x00` delimiters ([`encode_frame`]), and the
//! receiving side ([`FrameDecoder`], [`check_frame`], [`decode_message`])
//! that resynchronises at the next delimiter after garbage or a cut frame.

use serde::{Deserialize, Serialize};

use crate::MAX_MESSAGE_BYTES;

/// CRC appended to every message.
const CRC_BYTES: usize = 4;

/// Largest frame on the wire, delimiters included: COBS adds one byte per
/// 254 bytes plus one, we add the leading and trailing `0x00`.
pub const MAX_FRAME_BYTES: usize =
    (MAX_MESSAGE_BYTES + CRC_BYTES) + (MAX_MESSAGE_BYTES + CRC_BYTES) / 254 + 1 + 2;

/// The CRC used by the frames (and by the table format: CRC-32/ISO-HDLC,
/// the zlib/PNG one).
pub const FRAME_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

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
/// [`FrameDecoder::feed`] (CRC already checked and stripped). The message
/// must fill the payload: bytes after it are refused as [`FrameError::Decode`]
/// (a frame is one message, nothing is silently ignored).
pub fn decode_message<'a, T: Deserialize<'a>>(payload: &'a [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes(payload) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(FrameError::Decode),
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::*;
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
    fn a_message_with_bytes_after_it_is_refused() {
        let p = Packet {
            seq: 7,
            msg: Request::Status,
        };
        let mut buf = [0u8; 64];
        let n = postcard::to_slice(&p, &mut buf).unwrap().len();
        assert_eq!(decode_message::<Packet<Request>>(&buf[..n]), Ok(p));
        for junk in [&[0u8][..], &[0xFF], &[1, 2, 3]] {
            let mut v = buf[..n].to_vec();
            v.extend_from_slice(junk);
            assert_eq!(
                decode_message::<Packet<Request>>(&v),
                Err(FrameError::Decode),
                "{junk:?}"
            );
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
            referenced: [true; 3],
            reference_needed: [true; 3],
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
