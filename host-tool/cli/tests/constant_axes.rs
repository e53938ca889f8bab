//! Single-axis data whose other position columns hold one value on every
//! row (`simulate --plan line:x:…` and `iso230:x` write y = z = 250 mm):
//! every command treats such an axis like one absent from the data —
//! `fit`/`improve` with cubic19 and kinematic fit the cubic in x alone and
//! warn that y and z are not modelled, the model does not depend on y or z,
//! `compare` reads the data, and `export` (table, linuxcnc, sinumerik)
//! treats y and z as axes the model does not use (docs/cli.md, fit).

mod common;

use std::path::{Path, PathBuf};

use common::{compare, expect_exit, export, fit, json, s, tmp_dir, CUBIC19_REVERSAL_X};
use trueaxis_engine::data::Dataset;
use trueaxis_engine::import;
use trueaxis_engine::model::{FittedModel, ModelFile};

/// `trueaxis simulate --plan PLAN --effect reversal:axis=x,backlash_um=8
/// --seed 7 -o DIR/NAME`.
fn simulate(dir: &Path, name: &str, plan: &str) -> PathBuf {
    let csv = dir.join(name);
    common::simulate(
        &[
            "--plan",
            plan,
            "--effect",
            "reversal:axis=x,backlash_um=8",
            "--seed",
            "7",
        ],
        &csv,
    );
    csv
}

/// `simulate(DIR, STEM.csv, PLAN)` fitted to `DIR/m.json` with cubic19 and
/// x reversal. Returns (data, model).
fn fitted(dir: &Path, stem: &str, plan: &str) -> (PathBuf, PathBuf) {
    let csv = simulate(dir, &format!("{stem}.csv"), plan);
    let model = dir.join("m.json");
    fit(&csv, CUBIC19_REVERSAL_X, &model);
    (csv, model)
}

fn warnings(v: &serde_json::Value) -> Vec<String> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

/// The warnings `fit` gives for y = z = 250 mm on every row.
fn assert_y_z_not_modelled(v: &serde_json::Value) {
    let w = warnings(v);
    for ax in ["y", "z"] {
        let want = format!(
            "{ax}: every measured point is at {ax} = 250 mm; {ax} is not modelled (the correction does not depend on {ax}, as for an axis absent from the data)"
        );
        assert!(w.contains(&want), "{w:?}");
    }
}

#[test]
fn simulated_line_and_iso230_data_fit_with_the_polynomial_seeds() {
    let dir = tmp_dir("constant-axes", "fit");
    let line = simulate(&dir, "line.csv", "line:x:5,bidir");
    let iso = simulate(&dir, "iso.csv", "iso230:x");
    let data = import::load(&line).unwrap();
    assert_eq!(data.axes(), vec![0, 1, 2]);
    assert_eq!(data.varying_axes(), vec![0]);
    assert_eq!(data.constant_position(1), Some(250.0));

    for csv in [&line, &iso] {
        // cubic19 in x alone: 1, x, x², x³ for every target.
        let model = dir.join("m.json");
        let v = fit(csv, &["--model", "cubic19"], &model);
        for t in ["ex", "ey", "ez"] {
            assert_eq!(v["terms_per_target"][t], 4, "{v}");
        }
        assert_y_z_not_modelled(&v);
        // kinematic: ex's cubic in x (4 terms); ey, ez keep 1, x², x³.
        let v = fit(csv, &["--model", "kinematic"], &model);
        assert_eq!(v["terms_per_target"]["ex"], 4, "{v}");
        assert_eq!(v["terms_per_target"]["ey"], 3, "{v}");
        assert_y_z_not_modelled(&v);
    }

    // What `diagnose` suggests on the ISO run, as the user typed it.
    let model = dir.join("iso.model.json");
    let v = fit(&iso, CUBIC19_REVERSAL_X, &model);
    assert_eq!(v["terms_per_target"]["ex"], 5, "{v}");
    // The 8 µm backlash is found: ±4 µm on dir_x, the residual at the noise.
    let m = ModelFile::load(&model).unwrap();
    let FittedModel::Linear(lin) = &m.model else {
        panic!("linear")
    };
    let ex = lin.outputs.iter().find(|o| o.target == 0).unwrap();
    assert_eq!(ex.features.len(), 5);
    assert!((ex.coef_um[4].abs() - 4.0).abs() < 0.1, "{:?}", ex.coef_um);
    assert!(v["rms_um"]["ex"].as_f64().unwrap() < 0.3, "{v}");
    // The held axes keep a finite, positive normalisation (centre = the
    // position, half span 1 µm): u is 0 on the data and finite elsewhere.
    assert_eq!(lin.norm.centre_mm[1], 250.0);
    assert_eq!(lin.norm.half_span_mm[1], 0.001);
    assert_eq!(lin.norm.half_span_mm[2], 0.001);

    // improve from the bare seed adds the reversal and stops at the floor.
    let v = json(&common::cubic19(
        "improve",
        &iso,
        &dir.join("improved.json"),
        &[],
    ));
    assert_eq!(v["model"], "cubic19 --add reversal:target=ex,axis=x", "{v}");
    assert_eq!(v["verdict"], "at_noise_floor", "{v}");
}

#[test]
fn the_model_of_a_line_does_not_depend_on_the_held_axes() {
    let dir = tmp_dir("constant-axes", "predict");
    let (line, model) = fitted(&dir, "line", "line:x:5,bidir");
    let m = ModelFile::load(&model).unwrap();
    let at = |y: f64, z: f64| -> [Option<Vec<f64>>; 3] {
        let x: Vec<f64> = (0..=16).map(|i| f64::from(i) * 50.0).collect();
        let n = x.len();
        let data = Dataset {
            source: "sweep".into(),
            pos_mm: [Some(x), Some(vec![y; n]), Some(vec![z; n])],
            dir: [Some(vec![1; n]), None, None],
            ..Dataset::default()
        };
        m.model.predict(&data).unwrap()
    };
    let base = at(250.0, 250.0);
    for (y, z) in [(0.0, 0.0), (500.0, 10.0), (-100.0, 1000.0)] {
        let other = at(y, z);
        for t in 0..3 {
            let (a, b) = (base[t].as_ref().unwrap(), other[t].as_ref().unwrap());
            assert!(b.iter().all(|v| v.is_finite()));
            assert_eq!(a, b, "target {t} at y = {y}, z = {z}");
        }
    }

    // compare reads the data the model was fitted to.
    let v = compare(&line, &model);
    assert!(v["targets"]["ex"]["rms_um"].as_f64().unwrap() < 0.3, "{v}");
}

#[test]
fn every_export_format_treats_the_held_axes_as_unused() {
    let dir = tmp_dir("constant-axes", "export");
    let (iso, model) = fitted(&dir, "iso", "iso230:x");
    // Firmware table: y and z unbounded, the firmware's own evaluation
    // agrees with the model to well under 1 nm.
    let v = export(&model, &[], &dir.join("m.tbl"));
    let travel = &v["envelope"]["travel_mm"];
    assert!(travel[0].is_array(), "{v}");
    assert!(travel[1].is_null() && travel[2].is_null(), "{v}");
    assert!(v["max_f32_error_nm"].as_f64().unwrap() < 1.0, "{v}");
    assert!(v["max_fixed_error_nm"].as_f64().unwrap() < 1.0, "{v}");
    // Controller tables: x is the only axis the model uses (no --axis
    // needed), the other axes at 0 as for an absent axis.
    for fmt in ["linuxcnc", "sinumerik"] {
        let v = export(&model, &["--format", fmt], &dir.join(format!("m.{fmt}")));
        assert_eq!(v["axis"], "x", "{v}");
        assert_eq!(
            v["at_mm"],
            serde_json::json!({"x": 0.0, "y": 0.0, "z": 0.0}),
            "{v}"
        );
        assert!(
            (v["backlash_um"].as_f64().unwrap() - 8.0).abs() < 0.2,
            "{v}"
        );
    }
    // A --local line model also uses x alone: a controller table needs no
    // --axis (it named x, y, z before).
    let local = dir.join("local.json");
    fit(&iso, &["--model", "cubic19", "--local"], &local);
    let v = export(&local, &["--format", "linuxcnc"], &dir.join("local.lc"));
    assert_eq!(v["axis"], "x", "{v}");
}

#[test]
fn a_term_in_a_held_axis_is_refused_naming_its_position() {
    let dir = tmp_dir("constant-axes", "refuse");
    let line = simulate(&dir, "line.csv", "line:x:5,bidir");
    let err = expect_exit(
        &[
            "fit",
            s(&line),
            "--model",
            "cubic19",
            "--add",
            "squareness:target=ex,axis=y",
            "-o",
            s(&dir.join("m.json")),
        ],
        1,
        &["ex: the model's columns are linearly dependent on these data (rank 4 of 5): y cannot be fitted: y is 250 mm at every measured point"],
    );
    assert!(!err.contains("is zero"), "{err}");
}
