//! Fuzz the link's receive path in trueaxis-protocol — what the board does with
//! every byte that arrives on USB or the UART: the streaming frame decoder
//! (COBS + CRC), and the postcard messages behind it, and the flash slot
//! header decoder. Any bytes must give frames or typed errors, never a panic
//! or a stuck decoder; a message that decodes re-encodes to a frame that
//! decodes to the same message (nothing silently altered).
//! Run: `cd fuzz && cargo +nightly fuzz run frames`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use trueaxis_protocol::{
    decode_message, encode_frame, slot, FrameDecoder, Packet, Request, Response, Slot,
    MAX_FRAME_BYTES,
};

/// Encodes `p` as a frame and decodes it again with a fresh decoder.
fn round_trip<T>(p: &Packet<T>)
where
    T: serde::Serialize + for<'a> serde::Deserialize<'a> + PartialEq + core::fmt::Debug,
{
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let Ok(n) = encode_frame(p, &mut buf) else {
        return;
    };
    let mut dec = FrameDecoder::<MAX_FRAME_BYTES>::new();
    let mut input = &buf[..n];
    let payload = dec
        .feed(&mut input)
        .expect("an encoded frame completes")
        .expect("an encoded frame checks");
    let back: Packet<T> = decode_message(payload).expect("an encoded message decodes");
    assert_eq!(&back, p);
}

fuzz_target!(|data: &[u8]| {
    // The stream: frames in any bytes, resynchronising at every 0x00.
    let mut dec = FrameDecoder::<MAX_FRAME_BYTES>::new();
    let mut input = data;
    while let Some(r) = dec.feed(&mut input) {
        if let Ok(payload) = r {
            let _ = decode_message::<Packet<Request>>(payload);
            let _ = decode_message::<Packet<Response>>(payload);
        }
    }
    // Past the CRC: the bytes as a message payload.
    if let Ok(p) = decode_message::<Packet<Request>>(data) {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        if let Ok(n) = encode_frame(&p, &mut buf) {
            let mut dec = FrameDecoder::<MAX_FRAME_BYTES>::new();
            let mut input = &buf[..n];
            let payload = dec.feed(&mut input).unwrap().unwrap();
            assert_eq!(decode_message::<Packet<Request>>(payload).unwrap(), p);
        }
    }
    if let Ok(p) = decode_message::<Packet<Response>>(data) {
        round_trip(&p);
    }
    // A flash slot header read back from any contents.
    for s in [Slot::A, Slot::B] {
        if let Some(info) = slot::decode_header(data, s) {
            assert_eq!(info.slot, s);
        }
    }
});
