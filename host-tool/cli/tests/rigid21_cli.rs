//! `trueaxis fit --model rigid21` end to end on the simulator's volumetric
//! instruments (docs/volumetric.md): laser lines written as the
//! measurement CSV with set-ups, fitted from the command line; the JSON's
//! `errors` say the tilt cannot be known (no value), `hidden_um` how much
//! that hides and `measure` what to add; MODEL.json reads back and
//! `compare` evaluates it at each row's tool point.

mod common;

use common::{json, run, tmp_dir};
use trueaxis_engine::import;
use trueaxis_engine::model::{FittedModel, ModelFile};
use trueaxis_engine::simulate::instruments::{laser_lines, measure};
use trueaxis_engine::simulate::Machine;

/// The simulator's laser lines at tool 0 and 150 mm (seed 11) fitted with
/// `fit --model rigid21` in a fresh directory: MODEL.json's path and the
/// run.
fn fit_lines(name: &str) -> (std::path::PathBuf, std::process::Output) {
    let dir = tmp_dir("rigid21", name);
    let m = Machine::preset("mill800-21").unwrap();
    let data = measure(&m, &laser_lines(m.travel_mm, &[0.0, 150.0]), 11, true);
    let csv = dir.join("lines.csv");
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    let model = dir.join("lines.model.json");
    let out = run(&[
        "fit",
        csv.to_str().unwrap(),
        "--model",
        "rigid21",
        "-o",
        model.to_str().unwrap(),
        "--json",
    ]);
    (model, out)
}

#[test]
fn laser_lines_fit_says_what_it_cannot_know() {
    let (model, out) = fit_lines("lines");
    let doc = json(&out);
    assert_eq!(doc["kind"], "rigid21");
    let errors = doc["errors"].as_array().unwrap();
    assert_eq!(errors.len(), 23);
    let a0t = errors.iter().find(|e| e["name"] == "A0T").unwrap();
    assert_eq!(a0t["status"], "cannot_know");
    assert!(
        a0t.get("peak").is_none() && a0t.get("coef").is_none(),
        "{a0t}"
    );
    assert!(a0t["hidden_um"].as_f64().unwrap() > 4.0, "{a0t}");
    let exx = errors.iter().find(|e| e["name"] == "EXX").unwrap();
    assert_eq!(exx["status"], "estimated");
    assert!(exx["peak"].as_f64().unwrap() > 1.0, "{exx}");
    assert!(doc["hidden_um"].as_f64().unwrap() > 4.0);
    assert!(doc["measure"]["what"].as_str().is_some(), "{doc}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cannot know") && stderr.contains("A0T"),
        "{stderr}"
    );
    let file = ModelFile::load(&model).unwrap();
    let FittedModel::Rigid21(r) = &file.model else {
        panic!("kind {}", file.model.kind())
    };
    assert!(r.error("A0T").unwrap().coef.is_none());
}

/// A fitted rigid21 model exports as a board table (poly and Abbe blocks,
/// the tool length as the table's tool arm) and passes the accuracy check.
#[test]
fn a_fitted_rigid21_model_exports_as_a_table() {
    let (model, fit) = fit_lines("export");
    assert!(fit.status.success(), "{fit:?}");
    let table = model.with_file_name("t.bin");
    let out = run(&[
        "export",
        model.to_str().unwrap(),
        "-o",
        table.to_str().unwrap(),
        "--json",
    ]);
    assert!(out.status.success(), "{out:?}");
    let doc = json(&out);
    assert_eq!(doc["format"], "table");
    assert!(doc["terms"].as_u64().unwrap() >= 5, "{doc}");
    assert!(doc["max_fixed_error_nm"].as_f64().unwrap() <= 1.0, "{doc}");
    assert_eq!(doc["envelope"]["tool_range_mm"][1], 300.0, "{doc}");
    assert!(table.exists());
}
