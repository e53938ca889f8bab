//! `trueaxis export` to the controllers' own compensation files, end to end
//! through the binary:
//! - **linuxcnc**: read as LinuxCNC reads it (three numbers a line,
//!   ascending, ≤ 256), trims = −error (mm) against the model and against
//!   the hand-made data's own formula, forward − reverse = −backlash.
//! - **sinumerik**: variable names, `_STEP/_MIN/_MAX/_IS_MODULO`, N values
//!   = +mean error of both directions (mm).
//! - Golden files (tests/golden/) compared byte for byte; set
//!   `TRUEAXIS_BLESS=1` to rewrite them after an intended change.
//! - The interpolation error of a one-axis file and a reference outside
//!   the data are said.
//!
//! The firmware table's tests are in `export_cli.rs`.

mod common;

use common::export::*;
use common::*;
use trueaxis_engine::data::Dataset;
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

#[test]
fn linuxcnc_trims_are_minus_the_error_in_mm() {
    let dir = tmp_dir("export", "linuxcnc");
    let model = line_model(&dir);
    let out = dir.join("x.comp");
    let v = export(&model, &["--format", "linuxcnc"], &out);
    let text = std::fs::read_to_string(&out).unwrap();
    let rows = read_linuxcnc(&text);
    // Defaults: 201 points over the data's span, axis x (the only one).
    assert_eq!(rows.len(), 201);
    assert_eq!(v["points"], 201);
    assert_eq!(v["axis"], "x");
    assert_eq!(v["format"], "linuxcnc");
    assert_eq!((num(&v["min_mm"]), num(&v["max_mm"])), (0.0, 200.0));
    assert!((num(&v["step_mm"]) - 1.0).abs() < 1e-12);
    assert_eq!(v["bytes"].as_u64(), Some(text.len() as u64));
    assert_eq!(
        v["crc32"].as_str().unwrap(),
        format!("0x{:08x}", crc32_ieee(text.as_bytes()))
    );
    assert!(num(&v["max_interp_error_um"]) < 0.01, "{v}");

    let mf = ModelFile::load(&model).unwrap();
    let xs: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let fwd = predict_ex(&mf, &xs, 1, None);
    let rev = predict_ex(&mf, &xs, -1, None);
    for (i, r) in rows.iter().enumerate() {
        assert!((r[0] - i as f64).abs() < 1e-9, "nominal {}", r[0]);
        // Against the host model: −error, µm → mm, to the written 1 nm.
        assert!((r[1] + fwd[i] * 1e-3).abs() <= 0.5e-6 + 1e-12, "fwd {i}");
        assert!((r[2] + rev[i] * 1e-3).abs() <= 0.5e-6 + 1e-12, "rev {i}");
        // Against the formula the data were made from (independent of the
        // fit): a machine that overshoots gets a negative trim.
        assert!(
            (r[1] + line_truth_um(r[0], 1.0) * 1e-3).abs() <= 2e-6,
            "{r:?}"
        );
        assert!(
            (r[2] + line_truth_um(r[0], -1.0) * 1e-3).abs() <= 2e-6,
            "{r:?}"
        );
        // Forward and reverse differ by the reversal: 2 × 2.4 µm.
        assert!(((r[1] - r[2]) + 4.8e-3).abs() <= 1e-6, "{r:?}");
    }
    assert!((num(&v["backlash_um"]) - 4.8).abs() < 1e-3, "{v}");

    // LinuxCNC's limit: 256 entries exactly, no more.
    let v = export(&model, &["--format", "linuxcnc", "--points", "256"], &out);
    assert_eq!(v["points"], 256);
    assert_eq!(
        read_linuxcnc(&std::fs::read_to_string(&out).unwrap()).len(),
        256
    );
    let big = dir.join("big.comp");
    expect_exit(
        &export_args(&model, &["--format", "linuxcnc", "--points", "300"], &big),
        1,
        &["--points 300", "at most 256"],
    );
    assert!(!big.exists());
    expect_exit(
        &export_args(&model, &["--format", "linuxcnc", "--points", "1"], &big),
        1,
        &["at least 2 points"],
    );
}

#[test]
fn sinumerik_table_holds_plus_the_mean_error_in_mm() {
    let dir = tmp_dir("export", "sinumerik");
    let model = line_model(&dir);
    let out = dir.join("x.ini");
    let v = export(
        &model,
        &["--format", "sinumerik", "--sinumerik-axis", "X1"],
        &out,
    );
    assert_eq!(v["format"], "sinumerik");
    assert_eq!(v["points"], 200, "default: a Sinumerik 808D's 200 points");
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "%_N_AX_EEC_INI");
    assert_eq!(lines[1], "CHANDATA(1)");
    assert_eq!(*lines.last().unwrap(), "M17");
    let n = 200;
    assert_eq!(lines.len(), 2 + n + 4 + 1);
    let value = |line: &str, name: &str| -> f64 {
        let (lhs, rhs) = line.split_once('=').unwrap();
        assert_eq!(lhs, name);
        rhs.parse().unwrap()
    };
    let vals: Vec<f64> = (0..n)
        .map(|i| value(lines[2 + i], &format!("$AA_ENC_COMP[0,{i},X1]")))
        .collect();
    let step = value(lines[2 + n], "$AA_ENC_COMP_STEP[0,X1]");
    let min = value(lines[3 + n], "$AA_ENC_COMP_MIN[0,X1]");
    let max = value(lines[4 + n], "$AA_ENC_COMP_MAX[0,X1]");
    assert_eq!(lines[5 + n], "$AA_ENC_COMP_IS_MODULO[0,X1]=0");
    // 200 points over the data's 0…200 mm: the step 200/199 mm written to
    // 1 nm, and _MAX the last point of that step (the control puts point N
    // at _MIN + N·_STEP).
    assert_eq!((min, step, max), (0.0, 1.005025, 199.999975));
    assert!((min + step * (n - 1) as f64 - max).abs() < 1e-9);
    assert_eq!(num(&v["step_mm"]), step);
    assert_eq!(num(&v["max_mm"]), max);

    let mf = ModelFile::load(&model).unwrap();
    let xs: Vec<f64> = (0..n).map(|i| min + step * i as f64).collect();
    let fwd = predict_ex(&mf, &xs, 1, None);
    let rev = predict_ex(&mf, &xs, -1, None);
    for (i, v) in vals.iter().enumerate() {
        // +error (Siemens moves the axis the negative way for a positive
        // value), the mean of both directions, µm → mm.
        let mean_um = 0.5 * (fwd[i] + rev[i]);
        assert!(
            (v - mean_um * 1e-3).abs() <= 0.5e-6 + 1e-9,
            "{i}: {v} vs {mean_um}"
        );
        let truth = 0.5 * (line_truth_um(xs[i], 1.0) + line_truth_um(xs[i], -1.0));
        assert!((v - truth * 1e-3).abs() <= 2e-6, "{i}: {v} vs {truth}");
    }
    // The reversal is not in the table: it is reported for MD32450, which
    // Siemens enters positive when the slide falls short in the direction of
    // travel (e_fwd < e_rev). This line overshoots forward (fwd − rev =
    // +4.8 µm), so MD32450 is negative.
    assert!((num(&v["backlash_um"]) - 4.8).abs() < 1e-3, "{v}");
    assert!(
        (num(&v["md32450_backlash_mm"]) + 0.0048).abs() < 1e-6,
        "{v}"
    );
    let text_out = run(&["export", s(&model), "--format", "sinumerik", "-o", s(&out)]);
    assert!(text_out.status.success());
    let text = String::from_utf8_lossy(&text_out.stdout);
    assert!(
        text.contains("MD32450 $MA_BACKLASH = -0.004800 mm"),
        "{text}"
    );
    expect_exit(
        &export_args(
            &model,
            &["--format", "sinumerik", "--sinumerik-axis", "AX 1"],
            &out,
        ),
        1,
        &["Sinumerik axis name `AX 1`"],
    );
}

#[test]
fn golden_linuxcnc_and_sinumerik_files() {
    let dir = tmp_dir("export", "golden");
    let model = line_model(&dir);
    let mf = ModelFile::load(&model).unwrap();
    // The golden values must not sit on a rounding edge of the written
    // 1 nm, or a last-bit difference of the fit would flip a digit.
    let xs: Vec<f64> = (0..21).map(|i| 10.0 * f64::from(i)).collect();
    let (fwd, rev) = (
        predict_ex(&mf, &xs, 1, None),
        predict_ex(&mf, &xs, -1, None),
    );
    for (f, r) in fwd.iter().zip(&rev) {
        for nm in [1000.0 * f, 1000.0 * r, 500.0 * (f + r)] {
            let edge = (nm - nm.floor() - 0.5).abs();
            assert!(edge > 1e-6, "{nm} nm is on a rounding edge");
        }
    }
    for (format, name) in [
        ("linuxcnc", "line_x.linuxcnc.txt"),
        ("sinumerik", "line_x.sinumerik.ini"),
    ] {
        let out = dir.join(name);
        export(&model, &["--format", format, "--points", "21"], &out);
        golden(name, &std::fs::read(&out).unwrap());
    }
}

/// A periodic term left out of a controller file (period shorter than 4
/// table steps) counts in `max_interp_error_um` — the file differs from
/// the model by that much — and a zero backlash prints as 0, not −0.
#[test]
fn interpolation_error_counts_the_terms_left_out() {
    let dir = tmp_dir("export", "interp");
    let n = 1001;
    let y: Vec<f64> = (0..n).map(|i| 0.5 * i as f64).collect();
    let ey: Vec<Option<f64>> = y
        .iter()
        .map(|&p| {
            let e = 1e-3 * p + 3.0 * (2.0 * std::f64::consts::PI * p / 5.08).sin();
            Some((e * 1e4).round() / 1e4)
        })
        .collect();
    let data = Dataset {
        source: "periodic line".into(),
        pos_mm: [None, Some(y), None],
        err_um: [None, Some(ey), None],
        ..Dataset::default()
    };
    let csv = dir.join("y.csv");
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    let model = dir.join("y.model.json");
    fit(
        &csv,
        &[
            "--model",
            "cubic19",
            "--add",
            "periodic:target=ey,axis=y,period_mm=5.08",
        ],
        &model,
    );
    let ini = dir.join("y.ini");
    let mut args = export_args(&model, &["--format", "sinumerik"], &ini);
    args.push("--json");
    let out = run(&args);
    let v = json(&out);
    assert!(warning_codes(&v).contains(&"periodic_left_out"), "{v}");
    let e = num(&v["max_interp_error_um"]);
    assert!((2.95..3.05).contains(&e), "the 3 µm wave left out: {e}");
    let raw = String::from_utf8_lossy(&out.stdout);
    assert!(raw.contains(r#""md32450_backlash_mm":0.0"#), "{raw}");
    assert!(raw.contains(r#""backlash_um":0.0"#), "{raw}");
    let out = run(&export_args(&model, &["--format", "sinumerik"], &ini));
    let text = String::from_utf8_lossy(&out.stdout);
    common::assert_has(
        &text,
        &[
            "differs from the full model by at most 3.0",
            "(terms left out included)",
        ],
    );
    assert!(text.contains("$MA_BACKLASH = 0.000000 mm"), "{text}");
    assert!(
        text.contains("mean reversal (fwd − rev) 0.000 µm"),
        "{text}"
    );
    assert!(!text.contains("-0.0"), "{text}");
}

/// A controller file is evaluated at the thermal reference temperature; one
/// outside the measured range is an extrapolation and is warned.
#[test]
fn controller_file_warns_about_a_reference_outside_the_data() {
    let dir = tmp_dir("export", "tref");
    let csv = thermal_csv(&dir);
    let comp = dir.join("x.comp");
    for (t_ref, warned) in [("20", false), ("25", true)] {
        let model = dir.join(format!("tref{t_ref}.model.json"));
        let thermal = format!("thermal:target=ex,channel=bed,times=x,t_ref_c={t_ref}");
        fit(&csv, &["--model", "cubic19", "--add", &thermal], &model);
        let v = export(&model, &["--format", "linuxcnc"], &comp);
        let w = find_warning(&v, "thermal_reference_outside_data");
        assert_eq!(w.is_some(), warned, "t_ref {t_ref}: {v}");
        if let Some(w) = w {
            assert!(
                w["detail"].as_str().unwrap().contains(
                    "T_bed_C = 25 °C, where the file is evaluated, is outside the 20…21.71 °C"
                ),
                "{w}"
            );
        }
    }
}
