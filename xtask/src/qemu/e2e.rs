//! The host against the board image in QEMU: the serial loopback check,
//! the end-to-end runner (`tests/e2e`: `trueaxis upload` over the emulated
//! serial port, the board's corrections against the host's), and the
//! demo's board step.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::thread;
use std::time::{Duration, Instant};

use super::build::{build_bin, target_dir, Profile};
use super::run::{describe, start_with_serial};
use crate::Result;

/// The end of `cargo xtask demo`: the board image in QEMU gets the table the
/// demo exported (`out/demo/table.bin`) through `trueaxis upload`, and its
/// corrections along a path are printed beside the host's.
pub fn demo_board(out: &Path) -> Result<()> {
    let table = out.join("table.bin");
    if !table.exists() {
        eprintln!(
            "\nxtask demo: {} does not exist, skipping the QEMU board stage",
            table.display()
        );
        return Ok(());
    }
    // The demo ran `cargo run --release -p trueaxis`, so this is a no-op build.
    let trueaxis = build_trueaxis(Profile::Release)?;
    let runner = build_e2e_runner()?;
    let board = build_bin("board", Profile::Release)?;
    eprintln!("\n== the board (STM32F405 in QEMU) with the demo's table ==");
    run_against_board(
        &board,
        &runner,
        &[
            "show",
            "--table",
            &table.to_string_lossy(),
            "--trueaxis",
            &trueaxis.to_string_lossy(),
        ],
    )
}

/// Builds the host tool and returns its binary.
pub(super) fn build_trueaxis(profile: Profile) -> Result<PathBuf> {
    let root = crate::root();
    let mut args = vec!["build", "--quiet", "-p", "trueaxis"];
    if profile == Profile::Release {
        args.push("--release");
    }
    crate::run(&root, "cargo", &args)?;
    let dir = match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) if Path::new(&d).is_absolute() => PathBuf::from(d),
        Some(d) => root.join(d),
        None => root.join("target"),
    };
    let bin = dir
        .join(profile.dir())
        .join(format!("trueaxis{}", std::env::consts::EXE_SUFFIX));
    if bin.exists() {
        Ok(bin)
    } else {
        Err(format!(
            "cargo built trueaxis but {} is missing",
            bin.display()
        ))
    }
}

/// Builds the end-to-end runner (tests/e2e, its own workspace, for the host)
/// into CARGO_TARGET_DIR or tests/target (git-ignored).
pub(super) fn build_e2e_runner() -> Result<PathBuf> {
    let root = crate::root();
    let dir = root.join("tests").join("e2e");
    let target = match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) if Path::new(&d).is_absolute() => PathBuf::from(d),
        Some(d) => dir.join(d),
        None => root.join("tests").join("target"),
    };
    let target_s = target.to_string_lossy().into_owned();
    crate::run(
        &dir,
        "cargo",
        &["build", "--quiet", "--release", "--target-dir", &target_s],
    )?;
    let bin = target
        .join("release")
        .join(format!("trueaxis-e2e{}", std::env::consts::EXE_SUFFIX));
    if bin.exists() {
        Ok(bin)
    } else {
        Err(format!(
            "cargo built trueaxis-e2e but {} is missing",
            bin.display()
        ))
    }
}

/// Starts `board` with USART1 on a TCP socket, runs `runner ARGS --port P`
/// against it, and requires the runner to pass and the board to be still
/// running afterwards (no fault, no panic); then stops the board.
pub(super) fn run_against_board(board: &Path, runner: &Path, args: &[&str]) -> Result<()> {
    let (mut image, stream, port) = start_with_serial(board)?;
    // Our connection only started the guest (wait=on); the runner connects
    // on its own once QEMU has seen this one go.
    drop(stream);
    let port_s = port.to_string();
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--port", &port_s]);
    eprintln!("\n$ {} {}", runner.display(), all.join(" "));
    let status = run_with_timeout(runner, &all, RUNNER_TIMEOUT);
    let board_alive = matches!(image.qemu.try_wait(), Ok(None));
    image.kill();
    let run = image.wait()?;
    let status = status?;
    if !board_alive {
        return Err(format!(
            "the board image stopped during the run ({})\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    if !status.success() {
        return Err(format!(
            "end-to-end run failed ({status}); board log:\n{}{}",
            run.log, run.stderr
        ));
    }
    Ok(())
}

/// How long the end-to-end runner may take (wall clock; it normally needs
/// a few seconds).
pub(super) const RUNNER_TIMEOUT: Duration = Duration::from_secs(180);

/// Runs `program args`, killing it (an error) when it outlives `limit`.
pub(super) fn run_with_timeout(
    program: &Path,
    args: &[&str],
    limit: Duration,
) -> Result<ExitStatus> {
    let mut child = Command::new(program)
        .args(args)
        .spawn()
        .map_err(|e| format!("cannot run {}: {e}", program.display()))?;
    let started = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok(status),
            Ok(None) if started.elapsed() > limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "{} hung: killed after {} s",
                    program.display(),
                    limit.as_secs()
                ));
            }
            Ok(None) => thread::sleep(Duration::from_millis(50)),
            Err(e) => return Err(format!("waiting for {}: {e}", program.display())),
        }
    }
}

/// The end-to-end test: a table from a real fit (simulate → fit → export
/// with the host tool, fixed seed) sent by `trueaxis upload` to the board
/// image in QEMU, then the scenarios of tests/e2e/src/check.rs.
pub(super) fn check_end_to_end() -> Result<()> {
    let trueaxis = build_trueaxis(Profile::Dev)?;
    let runner = build_e2e_runner()?;
    let board = build_bin("board", Profile::Release)?;

    let work = target_dir().join("qemu-e2e");
    std::fs::create_dir_all(&work).map_err(|e| format!("create {}: {e}", work.display()))?;
    let t = trueaxis.to_string_lossy().into_owned();
    let ws = |name: &str| work.join(name).to_string_lossy().into_owned();
    let (data, model, table) = (ws("data.csv"), ws("model.json"), ws("table.bin"));
    let quiet = |args: &[&str]| -> Result<()> {
        eprintln!("$ trueaxis {}", args.join(" "));
        let out = Command::new(&t)
            .args(args)
            .output()
            .map_err(|e| format!("cannot run {t}: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "`trueaxis {}` failed ({}):\n{}",
                args.join(" "),
                out.status,
                String::from_utf8_lossy(&out.stderr)
            ))
        }
    };
    quiet(&[
        "simulate", "--plan", "grid:100", "--seed", "3", "-o", &data, "--json",
    ])?;
    quiet(&["fit", &data, "--model", "cubic19", "-o", &model, "--json"])?;
    quiet(&["export", &model, "-o", &table, "--json"])?;

    run_against_board(
        &board,
        &runner,
        &["check", "--table", &table, "--trueaxis", &t],
    )?;
    eprintln!("qemu: end to end passed");
    Ok(())
}

/// The transport under the link: the loopback image must echo a seeded
/// pseudo-random stream (no 0xFF in it) byte for byte over QEMU's TCP
/// serial, after announcing itself with `0xFF 'R'`, then quit on `0xFF 'Q'`.
pub(super) fn check_loopback() -> Result<()> {
    let elf = build_bin("loopback", Profile::Dev)?;
    let (image, mut stream, port) = start_with_serial(&elf)?;
    eprintln!("\n$ qemu loopback (USART1 on 127.0.0.1:{port})");
    let mut state: u32 = 0x2545_f491; // fixed seed: the same stream every run
    let sent: Vec<u8> = (0..20_000)
        .map(|_| {
            // xorshift32; 0xFF is reserved for the quit sequence.
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % 255) as u8
        })
        .collect();
    let exchange = (|| -> std::io::Result<Vec<u8>> {
        stream.set_read_timeout(Some(Duration::from_secs(20)))?;
        // The image says when its USART is on (QEMU drops bytes before).
        let mut ready = [0u8; 2];
        stream.read_exact(&mut ready)?;
        if ready != [0xFF, b'R'] {
            return Err(std::io::Error::other(format!(
                "bad ready marker {ready:02x?}"
            )));
        }
        let mut writer = stream.try_clone()?;
        let data = sent.clone();
        let sender = thread::spawn(move || writer.write_all(&data));
        let mut got = vec![0u8; sent.len()];
        stream.read_exact(&mut got)?;
        sender
            .join()
            .map_err(|_| std::io::Error::other("sender thread panicked"))??;
        stream.write_all(&[0xFF, b'Q'])?;
        Ok(got)
    })();
    let got = match exchange {
        Ok(got) => got,
        Err(e) => return Err(format!("loopback exchange failed: {e}\n{}", image.abort())),
    };
    let run = image.wait()?;
    print!("{}", run.log);
    eprint!("{}", run.stderr);
    if let Some(i) = got.iter().zip(&sent).position(|(a, b)| a != b) {
        return Err(format!(
            "loopback: byte {i} came back as {:#04x}, sent {:#04x}",
            got[i], sent[i]
        ));
    }
    if !run.status.success() {
        return Err(format!("loopback image failed ({})", describe(&run.status)));
    }
    eprintln!("qemu: loopback echoed {} bytes exactly", sent.len());
    Ok(())
}
