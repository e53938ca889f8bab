//! The simulated board's TCP service (`SimBoard::serve`) with misbehaving
//! clients: one that sends requests and never reads its answers must not
//! stall the board for the others (issue 25: the answers were written
//! blocking, so a full socket buffer stopped every client and the loop).

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use trueaxis_app::sim::SimBoard;
use trueaxis_protocol::{
    decode_message, encode_frame, FrameDecoder, Packet, Request, Response, MAX_FRAME_BYTES,
};

fn frame(seq: u16, req: Request<'_>) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode_frame(&Packet { seq, msg: req }, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// Sends one request on `s` and reads until its answer arrives (or
/// `deadline`).
fn ask(s: &mut TcpStream, seq: u16, req: Request<'_>, deadline: Instant) -> Option<Response> {
    s.write_all(&frame(seq, req)).ok()?;
    let mut dec: FrameDecoder = FrameDecoder::new();
    let mut buf = [0u8; 512];
    while Instant::now() < deadline {
        let n = match s.read(&mut buf) {
            Ok(0) => return None,
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(_) => return None,
        };
        let mut input = &buf[..n];
        while let Some(f) = dec.feed(&mut input) {
            let p = decode_message::<Packet<Response>>(f.ok()?).ok()?;
            if p.seq == seq {
                return Some(p.msg);
            }
        }
    }
    None
}

#[test]
fn a_client_that_never_reads_does_not_stall_the_others() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let board = std::thread::spawn(move || SimBoard::new().serve(listener, s));

    // The stuck client: Status requests as fast as the socket takes them,
    // never a read. Its answers (≈ 140 bytes each, for 10-byte requests)
    // fill its receive buffer and then the board's send buffer.
    let stuck = TcpStream::connect(addr).unwrap();
    stuck
        .set_write_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let flood = {
        let mut stuck = stuck.try_clone().unwrap();
        let stop = stop.clone();
        std::thread::spawn(move || {
            let req = frame(1, Request::Status);
            let mut sent = 0usize;
            while !stop.load(Ordering::Relaxed) && sent < 64 << 20 {
                match stuck.write(&req) {
                    Ok(n) => sent += n,
                    Err(_) => std::thread::sleep(Duration::from_millis(5)),
                }
            }
            sent
        })
    };
    std::thread::sleep(Duration::from_millis(1500));

    // A normal client still gets its answers, and the board's loop runs.
    let mut ok = TcpStream::connect(addr).unwrap();
    ok.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let mut ticks = Vec::new();
    for seq in 0..5u16 {
        let deadline = Instant::now() + Duration::from_secs(3);
        match ask(&mut ok, 100 + seq, Request::Status, deadline) {
            Some(Response::Status(t)) => ticks.push(t.ticks),
            other => {
                stop.store(true, Ordering::Relaxed);
                panic!("the normal client got {other:?} while another client does not read");
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        ticks.windows(2).all(|w| w[1] > w[0]),
        "the loop stalled: {ticks:?}"
    );
    stop.store(true, Ordering::Relaxed);
    drop(stuck);
    let sent = flood.join().unwrap();
    assert!(sent > 1 << 20, "the stuck client sent only {sent} bytes");
    board.join().unwrap();
}
