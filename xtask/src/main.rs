//! `cargo xtask …` — the repository's tasks (CONTRACT.md §3).
//!
//! `setup` installs what a fresh machine lacks, `test` runs every check CI
//! runs, `demo` runs the main job end to end, `bench-mcu` counts instructions
//! under QEMU. Kept dependency-free on purpose: it is the first thing a fresh
//! clone compiles, and it must work before anything else is installed.

mod qemu;

use std::env;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// The target the MCU code is built for (STM32F405, Cortex-M4F).
pub const THUMB: &str = "thumbv7em-none-eabihf";

type Result<T> = std::result::Result<T, String>;

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let (cmd, rest) = match args.split_first() {
        Some((c, r)) => (c.as_str(), r),
        None => {
            eprintln!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    let result = match cmd {
        "setup" => setup(),
        "test" => test(rest),
        "demo" => demo(rest),
        "bench-mcu" => setup().and_then(|()| qemu::bench_mcu(rest)),
        "test-qemu" => setup().and_then(|()| qemu::test_all()),
        "-h" | "--help" | "help" => {
            println!("{USAGE}");
            Ok(())
        }
        other => {
            eprintln!("unknown task `{other}`\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

const USAGE: &str = "usage: cargo xtask <task>

tasks:
  setup       install what is missing (thumb target, qemu-system-arm, defmt-print)
  test        every test: fmt, clippy, host tests, no_std build, firmware, QEMU
  demo        the main job, end to end (writes into out/demo)
  test-qemu   only the QEMU suites and the end-to-end run (part of `test`)
  bench-mcu   instruction counts per model update under QEMU (-icount shift=0)";

/// The repository root (the parent of xtask/).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives one level below the root")
        .to_path_buf()
}

/// Runs a command in `dir`, echoing it, and fails with its exit status.
pub fn run(dir: &Path, program: &str, args: &[&str]) -> Result<()> {
    run_env(dir, program, args, &[])
}

/// Like [`run`], with extra environment variables.
pub fn run_env(dir: &Path, program: &str, args: &[&str], envs: &[(&str, &str)]) -> Result<()> {
    eprintln!("\n$ {program} {}", args.join(" "));
    let status = Command::new(program)
        .args(args)
        .current_dir(dir)
        .envs(envs.iter().copied())
        .status()
        .map_err(|e| format!("cannot start `{program}`: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{program} {}` failed ({status})", args.join(" ")))
    }
}

/// True when `program --version` (or `-V`) runs.
fn have(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

/// Installs what is missing. Each step checks first, so a second run is fast.
pub fn setup() -> Result<()> {
    let root = root();
    // rust-toolchain.toml names the target, but older rustups only honour it
    // on the first toolchain install; adding it explicitly is idempotent.
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .current_dir(&root)
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !installed.lines().any(|l| l.trim() == THUMB) {
        run(&root, "rustup", &["target", "add", THUMB])?;
    }
    if !have("qemu-system-arm") {
        if !is_root() {
            return Err("qemu-system-arm is missing and this is not root: \
                 run `sudo apt-get install --no-install-recommends qemu-system-arm`"
                .into());
        }
        // Debian bookworm's qemu-system-arm (7.2) emulates the STM32F405
        // (netduinoplus2); --no-install-recommends keeps the install small.
        run(&root, "apt-get", &["update", "-q"])?;
        run_env(
            &root,
            "apt-get",
            &[
                "install",
                "-y",
                "-q",
                "--no-install-recommends",
                "qemu-system-arm",
            ],
            &[("DEBIAN_FRONTEND", "noninteractive")],
        )?;
    }
    if !have("defmt-print") {
        run(&root, "cargo", &["install", "defmt-print", "--locked"])?;
    }
    Ok(())
}

/// Every check CI makes, in order of cost so a cheap failure shows first.
fn test(args: &[String]) -> Result<()> {
    let quick = args.iter().any(|a| a == "--no-qemu");
    setup()?;
    let root = root();
    let fw = root.join("firmware");

    // Formatting and lints, host workspace and firmware workspace.
    run(&root, "cargo", &["fmt", "--all", "--check"])?;
    run(&fw, "cargo", &["fmt", "--all", "--check"])?;
    run(
        &root,
        "cargo",
        &[
            "clippy",
            "--workspace",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ],
    )?;

    // Host tests (model-core, host-tool, xtask).
    run(&root, "cargo", &["test", "--workspace"])?;

    // model-core must stay no_std: build and lint it for the MCU.
    run(
        &root,
        "cargo",
        &[
            "clippy",
            "-p",
            "model-core",
            "--target",
            THUMB,
            "--no-default-features",
            "--",
            "-D",
            "warnings",
        ],
    )?;

    // Firmware workspace: the hardware-agnostic core is tested on the host,
    // then everything is built and linted for the MCU.
    let host = host_triple()?;
    run(
        &fw,
        "cargo",
        &["test", "-p", "trueaxis-app", "--target", &host],
    )?;
    run(
        &fw,
        "cargo",
        &[
            "clippy",
            "--workspace",
            "--target",
            THUMB,
            "--",
            "-D",
            "warnings",
        ],
    )?;
    run(
        &fw,
        "cargo",
        &[
            "build",
            "--release",
            "-p",
            "trueaxis-board",
            "--target",
            THUMB,
        ],
    )?;

    if !quick {
        qemu::test_all()?;
    }
    eprintln!("\nxtask test: all checks passed");
    Ok(())
}

/// The host's target triple, from `rustc -vV`.
pub fn host_triple() -> Result<String> {
    let out = Command::new("rustc")
        .arg("-vV")
        .current_dir(root())
        .output()
        .map_err(|e| format!("cannot run rustc: {e}"))?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_owned))
        .ok_or_else(|| "rustc -vV printed no host line".into())
}

/// The main job end to end: the host tool's guided demo, then (when the QEMU
/// image exists) the board image running the fitted table.
fn demo(args: &[String]) -> Result<()> {
    setup()?;
    let root = root();
    let out = root.join("out").join("demo");
    std::fs::create_dir_all(&out).map_err(|e| format!("create {}: {e}", out.display()))?;
    let out_s = out.to_string_lossy().into_owned();
    let mut cargo_args = vec![
        "run",
        "--release",
        "--quiet",
        "-p",
        "trueaxis",
        "--",
        "demo",
        "--out",
        &out_s,
    ];
    cargo_args.extend(args.iter().map(String::as_str));
    run(&root, "cargo", &cargo_args)?;
    qemu::demo_board(&out)?;
    Ok(())
}
