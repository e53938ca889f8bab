//! What the end-to-end CLI tests share: a scratch directory per test, the
//! built `trueaxis` binary run with arguments (and environment), its
//! stdout read as the one JSON document `--json` promises, and the usual
//! first two steps (a simulated grid, its cubic19 fit).
//!
//! Each test binary uses only part of it.
#![allow(dead_code)]

pub mod export;
pub mod onmachine;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;
use trueaxis_engine::import;
use trueaxis_engine::simulate::instruments::{measure, Instrument};
use trueaxis_engine::simulate::Machine;

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

/// Asserts that a run exited 0, showing its exit and stderr if not.
pub fn assert_success(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Stdout of a successful run as one JSON document.
pub fn json(out: &Output) -> Value {
    assert_success(out);
    serde_json::from_slice(&out.stdout).expect("exactly one JSON document on stdout")
}

/// A JSON array of strings, each as `&str` (panics on anything else).
pub fn strs(v: &Value) -> Vec<&str> {
    array_of(v, Value::as_str)
}

/// A JSON array of numbers, each as `f64` (panics on anything else).
pub fn f64s(v: &Value) -> Vec<f64> {
    array_of(v, Value::as_f64)
}

/// A JSON array of whole numbers, each as `u64` (panics on anything else).
pub fn u64s(v: &Value) -> Vec<u64> {
    array_of(v, Value::as_u64)
}

fn array_of<'a, T>(v: &'a Value, each: impl Fn(&'a Value) -> Option<T>) -> Vec<T> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| each(x).unwrap())
        .collect()
}

/// `trueaxis simulate ARGS… -o OUT --json`; returns its JSON.
pub fn simulate(args: &[&str], out: &Path) -> Value {
    let mut a = vec!["simulate"];
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", s(out), "--json"]);
    json(&run(&a))
}

/// `trueaxis simulate --plan grid:100 --seed SEED -o DIR/NAME --json`: the
/// preset mill on a 100 mm grid (9 × 6 × 6 = 324 points, ex ey ez),
/// σ = 0.2 µm noise. Returns the CSV's path.
pub fn simulate_grid(dir: &Path, name: &str, seed: u64) -> PathBuf {
    let csv = dir.join(name);
    let seed = seed.to_string();
    simulate(&["--plan", "grid:100", "--seed", &seed], &csv);
    csv
}

/// The arguments `CMD CSV --model cubic19 -o MODEL [EXTRA…]`.
pub fn cubic19_args<'a>(
    cmd: &'a str,
    csv: &'a Path,
    model: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![cmd, s(csv), "--model", "cubic19", "-o", s(model)];
    args.extend_from_slice(extra);
    args
}

/// `trueaxis CMD CSV --model cubic19 -o MODEL [EXTRA…] --json`.
pub fn cubic19(cmd: &str, csv: &Path, model: &Path, extra: &[&str]) -> Output {
    let mut args = cubic19_args(cmd, csv, model, extra);
    args.push("--json");
    run(&args)
}

/// `trueaxis fit CSV --model cubic19 -o MODEL --json`; returns its JSON.
pub fn fit_cubic19(csv: &Path, model: &Path) -> Value {
    json(&cubic19("fit", csv, model, &[]))
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
    assert_no_document(args, &out);
    err
}

/// A failed run writes no half document: under `--json` stdout holds only
/// the error document (`{"error": …, "exit_code": …}`, the message as on
/// stderr), without it nothing.
pub fn assert_no_document(args: &[&str], out: &Output) {
    // Usage errors too (exit 2, clap's or one a command raises after
    // parsing, like `export`'s flags of another format) carry the document.
    if args.contains(&"--json") {
        let doc: Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{args:?}: stdout is no one JSON document ({e})"));
        assert_eq!(
            doc["exit_code"].as_i64(),
            out.status.code().map(i64::from),
            "{doc}"
        );
        let msg = doc["error"].as_str().unwrap_or_else(|| panic!("{doc}"));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.code() == Some(2) || err.contains(msg),
            "{args:?}: the error document says what stderr says: {msg} / {err}"
        );
    } else {
        assert!(out.stdout.is_empty(), "no output on failure: {args:?}");
    }
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

/// `--model cubic19 --add reversal:target=ex,axis=x`: the cubic plus the
/// x reversal on ex, the model an x line measured both ways is fitted with.
pub const CUBIC19_REVERSAL_X: &[&str] =
    &["--model", "cubic19", "--add", "reversal:target=ex,axis=x"];

/// `trueaxis fit CSV ARGS… -o MODEL --json`; returns its JSON.
pub fn fit(csv: &Path, args: &[&str], model: &Path) -> Value {
    let mut a = vec!["fit", s(csv)];
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", s(model), "--json"]);
    json(&run(&a))
}

/// `simulate_grid(DIR, STEM.csv, SEED)` fitted with `fit_cubic19` to
/// `DIR/STEM.model.json`. Returns (data, model, the fit's JSON).
pub fn grid_cubic19(dir: &Path, stem: &str, seed: u64) -> (PathBuf, PathBuf, Value) {
    let csv = simulate_grid(dir, &format!("{stem}.csv"), seed);
    let model = dir.join(format!("{stem}.model.json"));
    let v = fit_cubic19(&csv, &model);
    (csv, model, v)
}

/// The `trueaxis export MODEL ARGS… -o OUT` command line.
pub fn export_args<'a>(model: &'a Path, args: &[&'a str], out: &'a Path) -> Vec<&'a str> {
    let mut a = vec!["export", s(model)];
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", s(out)]);
    a
}

/// `trueaxis export MODEL ARGS… -o OUT --json`; returns its JSON.
pub fn export(model: &Path, args: &[&str], out: &Path) -> Value {
    let mut a = export_args(model, args, out);
    a.push("--json");
    json(&run(&a))
}

/// `trueaxis diagnose CSV --model MODEL --report DIR --json`; returns its
/// JSON.
pub fn diagnose_report(csv: &Path, model: &str, report: &Path) -> Value {
    let args = ["diagnose", s(csv), "--model", model, "--report", s(report)];
    json(&run(&[&args[..], &["--json"]].concat()))
}

/// `trueaxis compare CSV --model MODEL --json`; returns its JSON.
pub fn compare(csv: &Path, model: &Path) -> Value {
    json(&run(&["compare", s(csv), "--model", s(model), "--json"]))
}

/// The `code`s of a JSON document's `warnings`, in order.
pub fn warning_codes(v: &Value) -> Vec<&str> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w["code"].as_str())
        .collect()
}

/// `machine` measured with `plan` (random stream SEED, with noise), written
/// to `DIR/NAME.csv`, then `trueaxis fit DIR/NAME.csv --model SPEC -o
/// DIR/NAME.model.json EXTRA…`: (data, model, the fit's run).
pub fn measured_fit(
    dir: &Path,
    name: &str,
    machine: &Machine,
    plan: &[Instrument],
    seed: u64,
    spec: &str,
    extra: &[&str],
) -> (PathBuf, PathBuf, Output) {
    let data = measure(machine, plan, seed, true);
    let csv = dir.join(format!("{name}.csv"));
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    let model = dir.join(format!("{name}.model.json"));
    let mut args = vec!["fit", s(&csv), "--model", spec, "-o", s(&model)];
    args.extend_from_slice(extra);
    let out = run(&args);
    (csv, model, out)
}

/// Writes `text` to `DIR/NAME`; returns its path.
pub fn file_in(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// The first line of `text` that passes `test`; panics, showing `text`,
/// when none does.
#[track_caller]
pub fn line_where(text: &str, test: impl Fn(&str) -> bool) -> &str {
    let found = text.lines().find(|l| test(l));
    found.unwrap_or_else(|| panic!("no such line in\n{text}"))
}

/// Asserts that `text` contains every one of `needles`, showing it if not.
#[track_caller]
pub fn assert_has(text: &str, needles: &[&str]) {
    assert!(needles.iter().all(|n| text.contains(n)), "{text}");
}

/// The first element of the JSON array `v` that passes `test`; panics,
/// showing `v`, when none does.
pub fn find_in(v: &Value, test: impl Fn(&Value) -> bool) -> &Value {
    let found = v.as_array().unwrap().iter().find(|e| test(e));
    found.unwrap_or_else(|| panic!("none found in {v}"))
}

/// The first of a JSON document's `warnings` with `code`, if any.
pub fn find_warning<'a>(v: &'a Value, code: &str) -> Option<&'a Value> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["code"] == code)
}

/// A checked-in golden file, `tests/golden/NAME`.
pub fn golden_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name)
}

/// Compares `actual` with the checked-in golden file `tests/golden/NAME`,
/// or rewrites it when TRUEAXIS_BLESS=1.
pub fn golden(name: &str, actual: &[u8]) {
    let path = golden_file(name);
    if std::env::var("TRUEAXIS_BLESS").is_ok_and(|v| v == "1") {
        std::fs::write(&path, actual).unwrap();
        return;
    }
    let expected = std::fs::read(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run with TRUEAXIS_BLESS=1 to create it)",
            path.display()
        )
    });
    if expected != actual {
        let (e, a) = (
            String::from_utf8_lossy(&expected),
            String::from_utf8_lossy(actual),
        );
        let first = e
            .lines()
            .zip(a.lines())
            .position(|(x, y)| x != y)
            .map_or("the length".to_string(), |i| format!("line {}", i + 1));
        panic!(
            "{} differs from the output at {first} (TRUEAXIS_BLESS=1 rewrites it after an intended change)\nexpected:\n{e}\nactual:\n{a}",
            path.display()
        );
    }
}

/// The simulated on-machine campaign (seed 7) in `dir/camp`: its directory
/// and the hidden answers (`truth.json`'s content).
pub fn on_machine_campaign(dir: &Path) -> (PathBuf, Value) {
    let camp = dir.join("camp");
    let doc = simulate(&["--scenario", "on-machine", "--seed", "7"], &camp);
    (camp, doc["truth"].clone())
}

/// A page's Next (`<pre class="next">`), unescaped, when it is a command
/// (some pages say in words what to measure first).
pub fn page_next(page: &Path) -> Option<String> {
    let html = std::fs::read_to_string(page).unwrap();
    let start = html.find("<pre class=\"next\">")? + "<pre class=\"next\">".len();
    let end = start + html[start..].find("</pre>")?;
    let cmd = html[start..end]
        .replace("&#39;", "'")
        .replace("&quot;", "\"")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&");
    cmd.starts_with("trueaxis ").then_some(cmd)
}

/// Pastes `cmd` into `sh` in `dir`, as a user would; its stdout, or the
/// failure in words.
pub fn paste(dir: &Path, cmd: &str) -> Result<String, String> {
    let script = format!(
        "trueaxis() {{ '{}' \"$@\"; }}\n{cmd}\n",
        env!("CARGO_BIN_EXE_trueaxis")
    );
    let out = Command::new("sh")
        .arg("-c")
        .arg(&script)
        .current_dir(dir)
        .output()
        .unwrap();
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    } else {
        Err(format!(
            "`{cmd}` (in {}) exited {:?}: {}",
            dir.display(),
            out.status.code(),
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

/// Every `index.html` under `root`, sorted.
pub fn pages_under(root: &Path) -> Vec<PathBuf> {
    let mut v = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|f| f == "index.html") {
                v.push(p);
            }
        }
    }
    v.sort();
    v
}
