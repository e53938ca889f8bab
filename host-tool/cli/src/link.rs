//! The host end of the board link: opens a serial port (`/dev/ttyACM0`,
//! `COM3`) or a TCP socket (`tcp://HOST:PORT`, emulators and the simulated
//! board), and runs request/response exchanges of the link protocol (the
//! `trueaxis-protocol` crate) with timeouts and retries. The upload
//! procedure (chunks, acknowledgements, resume, commit, activate, verify)
//! lives here too, so the `upload` command is only arguments and output.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use trueaxis_protocol::{
    decode_message, encode_frame, table_id, FrameDecoder, Identity, LinkError, Packet, Request,
    Response, SlotInfo, Telemetry, MAX_CHUNK_BYTES, MAX_FRAME_BYTES, PROTOCOL_VERSION,
};

/// What can go wrong talking to the board.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The port could not be opened.
    #[error("cannot open {port}")]
    Open {
        /// As given.
        port: String,
        /// Why.
        source: io::Error,
    },
    /// Reading or writing failed.
    #[error("link I/O on {port}")]
    Io {
        /// As given.
        port: String,
        /// Why.
        source: io::Error,
    },
    /// No answer after all retries.
    #[error(
        "no answer from the board on {port} to {what} after {tries} tries ({timeout_ms} ms each)"
    )]
    Timeout {
        /// As given.
        port: String,
        /// The request.
        what: &'static str,
        /// Attempts.
        tries: u32,
        /// Per attempt.
        timeout_ms: u64,
    },
    /// The board refused the request.
    #[error("the board refused {what}: {error}")]
    Refused {
        /// The request.
        what: &'static str,
        /// Its reason.
        error: LinkError,
    },
    /// An answer that does not belong to the request.
    #[error("unexpected answer to {what}: {answer:?}")]
    Unexpected {
        /// The request.
        what: &'static str,
        /// The answer.
        answer: Box<Response>,
    },
    /// The board speaks another protocol or table format.
    #[error("incompatible board: {0}")]
    Incompatible(String),
    /// A rollback the host refused before sending anything: the board
    /// holds no second valid table.
    #[error("nothing to roll back to: the board holds {0}; the active table is unchanged")]
    NothingToRollBackTo(String),
    /// After activation the board does not report the uploaded table.
    #[error("verification failed: the board reports {got}, expected CRC {want:#010x}")]
    Verify {
        /// Expected CRC.
        want: u32,
        /// What the board says.
        got: String,
    },
}

/// A byte stream to the board.
trait Stream: Read + Write + Send {}
impl<T: Read + Write + Send> Stream for T {}

/// Timeouts and retries of a [`Client`].
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// Wait for one answer.
    pub timeout: Duration,
    /// Attempts per request.
    pub tries: u32,
    /// Wait for the answer to a commit (the board erases a 128 KiB flash
    /// sector: 1-2 s on the F405, up to 4 s worst case).
    pub commit_timeout: Duration,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            tries: 4,
            commit_timeout: Duration::from_secs(10),
        }
    }
}

/// A connection to the board.
pub struct Client {
    port: String,
    io: Box<dyn Stream>,
    decoder: FrameDecoder,
    seq: u16,
    timing: Timing,
    /// Requests sent again after a timeout or a lost answer.
    pub retries: u32,
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("port", &self.port)
            .field("seq", &self.seq)
            .finish_non_exhaustive()
    }
}

/// Short name of a request, for messages.
fn name(req: &Request<'_>) -> &'static str {
    match req {
        Request::Identify => "identify",
        Request::Status => "status",
        Request::UploadBegin { .. } => "upload begin",
        Request::UploadChunk { .. } => "upload chunk",
        Request::Commit => "commit",
        Request::Activate => "activate",
        Request::Rollback => "rollback",
        Request::ClearFaults => "clear faults",
        Request::Inject(_) => "inject",
        Request::EndInject => "end inject",
        Request::ReadCorrection => "read correction",
        Request::Reference { .. } => "reference",
    }
}

impl Client {
    /// Opens `port`: `tcp://HOST:PORT`, or a serial device (115 200 8N1;
    /// the USB CDC-ACM link ignores the rate).
    pub fn open(port: &str, timing: Timing) -> Result<Self, ClientError> {
        let open_err = |source| ClientError::Open {
            port: port.to_string(),
            source,
        };
        let io: Box<dyn Stream> = if let Some(addr) = port.strip_prefix("tcp://") {
            let s = TcpStream::connect(addr).map_err(open_err)?;
            s.set_nodelay(true).map_err(open_err)?;
            s.set_read_timeout(Some(Duration::from_millis(20)))
                .map_err(open_err)?;
            Box::new(s)
        } else {
            let s = serialport::new(port, 115_200)
                .timeout(Duration::from_millis(20))
                .open()
                .map_err(|e| open_err(io::Error::other(e)))?;
            Box::new(s)
        };
        Ok(Self {
            port: port.to_string(),
            io,
            decoder: FrameDecoder::new(),
            seq: 0,
            timing,
            retries: 0,
        })
    }

    /// The port as given.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// Sends `req` and returns the board's answer (a refusal is an
    /// `Ok(Response::Error)` here; see [`Client::request`]). Retries on
    /// timeout: requests are idempotent or resumable by design — uploads
    /// resume, a repeated chunk is acknowledged again, and a repeated
    /// `Commit` whose first answer was lost gets the same `Committed` (the
    /// board remembers its last commit), and so does a repeated `Rollback`.
    pub fn call(&mut self, req: &Request<'_>) -> Result<Response, ClientError> {
        let timeout = if matches!(req, Request::Commit | Request::Rollback) {
            self.timing.commit_timeout
        } else {
            self.timing.timeout
        };
        for attempt in 0..self.timing.tries {
            if attempt > 0 {
                self.retries += 1;
            }
            self.seq = self.seq.wrapping_add(1);
            let mut frame = [0u8; MAX_FRAME_BYTES];
            let n = encode_frame(
                &Packet {
                    seq: self.seq,
                    msg: req.clone(),
                },
                &mut frame,
            )
            .expect("every request fits a frame");
            self.io
                .write_all(&frame[..n])
                .and_then(|_| self.io.flush())
                .map_err(|source| ClientError::Io {
                    port: self.port.clone(),
                    source,
                })?;
            if let Some(r) = self.wait_for(self.seq, timeout)? {
                return Ok(r);
            }
        }
        Err(ClientError::Timeout {
            port: self.port.clone(),
            what: name(req),
            tries: self.timing.tries,
            timeout_ms: timeout.as_millis() as u64,
        })
    }

    /// Like [`call`](Self::call), but a refusal is an error.
    pub fn request(&mut self, req: &Request<'_>) -> Result<Response, ClientError> {
        match self.call(req)? {
            Response::Error(error) => Err(ClientError::Refused {
                what: name(req),
                error,
            }),
            r => Ok(r),
        }
    }

    /// Reads until the answer with `seq` arrives (older answers — to
    /// requests that timed out — and broken frames are skipped).
    fn wait_for(&mut self, seq: u16, timeout: Duration) -> Result<Option<Response>, ClientError> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 512];
        while Instant::now() < deadline {
            let n = match self.io.read(&mut buf) {
                Ok(0) => {
                    return Err(ClientError::Io {
                        port: self.port.clone(),
                        source: io::Error::new(io::ErrorKind::UnexpectedEof, "link closed"),
                    })
                }
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    continue
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(ClientError::Io {
                        port: self.port.clone(),
                        source,
                    })
                }
            };
            let mut input = &buf[..n];
            let mut found = None;
            while let Some(frame) = self.decoder.feed(&mut input) {
                let Ok(p) = frame.and_then(decode_message::<Packet<Response>>) else {
                    continue;
                };
                if p.seq == seq {
                    found = Some(p.msg);
                }
            }
            if found.is_some() {
                return Ok(found);
            }
        }
        Ok(None)
    }

    /// Identity, checked for protocol and table-format compatibility.
    pub fn identify(&mut self) -> Result<Identity, ClientError> {
        match self.request(&Request::Identify)? {
            Response::Identity(id) => {
                if id.protocol != PROTOCOL_VERSION {
                    return Err(ClientError::Incompatible(format!(
                        "board speaks link protocol {}, this tool {}",
                        id.protocol, PROTOCOL_VERSION
                    )));
                }
                Ok(id)
            }
            r => Err(unexpected("identify", r)),
        }
    }

    /// Telemetry.
    pub fn status(&mut self) -> Result<Telemetry, ClientError> {
        match self.request(&Request::Status)? {
            Response::Status(t) => Ok(t),
            r => Err(unexpected("status", r)),
        }
    }

    /// Uploads `table`, commits, activates and verifies that the board runs
    /// it. `progress(done, total)` is called after every acknowledged
    /// chunk. The caller validated the table (model_core::parse) first.
    pub fn upload(
        &mut self,
        table: &[u8],
        mut progress: impl FnMut(u64, u64),
    ) -> Result<UploadReport, ClientError> {
        let id = self.identify()?;
        if id.table_format != model_core::FORMAT_VERSION {
            return Err(ClientError::Incompatible(format!(
                "board reads table format {}, the table is format {}",
                id.table_format,
                model_core::FORMAT_VERSION
            )));
        }
        if table.len() as u64 > id.max_table_bytes as u64 {
            return Err(ClientError::Refused {
                what: "upload begin",
                error: LinkError::TooLarge {
                    max_bytes: id.max_table_bytes,
                },
            });
        }
        let size = table.len() as u32;
        let crc32 = table_id(table);
        // The table already runs: writing it again would put it in the
        // other slot too and erase the table a rollback returns to.
        if let Some(a) = id.active.filter(|a| a.crc32 == crc32 && a.len == size) {
            return Ok(UploadReport {
                bytes: size,
                crc32,
                resumed_at: 0,
                chunks: 0,
                committed: a,
                activated: a,
                retries: self.retries,
                already_active: true,
            });
        }
        let begin = Request::UploadBegin { size, crc32 };
        let mut offset = match self.request(&begin)? {
            Response::UploadAck { next_offset } => next_offset,
            r => return Err(unexpected("upload begin", r)),
        };
        let resumed_at = offset;
        let mut chunks = 0u32;
        let mut restarts = 0u32;
        while offset < size {
            let end = (offset as usize + MAX_CHUNK_BYTES).min(table.len());
            let req = Request::UploadChunk {
                offset,
                data: &table[offset as usize..end],
            };
            let answer = match self.call(&req) {
                Ok(a) => a,
                // The link hiccuped for longer than the retries: resume
                // from where the board is.
                Err(ClientError::Timeout { .. }) if restarts < 3 => {
                    Response::Error(LinkError::NoUpload)
                }
                Err(e) => return Err(e),
            };
            offset = match answer {
                Response::UploadAck { next_offset } => next_offset,
                Response::Error(LinkError::BadOffset { expected }) => expected,
                Response::Error(LinkError::NoUpload) if restarts < 3 => {
                    restarts += 1;
                    match self.request(&begin)? {
                        Response::UploadAck { next_offset } => next_offset,
                        r => return Err(unexpected("upload begin", r)),
                    }
                }
                Response::Error(error) => {
                    return Err(ClientError::Refused {
                        what: "upload chunk",
                        error,
                    })
                }
                r => return Err(unexpected("upload chunk", r)),
            };
            chunks += 1;
            progress(offset as u64, size as u64);
        }
        let committed = match self.request(&Request::Commit)? {
            Response::Committed(info) => info,
            r => return Err(unexpected("commit", r)),
        };
        let activated = match self.call(&Request::Activate)? {
            Response::Activated(info) => info,
            // The commit ran the table already (a board commits and
            // activates in one step); `Activate` is under the commit's
            // quiet rule, so an axis that started moving since is no
            // failure. `Identify` below checks what runs.
            Response::Error(LinkError::AxesMoving { .. }) => committed,
            Response::Error(error) => {
                return Err(ClientError::Refused {
                    what: "activate",
                    error,
                })
            }
            r => return Err(unexpected("activate", r)),
        };
        let id = self.identify()?;
        match id.active {
            Some(a) if a.crc32 == crc32 => {}
            other => {
                return Err(ClientError::Verify {
                    want: crc32,
                    got: match other {
                        Some(a) => format!("CRC {:#010x}", a.crc32),
                        None => "no active table".into(),
                    },
                })
            }
        }
        Ok(UploadReport {
            bytes: size,
            crc32,
            resumed_at,
            chunks,
            committed,
            activated,
            retries: self.retries,
            already_active: false,
        })
    }

    /// Rolls the board back to its standby table: the active (newest)
    /// table is revoked, the other slot's becomes active, and the board is
    /// asked again which table it runs. Refused before anything is sent
    /// when the board holds no standby table (`NothingToRollBackTo`, as the
    /// board would answer) — so a rollback is never mistaken for the
    /// board's answer to an earlier one, which it repeats unchanged.
    pub fn rollback(&mut self) -> Result<RollbackReport, ClientError> {
        let id = self.identify()?;
        let (revoked, standby) = match (id.active, id.standby) {
            (Some(a), Some(s)) => (a, s),
            (Some(a), None) => {
                return Err(ClientError::NothingToRollBackTo(format!(
                    "one valid table ({})",
                    slot_text(&a)
                )))
            }
            (None, _) => return Err(ClientError::NothingToRollBackTo("no active table".into())),
        };
        let active = match self.request(&Request::Rollback)? {
            Response::RolledBack(info) => info,
            r => return Err(unexpected("rollback", r)),
        };
        let id = self.identify()?;
        if active != standby || id.active != Some(standby) {
            return Err(ClientError::Verify {
                want: standby.crc32,
                got: match id.active {
                    Some(a) => format!("CRC {:#010x} (slot {:?} seq {})", a.crc32, a.slot, a.seq),
                    None => "no active table".into(),
                },
            });
        }
        Ok(RollbackReport {
            revoked,
            active,
            retries: self.retries,
        })
    }

    /// References `axis` (0 = X) at machine position `pos_nm`: the board
    /// takes the count its encoder reads at its next tick as that position
    /// (`Reference`; refused while the axes move), then this waits until
    /// the board's status shows the axis referenced (a tick is 50 µs on the
    /// board; up to the request timeout is allowed) and returns that status.
    pub fn reference(&mut self, axis: u8, pos_nm: i32) -> Result<Telemetry, ClientError> {
        match self.request(&Request::Reference { axis, pos_nm })? {
            Response::Ok => {}
            r => return Err(unexpected("reference", r)),
        }
        let started = Instant::now();
        loop {
            let t = self.status()?;
            if t.referenced.get(usize::from(axis)) == Some(&true) {
                return Ok(t);
            }
            if started.elapsed() > self.timing.timeout {
                return Err(ClientError::Timeout {
                    port: self.port.clone(),
                    what: "reference (the board accepted it but its status never showed the axis referenced)",
                    tries: 1,
                    timeout_ms: self.timing.timeout.as_millis() as u64,
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Clears the board's latched faults (`ClearFaults`): the correction
    /// slews back to the model's; a fault whose cause remains is raised
    /// again at the next tick.
    pub fn clear_faults(&mut self) -> Result<(), ClientError> {
        match self.request(&Request::ClearFaults)? {
            Response::Ok => Ok(()),
            r => Err(unexpected("clear faults", r)),
        }
    }
}

/// What [`Client::rollback`] did.
#[derive(Debug, Clone, Copy)]
pub struct RollbackReport {
    /// The table that was active and is now revoked.
    pub revoked: SlotInfo,
    /// The table running now (the former standby).
    pub active: SlotInfo,
    /// Requests repeated.
    pub retries: u32,
}

/// What [`Client::upload`] did.
#[derive(Debug, Clone, Copy)]
pub struct UploadReport {
    /// Table length.
    pub bytes: u32,
    /// Its CRC-32.
    pub crc32: u32,
    /// Where the upload started (non-zero: resumed a previous one).
    pub resumed_at: u32,
    /// Chunks sent.
    pub chunks: u32,
    /// Slot written.
    pub committed: SlotInfo,
    /// Table running now.
    pub activated: SlotInfo,
    /// Requests repeated.
    pub retries: u32,
    /// The board already ran this table: nothing was sent or written.
    pub already_active: bool,
}

fn unexpected(what: &'static str, r: Response) -> ClientError {
    match r {
        Response::Error(error) => ClientError::Refused { what, error },
        answer => ClientError::Unexpected {
            what,
            answer: Box::new(answer),
        },
    }
}

/// JSON for a slot.
pub fn slot_json(s: &SlotInfo) -> serde_json::Value {
    serde_json::json!({
        "slot": match s.slot { trueaxis_protocol::Slot::A => "A", trueaxis_protocol::Slot::B => "B" },
        "seq": s.seq,
        "bytes": s.len,
        "crc32": format!("{:#010x}", s.crc32),
    })
}

/// Human text for a slot.
pub fn slot_text(s: &SlotInfo) -> String {
    format!(
        "slot {:?} seq {} ({} bytes, CRC {:#010x})",
        s.slot, s.seq, s.len, s.crc32
    )
}

/// Axis names, in the order of the link's per-axis arrays.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// Per axis: referenced or not, and whether the board needs it to correct
/// (`{"x": {"referenced": true, "reference_needed": true}, …}`).
pub fn axes_json(t: &Telemetry) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    for (a, name) in AXES.iter().enumerate() {
        m.insert(
            (*name).to_string(),
            serde_json::json!({
                "referenced": t.referenced[a],
                "reference_needed": t.reference_needed[a],
            }),
        );
    }
    serde_json::Value::Object(m)
}

/// Per axis as text: `x referenced, y NOT REFERENCED, z no encoder`.
pub fn axes_text(t: &Telemetry) -> String {
    AXES.iter()
        .enumerate()
        .map(|(a, name)| match (t.reference_needed[a], t.referenced[a]) {
            (_, true) => format!("{name} referenced"),
            (true, false) => format!("{name} NOT REFERENCED"),
            (false, false) => format!("{name} needs none"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// JSON for telemetry (fault bits by name).
pub fn telemetry_json(t: &Telemetry) -> serde_json::Value {
    serde_json::json!({
        "uptime_us": t.uptime_us,
        "ticks": t.ticks,
        "period_us": t.period_us,
        "worst_loop_us": t.worst_loop_us,
        "worst_tick_us": t.worst_tick_us,
        "overruns": t.overruns,
        "pos_nm": t.pos_nm,
        "temp_mc": t.temp_mc,
        "model_corr_nm": t.model_corr_nm,
        "corr_nm": t.corr_nm,
        "steps": t.steps,
        "model_flags": t.model_flags,
        "faults": t.faults.names().collect::<Vec<_>>(),
        "faults_latched": t.faults_latched.names().collect::<Vec<_>>(),
        "injecting": t.injecting,
        "axes": axes_json(t),
        "active": t.active.as_ref().map(slot_json),
        "rx_bad_frames": t.rx_bad_frames,
    })
}
