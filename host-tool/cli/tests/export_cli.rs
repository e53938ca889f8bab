//! `trueaxis export` end to end through the binary, for each format.
//!
//! - **table**: the `--json` of docs/cli.md agrees with the file (length,
//!   an independently computed CRC-32), the file parses with model-core as
//!   the firmware parses it, its envelope is the data's span and follows
//!   `--max-corr-um` / `--max-slew-nm-per-ms` / `--max-feed-mm-per-min`, the
//!   firmware's evaluation is −error (nm) of the host model, a failed
//!   accuracy check exits 1 without writing, a thermal lag is refused
//!   without `--drop-lag`, a drift term is left out with a warning.
//! - The controllers' files (linuxcnc, sinumerik) and their golden files
//!   are tested in `export_controllers_cli.rs`.
//! - Bad input: missing / truncated / non-model files, an axis the model
//!   does not use, out-of-range options → exit 1 with a clear message.

mod common;

use common::export::*;
use common::{
    expect_exit, export, export_args, find_warning, fit, fit_cubic19, golden, json, run, run_env,
    s, simulate_grid, tmp_dir, warning_codes,
};
use model_core::{Inputs, Model, MAX_TEMPS};
use serde_json::Value;
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

// ---------------------------------------------------------------------------
// Data and models.

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
    let codes = warning_codes(&v);
    assert!(codes.contains(&"max_corr_below_model"), "{v}");
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
    // A slew the format (and the board) refuses is refused here with the
    // limit named (issue 14: 400 000 000 nm/ms crashed the board); a feed
    // so high that the default slew would pass it gives the limit.
    expect_exit(
        &export_args(&model, &["--max-slew-nm-per-ms", "400000000"], &bin),
        1,
        &["--max-slew-nm-per-ms 400000000: a table holds at most 10000000 nm/ms"],
    );
    let (_, env) = envelope(&["--max-feed-mm-per-min", "1e11"]);
    assert_eq!(
        env.max_slew_nm_per_ms,
        model_core::table::MAX_SLEW_LIMIT_NM_PER_MS
    );
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
    let lagged = "thermal:target=ex,channel=bed,times=x,lag_s=300";
    let mut args = common::CUBIC19_REVERSAL_X.to_vec();
    args.extend(["--add", lagged, "--add", "drift:target=ex"]);
    fit(&csv, &args, &model);
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
    common::assert_has(&err, &["warning (drift_left_out)", "warning (lag_dropped)"]);
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

// ---------------------------------------------------------------------------
// Sinumerik.

// ---------------------------------------------------------------------------
// Golden files.

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
    let cut = common::file_in(&dir, "cut.model.json", &text[..text.len() / 3]);
    expect_exit(
        &["export", s(&cut), "-o", o],
        1,
        &[s(&cut), "not a trueaxis model file"],
    );
    let not_model = common::file_in(
        &dir,
        "other.json",
        r#"{"bytes": 316, "crc32": "0x00000000"}"#,
    );
    expect_exit(
        &["export", s(&not_model), "-o", o, "--format", "linuxcnc"],
        1,
        &[s(&not_model), "not a trueaxis model file"],
    );
    let garbage = common::file_in(&dir, "garbage.json", [0xff, 0xfe, 0x00, 0x41]);
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
    // … and before the checksum was written (docs/cli.md § MODEL.json).
    old.as_object_mut().unwrap().remove("checksum_sha256");
    let old_model = common::file_in(
        &dir,
        "old.model.json",
        serde_json::to_string_pretty(&old).unwrap(),
    );
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
