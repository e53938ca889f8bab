//! Auxiliary columns are "kept and reported" (docs/cli.md § Measurement CSV): `fit`,
//! `improve` and `diagnose` say which columns of the data no model uses,
//! in text and JSON, and name the contract column a misspelled one
//! probably meant (the user test's R5: `ey [um]` and `T_bed` were kept as
//! auxiliary channels without a word, the fit ran on ex only). A contract
//! name in the wrong case (`dir_X`) is refused like `X_mm`.

mod common;

use std::path::{Path, PathBuf};

use common::{expect_exit, fit_cubic19, json, run, s, simulate_grid, tmp_dir};
use serde_json::Value;

const MEANT: &str = "columns are kept as auxiliary and not fitted, though the name looks like a contract column written another way: `ey [um]` (probably `ey_um`), `T_bed` (probably `T_bed_C`) — rename the header to the contract name to use it";
const OTHER: &str = "auxiliary column is kept, not used by any model: `feed`";

/// The simulated grid with `ey_um` written `ey [um]` and two more
/// columns, `T_bed` (a temperature without its unit) and `feed`.
fn spreadsheet_csv(dir: &Path) -> PathBuf {
    let src = simulate_grid(dir, "grid.csv", 1);
    let text = std::fs::read_to_string(&src).unwrap();
    let mut out = String::new();
    let mut header = true;
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if header {
            out.push_str(&line.replace("ey_um", "ey [um]"));
            out.push_str(",T_bed,feed");
            header = false;
        } else {
            out.push_str(line);
            out.push_str(",20.5,1000");
        }
        out.push('\n');
    }
    common::file_in(dir, "sheet.csv", out)
}

#[test]
fn a_contract_name_in_the_wrong_case_is_refused_like_x_mm() {
    let dir = tmp_dir("aux", "case");
    let csv = common::file_in(
        &dir,
        "r5.csv",
        "x_mm,ex_um,ey [um],T_bed,dir_X\n0,1,3,20,1\n100,2,4,20.5,1\n200,1.5,5,21,1\n300,0.5,6,21.5,-1\n400,-1,7,22,-1\n500,-2,8,22.5,-1\n",
    );
    let msg = format!(
        "{}:1:5: column `dir_X`: expected `dir_x` (column names are case-sensitive)",
        s(&csv)
    );
    expect_exit(
        &common::cubic19_args("fit", &csv, &dir.join("m.json"), &[]),
        1,
        &[&msg],
    );
    expect_exit(&["import", s(&csv), "--json"], 1, &[&msg]);
    expect_exit(&["diagnose", s(&csv), "--model", "cubic19"], 1, &[&msg]);
}

fn warnings_with_code(doc: &Value) -> Vec<(String, String)> {
    doc["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| {
            (
                w["code"].as_str().unwrap().to_string(),
                w["detail"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn fit_diagnose_and_improve_report_aux_columns_and_what_they_probably_meant() {
    let dir = tmp_dir("aux", "report");
    let csv = spreadsheet_csv(&dir);
    let src = s(&csv);
    let meant = format!("{src}: {MEANT}");
    let other = format!("{src}: {OTHER}");

    // fit: its warnings are strings, the code first; stderr in both modes.
    let model = dir.join("m.json");
    let out = run(&["fit", src, "--model", "cubic19", "-o", s(&model), "--json"]);
    let doc = json(&out);
    let w = common::strs(&doc["warnings"]);
    assert!(
        w.contains(&format!("aux_misspelled: {meant}").as_str()),
        "{w:?}"
    );
    assert!(
        w.contains(&format!("aux_columns: {other}").as_str()),
        "{w:?}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("warning: aux_misspelled: {meant}")),
        "{err}"
    );
    // The fit used ex and ez only: `ey [um]` is not a target.
    assert_eq!(
        doc["rms_um"]
            .as_object()
            .unwrap()
            .keys()
            .collect::<Vec<_>>(),
        ["ex", "ez"]
    );
    let out = run(&["fit", src, "--model", "cubic19", "-o", s(&model)]);
    assert!(out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains(&format!("warning: aux_columns: {other}"))
    );

    // diagnose: {code, detail} in `warnings`; the text lists them.
    let doc = json(&run(&["diagnose", src, "--model", "cubic19", "--json"]));
    let w = warnings_with_code(&doc);
    assert!(
        w.contains(&("aux_misspelled".into(), meant.clone())),
        "{w:?}"
    );
    assert!(w.contains(&("aux_columns".into(), other.clone())), "{w:?}");
    let out = run(&["diagnose", src, "--model", "cubic19"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!("[aux_misspelled] {meant}")),
        "{text}"
    );

    // improve: `warnings` as diagnose's, and on stderr as `warning (code)`.
    let out = run(&[
        "improve",
        src,
        "--model",
        "cubic19",
        "-o",
        s(&dir.join("i.json")),
        "--json",
    ]);
    let doc = json(&out);
    // The data's warnings first; the last diagnosis' design warnings
    // (aliasing, no_temperature, …) follow them (issue 28).
    let w: Vec<(String, String)> = warnings_with_code(&doc)
        .into_iter()
        .take_while(|(code, _)| code.starts_with("aux_"))
        .collect();
    assert_eq!(
        w,
        vec![
            ("aux_misspelled".to_string(), meant.clone()),
            ("aux_columns".to_string(), other.clone())
        ]
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("warning (aux_misspelled): {meant}")),
        "{err}"
    );
    assert!(
        err.contains(&format!("warning (aux_columns): {other}")),
        "{err}"
    );
}

#[test]
fn data_without_aux_columns_gets_no_aux_warning() {
    let dir = tmp_dir("aux", "none");
    let csv = simulate_grid(&dir, "grid.csv", 2);
    let doc = fit_cubic19(&csv, &dir.join("m.json"));
    assert!(
        !doc["warnings"].to_string().contains("aux_"),
        "{}",
        doc["warnings"]
    );
    let doc = json(&common::cubic19("improve", &csv, &dir.join("i.json"), &[]));
    // No aux warning; the design warnings of the last diagnosis only.
    let codes = common::warning_codes(&doc);
    assert!(codes.iter().all(|c| !c.starts_with("aux_")), "{codes:?}");
    assert!(codes.contains(&"no_temperature"), "{codes:?}");
}
