//! No command writes over its own input (the user test's R6: `fit r6.csv
//! -o r6.csv` replaced the measurements with model JSON, exit 0; `export
//! m.json -o m.json` replaced the model with the table). Each is refused
//! with exit 1 before anything is written, and the input is unchanged.

mod common;

use std::path::{Path, PathBuf};

use common::{expect_exit, fit_cubic19, s, tmp_dir};

const CSV: &str = "x_mm,ex_um\n0,1\n100,2\n200,1.5\n300,0.5\n400,-1\n500,-2\n";

fn unchanged(p: &Path, was: &str) {
    assert_eq!(
        std::fs::read_to_string(p).unwrap(),
        was,
        "{p:?} was changed"
    );
}

/// CSV in `DIR/d.csv` fitted with cubic19 to `DIR/m.json`: (data, model,
/// the model file's text).
fn fitted(dir: &Path) -> (PathBuf, PathBuf, String) {
    let csv = common::file_in(dir, "d.csv", CSV);
    let model = dir.join("m.json");
    fit_cubic19(&csv, &model);
    let text = std::fs::read_to_string(&model).unwrap();
    (csv, model, text)
}

#[test]
fn fit_improve_and_import_refuse_to_write_over_the_data() {
    let dir = tmp_dir("overwrite", "data");
    let csv = common::file_in(&dir, "r6.csv", CSV);
    let msg = format!(
        "-o {} is the data file {}: writing it would destroy the input; nothing was written — choose another output path",
        s(&csv),
        s(&csv)
    );
    expect_exit(
        &["fit", s(&csv), "--model", "cubic19", "-o", s(&csv)],
        1,
        &[&msg],
    );
    unchanged(&csv, CSV);
    expect_exit(
        &common::cubic19_args("improve", &csv, &csv, &["--json"]),
        1,
        &[&msg],
    );
    unchanged(&csv, CSV);
    // Another spelling of the same path.
    let other = dir.join(".").join("r6.csv");
    expect_exit(
        &common::cubic19_args("fit", &csv, &other, &["--json"]),
        1,
        &["is the data file", "nothing was written"],
    );
    unchanged(&csv, CSV);
    expect_exit(
        &["import", s(&csv), "-o", s(&csv)],
        1,
        &[&format!("-o {} is the input file {}", s(&csv), s(&csv))],
    );
    unchanged(&csv, CSV);
    // The history file fit keeps beside the model: `-o h.json` writes
    // h.history.json, which here is the data.
    let hist = common::file_in(&dir, "h.history.json", CSV);
    let model = dir.join("h.json");
    expect_exit(
        &["fit", s(&hist), "--model", "cubic19", "-o", s(&model)],
        1,
        &[&format!(
            "the history file {} is the data file {}",
            s(&hist),
            s(&hist)
        )],
    );
    unchanged(&hist, CSV);
    assert!(!model.exists(), "no model written either");
}

#[test]
fn export_refuses_to_write_over_the_model() {
    let dir = tmp_dir("overwrite", "export");
    let (_, model, text) = fitted(&dir);
    let msg = format!("-o {} is the model file {}", s(&model), s(&model));
    expect_exit(
        &["export", s(&model), "-o", s(&model), "--json"],
        1,
        &[&msg],
    );
    unchanged(&model, &text);
    #[cfg(unix)]
    {
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&model, &link).unwrap();
        expect_exit(
            &["export", s(&model), "-o", s(&link), "--format", "linuxcnc"],
            1,
            &["is the model file", "nothing was written"],
        );
        unchanged(&model, &text);
    }
}

#[test]
fn a_damaged_history_stops_the_fit_before_anything_is_written() {
    // MODEL.history.json that is not a history used to be replaced
    // silently by a new one; a history that could not be written (here a
    // directory in its place) left m.json written without its step.
    let dir = tmp_dir("overwrite", "history");
    let (csv, model, text) = fitted(&dir);
    let hist = common::file_in(&dir, "m.history.json", "garbage\n");
    let want = format!(
        "the history beside {} cannot be continued; move {} away (a new history then starts) or choose another -o — nothing was written: {}: not a trueaxis history file",
        s(&model),
        s(&hist),
        s(&hist)
    );
    for cmd in ["fit", "improve"] {
        expect_exit(
            &[cmd, s(&csv), "--model", "cubic19", "-o", s(&model)],
            1,
            &[&want],
        );
        unchanged(&model, &text);
        unchanged(&hist, "garbage\n");
    }
    // Moved away, the next fit starts a new history.
    std::fs::remove_file(&hist).unwrap();
    fit_cubic19(&csv, &model);
    let h: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&hist).unwrap()).unwrap();
    assert_eq!(h["steps"].as_array().unwrap().len(), 1);

    // A directory where the history goes: no model file either.
    let m2 = dir.join("m2.json");
    std::fs::create_dir(dir.join("m2.history.json")).unwrap();
    expect_exit(
        &["fit", s(&csv), "--model", "cubic19", "-o", s(&m2)],
        1,
        &["the history beside", "nothing was written"],
    );
    assert!(!m2.exists(), "no model without its history step");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}
