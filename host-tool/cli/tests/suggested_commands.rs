//! Every command the tool suggests runs as pasted (issue 28: the ISO page
//! of an ecmc `.dat` proposed a `fit` that needs `--axis`, `history` run
//! from another directory proposed a data path that did not read there,
//! pages proposed `probe correct SCAN.csv`). The README workflow, the
//! on-machine commands, ISO 230-2 runs (simulated, `.rtl`, ecmc `.dat`) and
//! a printer bed are run in a fresh directory; every `next:` line they
//! print and every page's "Next" command is pasted into `sh` in the
//! directory the command ran in (`trueaxis` a shell function calling the
//! built binary), and what those print next is followed too, a few steps
//! deep. A suggestion that exits non-zero fails the test with its stderr.
//! (The demo's pages are checked in `demo.rs`, which already runs it.)

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{page_next, pages_under, paste, tmp_dir};
use trueaxis_test_support::assert_any;

const BIN: &str = env!("CARGO_BIN_EXE_trueaxis");
const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");

/// Runs `trueaxis ARGS` in `dir` (text output), asserting success; its
/// stdout.
fn tx(dir: &Path, args: &[&str]) -> String {
    let out = Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "trueaxis {} (in {}): exit {:?}\n{}",
        args.join(" "),
        dir.display(),
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The commands of a text output's `next:` lines.
fn next_lines(stdout: &str) -> Vec<String> {
    stdout
        .lines()
        .filter_map(|l| l.strip_prefix("next: "))
        .map(String::from)
        .collect()
}

/// What was suggested and how it went.
#[derive(Default)]
struct Log {
    ran: Vec<String>,
    failed: Vec<String>,
}

impl Log {
    /// Pastes every `next:` of `stdout` in `dir`, then what those print
    /// next, up to `depth` commands down a chain.
    fn follow(&mut self, dir: &Path, stdout: &str, depth: usize) {
        if depth == 0 {
            return;
        }
        for cmd in next_lines(stdout) {
            if self.ran.contains(&cmd) {
                continue;
            }
            self.ran.push(cmd.clone());
            match paste(dir, &cmd) {
                Ok(out) => self.follow(dir, &out, depth - 1),
                Err(e) => self.failed.push(e),
            }
        }
    }

    /// Pastes the Next command of every page under `root` in `dir`.
    fn pages(&mut self, root: &Path, dir: &Path) {
        for page in pages_under(root) {
            if let Some(cmd) = page_next(&page) {
                self.ran.push(format!("{} ← {}", cmd, page.display()));
                if let Err(e) = paste(dir, &cmd) {
                    self.failed.push(format!("{}: {e}", page.display()));
                }
            }
        }
    }
}

fn copy_data(dir: &Path, name: &str) {
    std::fs::copy(Path::new(DATA).join(name), dir.join(name)).unwrap();
}

fn fresh(name: &str) -> PathBuf {
    let d = tmp_dir("suggested", name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn assert_all_ran(log: &Log, at_least: usize) {
    assert!(
        log.failed.is_empty(),
        "suggested commands that fail:\n{}\n(ran {})",
        log.failed.join("\n"),
        log.ran.len()
    );
    assert!(
        log.ran.len() >= at_least,
        "only {} suggestions found: {:#?}",
        log.ran.len(),
        log.ran
    );
}

#[test]
fn the_workflow_suggests_only_commands_that_run() {
    let w = fresh("workflow");
    let mut log = Log::default();
    // simulate → fit → compare → diagnose → fit --add → …, each the one
    // the previous printed.
    let sim = tx(
        &w,
        &[
            "simulate",
            "--plan",
            "grid:100",
            "--plan",
            "line:y:1",
            "--effect",
            "periodic:axis=y,period_mm=5.08,amp_um=3",
            "--seed",
            "3",
            "-o",
            "data.csv",
        ],
    );
    assert!(
        next_lines(&sim)[0].starts_with("trueaxis fit data.csv"),
        "{sim}"
    );
    log.follow(&w, &sim, 5);
    // The commands that change something each print their next.
    for (args, want) in [
        (
            &["fit", "data.csv", "--model", "cubic19", "-o", "m2.json"][..],
            "trueaxis compare data.csv --model m2.json",
        ),
        (
            &[
                "compare", "data.csv", "--model", "m2.json", "--report", "r2",
            ][..],
            "trueaxis diagnose data.csv --model m2.json --report r2/diagnose",
        ),
        (
            &[
                "improve", "data.csv", "--model", "cubic19", "-o", "imp.json",
            ][..],
            "trueaxis history imp.json --report history",
        ),
    ] {
        let out = tx(&w, args);
        let next = next_lines(&out);
        assert!(
            next.iter().any(|n| n.starts_with(want)),
            "{args:?} printed no `next: {want}…`:\n{out}"
        );
        log.follow(&w, &out, 2);
    }
    log.pages(&w, &w);
    // History read from another directory proposes a path that reads there.
    let elsewhere = w.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    tx(&elsewhere, &["history", "../m2.json", "--report", "h"]);
    log.pages(&elsewhere, &elsewhere);
    assert_all_ran(&log, 8);
}

#[test]
fn iso_runs_beds_and_imports_suggest_commands_that_run() {
    let w = fresh("iso-bed");
    let mut log = Log::default();
    for f in ["iso_worked.rtl", "axis1_ISO230.dat", "bed_heightmap.csv"] {
        copy_data(&w, f);
    }
    let sim = tx(
        &w,
        &[
            "simulate", "--plan", "iso230:x", "--seed", "2", "-o", "iso.csv",
        ],
    );
    assert!(
        next_lines(&sim)[0].starts_with("trueaxis iso230 iso.csv"),
        "{sim}"
    );
    log.follow(&w, &sim, 2);
    // A 3-target .rtl (no cubic along x) and an ecmc .dat (needs --axis).
    tx(&w, &["iso230", "iso_worked.rtl", "--report", "iso_rtl"]);
    tx(
        &w,
        &[
            "iso230",
            "axis1_ISO230.dat",
            "--axis",
            "x",
            "--report",
            "iso_dat",
        ],
    );
    for file in ["axis1_ISO230.dat", "bed_heightmap.csv"] {
        let mut args = vec!["import", file, "-o"];
        let out_name = format!("{file}.csv");
        args.push(&out_name);
        if file.ends_with(".dat") {
            args.extend(["--axis", "x"]);
        }
        let out = tx(&w, &args);
        log.follow(&w, &out, 3);
    }
    log.pages(&w, &w);
    // The bed is fitted with a grid, not the machine-tool polynomial.
    assert_any(&log.ran, |c| {
        c.starts_with("trueaxis fit bed_heightmap.csv.csv --model grid:")
    });
    assert_all_ran(&log, 7);
}

#[test]
fn the_on_machine_commands_suggest_commands_that_run() {
    let w = fresh("on-machine");
    let mut log = Log::default();
    let sim = tx(&w, &["simulate", "--scenario", "on-machine", "-o", "om/"]);
    assert!(
        next_lines(&sim)[0].starts_with("trueaxis probe calibrate om/ball.csv"),
        "{sim}"
    );
    log.follow(&w, &sim, 2);
    let runs: [&[&str]; 6] = [
        &[
            "probe",
            "calibrate",
            "om/ball3d.csv",
            "--ball-diameter-mm",
            "4",
            "--plane",
            "xyz",
            "-o",
            "probe3d.json",
            "--report",
            "p3",
        ],
        &[
            "separate",
            "reversal",
            "om/run0.csv",
            "om/run180.csv",
            "-o",
            "rev.csv",
            "--report",
            "sr",
        ],
        &[
            "separate",
            "three-probe",
            "om/three-probe.csv",
            "--angles-deg",
            "0,99.84,202.5",
            "-o",
            "tp.csv",
            "--report",
            "st",
        ],
        &[
            "separate",
            "multi-step",
            "om/multi-step.csv",
            "-o",
            "ms.csv",
            "--report",
            "sm",
        ],
        &["workpiece", "om/grinder.csv", "--report", "wp"],
        &[
            "diagnose-part",
            "om/run0.csv",
            "--reversal",
            "om/run180.csv",
            "--report",
            "dp",
        ],
    ];
    for args in runs {
        let out = tx(&w, args);
        log.follow(&w, &out, 2);
    }
    log.pages(&w, &w);
    // The probe page says what its radius interval is about (issue 28).
    let probe_page = std::fs::read_to_string(w.join("probe").join("index.html")).unwrap();
    assert!(
        probe_page.contains("zero mean and no tilt"),
        "the radius convention"
    );
    // No placeholder a user would have to replace.
    for c in &log.ran {
        for placeholder in ["SCAN.csv", "SURFACE.csv", "DATA.csv", "MODEL.json"] {
            assert!(!c.contains(placeholder), "{c}");
        }
    }
    assert_all_ran(&log, 2);
}
