//! The end-to-end scenarios against the board image (see main.rs).
//!
//! Every expectation is computed on the host from the table bytes with
//! model-core (`parse` + `Model::load` + `eval_fixed`), the very code the
//! board runs, so "equal" means bit for bit.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use model_core::{Inputs, Model, MAX_TEMPS};
// splitmix64 with a fixed seed: the same trajectory and garbage every run.
use trueaxis_protocol::{
    table_id, Correction, Faults, Injection, LinkError, Request, Response, SlotInfo, LINK_TEMPS,
    MAX_CHUNK_BYTES,
};
use trueaxis_test_support::SplitMix64 as Rng;

use crate::link::LinkClient;
use crate::Cli;

/// A table file with its host-side model.
struct HostTable {
    name: String,
    bytes: Vec<u8>,
    crc32: u32,
    model: Box<Model>,
}

impl HostTable {
    fn read(path: &Path) -> Result<Self, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
        Self::from_bytes(path.display().to_string(), bytes)
    }

    fn from_bytes(name: String, bytes: Vec<u8>) -> Result<Self, String> {
        let table = model_core::parse(&bytes).map_err(|e| format!("{name}: {e}"))?;
        let model =
            Box::new(Model::load(&table).map_err(|e| format!("{name}: cannot load: {e:?}"))?);
        Ok(Self {
            name,
            crc32: table_id(&bytes),
            bytes,
            model,
        })
    }

    /// The host's fixed-point evaluation of an injection.
    fn expect(&self, inj: &Injection) -> ([i32; 3], u16) {
        let mut temp_mc = [0; MAX_TEMPS];
        temp_mc.copy_from_slice(&inj.temp_mc[..MAX_TEMPS]);
        let out = self.model.eval_fixed(&Inputs {
            pos_nm: inj.pos_nm,
            rev_q30: inj.rev_q30,
            temp_mc,
            tool_nm: inj.tool_nm,
        });
        (out.corr_nm, out.flags.bits())
    }
}

/// A trajectory through the table's envelope: a zig-zag raster with the
/// reversal state following the direction of travel, the bed temperature
/// drifting, and a few points beyond the travel (the board must hold the
/// correction at the edge and flag it exactly as the host does).
fn trajectory(t: &HostTable, points: usize) -> Vec<Injection> {
    let env = t.model.envelope();
    let mut rng = Rng(0x7EA1_0000_E2E0_0001);
    let lo = env.travel_min_nm.map(f64::from);
    let hi = env.travel_max_nm.map(f64::from);
    let mut prev = lo;
    (0..points)
        .map(|i| {
            let s = i as f64 / points as f64;
            // X sweeps back and forth 5 times, Y climbs, Z wobbles.
            let fx = ((s * 5.0).fract() * 2.0 - 1.0).abs();
            let fy = s;
            let fz = 0.5 + 0.45 * (s * 17.0).sin();
            let mut pos = [fx, fy, fz];
            if i % 50 == 49 {
                // Beyond the travel by up to 2 %.
                pos[i % 3] = if rng.unit() < 0.5 { -0.02 } else { 1.02 } * rng.unit().max(0.5);
            }
            let pos_nm: [i32; 3] =
                std::array::from_fn(|a| (lo[a] + (hi[a] - lo[a]) * pos[a]).round() as i32);
            let rev_q30 = std::array::from_fn(|a| {
                let p = f64::from(pos_nm[a]);
                let r = if p >= prev[a] { 1 << 30 } else { -(1 << 30) };
                prev[a] = p;
                r
            });
            let mut temp_mc = [0; LINK_TEMPS];
            temp_mc[0] = 20_000 + (4_000.0 * s) as i32 + (rng.unit() * 200.0) as i32;
            Injection {
                pos_nm,
                rev_q30,
                temp_mc,
                tool_nm: (env.tool_min_nm as f64
                    + (env.tool_max_nm as f64 - env.tool_min_nm as f64) * rng.unit())
                    as i32,
            }
        })
        .collect()
}

fn err<T>(what: &str, resp: Response) -> Result<T, String> {
    Err(format!("{what}: unexpected answer {resp:?}"))
}

fn req(link: &mut LinkClient, r: &Request<'_>) -> Result<Response, String> {
    link.request(r).map_err(|e| e.to_string())
}

/// Connects and waits until the board answers `Identify`.
fn connect(port: u16) -> Result<LinkClient, String> {
    let mut link = LinkClient::connect(port).map_err(|e| e.to_string())?;
    match req(&mut link, &Request::Identify)? {
        Response::Identity(_) => Ok(link),
        other => err("Identify", other),
    }
}

/// The active and standby slots.
fn slots(link: &mut LinkClient) -> Result<(Option<SlotInfo>, Option<SlotInfo>), String> {
    match req(link, &Request::Identify)? {
        Response::Identity(id) => Ok((id.active, id.standby)),
        other => err("Identify", other),
    }
}

/// Sends a request that may be refused while the axes are not quiet
/// (injections count as motion): waits and retries.
fn req_when_quiet(link: &mut LinkClient, r: &Request<'_>) -> Result<Response, String> {
    for _ in 0..50 {
        match req(link, r)? {
            Response::Error(LinkError::AxesMoving { quiet_ms }) => {
                std::thread::sleep(Duration::from_millis(u64::from(quiet_ms) + 10));
            }
            other => return Ok(other),
        }
    }
    Err(format!("{r:?}: the board kept saying the axes move"))
}

/// Uploads `bytes` announced with `crc32`, the first `send` bytes only
/// (`None`: all). Returns the next offset the board wants.
fn upload_bytes(
    link: &mut LinkClient,
    bytes: &[u8],
    crc32: u32,
    send: Option<usize>,
) -> Result<u32, String> {
    let size = bytes.len() as u32;
    let mut next = match req(link, &Request::UploadBegin { size, crc32 })? {
        Response::UploadAck { next_offset } => next_offset,
        other => return err("UploadBegin", other),
    };
    let end = send.unwrap_or(bytes.len()).min(bytes.len());
    while (next as usize) < end {
        let from = next as usize;
        let to = (from + MAX_CHUNK_BYTES).min(end);
        match req(
            link,
            &Request::UploadChunk {
                offset: next,
                data: &bytes[from..to],
            },
        )? {
            Response::UploadAck { next_offset } if next_offset as usize == to => next = next_offset,
            other => return err("UploadChunk", other),
        }
    }
    Ok(next)
}

/// Upload, commit and activate with our own client.
fn upload_activate(link: &mut LinkClient, t: &HostTable) -> Result<SlotInfo, String> {
    upload_bytes(link, &t.bytes, t.crc32, None)?;
    match req_when_quiet(link, &Request::Commit)? {
        Response::Committed(info) if info.crc32 == t.crc32 => {}
        other => return err("Commit", other),
    }
    match req_when_quiet(link, &Request::Activate)? {
        Response::Activated(info) if info.crc32 == t.crc32 => Ok(info),
        other => err("Activate", other),
    }
}

/// `trueaxis upload` (the host tool, as a user runs it) against the board.
fn upload_with_trueaxis(bin: &Path, port: u16, table: &Path) -> Result<(), String> {
    let port_arg = format!("tcp://127.0.0.1:{port}");
    let table_s = table.to_string_lossy();
    run_trueaxis(bin, &["upload", &table_s, "--port", &port_arg, "--json"])
}

/// Runs `trueaxis <args>`, passing its output on; an error unless it exits 0.
fn run_trueaxis(bin: &Path, args: &[&str]) -> Result<(), String> {
    eprintln!("e2e: $ {} {}", bin.display(), args.join(" "));
    let out = Command::new(bin)
        .args(args)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", bin.display()))?;
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    println!("{}", String::from_utf8_lossy(&out.stdout).trim_end());
    if !out.status.success() {
        return Err(format!("`trueaxis {}` failed ({})", args[0], out.status));
    }
    Ok(())
}

/// Injects every point and compares with the host; returns how many points
/// were flagged by the model (clamps exercised).
fn compare_trajectory(
    link: &mut LinkClient,
    t: &HostTable,
    points: &[Injection],
) -> Result<usize, String> {
    let mut flagged = 0;
    for (i, inj) in points.iter().enumerate() {
        let c: Correction = match req(link, &Request::Inject(*inj))? {
            Response::Correction(c) => c,
            other => return err("Inject", other),
        };
        let (want_nm, want_flags) = t.expect(inj);
        if c.model_corr_nm != want_nm || c.model_flags != want_flags {
            return Err(format!(
                "point {i} {inj:?}: board {:?} flags {:#x}, host ({}) {want_nm:?} flags {want_flags:#x}",
                c.model_corr_nm, c.model_flags, t.name
            ));
        }
        flagged += usize::from(want_flags != 0);
    }
    Ok(flagged)
}

/// The loop's output: at each point the board's `corr_nm` — what the
/// correction loop drives the axes with, after the slew limit, not the
/// link task's `model_corr_nm` — must settle on the host's fixed-point
/// evaluation exactly. Waits for the slew: |change| / the table's slew
/// limit, tripled (the engine may lower the limit to what its pulses can
/// follow; QEMU's virtual time is not the wall clock's), plus 2 s. A fault
/// ramps the output to zero instead, so there must be none — except loop
/// overruns, which QEMU produces by itself: while the guest idles its
/// virtual clock follows the host's, so a host that deschedules QEMU for a
/// few ms (a loaded CI machine) shows the engine a gap of several periods.
/// Those are cleared and counted, and the output must still settle.
/// Returns the longest wait and the overruns cleared.
fn settle_output(
    link: &mut LinkClient,
    t: &HostTable,
    points: &[Injection],
) -> Result<(Duration, u32), String> {
    let slew = u64::from(
        t.model
            .envelope()
            .max_slew_nm_per_ms()
            .unsigned_abs()
            .max(1),
    );
    match req(link, &Request::ClearFaults)? {
        Response::Ok => {}
        other => return err("ClearFaults", other),
    }
    let read = |link: &mut LinkClient| -> Result<Correction, String> {
        match req(link, &Request::ReadCorrection)? {
            Response::Correction(c) => Ok(c),
            other => err("ReadCorrection", other),
        }
    };
    // The injection is a lease (2 s of board ticks): each poll renews it
    // with the same point, and its answer carries the output too.
    let inject = |link: &mut LinkClient, inj: &Injection| -> Result<Correction, String> {
        match req(link, &Request::Inject(*inj))? {
            Response::Correction(c) => Ok(c),
            other => err("Inject", other),
        }
    };
    let mut longest = Duration::ZERO;
    let mut overruns = 0u32;
    for (i, inj) in points.iter().enumerate() {
        let before = read(link)?.corr_nm;
        let (want, _) = t.expect(inj);
        let c = inject(link, inj)?;
        if c.model_corr_nm != want {
            return err("Inject before the output settles", Response::Correction(c));
        }
        let dist = (0..3)
            .map(|a| u64::from(want[a].abs_diff(before[a])))
            .max()
            .unwrap_or(0);
        let limit = Duration::from_millis(2000 + 3 * dist / slew);
        let started = std::time::Instant::now();
        loop {
            std::thread::sleep(Duration::from_millis(20));
            let c = inject(link, inj)?;
            if c.faults == Faults::LOOP_OVERRUN && overruns < 20 {
                overruns += 1;
                match req(link, &Request::ClearFaults)? {
                    Response::Ok => continue,
                    other => return err("ClearFaults", other),
                }
            }
            if !c.faults.is_empty() {
                return Err(format!(
                    "point {i}: faults {:?} while the output settles (corr_nm {:?}, host {want:?})",
                    c.faults.names().collect::<Vec<_>>(),
                    c.corr_nm
                ));
            }
            if c.corr_nm == want {
                longest = longest.max(started.elapsed());
                break;
            }
            if started.elapsed() > limit + Duration::from_millis(500) * overruns {
                return Err(format!(
                    "point {i} {inj:?}: the loop's output corr_nm is {:?} after {} ms, the host's evaluation {want:?} ({} nm to go at {slew} nm/ms)",
                    c.corr_nm,
                    limit.as_millis(),
                    dist
                ));
            }
        }
    }
    Ok((longest, overruns))
}

fn status(link: &mut LinkClient) -> Result<trueaxis_protocol::Telemetry, String> {
    match req(link, &Request::Status)? {
        Response::Status(t) => Ok(t),
        other => err("Status", other),
    }
}

/// Before any reference: an injected point's correction is computed, but
/// the loop's output stays at zero with `not_referenced` (checked for
/// 300 ms, the injection renewed).
fn not_referenced_holds_zero(link: &mut LinkClient, inj: &Injection) -> Result<(), String> {
    let t = status(link)?;
    if t.referenced != [false; 3] || t.reference_needed != [true; 3] {
        return Err(format!(
            "a fresh board: referenced {:?}, needed {:?}",
            t.referenced, t.reference_needed
        ));
    }
    let started = std::time::Instant::now();
    while started.elapsed() < Duration::from_millis(300) {
        let c = match req(link, &Request::Inject(*inj))? {
            Response::Correction(c) => c,
            other => return err("Inject", other),
        };
        if c.model_corr_nm == [0; 3] {
            return Err("the test point has no correction to hold back".into());
        }
        if c.corr_nm != [0; 3] || !c.faults.contains(Faults::NOT_REFERENCED) {
            return Err(format!(
                "not referenced, yet the output is {:?} (faults {:?})",
                c.corr_nm,
                c.faults.names().collect::<Vec<_>>()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

/// References X, Y and Z at 0 (the image's encoders rest at 0): with
/// `trueaxis reference` when the host tool is given, else with this
/// program's client. Returns the (re)connected link.
fn reference_axes(cli: &Cli, link: LinkClient) -> Result<LinkClient, String> {
    let mut link = match &cli.trueaxis {
        Some(bin) => {
            drop(link);
            let port_arg = format!("tcp://127.0.0.1:{}", cli.port);
            for axis in ["x", "y", "z"] {
                run_trueaxis(
                    bin,
                    &[
                        "reference",
                        "--port",
                        &port_arg,
                        "--axis",
                        axis,
                        "--at-mm",
                        "0",
                        "--json",
                    ],
                )?;
            }
            connect(cli.port)?
        }
        None => {
            let mut link = link;
            for axis in 0..3 {
                match req(&mut link, &Request::Reference { axis, pos_nm: 0 })? {
                    Response::Ok => {}
                    other => return err("Reference", other),
                }
            }
            std::thread::sleep(Duration::from_millis(100));
            link
        }
    };
    let t = status(&mut link)?;
    if t.referenced != [true; 3] || t.faults.contains(Faults::NOT_REFERENCED) {
        return Err(format!(
            "after referencing: referenced {:?}, faults {:?}",
            t.referenced,
            t.faults.names().collect::<Vec<_>>()
        ));
    }
    Ok(link)
}

/// Stops renewing the injection and waits (up to 10 s of wall time) until
/// the board is back on its sensors; returns how long that took.
fn injection_lease(link: &mut LinkClient) -> Result<Duration, String> {
    let started = std::time::Instant::now();
    loop {
        let t = status(link)?;
        if !t.injecting {
            if t.pos_nm != [0; 3] {
                return Err(format!(
                    "the injection ended but the position is {:?}, not the encoders' 0",
                    t.pos_nm
                ));
            }
            return Ok(started.elapsed());
        }
        if started.elapsed() > Duration::from_secs(10) {
            return Err("the injection outlived its 2 s lease by 8 s".into());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The end-to-end test.
pub fn check(cli: &Cli) -> Result<(), String> {
    let t = HostTable::read(&cli.table)?;
    let o = match &cli.other {
        Some(p) => HostTable::read(p)?,
        None => HostTable::from_bytes(
            "build/tables.rs full".into(),
            crate::tables::full(0x0E2E).map_err(|e| e.to_string())?,
        )?,
    };
    if t.bytes == o.bytes {
        return Err("--table and --other must differ".into());
    }

    let mut link = connect(cli.port)?;
    let (active, _) = slots(&mut link)?;
    if active.is_some() {
        return Err(format!(
            "a fresh board should have no table, has {active:?}"
        ));
    }
    eprintln!("e2e: board up, no table");

    // 1. Garbage on the line: seeded random bytes (zeros included, so they
    // form many bad frames), then a frame cut in half. The next request
    // must be answered and the bad frames counted.
    let mut rng = Rng(0x6A2B_A6E0_0000_0001);
    let garbage: Vec<u8> = (0..4096).map(|_| rng.next_u64() as u8).collect();
    link.send_raw(&garbage).map_err(|e| e.to_string())?;
    let mut half = vec![0u8; trueaxis_protocol::MAX_FRAME_BYTES];
    let n = trueaxis_protocol::encode_frame(
        &trueaxis_protocol::Packet {
            seq: 7,
            msg: Request::Status,
        },
        &mut half,
    )
    .map_err(|e| e.to_string())?;
    link.send_raw(&half[..n / 2]).map_err(|e| e.to_string())?;
    let bad = match req(&mut link, &Request::Status)? {
        Response::Status(s) => s.rx_bad_frames,
        other => return err("Status after garbage", other),
    };
    if bad == 0 {
        return Err("garbage was sent but the board counted no bad frame".into());
    }
    eprintln!("e2e: garbage survived ({bad} bad frames dropped by the board)");

    // 2. `trueaxis upload` of the fitted table, as a user would run it.
    drop(link);
    let mut link = match &cli.trueaxis {
        Some(bin) => {
            upload_with_trueaxis(bin, cli.port, &cli.table)?;
            connect(cli.port)?
        }
        None => {
            eprintln!("e2e: NOTE no --trueaxis given: uploading with this program's own client");
            let mut link = connect(cli.port)?;
            upload_activate(&mut link, &t)?;
            link
        }
    };
    let (active, _) = slots(&mut link)?;
    match active {
        Some(info) if info.crc32 == t.crc32 && info.len as usize == t.bytes.len() => {}
        other => {
            return Err(format!(
                "after `trueaxis upload` the active table is {other:?}"
            ))
        }
    }
    eprintln!(
        "e2e: `trueaxis upload` activated {} ({:#010x})",
        t.name, t.crc32
    );

    // 3. A trajectory: the board's corrections equal the host's, bit for bit.
    let points = trajectory(&t, 600);
    let started = std::time::Instant::now();
    let flagged = compare_trajectory(&mut link, &t, &points)?;
    eprintln!(
        "e2e: {:.1} ms per injection round trip",
        started.elapsed().as_secs_f64() * 1e3 / points.len() as f64
    );
    if flagged == 0 {
        return Err("no trajectory point reached the envelope's edges".into());
    }
    eprintln!(
        "e2e: {} injected points, board == host (fixed point, bit exact; {flagged} flagged at the edges)",
        points.len()
    );
    // Not referenced yet: whatever is injected, the loop's output stays at
    // zero and says why. Then `trueaxis reference` for each axis.
    not_referenced_holds_zero(&mut link, &points[300])?;
    let mut link = reference_axes(cli, link)?;
    eprintln!("e2e: output held at zero until referenced; X, Y, Z referenced at 0");

    // The loop's output, after the slew limit, at points across the
    // trajectory (one beyond the travel, index 49).
    let settle: Vec<Injection> = [0, 49, 150, 300, 450, 599]
        .iter()
        .map(|&i| points[i])
        .collect();
    let (longest, overruns) = settle_output(&mut link, &t, &settle)?;
    eprintln!(
        "e2e: the loop's output corr_nm settled on the host's evaluation at {} points (longest {} ms; {overruns} emulation overruns cleared on the way)",
        settle.len(),
        longest.as_millis()
    );

    // The injection's lease: not renewed, it ends by itself (2 s counted
    // in the board's ticks).
    let lease = injection_lease(&mut link)?;
    eprintln!(
        "e2e: the injection ended {} ms after the last Inject (lease 2 s of board ticks)",
        lease.as_millis()
    );

    // 4. A cut upload: half of another table, then the connection drops.
    // The board must keep the old table active, and refuse to commit.
    let sent = upload_bytes(&mut link, &o.bytes, o.crc32, Some(o.bytes.len() / 2))?;
    drop(link);
    let mut link = connect(cli.port)?;
    let size = o.bytes.len() as u32;
    match req_when_quiet(&mut link, &Request::Commit)? {
        Response::Error(LinkError::Incomplete { received, size: s })
            if received == sent && s == size => {}
        other => return err("Commit of a cut upload", other),
    }
    let (active, _) = slots(&mut link)?;
    if active.map(|a| a.crc32) != Some(t.crc32) {
        return Err(format!("after a cut upload the active table is {active:?}"));
    }
    compare_trajectory(&mut link, &t, &points[..50])?;
    eprintln!("e2e: cut upload refused, old table still active and correcting");

    // 5. The other table for real, resuming the cut upload where it
    // stopped (the board kept the bytes across the dropped connection),
    // then a rollback to the first: the corrections follow each.
    match req(
        &mut link,
        &Request::UploadBegin {
            size,
            crc32: o.crc32,
        },
    )? {
        Response::UploadAck { next_offset } if next_offset == sent => {}
        other => return err("UploadBegin resuming the cut upload", other),
    }
    eprintln!("e2e: the cut upload resumes at byte {sent} of {size}");
    upload_activate(&mut link, &o)?;
    compare_trajectory(&mut link, &o, &points[..100])?;
    match &cli.trueaxis {
        Some(bin) => {
            drop(link);
            let port_arg = format!("tcp://127.0.0.1:{}", cli.port);
            run_trueaxis(bin, &["rollback", "--port", &port_arg, "--json"])?;
            link = connect(cli.port)?;
        }
        None => match req_when_quiet(&mut link, &Request::Rollback)? {
            Response::RolledBack(info) if info.len as usize == t.bytes.len() => {}
            other => return err("Rollback", other),
        },
    }
    let (active, standby) = slots(&mut link)?;
    if active.map(|a| a.crc32) != Some(t.crc32) || standby.is_some() {
        return Err(format!(
            "after the rollback the active table is {active:?}, the standby {standby:?}"
        ));
    }
    compare_trajectory(&mut link, &t, &points[..100])?;
    eprintln!("e2e: second table activated and rolled back, corrections follow each");

    // 6. Bytes that do not match the announced CRC: refused, the active
    // table stays. The flipped byte is in the second half of a fresh
    // upload of the other table.
    let mut flipped = o.bytes.clone();
    flipped[o.bytes.len() * 3 / 4] ^= 0x10;
    upload_bytes(&mut link, &flipped, o.crc32, None)?;
    match req_when_quiet(&mut link, &Request::Commit)? {
        Response::Error(LinkError::CrcMismatch | LinkError::InvalidTable) => {}
        other => return err("Commit of a corrupted upload", other),
    }
    compare_trajectory(&mut link, &t, &points[..50])?;
    eprintln!("e2e: corrupted upload refused, the active table still corrects");

    // 7. What a user does after a failed upload: run `trueaxis upload`
    // again. It must succeed.
    match &cli.trueaxis {
        Some(bin) => {
            drop(link);
            let path =
                std::env::temp_dir().join(format!("trueaxis-e2e-{}.bin", std::process::id()));
            std::fs::write(&path, &o.bytes)
                .map_err(|e| format!("write {}: {e}", path.display()))?;
            let r = upload_with_trueaxis(bin, cli.port, &path);
            let _ = std::fs::remove_file(&path);
            r.map_err(|e| format!("re-upload after a refused corrupted upload: {e}"))?;
            link = connect(cli.port)?;
        }
        None => {
            upload_activate(&mut link, &o)
                .map_err(|e| format!("re-upload after a refused corrupted upload: {e}"))?;
        }
    }
    compare_trajectory(&mut link, &o, &points[..100])?;
    eprintln!("e2e: re-upload after the refused one succeeded");

    match req(&mut link, &Request::EndInject)? {
        Response::Ok => {}
        other => return err("EndInject", other),
    }
    eprintln!("e2e: all checks passed");
    Ok(())
}

/// Uploads the demo's table and prints the board's corrections beside the
/// host's along a short path.
pub fn show(cli: &Cli) -> Result<(), String> {
    let t = HostTable::read(&cli.table)?;
    let mut link = connect(cli.port)?;
    match &cli.trueaxis {
        Some(bin) => {
            drop(link);
            upload_with_trueaxis(bin, cli.port, &cli.table)?;
            link = connect(cli.port)?;
        }
        None => {
            upload_activate(&mut link, &t)?;
        }
    }
    let points = trajectory(&t, 400);
    println!(
        "\n{:>10} {:>10} {:>10} | {:>27} | {:>27} | same",
        "x_mm", "y_mm", "z_mm", "board corr_nm (ex ey ez)", "host corr_nm (ex ey ez)"
    );
    let mut all_same = true;
    for inj in points.iter().step_by(40) {
        let c = match req(&mut link, &Request::Inject(*inj))? {
            Response::Correction(c) => c,
            other => return err("Inject", other),
        };
        let (want, _) = t.expect(inj);
        let same = c.model_corr_nm == want;
        all_same &= same;
        let mm = inj.pos_nm.map(|p| f64::from(p) / 1e6);
        println!(
            "{:>10.3} {:>10.3} {:>10.3} | {:>8} {:>8} {:>9} | {:>8} {:>8} {:>9} | {}",
            mm[0],
            mm[1],
            mm[2],
            c.model_corr_nm[0],
            c.model_corr_nm[1],
            c.model_corr_nm[2],
            want[0],
            want[1],
            want[2],
            if same { "yes" } else { "NO" }
        );
    }
    let _ = req(&mut link, &Request::EndInject);
    if all_same {
        println!("board (QEMU, fixed point) and host agree bit for bit");
        Ok(())
    } else {
        Err("the board's corrections differ from the host's".into())
    }
}
