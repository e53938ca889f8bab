//! `trueaxis fit` end to end: the JSON of docs/cli.md (only the targets
//! present), MODEL.json written beside the data and read back to the same
//! predictions, every model kind from the command line, and the exit codes —
//! 1 for bad input (too few distinct points, unknown model, bad --add,
//! collinear terms), 2 for usage.

mod common;

use std::path::{Path, PathBuf};

use common::{json, run, s, tmp_dir, with_blank_error_row};
use trueaxis_engine::data::Dataset;
use trueaxis_engine::import;
use trueaxis_engine::model::{FittedModel, ModelFile};

/// [`grid_data`] written to `grid.csv` in a fresh directory for test
/// NAME: (the directory, the file).
fn grid_csv(name: &str) -> (PathBuf, PathBuf) {
    let dir = tmp_dir("fit", name);
    let csv = dir.join("grid.csv");
    write(&grid_data(), &csv);
    (dir, csv)
}

fn write(data: &Dataset, path: &Path) {
    let f = std::fs::File::create(path).unwrap();
    import::write_csv(data, f).unwrap();
}

/// A 9 × 6 × 5 grid (100 / 100 / 50 mm) with ex and ey only; ey has a cell
/// left empty. Deterministic pseudo-noise of ±0.05 µm.
fn grid_data() -> Dataset {
    let (mut x, mut y, mut z, mut ex, mut ey) = (vec![], vec![], vec![], vec![], vec![]);
    let mut r = 0usize;
    for i in 0..9 {
        for j in 0..6 {
            for k in 0..5 {
                let (px, py, pz) = (i as f64 * 100.0, j as f64 * 100.0, k as f64 * 50.0);
                let noise = ((r * 7919) % 101) as f64 / 1000.0 - 0.05;
                x.push(px);
                y.push(py);
                z.push(pz);
                ex.push(Some(
                    2.0 + px * 0.01 - 1e-8 * px * px * px + 0.003 * py + noise,
                ));
                ey.push(if r == 17 {
                    None
                } else {
                    Some(-1.0 + 4e-5 * py * py / 10.0 + 0.002 * px * pz / 100.0 + noise)
                });
                r += 1;
            }
        }
    }
    Dataset {
        source: "grid".into(),
        pos_mm: [Some(x), Some(y), Some(z)],
        err_um: [Some(ex), Some(ey), None],
        ..Default::default()
    }
}

#[test]
fn json_shape_and_model_file_round_trip() {
    let (dir, csv) = grid_csv("shape");
    let out = run(&["fit", csv.to_str().unwrap(), "--model", "cubic19", "--json"]);
    let v = json(&out);
    assert_eq!(v["model"], "cubic19");
    assert_eq!(v["terms"], 19);
    for key in ["rms_um", "held_out_rms_um", "max_abs_um"] {
        let m = v[key]
            .as_object()
            .unwrap_or_else(|| panic!("{key} missing: {v}"));
        let keys: Vec<&str> = m.keys().map(String::as_str).collect();
        assert_eq!(keys, vec!["ex", "ey"], "{key}: only the targets present");
        for val in m.values() {
            assert!(val.as_f64().unwrap() >= 0.0);
        }
    }
    // Noise ±0.05 µm uniform → rms ≈ 0.03 µm; held-out a little above.
    let rms = v["rms_um"]["ex"].as_f64().unwrap();
    assert!(rms > 0.01 && rms < 0.05, "{rms}");
    assert!(v["held_out_rms_um"]["ex"].as_f64().unwrap() >= rms * 0.9);
    assert_eq!(v["rows"]["ey"], 269, "the empty ey cell is not fitted");

    // Default output path: beside the data.
    let model_path = dir.join("grid.csv.model.json");
    assert_eq!(v["model_file"], model_path.to_str().unwrap());
    let m = ModelFile::load(&model_path).unwrap();
    assert_eq!(m.format, trueaxis_engine::model::MODEL_FORMAT);
    assert_eq!(m.data.rows, 270);
    assert_eq!(m.data.sha256.len(), 64);
    // Saving what was loaded gives the same text (floats round-trip
    // exactly); predictions reproduce rms_um.
    let again = dir.join("again.json");
    m.save(&again).unwrap();
    let (a, b) = (
        std::fs::read_to_string(&model_path).unwrap(),
        std::fs::read_to_string(&again).unwrap(),
    );
    assert!(a == b, "MODEL.json changed on load + save");
    let data = import::load(&csv).unwrap();
    let res = m.model.residuals(&data).unwrap();
    let r = res[0].as_ref().unwrap();
    let rms2 = (r.iter().map(|x| x.1 * x.1).sum::<f64>() / r.len() as f64).sqrt();
    assert!((rms2 - rms).abs() < 1e-9, "{rms2} vs {rms}");
    assert!(res[2].is_none());
}

#[test]
fn add_effects_and_output_path() {
    let (dir, csv) = grid_csv("add");
    let model = dir.join("m.json");
    let squareness = [
        "--model",
        "kinematic",
        "--add",
        "squareness:target=ex,axis=y",
        "--add",
        "squareness:target=ey,axis=x",
    ];
    let v = common::fit(&csv, &squareness, &model);
    assert_eq!(
        v["model"],
        "kinematic --add squareness:target=ex,axis=y --add squareness:target=ey,axis=x"
    );
    assert_eq!(v["terms"], 9);
    let m = ModelFile::load(&model).unwrap();
    assert_eq!(m.adds.len(), 2);
    let FittedModel::Linear(lm) = &m.model else {
        panic!("linear expected")
    };
    // ex = … + 0.003·y (µm/mm) → in normalised y (half span 250 mm): 0.75.
    let o = &lm.outputs[0];
    let j = o.features.len() - 1;
    assert!((o.coef_um[j] - 0.75).abs() < 0.02, "{}", o.coef_um[j]);
    assert!(o.coef_sd_um[j] > 0.0 && o.coef_sd_um[j] < 0.02);
}

#[test]
fn every_model_kind_runs_from_the_command_line() {
    let (dir, csv) = grid_csv("kinds");
    for (args, kind) in [
        (vec!["--model", "grid:100"], "grid"),
        (vec!["--model", "cubic19", "--local"], "local"),
        (vec!["--model", "nn:4", "--max-epochs", "30"], "nn"),
    ] {
        let mut a = vec!["fit", csv.to_str().unwrap(), "--json"];
        a.extend(args.iter().copied());
        let v = json(&run(&a));
        assert_eq!(v["kind"], kind, "{v}");
        assert!(v["rms_um"]["ex"].as_f64().is_some(), "{v}");
        assert!(v["held_out_rms_um"]["ey"].as_f64().is_some(), "{v}");
        let m = ModelFile::load(dir.join("grid.csv.model.json")).unwrap();
        let data = import::load(&csv).unwrap();
        let p = m.model.predict(&data).unwrap();
        assert!(p[0].is_some() && p[1].is_some() && p[2].is_none());
    }
    // Human text mode works too and names the output.
    let out = run(&["fit", csv.to_str().unwrap(), "--model", "cubic19"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    common::assert_has(&text, &["held-out", "model written to"]);
}

/// Rows the importer leaves out are said on stderr (with the line and the
/// reason) and counted in the JSON as `skipped_count`.
#[test]
fn rows_left_out_are_counted_and_said() {
    let (dir, csv) = grid_csv("skipped");
    let clean = run(&["fit", csv.to_str().unwrap(), "--model", "cubic19", "--json"]);
    assert_eq!(json(&clean)["skipped_count"], 0);
    assert!(!String::from_utf8_lossy(&clean.stderr).contains("left out"));

    let holed = dir.join("holed.csv");
    let line = with_blank_error_row(&csv, &holed);
    let out = run(&["fit", s(&holed), "--model", "cubic19", "--json"]);
    let v = json(&out);
    assert_eq!(v["skipped_count"], 1);
    assert_eq!(v["rows"]["ex"], 270, "the row is not fitted");
    let err = String::from_utf8_lossy(&out.stderr);
    common::assert_has(
        &err,
        &[&format!(
            "was left out (line {line}: no error value on this row)"
        )],
    );
    // In text mode too.
    let out = run(&["fit", holed.to_str().unwrap(), "--model", "cubic19"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("note: 1 row of"));
}

fn expect_exit(args: &[&str], code: i32, needle: &str) {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}: stderr {err}");
    assert!(
        err.contains(needle),
        "{args:?}: expected `{needle}` in stderr: {err}"
    );
    if code == 1 {
        common::assert_no_document(args, &out);
    }
}

#[test]
fn bad_input_exits_1_and_usage_exits_2() {
    let (dir, csv) = grid_csv("bad");
    let c = csv.to_str().unwrap();
    expect_exit(
        &["fit", c, "--model", "cubic21", "--json"],
        1,
        "unknown model `cubic21`",
    );
    expect_exit(&["fit", c, "--model", "nn:x"], 1, "hidden neurons");
    expect_exit(&["fit", c, "--model", "grid:-5"], 1, "grid step");
    expect_exit(
        &[
            "fit",
            c,
            "--model",
            "cubic19",
            "--add",
            "wobble:target=ex",
            "--json",
        ],
        1,
        "unknown effect family `wobble`",
    );
    expect_exit(
        &[
            "fit",
            c,
            "--model",
            "cubic19",
            "--add",
            "periodic:target=ez,axis=x,period_mm=5",
        ],
        1,
        "no ez_um",
    );
    // cubic19 already holds y; adding it again is collinear, named.
    expect_exit(
        &[
            "fit",
            c,
            "--model",
            "cubic19",
            "--add",
            "squareness:target=ex,axis=y",
        ],
        1,
        "{y, y} are collinear",
    );
    expect_exit(
        &[
            "fit",
            c,
            "--model",
            "cubic19",
            "--add",
            "thermal:target=ex,channel=bed",
        ],
        1,
        "no T_bed_C",
    );
    expect_exit(
        &["fit", s(&dir.join("missing.csv")), "--model", "cubic19"],
        1,
        "missing.csv",
    );

    // Three points on a line, a cubic (4 terms there): too few.
    let line = Dataset {
        source: "line".into(),
        pos_mm: [Some(vec![0.0, 10.0, 20.0, 20.0]), None, None],
        err_um: [
            Some(vec![Some(1.0), Some(2.0), Some(2.5), Some(2.6)]),
            None,
            None,
        ],
        ..Default::default()
    };
    let small = dir.join("line.csv");
    write(&line, &small);
    expect_exit(
        &["fit", s(&small), "--model", "cubic19", "--json"],
        1,
        &format!(
            "{}: cannot fit cubic19: ex: 3 distinct points but the model has 4 terms",
            small.display()
        ),
    );

    // Usage errors: clap's exit code 2.
    expect_exit(&["fit", c], 2, "--model");
    // No training at all is refused, not quietly turned into 1 epoch.
    expect_exit(
        &["fit", c, "--model", "nn:4", "--max-epochs", "0"],
        2,
        "invalid value '0' for '--max-epochs <MAX_EPOCHS>'",
    );
    expect_exit(
        &["fit", c, "--model", "cubic19", "--blocks", "1"],
        2,
        "blocks",
    );
}

#[test]
fn the_text_gives_each_targets_term_count_when_they_differ() {
    // Issue 28: "21 terms per target" when ey and ez had 19.
    let dir = common::tmp_dir("fit", "terms");
    let csv = dir.join("d.csv");
    common::json(&common::run(&[
        "simulate",
        "--plan",
        "grid:100",
        "--plan",
        "line:x:5,bidir",
        "--seed",
        "4",
        "-o",
        s(&csv),
        "--json",
    ]));
    let out = common::run(&[
        "fit",
        s(&csv),
        "--model",
        "cubic19",
        "--add",
        "reversal:target=ex,axis=x",
        "-o",
        s(&dir.join("m.json")),
    ]);
    common::assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    let first = text.lines().next().unwrap();
    assert!(
        first.contains("terms per target ex 20, ey 19, ez 19"),
        "{first}"
    );
    assert!(first.contains(" rows, "), "{first}");
    assert!(text.contains("\nnext: trueaxis compare "), "{text}");
}

#[test]
fn a_json_error_is_a_json_document_on_stdout() {
    // Issue 28: `--json` errors wrote nothing to stdout, so a script
    // reading it got no document at all.
    for (args, code) in [
        (
            &["fit", "no-such.csv", "--model", "cubic19", "--json"][..],
            1,
        ),
        (&["fit", "--no-such-flag", "--json"][..], 2),
    ] {
        let out = run(args);
        assert_eq!(out.status.code(), Some(code), "{args:?}");
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{args:?}: {e}: {}", String::from_utf8_lossy(&out.stdout)));
        assert_eq!(doc["exit_code"], code, "{doc}");
        assert!(
            doc["error"].as_str().is_some_and(|e| !e.is_empty()),
            "{doc}"
        );
    }
    // Without --json an error stays on stderr only.
    let out = run(&["fit", "no-such.csv", "--model", "cubic19"]);
    assert!(out.stdout.is_empty());
}
