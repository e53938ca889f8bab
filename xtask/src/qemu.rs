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

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use crate::{Result, THUMB};

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
    // statics, tests/qemu.x): QEMU ends in a lockup, never a clean exit.
    let overflow = build_bin("overflow", Profile::Dev)?;
    let run = run_image(&overflow, &QemuOpts::default())?;
    if run.status.success() || !run.stderr.contains("Lockup") {
        return Err(format!(
            "the overflow image should lock the core up, got {}\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    eprintln!("qemu: stack overflow image stops with a lockup, as it must");

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

/// The instruction budgets per 3-axis model update (issue 6): the bench
/// names CONTRACT.md §3 requires and the most instructions each may take.
/// `cargo xtask bench-mcu` prints them beside the counts; `cargo xtask
/// test` fails when a bench is missing or its worst call exceeds its budget.
pub const BUDGETS: [(&str, u64); 4] = [
    ("cubic19_f32", 300),
    ("cubic19_fixed", 600),
    ("full_f32", 500),
    ("nn_3x16x3_f32", 1000),
];

/// Builds and runs the bench image (firmware release profile, `-icount
/// shift=0`) and returns its figures: the one code path of `bench-mcu` and
/// of the check in `cargo xtask test`. With `calibrate`, the image also
/// evaluates the cost estimate's calibration set (the QEMU crate's
/// `calibrate` feature: build/cost_tables.rs, `calibration`).
fn run_bench(calibrate: bool) -> Result<Vec<BenchResult>> {
    let features: &[&str] = if calibrate { &["calibrate"] } else { &[] };
    let elf = build_package_bin(PACKAGE, "bench", Profile::Release, features)?;
    eprintln!("\n$ qemu bench (-icount shift=0)");
    let run = run_image(&elf, &QemuOpts::default())?;
    if !run.status.success() {
        return Err(format!(
            "the bench image failed ({})\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    parse_bench_log(&run.log)
}

/// Every name of [`BUDGETS`] measured, and no worst call above its budget;
/// the error lists every miss.
fn check_budgets(results: &[BenchResult]) -> Result<()> {
    let mut misses = Vec::new();
    for (name, budget) in BUDGETS {
        match results.iter().find(|r| r.name == name) {
            None => misses.push(format!("{name}: not measured by the bench image")),
            Some(r) if r.max > budget => misses.push(format!(
                "{name}: {} instructions per update (worst call), budget {budget}",
                r.max
            )),
            Some(_) => {}
        }
    }
    if misses.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "instruction budgets exceeded (cargo xtask bench-mcu):\n  {}",
            misses.join("\n  ")
        ))
    }
}

/// The cost estimate must bound every count and not by too much: for every
/// bench, worst call ≤ estimate ≤ 1.5 × worst call. The firmware refuses
/// tables by this estimate, so an estimate below a count would let a table
/// too slow for the loop through, and one far above would refuse tables
/// that fit.
fn check_estimates(results: &[BenchResult]) -> Result<()> {
    let mut misses = Vec::new();
    for r in results {
        match r.est {
            None => misses.push(format!("{}: no estimate", r.name)),
            Some(est) if est < r.max => misses.push(format!(
                "{}: estimate {est} below the measured {} instructions",
                r.name, r.max
            )),
            Some(est) if 2 * est > 3 * r.max => misses.push(format!(
                "{}: estimate {est} above 1.5 × the measured {} instructions",
                r.name, r.max
            )),
            Some(_) => {}
        }
    }
    if misses.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "model-core's cost estimate (model-core/src/cost.rs) is off:\n  {}",
            misses.join("\n  ")
        ))
    }
}

/// The budget of a bench, if it has one.
fn budget_of(name: &str) -> Option<u64> {
    BUDGETS.iter().find(|(n, _)| *n == name).map(|&(_, b)| b)
}

/// The bench image in `cargo xtask test`: the budgets must hold.
fn check_bench() -> Result<()> {
    let results = run_bench(false)?;
    print_bench_table(&results);
    check_budgets(&results)?;
    eprintln!("qemu: instruction budgets met ({} benches)", BUDGETS.len());
    check_estimates(&results)?;
    let worst = results
        .iter()
        .filter_map(|r| Some(r.est? as f64 / r.max as f64))
        .fold(0.0f64, f64::max);
    eprintln!(
        "qemu: cost estimate within [1, 1.5] × the count for all {} benches (largest ratio {worst:.2})",
        results.len()
    );
    Ok(())
}

/// Instruction counts per model update (CONTRACT.md §3): one JSON line per
/// model kind on stdout, `{"bench": "cubic19_f32", "instructions_per_update":
/// N, "outputs": 3}`, a human summary with the budgets and the loop rate
/// each allows at 168 MHz on stderr.
///
/// With `--calibrate`, the cost estimate against the counts instead
/// ([`calibrate`]).
pub fn bench_mcu(args: &[String]) -> Result<()> {
    match args {
        [] => {}
        [a] if a == "--calibrate" => return calibrate(),
        [a, ..] => {
            return Err(format!(
                "bench-mcu takes no argument but --calibrate (got `{a}`)"
            ))
        }
    }
    let results = run_bench(false)?;
    for r in &results {
        println!(
            "{{\"bench\": \"{}\", \"instructions_per_update\": {}, \"outputs\": 3}}",
            r.name, r.per_update
        );
    }
    print_bench_table(&results);
    Ok(())
}

/// `cargo xtask bench-mcu --calibrate`: the bench image with the cost
/// estimate's calibration set (the bench tables and 191 seeded random
/// tables the board can load, build/cost_tables.rs) — on stdout, per table
/// the worst call and model-core's estimate of `eval_f32` and `eval_fixed`
/// and their ratio, then the smallest and largest ratio (the figures
/// BENCHMARKS.md "Static cost estimate" quotes). Fails, like `cargo xtask
/// test` on the bench tables, when an estimate is below its count or above
/// 1.5 × it.
fn calibrate() -> Result<()> {
    let results = run_bench(true)?;
    let rows = estimate_rows(&results)?;
    println!(
        "{:<22} {:>7} {:>8} {:>6} {:>7} {:>8} {:>6}",
        "table", "f32", "estimate", "ratio", "fixed", "estimate", "ratio"
    );
    for r in &rows {
        println!(
            "{:<22} {:>7} {:>8} {:>6.3} {:>7} {:>8} {:>6.3}",
            r.table,
            r.f32.0,
            r.f32.1,
            ratio(r.f32),
            r.fixed.0,
            r.fixed.1,
            ratio(r.fixed)
        );
    }
    let random: Vec<&EstimateRow> = rows
        .iter()
        .filter(|r| r.table.starts_with("cal_"))
        .collect();
    for (what, set) in [("all", rows.iter().collect::<Vec<_>>()), ("random", random)] {
        let (f32_lo, f32_hi) = ratio_range(set.iter().map(|r| r.f32));
        let (fx_lo, fx_hi) = ratio_range(set.iter().map(|r| r.fixed));
        println!(
            "estimate / count, {what} {} tables: fixed {fx_lo:.2}–{fx_hi:.2}, f32 {f32_lo:.2}–{f32_hi:.2}",
            set.len()
        );
    }
    check_estimates(&results)
}

/// One table's worst call and estimate (count, estimate) on each path.
#[derive(Debug, PartialEq)]
struct EstimateRow {
    table: String,
    f32: (u64, u64),
    fixed: (u64, u64),
}

/// Pairs the `<table>_f32` and `<table>_fixed` benches.
fn estimate_rows(results: &[BenchResult]) -> Result<Vec<EstimateRow>> {
    let get = |name: String| -> Result<(u64, u64)> {
        let r = results
            .iter()
            .find(|r| r.name == name)
            .ok_or_else(|| format!("no bench {name}"))?;
        Ok((r.max, r.est.ok_or_else(|| format!("{name}: no estimate"))?))
    };
    results
        .iter()
        .filter_map(|r| r.name.strip_suffix("_f32"))
        .map(|t| {
            Ok(EstimateRow {
                table: t.to_owned(),
                f32: get(format!("{t}_f32"))?,
                fixed: get(format!("{t}_fixed"))?,
            })
        })
        .collect()
}

/// estimate / count.
fn ratio((count, est): (u64, u64)) -> f64 {
    est as f64 / count as f64
}

/// The smallest and largest [`ratio`].
fn ratio_range(pairs: impl Iterator<Item = (u64, u64)>) -> (f64, f64) {
    pairs
        .map(ratio)
        .fold((f64::INFINITY, 0.0), |(lo, hi), r| (lo.min(r), hi.max(r)))
}

/// The human summary of the bench figures, on stderr.
fn print_bench_table(results: &[BenchResult]) {
    eprintln!(
        "\n{:<24} {:>12} {:>12} {:>8} {:>9} {:>10}",
        "model", "instr/update", "min..max", "budget", "estimate", "kHz@168MHz"
    );
    for r in results {
        let budget = match budget_of(&r.name) {
            Some(b) if r.max <= b => format!("{b} ok"),
            Some(b) => format!("{b} OVER"),
            None => "-".into(),
        };
        eprintln!(
            "{:<24} {:>12} {:>12} {:>8} {:>9} {:>10.0}",
            r.name,
            r.per_update,
            format!("{}..{}", r.min, r.max),
            budget,
            r.est.map_or("-".into(), |e| e.to_string()),
            168_000.0 / r.per_update as f64
        );
    }
    eprintln!("(instructions, not cycles: a loop rate is an upper bound on the real chip)");
}

/// The loop budget of the board as the tickbench image prints it (model-core's
/// `board` constants: defined once, read here from the image).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct TickBudget {
    /// One period at one instruction per cycle (8 400 at 20 kHz, 168 MHz).
    period: u64,
    /// What a tick may take: the period less the margin kept for what
    /// QEMU's counts do not see.
    tick: u64,
    /// The engine's own share of a tick, at most.
    engine: u64,
    /// The most a table's estimated evaluation may take to be accepted.
    model: u64,
}

/// One case of the tickbench image.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TickResult {
    name: String,
    min: u64,
    mean: u64,
    max: u64,
    /// model-core's estimate of the table's fixed-point evaluation (0
    /// without a table).
    est_fixed: u64,
}

/// Reads tickbench's `BUDGET …` line and `TICK name min=… mean=… max=…
/// faults=… est_fixed=…` lines.
fn parse_tick_log(log: &str) -> Result<(TickBudget, Vec<TickResult>)> {
    let field = |line: &str, key: &str| -> Result<u64> {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
            .ok_or_else(|| format!("tickbench line without {key}: {line}"))?
            .parse::<u64>()
            .map_err(|e| format!("tickbench {key}: {e} in {line}"))
    };
    let mut budget = None;
    let mut out = Vec::new();
    for line in log.lines() {
        if let Some(rest) = line.strip_prefix("BUDGET ") {
            budget = Some(TickBudget {
                period: field(rest, "period")?,
                tick: field(rest, "tick")?,
                engine: field(rest, "engine")?,
                model: field(rest, "model")?,
            });
        } else if let Some(rest) = line.strip_prefix("TICK ") {
            let name = rest.split_whitespace().next().unwrap_or_default();
            out.push(TickResult {
                name: name.to_owned(),
                min: field(rest, "min")?,
                mean: field(rest, "mean")?,
                max: field(rest, "max")?,
                est_fixed: field(rest, "est_fixed")?,
            });
        }
    }
    let budget = budget.ok_or_else(|| format!("tickbench printed no BUDGET line:\n{log}"))?;
    if out.is_empty() {
        return Err(format!("tickbench printed no TICK line:\n{log}"));
    }
    Ok((budget, out))
}

/// Whether the board accepts a table of this estimate (its admission at
/// commit: `est ≤ budget.model`).
fn accepted(budget: &TickBudget, est_fixed: u64) -> bool {
    est_fixed <= budget.model
}

/// The loop-rate claim: every tick of a table the board accepts fits the
/// tick budget (the 20 kHz period less its margin), the engine without a
/// table stays within its share, and every tick is at most the engine's
/// share plus the table's estimate (what the admission assumes). A table
/// the board refuses (its estimate over the budget) is reported, not
/// failed; `all_kinds` is one.
fn check_ticks(budget: &TickBudget, ticks: &[TickResult]) -> Result<Vec<String>> {
    let mut misses = Vec::new();
    let mut notes = Vec::new();
    if budget.tick > budget.period || budget.engine + budget.model != budget.tick {
        misses.push(format!("inconsistent budget {budget:?}"));
    }
    for t in ticks {
        let bound = budget.engine + t.est_fixed;
        if t.max > bound {
            misses.push(format!(
                "{}: worst tick {} > engine share {} + estimate {} = {bound}",
                t.name, t.max, budget.engine, t.est_fixed
            ));
        }
        if t.name == "no_table" {
            continue;
        }
        if accepted(budget, t.est_fixed) {
            if t.max > budget.tick {
                misses.push(format!(
                    "{}: worst tick {} instructions > the tick budget {} ({} a period, less the margin)",
                    t.name, t.max, budget.tick, budget.period
                ));
            }
        } else {
            notes.push(format!(
                "{}: refused by the board (estimate {} > {}); its tick takes {} instructions, {:.0} kHz at most",
                t.name,
                t.est_fixed,
                budget.model,
                t.max,
                168_000.0 / t.max as f64
            ));
        }
    }
    if !ticks.iter().any(|t| t.name == "no_table") {
        misses.push("no `no_table` case".into());
    }
    if misses.is_empty() {
        Ok(notes)
    } else {
        Err(format!(
            "correction tick over budget (firmware/tickbench):\n  {}",
            misses.join("\n  ")
        ))
    }
}

/// firmware/tickbench under QEMU: instructions of whole engine ticks.
fn check_tickbench() -> Result<()> {
    let elf = build_package_bin("trueaxis-tickbench", "tickbench", Profile::Release, &[])?;
    eprintln!("\n$ qemu tickbench (-icount shift=0)");
    let run = run_image(
        &elf,
        &QemuOpts {
            plain: true,
            ..QemuOpts::default()
        },
    )?;
    if !run.status.success() {
        return Err(format!(
            "the tickbench image failed ({})\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    let (budget, ticks) = parse_tick_log(&run.log)?;
    eprintln!(
        "\n{:<16} {:>22} {:>10} {:>9}",
        "tick", "min / mean / max", "estimate", "accepted"
    );
    for t in &ticks {
        eprintln!(
            "{:<16} {:>22} {:>10} {:>9}",
            t.name,
            format!("{} / {} / {}", t.min, t.mean, t.max),
            budget.engine + t.est_fixed,
            if t.name == "no_table" {
                "-"
            } else if accepted(&budget, t.est_fixed) {
                "yes"
            } else {
                "no"
            }
        );
    }
    eprintln!(
        "(budget: {} instructions per tick = the {}-instruction period less the margin; estimate = engine {} + the table's)",
        budget.tick, budget.period, budget.engine
    );
    for n in check_ticks(&budget, &ticks)? {
        eprintln!("qemu: note: {n}");
    }
    eprintln!("qemu: every accepted table ticks within the budget");
    Ok(())
}

/// One model kind's figures from the bench image.
#[derive(Debug, Clone, PartialEq, Eq)]
struct BenchResult {
    name: String,
    /// Mean instructions per call, rounded to nearest.
    per_update: u64,
    min: u64,
    max: u64,
    /// model-core's static estimate of the same evaluation (`est=`).
    est: Option<u64>,
}

/// Reads the bench image's `BENCH <name> total=T calls=C min=A max=B` lines.
fn parse_bench_log(log: &str) -> Result<Vec<BenchResult>> {
    let mut out = Vec::new();
    for line in log.lines() {
        let Some(rest) = line.split("BENCH ").nth(1) else {
            continue;
        };
        let mut words = rest.split_whitespace();
        let name = words
            .next()
            .ok_or_else(|| format!("bad BENCH line: {line}"))?;
        let field = |key: &str| -> Result<u64> {
            rest.split_whitespace()
                .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
                .ok_or_else(|| format!("BENCH line without {key}: {line}"))?
                .parse::<u64>()
                .map_err(|e| format!("BENCH {key}: {e} in {line}"))
        };
        let (total, calls) = (field("total")?, field("calls")?);
        if calls == 0 {
            return Err(format!("BENCH line with no calls: {line}"));
        }
        out.push(BenchResult {
            name: name.to_owned(),
            per_update: (total + calls / 2) / calls,
            min: field("min")?,
            max: field("max")?,
            est: field("est").ok(),
        });
    }
    if out.is_empty() {
        return Err(format!("the bench image printed no BENCH line:\n{log}"));
    }
    Ok(out)
}

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
fn build_trueaxis(profile: Profile) -> Result<PathBuf> {
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
fn build_e2e_runner() -> Result<PathBuf> {
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
fn run_against_board(board: &Path, runner: &Path, args: &[&str]) -> Result<()> {
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
const RUNNER_TIMEOUT: Duration = Duration::from_secs(180);

/// Runs `program args`, killing it (an error) when it outlives `limit`.
fn run_with_timeout(program: &Path, args: &[&str], limit: Duration) -> Result<ExitStatus> {
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
fn check_end_to_end() -> Result<()> {
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

/// Cargo profile an image is built with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Profile {
    /// opt-level "s" with overflow checks: the test suites.
    Dev,
    /// The firmware's release profile (fat LTO, opt-level 3): what is
    /// benchmarked and what the board would run.
    Release,
}

impl Profile {
    fn dir(self) -> &'static str {
        match self {
            Profile::Dev => "debug",
            Profile::Release => "release",
        }
    }
}

/// The firmware workspace, where cargo must run so that its
/// .cargo/config.toml (thumb target, DEFMT_LOG) applies.
fn firmware_dir() -> PathBuf {
    crate::root().join("firmware")
}

/// The target directory cargo uses (honours CARGO_TARGET_DIR).
fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) => {
            let d = PathBuf::from(d);
            if d.is_absolute() {
                d
            } else {
                firmware_dir().join(d)
            }
        }
        None => firmware_dir().join("target"),
    }
}

/// Builds one binary of the QEMU crate and returns the ELF's path.
fn build_bin(bin: &str, profile: Profile) -> Result<PathBuf> {
    build_package_bin(PACKAGE, bin, profile, &[])
}

/// Builds binary `bin` of firmware-workspace package `package` with
/// `features`. (Cargo keeps each feature set's build apart and copies the
/// one just built to the ELF's path, so switching sets rebuilds nothing.)
fn build_package_bin(
    package: &str,
    bin: &str,
    profile: Profile,
    features: &[&str],
) -> Result<PathBuf> {
    let mut args = vec!["build", "-p", package, "--target", THUMB, "--bin", bin];
    if profile == Profile::Release {
        args.push("--release");
    }
    let features = features.join(",");
    if !features.is_empty() {
        args.extend(["--features", &features]);
    }
    crate::run(&firmware_dir(), "cargo", &args)?;
    let elf = target_dir().join(THUMB).join(profile.dir()).join(bin);
    if elf.exists() {
        Ok(elf)
    } else {
        Err(format!(
            "cargo built `{bin}` but {} is missing",
            elf.display()
        ))
    }
}

/// Builds the defmt-test suites and returns (suite name, ELF) pairs, read
/// from cargo's JSON messages (the test executables carry a hash).
fn build_suites() -> Result<Vec<(String, PathBuf)>> {
    let args = [
        "test",
        "-p",
        PACKAGE,
        "--target",
        THUMB,
        "--no-run",
        "--message-format=json-render-diagnostics",
    ];
    eprintln!("\n$ cargo {}", args.join(" "));
    let out = Command::new("cargo")
        .args(args)
        .current_dir(firmware_dir())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!("building the QEMU suites failed ({})", out.status));
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let mut suites = Vec::new();
    for line in stdout.lines() {
        if !line.contains(r#""reason":"compiler-artifact""#) || !line.contains(r#""test":true"#) {
            continue;
        }
        let (Some(name), Some(exe)) = (
            line.find(r#""target":{"#)
                .and_then(|i| json_str(&line[i..], "name")),
            json_str(line, "executable"),
        ) else {
            continue;
        };
        suites.push((name, PathBuf::from(exe)));
    }
    suites.sort();
    Ok(suites)
}

/// The string value of the first `"key":"…"` in a JSON text (cargo's
/// messages; paths with escaped quotes or backslashes are not expected).
fn json_str(json: &str, key: &str) -> Option<String> {
    let pat = format!("\"{key}\":\"");
    let start = json.find(&pat)? + pat.len();
    let len = json[start..].find('"')?;
    Some(json[start..start + len].replace("\\\\", "\\"))
}

/// Extra QEMU settings of one run.
#[derive(Debug, Default, Clone)]
struct QemuOpts {
    /// `-serial` backend (USART1); `null` when not given.
    serial: Option<String>,
    /// Wall-clock limit; [`TIMEOUT`] when not given.
    timeout: Option<Duration>,
    /// The image prints plain text on semihosting stdout (tickbench), not
    /// defmt: no `defmt-print`.
    plain: bool,
}

/// What one image printed and how it ended.
#[derive(Debug)]
struct ImageRun {
    status: ExitStatus,
    /// The decoded defmt log (defmt-print's output).
    log: String,
    /// QEMU's stderr: the HardFault report, QEMU's own errors.
    stderr: String,
}

/// Runs `elf` in QEMU with its semihosting output piped through
/// `defmt-print`, and waits for it to exit (or kills it at the timeout).
fn run_image(elf: &Path, opts: &QemuOpts) -> Result<ImageRun> {
    start_image(elf, opts)?.wait()
}

/// An image running in QEMU, its log being decoded in the background.
struct RunningImage {
    elf: PathBuf,
    qemu: std::process::Child,
    printer: Option<std::process::Child>,
    log_reader: thread::JoinHandle<String>,
    err_reader: thread::JoinHandle<String>,
    started: Instant,
    limit: Duration,
}

/// Starts `elf` in QEMU (see [`run_image`]); the caller talks to it (TCP
/// serial) and then calls [`RunningImage::wait`].
fn start_image(elf: &Path, opts: &QemuOpts) -> Result<RunningImage> {
    let elf_s = elf.to_string_lossy().into_owned();
    let serial = opts.serial.clone().unwrap_or_else(|| "null".into());
    let mut qemu = Command::new("qemu-system-arm")
        .args([
            "-M",
            "netduinoplus2",
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            &serial,
            "-semihosting-config",
            "enable=on,target=native",
            "-icount",
            "shift=0",
            "-kernel",
            &elf_s,
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm (cargo xtask setup): {e}"))?;
    let mut qemu_out = qemu.stdout.take().expect("stdout is piped");
    let mut qemu_err = qemu.stderr.take().expect("stderr is piped");
    let err_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = qemu_err.read_to_string(&mut s);
        s
    });
    if opts.plain {
        let log_reader = thread::spawn(move || {
            let mut s = String::new();
            let _ = qemu_out.read_to_string(&mut s);
            s
        });
        return Ok(RunningImage {
            elf: elf.to_path_buf(),
            qemu,
            printer: None,
            log_reader,
            err_reader,
            started: Instant::now(),
            limit: opts.timeout.unwrap_or(TIMEOUT),
        });
    }
    let printer = Command::new("defmt-print")
        .args(["-e", &elf_s, "stdin"])
        .stdin(Stdio::from(qemu_out))
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn();
    let mut printer = match printer {
        Ok(p) => p,
        Err(e) => {
            let _ = qemu.kill();
            let _ = qemu.wait();
            return Err(format!("cannot start defmt-print (cargo xtask setup): {e}"));
        }
    };
    let mut printer_out = printer.stdout.take().expect("stdout is piped");
    let log_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = printer_out.read_to_string(&mut s);
        s
    });
    Ok(RunningImage {
        elf: elf.to_path_buf(),
        qemu,
        printer: Some(printer),
        log_reader,
        err_reader,
        started: Instant::now(),
        limit: opts.timeout.unwrap_or(TIMEOUT),
    })
}

impl RunningImage {
    /// Waits for QEMU to exit; kills it when the time limit (counted from
    /// the start) runs out, which is an error.
    fn wait(mut self) -> Result<ImageRun> {
        let status = loop {
            match self.qemu.try_wait() {
                Ok(Some(status)) => break Some(status),
                Ok(None) if self.started.elapsed() > self.limit => break None,
                Ok(None) => thread::sleep(Duration::from_millis(20)),
                Err(e) => {
                    self.kill();
                    return Err(format!("waiting for qemu: {e}"));
                }
            }
        };
        if status.is_none() {
            self.kill();
        }
        // QEMU's exit closes the pipe, so defmt-print ends by itself.
        if let Some(p) = self.printer.as_mut() {
            let _ = p.wait();
        }
        let log = self.log_reader.join().unwrap_or_default();
        let stderr = self.err_reader.join().unwrap_or_default();
        match status {
            Some(status) => Ok(ImageRun {
                status,
                log,
                stderr,
            }),
            None => Err(format!(
                "{} hung: killed after {} s\n{log}{stderr}",
                self.elf.display(),
                self.limit.as_secs()
            )),
        }
    }

    /// Stops QEMU now (a failed exchange); the log is still collected.
    fn kill(&mut self) {
        let _ = self.qemu.kill();
        let _ = self.qemu.wait();
    }

    /// Stops QEMU and returns what it logged, for an error message.
    fn abort(mut self) -> String {
        self.kill();
        self.wait()
            .map(|r| format!("{}{}", r.log, r.stderr))
            .unwrap_or_else(|e| e)
    }
}

/// A free TCP port on 127.0.0.1 for QEMU's serial server. (Another process
/// could take it between here and QEMU's bind; QEMU then fails to start
/// and the caller retries with a new port.)
fn free_port() -> Result<u16> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(|e| format!("bind 127.0.0.1:0: {e}"))?;
    l.local_addr()
        .map(|a| a.port())
        .map_err(|e| format!("local_addr: {e}"))
}

/// Starts `elf` with USART1 on a TCP server socket and connects to it.
fn start_with_serial(elf: &Path) -> Result<(RunningImage, TcpStream, u16)> {
    let mut last_err = String::new();
    for _attempt in 0..3 {
        let port = free_port()?;
        let opts = QemuOpts {
            serial: Some(format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on")),
            ..QemuOpts::default()
        };
        let mut image = start_image(elf, &opts)?;
        // QEMU listens as soon as it has parsed its options and, with
        // wait=on, starts the guest only once we are connected: nothing the
        // image sends at boot can be lost.
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(stream) => return Ok((image, stream, port)),
                Err(e) => {
                    if let Ok(Some(status)) = image.qemu.try_wait() {
                        last_err = format!("qemu exited ({status}) before listening on {port}");
                        let _ = image.abort();
                        break;
                    }
                    if Instant::now() > deadline {
                        last_err = format!("cannot connect to QEMU's serial on {port}: {e}");
                        let _ = image.abort();
                        break;
                    }
                    thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }
    Err(last_err)
}

/// The transport under the link: the loopback image must echo a seeded
/// pseudo-random stream (no 0xFF in it) byte for byte over QEMU's TCP
/// serial, after announcing itself with `0xFF 'R'`, then quit on `0xFF 'Q'`.
fn check_loopback() -> Result<()> {
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

fn describe(status: &ExitStatus) -> String {
    match status.code() {
        Some(c) => format!("exit status {c}"),
        None => "killed by a signal".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_lines_become_means() {
        let log = "INFO  BENCH cubic19_f32 total=42433 calls=64 min=663 max=664\n\
                   INFO  unrelated\n\
                   INFO  BENCH nn_fixed total=10 calls=4 min=2 max=3\n";
        let r = parse_bench_log(log).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].name, "cubic19_f32");
        assert_eq!(r[0].per_update, 663); // 663.02 rounds down
        assert_eq!((r[0].min, r[0].max), (663, 664));
        assert_eq!(r[1].per_update, 3); // 2.5 rounds half up
        assert!(parse_bench_log("INFO  BENCH x total=1 calls=0 min=0 max=0").is_err());
        assert!(parse_bench_log("INFO  nothing").is_err());
    }

    #[test]
    fn budgets_fail_on_a_miss_or_an_overrun() {
        let r = |name: &str, max: u64| BenchResult {
            name: name.into(),
            per_update: max,
            min: max,
            max,
            est: Some(max),
        };
        let all: Vec<BenchResult> = BUDGETS.iter().map(|&(n, b)| r(n, b)).collect();
        assert!(check_budgets(&all).is_ok(), "at the budget is within it");
        let mut over = all.clone();
        over[2].max = BUDGETS[2].1 + 1;
        let e = check_budgets(&over).unwrap_err();
        assert!(e.contains("full_f32") && e.contains("budget 500"), "{e}");
        let e = check_budgets(&all[1..]).unwrap_err();
        assert!(e.contains("cubic19_f32: not measured"), "{e}");
    }

    #[test]
    fn estimates_must_bound_the_counts_within_half() {
        let r = |max: u64, est: Option<u64>| BenchResult {
            name: "t".into(),
            per_update: max,
            min: max,
            max,
            est,
        };
        assert!(check_estimates(&[r(100, Some(100)), r(100, Some(150))]).is_ok());
        assert!(check_estimates(&[r(100, Some(99))])
            .unwrap_err()
            .contains("below"));
        assert!(check_estimates(&[r(100, Some(151))])
            .unwrap_err()
            .contains("above"));
        assert!(check_estimates(&[r(100, None)]).is_err());
        let log = "INFO  BENCH a_f32 total=64 calls=64 min=1 max=1 est=2\n";
        assert_eq!(parse_bench_log(log).unwrap()[0].est, Some(2));
    }

    #[test]
    fn calibration_pairs_the_paths_and_reports_the_ratio_range() {
        let log = "INFO  BENCH a_f32 total=100 calls=1 min=100 max=100 est=110\n\
                   INFO  BENCH a_fixed total=200 calls=1 min=200 max=200 est=250\n\
                   INFO  BENCH cal_000_f32 total=50 calls=1 min=50 max=50 est=60\n\
                   INFO  BENCH cal_000_fixed total=80 calls=1 min=80 max=80 est=84\n";
        let rows = estimate_rows(&parse_bench_log(log).unwrap()).unwrap();
        assert_eq!(
            rows[1],
            EstimateRow {
                table: "cal_000".into(),
                f32: (50, 60),
                fixed: (80, 84)
            }
        );
        assert_eq!(ratio_range(rows.iter().map(|r| r.f32)), (1.1, 1.2));
        assert_eq!(ratio_range(rows.iter().map(|r| r.fixed)), (1.05, 1.25));
        // A table measured on one path only is an error, not a silent gap.
        let one = parse_bench_log("INFO  BENCH b_f32 total=1 calls=1 min=1 max=1 est=1\n").unwrap();
        assert!(estimate_rows(&one).unwrap_err().contains("b_fixed"));
    }

    #[test]
    fn ticks_over_the_budget_fail() {
        let log = "BUDGET period=8400 tick=6720 engine=1400 model=5320\n\
                   TICK no_table min=1060 mean=1060 max=1060 faults=0x1 est_fixed=0\n\
                   TICK small min=1600 mean=1600 max=1640 faults=0x0 est_fixed=656\n\
                   TICK huge min=10900 mean=10970 max=10986 faults=0x0 est_fixed=10691\n";
        let (b, ticks) = parse_tick_log(log).unwrap();
        assert_eq!(
            (b.period, b.tick, b.engine, b.model),
            (8400, 6720, 1400, 5320)
        );
        assert_eq!(ticks[1].max, 1640);
        // The refused table is a note, not a failure.
        let notes = check_ticks(&b, &ticks).unwrap();
        assert!(
            notes.len() == 1 && notes[0].contains("huge: refused"),
            "{notes:?}"
        );
        // An accepted table over the tick budget fails (estimate too low
        // for it as well).
        let mut over = ticks.clone();
        over[1].max = 6721;
        let e = check_ticks(&b, &over).unwrap_err();
        assert!(e.contains("small: worst tick 6721"), "{e}");
        // A tick above engine share + estimate fails even within budget.
        let mut under_est = ticks.clone();
        under_est[1].max = 1400 + 656 + 1;
        assert!(check_ticks(&b, &under_est).is_err());
        assert!(parse_tick_log("TICK x min=1 mean=1 max=1 faults=0 est_fixed=0").is_err());
    }

    #[test]
    fn json_str_reads_cargo_messages() {
        let line = r#"{"reason":"compiler-artifact","package_id":"path+file:///x#trueaxis-qemu@0.1.0","target":{"kind":["test"],"crate_types":["bin"],"name":"infra","src_path":"/x/suites/infra.rs"},"profile":{"test":true},"executable":"/t/deps/infra-1ce9"}"#;
        let target = &line[line.find(r#""target":{"#).unwrap()..];
        assert_eq!(json_str(target, "name").as_deref(), Some("infra"));
        assert_eq!(
            json_str(line, "executable").as_deref(),
            Some("/t/deps/infra-1ce9")
        );
        assert_eq!(json_str(line, "missing"), None);
    }
}
