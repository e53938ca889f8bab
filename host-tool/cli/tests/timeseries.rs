//! Time series at one point are first-class: the spindle thermal test
//! (`simulate --scenario spindle-thermal`, 48 h at one position, 12
//! temperature sensors, readings quantised to 0.25 µm) is fitted, not
//! refused; `diagnose` and `improve` name the two temperature channels that
//! drive the growth (a multi-sensor thermal effect), not a polynomial in
//! time nor the best single proxy; no held-out RMS is NaN; compare and
//! export work on the model.

mod common;

use common::{json, run, s, tmp_dir};
use std::path::Path;

#[test]
fn a_thermal_test_at_one_point_is_fitted_and_its_temperature_named() {
    let dir = tmp_dir("timeseries", "spindle");
    let csv = dir.join("spindle.csv");
    let sim = common::simulate(&["--scenario", "spindle-thermal", "--seed", "1"], &csv);
    assert_eq!(sim["rows"], 2881);
    // fit: a constant per target, said in a warning (it used to stop with
    // "every measured point lies at one position").
    let fit = json(&common::cubic19("fit", &csv, &dir.join("m.json"), &[]));
    assert_eq!(fit["terms"], 1);
    assert!(fit["warnings"][0]
        .as_str()
        .unwrap()
        .contains("reduced to a constant per target"));
    for t in ["ex", "ey", "ez"] {
        assert!(fit["held_out_rms_um"][t].as_f64().unwrap().is_finite());
    }
    // diagnose: held-out RMS finite everywhere; the growth of ez is a
    // spindle temperature's, and no drift is significant.
    let report = dir.join("report");
    let d = common::diagnose_report(&csv, "cubic19", &report);
    // The multi-sensor component is drawn against time.
    let svg = std::fs::read_to_string(report.join("component_ez_1.svg")).unwrap();
    assert!(svg.contains("t_s (s)"));
    assert_eq!(d["verdict"], "missing_effect");
    for t in ["ex", "ey", "ez"] {
        assert!(d["held_out_rms_um"][t].as_f64().unwrap().is_finite(), "{t}");
    }
    // No candidate in position along an axis that never moves (squareness,
    // thermal × x, higher_order …): each was an `in_model_span` line; and
    // no `one_direction` for an axis that never moves (no backlash to find).
    assert!(
        d["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .all(|w| w["code"] != "in_model_span" && w["code"] != "one_direction"),
        "{}",
        d["warnings"]
    );
    let cands = d["candidates"].as_array().unwrap();
    let best = &cands[0];
    assert_eq!(best["significant"], true);
    assert_eq!(best["effect"], "thermal");
    assert_eq!(best["target"], "ez");
    assert_eq!(best["hold_out"], "forward");
    // The two sensors the growth follows (simulate::thermal_test::DRIVING),
    // each with its lag (0 s in the scenario), as one multi-sensor effect —
    // not the best single proxy (the rear bearing with a 1013 s lag).
    assert_eq!(
        best["add"], "thermal:target=ez,channel=column_front+spindle_housing",
        "{best}"
    );
    assert_eq!(best["channel"], "T_column_front_C+T_spindle_housing_C");
    assert!(best["rms_um_after"].as_f64().unwrap() < 0.15, "{best}");
    assert!(cands
        .iter()
        .all(|c| c["effect"] != "drift" || c["significant"] == false));
    // improve: the loop adds the two temperatures, never drift.
    improve_adds_the_two_temperatures_never_drift(&csv, &dir.join("imp.json"));
}

/// `improve` on `csv` (cubic19, model written to `model`) adds the two
/// temperatures of the thermal test, and no drift in time.
fn improve_adds_the_two_temperatures_never_drift(csv: &Path, model: &Path) {
    let imp = json(&common::cubic19("improve", csv, model, &[]));
    let model = imp["model"].as_str().unwrap();
    assert!(
        model.contains("thermal:target=ez,channel=column_front+spindle_housing"),
        "{model}"
    );
    assert!(!model.contains("drift"), "{model}");
}

#[test]
fn in_model_span_is_one_line_in_text_and_every_one_in_json_and_verbose() {
    let dir = tmp_dir("timeseries", "in_span");
    let csv = common::simulate_grid(&dir, "g.csv", 3);
    let j = json(&run(&["diagnose", s(&csv), "--model", "cubic19", "--json"]));
    let n = common::warning_codes(&j)
        .into_iter()
        .filter(|&c| c == "in_model_span")
        .count();
    assert!(n >= 2, "{n}");
    let lines = |args: &[&str]| {
        let out = run(args);
        common::assert_success(&out);
        String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .filter(|l| l.contains("[in_model_span]"))
            .count()
    };
    assert_eq!(lines(&["diagnose", s(&csv), "--model", "cubic19"]), 1);
    assert_eq!(
        lines(&["diagnose", s(&csv), "--model", "cubic19", "--verbose"]),
        n
    );
}

#[test]
fn a_thermal_model_at_one_point_compares_and_exports() {
    let dir = tmp_dir("timeseries", "export");
    let csv = dir.join("spindle.csv");
    common::simulate(&["--scenario", "spindle-thermal"], &csv);
    let model = dir.join("m.json");
    let add = "thermal:target=ez,channel=spindle_housing";
    json(&run(&[
        "fit",
        s(&csv),
        "--model",
        "cubic19",
        "--add",
        add,
        "-o",
        s(&model),
        "--json",
    ]));
    let c = json(&run(&["compare", s(&csv), "--model", s(&model), "--json"]));
    assert!(c["rms_um"]["ez"].as_f64().unwrap() < 1.0, "{}", c["rms_um"]);
    let table = dir.join("t.bin");
    let e = json(&run(&["export", s(&model), "-o", s(&table), "--json"]));
    assert!(e["max_f32_error_nm"].as_f64().unwrap() < 5.0);
    assert_eq!(
        e["envelope"]["travel_mm"],
        serde_json::json!([null, null, null])
    );
    let w = common::find_warning(&e, "measured_at_one_point").expect("warned");
    assert!(w["detail"].as_str().unwrap().contains("x = 400 mm"), "{w}");
    // A sensor name longer than the table's 16 bytes: named, with the limit.
    let long = dir.join("long.csv");
    let text = std::fs::read_to_string(&csv)
        .unwrap()
        .replace("T_spindle_housing_C", "T_spindle_housing_sensor_C");
    std::fs::write(&long, text).unwrap();
    let lm = dir.join("long.json");
    json(&run(&[
        "fit",
        s(&long),
        "--model",
        "cubic19",
        "--add",
        "thermal:target=ez,channel=spindle_housing_sensor",
        "-o",
        s(&lm),
        "--json",
    ]));
    common::expect_exit(
        &["export", s(&lm), "-o", s(&dir.join("l.bin"))],
        1,
        &["T_spindle_housing_sensor_C", "at most 16 bytes"],
    );
}

/// The user-eye test: the thermal test with a fake travel added
/// (x stepping 400 … 440 mm, so the seed has position terms and the old
/// hold-out was spatial) — `improve` picked `drift:order=3` over the
/// temperatures. It adds the two driving sensors now.
#[test]
fn with_a_fake_travel_improve_still_picks_the_temperatures_not_drift() {
    let dir = tmp_dir("timeseries", "fake_travel");
    let csv = dir.join("spindle.csv");
    common::simulate(&["--scenario", "spindle-thermal"], &csv);
    let mut row = 0usize;
    let text: Vec<String> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .map(|l| {
            if l.starts_with('#') || l.starts_with("x_mm") {
                return l.to_string();
            }
            let rest = l.split_once(',').unwrap().1;
            row += 1;
            format!("{},{rest}", 400 + ((row - 1) % 5) * 10)
        })
        .collect();
    let fake = common::file_in(&dir, "fake.csv", text.join("\n") + "\n");
    improve_adds_the_two_temperatures_never_drift(&fake, &dir.join("m.json"));
}

/// A warm-up read at one point for 30 min (`point:` plan, one spindle
/// sensor with a 600 s lag): a cubic in time explains the same residual
/// nearly as well (ΔBIC −1880 against −1884), and both predict the rest of
/// a smooth warm-up. Before, neither was significant ("no clear gap to the
/// competing candidate") and the verdict was `at_noise_floor` with 1 µm
/// left; the temperature is now taken, and its evidence names the drift.
#[test]
fn a_temperature_is_preferred_over_a_drift_that_explains_the_same_warm_up() {
    let dir = tmp_dir("timeseries", "warm_up");
    let csv = dir.join("warm.csv");
    common::assert_success(&run(&[
        "simulate",
        "--preset",
        "perfect800",
        "--plan",
        "point:x=400,y=250,z=250,repeats=600",
        "--effect",
        "thermal:channel=spindle,target=ez,times=none,offset_um_per_k=-2,cte_um_per_m_k=0,rise_c=8,tau_s=5400,lag_s=600",
        "--noise-um",
        "0.2",
        "-o",
        s(&csv),
    ]));
    let d = json(&run(&["diagnose", s(&csv), "--model", "cubic19", "--json"]));
    assert_eq!(d["verdict"], "missing_effect");
    let best = &d["candidates"][0];
    assert_eq!(best["significant"], true, "{best}");
    assert_eq!(best["effect"], "thermal", "{best}");
    assert_eq!(best["channel"], "T_spindle_C");
    let ev = best["evidence"].as_str().unwrap();
    assert!(
        ev.contains("preferred over `drift:target=ez,order=3`"),
        "{ev}"
    );
}
