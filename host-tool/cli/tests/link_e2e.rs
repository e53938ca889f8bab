//! End to end: the `trueaxis` binary's link commands (upload, status,
//! monitor) against the firmware's application core running on the host —
//! the simulated board of `trueaxis-app` (engine, table store on a RAM
//! flash, link server, fake sensors) served on a loopback TCP socket, the
//! same bytes a board sees on its USB/UART link. Also: corrections read
//! back over the link equal model-core's own evaluation, an interrupted
//! upload keeps the running table and resumes, garbage on the line does
//! not stick the board, and `trueaxis flash` says clearly that no probe is
//! attached.

mod common;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use model_core::{parse, Inputs, Model};
use serde_json::Value;
use trueaxis::link::{Client, Timing};
use trueaxis_app::sim::{sample_spec, sample_table, SimBoard};
use trueaxis_protocol::{
    encode_frame, table_id, FrameDecoder, Injection, Packet, Request, Response, LINK_TEMPS,
    MAX_FRAME_BYTES,
};

/// A simulated board on a loopback port; stopped on drop.
struct Board {
    port: String,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<SimBoard>>,
    /// The board's sensors (tests move its encoders).
    io: Arc<std::sync::Mutex<trueaxis_app::sim::SimIo>>,
}

impl Board {
    fn start() -> Self {
        Self::serve(SimBoard::new())
    }

    /// Serves `board` (prepared in process) on a loopback port.
    fn serve(board: SimBoard) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = format!("tcp://{}", listener.local_addr().unwrap());
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let io = board.io.clone();
        let thread = std::thread::spawn(move || board.serve(listener, s));
        Self {
            port,
            stop,
            thread: Some(thread),
            io,
        }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Two clients at once (a `monitor` running while someone asks `status`):
/// the simulated board answers both, each on its own connection (issue 14:
/// the second used to get no answer until the first went away).
#[test]
fn the_simulated_board_answers_two_clients_at_once() {
    let board = Board::start();
    let mut first = Client::open(&board.port, Timing::default()).unwrap();
    let mut second = Client::open(&board.port, Timing::default()).unwrap();
    for _ in 0..3 {
        let a = first.status().unwrap();
        let b = second.status().unwrap();
        assert!(b.ticks >= a.ticks, "{} then {}", a.ticks, b.ticks);
    }
    drop(first);
    // The one left keeps being served after the other hangs up.
    assert!(second.status().is_ok());
}

/// Runs the built `trueaxis` with `args`.
fn trueaxis(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_trueaxis"))
        .args(args)
        .output()
        .unwrap()
}

/// Stdout of `trueaxis ARGS…` as JSON; the run must succeed.
fn json_ok(args: &[&str]) -> Value {
    let out = trueaxis(args);
    assert!(
        out.status.success(),
        "trueaxis {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `trueaxis upload FILE --port PORT --json`: its JSON (the run must succeed).
fn upload_json(file: &Path, port: &str) -> Value {
    json_ok(&["upload", file.to_str().unwrap(), "--port", port, "--json"])
}

/// `trueaxis status --port PORT --json`: its JSON (the run must succeed).
fn status_json(port: &str) -> Value {
    json_ok(&["status", "--port", port, "--json"])
}

fn table_file(name: &str, bytes: &[u8]) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("link_e2e_{name}.bin"));
    std::fs::write(&p, bytes).unwrap();
    p
}

/// `trueaxis reference --axis A --at-mm 0` for X, Y and Z (the simulated
/// encoders rest at 0).
fn reference_all(port: &str) {
    for axis in ["x", "y", "z"] {
        let r = json_ok(&[
            "reference",
            "--port",
            port,
            "--axis",
            axis,
            "--at-mm",
            "0",
            "--json",
        ]);
        assert_eq!(r["axes"][axis]["referenced"], true, "{r}");
    }
}

fn crc_hex(bytes: &[u8]) -> String {
    format!("{:#010x}", table_id(bytes))
}

#[test]
fn upload_status_monitor_and_read_back_equal_model_core() {
    let board = Board::start();
    let s = status_json(&board.port);
    assert!(s["active"].is_null());
    assert!(s["telemetry"]["faults"]
        .as_array()
        .unwrap()
        .contains(&"no_table".into()));

    let table = sample_table(0);
    let path = table_file("t0", &table);
    let u = upload_json(&path, &board.port);
    assert_eq!(u["crc32"], crc_hex(&table));
    assert_eq!(u["verified"], true);
    assert_eq!(u["active"]["slot"], "A");

    let s = status_json(&board.port);
    assert_eq!(s["active"]["crc32"], crc_hex(&table));
    assert_eq!(s["table_format"], model_core::FORMAT_VERSION);

    // Inject positions and read the corrections back over the link (the
    // board corrects only from referenced axes).
    reference_all(&board.port);
    let model = Model::load(&parse(&table).unwrap()).unwrap();
    let mut c = Client::open(&board.port, Timing::default()).unwrap();
    for pos_nm in [
        [0, 0, 0],
        [250_000_000, -120_000_000, 30_000_000],
        [-399_999_999, 399_999_999, -5],
    ] {
        let mut temp_mc = [21_000; LINK_TEMPS];
        temp_mc[0] = 24_500;
        let inj = Injection {
            pos_nm,
            rev_q30: [-(1 << 30), 1 << 30, 0],
            temp_mc,
            tool_nm: 10_000_000,
        };
        let Response::Correction(got) = c.request(&Request::Inject(inj)).unwrap() else {
            panic!()
        };
        let mut t = [0; model_core::MAX_TEMPS];
        t.copy_from_slice(&temp_mc[..model_core::MAX_TEMPS]);
        let want = model.eval_fixed(&Inputs {
            pos_nm,
            rev_q30: inj.rev_q30,
            temp_mc: t,
            tool_nm: inj.tool_nm,
        });
        assert_eq!(got.model_corr_nm, want.corr_nm, "at {pos_nm:?}");
        // The output slews to it (500 nm/ms, |corr| ≤ 60 µm: < 150 ms).
        std::thread::sleep(Duration::from_millis(400));
        let Response::Correction(now) = c.request(&Request::ReadCorrection).unwrap() else {
            panic!()
        };
        assert_eq!(now.corr_nm, want.corr_nm);
    }
    c.request(&Request::EndInject).unwrap();
    drop(c);

    let m = json_ok(&[
        "monitor",
        "--port",
        &board.port,
        "--count",
        "3",
        "--interval-ms",
        "20",
        "--json",
    ]);
    let samples = m["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 3);
    assert!(samples[2]["ticks"].as_u64() > samples[0]["ticks"].as_u64());
    assert_eq!(samples[0]["active"]["crc32"], crc_hex(&table));
}

/// The serial-port path of the host's link (every other test here uses
/// tcp://): the simulated board on the master side of a pseudo-terminal,
/// `trueaxis upload/status --port /dev/pts/N` opening the other side as a
/// serial port (115 200 8N1, exclusive, raw) like a USB CDC-ACM or UART
/// device.
#[cfg(unix)]
#[test]
fn upload_and_status_over_a_serial_port() {
    use serialport::{SerialPort, TTYPort};
    let (mut master, slave) = TTYPort::pair().expect("a pseudo-terminal pair");
    let path = slave.name().expect("the pty has a name");
    // Only the host tool holds the serial side: its exclusive lock is gone
    // when it exits, and the next command can open the port again.
    drop(slave);
    master.set_timeout(Duration::from_millis(1)).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let board = std::thread::spawn(move || SimBoard::new().serve_stream(master, s));

    let table = sample_table(1);
    let file = table_file("serial", &table);
    let u = upload_json(&file, &path);
    assert_eq!(u["port"], path.as_str());
    assert_eq!(u["crc32"], crc_hex(&table));
    assert_eq!(u["verified"], true);
    let st = status_json(&path);
    assert_eq!(st["active"]["crc32"], crc_hex(&table));
    assert_eq!(st["telemetry"]["rx_bad_frames"], 0);

    stop.store(true, Ordering::Relaxed);
    let b = board.join().unwrap();
    assert_eq!(b.engine().active().map(|a| a.crc32), Some(table_id(&table)));
}

#[test]
fn a_cut_upload_keeps_the_old_table_and_the_next_upload_resumes() {
    let board = Board::start();
    let t1 = sample_table(0);
    let p1 = table_file("cut_t1", &t1);
    upload_json(&p1, &board.port);

    // Half of t2, then the host goes away.
    let t2 = sample_table(2);
    {
        let mut c = Client::open(&board.port, Timing::default()).unwrap();
        c.request(&Request::UploadBegin {
            size: t2.len() as u32,
            crc32: table_id(&t2),
        })
        .unwrap();
        c.request(&Request::UploadChunk {
            offset: 0,
            data: &t2[..256],
        })
        .unwrap();
    }
    let s = status_json(&board.port);
    assert_eq!(s["active"]["crc32"], crc_hex(&t1));

    // Uploading t2 again picks up at byte 256.
    let p2 = table_file("cut_t2", &t2);
    let u = upload_json(&p2, &board.port);
    assert_eq!(u["resumed_at"], 256);
    assert_eq!(u["active"]["crc32"], crc_hex(&t2));
    assert_eq!(u["active"]["slot"], "B");
    let s = status_json(&board.port);
    assert_eq!(s["standby"]["crc32"], crc_hex(&t1));
}

/// A TCP proxy between the host and the board that drops the board's first
/// answer to a request `lost` picks (a frame lost on the way back) and
/// passes every other byte through.
fn lossy_proxy(board: &str, lost: fn(&Request) -> bool) -> String {
    proxy(board, lost, None)
}

/// A TCP proxy between the host and the board that replaces the board's
/// first answer to a request `pick` picks by `instead` (`None`: drops it)
/// and passes every other byte through.
fn proxy(board: &str, lost: fn(&Request) -> bool, instead: Option<Response>) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = format!("tcp://{}", listener.local_addr().unwrap());
    let board = board.strip_prefix("tcp://").unwrap().to_string();
    std::thread::spawn(move || {
        let (host, _) = listener.accept().unwrap();
        let up = TcpStream::connect(board).unwrap();
        let lost_seq = Arc::new(std::sync::Mutex::new(None::<u16>));
        // Host → board: note the sequence number of the first such request.
        let (mut from_host, mut to_board) = (host.try_clone().unwrap(), up.try_clone().unwrap());
        let seen = lost_seq.clone();
        std::thread::spawn(move || {
            let mut dec: FrameDecoder = FrameDecoder::new();
            let mut buf = [0u8; 1024];
            while let Ok(n) = from_host.read(&mut buf) {
                if n == 0 {
                    break;
                }
                // Noted before it is passed on, so the answer cannot overtake it.
                let mut input = &buf[..n];
                while let Some(f) = dec.feed(&mut input) {
                    let Ok(p) = f.and_then(trueaxis_protocol::decode_message::<Packet<Request>>)
                    else {
                        continue;
                    };
                    let mut s = seen.lock().unwrap();
                    if lost(&p.msg) && s.is_none() {
                        *s = Some(p.seq);
                    }
                }
                if to_board.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
            // The host hung up: hang up on the board too (it serves one
            // connection at a time).
            let _ = to_board.shutdown(std::net::Shutdown::Both);
        });
        // Board → host: every frame but the answer to that request.
        let (mut from_board, mut to_host) = (up, host);
        let mut dec: FrameDecoder = FrameDecoder::new();
        let mut buf = [0u8; 1024];
        let mut dropped = false;
        while let Ok(n) = from_board.read(&mut buf) {
            if n == 0 {
                break;
            }
            let mut input = &buf[..n];
            while let Some(f) = dec.feed(&mut input) {
                let Ok(p) = f.and_then(trueaxis_protocol::decode_message::<Packet<Response>>)
                else {
                    continue;
                };
                let mut p = p;
                if !dropped && Some(p.seq) == *lost_seq.lock().unwrap() {
                    dropped = true;
                    match &instead {
                        None => continue,
                        Some(r) => p.msg = r.clone(),
                    }
                }
                let mut frame = [0u8; MAX_FRAME_BYTES];
                let k = encode_frame(&p, &mut frame).unwrap();
                if to_host.write_all(&frame[..k]).is_err() {
                    return;
                }
            }
        }
    });
    addr
}

#[test]
fn an_upload_whose_commit_answer_is_lost_still_succeeds() {
    let board = Board::start();
    let proxy = lossy_proxy(&board.port, |r| matches!(r, Request::Commit));
    let table = sample_table(0);
    let timing = Timing {
        timeout: Duration::from_millis(300),
        tries: 4,
        commit_timeout: Duration::from_millis(500),
    };
    let mut c = Client::open(&proxy, timing).unwrap();
    // The commit is retried after its answer is lost; the board answers the
    // retry with the same success, so the upload completes.
    let r = c.upload(&table, |_, _| {}).unwrap();
    assert!(r.retries >= 1, "the commit's answer was not dropped");
    assert_eq!(r.committed.crc32, table_id(&table));
    assert_eq!(r.activated, r.committed);
    drop(c);
    let s = status_json(&board.port);
    assert_eq!(s["active"]["crc32"], crc_hex(&table));
    assert_eq!(s["active"]["seq"], 1, "written once");
}

/// Issue 25: `Activate` is under the commit's quiet rule. An axis that
/// starts moving between the commit and the activation gets `AxesMoving`
/// for the `Activate` — but the commit ran the table already, so the
/// upload succeeds (what runs is checked by `Identify`), with the
/// committed table reported active.
#[test]
fn an_upload_whose_activate_meets_a_moving_axis_still_succeeds() {
    let board = Board::start();
    let refused = Response::Error(trueaxis_protocol::LinkError::AxesMoving { quiet_ms: 200 });
    let proxy = proxy(
        &board.port,
        |r| matches!(r, Request::Activate),
        Some(refused),
    );
    let table = sample_table(0);
    let mut c = Client::open(&proxy, Timing::default()).unwrap();
    let r = c.upload(&table, |_, _| {}).unwrap();
    assert_eq!(r.committed.crc32, table_id(&table));
    assert_eq!(r.activated, r.committed);
    drop(c);
    assert_eq!(status_json(&board.port)["active"]["crc32"], crc_hex(&table));
}

/// Uploading the table that already runs writes nothing: written again it
/// would fill the other slot too and erase the table a rollback returns to.
#[test]
fn uploading_the_running_table_keeps_the_standby() {
    let board = Board::start();
    let (t0, t1) = (sample_table(0), sample_table(1));
    let (p0, p1) = (table_file("aa0", &t0), table_file("aa1", &t1));
    for p in [&p0, &p1] {
        let u = upload_json(p, &board.port);
        assert_eq!(u["already_active"], false);
    }
    let u = upload_json(&p1, &board.port);
    assert_eq!(u["already_active"], true);
    assert_eq!(u["chunks"], 0);
    assert_eq!(u["active"]["crc32"], crc_hex(&t1));
    assert_eq!(u["active"]["seq"], 2, "nothing written");
    let s = status_json(&board.port);
    assert_eq!(s["active"]["seq"], 2);
    assert_eq!(s["standby"]["crc32"], crc_hex(&t0));
    let out = trueaxis(&["upload", p1.to_str().unwrap(), "--port", &board.port]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    common::assert_has(
        &text,
        &["already runs on", "nothing written, the standby table kept"],
    );
}

/// `trueaxis rollback`: back to the previous table, refused (exit 1, the
/// active table kept) when there is none, and complete when the board's
/// answer is lost on the way back (the retry gets the same answer).
#[test]
fn rollback_returns_to_the_previous_table_even_when_its_answer_is_lost() {
    let board = Board::start();
    let (t0, t1) = (sample_table(0), sample_table(1));
    let (p0, p1) = (table_file("rb0", &t0), table_file("rb1", &t1));
    let upload = |p: &PathBuf| upload_json(p, &board.port);
    let refused = || {
        let out = trueaxis(&["rollback", "--port", &board.port, "--json"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        common::assert_no_document(&["--json"], &out);
        assert!(
            err.contains(&board.port)
                && err.contains("nothing to roll back to: the board holds one valid table (slot ")
                && err.contains("the active table is unchanged")
                && !err.contains("the board refused"),
            "{err}"
        );
    };
    upload(&p0);
    refused();
    upload(&p1);
    let r = json_ok(&["rollback", "--port", &board.port, "--json"]);
    assert_eq!(r["revoked"]["crc32"], crc_hex(&t1));
    assert_eq!(r["active"]["crc32"], crc_hex(&t0));
    assert_eq!(r["active"]["seq"], 1);
    assert_eq!(r["verified"], true);
    let s = status_json(&board.port);
    assert_eq!(s["active"], r["active"]);
    assert!(s["standby"].is_null(), "{s}");
    // The revoked table is gone: a second rollback has nothing to go to.
    refused();

    // The rollback's answer is lost: the client's retry gets the same one.
    upload(&p1);
    let proxy = lossy_proxy(&board.port, |r| matches!(r, Request::Rollback));
    let timing = Timing {
        timeout: Duration::from_millis(300),
        tries: 4,
        commit_timeout: Duration::from_millis(500),
    };
    let mut c = Client::open(&proxy, timing).unwrap();
    let r = c.rollback().unwrap();
    assert!(r.retries >= 1, "the rollback's answer was not dropped");
    assert_eq!(r.revoked.crc32, table_id(&t1));
    assert_eq!((r.active.crc32, r.active.seq), (table_id(&t0), 1));
    drop(c);
    let s = status_json(&board.port);
    assert_eq!(s["active"]["crc32"], crc_hex(&t0));
    assert!(s["standby"].is_null(), "{s}");
}

#[test]
fn garbage_on_the_line_does_not_stick_the_board() {
    let board = Board::start();
    let addr = board.port.strip_prefix("tcp://").unwrap().to_string();
    let mut s = TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let mut frame = [0u8; MAX_FRAME_BYTES];
    let n = encode_frame(
        &Packet {
            seq: 5,
            msg: Request::Identify,
        },
        &mut frame,
    )
    .unwrap();
    let mut junk: Vec<u8> = (0..3000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    junk.extend_from_slice(&frame[..n / 2]); // a cut frame
    s.write_all(&junk).unwrap();
    s.write_all(&frame[..n]).unwrap();
    let mut dec: FrameDecoder = FrameDecoder::new();
    let mut buf = [0u8; 1024];
    let mut answered = false;
    while !answered {
        let k = s.read(&mut buf).unwrap();
        assert!(k > 0, "board closed the link");
        let mut input = &buf[..k];
        while let Some(f) = dec.feed(&mut input) {
            let p: Packet<Response> = trueaxis_protocol::decode_message(f.unwrap()).unwrap();
            answered |= p.seq == 5 && matches!(p.msg, Response::Identity(_));
        }
    }
    drop(s);
    // And the next client is served normally.
    let st = status_json(&board.port);
    assert!(st["telemetry"]["rx_bad_frames"].as_u64().unwrap() >= 1);
}

#[test]
fn invalid_tables_are_refused_before_anything_is_sent() {
    let mut t = sample_table(0);
    t[100] ^= 1;
    let p = table_file("bad", &t);
    // No board on this port: the local check must fail first.
    let out = trueaxis(&[
        "upload",
        common::s(&p),
        "--port",
        "tcp://127.0.0.1:9",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a valid table"));
}

/// A valid table with one `n` × `n` grid on ex (model-core's default
/// capacity loads it; the board's may not).
fn grid_table(n: u16) -> Vec<u8> {
    trueaxis_app::sim::sample_grid_spec(n).encode().unwrap()
}

#[test]
fn tables_beyond_the_boards_limits_are_refused_before_touching_it() {
    // 40 × 40 = 1600 grid values (12.8 KB): over the 1024 of the board's
    // models. 60 × 60 (28.8 KB): over its 24 KiB staging buffer. And a
    // table too slow for the correction loop.
    let grid = table_file("limit_grid", &grid_table(40));
    let big_bytes = grid_table(60);
    let over = big_bytes.len() - model_core::board::STAGE_BYTES;
    let big = table_file("limit_bytes", &big_bytes);
    // model-core's golden all_kinds: fits the memory, but its fixed-point
    // evaluation is estimated over what the 20 kHz loop leaves for a model.
    let slow_bytes = include_bytes!("../../../model-core/tests/golden/all_kinds.bin");
    let est = model_core::cost::estimate(&parse(slow_bytes).unwrap()).fixed_instr;
    let budget = model_core::board::MODEL_BUDGET_INSTR;
    let slow = table_file("limit_slow", slow_bytes);
    let slow_want = format!(
        "estimated at {est} instructions, the board's 20000 Hz correction loop leaves {budget} for it: {} over",
        est - budget
    );
    for (path, want) in [
        (
            &grid,
            "needs 1600 grid values, the board's models hold 1024: 576 over".to_string(),
        ),
        (
            &big,
            format!("the board takes at most 24576 (its staging buffer): {over} bytes over"),
        ),
        (&slow, slow_want),
    ] {
        // No board on this port and (here) no probe: the check comes first.
        for args in [
            vec!["upload", common::s(path), "--port", "tcp://127.0.0.1:9"],
            vec!["flash", path.to_str().unwrap()],
        ] {
            let out = trueaxis(&args);
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
            assert!(err.contains("does not fit the board"), "{args:?}: {err}");
            assert!(err.contains(&want), "{args:?}: {err}");
        }
    }
}

/// The sample table with an Abbe term whose coefficients sum near the
/// loader's limit and a tool-arm range reaching 2^31 nm: valid and
/// loadable, but its fixed point departs from its own definition by tens
/// of µm (issue 25).
fn off_definition_table() -> Vec<u8> {
    use model_core::spec::TermSpec;
    let mut spec = sample_spec(0);
    spec.terms.push(TermSpec::Abbe {
        output: 0,
        coefs: vec![([1, 0, 0], 30_000.0)],
    });
    spec.envelope.tool_min_nm = -i32::MAX;
    spec.envelope.tool_max_nm = i32::MAX;
    spec.encode().unwrap()
}

/// Issue 25: `trueaxis upload` and `flash` refuse a table whose fixed
/// point departs from its own definition, saying by how much, on which
/// output and what the board allows, before touching the board; and the
/// board, sent the same table anyway (the link client's raw upload, as a
/// host tool that does not check would), refuses it at commit and keeps
/// the table it runs.
#[test]
fn an_off_definition_table_is_refused_by_upload_flash_and_the_board() {
    let bad = off_definition_table();
    let path = table_file("off_definition", &bad);
    let board = Board::start();
    let good = sample_table(0);
    let good_path = table_file("off_definition_good", &good);
    upload_json(&good_path, &board.port);
    for args in [
        vec!["upload", path.to_str().unwrap(), "--port", &board.port],
        vec!["flash", path.to_str().unwrap()],
    ] {
        let out = trueaxis(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        for want in [
            "does not fit the board",
            "its fixed-point evaluation can depart from the table's own definition",
            "nm on ex",
            "(Abbe)",
            "the board allows 100 nm",
        ] {
            assert!(err.contains(want), "{args:?}: no `{want}` in {err}");
        }
    }
    let mut client = Client::open(&board.port, Timing::default()).unwrap();
    let e = client.upload(&bad, |_, _| {}).unwrap_err();
    assert!(
        e.to_string().contains("rejected the table as invalid"),
        "{e}"
    );
    drop(client);
    assert_eq!(status_json(&board.port)["active"]["crc32"], crc_hex(&good));
}

#[test]
fn status_without_a_board_fails_with_the_port_named() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", listener.local_addr().unwrap());
    drop(listener);
    let out = trueaxis(&["status", "--port", &port]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("cannot open {port}: ")), "{err}");
    // The cause once, not `refused (os error 111): refused (os error 111)`.
    assert_eq!(err.matches("os error").count(), 1, "{err}");
}

/// A port that is not a board: `tcp:/` (one slash) gets a hint, a file or
/// /dev/null is "not a serial device" rather than "Not a typewriter" alone.
#[test]
fn ports_that_are_not_a_board_are_named_as_such() {
    let out = trueaxis(&["status", "--port", "tcp:/127.0.0.1:1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("cannot open tcp:/127.0.0.1:1: a TCP port is written tcp://HOST:PORT"),
        "{err}"
    );
    let file = table_file("not_a_port", b"x_mm,err_um\n");
    for port in [file.to_str().unwrap(), "/dev/null"] {
        let out = trueaxis(&["status", "--port", port]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains(&format!("{port} is not a serial device")),
            "{port}: {err}"
        );
    }
}

/// A closed link is said once (`link I/O on PORT: link closed`).
#[test]
fn a_closed_link_is_said_once() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", listener.local_addr().unwrap());
    let t = std::thread::spawn(move || {
        let (mut c, _) = listener.accept().unwrap();
        let mut b = [0u8; 64];
        let _ = c.read(&mut b);
    });
    let out = trueaxis(&["status", "--port", &port]);
    t.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("link I/O on {port}: link closed")),
        "{err}"
    );
    assert_eq!(err.matches("link closed").count(), 1, "{err}");
}

/// A table whose temperature envelope (30-50 °C) excludes the board's
/// 20 °C: status and monitor name TEMP_OUT_OF_RANGE (bit 4) and show the
/// temperatures in °C.
#[test]
fn status_and_monitor_name_the_model_flags_and_show_temperatures() {
    let board = Board::start();
    let mut spec = sample_spec(0);
    spec.envelope.temp_min_mc = [30_000, 30_000, 0, 0];
    let table = spec.encode().unwrap();
    let path = table_file("warm", &table);
    upload_json(&path, &board.port);
    std::thread::sleep(Duration::from_millis(50));
    let s = status_json(&board.port);
    let t = &s["telemetry"];
    assert_eq!(t["model_flags"], 16, "{s}");
    assert_eq!(
        t["model_flags_names"],
        serde_json::json!(["temp_out_of_range"])
    );
    assert_eq!(t["temp_mc"][0], 20_000);
    let out = trueaxis(&["status", "--port", &board.port]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("model flags: temp_out_of_range\n"), "{text}");
    assert!(text.contains("temperatures:  20.000, 20.000"), "{text}");
    assert!(text.contains(" °C\n"), "{text}");
    let m = json_ok(&["monitor", "--port", &board.port, "--json"]);
    assert_eq!(
        m["samples"][0]["model_flags_names"],
        serde_json::json!(["temp_out_of_range"])
    );
    let out = trueaxis(&["monitor", "--port", &board.port, "--count", "1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("model_flags=temp_out_of_range "), "{text}");
    assert!(text.contains("temps=[20.000, "), "{text}");
}

/// `status --clear-faults`: the fault latched at boot (no table) is
/// reported as cleared and is gone from `faults_latched`; text says the
/// correction resumes.
#[test]
fn status_clear_faults_clears_the_latched_faults() {
    let board = Board::start();
    let path = table_file("clear", &sample_table(0));
    upload_json(&path, &board.port);
    reference_all(&board.port);
    let s = status_json(&board.port);
    assert!(s["cleared_faults"].is_null(), "{s}");
    assert_eq!(s["telemetry"]["faults"], serde_json::json!([]), "{s}");
    assert_eq!(
        s["telemetry"]["faults_latched"],
        serde_json::json!(["no_table", "not_referenced"]),
        "{s}"
    );
    let s = json_ok(&["status", "--port", &board.port, "--json", "--clear-faults"]);
    assert_eq!(
        s["cleared_faults"],
        serde_json::json!(["no_table", "not_referenced"]),
        "{s}"
    );
    assert_eq!(
        s["telemetry"]["faults_latched"],
        serde_json::json!([]),
        "{s}"
    );
    let out = trueaxis(&["status", "--port", &board.port, "--clear-faults"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("cleared latched faults: none (the correction slews back"),
        "{text}"
    );
    assert!(text.contains("faults: none (latched: none)"), "{text}");
}

#[test]
fn flash_without_a_probe_is_a_clear_error() {
    let p = table_file("flash", &sample_table(0));
    let out = trueaxis(&["flash", p.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no debug probe attached"), "{err}");
}

/// The link lost in the middle of an upload (here: the board hangs up at
/// once): exit 1, and the message says how to find out whether the board
/// runs the new table already — a lost answer to the last chunk or the
/// commit leaves that open.
#[test]
fn a_lost_link_during_upload_says_how_to_check_the_board() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = format!("tcp://{}", listener.local_addr().unwrap());
    let hang_up = std::thread::spawn(move || drop(listener.accept()));
    let path = table_file("lost", &sample_table(0));
    let out = trueaxis(&["upload", path.to_str().unwrap(), "--port", &port, "--json"]);
    hang_up.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    common::assert_no_document(&["--json"], &out);
    common::assert_has(
        &err,
        &[&format!(
            "the board may run the new table already: `trueaxis status --port {port}` tells"
        )],
    );
}

/// Issue 14: the board corrects only after every axis is referenced, with
/// `trueaxis reference`; `status` and `monitor` show the state per axis
/// (text and JSON); an injection ends when its client goes.
#[test]
fn the_board_corrects_only_after_trueaxis_reference_and_status_shows_it() {
    let board = Board::start();
    let table = sample_table(0);
    upload_json(&table_file("ref", &table), &board.port);
    let s = status_json(&board.port);
    let t = &s["telemetry"];
    assert_eq!(t["faults"], serde_json::json!(["not_referenced"]), "{s}");
    assert_eq!(
        t["axes"]["y"],
        serde_json::json!({"referenced": false, "reference_needed": true})
    );
    let out = trueaxis(&["status", "--port", &board.port]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("referencing:   x NOT REFERENCED, y NOT REFERENCED, z NOT REFERENCED\n"),
        "{text}"
    );

    // Injected, not referenced: the output stays at zero.
    let pos_nm = [250_000_000, -120_000_000, 30_000_000];
    let inj = Injection {
        pos_nm,
        rev_q30: [0; 3],
        temp_mc: [20_000; LINK_TEMPS],
        tool_nm: 0,
    };
    let mut c = Client::open(&board.port, Timing::default()).unwrap();
    let Response::Correction(got) = c.request(&Request::Inject(inj)).unwrap() else {
        panic!()
    };
    assert_ne!(got.model_corr_nm, [0; 3]);
    std::thread::sleep(Duration::from_millis(300));
    let Response::Correction(now) = c.request(&Request::ReadCorrection).unwrap() else {
        panic!()
    };
    assert_eq!(now.corr_nm, [0; 3]);

    // One axis: text says which are still missing.
    let out = trueaxis(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "x",
        "--at-mm",
        "0",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    common::assert_has(
        &text,
        &["x referenced at 0.000000 mm on ", "y NOT REFERENCED"],
    );
    assert!(
        text.contains("the correction stays at zero until"),
        "{text}"
    );
    let r = json_ok(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "y",
        "--at-mm",
        "0",
        "--json",
    ]);
    assert_eq!(r["all_referenced"], false, "{r}");
    let r = json_ok(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "z",
        "--at-mm",
        "0",
        "--json",
    ]);
    assert_eq!(r["all_referenced"], true, "{r}");
    assert_eq!(r["faults"], serde_json::json!([]), "{r}");
    assert_eq!(r["pos_nm"], 0);

    // Now the output ramps in to the model's (500 nm/ms: < 150 ms).
    c.request(&Request::Inject(inj)).unwrap();
    std::thread::sleep(Duration::from_millis(400));
    let Response::Correction(now) = c.request(&Request::ReadCorrection).unwrap() else {
        panic!()
    };
    assert_eq!(now.corr_nm, got.model_corr_nm);
    let out = trueaxis(&["monitor", "--port", &board.port, "--count", "1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains(" ref=[x,y,z] "), "{text}");
    assert_eq!(status_json(&board.port)["telemetry"]["injecting"], true);
    // The injecting client goes: the board is back on its sensors.
    drop(c);
    std::thread::sleep(Duration::from_millis(100));
    let t = &status_json(&board.port)["telemetry"];
    assert_eq!(t["injecting"], false, "{t}");
    assert_eq!(t["pos_nm"], serde_json::json!([0, 0, 0]), "{t}");

    // A negative position is a value, not a flag (docs/cli.md); status then
    // reports the position it names.
    let r = json_ok(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "y",
        "--at-mm",
        "-12.5",
        "--json",
    ]);
    assert_eq!(r["pos_nm"], -12_500_000, "{r}");
    let t = &status_json(&board.port)["telemetry"];
    assert_eq!(t["pos_nm"], serde_json::json!([0, -12_500_000, 0]), "{t}");

    // A position the link cannot carry is refused before anything is sent.
    let out = trueaxis(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "x",
        "--at-mm",
        "5000",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--at-mm 5000: expected a position within ±2147 mm"),
        "{err}"
    );
}

/// `trueaxis reference` while an axis moves: refused by the board, exit 1,
/// the reason named; nothing referenced.
#[test]
fn reference_is_refused_while_an_axis_moves() {
    let board = Board::start();
    let moving = Arc::new(AtomicBool::new(true));
    let (m, io) = (moving.clone(), board.io.clone());
    // X creeps 1 µm (10 counts) every millisecond: 1 mm/s.
    let mover = std::thread::spawn(move || {
        while m.load(Ordering::Relaxed) {
            io.lock().unwrap().counts[0] += 10;
            std::thread::sleep(Duration::from_millis(1));
        }
    });
    std::thread::sleep(Duration::from_millis(50));
    let out = trueaxis(&[
        "reference",
        "--port",
        &board.port,
        "--axis",
        "y",
        "--at-mm",
        "0",
    ]);
    moving.store(false, Ordering::Relaxed);
    mover.join().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    common::assert_has(
        &err,
        &[
            "referencing y on tcp://",
            "the board refused reference: the axes are moving",
            "at rest (within 1 µm) for 20 ms",
        ],
    );
    let t = &status_json(&board.port)["telemetry"];
    assert_eq!(t["axes"]["y"]["referenced"], false, "{t}");
}

/// Sends `req` to the simulated board in process; its one answer.
fn sim_call(b: &mut SimBoard, p: &mut trueaxis_app::server::Port, req: Request<'_>) -> Response {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode_frame(&Packet { seq: 1, msg: req }, &mut buf).unwrap();
    let out = b.receive(p, &buf[..n]);
    let mut dec: FrameDecoder = FrameDecoder::new();
    let mut input = &out[..];
    let frame = dec.feed(&mut input).unwrap().unwrap();
    trueaxis_protocol::decode_message::<Packet<Response>>(frame)
        .unwrap()
        .msg
}

/// Uploads and commits `t` to the simulated board in process.
fn sim_install(b: &mut SimBoard, t: &[u8]) {
    let mut p = trueaxis_app::server::Port::new();
    let begin = Request::UploadBegin {
        size: t.len() as u32,
        crc32: table_id(t),
    };
    assert!(matches!(
        sim_call(b, &mut p, begin),
        Response::UploadAck { .. }
    ));
    for (i, data) in t.chunks(trueaxis_protocol::MAX_CHUNK_BYTES).enumerate() {
        let offset = (i * trueaxis_protocol::MAX_CHUNK_BYTES) as u32;
        let r = sim_call(b, &mut p, Request::UploadChunk { offset, data });
        assert!(matches!(r, Response::UploadAck { .. }), "{r:?}");
    }
    let r = sim_call(b, &mut p, Request::Commit);
    assert!(matches!(r, Response::Committed(_)), "{r:?}");
}

/// The boot fallback as `trueaxis status` shows it: a table that panicked
/// the board during its trial window is gone after the reset, the previous
/// one runs, and the latched faults say why (JSON and text).
#[test]
fn status_shows_a_boot_fallback_and_why() {
    let (t1, t2) = (sample_table(0), sample_table(1));
    let mut sim = SimBoard::new();
    sim_install(&mut sim, &t1);
    sim.tick(5000); // t1 confirmed (5 s of 1 ms ticks)
    sim_install(&mut sim, &t2);
    sim.tick(100); // t2 on trial
    let board = Board::serve(sim.fault_reset(trueaxis_app::boot::Fault::Panic));
    let s = status_json(&board.port);
    let t = &s["telemetry"];
    assert_eq!(t["active"]["crc32"], crc_hex(&t1), "{s}");
    let latched = common::strs(&t["faults_latched"]);
    assert!(latched.contains(&"trial_failed"), "{s}");
    assert!(latched.contains(&"reset_by_panic"), "{s}");
    assert!(!t["faults"].to_string().contains("trial_failed"), "{s}");
    let out = trueaxis(&["status", "--port", &board.port]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("trial_failed, reset_by_panic"), "{text}");
}
