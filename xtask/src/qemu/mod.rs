//! QEMU tasks: the firmware's application core and model-core on an emulated
//! STM32F405 (`qemu-system-arm -M netduinoplus2`), images from the
//! `trueaxis-qemu` crate (tests/, a member of the firmware workspace).
//!
//! Every image logs with defmt over semihosting and ends with a semihosting
//! exit, so QEMU's exit status is the verdict; `defmt-print` decodes the log.
//! `-icount shift=0` makes every run deterministic (1 instruction = 1 ns of
//! virtual time) and turns the STM32 timers into instruction counters, which
//! is what `bench-mcu` reads. A wall-clock timeout turns a hang into a
//! failure instead of a blocked CI job.
//!
//! The tasks are split by concern: `build` compiles the images (cargo's JSON
//! messages name the suite executables), `run` starts QEMU on an image and
//! collects its verdict, log and serial port, `budgets` runs the bench and
//! tick-bench images and checks their instruction counts against the
//! budgets and the cost estimate, and `e2e` drives the board image from the
//! host (serial loopback, `trueaxis upload`, the end-to-end runner, the
//! demo's board step).

mod budgets;
mod build;
mod e2e;
mod run;

pub use budgets::bench_mcu;
pub use e2e::demo_board;

use std::time::Duration;

use crate::Result;
use budgets::{check_bench, check_tickbench};
use build::{build_bin, build_suites, Profile};
use e2e::{check_end_to_end, check_loopback};
use run::{describe, run_image, QemuOpts};

/// The QEMU test crate's package name (tests/Cargo.toml).
const PACKAGE: &str = "trueaxis-qemu";

/// How long one image may run (wall clock) before it counts as hung. The
/// suites take well under a second each; QEMU's start-up dominates.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Runs every QEMU test suite (defmt-test on target, host ↔ board end to end).
pub fn test_all() -> Result<()> {
    let root = crate::root();
    if !root.join("tests").join("Cargo.toml").exists() {
        // Never a silent pass: a checkout without the QEMU suites is broken.
        return Err(format!(
            "the QEMU test crate {} is missing",
            root.join("tests").join("Cargo.toml").display()
        ));
    }

    // The harness first: a deliberately faulting image must fail with the
    // fault report, or every verdict below would be worthless.
    let fault = build_bin("fault", Profile::Dev)?;
    let run = run_image(&fault, &QemuOpts::default())?;
    if run.status.code() != Some(1) || !run.stderr.contains("HardFault") {
        return Err(format!(
            "the fault image should exit 1 with a HardFault report, got {} \n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    eprintln!("qemu: fault image exits 1 with a HardFault report, as it must");
    // And a stack overflow must stop the run (the stack sits below the
    // statics, tests/qemu.x, with the board's guard: trueaxis_stack_guard's
    // fault entry leaves the overflowed stack): exit 1 with the HardFault
    // handler's report of it, never a clean exit or a lockup.
    let overflow = build_bin("overflow", Profile::Dev)?;
    let run = run_image(&overflow, &QemuOpts::default())?;
    if run.status.code() != Some(1) || !run.stderr.contains("HardFault: stack overflow") {
        return Err(format!(
            "the overflow image should exit 1 with a stack-overflow report, got {}\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    eprintln!("qemu: stack overflow image faults with a report, as it must");
    // The board's stack guard end to end (issue 25): an overflow while a
    // table is on trial reaches the HardFault handler, which records it in
    // the boot record and resets; the next boot finds the record whole.
    let guard = build_bin("stack_guard", Profile::Dev)?;
    let run = run_image(&guard, &QemuOpts::default())?;
    if !run.status.success()
        || !run
            .log
            .contains("a stack overflow faulted: the boot record kept its table")
    {
        return Err(format!(
            "the stack_guard image should exit 0 after the overflow's reset, got {}\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    eprintln!("qemu: a stack overflow faults and the boot record survives it (stack_guard)");
    // The boot fallback through real resets (SYSRESETREQ; QEMU keeps RAM):
    // a table that faults during its trial is left for the previous one.
    let fallback = build_bin("fallback", Profile::Dev)?;
    let run = run_image(&fallback, &QemuOpts::default())?;
    if !run.status.success()
        || !run
            .log
            .contains("a crashing table was left by itself, twice")
    {
        return Err(format!(
            "the boot-fallback image should exit 0 after falling back twice, got {}\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    eprintln!("qemu: a table that faults on trial is left by the next boot (panic, HardFault)");

    // defmt-test suites, one image per suite.
    let suites = build_suites()?;
    if suites.is_empty() {
        return Err("no defmt-test suites were built".into());
    }
    let mut failed = Vec::new();
    for (name, elf) in &suites {
        eprintln!("\n$ qemu {name}");
        let run = run_image(elf, &QemuOpts::default())?;
        print!("{}", run.log);
        eprint!("{}", run.stderr);
        if !run.status.success() || !run.log.contains("all tests passed!") {
            eprintln!("qemu: suite `{name}` FAILED ({})", describe(&run.status));
            failed.push(name.clone());
        }
    }
    if !failed.is_empty() {
        return Err(format!("QEMU suites failed: {}", failed.join(", ")));
    }
    eprintln!("\nqemu: {} suites passed", suites.len());

    check_bench()?;
    check_tickbench()?;
    check_loopback()?;
    check_end_to_end()?;
    Ok(())
}
