//! `trueaxis export` end to end through the binary, for each format.
//!
//! - **table**: the `--json` of docs/cli.md agrees with the file (length,
//!   an independently computed CRC-32), the file parses with model-core as
//!   the firmware parses it, its envelope is the data's span and follows
//!   `--max-corr-um` / `--max-slew-nm-per-ms` / `--max-feed-mm-per-min`, the
//!   firmware's evaluation is −error (nm) of the host model, a failed
//!   accuracy check exits 1 without writing, a thermal lag is refused
//!   without `--drop-lag`, a drift term is left out with a warning.
//! - **linuxcnc**: read as LinuxCNC reads it (three numbers a line,
//!   ascending, ≤ 256), trims = −error (mm) against the model and against
//!   the hand-made data's own formula, forward − reverse = −backlash.
//! - **sinumerik**: variable names, `_STEP/_MIN/_MAX/_IS_MODULO`, N values
//!   = +mean error of both directions (mm).
//! - Golden files (tests/golden/) compared byte for byte; set
//!   `TRUEAXIS_BLESS=1` to rewrite them after an intended change.
//! - Bad input: missing / truncated / non-model files, an axis the model
//!   does not use, out-of-range options → exit 1 with a clear message.

mod common;

use std::path::{Path, PathBuf};

use common::{
    expect_exit, export, export_args, find_warning, fit, fit_cubic19, golden, golden_file,
    grid_cubic19, json, run, run_env, s, simulate_grid, tmp_dir, warning_codes, CUBIC19_REVERSAL_X,
};
use model_core::{Inputs, Model, MAX_TEMPS};
use serde_json::Value;
use trueaxis_engine::data::{Dataset, TempChannel};
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// CRC-32 (IEEE 802.3, reflected 0xEDB88320, as zlib), bit by bit — an
/// implementation independent of the `crc` crate model-core uses.
fn crc32_ieee(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

// ---------------------------------------------------------------------------
// Data and models.

/// The preset mill on a 100 mm grid (324 points, ex ey ez), seed 7, fitted
/// with cubic19. Returns (data, model).
fn grid_model(dir: &Path) -> (PathBuf, PathBuf) {
    let (csv, model, _) = grid_cubic19(dir, "grid", 7);
    (csv, model)
}

/// The checked-in hand-made x line (tests/golden/line_x.csv).
fn line_csv() -> PathBuf {
    golden_file("line_x.csv")
}

/// The error the hand-made line was generated from, µm (see its header).
fn line_truth_um(x_mm: f64, dir: f64) -> f64 {
    1.3137 + 0.0213457 * x_mm - 3.1e-4 * x_mm * x_mm + 7.7e-7 * x_mm * x_mm * x_mm + 2.4 * dir
}

/// cubic19 + reversal fitted to the hand-made line (ex over x only).
fn line_model(dir: &Path) -> PathBuf {
    let model = dir.join("line.model.json");
    let v = fit(&line_csv(), CUBIC19_REVERSAL_X, &model);
    assert_eq!(v["terms"], 5, "1, x, x², x³ and dir_x: {v}");
    model
}

/// A hand-made x line with a warming bed: ex = cubic(x) + reversal +
/// 0.0115 µm/(K·mm)·(T_bed − 20)·x + 0.5 µm/h drift, 6 bidirectional runs
/// of 21 points, 4 s per point. Deterministic pseudo-noise ±0.02 µm.
fn thermal_csv(dir: &Path) -> PathBuf {
    let (mut x, mut ex, mut t, mut d, mut temp) = (vec![], vec![], vec![], vec![], vec![]);
    let mut row = 0usize;
    for run in 0..12 {
        let dir_x: i8 = if run % 2 == 0 { 1 } else { -1 };
        for i in 0..=20 {
            let p = if dir_x > 0 { i * 10 } else { 200 - i * 10 } as f64;
            let t_s = 4.0 * row as f64;
            let bed = 20.0 + 4.0 * (1.0 - (-t_s / 1800.0).exp());
            let noise = ((row * 7919) % 41) as f64 / 1000.0 - 0.02;
            let e = line_truth_um(p, f64::from(dir_x)) - 2.4 * f64::from(dir_x)
                + 1.5 * f64::from(dir_x)
                + 0.0115 * (bed - 20.0) * p
                + 0.5 * t_s / 3600.0
                + noise;
            x.push(p);
            ex.push(Some((e * 1e4).round() / 1e4));
            t.push(t_s);
            d.push(dir_x);
            temp.push((bed * 1e3).round() / 1e3);
            row += 1;
        }
    }
    let data = Dataset {
        source: "thermal line".into(),
        pos_mm: [Some(x), None, None],
        err_um: [Some(ex), None, None],
        t_s: Some(t),
        dir: [Some(d), None, None],
        temps: vec![TempChannel {
            name: "bed".into(),
            temp_c: temp,
        }],
        ..Dataset::default()
    };
    let csv = dir.join("thermal.csv");
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    csv
}

/// The host model's error prediction for target ex at `x_mm` after an
/// approach in `dir`, at t = 0 and the given bed temperature, µm.
fn predict_ex(model: &ModelFile, x_mm: &[f64], dir: i8, bed_c: Option<f64>) -> Vec<f64> {
    let n = x_mm.len();
    let data = Dataset {
        source: "test".into(),
        pos_mm: [Some(x_mm.to_vec()), None, None],
        t_s: Some(vec![0.0; n]),
        dir: [Some(vec![dir; n]), None, None],
        temps: bed_c
            .map(|c| {
                vec![TempChannel {
                    name: "bed".into(),
                    temp_c: vec![c; n],
                }]
            })
            .unwrap_or_default(),
        ..Dataset::default()
    };
    model.model.predict(&data).unwrap()[0].clone().unwrap()
}

// ---------------------------------------------------------------------------
// Firmware table.

#[test]
fn table_json_matches_the_file_and_the_firmware_corrects_minus_the_error() {
    let dir = tmp_dir("export", "table");
    let (csv, model) = grid_model(&dir);
    let bin = dir.join("grid.bin");
    let v = export(&model, &[], &bin);
    // docs/cli.md.
    let bytes = std::fs::read(&bin).unwrap();
    assert_eq!(v["bytes"].as_u64(), Some(bytes.len() as u64));
    let crc = v["crc32"].as_str().unwrap();
    assert!(crc.starts_with("0x") && crc.len() == 10, "{crc}");
    let n = bytes.len();
    let stored = u32::from_le_bytes(bytes[n - 4..].try_into().unwrap());
    assert_eq!(crc32_ieee(&bytes[..n - 4]), stored, "trailer is the CRC");
    assert_eq!(crc, format!("0x{stored:08x}"));
    let (f32_nm, fixed_nm) = (num(&v["max_f32_error_nm"]), num(&v["max_fixed_error_nm"]));
    assert!((0.0..=1.0).contains(&f32_nm), "{v}");
    assert!((0.0..=1.0).contains(&fixed_nm), "{v}");
    assert!(v["sweep_points"].as_u64().unwrap() > 1000);
    assert_eq!(v["format"], "table");
    assert_eq!(v["warnings"], serde_json::json!([]));

    // The file as the firmware sees it.
    let t = model_core::parse(&bytes).expect("the table parses");
    assert_eq!(t.term_count() as u64, v["terms"].as_u64().unwrap());
    assert_eq!(t.term_count(), 3, "one polynomial per output");
    assert_eq!(t.outputs_mask(), 0b111);
    assert_eq!(t.channel_count(), 0);
    let mf = ModelFile::load(&model).unwrap();
    let hash: Vec<u8> = (0..32)
        .map(|i| u8::from_str_radix(&mf.data.sha256[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    assert_eq!(t.source_hash().to_vec(), hash, "source hash = the data's");
    let env = t.envelope();
    // Travel = the fitted data's span (grid:100 on 800 × 500 × 500 mm).
    assert_eq!(env.travel_nm(0), (0, 800_000_000));
    assert_eq!(env.travel_nm(1), (0, 500_000_000));
    assert_eq!(env.travel_nm(2), (0, 500_000_000));
    assert_eq!(
        v["envelope"]["travel_mm"][0],
        serde_json::json!([0.0, 800.0])
    );
    for o in 0..3 {
        assert_eq!(
            f64::from(env.max_corr_nm(o)) / 1000.0,
            num(&v["envelope"]["max_corr_um"][o])
        );
    }
    assert_eq!(
        i64::from(env.max_slew_nm_per_ms),
        v["envelope"]["max_slew_nm_per_ms"].as_i64().unwrap()
    );

    // The firmware's correction is −error of the host model (nm) at every
    // measured point, and the default max |corr| does not clamp it there.
    let data = import::load(&csv).unwrap();
    let pred = mf.model.predict(&data).unwrap();
    let fw = Model::load(&t).unwrap();
    for row in (0..data.len()).step_by(7) {
        let inp = Inputs {
            pos_nm: [0, 1, 2].map(|a| (data.pos(a, row) * 1e6).round() as i32),
            rev_q30: [1 << 30; 3],
            temp_mc: [0; MAX_TEMPS],
            tool_nm: 0,
        };
        let (f, x) = (fw.eval_f32(&inp), fw.eval_fixed(&inp));
        for (o, p) in pred.iter().enumerate() {
            let want_nm = -1000.0 * p.as_ref().unwrap()[row];
            assert!(
                (f64::from(f.corr_nm[o]) - want_nm).abs() <= 1.0,
                "row {row} out {o}: f32 {} vs −error {want_nm}",
                f.corr_nm[o]
            );
            assert!((f64::from(x.corr_nm[o]) - want_nm).abs() <= 1.0);
            assert!(want_nm.abs() * 1.4 <= f64::from(env.max_corr_nm(o)));
        }
    }
}

#[test]
fn table_envelope_follows_the_options() {
    let dir = tmp_dir("export", "envelope");
    let (_, model) = grid_model(&dir);
    let bin = dir.join("t.bin");
    let envelope = |extra: &[&str]| {
        let v = export(&model, extra, &bin);
        let bytes = std::fs::read(&bin).unwrap();
        let env = model_core::parse(&bytes).unwrap().envelope();
        (v, env)
    };
    let (_, base) = envelope(&[]);
    let (v, env) = envelope(&["--max-corr-um", "50"]);
    assert_eq!(env.max_corr_nm, [50_000; 3]);
    assert_eq!(
        v["envelope"]["max_corr_um"],
        serde_json::json!([50.0, 50.0, 50.0])
    );
    // Below the model's own correction: accepted, but warned (the firmware
    // will clamp).
    let (v, env) = envelope(&["--max-corr-um", "2"]);
    assert_eq!(env.max_corr_nm, [2000; 3]);
    assert!(
        v["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w["code"] == "max_corr_below_model"),
        "{v}"
    );
    // … and it does: where the model asks for more, the table gives ±2 µm.
    let bytes = std::fs::read(&bin).unwrap();
    let t = model_core::parse(&bytes).unwrap();
    let fw = Model::load(&t).unwrap();
    let mut clamped = 0;
    for x in (0..=800).step_by(100) {
        let inp = Inputs {
            pos_nm: [x * 1_000_000, 0, 0],
            ..Inputs::default()
        };
        for c in fw.eval_fixed(&inp).corr_nm {
            assert!(c.abs() <= 2000, "{c}");
            clamped += usize::from(c.abs() == 2000);
        }
    }
    assert!(clamped > 0, "the limit bites somewhere on the model");
    let (_, env) = envelope(&["--max-slew-nm-per-ms", "123"]);
    assert_eq!(env.max_slew_nm_per_ms, 123);
    // Default slew = 1.5 × gradient × feed: twice the feed, twice the slew.
    let (_, fast) = envelope(&["--max-feed-mm-per-min", "20000"]);
    let ratio = f64::from(fast.max_slew_nm_per_ms) / f64::from(base.max_slew_nm_per_ms);
    assert!((ratio - 2.0).abs() < 0.05, "{ratio}");
    // The rest of the envelope is unchanged by these options.
    assert_eq!(fast.travel_min_nm, base.travel_min_nm);
    assert_eq!(fast.max_corr_nm, base.max_corr_nm);
    let (v, _) = envelope(&["--temp-range-c", "15..30"]);
    assert_eq!(
        v["envelope"]["temp_range_c"],
        serde_json::json!([15.0, 30.0])
    );
}

#[test]
fn failed_accuracy_check_exits_1_and_writes_nothing() {
    let dir = tmp_dir("export", "accuracy");
    let (_, model) = grid_model(&dir);
    let bin = dir.join("never.bin");
    expect_exit(
        &export_args(&model, &["--allow-error-nm", "0.000001", "--json"], &bin),
        1,
        &[
            "accuracy check failed",
            "--allow-error-nm",
            "was not written",
        ],
    );
    assert!(!bin.exists());
}

#[test]
fn thermal_lag_is_refused_without_drop_lag_and_drift_is_left_out() {
    let dir = tmp_dir("export", "thermal");
    let csv = thermal_csv(&dir);
    let model = dir.join("thermal.model.json");
    fit(
        &csv,
        &[
            "--model",
            "cubic19",
            "--add",
            "reversal:target=ex,axis=x",
            "--add",
            "thermal:target=ex,channel=bed,times=x,lag_s=300",
            "--add",
            "drift:target=ex",
        ],
        &model,
    );
    let bin = dir.join("thermal.bin");
    expect_exit(
        &["export", s(&model), "-o", s(&bin), "--json"],
        1,
        &["lag of 300 s", "--drop-lag"],
    );
    assert!(!bin.exists(), "nothing written when refused");

    let out = run(&["export", s(&model), "-o", s(&bin), "--drop-lag", "--json"]);
    let v = json(&out);
    let codes = warning_codes(&v);
    assert!(codes.contains(&"lag_dropped"), "{codes:?}");
    assert!(codes.contains(&"drift_left_out"), "{codes:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("warning (drift_left_out)") && err.contains("warning (lag_dropped)"),
        "{err}"
    );
    assert!(num(&v["max_f32_error_nm"]) <= 1.0 && num(&v["max_fixed_error_nm"]) <= 1.0);

    let bytes = std::fs::read(&bin).unwrap();
    let t = model_core::parse(&bytes).unwrap();
    assert_eq!(t.channel_name(0), Some("bed"));
    let env = t.envelope();
    // The temperature envelope is the range the bed was measured over (no
    // margin, like the travel), not a workshop's 10…40 °C.
    let data = import::load(&csv).unwrap();
    let bed = &data.temp("bed").unwrap().temp_c;
    let (lo, hi) = (
        bed.iter().copied().fold(f64::INFINITY, f64::min),
        bed.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    assert_eq!((lo, hi), (20.0, 21.71), "the data's own range");
    assert_eq!((env.temp_min_mc[0], env.temp_max_mc[0]), (20_000, 21_710));
    assert_eq!(
        v["envelope"]["temp_range_c"],
        serde_json::json!([20.0, 21.71])
    );
    assert_eq!(
        v["envelope"]["temp_range_c_by_channel"],
        serde_json::json!({"bed": [20.0, 21.71]})
    );
    // Polynomial, thermal, reversal — no drift term.
    assert_eq!(t.term_count(), 3);
    assert_eq!(v["terms"], 3);
    // The firmware at t = 0 (no drift) and 20 °C (the thermal reference)
    // corrects −error of the host model.
    let mf = ModelFile::load(&model).unwrap();
    let fw = Model::load(&t).unwrap();
    let xs = [0.0, 37.0, 100.0, 163.5, 200.0];
    for dir in [1i8, -1] {
        let pred = predict_ex(&mf, &xs, dir, Some(20.0));
        for (x, e) in xs.iter().zip(&pred) {
            let mut temp_mc = [0; MAX_TEMPS];
            temp_mc[0] = 20_000;
            let inp = Inputs {
                pos_nm: [(x * 1e6) as i32, 0, 0],
                rev_q30: [i32::from(dir) << 30, 0, 0],
                temp_mc,
                tool_nm: 0,
            };
            let c = fw.eval_fixed(&inp).corr_nm[0];
            assert!(
                (f64::from(c) + 1000.0 * e).abs() <= 1.0,
                "x {x}: {c} vs {e}"
            );
        }
    }

    // The one-axis controller files: drift left out too, thermal at the
    // reference temperature, both warned.
    let lc = dir.join("thermal.linuxcnc");
    let v = export(&model, &["--format", "linuxcnc"], &lc);
    let codes = warning_codes(&v);
    assert!(codes.contains(&"drift_left_out"), "{codes:?}");
    assert!(codes.contains(&"thermal_at_reference"), "{codes:?}");
}

// ---------------------------------------------------------------------------
// LinuxCNC.

/// Reads a COMP_FILE_TYPE 1 file the way LinuxCNC does: every line must be
/// exactly three numbers (LinuxCNC stops at the first that is not), nominal
/// strictly ascending, at most 256 entries.
fn read_linuxcnc(text: &str) -> Vec<[f64; 3]> {
    assert!(text.ends_with('\n'), "last line terminated");
    let mut out: Vec<[f64; 3]> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let cells: Vec<&str> = line.split(' ').collect();
        assert_eq!(cells.len(), 3, "line {}: `{line}`", i + 1);
        let v: Vec<f64> = cells
            .iter()
            .map(|c| {
                assert!(
                    c.chars()
                        .all(|ch| ch.is_ascii_digit() || ch == '-' || ch == '.'),
                    "line {}: `{c}` is not a plain decimal",
                    i + 1
                );
                c.parse::<f64>().unwrap()
            })
            .collect();
        if let Some(prev) = out.last() {
            assert!(v[0] > prev[0], "line {}: not ascending", i + 1);
        }
        out.push([v[0], v[1], v[2]]);
    }
    assert!(!out.is_empty() && out.len() <= 256, "{} entries", out.len());
    out
}

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

// ---------------------------------------------------------------------------
// Sinumerik.

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

// ---------------------------------------------------------------------------
// Golden files.

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

// ---------------------------------------------------------------------------
// Bad input.

#[test]
fn bad_input_exits_1_with_a_clear_message() {
    let dir = tmp_dir("export", "bad");
    let model = line_model(&dir);
    let out = dir.join("out.bin");
    let o = s(&out);

    let missing = dir.join("missing.model.json");
    expect_exit(
        &["export", s(&missing), "-o", o, "--json"],
        1,
        &["cannot read model file", s(&missing)],
    );
    let text = std::fs::read_to_string(&model).unwrap();
    let cut = dir.join("cut.model.json");
    std::fs::write(&cut, &text[..text.len() / 3]).unwrap();
    expect_exit(
        &["export", s(&cut), "-o", o],
        1,
        &[s(&cut), "not a trueaxis model file"],
    );
    let not_model = dir.join("other.json");
    std::fs::write(&not_model, r#"{"bytes": 316, "crc32": "0x00000000"}"#).unwrap();
    expect_exit(
        &["export", s(&not_model), "-o", o, "--format", "linuxcnc"],
        1,
        &[s(&not_model), "not a trueaxis model file"],
    );
    let garbage = dir.join("garbage.json");
    std::fs::write(&garbage, [0xff, 0xfe, 0x00, 0x41]).unwrap();
    expect_exit(&["export", s(&garbage), "-o", o], 1, &[s(&garbage)]);
    assert!(!out.exists(), "nothing written for bad input");

    // An axis the model does not use.
    for format in ["linuxcnc", "sinumerik"] {
        expect_exit(
            &export_args(&model, &["--format", format, "--axis", "y"], &out),
            1,
            &["does not depend on y", "fitted axes: x"],
        );
    }
    // A 3-axis model needs --axis for a one-axis controller file.
    let (_, grid) = grid_model(&dir);
    expect_exit(
        &["export", s(&grid), "--format", "linuxcnc", "-o", o],
        1,
        &["the model uses the axes x, y, z", "--axis"],
    );
    let lc = dir.join("grid_y.comp");
    let v = export(&grid, &["--format", "linuxcnc", "--axis", "y"], &lc);
    assert_eq!(v["axis"], "y");
    assert_eq!(
        v["at_mm"],
        serde_json::json!({"x": 400.0, "y": 0.0, "z": 250.0})
    );
    assert_eq!(num(&v["max_mm"]), 500.0);

    // Options out of range.
    expect_exit(
        &["export", s(&model), "-o", o, "--temp-range-c", "40..10"],
        1,
        &["--temp-range-c `40..10`"],
    );
    expect_exit(
        &["export", s(&model), "-o", o, "--max-corr-um", "0"],
        1,
        &["--max-corr-um must be positive"],
    );
    expect_exit(
        &["export", s(&model), "-o", o, "--max-corr-um", "5000"],
        1,
        &["exceeds the table's limit"],
    );
    // Usage errors: exit 2.
    expect_exit(&["export", s(&model)], 2, &["--output"]);
    expect_exit(
        &["export", s(&model), "-o", o, "--format", "fanuc"],
        2,
        &["fanuc"],
    );
    expect_exit(
        &["export", s(&model), "-o", o, "--axis", "w"],
        2,
        &["--axis"],
    );
}

/// Every exportable model kind from the command line: a grid table and a
/// tanh network fitted to the simulated grid become tables that pass the
/// accuracy check, and one-axis controller files; a local model is refused
/// as a table with a message that says what to fit instead.
#[test]
fn grid_and_network_models_export_and_local_is_refused() {
    let dir = tmp_dir("export", "kinds");
    let (csv, _) = grid_model(&dir);
    for (args, terms) in [
        (vec!["--model", "grid:100"], 3),
        (vec!["--model", "nn:4", "--max-epochs", "30"], 1),
    ] {
        let model = dir.join("kind.model.json");
        fit(&csv, &args, &model);
        let bin = dir.join("kind.bin");
        let v = export(&model, &[], &bin);
        assert!(num(&v["max_f32_error_nm"]) <= 1.0, "{args:?}: {v}");
        assert!(num(&v["max_fixed_error_nm"]) <= 1.0, "{args:?}: {v}");
        assert_eq!(v["terms"], terms, "{args:?}");
        let bytes = std::fs::read(&bin).unwrap();
        let t = model_core::parse(&bytes).unwrap();
        assert_eq!(t.envelope().travel_nm(0), (0, 800_000_000), "{args:?}");
        let lc = dir.join("kind.comp");
        let v = export(&model, &["--format", "linuxcnc", "--axis", "z"], &lc);
        assert_eq!(v["axis"], "z");
        let rows = read_linuxcnc(&std::fs::read_to_string(&lc).unwrap());
        assert_eq!(rows.len(), 201);
        assert_eq!((rows[0][0], rows[200][0]), (0.0, 500.0), "{args:?}");
    }
    let local = dir.join("local.model.json");
    fit(&csv, &["--model", "cubic19", "--local"], &local);
    let bin = dir.join("local.bin");
    expect_exit(
        &["export", s(&local), "-o", s(&bin)],
        1,
        &[
            "local (piecewise) models cannot be exported as a table",
            "grid:<step_mm>",
        ],
    );
    assert!(!bin.exists());
}

// ---------------------------------------------------------------------------
// Reproducible tables.

/// With SOURCE_DATE_EPOCH the same model gives the same bytes (and CRC):
/// two exports are identical, carry that creation time, and equal the
/// checked-in golden table; a malformed SOURCE_DATE_EPOCH is refused, and
/// `--axis` with a table (which holds every axis) is an error, not ignored.
#[test]
fn source_date_epoch_makes_the_table_reproducible() {
    let dir = tmp_dir("export", "epoch");
    let model = line_model(&dir);
    let mut bytes = Vec::new();
    for i in 0..2 {
        let out = dir.join(format!("t{i}.bin"));
        let v = json(&run_env(
            &["export", s(&model), "-o", s(&out), "--json"],
            &[("SOURCE_DATE_EPOCH", "1700000000")],
        ));
        let b = std::fs::read(&out).unwrap();
        assert_eq!(
            v["crc32"],
            format!("0x{:08x}", crc32_ieee(&b[..b.len() - 4]))
        );
        let t = model_core::parse(&b).unwrap();
        assert_eq!(t.created_unix_s(), 1_700_000_000);
        bytes.push(b);
    }
    assert_eq!(bytes[0], bytes[1]);
    golden("line_x.table.bin", &bytes[0]);

    let out = run_env(
        &["export", s(&model), "-o", s(&dir.join("bad.bin")), "--json"],
        &[("SOURCE_DATE_EPOCH", "yesterday")],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("SOURCE_DATE_EPOCH"));
    assert!(!dir.join("bad.bin").exists());

    let a_bin = dir.join("a.bin");
    expect_exit(
        &export_args(&model, &["--axis", "x"], &a_bin),
        2,
        &["--axis applies to --format linuxcnc and sinumerik only, not to --format table"],
    );
    assert!(!a_bin.exists());
}

// ---------------------------------------------------------------------------
// Envelope defaults, limits and flags (user test R7–R11).

/// `fit thermal.csv` with reversal + thermal (no lag) on ex.
fn thermal_model(dir: &Path) -> (PathBuf, PathBuf) {
    let csv = thermal_csv(dir);
    let model = dir.join("thermal_nolag.model.json");
    fit(
        &csv,
        &[
            "--model",
            "cubic19",
            "--add",
            "reversal:target=ex,axis=x",
            "--add",
            "thermal:target=ex,channel=bed,times=x",
        ],
        &model,
    );
    (csv, model)
}

/// The model remembers the measured temperature range; the table's default
/// envelope is that range, so outside it the firmware holds the edge value
/// and flags it instead of extrapolating the thermal term — and the
/// default max |correction| is 1.5 × the largest inside the data, not over
/// 10…40 °C. `--temp-range-c` still overrides; a model file from before
/// the range was recorded falls back to 10…40 °C with a warning.
#[test]
fn temperature_envelope_defaults_to_the_measured_range() {
    let dir = tmp_dir("export", "temp_env");
    let (_, model) = thermal_model(&dir);
    let text = std::fs::read_to_string(&model).unwrap();
    let mj: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(
        mj["data"]["temp_range_c"],
        serde_json::json!({"bed": [20.0, 21.71]}),
        "fit records the measured range"
    );
    let bin = dir.join("t.bin");
    let v = export(&model, &[], &bin);
    assert_eq!(
        v["envelope"]["temp_range_c"],
        serde_json::json!([20.0, 21.71])
    );
    assert!(v["warnings"].as_array().unwrap().is_empty(), "{v}");
    // Largest |correction| over the data's temperatures, both directions.
    let mf = ModelFile::load(&model).unwrap();
    let xs: Vec<f64> = (0..=2000).map(|i| 0.1 * f64::from(i)).collect();
    let mut largest = 0.0f64;
    for dir in [1i8, -1] {
        for t in [20.0, 21.71] {
            for e in predict_ex(&mf, &xs, dir, Some(t)) {
                largest = largest.max(e.abs());
            }
        }
    }
    let max_corr = num(&v["envelope"]["max_corr_um"][0]);
    assert!(
        (max_corr - 1.5 * largest).abs() < 0.01,
        "{max_corr} vs 1.5 × {largest}"
    );
    // The firmware at 40 °C holds the value at 21.71 °C and flags it.
    let bytes = std::fs::read(&bin).unwrap();
    let t = model_core::parse(&bytes).unwrap();
    let fw = Model::load(&t).unwrap();
    let at = |mc: i32| {
        let mut temp_mc = [0; MAX_TEMPS];
        temp_mc[0] = mc;
        fw.eval_fixed(&Inputs {
            pos_nm: [200_000_000, 0, 0],
            rev_q30: [1 << 30, 0, 0],
            temp_mc,
            tool_nm: 0,
        })
    };
    let (edge, hot) = (at(21_710), at(40_000));
    assert_eq!(hot.corr_nm[0], edge.corr_nm[0]);
    assert!(hot.flags.contains(model_core::Flags::TEMP_OUT_OF_RANGE));
    assert!(!edge.flags.contains(model_core::Flags::TEMP_OUT_OF_RANGE));

    // --temp-range-c overrides, for every channel.
    let v = export(&model, &["--temp-range-c", "-5..45"], &bin);
    assert_eq!(
        v["envelope"]["temp_range_c"],
        serde_json::json!([-5.0, 45.0])
    );
    let env = model_core::parse(&std::fs::read(&bin).unwrap())
        .unwrap()
        .envelope();
    assert_eq!((env.temp_min_mc[0], env.temp_max_mc[0]), (-5_000, 45_000));

    // A model file written before the range was recorded: still loads,
    // falls back to 10…40 °C and says so.
    let mut old = mj.clone();
    old["data"].as_object_mut().unwrap().remove("temp_range_c");
    let old_model = dir.join("old.model.json");
    std::fs::write(&old_model, serde_json::to_string_pretty(&old).unwrap()).unwrap();
    let out = run(&["export", s(&old_model), "-o", s(&bin), "--json"]);
    let v = json(&out);
    assert_eq!(
        v["envelope"]["temp_range_c"],
        serde_json::json!([10.0, 40.0])
    );
    let w = find_warning(&v, "temp_range_unknown").unwrap_or_else(|| panic!("{v}"));
    assert!(
        w["detail"].as_str().unwrap().contains("T_bed_C")
            && w["detail"].as_str().unwrap().contains("--temp-range-c"),
        "{w}"
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning (temp_range_unknown)"));
}

/// A model whose largest correction is ~3 mm (R8): the default limit is
/// 1.5 × that, above the 4 mm every export allows. The message says which
/// number is which and names --max-corr-um; the same rule refuses the
/// controller files, and an explicit --max-corr-um below what a
/// controller file would hold refuses it too (it cannot clamp).
#[test]
fn max_correction_limit_applies_to_every_format() {
    let dir = tmp_dir("export", "maxcorr");
    let csv = dir.join("big.csv");
    let mut text = String::from("x_mm,ex_um\n");
    for i in 0..=80 {
        let x = f64::from(i) * 10.0;
        let e =
            3000.0 * (2.0 * std::f64::consts::PI * x / 1600.0).sin() + 500.0 * (x / 800.0).powi(2);
        text.push_str(&format!("{x},{e:.1}\n"));
    }
    std::fs::write(&csv, text).unwrap();
    let model = dir.join("big.model.json");
    fit_cubic19(&csv, &model);
    let mf = ModelFile::load(&model).unwrap();
    let xs: Vec<f64> = (0..=8000).map(|i| 0.1 * f64::from(i)).collect();
    let largest = predict_ex(&mf, &xs, 1, None)
        .iter()
        .fold(0.0f64, |m, e| m.max(e.abs()));
    assert!(
        (2500.0..4000.0).contains(&largest) && 1.5 * largest > 4000.0,
        "{largest}"
    );
    let out = dir.join("big.out");
    for format in ["table", "linuxcnc", "sinumerik"] {
        // The table's figure is over its sweep; a controller file's over
        // its points (a hair less).
        let (default, own) = if format == "table" {
            (format!("{:.1}", 1.5 * largest), format!("{largest:.1}"))
        } else {
            ("460".to_string(), "306".to_string())
        };
        let err = expect_exit(
            &export_args(&model, &["--format", format], &out),
            1,
            &[
                &format!("ex: the default max |correction| {default}"),
                &format!("(1.5 × the model's largest correction, {own}"),
                "exceeds the table's limit of 4000 µm",
                "--max-corr-um",
            ],
        );
        assert!(!out.exists(), "{format}: {err}");
    }
    // An explicit limit: the table clamps (warned); a controller file
    // would hold more than it, so it is refused and not written.
    let v = export(&model, &["--max-corr-um", "4000"], &out);
    assert_eq!(v["envelope"]["max_corr_um"][0], 4000.0);
    std::fs::remove_file(&out).unwrap();
    for format in ["linuxcnc", "sinumerik"] {
        expect_exit(
            &export_args(&model, &["--format", format, "--max-corr-um", "100"], &out),
            1,
            &["above --max-corr-um 100", "cannot clamp", "was not written"],
        );
        assert!(!out.exists());
    }

    // A small model: the controller file's limit is reported, and follows
    // the flag; below its largest trim it is refused.
    let line = line_model(&dir);
    let comp = dir.join("x.comp");
    let v = export(&line, &["--format", "linuxcnc"], &comp);
    let rows = read_linuxcnc(&std::fs::read_to_string(&comp).unwrap());
    let largest_mm = rows
        .iter()
        .fold(0.0f64, |m, r| m.max(r[1].abs()).max(r[2].abs()));
    let got = num(&v["max_corr_um"]);
    assert!(
        (got - 1.5 * 1000.0 * largest_mm).abs() < 0.01,
        "{got} vs {largest_mm} mm"
    );
    let v = export(
        &line,
        &["--format", "linuxcnc", "--max-corr-um", "50"],
        &comp,
    );
    assert_eq!(v["max_corr_um"], 50.0);
    std::fs::remove_file(&comp).unwrap();
    expect_exit(
        &export_args(
            &line,
            &["--format", "linuxcnc", "--max-corr-um", "1"],
            &comp,
        ),
        1,
        &[
            "ex: the linuxcnc file would hold corrections up to",
            "above --max-corr-um 1",
        ],
    );
    assert!(!comp.exists());
}

/// A flag of another format is a usage error (exit 2) naming the flag and
/// the formats it applies to — not silently ignored; --allow-error-nm
/// must be a finite number ≥ 0 (NaN would switch the check off).
#[test]
fn flags_of_another_format_and_bad_limits_are_usage_errors() {
    let dir = tmp_dir("export", "flags");
    let model = line_model(&dir);
    let out = dir.join("never.out");
    let o = s(&out);
    let m = s(&model);
    let cases: &[(&[&str], &str)] = &[
        (
            &["--points", "21"],
            "--points applies to --format linuxcnc and sinumerik only, not to --format table",
        ),
        (
            &["--axis", "x"],
            "--axis applies to --format linuxcnc and sinumerik only, not to --format table",
        ),
        (
            &["--sinumerik-axis", "X1"],
            "--sinumerik-axis applies to --format sinumerik only, not to --format table",
        ),
        (
            &["--format", "linuxcnc", "--sinumerik-axis", "X1"],
            "--sinumerik-axis applies to --format sinumerik only, not to --format linuxcnc",
        ),
        (
            &["--format", "linuxcnc", "--temp-range-c", "15..30"],
            "--temp-range-c applies to --format table only, not to --format linuxcnc",
        ),
        (
            &["--format", "sinumerik", "--drop-lag"],
            "--drop-lag applies to --format table only, not to --format sinumerik",
        ),
        (
            &["--format", "linuxcnc", "--allow-error-nm", "2"],
            "--allow-error-nm applies to --format table only",
        ),
        (
            &["--format", "sinumerik", "--max-slew-nm-per-ms", "10"],
            "--max-slew-nm-per-ms applies to --format table only",
        ),
        (
            &["--format", "linuxcnc", "--max-feed-mm-per-min", "5000"],
            "--max-feed-mm-per-min applies to --format table only",
        ),
        (
            &["--format", "linuxcnc", "--reversal-transition-um", "5"],
            "--reversal-transition-um applies to --format table only",
        ),
        (
            &["--format", "linuxcnc", "--tool-range-mm", "0..100"],
            "--tool-range-mm applies to --format table only",
        ),
        (
            &["--allow-error-nm", "nan"],
            "invalid value 'nan' for '--allow-error-nm",
        ),
        (
            &["--allow-error-nm", "inf"],
            "invalid value 'inf' for '--allow-error-nm",
        ),
        (
            &["--allow-error-nm", "-1"],
            "invalid value '-1' for '--allow-error-nm",
        ),
    ];
    for (extra, needle) in cases {
        let mut a = vec!["export", m, "-o", o, "--json"];
        a.extend_from_slice(extra);
        expect_exit(&a, 2, &[needle]);
        assert!(!out.exists(), "{extra:?}");
    }
    // The flags of each format are still accepted with it.
    for extra in [
        &[
            "--format",
            "sinumerik",
            "--sinumerik-axis",
            "X1",
            "--points",
            "21",
            "--axis",
            "x",
            "--max-corr-um",
            "50",
        ][..],
        &[
            "--temp-range-c",
            "15..30",
            "--allow-error-nm",
            "2",
            "--max-slew-nm-per-ms",
            "100",
            "--max-feed-mm-per-min",
            "5000",
            "--reversal-transition-um",
            "5",
            "--drop-lag",
            "--tool-range-mm",
            "0..0",
            "--max-corr-um",
            "50",
        ][..],
    ] {
        export(&model, extra, &out);
        std::fs::remove_file(&out).unwrap();
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
    assert!(
        text.contains("differs from the full model by at most 3.0")
            && text.contains("(terms left out included)"),
        "{text}"
    );
    assert!(text.contains("$MA_BACKLASH = 0.000000 mm"), "{text}");
    assert!(
        text.contains("mean reversal (fwd − rev) 0.000 µm"),
        "{text}"
    );
    assert!(!text.contains("-0.0"), "{text}");
}

/// A grid table over what the firmware's model can load is refused (exit
/// 1, nothing written) with the step to fit instead; one over the board's
/// smaller store is written but warned with the same hint; the hinted step
/// fits.
#[test]
fn grid_over_capacity_is_refused_with_a_coarser_step() {
    let dir = tmp_dir("export", "gridcap");
    let csv = simulate_grid(&dir, "g.csv", 7);
    let fit_grid = |step: &str| {
        let model = dir.join(format!("g{step}.model.json"));
        fit(&csv, &["--model", &format!("grid:{step}")], &model);
        model
    };
    let bin = dir.join("g.bin");
    expect_exit(
        &["export", s(&fit_grid("60")), "-o", s(&bin)],
        1,
        &[
            "model needs 4500 grid values, capacity is 2048; nothing was written",
            "fit a coarser grid: grid:60 holds 4500 values over 3 output(s); grid:108 or coarser (972 values) fits the board's 1024",
        ],
    );
    assert!(!bin.exists());
    let out = run(&["export", s(&fit_grid("90")), "-o", s(&bin), "--json"]);
    let v = json(&out);
    assert_eq!(v["board"]["fits"], false);
    let w = find_warning(&v, "board_refuses").unwrap_or_else(|| panic!("{v}"));
    assert!(
        w["detail"]
            .as_str()
            .unwrap()
            .contains("grid:108 or coarser"),
        "{w}"
    );
    let v = export(&fit_grid("108"), &[], &bin);
    assert_eq!(v["board"]["fits"], true, "{v}");
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
