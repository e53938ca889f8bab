//! A message that quotes the input escapes its control characters and cuts
//! a long cell (docs/cli.md § Measurement CSV): an escape sequence in a
//! cell or a header never reaches the terminal (it used to: `ESC[2J`
//! cleared the screen the error was on), and a 50 MB bad cell is quoted
//! as its first 80 characters and its length, not echoed whole.

mod common;

use common::{run, s, tmp_dir};

/// `trueaxis ARGS`: exit 1 and stderr, which must hold no control
/// character but line ends.
fn refused(args: &[&str]) -> String {
    let out = run(args);
    assert_eq!(out.status.code(), Some(1), "{args:?}");
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        !err.chars().any(|c| c.is_control() && c != '\n'),
        "a control character reached stderr: {err:?}"
    );
    err
}

#[test]
fn an_escape_sequence_in_a_cell_or_header_is_shown_escaped() {
    let dir = tmp_dir("echoed", "escape");
    let cell = dir.join("cell.csv");
    std::fs::write(&cell, "x_mm,ex_um\n0,1\n100,\x1b[2J\x1b[31mred\n").unwrap();
    for cmd in [
        vec!["import", s(&cell)],
        vec!["fit", s(&cell), "--model", "cubic19"],
    ] {
        let err = refused(&cmd);
        common::assert_has(
            &err,
            &[&format!(
                "{}:3:2: column `ex_um`: expected a number, found `\\u{{1b}}[2J\\u{{1b}}[31mred`",
                cell.display()
            )],
        );
    }
    // A header: in an error (a unit suffix it does not know) …
    let head = common::file_in(&dir, "head.csv", "x_mm,ex_\x1b]0;owned\x07um\n0,1\n");
    let err = refused(&["import", s(&head)]);
    assert!(
        err.contains("column `ex_\\u{1b}]0;owned\\u{7}um`: unknown unit suffix"),
        "{err}"
    );
    // … and in a warning (an auxiliary column fit keeps).
    let aux = dir.join("aux.csv");
    let mut text = String::from("x_mm,ex_um,no\x1b[8mte\n");
    for i in 0..6 {
        text.push_str(&format!("{},{},a\n", i * 100, (i as f64 * 0.7).sin()));
    }
    std::fs::write(&aux, text).unwrap();
    let out = run(&common::cubic19_args("fit", &aux, &dir.join("m.json"), &[]));
    common::assert_success(&out);
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("`no\\u{1b}[8mte`"), "{err}");
    assert!(!err.contains('\x1b'), "{err:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_50_mb_cell_is_cut_in_the_message() {
    let dir = tmp_dir("echoed", "long");
    let csv = dir.join("long.csv");
    let big = "7".to_string() + &"x".repeat(50 * 1024 * 1024 - 1);
    std::fs::write(&csv, format!("x_mm,ex_um\n0,1\n100,{big}\n")).unwrap();
    let err = refused(&["import", s(&csv)]);
    let shown = format!("7{}… ({} bytes)", "x".repeat(79), big.len());
    assert!(
        err.contains(&format!(
            "{}:3:2: column `ex_um`: expected a number, found `{shown}`",
            csv.display()
        )),
        "{}",
        &err[..err.len().min(600)]
    );
    assert!(err.len() < 600, "{} bytes on stderr", err.len());
    std::fs::remove_dir_all(&dir).unwrap();
}
