//! MODEL.json is checked completely when it is read (`ModelFile::load`,
//! the one place compare, export and improve read it): a damaged or
//! hand-edited file is refused with exit 1, the file named, the JSON path
//! of the bad field and what was expected — never a panic (a target index 7
//! used to index out of bounds), never a NaN model that compares as
//! "predicts nothing" or exports as a table (a zero half span), never a
//! silently different model (a coefficient list cut short).
//!
//! And what `fit` writes still loads: every kind, on 3-D grid data, on data
//! where only x varies (y, z constant), and on data without y_mm/z_mm.
//!
//! A file whose content is not what `fit` wrote — a flipped bit that
//! leaves every field valid — is refused by its checksum (16 of 300
//! single-bit flips used to export a different table with exit 0); a file
//! without one (an older trueaxis) loads with a note.

mod common;

use std::path::{Path, PathBuf};

use common::{expect_exit, grid_cubic19, json, run, s, simulate_grid, tmp_dir};
use serde_json::Value;
use trueaxis_engine::model::ModelFile;

/// `trueaxis simulate --plan PLAN -o DIR/NAME`.
fn simulate(dir: &Path, name: &str, plan: &str) -> PathBuf {
    let csv = dir.join(name);
    json(&run(&["simulate", "--plan", plan, "-o", s(&csv), "--json"]));
    csv
}

/// `trueaxis fit CSV --model SPEC [extra] -o MODEL`; returns MODEL.
fn fit(csv: &Path, spec: &str, extra: &[&str], model: &Path) -> PathBuf {
    let mut args = vec!["fit", s(csv), "--model", spec, "-o", s(model), "--json"];
    args.extend_from_slice(extra);
    json(&run(&args));
    model.to_path_buf()
}

/// Writes `model`, changed by `edit`, to `dst` — as a deliberate edit
/// does, without the checksum (docs/cli.md § fit, MODEL.json), so that
/// what is checked is the edited field.
fn damaged(model: &Path, dst: &Path, edit: impl FnOnce(&mut Value)) -> PathBuf {
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(model).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("checksum_sha256");
    edit(&mut v);
    std::fs::write(dst, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    dst.to_path_buf()
}

/// An edit setting the value at JSON pointer `ptr` to `to`.
fn set(ptr: &'static str, to: Value) -> impl FnOnce(&mut Value) {
    move |v| *v.pointer_mut(ptr).unwrap_or_else(|| panic!("no {ptr}")) = to
}

/// `ModelFile::load`'s error (the whole chain) for a model damaged by `edit`.
fn load_error(model: &Path, dir: &Path, edit: impl FnOnce(&mut Value)) -> String {
    let p = damaged(model, &dir.join("damaged.json"), edit);
    match ModelFile::load(&p) {
        Ok(_) => panic!("a damaged model loaded"),
        Err(e) => format!("{e:#}"),
    }
}

fn assert_refused(model: &Path, dir: &Path, edit: impl FnOnce(&mut Value), needles: &[&str]) {
    let e = load_error(model, dir, edit);
    assert!(
        e.contains("damaged.json: not a valid trueaxis model file: "),
        "{e}"
    );
    for n in needles {
        assert!(e.contains(n), "expected `{n}` in: {e}");
    }
}

#[test]
fn out_of_range_target_is_an_error_not_a_panic() {
    // The user test's R2: `"target": 7` in model.outputs[0].
    let dir = tmp_dir("model-file", "target");
    let rows = "x_mm,ex_um\n0,1\n100,2\n200,1.5\n300,0.5\n400,-1\n500,-2\n";
    let csv = common::file_in(&dir, "r2.csv", rows);
    let model = fit(&csv, "cubic19", &[], &dir.join("r2.json"));
    let bad = damaged(
        &model,
        &dir.join("r2_bad.json"),
        set("/model/outputs/0/target", 7.into()),
    );
    let msg = [
        "r2_bad.json: not a valid trueaxis model file: model.outputs[0].target: 7, expected 0 (ex), 1 (ey), 2 (ez)",
    ];
    let bin = dir.join("r2.bin");
    expect_exit(&["export", s(&bad), "-o", s(&bin), "--json"], 1, &msg);
    assert!(!bin.exists());
    expect_exit(&["compare", s(&csv), "--model", s(&bad), "--json"], 1, &msg);
    expect_exit(
        &["diagnose", s(&csv), "--model", s(&bad), "--json"],
        1,
        &msg,
    );
    // A target given twice is as bad.
    let two = damaged(&model, &dir.join("two.json"), |v| {
        let o = v["model"]["outputs"][0].clone();
        v["model"]["outputs"].as_array_mut().unwrap().push(o);
    });
    expect_exit(
        &["compare", s(&csv), "--model", s(&two)],
        1,
        &["model.outputs[1].target: 0 (ex) appears twice"],
    );
}

#[test]
fn zero_span_and_short_coefficient_list_are_refused_by_every_reader() {
    // The user test's R3: half_span 0 made every prediction NaN (compare
    // exit 0 "predicts nothing", export wrote a table with error 0.0 nm);
    // 5 of 19 coefficients exported a different model.
    let dir = tmp_dir("model-file", "r3");
    let (csv, model, _) = grid_cubic19(&dir, "r3", 1);
    let zero = damaged(
        &model,
        &dir.join("zero.json"),
        set("/model/norm/half_span_mm/0", 0.0.into()),
    );
    let short = damaged(&model, &dir.join("short.json"), |v| {
        v["model"]["outputs"][0]["coef_um"]
            .as_array_mut()
            .unwrap()
            .truncate(5);
    });
    let zero_msg = "zero.json: not a valid trueaxis model file: model.norm.half_span_mm[0]: 0, expected a positive number of mm";
    let short_msg = "short.json: not a valid trueaxis model file: model.outputs[0].coef_um: 5 entries, expected 19 (one per feature)";
    for (bad, msg) in [(&zero, zero_msg), (&short, short_msg)] {
        let bin = dir.join("t.bin");
        expect_exit(&["export", s(bad), "-o", s(&bin), "--json"], 1, &[msg]);
        assert!(!bin.exists(), "no table from a damaged model");
        expect_exit(
            &["compare", s(&csv), "--model", s(bad), "--json"],
            1,
            &[msg],
        );
        expect_exit(
            &[
                "export",
                s(bad),
                "-o",
                s(&dir.join("t.cnc")),
                "--format",
                "linuxcnc",
                "--axis",
                "x",
            ],
            1,
            &[msg],
        );
    }
}

#[test]
fn linear_model_fields_are_checked_with_their_json_path() {
    let dir = tmp_dir("model-file", "linear");
    let csv = simulate_grid(&dir, "g.csv", 2);
    let model = fit(
        &csv,
        "cubic19",
        &["--add", "periodic:target=ey,axis=y,period_mm=7.3"],
        &dir.join("m.json"),
    );
    ModelFile::load(&model).expect("fit's own model loads");
    let cases: Vec<(&'static str, Value, &str)> = vec![
        (
            "/model/norm/half_span_mm/2",
            (-250.0).into(),
            "model.norm.half_span_mm[2]: -250, expected a positive number",
        ),
        (
            "/model/outputs/0/coef_sd_um",
            serde_json::json!([1.0]),
            "model.outputs[0].coef_sd_um: 1 entries, expected 19",
        ),
        (
            "/model/outputs/0/features",
            serde_json::json!([]),
            "model.outputs[0].features: empty",
        ),
        (
            "/model/outputs",
            serde_json::json!([]),
            "model.outputs: empty",
        ),
        (
            "/model/outputs/1/features/19/period_mm",
            0.0.into(),
            "model.outputs[1].features[19].period_mm: 0, expected a positive number of mm",
        ),
        (
            "/model/outputs/1/features/19/axis",
            3.into(),
            "model.outputs[1].features[19].axis: 3, expected 0 (x), 1 (y), 2 (z)",
        ),
        (
            "/adds/0",
            "periodic:target=ey".into(),
            "adds[0]: bad effect `periodic:target=ey`: missing `axis=`",
        ),
        ("/seed", "cubic91".into(), "seed: unknown model `cubic91`"),
        (
            "/data/temp_range_c",
            serde_json::json!({"bed": [25.0, 20.0]}),
            "data.temp_range_c.bed: [25, 20], expected finite °C, low ≤ high",
        ),
        (
            "/seed",
            "nn:8".into(),
            "seed `nn:8` with 1 --add effects does not describe the model of kind `linear`",
        ),
    ];
    for (ptr, to, msg) in cases {
        assert_refused(&model, &dir, set(ptr, to), &[msg]);
    }
}

#[test]
fn nn_grid_and_local_fields_are_checked() {
    let dir = tmp_dir("model-file", "kinds");
    let csv = simulate_grid(&dir, "g.csv", 3);
    let nn = fit(&csv, "nn:4", &["--max-epochs", "3"], &dir.join("nn.json"));
    let grid = fit(&csv, "grid:100", &[], &dir.join("grid.json"));
    let local = fit(&csv, "cubic19", &["--local"], &dir.join("local.json"));
    for m in [&nn, &grid, &local] {
        ModelFile::load(m).expect("fit's own model loads");
    }
    let nn_cases: Vec<(&'static str, Value, &str)> = vec![
        (
            "/model/w1",
            serde_json::json!([0.5]),
            "model.w1: 1 entries, expected 12 (hidden × inputs)",
        ),
        (
            "/model/b2",
            serde_json::json!([0.0]),
            "model.b2: 1 entries, expected 3 (one per output)",
        ),
        (
            "/model/inputs/0",
            5.into(),
            "model.inputs[0]: 5, expected 0 (x), 1 (y), 2 (z)",
        ),
        (
            "/model/outputs/1",
            0.into(),
            "model.outputs[1]: 0 (ex) appears twice",
        ),
        (
            "/model/in_max_mm/0",
            (-1.0).into(),
            "model.in_max_mm[0]: -1, expected ≥ in_min_mm[0] = 0",
        ),
        (
            "/model/hidden",
            5.into(),
            "seed `nn:4` does not describe the model of kind `nn`",
        ),
    ];
    for (ptr, to, msg) in nn_cases {
        assert_refused(&nn, &dir, set(ptr, to), &[msg]);
    }
    let grid_cases: Vec<(&'static str, Value, &str)> = vec![
        (
            "/model/counts/0",
            1.into(),
            "model.counts[0]: 1, expected at least 2 nodes",
        ),
        (
            "/model/counts/1",
            7.into(),
            "model.outputs[0].values_um: 324 entries, expected 378 (one per node",
        ),
        (
            "/model/origin_mm",
            serde_json::json!([0.0]),
            "model.origin_mm: 1 entries, expected 3 (one per grid axis)",
        ),
        (
            "/model/axes/2",
            0.into(),
            "model.axes[2]: 0 (x) appears twice",
        ),
        (
            "/model/outputs/2/target",
            9.into(),
            "model.outputs[2].target: 9, expected 0 (ex)",
        ),
        (
            "/model/step_mm",
            0.0.into(),
            "does not describe the model of kind `grid`",
        ),
    ];
    for (ptr, to, msg) in grid_cases {
        assert_refused(&grid, &dir, set(ptr, to), &[msg]);
    }
    // A grid whose node count overflows usize is refused, not multiplied.
    assert_refused(
        &grid,
        &dir,
        set(
            "/model/counts",
            serde_json::json!([4294967296u64, 4294967296u64, 2]),
        ),
        &["model.counts: [4294967296, 4294967296, 2], expected at most 2000000 nodes"],
    );
    let local_cases: Vec<(&'static str, Value, &str)> = vec![
        (
            "/model/shape",
            "sphere".into(),
            "model.shape: `sphere`, expected cuboid, plane or line",
        ),
        (
            "/model/planes_mm",
            serde_json::json!([0.0, 100.0]),
            "model.patches: 5 entries, expected 1 (one per pair of neighbouring planes)",
        ),
        (
            "/model/planes_mm/1",
            0.0.into(),
            "model.planes_mm: [0.0, 0.0, 200.0",
        ),
        (
            "/model/stack_axis",
            Value::Null,
            "model.stack_axis: null, expected the axis",
        ),
        (
            "/model/patches/1/outputs/0/target",
            1.into(),
            "model.patches[1].outputs[1].target: 1 (ey) appears twice",
        ),
        (
            "/seed",
            "cubic19".into(),
            "seed `cubic19` does not describe the model of kind `local`",
        ),
    ];
    for (ptr, to, msg) in local_cases {
        assert_refused(&local, &dir, set(ptr, to), &[msg]);
    }
}

#[test]
fn every_kind_fitted_where_only_x_varies_loads() {
    // A line along x (both directions) at y = z = 250 mm, and the same data
    // without y_mm/z_mm columns: the axes not fitted are written as `fit`
    // writes them (norm half span 0.001 mm at the held position, or centre
    // 0 and half span 1 when absent; no grid or network axis along them),
    // and the file must load.
    let dir = tmp_dir("model-file", "line");
    let csv = simulate(&dir, "line.csv", "line:x:5,bidir");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| header[i] != "y_mm" && header[i] != "z_mm")
        .collect();
    let pick = |l: &str| {
        let f: Vec<&str> = l.split(',').collect();
        keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
    };
    let mut out = pick(&header.join(","));
    for l in lines {
        out.push('\n');
        out.push_str(&pick(l));
    }
    let xonly = common::file_in(&dir, "xonly.csv", out + "\n");
    for data in [&csv, &xonly] {
        for (i, (spec, extra)) in [
            ("cubic19", &[][..]),
            ("kinematic", &["--add", "reversal:target=ex,axis=x"][..]),
            ("nn:3", &["--max-epochs", "3"][..]),
            ("grid:50", &[][..]),
            ("cubic19", &["--local"][..]),
        ]
        .into_iter()
        .enumerate()
        {
            let m = fit(data, spec, extra, &dir.join(format!("m{i}.json")));
            ModelFile::load(&m).unwrap_or_else(|e| panic!("{spec} {extra:?} on {data:?}: {e:#}"));
            json(&run(&["compare", s(data), "--model", s(&m), "--json"]));
        }
    }
}

#[test]
fn a_non_finite_prediction_fails_export() {
    // Finite coefficients whose sum overflows: every number in the file is
    // valid, the prediction is not. The table's accuracy check used to
    // read NaN as 0 nm (f64::max drops NaN); export now refuses the
    // prediction, naming the target and the point, and writes nothing.
    let dir = tmp_dir("model-file", "inf");
    let (_, model, _) = grid_cubic19(&dir, "g", 4);
    let huge = damaged(&model, &dir.join("huge.json"), |v| {
        v["model"]["outputs"][0]["coef_um"][0] = 1e308.into();
        v["model"]["outputs"][0]["coef_um"][1] = 1e308.into();
    });
    ModelFile::load(&huge).expect("finite numbers load");
    let bin = dir.join("t.bin");
    expect_exit(
        &["export", s(&huge), "-o", s(&bin)],
        1,
        &[
            "ex: the model predicts inf µm at x = ",
            "not a finite number; nothing was written",
        ],
    );
    assert!(!bin.exists());
}

#[test]
fn every_single_bit_flip_is_refused_or_changes_nothing() {
    let dir = tmp_dir("model-file", "flips");
    let csv = simulate_grid(&dir, "g.csv", 5);
    let model = fit(
        &csv,
        "cubic19",
        &["--add", "periodic:target=ey,axis=y,period_mm=7.3"],
        &dir.join("m.json"),
    );
    let original = ModelFile::load(&model).unwrap();
    let bytes = std::fs::read(&model).unwrap();
    let flipped = dir.join("flipped.json");
    let mut rng = trueaxis_test_support::SplitMix64(25);
    let (mut refused, mut same) = (0, 0);
    for _ in 0..600 {
        let mut b = bytes.clone();
        let at = rng.int(0, b.len() as i64 - 1) as usize;
        b[at] ^= 1 << rng.int(0, 7);
        std::fs::write(&flipped, &b).unwrap();
        match ModelFile::load(&flipped) {
            Err(e) => {
                let e = format!("{e:#}");
                assert!(e.contains(s(&flipped)), "the file is named: {e}");
                refused += 1;
            }
            // What still loads is the model that was written (`1e5` →
            // `1E5`, a flip in the checksum's own key), never another.
            Ok(m) => {
                assert_eq!(m, original, "byte {at} flipped: a different model loaded");
                same += 1;
            }
        }
    }
    assert_eq!(refused + same, 600);
    assert!(refused > same, "{refused} refused, {same} unchanged");
    // The words, through every reader, for a flip in a number that leaves
    // the file valid JSON with every field valid.
    let text = std::fs::read_to_string(&model).unwrap();
    let at = text.find("\"coef_um\": [").unwrap() + 20;
    let digit = text[at..]
        .find(|c: char| c.is_ascii_digit() && c != '9')
        .unwrap()
        + at;
    let mut b = text.into_bytes();
    b[digit] += 1;
    std::fs::write(&flipped, &b).unwrap();
    let msg = format!(
        "{}: damaged: its content does not match its checksum",
        flipped.display()
    );
    let bin = dir.join("t.bin");
    expect_exit(&["export", s(&flipped), "-o", s(&bin)], 1, &[&msg]);
    assert!(!bin.exists());
    expect_exit(&["compare", s(&csv), "--model", s(&flipped)], 1, &[&msg]);
    expect_exit(&["diagnose", s(&csv), "--model", s(&flipped)], 1, &[&msg]);
}

#[test]
fn a_model_file_without_a_checksum_loads_with_a_note() {
    let dir = tmp_dir("model-file", "old");
    let (_, model, _) = grid_cubic19(&dir, "g", 6);
    let text = std::fs::read_to_string(&model).unwrap();
    assert!(text.trim_end().ends_with('}'));
    let last = text
        .rfind(",\n  \"checksum_sha256\"")
        .expect("the checksum is the last field");
    let old = common::file_in(&dir, "old.json", format!("{}\n}}\n", &text[..last]));
    assert_eq!(
        ModelFile::load(&old).unwrap(),
        ModelFile::load(&model).unwrap()
    );
    let out = run(&["export", s(&old), "-o", s(&dir.join("t.bin")), "--json"]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    json(&out);
    common::assert_has(
        &err,
        &[&format!(
            "note: {} has no checksum (written by an older trueaxis, or edited by hand): it loads unchecked — refit it to have one",
            old.display()
        )],
    );
    // The table is the same as from the checked file.
    let checked = dir.join("c.bin");
    json(&run_env_export(&model, &checked));
    json(&run_env_export(&old, &dir.join("o.bin")));
    assert_eq!(
        std::fs::read(&checked).unwrap(),
        std::fs::read(dir.join("o.bin")).unwrap()
    );
}

/// `export MODEL -o OUT --json` at a fixed creation time (the same model
/// gives the same bytes).
fn run_env_export(model: &Path, out: &Path) -> std::process::Output {
    common::run_env(
        &["export", s(model), "-o", s(out), "--json"],
        &[("SOURCE_DATE_EPOCH", "1700000000")],
    )
}
