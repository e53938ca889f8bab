//! A stdout whose reader has gone away (`trueaxis compare … --json | head
//! -c 400`): every command stops quietly with exit 0 instead of panicking
//! on EPIPE. The pipe's read end is closed before the command starts, so
//! its very first write fails — deterministic, no race with the reader.

mod common;

use std::process::{Command, Stdio};

use common::{data_file, grid_cubic19, s, tmp_dir};

/// Runs `trueaxis args` with stdout a pipe nobody reads; returns the exit
/// code and stderr.
fn run_into_closed_pipe(args: &[&str]) -> (Option<i32>, String) {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_trueaxis"))
        .args(args)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn every_command_exits_0_quietly_when_stdout_is_closed() {
    let dir = tmp_dir("closed-stdout", "all");
    let (csv, model, _) = grid_cubic19(&dir, "d", 1);
    let csv2 = dir.join("d2.csv");
    let model2 = dir.join("m2.json");
    let table = dir.join("t.bin");
    let model3 = dir.join("m3.json");
    let iso_rtl = data_file("iso_worked.rtl");
    let iso = s(&iso_rtl);
    let cases: Vec<Vec<&str>> = vec![
        vec!["compare", s(&csv), "--model", s(&model), "--json"],
        vec!["compare", s(&csv), "--model", s(&model)],
        vec!["iso230", iso, "--json"],
        vec!["iso230", iso],
        vec!["import", iso, "--json"],
        vec!["import", iso],
        vec!["simulate", "--plan", "line:x:100", "-o", s(&csv2)],
        vec!["fit", s(&csv), "--model", "cubic19", "-o", s(&model2)],
        vec!["diagnose", s(&csv), "--model", "cubic19", "--json"],
        vec!["history", s(&model), "--json"],
        vec!["improve", s(&csv), "--model", "cubic19", "-o", s(&model3)],
        vec![
            "improve",
            s(&csv),
            "--model",
            "cubic19",
            "-o",
            s(&model3),
            "--json",
        ],
        vec!["export", s(&model), "-o", s(&table), "--json"],
    ];
    for args in &cases {
        let (code, err) = run_into_closed_pipe(args);
        assert_eq!(code, Some(0), "{args:?}: stderr {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(!err.contains("Broken pipe"), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
