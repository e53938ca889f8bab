//! Output files are written whole or not at all, and one writer at a time
//! (docs/cli.md § Output files): a write that fails half-way leaves the old
//! file as it was and no temporary file behind (`simulate -o`, `import -o`,
//! `export -o` wrote in place: a cut write left a truncated CSV that `fit`
//! accepted; `fit -o` left `*.tmp-PID` behind); a CSV cut in its last row is
//! refused with its line; parallel `fit -o` to one model record every step
//! (1 of 40 pairs lost one).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{expect_exit, fit_cubic19, grid_cubic19, json, run, s, simulate_grid, tmp_dir};

/// Runs `trueaxis ARGS` with files limited to `blocks` × 512 bytes
/// (`ulimit -f`; SIGXFSZ ignored, so a write past it fails with EFBIG as a
/// full disk would, instead of killing the process).
fn run_limited(blocks: u32, args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f {blocks}; exec \"$0\" \"$@\""
        ))
        .arg(env!("CARGO_BIN_EXE_trueaxis"))
        .args(args)
        .output()
        .unwrap()
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn a_write_that_fails_half_way_leaves_the_old_file_and_no_temporary() {
    let dir = tmp_dir("output-files", "cut");
    let (csv, model, _) = grid_cubic19(&dir, "d", 3);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let old = "the old content\n";
    // Each command writes well over 2 KiB; the limit cuts it half-way.
    let cases: Vec<(&str, Vec<String>)> = vec![
        (
            "sim.csv",
            vec!["simulate", "--plan", "grid:100", "-o"]
                .into_iter()
                .map(String::from)
                .collect(),
        ),
        (
            "copy.csv",
            vec!["import".into(), s(&csv).into(), "-o".into()],
        ),
        (
            "fit.json",
            vec![
                "fit".into(),
                s(&csv).into(),
                "--model".into(),
                "cubic19".into(),
                "-o".into(),
            ],
        ),
        (
            "y.comp",
            vec![
                "export".into(),
                s(&model).into(),
                "--format".into(),
                "linuxcnc".into(),
                "--axis".into(),
                "y".into(),
                "-o".into(),
            ],
        ),
    ];
    for (name, args) in &cases {
        let target = out.join(name);
        std::fs::write(&target, old).unwrap();
        let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
        a.push(s(&target));
        let r = run_limited(4, &a);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{a:?}: {err}");
        assert!(
            err.contains(&format!("cannot write {}", target.display())),
            "{a:?}: {err}"
        );
        assert_eq!(std::fs::read_to_string(&target).unwrap(), old, "{a:?}");
    }
    // No temporary file left, no lock: only the old files.
    assert_eq!(names(&out), ["copy.csv", "fit.json", "sim.csv", "y.comp"]);
    // Unlimited, the same commands replace them whole.
    for (name, args) in &cases {
        let target = out.join(name);
        let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
        a.push(s(&target));
        common::assert_success(&run(&a));
        assert_ne!(std::fs::read_to_string(&target).unwrap(), old);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_refused_rename_leaves_no_temporary_file() {
    // `fit -o DIR` where DIR is a directory: the rename fails after both
    // files were written to temporary files, which used to stay.
    let dir = tmp_dir("output-files", "rename");
    let csv = simulate_grid(&dir, "d.csv", 3);
    let target = dir.join("m.json");
    std::fs::create_dir(&target).unwrap();
    expect_exit(
        &["fit", s(&csv), "--model", "cubic19", "-o", s(&target)],
        1,
        &[&format!("cannot write {}", target.display())],
    );
    assert_eq!(names(&dir), ["d.csv", "m.json"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_csv_cut_in_its_last_row_is_refused_with_its_line() {
    let dir = tmp_dir("output-files", "truncated");
    let csv = simulate_grid(&dir, "d.csv", 3);
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines = text.lines().count();
    // Cut one byte into the last row's last cell (`pass_id` 35 → 3), and
    // right after its last comma (the cell empty): both read as a row.
    let whole = text.trim_end();
    for (i, cut) in [
        &whole[..whole.len() - 1],
        &whole[..whole.rfind(',').unwrap() + 1],
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.join(format!("cut{i}.csv"));
        std::fs::write(&p, cut).unwrap();
        for cmd in ["fit", "import"] {
            let mut args = vec![cmd, s(&p)];
            if cmd == "fit" {
                args.extend(["--model", "cubic19", "-o", "/dev/null/never"]);
            }
            expect_exit(
                &args,
                1,
                &[&format!(
                    "{}:{lines}: the last row has no line end: the file looks cut off in this row",
                    p.display()
                )],
            );
        }
    }
    // Cut mid-row (cells missing): refused as before, with its line.
    let p = common::file_in(&dir, "mid.csv", &whole[..whole.len() - 12]);
    expect_exit(
        &["import", s(&p)],
        1,
        &[&format!("{}:{lines}:", p.display())],
    );
    // The whole file reads.
    json(&run(&["import", s(&csv), "--json"]));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The six orders of three effects the simulated grid can fit: each
/// keeps every effect of any other, so every fit appends a step.
fn orders() -> Vec<Vec<&'static str>> {
    let e = [
        "reversal:target=ex,axis=x",
        "reversal:target=ey,axis=y",
        "reversal:target=ez,axis=x",
    ];
    let mut v = Vec::new();
    for (a, b, c) in [
        (0, 1, 2),
        (0, 2, 1),
        (1, 0, 2),
        (1, 2, 0),
        (2, 0, 1),
        (2, 1, 0),
    ] {
        v.push(vec![e[a], e[b], e[c]]);
    }
    v
}

#[test]
fn parallel_fits_to_one_model_record_every_step() {
    let dir = tmp_dir("output-files", "parallel");
    let csv = simulate_grid(&dir, "d.csv", 3);
    for round in 0..3 {
        let model = dir.join(format!("m{round}.json"));
        let children: Vec<_> = orders()
            .into_iter()
            .map(|adds| {
                let mut c = Command::new(env!("CARGO_BIN_EXE_trueaxis"));
                c.args([
                    "fit",
                    s(&csv),
                    "--model",
                    "cubic19",
                    "-o",
                    s(&model),
                    "--json",
                ]);
                for a in adds {
                    c.args(["--add", a]);
                }
                c.stdout(std::process::Stdio::null())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for c in children {
            let out = c.wait_with_output().unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let h = json(&run(&["history", s(&model), "--json"]));
        let steps = h["steps"].as_array().unwrap();
        assert_eq!(steps.len(), 6, "round {round}: {h}");
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
        assert_eq!(m["adds"], steps[5]["adds"], "the model is the last step's");
    }
    let left: Vec<String> = names(&dir)
        .into_iter()
        .filter(|n| n.contains(".tmp-") || n.ends_with(".lock"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_lock_held_by_a_running_process_is_refused_with_its_holder() {
    let dir = tmp_dir("output-files", "held");
    let csv = simulate_grid(&dir, "d.csv", 3);
    let model = dir.join("m.json");
    let lock: PathBuf = dir.join("m.json.lock");
    // This test's own process: running, and not writing.
    std::fs::write(&lock, std::process::id().to_string()).unwrap();
    expect_exit(
        &["fit", s(&csv), "--model", "cubic19", "-o", s(&model)],
        1,
        &[&format!(
            "{} is being written by another trueaxis (process {}; lock file {}): wait for it to finish — if no trueaxis is running, remove the lock file; nothing was written",
            model.display(),
            std::process::id(),
            lock.display()
        )],
    );
    assert!(!model.exists());
    // A lock left by a process that is gone is taken over.
    std::fs::write(&lock, "4194305").unwrap();
    fit_cubic19(&csv, &model);
    assert!(!lock.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
