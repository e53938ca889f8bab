//! Test helpers: a tiny in-process link client for the simulated board.
#![allow(dead_code)]

pub mod fake;

use trueaxis_app::server::Port;
use trueaxis_app::sim::SimBoard;
use trueaxis_protocol::{
    decode_message, encode_frame, FrameDecoder, Packet, Request, Response, MAX_CHUNK_BYTES,
    MAX_FRAME_BYTES,
};

/// Frames `req`, feeds it to the board and decodes the one answer.
pub fn call(board: &mut SimBoard, port: &mut Port, seq: u16, req: Request<'_>) -> Response {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode_frame(&Packet { seq, msg: req }, &mut buf).unwrap();
    let out = board.receive(port, &buf[..n]);
    let mut answers = decode_all(&out);
    assert_eq!(answers.len(), 1, "one answer per request");
    let p = answers.remove(0);
    assert_eq!(p.seq, seq);
    p.msg
}

/// Every response frame in `bytes`.
pub fn decode_all(bytes: &[u8]) -> Vec<Packet<Response>> {
    let mut dec: FrameDecoder = FrameDecoder::new();
    let mut input = bytes;
    let mut v = Vec::new();
    while let Some(r) = dec.feed(&mut input) {
        v.push(decode_message::<Packet<Response>>(r.unwrap()).unwrap());
    }
    v
}

/// Stages `table` on the board: `UploadBegin` announcing `crc32` (the
/// table's identity, or a wrong one to test the refusal), then every chunk
/// (as large as the link allows); each is acknowledged, the upload starting
/// at byte 0. Requests `seq` and `seq + 1`.
pub fn stage(board: &mut SimBoard, port: &mut Port, seq: u16, table: &[u8], crc32: u32) {
    let r = call(
        board,
        port,
        seq,
        Request::UploadBegin {
            size: table.len() as u32,
            crc32,
        },
    );
    assert_eq!(r, Response::UploadAck { next_offset: 0 });
    for (i, c) in table.chunks(MAX_CHUNK_BYTES).enumerate() {
        let r = call(
            board,
            port,
            seq.wrapping_add(1),
            Request::UploadChunk {
                offset: (i * MAX_CHUNK_BYTES) as u32,
                data: c,
            },
        );
        assert!(matches!(r, Response::UploadAck { .. }), "{r:?}");
    }
}

/// Uploads, commits and activates `table`.
pub fn install(board: &mut SimBoard, port: &mut Port, table: &[u8]) -> Response {
    stage(board, port, 1, table, trueaxis_protocol::table_id(table));
    let r = call(board, port, 3, Request::Commit);
    assert!(matches!(r, Response::Committed(_)), "{r:?}");
    call(board, port, 4, Request::Activate)
}
