//! A minimal blocking client of the link protocol (trueaxis-protocol) over TCP (QEMU's
//! serial socket): one request, one response with the same sequence number,
//! retried on timeout as the protocol prescribes. Used to inject positions,
//! read corrections, and to cut uploads short on purpose — things
//! `trueaxis upload` must never do.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use trueaxis_protocol::{
    decode_message, encode_frame, FrameDecoder, Packet, Request, Response, MAX_FRAME_BYTES,
};

/// Errors of the client, with what was going on.
#[derive(Debug)]
pub enum LinkClientError {
    /// Socket error.
    Io(std::io::Error),
    /// No matching response within the retries.
    Timeout {
        /// The request, for the message.
        what: String,
    },
    /// The request does not fit a frame (a bug of the caller).
    Encode(trueaxis_protocol::FrameError),
}

impl std::fmt::Display for LinkClientError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkClientError::Io(e) => write!(f, "link socket: {e}"),
            LinkClientError::Timeout { what } => write!(f, "no answer to {what}"),
            LinkClientError::Encode(e) => write!(f, "cannot encode request: {e}"),
        }
    }
}

impl std::error::Error for LinkClientError {}

impl From<std::io::Error> for LinkClientError {
    fn from(e: std::io::Error) -> Self {
        LinkClientError::Io(e)
    }
}

/// A connection to the board.
pub struct LinkClient {
    stream: TcpStream,
    decoder: Box<FrameDecoder>,
    seq: u16,
    /// Frames that arrived but did not decode (garbage, stale answers).
    pub dropped_frames: u32,
    /// How long to wait for one answer before re-sending.
    pub answer_timeout: Duration,
    /// How many times a request is sent before giving up.
    pub tries: u32,
}

impl LinkClient {
    /// Connects to `127.0.0.1:port`.
    pub fn connect(port: u16) -> Result<Self, LinkClientError> {
        let stream = TcpStream::connect(("127.0.0.1", port))?;
        stream.set_nodelay(true)?;
        Ok(Self {
            stream,
            decoder: Box::new(FrameDecoder::new()),
            seq: 1,
            dropped_frames: 0,
            answer_timeout: Duration::from_millis(1500),
            tries: 4,
        })
    }

    /// Writes raw bytes (garbage on purpose, partial frames).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), LinkClientError> {
        self.stream.write_all(bytes)?;
        Ok(())
    }

    /// Sends `req` and waits for the response with the same sequence number.
    pub fn request(&mut self, req: &Request<'_>) -> Result<Response, LinkClientError> {
        self.seq = self.seq.wrapping_add(1);
        let packet = Packet {
            seq: self.seq,
            msg: req.clone(),
        };
        let mut frame = vec![0u8; MAX_FRAME_BYTES];
        let n = encode_frame(&packet, &mut frame).map_err(LinkClientError::Encode)?;
        for _ in 0..self.tries {
            self.stream.write_all(&frame[..n])?;
            if let Some(resp) = self.wait_for(self.seq)? {
                return Ok(resp);
            }
        }
        Err(LinkClientError::Timeout {
            what: format!("{req:?}").chars().take(120).collect(),
        })
    }

    /// Reads frames until the response to `seq` arrives or the answer
    /// timeout passes.
    fn wait_for(&mut self, seq: u16) -> Result<Option<Response>, LinkClientError> {
        let deadline = Instant::now() + self.answer_timeout;
        let mut buf = [0u8; 512];
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.stream.set_read_timeout(Some(left))?;
            let n = match self.stream.read(&mut buf) {
                Ok(0) => {
                    return Err(LinkClientError::Io(std::io::Error::new(
                        ErrorKind::UnexpectedEof,
                        "the board closed the connection",
                    )))
                }
                Ok(n) => n,
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Ok(None)
                }
                Err(e) => return Err(e.into()),
            };
            let mut input = &buf[..n];
            while let Some(frame) = self.decoder.feed(&mut input) {
                match frame.and_then(decode_message::<Packet<Response>>) {
                    Ok(p) if p.seq == seq => {
                        // Anything after the answer is stale by definition.
                        self.decoder.reset();
                        return Ok(Some(p.msg));
                    }
                    _ => self.dropped_frames += 1,
                }
            }
        }
    }
}
