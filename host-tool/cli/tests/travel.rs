//! The travel a model is fitted on (docs/cli.md § fit, "Travel"): the
//! machine's, given with `--travel`, or the data's bulk — never widened by
//! one stray row. The case: one row at x = 1999 mm in 0–800 mm data
//! made `fit` and `export` exit 0 with no warning, the table's travel
//! 0–1999 mm and its max-correction clamp 5× higher. Now the row is named
//! (file, line, position, the model's miss there), left out, and every
//! export of the model names it again; `--travel` keeps it. Legitimate
//! sparse data — a coarse grid, a single line, an ISO 230-2 run, a dense
//! line in a coarse grid — have no stray.

mod common;

use std::path::{Path, PathBuf};

use common::{expect_exit, export, fit, json, run, s, simulate_grid, tmp_dir};
use serde_json::Value;

/// `src` with one more row: the last row's values at x = `x_mm`. Returns
/// the new row's line.
fn with_row_at_x(src: &Path, dst: &Path, x_mm: &str) -> usize {
    let text = std::fs::read_to_string(src).unwrap();
    let last = text.lines().last().unwrap();
    let rest = last.split_once(',').unwrap().1;
    std::fs::write(dst, format!("{text}{x_mm},{rest}\n")).unwrap();
    text.lines().count() + 1
}

/// The fit's `outside_travel` warnings (strings starting so).
fn travel_warnings(fit: &Value) -> Vec<String> {
    fit["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w.as_str())
        .filter(|w| w.starts_with("outside_travel"))
        .map(String::from)
        .collect()
}

/// (data, stray data, stray line) in `dir`.
fn stray_case(dir: &Path) -> (PathBuf, PathBuf, usize) {
    let clean = simulate_grid(dir, "d.csv", 3);
    let stray = dir.join("s.csv");
    let line = with_row_at_x(&clean, &stray, "1999");
    (clean, stray, line)
}

#[test]
fn a_stray_row_is_named_left_out_and_does_not_widen_the_table() {
    let dir = tmp_dir("travel", "stray");
    let (clean, stray, line) = stray_case(&dir);
    let c19 = ["--model", "cubic19"];
    let f_clean = fit(&clean, &c19, &dir.join("d.json"));
    let f_stray = fit(&stray, &c19, &dir.join("s.json"));
    // Named: file, line, position, the travel, the model's miss there, the
    // flag that keeps it.
    let w = travel_warnings(&f_stray);
    assert_eq!(w.len(), 1, "{w:?}");
    let expected = format!(
        "outside_travel: 1 row lies outside the travel and was left out of the fit: {}:{line}: x = 1999 mm, outside the travel x 0…800 mm (the data's bulk); the model fitted without it misses it by ex ",
        stray.display()
    );
    assert!(w[0].starts_with(&expected), "{}", w[0]);
    assert!(w[0].ends_with(" — --travel x=0..1999 keeps it"), "{}", w[0]);
    let o = &f_stray["outside_travel"][0];
    assert_eq!(o["line"], line);
    assert_eq!(o["row"], 324);
    assert_eq!(o["axis"], "x");
    assert_eq!(o["position_mm"], 1999.0);
    assert_eq!(o["rule"], "bulk");
    // The model extrapolated 1199 mm misses the row (its values are those
    // of a row at x = 0) by far more than the noise.
    assert!(o["resid_um"]["ex"].as_f64().unwrap().abs() > 10.0, "{o}");
    // Left out: the fit is the clean data's, held-out figures and all.
    assert_eq!(f_stray["held_out_rms_um"], f_clean["held_out_rms_um"]);
    assert!(travel_warnings(&f_clean).is_empty());
    assert_eq!(f_clean["outside_travel"], serde_json::json!([]));
    // The table: the clean data's envelope, and the row named again.
    let t_clean = export(&dir.join("d.json"), &[], &dir.join("d.bin"));
    let t_stray = export(&dir.join("s.json"), &[], &dir.join("s.bin"));
    assert_eq!(t_stray["envelope"], t_clean["envelope"]);
    assert_eq!(
        t_stray["envelope"]["travel_mm"][0],
        serde_json::json!([0.0, 800.0])
    );
    let w = common::find_warning(&t_stray, "outside_travel").expect("export warns");
    assert!(
        w["detail"].as_str().unwrap().contains(&format!(
            "{}:{line}: x = 1999 mm, outside the travel x 0…800 mm",
            stray.display()
        )),
        "{w}"
    );
    // Every format names it: a controller file too.
    let lc = export(
        &dir.join("s.json"),
        &["--format", "linuxcnc", "--axis", "x"],
        &dir.join("s.comp"),
    );
    assert!(common::find_warning(&lc, "outside_travel").is_some());
    assert_eq!(lc["max_mm"], 800.0);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_users_travel_keeps_the_row_or_cuts_where_it_says() {
    let dir = tmp_dir("travel", "given");
    let (_, stray, line) = stray_case(&dir);
    // The machine reaches 2000 mm: the row is the user's, and the table's.
    let f = fit(
        &stray,
        &["--model", "cubic19", "--travel", "x=0..2000"],
        &dir.join("kept.json"),
    );
    assert!(travel_warnings(&f).is_empty());
    assert_eq!(f["outside_travel"], serde_json::json!([]));
    let t = export(&dir.join("kept.json"), &[], &dir.join("kept.bin"));
    assert_eq!(
        t["envelope"]["travel_mm"][0],
        serde_json::json!([0.0, 1999.0])
    );
    // A travel narrower than the data: every row beyond it is named.
    let f = fit(
        &stray,
        &[
            "--model",
            "cubic19",
            "--travel",
            "x=0..700",
            "--travel",
            "y=-1..600",
        ],
        &dir.join("narrow.json"),
    );
    let out = f["outside_travel"].as_array().unwrap();
    // 36 rows at x = 800 and the stray.
    assert_eq!(out.len(), 37);
    assert!(out.iter().all(|o| o["rule"] == "given"));
    assert_eq!(out.last().unwrap()["line"], line);
    let w = travel_warnings(&f);
    assert!(
        w[0].starts_with(
            "outside_travel: 37 rows lie outside the travel and were left out of the fit: "
        ),
        "{}",
        w[0]
    );
    assert!(
        w[0].contains("; and 34 more — --travel x=0..1999 keeps them"),
        "{}",
        w[0]
    );
    // Refused: an axis the data lacks, a travel no row is in, bad syntax.
    let m = dir.join("m.json");
    for (travel, msg) in [
        ("x=900..1000", "every row lies outside --travel x=900..1000"),
        ("x=5..1", "--travel x `5..1`: expected finite LO ≤ HI"),
        (
            "w=0..1",
            "--travel `w=0..1`: expected AXIS=LO..HI with AXIS x, y or z",
        ),
        ("x=0-800", "--travel x `0-800`: expected LO..HI"),
    ] {
        expect_exit(
            &[
                "fit",
                s(&stray),
                "--model",
                "cubic19",
                "--travel",
                travel,
                "-o",
                s(&m),
            ],
            1,
            &[msg],
        );
    }
    assert!(!m.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn improve_leaves_the_stray_row_out_of_every_step() {
    let dir = tmp_dir("travel", "improve");
    let (_, stray, line) = stray_case(&dir);
    let out = common::cubic19("improve", &stray, &dir.join("imp.json"), &[]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let v = json(&out);
    assert_eq!(v["outside_travel"][0]["line"], line);
    assert!(common::find_warning(&v, "outside_travel").is_some(), "{v}");
    common::assert_has(
        &err,
        &[&format!(
            "warning (outside_travel): 1 row lies outside the travel and was left out of the fit: {}:{line}: x = 1999 mm",
            stray.display()
        )],
    );
    let t = export(&dir.join("imp.json"), &[], &dir.join("imp.bin"));
    assert_eq!(
        t["envelope"]["travel_mm"][0],
        serde_json::json!([0.0, 800.0])
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sparse_plans_have_no_stray() {
    let dir = tmp_dir("travel", "sparse");
    let plans: &[(&[&str], &str)] = &[
        // A coarse grid (5 × 3 × 3 planes) measured three times: 135 rows.
        (
            &[
                "--plan", "grid:200", "--plan", "grid:200", "--plan", "grid:200",
            ],
            "grid:200",
        ),
        // A single line, both ways.
        (&["--plan", "line:x:5,bidir"], "cubic19"),
        // An ISO 230-2 run.
        (&["--plan", "iso230:x"], "cubic19"),
        // A dense line in a coarse grid.
        (
            &["--plan", "grid:100", "--plan", "line:y:0.5,bidir"],
            "cubic19",
        ),
    ];
    for (i, (plan, model)) in plans.iter().enumerate() {
        let csv = dir.join(format!("p{i}.csv"));
        let mut args = vec!["simulate"];
        args.extend_from_slice(plan);
        args.extend_from_slice(&["-o", s(&csv), "--json"]);
        json(&run(&args));
        let f = fit(&csv, &["--model", model], &dir.join(format!("p{i}.json")));
        assert_eq!(f["outside_travel"], serde_json::json!([]), "{plan:?}");
        assert!(travel_warnings(&f).is_empty(), "{plan:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
