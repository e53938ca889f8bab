//! The instruction budgets: the bench image (one model update per table,
//! counted under `-icount shift=0`) against [`BUDGETS`] and against the
//! static cost estimate, the tick bench (one correction-engine tick per
//! table) against the board's loop budget, and `bench-mcu` with its
//! calibration report of the estimate.

use super::build::{build_package_bin, Profile};
use super::run::{describe, run_image, QemuOpts};
use super::PACKAGE;
use crate::Result;

/// The instruction budgets per 3-axis model update (issue 6, tightened by
/// issue 15 to what the kernels now take, a few instructions of margin):
/// the bench names docs/qemu.md ("Instruction counts") lists and the most
/// instructions each may take.
/// `cargo xtask bench-mcu` prints them beside the counts; `cargo xtask
/// test` fails when a bench is missing or its worst call exceeds its budget.
/// Round 3 (branch `mcu3`): the measured counts plus 3 — the harness's
/// calibration of its own overhead has moved every count by 2–3 when
/// unrelated code moved (BENCHMARKS.md). Round 4 (branch `mcu4`): the
/// same rule on its counts. Issue 26 (branch `vboard3`): the engine's
/// export of a fitted rigid21:4 model (tests/golden/rigid21.bin), the same
/// rule (rigid21_fixed 1 392 after the block by monomial read by LDM,
/// branch `vboard4`; 934 on the separable path's Horner rows, branch
/// `tick26`).
pub const BUDGETS: [(&str, u64); 8] = [
    ("cubic19_f32", 201),
    ("cubic19_fixed", 437),
    ("poly_deg1_f32", 104),
    ("poly_deg1_fixed", 151),
    ("full_f32", 485),
    ("nn_3x16x3_f32", 847),
    ("rigid21_f32", 1232),
    ("rigid21_fixed", 937),
];

/// Builds and runs the bench image (firmware release profile, `-icount
/// shift=0`) and returns its figures: the one code path of `bench-mcu` and
/// of the check in `cargo xtask test`. With `calibrate`, the image also
/// evaluates the cost estimate's calibration set (the QEMU crate's
/// `calibrate` feature: build/cost_tables.rs, `calibration`).
pub(super) fn run_bench(calibrate: bool) -> Result<Vec<BenchResult>> {
    parse_bench_log(&run_bench_log(calibrate)?)
}

/// The bench image's log ([`run_bench`]).
pub(super) fn run_bench_log(calibrate: bool) -> Result<String> {
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
    Ok(run.log)
}

/// Builds and runs the definition-check image (tests/src/bin/defcheck.rs,
/// firmware release profile, `-icount shift=0`) and returns its log.
pub(super) fn run_defcheck_log() -> Result<String> {
    let elf = build_package_bin(PACKAGE, "defcheck", Profile::Release, &[])?;
    eprintln!("\n$ qemu defcheck (-icount shift=0)");
    let run = run_image(&elf, &QemuOpts::default())?;
    if !run.status.success() {
        return Err(format!(
            "the defcheck image failed ({})\n{}{}",
            describe(&run.status),
            run.log,
            run.stderr
        ));
    }
    Ok(run.log)
}

/// The most instructions the board's definition check
/// (`model_core::definition::check_definition`) may take on a table the
/// board accepts otherwise (fixed-point estimate within its model budget):
/// 100 M, 0.6 s at 168 MHz — a commit waits for it before it writes
/// (the link task, which the correction loop preempts), and the boot runs
/// it on each slot before the loop starts. Measured: 2.0–38.9 M on the
/// bench tables (BENCHMARKS.md, "Definition check").
pub const CHECK_BUDGET_INSTR: u64 = 100_000_000;

/// One `CHECK <name> instructions=N accepted=…` line of the defcheck image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct CheckResult {
    name: String,
    instructions: u64,
    accepted: bool,
}

/// Reads the defcheck image's `CHECK` lines.
pub(super) fn parse_check_log(log: &str) -> Result<Vec<CheckResult>> {
    let mut out = Vec::new();
    for line in log.lines() {
        let Some(rest) = line.split("CHECK ").nth(1) else {
            continue;
        };
        let field = |key: &str| {
            rest.split_whitespace()
                .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
                .ok_or_else(|| format!("CHECK line without {key}: {line}"))
        };
        out.push(CheckResult {
            name: rest.split_whitespace().next().unwrap_or("").to_owned(),
            instructions: field("instructions")?
                .parse()
                .map_err(|e| format!("CHECK instructions: {e} in {line}"))?,
            accepted: field("accepted")? == "true",
        });
    }
    if out.is_empty() {
        return Err(format!("the defcheck image printed no CHECK line:\n{log}"));
    }
    Ok(out)
}

/// Every bench table passes the definition check (they are realistic
/// tables: an accuracy of 1 nm, far inside the bound), and on every one
/// the board would take otherwise (its `_fixed` estimate within
/// `model_budget`) the check costs at most [`CHECK_BUDGET_INSTR`].
pub(super) fn check_checks(
    checks: &[CheckResult],
    results: &[BenchResult],
    model_budget: u64,
) -> Result<()> {
    let mut misses = Vec::new();
    for c in checks {
        let takes = results
            .iter()
            .find(|r| r.name == format!("{}_fixed", c.name))
            .and_then(|r| r.est)
            .is_some_and(|est| est <= model_budget);
        if !c.accepted {
            misses.push(format!("{}: refused by the definition check", c.name));
        } else if takes && c.instructions > CHECK_BUDGET_INSTR {
            misses.push(format!(
                "{}: the definition check takes {} instructions, budget {CHECK_BUDGET_INSTR}",
                c.name, c.instructions
            ));
        }
    }
    if misses.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "definition check (model-core/src/definition.rs):\n  {}",
            misses.join("\n  ")
        ))
    }
}

/// The board's model budget as the defcheck image prints it (`MODEL_BUDGET
/// instructions=N`: model-core's `board::MODEL_BUDGET_INSTR`, defined once).
pub(super) fn parse_model_budget(log: &str) -> Result<u64> {
    log.lines()
        .find_map(|l| l.split("MODEL_BUDGET instructions=").nth(1))
        .and_then(|v| v.trim().parse().ok())
        .ok_or_else(|| format!("the defcheck image printed no MODEL_BUDGET line:\n{log}"))
}

/// The definition check's counts, on stderr.
pub(super) fn print_check_table(checks: &[CheckResult]) {
    eprintln!(
        "\n{:<24} {:>14} {:>10}",
        "definition check", "instructions", "ms@168MHz"
    );
    for c in checks {
        eprintln!(
            "{:<24} {:>14} {:>10.1}",
            c.name,
            c.instructions,
            c.instructions as f64 / 168_000.0
        );
    }
}

/// Every name of [`BUDGETS`] measured, and no worst call above its budget;
/// the error lists every miss.
pub(super) fn check_budgets(results: &[BenchResult]) -> Result<()> {
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
pub(super) fn check_estimates(results: &[BenchResult]) -> Result<()> {
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
pub(super) fn budget_of(name: &str) -> Option<u64> {
    BUDGETS.iter().find(|(n, _)| *n == name).map(|&(_, b)| b)
}

/// The bench image in `cargo xtask test`: the budgets must hold.
pub(super) fn check_bench() -> Result<()> {
    let results = run_bench(false)?;
    let log = run_defcheck_log()?;
    let checks = parse_check_log(&log)?;
    print_bench_table(&results);
    print_check_table(&checks);
    check_checks(&checks, &results, parse_model_budget(&log)?)?;
    eprintln!(
        "qemu: every bench table passes the definition check, within {CHECK_BUDGET_INSTR} instructions where the board takes it"
    );
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

/// Instruction counts per model update (docs/qemu.md, "Instruction
/// counts"): one JSON line per
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
    let checks = parse_check_log(&run_defcheck_log()?)?;
    for r in &results {
        println!(
            "{{\"bench\": \"{}\", \"instructions_per_update\": {}, \"outputs\": 3}}",
            r.name, r.per_update
        );
    }
    for c in &checks {
        println!(
            "{{\"definition_check\": \"{}\", \"instructions\": {}, \"accepted\": {}}}",
            c.name, c.instructions, c.accepted
        );
    }
    print_bench_table(&results);
    print_check_table(&checks);
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
pub(super) fn calibrate() -> Result<()> {
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
pub(super) struct EstimateRow {
    table: String,
    f32: (u64, u64),
    fixed: (u64, u64),
}

/// Pairs the `<table>_f32` and `<table>_fixed` benches.
pub(super) fn estimate_rows(results: &[BenchResult]) -> Result<Vec<EstimateRow>> {
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
pub(super) fn ratio((count, est): (u64, u64)) -> f64 {
    est as f64 / count as f64
}

/// The smallest and largest [`ratio`].
pub(super) fn ratio_range(pairs: impl Iterator<Item = (u64, u64)>) -> (f64, f64) {
    pairs
        .map(ratio)
        .fold((f64::INFINITY, 0.0), |(lo, hi), r| (lo.min(r), hi.max(r)))
}

/// The human summary of the bench figures, on stderr.
pub(super) fn print_bench_table(results: &[BenchResult]) {
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
pub(super) struct TickBudget {
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
pub(super) struct TickResult {
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
pub(super) fn parse_tick_log(log: &str) -> Result<(TickBudget, Vec<TickResult>)> {
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
pub(super) fn accepted(budget: &TickBudget, est_fixed: u64) -> bool {
    est_fixed <= budget.model
}

/// The loop-rate claim: every tick of a table the board accepts fits the
/// tick budget (the 20 kHz period less its margin), the engine without a
/// table stays within its share, and every tick is at most the engine's
/// share plus the table's estimate (what the admission assumes). A table
/// the board refuses (its estimate over the budget) is reported, not
/// failed; `all_kinds` is one.
pub(super) fn check_ticks(budget: &TickBudget, ticks: &[TickResult]) -> Result<Vec<String>> {
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
pub(super) fn check_tickbench() -> Result<()> {
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
pub(super) struct BenchResult {
    name: String,
    /// Mean instructions per call, rounded to nearest.
    per_update: u64,
    min: u64,
    max: u64,
    /// model-core's static estimate of the same evaluation (`est=`).
    est: Option<u64>,
}

/// Reads the bench image's `BENCH <name> total=T calls=C min=A max=B` lines.
pub(super) fn parse_bench_log(log: &str) -> Result<Vec<BenchResult>> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_lines_are_read_and_held_to_the_budget() {
        let log = "INFO  MODEL_BUDGET instructions=5320\n\
                   INFO  BENCH a_fixed total=64 calls=64 min=1 max=1 est=500\n\
                   INFO  BENCH slow_fixed total=64 calls=64 min=1 max=1 est=9000\n\
                   INFO  CHECK a instructions=6934249 accepted=true\n\
                   INFO  CHECK slow instructions=150000000 accepted=true\n";
        let checks = parse_check_log(log).unwrap();
        let results = parse_bench_log(log).unwrap();
        assert_eq!(parse_model_budget(log).unwrap(), 5320);
        assert_eq!(checks[0].instructions, 6_934_249);
        // `slow` is over the check's budget but the board refuses it for
        // its cost first: no miss.
        assert!(check_checks(&checks, &results, 5320).is_ok());
        // A table the board takes whose check is too slow, or a refusal.
        let over = [CheckResult {
            name: "a".into(),
            instructions: CHECK_BUDGET_INSTR + 1,
            accepted: true,
        }];
        assert!(check_checks(&over, &results, 5320).is_err());
        let refused = [CheckResult {
            name: "a".into(),
            instructions: 1,
            accepted: false,
        }];
        assert!(check_checks(&refused, &results, 5320).is_err());
        assert!(parse_check_log("nothing").is_err());
    }

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
        over[4].max = BUDGETS[4].1 + 1;
        let e = check_budgets(&over).unwrap_err();
        let budget = format!("budget {}", BUDGETS[4].1);
        assert!(e.contains("full_f32") && e.contains(&budget), "{e}");
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
}
