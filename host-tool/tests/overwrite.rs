//! No command writes over its own input (the user test's R6: `fit r6.csv
//! -o r6.csv` replaced the measurements with model JSON, exit 0; `export
//! m.json -o m.json` replaced the model with the table). Each is refused
//! with exit 1 before anything is written, and the input is unchanged.

mod common;

use std::path::Path;

use common::{expect_exit, fit_cubic19, s, tmp_dir};

const CSV: &str = "x_mm,ex_um\n0,1\n100,2\n200,1.5\n300,0.5\n400,-1\n500,-2\n";

fn unchanged(p: &Path, was: &str) {
    assert_eq!(
        std::fs::read_to_string(p).unwrap(),
        was,
        "{p:?} was changed"
    );
}

#[test]
fn fit_improve_and_import_refuse_to_write_over_the_data() {
    let dir = tmp_dir("overwrite", "data");
    let csv = dir.join("r6.csv");
    std::fs::write(&csv, CSV).unwrap();
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
        &[
            "improve",
            s(&csv),
            "--model",
            "cubic19",
            "-o",
            s(&csv),
            "--json",
        ],
        1,
        &[&msg],
    );
    unchanged(&csv, CSV);
    // Another spelling of the same path.
    let other = dir.join(".").join("r6.csv");
    expect_exit(
        &[
            "fit",
            s(&csv),
            "--model",
            "cubic19",
            "-o",
            s(&other),
            "--json",
        ],
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
    let hist = dir.join("h.history.json");
    std::fs::write(&hist, CSV).unwrap();
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
    let csv = dir.join("d.csv");
    std::fs::write(&csv, CSV).unwrap();
    let model = dir.join("m.json");
    fit_cubic19(&csv, &model);
    let text = std::fs::read_to_string(&model).unwrap();
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
