//! The link server end to end inside one process: the simulated board
//! (application core, RAM flash, fake sensors) fed with real frames.
//! Upload/resume/commit/activate/rollback, every refusal the protocol
//! defines, corrections equal to model-core's own evaluation, garbage on
//! the line, and fuzzed input.

mod common;

use common::{call, decode_all, install, stage};
use model_core::{parse, Inputs, Model};
use proptest::prelude::*;
use trueaxis_app::server::Port;
use trueaxis_app::sim::{sample_table, SimBoard};
use trueaxis_protocol::{
    encode_frame, table_id, Faults, Injection, LinkError, Packet, Request, Response, Slot,
    LINK_TEMPS, MAX_FRAME_BYTES,
};

fn injection(pos_nm: [i32; 3]) -> Injection {
    let mut temp_mc = [20_000; LINK_TEMPS];
    temp_mc[0] = 27_500;
    Injection {
        pos_nm,
        rev_q30: [1 << 30, -(1 << 30), 0],
        temp_mc,
        tool_nm: 50_000_000,
    }
}

fn host_eval(table: &[u8], inj: &Injection) -> [i32; 3] {
    let m = Model::load(&parse(table).unwrap()).unwrap();
    let mut temp_mc = [0; model_core::MAX_TEMPS];
    temp_mc.copy_from_slice(&inj.temp_mc[..model_core::MAX_TEMPS]);
    m.eval_fixed(&Inputs {
        pos_nm: inj.pos_nm,
        rev_q30: inj.rev_q30,
        temp_mc,
        tool_nm: inj.tool_nm,
    })
    .corr_nm
}

/// References X, Y and Z at 0 over the link (the encoders rest at 0) and
/// runs the tick that applies it.
fn reference_all(b: &mut SimBoard, p: &mut Port) {
    for axis in 0..3 {
        assert_eq!(
            call(
                b,
                p,
                50 + u16::from(axis),
                Request::Reference { axis, pos_nm: 0 }
            ),
            Response::Ok
        );
    }
    b.tick(1);
}

/// Request `seq` commits the uploaded table.
fn assert_committed(b: &mut SimBoard, p: &mut Port, seq: u16) {
    let answer = call(b, p, seq, Request::Commit);
    assert!(matches!(answer, Response::Committed(_)), "{answer:?}");
}

/// Request `seq` activates the committed table.
fn assert_activated(b: &mut SimBoard, p: &mut Port, seq: u16) {
    let answer = call(b, p, seq, Request::Activate);
    assert!(matches!(answer, Response::Activated(_)), "{answer:?}");
}

fn status(b: &mut SimBoard, p: &mut Port) -> trueaxis_protocol::Telemetry {
    let Response::Status(t) = call(b, p, 60, Request::Status) else {
        panic!()
    };
    t
}

#[test]
fn axes_are_referenced_over_the_link_only_at_rest() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    install(&mut b, &mut p, &sample_table(0));
    b.tick(5);
    let t = status(&mut b, &mut p);
    assert_eq!((t.referenced, t.reference_needed), ([false; 3], [true; 3]));
    assert!(t.faults.contains(Faults::NOT_REFERENCED));
    assert_eq!(
        call(&mut b, &mut p, 1, Request::Reference { axis: 3, pos_nm: 0 }),
        Response::Error(LinkError::BadAxis)
    );
    // X moves: refused, and nothing changes.
    for _ in 0..5 {
        b.io.lock().unwrap().counts[0] += 10;
        b.tick(1);
    }
    let moving = Request::Reference {
        axis: 1,
        pos_nm: 7_000_000,
    };
    assert_eq!(
        call(&mut b, &mut p, 2, moving.clone()),
        Response::Error(LinkError::NotStill { still_ms: 20 })
    );
    b.tick(5);
    assert_eq!(status(&mut b, &mut p).referenced, [false; 3]);
    // At rest for 20 ms: accepted, applied at the next tick.
    b.tick(20);
    assert_eq!(call(&mut b, &mut p, 3, moving), Response::Ok);
    b.tick(1);
    let t = status(&mut b, &mut p);
    assert_eq!(t.referenced, [false, true, false]);
    assert_eq!(t.pos_nm[1], 7_000_000);
    reference_all(&mut b, &mut p);
    let t = status(&mut b, &mut p);
    assert_eq!(t.referenced, [true; 3]);
    assert!(t.faults.is_empty(), "{:?}", t.faults);
}

#[test]
fn an_injection_needs_the_axes_at_rest_and_ends_with_its_lease_or_its_client() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    install(&mut b, &mut p, &sample_table(0));
    reference_all(&mut b, &mut p);
    // Z moves 10 µm (beyond the 1 µm a servo at rest dithers).
    b.io.lock().unwrap().counts[2] += 100;
    b.tick(1);
    let inj = injection([100_000_000, 0, 0]);
    assert_eq!(
        call(&mut b, &mut p, 1, Request::Inject(inj)),
        Response::Error(LinkError::NotStill { still_ms: 20 })
    );
    b.tick(20);
    assert!(matches!(
        call(&mut b, &mut p, 2, Request::Inject(inj)),
        Response::Correction(_)
    ));
    // The lease: 2 s at the sim's 1 ms ticks, renewed by each Inject.
    b.tick(1500);
    assert!(status(&mut b, &mut p).injecting);
    call(&mut b, &mut p, 3, Request::Inject(inj));
    b.tick(2000);
    let t = status(&mut b, &mut p);
    assert!(t.injecting);
    assert_eq!(t.pos_nm, inj.pos_nm);
    b.tick(1);
    let t = status(&mut b, &mut p);
    assert!(!t.injecting, "the lease ran out");
    assert_eq!(t.pos_nm, [0, 0, 100 * 100]);
    // Its client goes: the injection ends; another client going does not
    // end it.
    call(&mut b, &mut p, 4, Request::Inject(inj));
    let mut other = Port::new();
    status(&mut b, &mut other);
    b.close(&mut other);
    b.tick(1);
    assert!(status(&mut b, &mut p).injecting);
    // A refused injection (a reversal state no tracker has) takes nothing
    // over: its client leaving leaves the injection running.
    let mut refused = Port::new();
    let mut bad = inj;
    bad.rev_q30[0] = (1 << 30) + 1;
    assert_eq!(
        call(&mut b, &mut refused, 6, Request::Inject(bad)),
        Response::Error(LinkError::BadInjection)
    );
    b.close(&mut refused);
    b.tick(1);
    assert!(status(&mut b, &mut p).injecting);
    // A second client takes the injection over; the first one leaving no
    // longer ends it.
    call(&mut b, &mut other, 5, Request::Inject(inj));
    b.close(&mut p);
    b.tick(1);
    assert!(status(&mut b, &mut other).injecting);
    b.close(&mut other);
    b.tick(1);
    assert!(!status(&mut b, &mut other).injecting);
}

#[test]
fn empty_board_identifies_and_reports_no_table() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let Response::Identity(id) = call(&mut b, &mut p, 9, Request::Identify) else {
        panic!()
    };
    assert_eq!(id.active, None);
    assert_eq!(id.protocol, trueaxis_protocol::PROTOCOL_VERSION);
    assert_eq!(id.table_format, model_core::FORMAT_VERSION);
    b.tick(3);
    let Response::Status(t) = call(&mut b, &mut p, 10, Request::Status) else {
        panic!()
    };
    assert!(t.faults.contains(Faults::NO_TABLE));
    assert_eq!(t.corr_nm, [0; 3]);
    assert_eq!(
        call(&mut b, &mut p, 11, Request::Activate),
        Response::Error(LinkError::NothingToActivate)
    );
}

#[test]
fn install_inject_and_read_back_equals_model_core() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let table = sample_table(0);
    let r = install(&mut b, &mut p, &table);
    let Response::Activated(info) = r else {
        panic!("{r:?}")
    };
    assert_eq!(info.crc32, table_id(&table));
    assert_eq!((info.slot, info.seq), (Slot::A, 1));
    // Not referenced: the output stays at zero whatever is injected.
    call(&mut b, &mut p, 12, Request::Inject(injection([0; 3])));
    b.tick(200);
    let Response::Correction(c) = call(&mut b, &mut p, 13, Request::ReadCorrection) else {
        panic!()
    };
    assert_eq!(c.corr_nm, [0; 3]);
    assert_eq!(c.faults, Faults::NOT_REFERENCED);
    reference_all(&mut b, &mut p);

    for (k, pos) in [
        [0, 0, 0],
        [123_456_789, -98_765_432, 5_000_000],
        [-399_000_000, 399_000_000, 0],
    ]
    .into_iter()
    .enumerate()
    {
        let inj = injection(pos);
        let want = host_eval(&table, &inj);
        let Response::Correction(c) = call(&mut b, &mut p, 20 + k as u16, Request::Inject(inj))
        else {
            panic!()
        };
        assert_eq!(c.model_corr_nm, want, "at {pos:?}");
        // The output slews there: 500 nm/ms, 1 ms ticks, |corr| ≤ 60 µm.
        b.tick(200);
        let Response::Correction(c) = call(&mut b, &mut p, 30, Request::ReadCorrection) else {
            panic!()
        };
        assert_eq!(c.corr_nm, want);
        assert!(c.faults.is_empty(), "{:?}", c.faults);
        // Pulses follow: round(corr / 100 nm).
        let pulses = b.io.lock().unwrap().pulses;
        for a in 0..3 {
            assert_eq!(
                pulses[a],
                trueaxis_app::engine::round_div(want[a] as i64, 100)
            );
        }
    }
    let mut bad = injection([0; 3]);
    bad.rev_q30[2] = (1 << 30) + 1;
    assert_eq!(
        call(&mut b, &mut p, 39, Request::Inject(bad)),
        Response::Error(LinkError::BadInjection)
    );
    assert_eq!(call(&mut b, &mut p, 40, Request::EndInject), Response::Ok);
}

#[test]
fn upload_resumes_after_a_dropped_link() {
    let mut b = SimBoard::new();
    let table = sample_table(1);
    let crc32 = table_id(&table);
    let size = table.len() as u32;
    let mut p = Port::new();
    call(&mut b, &mut p, 1, Request::UploadBegin { size, crc32 });
    call(
        &mut b,
        &mut p,
        2,
        Request::UploadChunk {
            offset: 0,
            data: &table[..100],
        },
    );
    // Half a frame, then the link drops.
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode_frame(
        &Packet {
            seq: 3,
            msg: Request::UploadChunk {
                offset: 100,
                data: &table[100..200],
            },
        },
        &mut buf,
    )
    .unwrap();
    assert!(b.receive(&mut p, &buf[..n / 2]).is_empty());
    let mut p = Port::new();
    // Same size and CRC: resume at 100.
    assert_eq!(
        call(&mut b, &mut p, 4, Request::UploadBegin { size, crc32 }),
        Response::UploadAck { next_offset: 100 }
    );
    // A chunk at the wrong offset is refused and says where to go on.
    assert_eq!(
        call(
            &mut b,
            &mut p,
            5,
            Request::UploadChunk {
                offset: 150,
                data: &table[150..160]
            }
        ),
        Response::Error(LinkError::BadOffset { expected: 100 })
    );
    // A retried chunk is acknowledged again.
    assert_eq!(
        call(
            &mut b,
            &mut p,
            6,
            Request::UploadChunk {
                offset: 0,
                data: &table[..100]
            }
        ),
        Response::UploadAck { next_offset: 100 }
    );
    assert_eq!(
        call(&mut b, &mut p, 7, Request::Commit),
        Response::Error(LinkError::Incomplete {
            received: 100,
            size
        })
    );
    let mut off = 100;
    while off < table.len() {
        let end = (off + 256).min(table.len());
        call(
            &mut b,
            &mut p,
            8,
            Request::UploadChunk {
                offset: off as u32,
                data: &table[off..end],
            },
        );
        off = end;
    }
    assert_committed(&mut b, &mut p, 9);
    assert_activated(&mut b, &mut p, 10);
}

/// The host retries a request whose answer it did not get. For a commit
/// whose answer was lost on the way back, the retry must get the same
/// success — the upload it refers to is spent, and `NoUpload` would make
/// `trueaxis upload` fail although the table is stored.
#[test]
fn a_repeated_commit_gets_the_same_answer() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let table = sample_table(0);
    install(&mut b, &mut p, &table);
    let t2 = sample_table(1);
    let crc32 = table_id(&t2);
    let begin = Request::UploadBegin {
        size: t2.len() as u32,
        crc32,
    };
    stage(&mut b, &mut p, 20, &t2, crc32);
    // The first commit's answer is lost on the way back...
    let Response::Committed(first) = call(&mut b, &mut p, 22, Request::Commit) else {
        panic!("commit refused")
    };
    assert_eq!((first.slot, first.crc32), (Slot::B, crc32));
    // ... so the host sends it again (a new sequence number): the same
    // answer — same slot and sequence number, so nothing was written again.
    assert_eq!(
        call(&mut b, &mut p, 23, Request::Commit),
        Response::Committed(first)
    );
    assert!(matches!(
        call(&mut b, &mut p, 24, Request::Activate),
        Response::Activated(i) if i == first
    ));
    // Not once the board moved on: after a rollback, or once a new upload
    // began, a commit without an upload is refused again.
    assert!(matches!(
        call(&mut b, &mut p, 25, Request::Rollback),
        Response::RolledBack(_)
    ));
    assert_eq!(
        call(&mut b, &mut p, 26, Request::Commit),
        Response::Error(LinkError::NoUpload)
    );
    install(&mut b, &mut p, &t2);
    call(&mut b, &mut p, 27, begin);
    assert!(matches!(
        call(&mut b, &mut p, 28, Request::Commit),
        Response::Error(LinkError::Incomplete { received: 0, .. })
    ));
}

/// A committed table runs at once, without waiting for `Activate`: when
/// the link drops between the two, the board must not keep a newest table
/// that does not run — boot and rollback would start it, and the next
/// commit would erase the slot of the table actually running.
#[test]
fn a_commit_runs_its_table_without_waiting_for_activate() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let (t1, t2, t3) = (sample_table(0), sample_table(1), sample_table(2));
    install(&mut b, &mut p, &t1);
    // t2 committed; its Activate never arrives.
    stage(&mut b, &mut p, 40, &t2, table_id(&t2));
    let Response::Committed(c2) = call(&mut b, &mut p, 42, Request::Commit) else {
        panic!("commit refused")
    };
    assert_eq!(b.engine().active(), Some(c2));
    let Response::Identity(id) = call(&mut b, &mut p, 43, Request::Identify) else {
        panic!()
    };
    assert_eq!(id.active, Some(c2));
    assert_eq!(id.standby.map(|s| s.crc32), Some(table_id(&t1)));
    // The next commit goes over t1's slot, not over the table that runs.
    stage(&mut b, &mut p, 44, &t3, table_id(&t3));
    let Response::Committed(c3) = call(&mut b, &mut p, 46, Request::Commit) else {
        panic!("commit refused")
    };
    assert_ne!(c3.slot, c2.slot);
    assert_eq!(b.engine().active(), Some(c3));
    // A late Activate changes nothing; a rollback returns to t2.
    assert_eq!(
        call(&mut b, &mut p, 47, Request::Activate),
        Response::Activated(c3)
    );
    let Response::RolledBack(r) = call(&mut b, &mut p, 48, Request::Rollback) else {
        panic!("rollback refused")
    };
    assert_eq!(r, c2);
    assert_eq!(b.engine().active(), Some(c2));
}

/// The same for a rollback: its retry after a lost answer gets the same
/// `RolledBack`, not `NothingToRollBackTo` (the revoked table is gone),
/// and writes nothing. Once a new upload began, the board has moved on.
#[test]
fn a_repeated_rollback_gets_the_same_answer() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let (t1, t2) = (sample_table(0), sample_table(1));
    install(&mut b, &mut p, &t1);
    install(&mut b, &mut p, &t2);
    // The first rollback's answer is lost on the way back...
    let Response::RolledBack(first) = call(&mut b, &mut p, 30, Request::Rollback) else {
        panic!("rollback refused")
    };
    assert_eq!(first.crc32, table_id(&t1));
    let ops = b.flash_ops();
    // ... so the host sends it again: the same answer, nothing written,
    // the first table still the one correcting.
    assert_eq!(
        call(&mut b, &mut p, 31, Request::Rollback),
        Response::RolledBack(first)
    );
    assert_eq!(b.flash_ops(), ops);
    assert_eq!(b.engine().active(), Some(first));
    // A rollback is not a commit: a commit after it has no upload.
    assert_eq!(
        call(&mut b, &mut p, 32, Request::Commit),
        Response::Error(LinkError::NoUpload)
    );
    // A new upload forgets it: the next rollback is judged afresh, and
    // with one valid table there is nothing to roll back to.
    let crc32 = table_id(&t2);
    call(
        &mut b,
        &mut p,
        33,
        Request::UploadBegin {
            size: t2.len() as u32,
            crc32,
        },
    );
    assert_eq!(
        call(&mut b, &mut p, 34, Request::Rollback),
        Response::Error(LinkError::NothingToRollBackTo)
    );
}

#[test]
fn refusals() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    assert_eq!(
        call(&mut b, &mut p, 1, Request::Commit),
        Response::Error(LinkError::NoUpload)
    );
    assert_eq!(
        call(
            &mut b,
            &mut p,
            1,
            Request::UploadChunk {
                offset: 0,
                data: &[1]
            }
        ),
        Response::Error(LinkError::NoUpload)
    );
    assert!(matches!(
        call(
            &mut b,
            &mut p,
            1,
            Request::UploadBegin {
                size: 10_000_000,
                crc32: 0
            }
        ),
        Response::Error(LinkError::TooLarge { .. })
    ));

    // Announced CRC does not match the bytes.
    let table = sample_table(0);
    stage(&mut b, &mut p, 2, &table, 1);
    assert_eq!(
        call(&mut b, &mut p, 4, Request::Commit),
        Response::Error(LinkError::CrcMismatch)
    );
    // The refused bytes are forgotten: announcing the same upload again
    // starts from byte 0 instead of "resuming" the bad staged bytes.
    assert_eq!(
        call(
            &mut b,
            &mut p,
            4,
            Request::UploadBegin {
                size: table.len() as u32,
                crc32: 1,
            },
        ),
        Response::UploadAck { next_offset: 0 }
    );

    // Bytes that match their announced CRC but are not a valid table.
    let mut bad = table.clone();
    bad[300] ^= 0x40;
    let crc32 = table_id(&bad);
    stage(&mut b, &mut p, 5, &bad, crc32);
    assert_eq!(
        call(&mut b, &mut p, 7, Request::Commit),
        Response::Error(LinkError::InvalidTable)
    );
    assert_eq!(
        call(
            &mut b,
            &mut p,
            7,
            Request::UploadBegin {
                size: bad.len() as u32,
                crc32,
            },
        ),
        Response::UploadAck { next_offset: 0 }
    );
    assert_eq!(
        call(&mut b, &mut p, 8, Request::Rollback),
        Response::Error(LinkError::NothingToRollBackTo)
    );
}

/// A valid table the firmware's model capacity cannot hold (a 40 × 40
/// grid: 1600 values > `FW_GRID`) is refused at commit, not half loaded.
#[test]
fn tables_beyond_the_firmware_capacity_are_refused_at_commit() {
    let table = trueaxis_app::sim::sample_grid_spec(40).encode().unwrap();
    const { assert!(trueaxis_app::model::FW_GRID < 1600) };
    // Valid, and model-core's default capacity would take it.
    assert!(Model::load(&parse(&table).unwrap()).is_ok());
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let crc32 = table_id(&table);
    stage(&mut b, &mut p, 1, &table, crc32);
    assert_eq!(
        call(&mut b, &mut p, 3, Request::Commit),
        Response::Error(LinkError::InvalidTable)
    );
}

/// A valid table the correction loop could not evaluate every period —
/// model-core's golden `all_kinds`, a two-layer network among every other
/// term kind, estimated above the board's model budget — is refused at
/// commit with both figures; nothing is written, the active table stays.
#[test]
fn tables_too_slow_for_the_loop_are_refused_at_commit() {
    let slow: &[u8] = include_bytes!("../../../model-core/tests/golden/all_kinds.bin");
    let est = model_core::cost::estimate(&parse(slow).unwrap()).fixed_instr;
    let budget = model_core::board::MODEL_BUDGET_INSTR;
    assert!(est > budget, "{est} ≤ {budget}: not a test of the refusal");
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let table = sample_table(0);
    install(&mut b, &mut p, &table);
    let begin = Request::UploadBegin {
        size: slow.len() as u32,
        crc32: table_id(slow),
    };
    stage(&mut b, &mut p, 30, slow, table_id(slow));
    assert_eq!(
        call(&mut b, &mut p, 32, Request::Commit),
        Response::Error(LinkError::TooSlow {
            estimate_instr: est,
            budget_instr: budget
        })
    );
    let Response::Identity(id) = call(&mut b, &mut p, 33, Request::Identify) else {
        panic!()
    };
    assert_eq!(id.active.map(|a| a.crc32), Some(table_id(&table)));
    assert_eq!(id.standby, None, "nothing was written");
    // The staged bytes are spent: uploading again starts at 0.
    assert_eq!(
        call(&mut b, &mut p, 34, begin),
        Response::UploadAck { next_offset: 0 }
    );
}

#[test]
fn commit_is_refused_while_axes_move() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    install(&mut b, &mut p, &sample_table(0));
    let t2 = sample_table(1);
    let crc32 = table_id(&t2);
    stage(&mut b, &mut p, 1, &t2, crc32);
    b.tick(5);
    b.io.lock().unwrap().counts[1] += 1000;
    b.tick(5);
    assert_eq!(
        call(&mut b, &mut p, 3, Request::Commit),
        Response::Error(LinkError::AxesMoving { quiet_ms: 200 })
    );
    // Standing still for the quiet time makes it go through (the upload
    // is kept meanwhile).
    b.tick(200);
    assert_committed(&mut b, &mut p, 4);
}

#[test]
fn rollback_and_reboot_pick_the_right_table() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let (t1, t2) = (sample_table(0), sample_table(1));
    install(&mut b, &mut p, &t1);
    let Response::Activated(i2) = install(&mut b, &mut p, &t2) else {
        panic!()
    };
    assert_eq!((i2.slot, i2.seq), (Slot::B, 2));
    let Response::Identity(id) = call(&mut b, &mut p, 1, Request::Identify) else {
        panic!()
    };
    assert_eq!(id.active, Some(i2));
    assert_eq!(id.standby.map(|s| s.seq), Some(1));

    // Reboot: the newest boots.
    let mut b = SimBoard::with_flash(b.into_flash());
    assert_eq!(b.engine().active(), Some(i2));

    let Response::RolledBack(i1) = call(&mut b, &mut p, 2, Request::Rollback) else {
        panic!()
    };
    assert_eq!(i1.crc32, table_id(&t1));
    assert_eq!(b.engine().active(), Some(i1));
    let b = SimBoard::with_flash(b.into_flash());
    assert_eq!(b.engine().active(), Some(i1));
}

#[test]
fn an_interrupted_upload_keeps_the_running_table() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let t1 = sample_table(0);
    let Response::Activated(i1) = install(&mut b, &mut p, &t1) else {
        panic!()
    };
    let t2 = sample_table(2);
    call(
        &mut b,
        &mut p,
        1,
        Request::UploadBegin {
            size: t2.len() as u32,
            crc32: table_id(&t2),
        },
    );
    call(
        &mut b,
        &mut p,
        2,
        Request::UploadChunk {
            offset: 0,
            data: &t2[..256],
        },
    );
    // The host goes away. The board keeps correcting with t1, and after a
    // reboot still boots t1.
    b.tick(10);
    assert_eq!(b.engine().active(), Some(i1));
    let b = SimBoard::with_flash(b.into_flash());
    assert_eq!(b.engine().active(), Some(i1));
}

#[test]
fn garbage_and_cut_frames_between_requests() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let mut stream = vec![0x13u8, 0x37, 0x00, 0xFF, 0xFF, 0x01];
    let n = encode_frame(
        &Packet {
            seq: 1,
            msg: Request::Identify,
        },
        &mut buf,
    )
    .unwrap();
    stream.extend_from_slice(&buf[..n - 3]); // cut
    stream.extend_from_slice(&[0xAA; 700]); // overflow
    let n = encode_frame(
        &Packet {
            seq: 2,
            msg: Request::Status,
        },
        &mut buf,
    )
    .unwrap();
    stream.extend_from_slice(&buf[..n]);
    let out = b.receive(&mut p, &stream);
    let answers = decode_all(&out);
    assert_eq!(answers.len(), 1);
    assert_eq!(answers[0].seq, 2);
    let Response::Status(t) = &answers[0].msg else {
        panic!()
    };
    assert!(t.rx_bad_frames >= 2, "{}", t.rx_bad_frames);
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed),
        ..ProptestConfig::default()
    })]

    /// Random bytes, then a valid request: the board never panics, and the
    /// request is answered.
    #[test]
    fn fuzzed_input_never_sticks(junk in proptest::collection::vec(any::<u8>(), 0..3000)) {
        let mut b = SimBoard::new();
        let mut p = Port::new();
        b.receive(&mut p, &junk);
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = encode_frame(&Packet { seq: 77, msg: Request::Identify }, &mut buf).unwrap();
        let out = b.receive(&mut p, &buf[..n]);
        let answers = decode_all(&out);
        prop_assert!(answers.iter().any(|a| a.seq == 77));
    }
}

/// A reset (power loss) loses the references: the rebooted board runs the
/// stored table but holds the output at zero until referenced again.
#[test]
fn a_reboot_loses_the_references_the_table_stays() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let table = sample_table(0);
    install(&mut b, &mut p, &table);
    reference_all(&mut b, &mut p);
    b.io.lock().unwrap().counts = [1_000_000, 0, 0];
    b.tick(300);
    let t = status(&mut b, &mut p);
    assert!(t.faults.is_empty(), "{:?}", t.faults);
    assert_ne!(t.corr_nm, [0; 3]);

    let mut b = SimBoard::with_flash(b.into_flash());
    let mut p = Port::new();
    b.tick(300);
    let t = status(&mut b, &mut p);
    assert_eq!(t.active.map(|a| a.crc32), Some(table_id(&table)));
    assert_eq!(t.referenced, [false; 3]);
    assert_eq!(t.faults, Faults::NOT_REFERENCED);
    assert_eq!(t.corr_nm, [0; 3]);
    assert_eq!(t.steps, [0; 3]);
    assert!(t.faults_latched.contains(Faults::NOT_REFERENCED));
}

/// A servo holding an axis dithers by a count or two: the axis is at rest
/// (it can be referenced and injected on), while leaving the ±1 µm band
/// is motion.
#[test]
fn a_dithering_axis_is_at_rest() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    install(&mut b, &mut p, &sample_table(0));
    // A count or a few (0.1 µm each) either way, every tick for 100 ms:
    // never more than 1 µm from where the axis first stood (count 1).
    for k in 0..100 {
        b.io.lock().unwrap().counts[0] = [1, -1, 5, -5, 11, -9][k % 6];
        b.tick(1);
    }
    assert_eq!(
        call(&mut b, &mut p, 1, Request::Reference { axis: 0, pos_nm: 0 }),
        Response::Ok
    );
    assert!(matches!(
        call(&mut b, &mut p, 2, Request::Inject(injection([0; 3]))),
        Response::Correction(_)
    ));
    // 1.1 µm away from it: motion.
    b.io.lock().unwrap().counts[0] = 12;
    b.tick(1);
    assert_eq!(
        call(&mut b, &mut p, 3, Request::Reference { axis: 1, pos_nm: 0 }),
        Response::Error(LinkError::NotStill { still_ms: 20 })
    );
    assert!(!status(&mut b, &mut p).injecting);
}

fn identity(b: &mut SimBoard, p: &mut Port) -> trueaxis_protocol::Identity {
    let Response::Identity(id) = call(b, p, 70, Request::Identify) else {
        panic!()
    };
    id
}

/// The boot fallback (trueaxis_app::boot): a table that faults the board
/// during its trial window (5 s of ticks; 1 ms ticks here) is revoked by
/// the next boot, the previous table runs and `status` says why; after its
/// window a table is confirmed and a fault no longer throws it away; a
/// reset without a fault, or a power cut, is not held against a table.
#[test]
fn a_table_that_faults_during_its_trial_falls_back_to_the_previous_one() {
    use trueaxis_app::boot::Fault;
    let (t1, t2) = (sample_table(0), sample_table(1));
    for fault in [Fault::Panic, Fault::HardFault, Fault::Watchdog] {
        let mut b = SimBoard::new();
        let mut p = Port::new();
        install(&mut b, &mut p, &t1);
        b.tick(5000); // t1 confirmed
        install(&mut b, &mut p, &t2);
        b.tick(4000); // t2 still on trial
        let mut b = b.fault_reset(fault);
        let t = status(&mut b, &mut p);
        assert_eq!(t.active.map(|a| a.crc32), Some(table_id(&t1)), "{fault:?}");
        assert!(t
            .faults_latched
            .contains(Faults::TRIAL_FAILED.union(fault.bit())));
        assert!(!t.faults.contains(Faults::TRIAL_FAILED), "latched only");
        // t2 is revoked: nothing to roll back to, and a power cycle (RAM
        // lost) keeps t1.
        assert_eq!(identity(&mut b, &mut p).standby, None);
        let mut b = SimBoard::with_flash(b.into_flash());
        assert_eq!(
            status(&mut b, &mut p).active.map(|a| a.crc32),
            Some(table_id(&t1))
        );
    }

    // Confirmed after its window: a later fault keeps the table.
    let mut b = SimBoard::new();
    let mut p = Port::new();
    install(&mut b, &mut p, &t1);
    b.tick(5000);
    install(&mut b, &mut p, &t2);
    b.tick(5000);
    let mut b = b.fault_reset(Fault::Panic);
    let t = status(&mut b, &mut p);
    assert_eq!(t.active.map(|a| a.crc32), Some(table_id(&t2)));
    assert!(!t.faults_latched.contains(Faults::TRIAL_FAILED));
    // After that boot t2 is on trial again: a fault now falls back.
    b.tick(100);
    let mut b = b.fault_reset(Fault::Panic);
    assert_eq!(
        status(&mut b, &mut p).active.map(|a| a.crc32),
        Some(table_id(&t1))
    );

    // A reset without a fault during the trial keeps the new table.
    let mut b = SimBoard::new();
    install(&mut b, &mut p, &t1);
    b.tick(5000);
    install(&mut b, &mut p, &t2);
    b.tick(10);
    let mut b = b.plain_reset();
    assert_eq!(
        status(&mut b, &mut p).active.map(|a| a.crc32),
        Some(table_id(&t2))
    );

    // The only table faults: the board runs none rather than reset-loop,
    // until a power cycle gives the table a new trial.
    let mut b = SimBoard::new();
    install(&mut b, &mut p, &t1);
    b.tick(10);
    let mut b = b.fault_reset(Fault::Panic);
    let t = status(&mut b, &mut p);
    assert_eq!(t.active, None);
    assert!(t.faults.contains(Faults::NO_TABLE));
    assert!(t.faults_latched.contains(Faults::TRIAL_FAILED));
    let mut b = b.fault_reset(Fault::Panic);
    assert_eq!(status(&mut b, &mut p).active, None);
    let mut b = SimBoard::with_flash(b.into_flash());
    assert_eq!(
        status(&mut b, &mut p).active.map(|a| a.crc32),
        Some(table_id(&t1))
    );
}

/// `trueaxis export`, `upload` and `flash` refuse a table with
/// `model_core::board::check`'s message (export's JSON `board.refusal`);
/// this walks every way `check` refuses — and a table it accepts — and
/// requires the board itself (the real server, store and model load) to
/// refuse the same tables, with the same figures where its answer carries
/// them, and to write nothing.
#[test]
fn the_board_refuses_exactly_what_board_check_refuses() {
    use model_core::board::{check, LimitError, MODEL_BUDGET_INSTR, MODEL_GRID, STAGE_BYTES};
    use model_core::spec::{LayerSpec, MlpInputSpec, MlpSource, MlpSpec, TermSpec};
    use model_core::LoadError;

    let grid = |n: u16, value_nm: f64| {
        let mut spec = trueaxis_app::sim::sample_grid_spec(n);
        if let TermSpec::Grid(g) = &mut spec.terms[0] {
            g.values_nm[5] = value_nm;
        }
        spec.encode().unwrap()
    };
    // A two-layer network of 32 units: 3·32+32 + 32·32+32 + 32·3+3 = 1283
    // parameters.
    let mlp = {
        let mut spec = trueaxis_app::sim::sample_spec(0);
        let layer = |i: usize, o: usize| LayerSpec {
            weights: (0..i * o).map(|k| ((k % 7) as f64 - 3.0) * 0.1).collect(),
            bias: vec![0.01; o],
        };
        spec.terms.push(TermSpec::Mlp(MlpSpec {
            outputs: vec![0, 1, 2],
            inputs: (0..3u8)
                .map(|a| MlpInputSpec {
                    source: MlpSource::Pos(a),
                    min: -400e6,
                    max: 400e6,
                })
                .collect(),
            hidden: vec![layer(3, 32), layer(32, 32)],
            output: layer(32, 3),
            out_min_nm: vec![-20_000.0; 3],
            out_max_nm: vec![20_000.0; 3],
        }));
        spec.encode().unwrap()
    };
    let slow = include_bytes!("../../../model-core/tests/golden/all_kinds.bin").to_vec();
    let est = model_core::cost::estimate(&parse(&slow).unwrap()).fixed_instr;

    /// Name, table, what `check` says, what the board answers (`None`:
    /// it commits).
    type Case = (
        &'static str,
        Vec<u8>,
        Result<(), LimitError>,
        Option<LinkError>,
    );
    let cases: Vec<Case> = vec![
        ("fits", sample_table(0), Ok(()), None),
        (
            "grid capacity",
            grid(40, 10.0),
            Err(LimitError::Grid {
                needed: 1600,
                max: MODEL_GRID as u32,
            }),
            Some(LinkError::InvalidTable),
        ),
        (
            "staging buffer",
            grid(60, 10.0),
            Err(LimitError::TooLarge {
                bytes: grid(60, 10.0).len() as u32,
                max: STAGE_BYTES as u32,
            }),
            Some(LinkError::TooLarge {
                max_bytes: STAGE_BYTES as u32,
            }),
        ),
        (
            "parameter capacity",
            mlp.clone(),
            Err(LimitError::Params {
                // The network and the sample table's two coefficients.
                needed: 1283 + 2,
                max: model_core::board::MODEL_PARAMS as u32,
            }),
            Some(LinkError::InvalidTable),
        ),
        (
            "load (grid value range)",
            grid(8, 5_000_000.0),
            Err(LimitError::Load(LoadError::GridValueRange { term: 0 })),
            Some(LinkError::InvalidTable),
        ),
        (
            "off its definition",
            off_definition_table(),
            check(&parse(&off_definition_table()).unwrap()),
            Some(LinkError::InvalidTable),
        ),
        (
            "loop budget",
            slow,
            Err(LimitError::TooSlow {
                estimate: est,
                budget: MODEL_BUDGET_INSTR,
            }),
            Some(LinkError::TooSlow {
                estimate_instr: est,
                budget_instr: MODEL_BUDGET_INSTR,
            }),
        ),
    ];
    for (name, table, want_check, want_board) in cases {
        let got_check = parse(&table).map(|t| check(&t));
        assert_eq!(got_check, Ok(want_check), "{name}: board::check");
        let mut b = SimBoard::new();
        let mut p = Port::new();
        install(&mut b, &mut p, &sample_table(1));
        let ops = b.flash_ops();
        let begin = call(
            &mut b,
            &mut p,
            1,
            Request::UploadBegin {
                size: table.len() as u32,
                crc32: table_id(&table),
            },
        );
        let answer = if let Response::Error(e) = begin {
            Response::Error(e)
        } else {
            stage(&mut b, &mut p, 1, &table, table_id(&table));
            call(&mut b, &mut p, 3, Request::Commit)
        };
        match want_board {
            None => assert!(
                matches!(answer, Response::Committed(_)),
                "{name}: {answer:?}"
            ),
            Some(e) => {
                assert_eq!(answer, Response::Error(e), "{name}");
                assert_eq!(b.flash_ops(), ops, "{name}: nothing written");
            }
        }
    }
}

/// The sample table with an Abbe term whose coefficients sum near the
/// loader's limit and a tool-arm range reaching 2^31 nm: it loads, but its
/// fixed point departs from its own definition by tens of µm.
fn off_definition_table() -> Vec<u8> {
    use model_core::spec::TermSpec;
    let mut spec = trueaxis_app::sim::sample_spec(0);
    spec.terms.push(TermSpec::Abbe {
        output: 0,
        coefs: vec![([1, 0, 0], 30_000.0)],
    });
    spec.envelope.tool_min_nm = -i32::MAX;
    spec.envelope.tool_max_nm = i32::MAX;
    let bad = spec.encode().unwrap();
    assert!(matches!(
        model_core::board::check(&parse(&bad).unwrap()),
        Err(model_core::board::LimitError::OffDefinition(_))
    ));
    bad
}

/// Issue 25: a table whose fixed point departs from its own definition —
/// an Abbe term whose coefficients sum near the loader's limit, with a
/// tool-arm range reaching 2^31 nm — is refused at commit (nothing
/// written), and the table that ran keeps running.
#[test]
fn an_off_definition_table_is_refused_at_commit_and_the_old_one_keeps_running() {
    let bad = off_definition_table();
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let good = sample_table(1);
    install(&mut b, &mut p, &good);
    let ops = b.flash_ops();
    stage(&mut b, &mut p, 10, &bad, table_id(&bad));
    assert_eq!(
        call(&mut b, &mut p, 12, Request::Commit),
        Response::Error(LinkError::InvalidTable)
    );
    assert_eq!(b.flash_ops(), ops, "nothing written");
    assert_eq!(b.engine().active().map(|a| a.crc32), Some(table_id(&good)));
}

/// Issue 25: the same table reaching a slot without a commit (written
/// through a debug probe by a host tool that did not check it): the boot
/// does not run it — the other slot's table runs.
#[test]
fn an_off_definition_table_in_flash_is_not_booted() {
    use trueaxis_app::sim::{SimFlash, SIM_LAYOUT, SIM_SLOT_BYTES};
    use trueaxis_app::store::TableStore;
    let good = sample_table(1);
    let bad = off_definition_table();
    let flash = SimFlash::new_erased(vec![0; 2 * SIM_SLOT_BYTES as usize]);
    let mut store = TableStore::new(flash, SIM_LAYOUT).unwrap();
    let mut buf = vec![0u8; model_core::board::STAGE_BYTES];
    store.scan(&mut buf, |_| true);
    store.commit(&good, |_| true).unwrap();
    store.commit(&bad, |_| true).unwrap();
    assert_eq!(store.active().map(|a| a.crc32), Some(table_id(&bad)));
    let b = SimBoard::with_flash(store.into_flash());
    assert_eq!(b.engine().active().map(|a| a.crc32), Some(table_id(&good)));
}

/// Issue 25: `Activate` while an axis moves. It reloads the newest table
/// and used to reset the reversal trackers: ex dropped by the whole
/// reversal amplitude (2.5 µm) until X had travelled 20 µm. Now it is
/// refused while the axes move (the commit's quiet rule) and, at rest,
/// keeps the reversal state.
#[test]
fn activate_while_moving_does_not_reset_the_reversal_state() {
    let mut b = SimBoard::new();
    let mut p = Port::new();
    let t = sample_table(0);
    install(&mut b, &mut p, &t);
    reference_all(&mut b, &mut p);
    // X moves forward 0.1 µm per tick for 500 ticks: reversal state +1.
    for _ in 0..500 {
        b.io.lock().unwrap().counts[0] += 1;
        b.tick(1);
    }
    let before = b.engine().telemetry().model_corr_nm;
    let answer = call(&mut b, &mut p, 20, Request::Activate);
    assert_eq!(
        answer,
        Response::Error(LinkError::AxesMoving { quiet_ms: 200 })
    );
    b.io.lock().unwrap().counts[0] += 1;
    b.tick(1);
    let after = b.engine().telemetry().model_corr_nm;
    assert!(
        (after[0] - before[0]).abs() < 100,
        "Activate while moving ({answer:?}) changed ex {} -> {}",
        before[0],
        after[0]
    );
    // At rest for the quiet time it goes through, and the reversal state
    // (+1: X last moved forward) is kept across the table's reload.
    b.tick(250);
    let before = b.engine().telemetry().model_corr_nm;
    assert_activated(&mut b, &mut p, 21);
    b.tick(1);
    assert_eq!(b.engine().telemetry().model_corr_nm, before);
}
