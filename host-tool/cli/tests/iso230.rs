//! ISO 230-2 against a worked example computed by hand (below), through the
//! library and the CLI (JSON keys of docs/cli.md, plot with --report),
//! from both the contract CSV and the equivalent Renishaw .rtl file.
//!
//! The example (tests/data/iso_worked.csv and .rtl): targets 0, 100, 200 mm,
//! two runs each way. Readings x_ij in µm:
//!
//! | target | ↑ (runs 1, 3) | ↓ (runs 2, 4) |
//! | ---    | ---           | ---           |
//! | 0      | 1.0, 2.0      | -1.0, 0.0     |
//! | 100    | 3.0, 5.0      | 2.0, 2.0      |
//! | 200    | -1.0, 1.0     | -3.0, -2.0    |
//!
//! Per target (s with n − 1 = 1, so s = |a − b| / √2):
//! - 0 mm:   x̄↑ = 1.5, s↑ = 1/√2 = 0.707107; x̄↓ = −0.5, s↓ = 0.707107;
//!   x̄ = 0.5; B = 2.0; R↑ = R↓ = 4·0.707107 = 2.828427;
//!   2s↑ + 2s↓ + |B| = 1.414214 + 1.414214 + 2 = 4.828427 → R = 4.828427.
//! - 100 mm: x̄↑ = 4.0, s↑ = 2/√2 = 1.414214; x̄↓ = 2.0, s↓ = 0; x̄ = 3.0;
//!   B = 2.0; R↑ = 5.656854, R↓ = 0; 2.828427 + 0 + 2 = 4.828427
//!   → R = max(4.828427, 5.656854, 0) = 5.656854.
//! - 200 mm: x̄↑ = 0.0, s↑ = 1.414214; x̄↓ = −2.5, s↓ = 0.707107;
//!   x̄ = −1.25; B = 2.5; R↑ = 5.656854, R↓ = 2.828427;
//!   2.828427 + 1.414214 + 2.5 = 6.742641 → R = 6.742641.
//!
//! Axis values:
//! - B = max|B_i| = 2.5; B̄ = (2 + 2 + 2.5)/3 = 2.166667.
//! - R↑ = 5.656854, R↓ = 2.828427, R = 6.742641.
//! - E↑ = 4 − 0 = 4; E↓ = 2 − (−2.5) = 4.5; E = 4 − (−2.5) = 6.5.
//! - M = 3 − (−1.25) = 4.25.
//! - A↑: max(x̄↑ + 2s↑) = max(2.914214, 6.828427, 2.828427) = 6.828427,
//!   min(x̄↑ − 2s↑) = min(0.085786, 1.171573, −2.828427) = −2.828427
//!   → A↑ = 9.656854.
//! - A↓: max(x̄↓ + 2s↓) = max(0.914214, 2, −1.085786) = 2,
//!   min(x̄↓ − 2s↓) = min(−1.914214, 2, −3.914214) = −3.914214
//!   → A↓ = 5.914214.
//! - A = max(6.828427, 2) − min(−2.828427, −3.914214) = 10.742641.

mod common;

use common::{assert_success, data_file, json, run, s};
use trueaxis_engine::{import, iso230};
use trueaxis_test_support::assert_any;

const TOL: f64 = 1e-6;

fn close(got: f64, want: f64, what: &str) {
    assert!((got - want).abs() < TOL, "{what}: got {got}, want {want}");
}

fn check_worked(r: &iso230::Iso230) {
    assert_eq!(r.axis, "x");
    assert_eq!(r.targets, 3);
    assert_eq!(r.runs, 2);
    close(r.b_um, 2.5, "B");
    close(r.b_mean_um, 6.5 / 3.0, "B mean");
    close(r.r_up_um, 5.656854, "R up");
    close(r.r_down_um, 2.828427, "R down");
    close(r.r_um, 6.742641, "R");
    close(r.e_up_um, 4.0, "E up");
    close(r.e_down_um, 4.5, "E down");
    close(r.e_um, 6.5, "E");
    close(r.m_um, 4.25, "M");
    close(r.a_up_um, 9.656854, "A up");
    close(r.a_down_um, 5.914214, "A down");
    close(r.a_um, 10.742641, "A");
    let t = &r.per_target;
    assert_eq!(
        t.iter().map(|s| s.pos_mm).collect::<Vec<_>>(),
        vec![0.0, 100.0, 200.0]
    );
    close(t[0].mean_up_um, 1.5, "x̄↑ 0");
    close(
        t[0].s_down_um,
        std::f64::consts::FRAC_1_SQRT_2,
        "s↓ 0 = 1/√2",
    );
    close(t[1].r_um, 5.656854, "R 100");
    close(t[2].mean_um, -1.25, "x̄ 200");
    close(t[2].b_um, 2.5, "B 200");
}

#[test]
fn worked_example_from_csv_and_rtl() {
    for f in ["iso_worked.csv", "iso_worked.rtl"] {
        let d = import::load(&data_file(f)).unwrap();
        let r = iso230::evaluate(&d, 0).unwrap();
        check_worked(&r);
        assert_eq!(r.rows_used, 12, "{f}");
        assert_eq!(r.rows_ignored, 0, "{f}");
    }
}

#[test]
fn cli_json_keys_and_plot() {
    let dir = std::env::temp_dir().join(format!("trueaxis-iso-{}", std::process::id()));
    let out = run(&[
        "iso230",
        s(&data_file("iso_worked.csv")),
        "--axis",
        "x",
        "--json",
        "--report",
        s(&dir),
    ]);
    let v = json(&out);
    for k in [
        "axis",
        "targets",
        "runs",
        "B_um",
        "B_mean_um",
        "R_up_um",
        "R_down_um",
        "R_um",
        "E_up_um",
        "E_down_um",
        "E_um",
        "M_um",
        "A_up_um",
        "A_down_um",
        "A_um",
        "per_target",
    ] {
        assert!(v.get(k).is_some(), "missing key {k} in {v}");
    }
    assert_eq!(v["axis"], "x");
    assert_eq!(v["targets"], 3);
    assert!((v["A_um"].as_f64().unwrap() - 10.742641).abs() < TOL);
    let t0 = &v["per_target"][0];
    for k in [
        "pos_mm",
        "n_up",
        "n_down",
        "mean_up_um",
        "mean_down_um",
        "mean_um",
        "s_up_um",
        "s_down_um",
        "B_um",
        "R_um",
    ] {
        assert!(t0.get(k).is_some(), "missing per_target key {k}");
    }
    let svg = std::fs::read_to_string(dir.join("iso230_x.svg")).expect("plot written");
    assert!(svg.starts_with("<svg"), "an SVG document");
    assert!(svg.contains("<text"), "labels as SVG text");
    assert!(svg.contains("A = 10.74"), "caption with A");
    // The page: the verdict card first, then the plot and the table.
    assert_eq!(v["report"], s(&dir.join("index.html")));
    let html = std::fs::read_to_string(dir.join("index.html")).expect("page written");
    let body = &html[html.find("</h1>").unwrap() + 5..];
    assert!(
        body.trim_start().starts_with("<section id=\"verdict\""),
        "{body}"
    );
    assert!(body.contains("Axis x: accuracy A = 10.7 µm"), "{body}");
    assert!(body.contains("<pre class=\"next\">trueaxis fit "), "{body}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn human_table_without_json() {
    let out = run(&["iso230", data_file("iso_worked.rtl").to_str().unwrap()]);
    assert_success(&out);
    let s = String::from_utf8(out.stdout).unwrap();
    assert!(s.contains("axis x: 3 targets, 2 bidirectional runs"), "{s}");
    assert!(s.contains("A  =   10.743 µm"), "{s}");
}

/// A run along x at fixed y and z (what `simulate --plan iso230:x`, and a
/// laser on one axis, writes: all three axes have position, error and
/// direction columns): x is the axis, without `--axis`. Two moving axes
/// still need `--axis`.
#[test]
fn the_default_axis_is_the_one_that_moves() {
    let mut text = String::from("x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,dir_x,dir_y,dir_z\n");
    for (x, e, d) in [
        (0, 1.0, 1),
        (100, 3.0, 1),
        (0, -1.0, -1),
        (100, 2.0, -1),
        (0, 2.0, 1),
        (100, 5.0, 1),
        (0, 0.0, -1),
        (100, 2.0, -1),
    ] {
        text.push_str(&format!("{x},250,40,{e},0.1,0.2,{d},1,1\n"));
    }
    let d = import::read_csv(text.as_bytes(), "line.csv").unwrap();
    assert_eq!(iso230::default_axis(&d).unwrap(), 0);
    let moving_y = text.replacen("0,250,40,1,", "0,251,40,1,", 1);
    let d = import::read_csv(moving_y.as_bytes(), "xy.csv").unwrap();
    let e = iso230::default_axis(&d).unwrap_err().to_string();
    assert!(e.contains("several axes could be evaluated (x, y)"), "{e}");
}

#[test]
fn one_direction_only_is_bad_input() {
    // Only the forward runs of the worked example.
    let text = "x_mm,ex_um,dir_x\n0,1,1\n100,3,1\n0,2,1\n100,5,1\n";
    let d = import::read_csv(text.as_bytes(), "fwd.csv").unwrap();
    let e = iso230::evaluate(&d, 0).unwrap_err().to_string();
    assert!(
        e.contains("0 reading(s) approached in the negative direction"),
        "{e}"
    );
    let no_dir = import::read_csv("x_mm,ex_um\n0,1\n100,2\n".as_bytes(), "nodir.csv").unwrap();
    let e = iso230::evaluate(&no_dir, 0).unwrap_err().to_string();
    assert!(e.contains("no dir_x column"), "{e}");
}

/// A reading with no error value is left out on load: the evaluation is
/// the worked example's, `rows_ignored` stays 0 (it counts readings of the
/// data set that were not evaluated) and `skipped_count` says 1, with the
/// line on stderr.
#[test]
fn rows_left_out_on_load_are_counted_and_said() {
    let dir = common::tmp_dir("iso230", "skipped");
    let holed = dir.join("holed.csv");
    let line = common::with_blank_error_row(&data_file("iso_worked.csv"), &holed);
    let out = common::run(&["iso230", s(&holed), "--json"]);
    let v = common::json(&out);
    assert_eq!(v["skipped_count"], 1);
    assert_eq!(v["rows_ignored"], 0);
    assert_eq!(v["rows_used"], 12);
    assert!((v["A_um"].as_f64().unwrap() - 10.742641).abs() < TOL);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("(line {line}: no error value on this row)")),
        "{err}"
    );
    let clean = common::run(&["iso230", s(&data_file("iso_worked.csv")), "--json"]);
    assert_eq!(common::json(&clean)["skipped_count"], 0);
    let _ = std::fs::remove_dir_all(dir);
}

/// `--axis` reaches the .rtl reader: a file whose USER-TEXT:: has no
/// `Axis:` line is evaluated along the axis named on the command line
/// (before, it failed with "no `Axis:` line … or pass --axis" even when
/// --axis was passed).
#[test]
fn axis_option_reaches_the_rtl_reader() {
    let dir = common::tmp_dir("iso230", "axis");
    let text = std::fs::read_to_string(data_file("iso_worked.rtl")).unwrap();
    assert!(text.contains("Axis: X\r\n"));
    let no_axis = common::file_in(&dir, "no_axis.rtl", text.replace("Axis: X\r\n", ""));
    let f = s(&no_axis);

    let out = common::run(&["iso230", f]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("or pass --axis"));

    let v = common::json(&common::run(&["iso230", f, "--axis", "x", "--json"]));
    assert_eq!(v["axis"], "x");
    assert!((v["A_um"].as_f64().unwrap() - 10.742641).abs() < TOL);
    // The same runs read as Y: the axis named wins, the numbers are the same.
    let v = common::json(&common::run(&["iso230", f, "--axis", "y", "--json"]));
    assert_eq!(v["axis"], "y");
    assert!((v["A_um"].as_f64().unwrap() - 10.742641).abs() < TOL);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_page_shows_every_run_and_the_test_conditions() {
    // Issue 28: individual runs were not plotted (one reading 100 µm off
    // was invisible) and the .rtl's test conditions were dropped.
    let dir = std::env::temp_dir().join(format!("trueaxis-iso-page-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let rtl = data_file("iso_worked.rtl");
    json(&run(&["iso230", s(&rtl), "--report", s(&dir), "--json"]));
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    for want in [
        "Test conditions",
        "VMC-1",
        "SN-42",
        "2026-11-20",
        "A. Tester",
        "20.1 C",
        "XL-80",
    ] {
        assert!(html.contains(want), "{want} missing from the page");
    }
    // The 12 readings as open dots (stroke, no fill) beside the 6 means.
    let svg = std::fs::read_to_string(dir.join("iso230_x.svg")).unwrap();
    let open = svg
        .split("<circle")
        .skip(1)
        .filter(|c| c[..c.find("/>").unwrap()].contains("fill=\"none\""))
        .count();
    assert!(open >= 12, "{open} open dots: the runs are not plotted");
    // The legend sits right of the plot area: its text starts right of
    // the last x tick label (200.0).
    let x_of = |text: &str| -> f64 {
        let at = svg.find(text).unwrap_or_else(|| panic!("{text}"));
        let head = &svg[svg[..at].rfind("<text").unwrap()..at];
        let (_, x) = head.split_once("x=\"").unwrap();
        x[..x.find('"').unwrap()].parse().unwrap()
    };
    assert!(x_of("x̄↑ ± 2s (from below)") > x_of("200.0\n</text>") + 10.0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// An ISO 230-2 run of 10 targets, 5 runs per direction, with a 1 µm
/// scatter; `bad` replaces one reading (run 1, the 4th target, ↑) with
/// +93 µm against its neighbours' ~−21 µm, as on a public ecmc run.
fn iso_with(bad: bool) -> trueaxis_engine::data::Dataset {
    let (mut x, mut e, mut dir, mut pass) = (vec![], vec![], vec![], vec![]);
    let mut rng = trueaxis_test_support::SplitMix64::new(24);
    for run in 1..=10i64 {
        let up = run % 2 == 1;
        for i in 0..10 {
            let i = if up { i } else { 9 - i };
            let scatter = rng.normal();
            let mut v = -21.0 + 0.5 * i as f64 + if up { 0.0 } else { 3.0 } + scatter;
            if bad && run == 1 && i == 3 {
                v = 93.0;
            }
            x.push(i as f64 * 50.0);
            e.push(Some(v));
            dir.push(if up { 1 } else { -1 });
            pass.push(run);
        }
    }
    let n = x.len();
    trueaxis_engine::data::Dataset {
        source: "run.csv".into(),
        pos_mm: [Some(x), None, None],
        err_um: [Some(e), None, None],
        dir: [Some(dir), None, None],
        pass_id: Some(pass),
        line: (2..n + 2).collect(),
        ..Default::default()
    }
}

/// One bad reading (issue 24): the standard's figures keep it, the reading
/// is flagged with its run, target, value and A and R without it, and the
/// card does not turn green because of it.
#[test]
fn one_bad_reading_is_flagged_and_the_figures_kept() {
    let clean = iso230::evaluate(&iso_with(false), 0).unwrap();
    assert!(clean.flags.is_empty(), "{:?}", clean.flags);
    let r = iso230::evaluate(&iso_with(true), 0).unwrap();
    assert_eq!(r.flags.len(), 1, "{:?}", r.flags);
    let f = &r.flags[0];
    assert_eq!((f.row, f.line, f.run, f.dir), (3, Some(5), Some(1), 1));
    assert_eq!((f.target_mm, f.value_um), (150.0, 93.0));
    // The standard's figures keep the reading: A is set by it.
    assert!(r.a_um > 100.0 && r.r_um > 100.0, "{} {}", r.a_um, r.r_um);
    assert!(f.a_without_um < 15.0 && f.r_without_um < 10.0, "{f:?}");
    assert!(
        (f.a_without_um - clean.a_um).abs() < 2.0,
        "{f:?} {}",
        clean.a_um
    );
    let text = r.table();
    assert!(
        text.contains("flagged: run 1, target 150 mm ↑: +93.000 µm"),
        "{text}"
    );
    let v = trueaxis::report::iso230::verdict(&r, "run.csv");
    assert_any(&v.warnings, |w| {
        w.starts_with("flagged reading: run 1, target 150 mm")
    });
    assert_ne!(v.tone, trueaxis::report::Tone::Good);
    let reads = trueaxis::report::iso230::flagged_readings(&iso_with(true), 0, &r);
    assert_eq!(reads.iter().filter(|x| x.flag.is_some()).count(), 1);
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["flags"][0]["run"], 1);
    assert!(json["flags"][0]["A_without_um"].as_f64().unwrap() < 15.0);
}
