//! `trueaxis improve`'s text: a step that adds several effects (one per
//! target) names each of them and gives each its evidence — the text once
//! explained only the first (issue 13).

mod common;

use common::{run, s, tmp_dir};

#[test]
fn a_step_that_adds_two_effects_explains_both() {
    let dir = tmp_dir("improve_text", "two");
    let data = dir.join("d.csv");
    // Lines every 1 mm: on 2 mm steps the 25 mm wave could be a 2.17 mm
    // lead's alias, and is held back (tests/aliasing.rs).
    let o = run(&[
        "simulate",
        "--plan",
        "grid:100",
        "--plan",
        "line:x:1,bidir",
        "--plan",
        "line:y:1,bidir",
        "--effect",
        "periodic:axis=x,target=ex,period_mm=25,amp_um=3",
        "--effect",
        "reversal:axis=y,backlash_um=8,target=ey",
        "-o",
        s(&data),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(&common::cubic19_args(
        "improve",
        &data,
        &dir.join("m.json"),
        &[],
    ));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let step = common::line_where(&text, |l| l.starts_with("step 2:"));
    common::assert_has(step, &["add reversal:target=ey", "add periodic:target=ex"]);
    let because: Vec<&str> = text.lines().filter(|l| l.contains("because (")).collect();
    assert_eq!(because.len(), 2, "{text}");
    assert!(
        because
            .iter()
            .any(|l| l.contains("backlash 7.9") || l.contains("backlash 8.0")),
        "{text}"
    );
    assert!(
        because.iter().any(|l| l.contains("period 25.0 mm")),
        "{text}"
    );
}

#[test]
fn improve_carries_diagnoses_design_warnings() {
    // Issue 28: on the README workflow `improve --json` had `warnings: []`
    // and "at the noise floor" where diagnose warned that the grid hides
    // leads and that no temperature was logged.
    let dir = tmp_dir("improve_text", "design");
    let data = dir.join("d.csv");
    let o = run(&[
        "simulate",
        "--plan",
        "grid:100",
        "--seed",
        "2",
        "-o",
        s(&data),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = dir.join("m.json");
    let o = common::cubic19("improve", &data, &m, &[]);
    let doc = common::json(&o);
    let codes = common::warning_codes(&doc);
    for want in ["aliasing", "no_temperature"] {
        assert!(codes.contains(&want), "{want} missing: {codes:?}");
    }
    // The text says them before its closing line, and what to run next.
    let o = run(&["improve", s(&data), "--model", "cubic19", "-o", s(&m)]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("warning (aliasing): "), "{text}");
    assert!(text.contains("warning (no_temperature): "), "{text}");
    assert!(text.contains("\nnext: trueaxis history "), "{text}");
}
