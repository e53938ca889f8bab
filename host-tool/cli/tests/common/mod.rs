//! What the end-to-end CLI tests share: a scratch directory per test, the
//! built `trueaxis` binary run with arguments (and environment), its
//! stdout read as the one JSON document `--json` promises, and the usual
//! first two steps (a simulated grid, its cubic19 fit).
//!
//! Each test binary uses only part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

/// A fresh directory `trueaxis-<suite>-<pid>-<name>` under the temp dir.
pub fn tmp_dir(suite: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("trueaxis-{suite}-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the built `trueaxis` with `args`.
pub fn run(args: &[&str]) -> Output {
    run_env(args, &[])
}

/// Runs the built `trueaxis` with `args` and extra environment variables.
pub fn run_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_trueaxis"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .unwrap()
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Stdout of a successful run as one JSON document.
pub fn json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "exit {:?}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("exactly one JSON document on stdout")
}

/// `trueaxis simulate --plan grid:100 --seed SEED -o DIR/NAME --json`: the
/// preset mill on a 100 mm grid (9 × 6 × 6 = 324 points, ex ey ez),
/// σ = 0.2 µm noise. Returns the CSV's path.
pub fn simulate_grid(dir: &Path, name: &str, seed: u64) -> PathBuf {
    let csv = dir.join(name);
    let seed = seed.to_string();
    json(&run(&[
        "simulate",
        "--plan",
        "grid:100",
        "--seed",
        &seed,
        "-o",
        s(&csv),
        "--json",
    ]));
    csv
}

/// `trueaxis fit CSV --model cubic19 -o MODEL --json`; returns its JSON.
pub fn fit_cubic19(csv: &Path, model: &Path) -> Value {
    json(&run(&[
        "fit",
        s(csv),
        "--model",
        "cubic19",
        "-o",
        s(model),
        "--json",
    ]))
}

/// A checked-in input file, `tests/data/NAME`.
pub fn data_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Runs `trueaxis` expecting exit `code`, every one of `needles` in stderr
/// and nothing on stdout (no half document on failure); returns stderr.
pub fn expect_exit(args: &[&str], code: i32, needles: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{args:?}: stderr {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: expected `{n}` in stderr: {err}");
    }
    assert!(out.stdout.is_empty(), "no output on failure: {args:?}");
    err
}

/// Copies the CSV `src` to `dst` with one more row whose error cells
/// (`ex_um`, `ey_um`, `ez_um`) are empty — the row a measurement file gets
/// when the instrument lost its beam, which the importer leaves out ("no
/// error value on this row"). Returns the row's 1-based line number.
pub fn with_blank_error_row(src: &Path, dst: &Path) -> usize {
    let text = std::fs::read_to_string(src).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let header = lines
        .iter()
        .find(|l| !l.starts_with('#') && !l.trim().is_empty())
        .unwrap();
    let last = lines.last().unwrap();
    let row: Vec<&str> = header
        .split(',')
        .zip(last.split(','))
        .map(|(h, v)| match h.trim() {
            "ex_um" | "ey_um" | "ez_um" => "",
            _ => v,
        })
        .collect();
    std::fs::write(dst, format!("{}\n{}\n", text.trim_end(), row.join(","))).unwrap();
    lines.len() + 1
}
