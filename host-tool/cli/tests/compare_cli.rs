//! `trueaxis compare` end to end through the binary, on a fixed-seed
//! simulated grid and the cubic19 model `trueaxis fit` makes of it: the
//! `--json` document has the keys of docs/cli.md / docs/cli.md per target,
//! and its numbers agree with an independent recomputation (the raw error
//! read straight from the CSV, the residual from the model file and our own
//! RMS / percentile code); `--report DIR` writes a page whose figures exist
//! and that needs no network; comparing with other data warns
//! `data_hash_mismatch`; and each class of bad input exits 1 with a message
//! that names the file (and line and column for a bad cell), usage errors 2.

mod common;

use std::path::Path;

use common::{
    compare, expect_exit, fit, fit_cubic19, golden_file, grid_cubic19, json, run, s, simulate_grid,
    tmp_dir, warning_codes, with_blank_error_row, CUBIC19_REVERSAL_X,
};
use serde_json::Value;
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

/// `trueaxis compare CSV --model MODEL --report REP --json`; returns its JSON.
fn compare_report(csv: &Path, model: &Path, rep: &Path) -> Value {
    json(&run(&[
        "compare",
        s(csv),
        "--model",
        s(model),
        "--report",
        s(rep),
        "--json",
    ]))
}

/// Names of the files in the report directory `rep` that start with `prefix`.
fn report_files(rep: &Path, prefix: &str) -> Vec<String> {
    std::fs::read_dir(rep)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with(prefix))
        .collect()
}

/// The `column` of a CSV as numbers, read with the csv crate directly (not
/// through trueaxis' importer): `#` lines before the header are skipped.
fn csv_column(path: &Path, column: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let body: String = text
        .lines()
        .skip_while(|l| l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    let mut r = csv::Reader::from_reader(body.as_bytes());
    let idx = r
        .headers()
        .unwrap()
        .iter()
        .position(|h| h == column)
        .unwrap_or_else(|| panic!("no column {column}"));
    r.records()
        .map(|rec| rec.unwrap()[idx].parse::<f64>().unwrap())
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Percentile of |v| with linear interpolation between order statistics
/// (Hyndman–Fan type 7, numpy's default) — written out here so the test
/// does not share the code it checks.
fn pct_abs(v: &[f64], p: f64) -> f64 {
    let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
    a.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let h = (a.len() - 1) as f64 * p / 100.0;
    let (lo, frac) = (h.floor() as usize, h - h.floor());
    if lo + 1 < a.len() {
        a[lo] + frac * (a[lo + 1] - a[lo])
    } else {
        a[lo]
    }
}

fn close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-9 * (1.0 + b.abs()),
        "{what}: {a} vs {b} (independent)"
    );
}

fn num(v: &Value, what: &str) -> f64 {
    v.as_f64()
        .unwrap_or_else(|| panic!("{what} is not a number: {v}"))
}

#[test]
fn json_has_the_contract_keys_and_numbers_that_recompute() {
    let dir = tmp_dir("compare", "json");
    let (csv, model, f) = grid_cubic19(&dir, "grid", 7);
    let v = compare(&csv, &model);

    assert_eq!(v["model"], "cubic19");
    assert_eq!(v["rows"], 324);
    for key in ["rms_um", "max_abs_um", "pv_um", "held_out_rms_um"] {
        let keys: Vec<&str> = v[key]
            .as_object()
            .unwrap_or_else(|| panic!("{key} missing: {v}"))
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(keys, ["ex", "ey", "ez"], "{key}");
    }
    let per_target = [
        "points",
        "rms_um",
        "mean_um",
        "max_abs_um",
        "pv_um",
        "p50_abs_um",
        "p95_abs_um",
        "p99_abs_um",
    ];
    let mf = ModelFile::load(&model).unwrap();
    let data = import::load(&csv).unwrap();
    let pred = mf.model.predict(&data).unwrap();
    for (t, name) in ["ex", "ey", "ez"].iter().enumerate() {
        let r = &v["targets"][*name];
        for key in per_target {
            assert!(r[key].is_number(), "targets.{name}.{key}: {r}");
            assert!(r["before"][key].is_number(), "targets.{name}.before.{key}");
        }
        assert!(r["improvement"].is_number() && r["held_out_rms_um"].is_number());

        // Before: the raw error column, read from the CSV by hand.
        let raw = csv_column(&csv, &format!("{name}_um"));
        assert_eq!(raw.len(), 324);
        let b = &r["before"];
        close(num(&b["rms_um"], "before rms"), rms(&raw), "before rms");
        let max_raw = raw.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        close(num(&b["max_abs_um"], "before max"), max_raw, "before max");
        close(
            num(&b["p95_abs_um"], "before p95"),
            pct_abs(&raw, 95.0),
            "before p95",
        );

        // After: residual = raw − the model file's prediction.
        let p = pred[t].as_ref().unwrap();
        let res: Vec<f64> = raw.iter().zip(p).map(|(e, m)| e - m).collect();
        let after_rms = num(&v["rms_um"][*name], "rms");
        close(after_rms, rms(&res), "residual rms");
        close(num(&r["rms_um"], "rms"), after_rms, "targets.rms = rms_um");
        let max_res = res.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        close(num(&v["max_abs_um"][*name], "max"), max_res, "residual max");
        let (lo, hi) = res
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        close(num(&v["pv_um"][*name], "pv"), hi - lo, "residual pv");
        for (key, p) in [
            ("p50_abs_um", 50.0),
            ("p95_abs_um", 95.0),
            ("p99_abs_um", 99.0),
        ] {
            close(num(&r[key], key), pct_abs(&res, p), key);
        }
        close(
            num(&r["improvement"], "improvement"),
            rms(&raw) / rms(&res),
            "improvement",
        );

        // Same data, same model: the fit's own numbers.
        close(after_rms, num(&f["rms_um"][*name], "fit rms"), "fit rms");
        close(
            num(&v["held_out_rms_um"][*name], "held out"),
            num(&f["held_out_rms_um"][*name], "fit held out"),
            "held-out",
        );
        // The model removes the geometric error: the residual is at the
        // noise level (σ = 0.2 µm), the raw error several µm.
        assert!(
            after_rms <= rms(&raw),
            "{name}: residual above the raw error"
        );
        assert!(
            after_rms < 0.3 && rms(&raw) > 2.0,
            "{name}: {after_rms} vs {}",
            rms(&raw)
        );
    }
    // Worst regions and channel profiles are there for every target.
    let regions = v["worst_regions"].as_array().unwrap();
    for name in ["ex", "ey", "ez"] {
        assert!(regions.iter().any(|r| r["target"] == name), "{name}");
    }
    let channels = v["channels"].as_array().unwrap();
    for ch in ["x_mm", "y_mm", "z_mm", "t_s", "dir_x"] {
        assert!(
            channels
                .iter()
                .any(|c| c["channel"] == ch && c["target"] == "ex"),
            "no profile of ex against {ch}"
        );
    }
    // The data are the data the model was fitted to: no warning.
    assert_eq!(v["warnings"], serde_json::json!([]), "{}", v["warnings"]);
    assert!(v["report"].is_null());

    // Text mode works and says the same RMS.
    let out = run(&["compare", s(&csv), "--model", s(&model)]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let ex_rms = format!("{:.3}", num(&v["rms_um"]["ex"], "rms"));
    assert!(text.contains("RMS µm") && text.contains(&ex_rms), "{text}");
}

#[test]
fn report_opens_offline_with_every_figure() {
    let dir = tmp_dir("compare", "report");
    let (csv, model, _) = grid_cubic19(&dir, "grid", 7);
    let rep = dir.join("rep");
    let v = compare_report(&csv, &model, &rep);
    let index = rep.join("index.html");
    assert_eq!(v["report"], s(&index));
    let html = std::fs::read_to_string(&index).unwrap();
    assert!(html.contains("<svg"), "figures are inlined");
    // Every linked figure exists beside the page and is an SVG.
    let links: Vec<&str> = html
        .split("href=\"")
        .skip(1)
        .filter_map(|rest| rest.split('"').next())
        .collect();
    let svgs: Vec<&&str> = links.iter().filter(|l| l.ends_with(".svg")).collect();
    assert!(svgs.len() >= 5, "too few figures: {links:?}");
    for l in &svgs {
        let p = rep.join(l);
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{l}: {e}"));
        assert!(text.contains("<svg"), "{l} is not an SVG");
        assert!(no_network(&text), "{l} fetches something");
    }
    // Residual maps per measured plane and the before/after figures.
    assert!(svgs.iter().any(|l| l.starts_with("map_ex_")), "{svgs:?}");
    assert!(
        svgs.iter().any(|l| l.starts_with("before_after")),
        "{svgs:?}"
    );
    // Nothing is loaded from the network: only the SVG namespace URIs
    // (names, never fetched) may appear.
    assert!(no_network(&html));
    assert!(!html.contains("<script src") && !html.contains("<link"));
    // The page opens with the verdict (what is left, where, the next
    // command), before any table or figure.
    let body = &html[html.find("</h1>").unwrap() + 5..];
    assert!(
        body.trim_start().starts_with("<section id=\"verdict\""),
        "{}",
        &body[..300.min(body.len())]
    );
    let verdict = &body[..body.find("</section>").unwrap()];
    let next = format!("trueaxis diagnose {} --model {}", s(&csv), s(&model));
    common::assert_has(verdict, &["After compensation e", &next]);
    // Figures scale to the window: no fixed pixel width on any SVG.
    for l in &svgs {
        let text = std::fs::read_to_string(rep.join(l)).unwrap();
        let head = &text[..text.find('>').unwrap()];
        assert!(
            head.contains("viewBox=") && !head.contains(" width="),
            "{l}: {head}"
        );
    }
    // The planes of a target are small multiples on one colour scale: the
    // page names the scale, and every map's colour bar ends at it.
    for t in ["ex", "ey"] {
        let key = format!("{t} residual on the measured planes — one colour scale, ±");
        let at = html.find(&key).unwrap_or_else(|| panic!("{key}"));
        let limit = html[at + key.len()..].split(' ').next().unwrap();
        let maps: Vec<&&&str> = svgs
            .iter()
            .filter(|l| l.starts_with(&format!("map_{t}_")) && !l.contains("before_after"))
            .collect();
        assert!(maps.len() >= 2, "{maps:?}");
        for l in maps {
            let text = std::fs::read_to_string(rep.join(l)).unwrap();
            assert!(
                text.contains(&format!("\n{limit}\n</text>")),
                "{l}: colour bar does not end at ±{limit}"
            );
        }
    }
    assert!(html.contains("<div class=\"grid\">"), "planes side by side");
    // x–y plots two per row, not one 30 000 px column.
    assert!(
        html.contains("<div class=\"grid wide\">\n<figure id=\"channel0\""),
        "channel plots in a grid"
    );
    assert!(html.contains("<div class=\"grid wide\">\n<figure id=\"before_after_rms\""));
}

/// Three planes, one per orientation (the plans of a user who measures
/// line → plane → volume): each gets its residual maps, not just the
/// planes facing the first orientation found.
#[test]
fn report_maps_every_plane_in_every_orientation() {
    let dir = tmp_dir("compare", "planes");
    let csv = dir.join("planes.csv");
    common::simulate(
        &[
            "--plan",
            "plane:xz:50,y=250",
            "plane:xy:50,z=100",
            "plane:yz:50,x=400",
        ],
        &csv,
    );
    let model = dir.join("planes.model.json");
    fit_cubic19(&csv, &model);
    let rep = dir.join("rep");
    compare_report(&csv, &model, &rep);
    for t in ["ex", "ey", "ez"] {
        for normal in ["x", "y", "z"] {
            let maps = report_files(&rep, &format!("map_{t}_{normal}"));
            assert_eq!(maps.len(), 1, "{t} normal {normal}: {maps:?}");
        }
    }
    let html = std::fs::read_to_string(rep.join("index.html")).unwrap();
    for at in ["x = 400 mm", "y = 250 mm", "z = 100 mm"] {
        assert!(html.contains(&format!("residual at {at}")), "{at}");
    }
    assert!(!html.contains("shown (at most"), "nothing is left out here");
}

/// A 100 mm grid has 9 planes normal to x and 6 normal to y and z: five
/// of each are mapped (both ends included) and the page says which.
#[test]
fn report_caps_planes_per_orientation_and_says_so() {
    let dir = tmp_dir("compare", "cap");
    let (csv, model, _) = grid_cubic19(&dir, "grid", 7);
    let rep = dir.join("rep");
    compare_report(&csv, &model, &rep);
    let count = |prefix: &str| {
        report_files(&rep, prefix)
            .iter()
            .filter(|n| n.ends_with(".svg"))
            .count()
    };
    for normal in ["x", "y", "z"] {
        assert_eq!(count(&format!("map_ex_{normal}")), 5, "{normal}");
    }
    // The last plane of each orientation is among them.
    assert!(rep.join("map_ex_x8.svg").is_file());
    assert!(rep.join("map_ex_z5.svg").is_file());
    let html = std::fs::read_to_string(rep.join("index.html")).unwrap();
    assert!(
        html.contains("Planes x = const: 9 measured, 5 shown (at most 5 per orientation, evenly spaced, first and last included): 0, 200, 400, 600, 800 mm."),
        "the cap is said"
    );
    assert!(html.contains("Planes z = const: 6 measured, 5 shown"));
}

/// True when `text` holds no http(s) URL other than XML namespace names.
fn no_network(text: &str) -> bool {
    let t = text
        .replace("xmlns=\"http://www.w3.org/2000/svg\"", "")
        .replace("xmlns:xlink=\"http://www.w3.org/1999/xlink\"", "");
    !t.contains("http://") && !t.contains("https://")
}

#[test]
fn other_data_warns_data_hash_mismatch() {
    let dir = tmp_dir("compare", "hash");
    let (csv, model, _) = grid_cubic19(&dir, "a", 7);
    let other = simulate_grid(&dir, "b.csv", 8);
    let out = run(&["compare", s(&other), "--model", s(&model), "--json"]);
    let v = json(&out);
    let w = v["warnings"].as_array().unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(w[0]["code"], "data_hash_mismatch");
    let detail = w[0]["detail"].as_str().unwrap();
    assert!(
        detail.contains(s(&other)) && detail.contains(s(&csv)),
        "{detail}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("warning (data_hash_mismatch)"), "{err}");
    // A validation on fresh noise of the same machine: still at the noise
    // level, and no better than the fit's own residual would suggest.
    let r = num(&v["rms_um"]["ex"], "rms");
    assert!(r > 0.1 && r < 0.35, "{r}");
}

/// A row with no error value is left out, and compare says so: the count
/// in the JSON (`skipped_count`) and the line with its reason on stderr —
/// docs/cli.md § Measurement CSV, nothing is silently skipped.
#[test]
fn rows_left_out_are_counted_and_said() {
    let dir = tmp_dir("compare", "skipped");
    let (csv, model, _) = grid_cubic19(&dir, "grid", 7);
    let clean = run(&["compare", s(&csv), "--model", s(&model), "--json"]);
    assert_eq!(json(&clean)["skipped_count"], 0);
    assert!(!String::from_utf8_lossy(&clean.stderr).contains("left out"));

    let holed = dir.join("holed.csv");
    let line = with_blank_error_row(&csv, &holed);
    for json_flag in [true, false] {
        let mut args = vec!["compare", s(&holed), "--model", s(&model)];
        if json_flag {
            args.push("--json");
        }
        let out = run(&args);
        assert!(out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        common::assert_has(
            &err,
            &[&format!(
                "note: 1 row of {} was left out (line {line}: no error value on this row)",
                s(&holed)
            )],
        );
        if json_flag {
            let v = json(&out);
            assert_eq!(v["skipped_count"], 1);
            assert_eq!(v["rows"], 324, "the row is not in the data set");
        }
    }
}

/// A numeric auxiliary column (`humidity_pct`) is a channel like the
/// contract's own: kept, and the residual's dependence on it reported. The
/// simulated grid gets a humidity reading per row and an ex error of
/// 0.8 µm per % humidity — which no polynomial in x, y, z holds — and a
/// text column (`operator`), which is kept but is no channel.
#[test]
fn numeric_auxiliary_columns_are_channels() {
    let dir = tmp_dir("compare", "aux");
    let csv = simulate_grid(&dir, "grid.csv", 7);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut out = String::new();
    let mut ex_col = None;
    let mut row = 0usize;
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if ex_col.is_none() {
            ex_col = line.split(',').position(|h| h == "ex_um");
            out.push_str(&format!("{line},humidity_pct,operator"));
        } else {
            // A deterministic humidity that jumps around (no smooth
            // function of position): 40…60 %.
            let h = 40.0 + ((row * 7919) % 21) as f64;
            let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
            let i = ex_col.unwrap();
            let ex: f64 = cells[i].parse().unwrap();
            cells[i] = format!("{:.4}", ex + 0.8 * (h - 50.0));
            out.push_str(&format!("{},{h},Anna", cells.join(",")));
            row += 1;
        }
        out.push('\n');
    }
    let humid = common::file_in(&dir, "humid.csv", out);
    let model = dir.join("humid.model.json");
    fit_cubic19(&humid, &model);
    let v = compare(&humid, &model);
    let chans = v["channels"].as_array().unwrap();
    let h = chans
        .iter()
        .find(|c| c["channel"] == "humidity_pct" && c["target"] == "ex")
        .expect("humidity_pct is a channel of ex");
    let r = num(&h["corr"], "corr");
    let slope = num(&h["slope_um_per_unit"], "slope");
    assert!(r > 0.95, "ex residual follows humidity: r = {r}");
    assert!((slope - 0.8).abs() < 0.05, "0.8 µm per %: {slope}");
    assert_eq!(h["bins"].as_array().unwrap().len(), 10);
    assert!(
        !chans.iter().any(|c| c["channel"] == "operator"),
        "a text column is no channel"
    );
    // The text output names it among the channels the residual follows.
    let out = run(&["compare", s(&humid), "--model", s(&model)]);
    let text = String::from_utf8_lossy(&out.stdout);
    let line = common::line_where(&text, |l| l.contains("ex vs humidity_pct:"));
    common::assert_has(line, &["(r = +0.99)", "µm per unit"]);
}

#[test]
fn a_target_the_model_lacks_is_warned() {
    let dir = tmp_dir("compare", "target");
    let csv = simulate_grid(&dir, "grid.csv", 7);
    // The same data with ex only → a model of ex only.
    let mut data = import::load(&csv).unwrap();
    data.err_um[1] = None;
    data.err_um[2] = None;
    let ex_only = dir.join("ex.csv");
    import::write_csv(&data, std::fs::File::create(&ex_only).unwrap()).unwrap();
    let model = dir.join("ex.model.json");
    fit_cubic19(&ex_only, &model);
    let v = compare(&csv, &model);
    let keys: Vec<&String> = v["rms_um"].as_object().unwrap().keys().collect();
    assert_eq!(keys, ["ex"]);
    let codes = warning_codes(&v);
    assert_eq!(
        codes.iter().filter(|c| **c == "no_prediction").count(),
        2,
        "{codes:?}"
    );
    assert!(codes.contains(&"data_hash_mismatch"), "{codes:?}");
}

#[test]
fn bad_input_exits_1_and_usage_exits_2() {
    let dir = tmp_dir("compare", "bad");
    let (csv, model, fit_json) = grid_cubic19(&dir, "grid", 7);

    // The model file is missing.
    let missing = dir.join("missing.model.json");
    expect_exit(
        &["compare", s(&csv), "--model", s(&missing), "--json"],
        1,
        &["cannot read model file", s(&missing)],
    );
    // JSON, but not a model: `fit --json` output saved by mistake.
    let not_model = common::file_in(&dir, "fit-output.json", fit_json.to_string());
    expect_exit(
        &["compare", s(&csv), "--model", s(&not_model), "--json"],
        1,
        &[
            s(&not_model),
            "not a trueaxis model file: it looks like the output of `trueaxis compare` or `fit --json`",
        ],
    );
    // The fit history beside the model, and diagnose's output: named as
    // what they are, not as what serde missed in them.
    let history = common::file_in(
        &dir,
        "m.history.json",
        r#"{"format": "trueaxis-history/1", "steps": []}"#,
    );
    expect_exit(
        &["compare", s(&csv), "--model", s(&history)],
        1,
        &["it is a fit history (MODEL.history.json)"],
    );
    let diagnosis = common::file_in(
        &dir,
        "diagnosis.json",
        r#"{"candidates": [], "rms_um": {}}"#,
    );
    expect_exit(
        &["compare", s(&csv), "--model", s(&diagnosis)],
        1,
        &["it looks like the output of `trueaxis diagnose --json`"],
    );
    // A truncated model file.
    let text = std::fs::read_to_string(&model).unwrap();
    let cut = common::file_in(&dir, "cut.model.json", &text[..text.len() / 2]);
    expect_exit(
        &["compare", s(&csv), "--model", s(&cut)],
        1,
        &[s(&cut), "not a trueaxis model file"],
    );
    // A model of another format version.
    let other = dir.join("v2.model.json");
    std::fs::write(
        &other,
        text.replace("\"trueaxis-model/1\"", "\"trueaxis-model/2\""),
    )
    .unwrap();
    expect_exit(
        &["compare", s(&csv), "--model", s(&other)],
        1,
        &["model format `trueaxis-model/2`"],
    );

    // The data: a cell that is not a number, named by file:line:column.
    let data_text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = data_text.lines().collect();
    let header = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    let col = lines[header].split(',').position(|c| c == "ey_um").unwrap();
    let bad_line = header + 4; // 0-based index of the third data row
    let mut cells: Vec<&str> = lines[bad_line].split(',').collect();
    cells[col] = "1.2.3";
    let bad_row = cells.join(",");
    let mut bad_lines = lines.clone();
    bad_lines[bad_line] = &bad_row;
    let bad = common::file_in(&dir, "bad.csv", bad_lines.join("\n") + "\n");
    let at = format!("{}:{}:{}:", s(&bad), bad_line + 1, col + 1);
    expect_exit(
        &["compare", s(&bad), "--model", s(&model), "--json"],
        1,
        &[&at, "column `ey_um`: expected a number, found `1.2.3`"],
    );
    // NaN in an error cell: refused the same way.
    cells[col] = "NaN";
    let nan_row = cells.join(",");
    bad_lines[bad_line] = &nan_row;
    let nan = common::file_in(&dir, "nan.csv", bad_lines.join("\n") + "\n");
    let at = format!("{}:{}:{}:", s(&nan), bad_line + 1, col + 1);
    expect_exit(
        &["compare", s(&nan), "--model", s(&model)],
        1,
        &[&at, "ey_um"],
    );
    // The data file is missing.
    let gone = dir.join("gone.csv");
    expect_exit(&["compare", s(&gone), "--model", s(&model)], 1, &[s(&gone)]);

    // Usage errors: clap's exit code 2.
    expect_exit(&["compare", s(&csv)], 2, &["--model"]);
    expect_exit(&["compare", "--model", s(&model)], 2, &["DATA"]);
    expect_exit(
        &["compare", s(&csv), "--model", s(&model), "--bogus"],
        2,
        &["--bogus"],
    );
}

/// A hand-made file (tests/golden/line_x.csv: an x line with a ±2.4 µm
/// reversal, both directions): a cubic without the reversal leaves exactly
/// the reversal, and compare shows it as a step between dir_x = −1 and +1;
/// with the reversal added the residual is the file's 0.1 nm rounding.
#[test]
fn hand_made_line_shows_the_missing_reversal() {
    let dir = tmp_dir("compare", "line");
    let csv = golden_file("line_x.csv");
    let plain = dir.join("plain.model.json");
    fit_cubic19(&csv, &plain);
    let v = compare(&csv, &plain);
    assert_eq!(v["rows"], 42);
    let r = num(&v["rms_um"]["ex"], "rms");
    assert!(
        (r - 2.4).abs() < 1e-3,
        "the reversal is all that is left: {r}"
    );
    let prof = v["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["channel"] == "dir_x")
        .expect("a dir_x profile");
    assert!(num(&prof["corr"], "corr") > 0.999, "{prof}");
    let bins = prof["bins"].as_array().unwrap();
    assert_eq!(bins.len(), 2);
    assert!(
        (num(&bins[0]["mean_um"], "mean") + 2.4).abs() < 1e-3,
        "{prof}"
    );
    assert!(
        (num(&bins[1]["mean_um"], "mean") - 2.4).abs() < 1e-3,
        "{prof}"
    );
    assert_eq!(
        (bins[0]["points"].as_u64(), bins[1]["points"].as_u64()),
        (Some(21), Some(21))
    );
    // The text output names the correlated channel.
    let out = run(&["compare", s(&csv), "--model", s(&plain)]);
    let text = String::from_utf8_lossy(&out.stdout);
    // Ranked by what it explains beyond position, the step from −1 to +1
    // in words (2 × 2.4 µm).
    assert!(
        text.contains("ex vs dir_x: 100 % (r = +1.00), slope +4.8000 µm per direction change"),
        "{text}"
    );

    let full = dir.join("full.model.json");
    fit(&csv, CUBIC19_REVERSAL_X, &full);
    let v = compare(&csv, &full);
    let after = num(&v["rms_um"]["ex"], "rms");
    assert!(after < 1e-4, "{after}");
    let before = num(&v["targets"]["ex"]["before"]["rms_um"], "before");
    close(before, rms(&csv_column(&csv, "ex_um")), "before rms");
    assert!(num(&v["targets"]["ex"]["improvement"], "improvement") > 1e4);
}

/// Data without a column the model's effect terms need: exit 1, the data
/// file named with what is missing.
#[test]
fn data_lacking_an_effect_input_is_named() {
    let dir = tmp_dir("compare", "lacking");
    let csv = simulate_grid(&dir, "grid.csv", 4);
    let model = dir.join("m.json");
    fit(
        &csv,
        &[
            "--model",
            "cubic19",
            "--add",
            "periodic:target=ey,axis=y,period_mm=7.3",
        ],
        &model,
    );
    let xonly = common::file_in(
        &dir,
        "xonly.csv",
        "x_mm,ex_um\n0,1\n100,2\n200,1.5\n300,2.5\n",
    );
    expect_exit(
        &["compare", s(&xonly), "--model", s(&model)],
        1,
        &[&format!(
            "{}: the model cannot be evaluated on it: periodic term on y: the data has no y_mm column",
            s(&xonly)
        )],
    );
}

/// Bytes of every file in `dir`.
fn dir_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum()
}

/// Issue 15: a report's size is bounded whatever the number of rows. 54 000
/// readings (a 50 mm grid and dense 0.05 mm lines along x and y, both
/// directions, fixed seed) give a page under 3 MB and a directory under
/// 5 MB; the line plots carry the note that says how they were reduced, and
/// the passes of one line are one plot. Before: 7.1 MB at 18 000 rows and
/// 16 MB at 194 000 (a scatter of every row of a line, a plot per pass).
#[test]
fn a_large_capture_gives_a_report_of_bounded_size() {
    let dir = tmp_dir("compare", "large");
    let csv = dir.join("big.csv");
    run(&[
        "simulate",
        "--plan",
        "grid:50",
        "--plan",
        "line:x:0.05,bidir",
        "--plan",
        "line:y:0.05,bidir",
        "--effect",
        "periodic:axis=x,period_mm=5,amp_um=3",
        "--seed",
        "15",
        "-o",
        s(&csv),
    ]);
    let model = dir.join("m.json");
    fit_cubic19(&csv, &model);
    let rep = dir.join("rep");
    compare_report(&csv, &model, &rep);
    let index = std::fs::read_to_string(rep.join("index.html")).unwrap();
    assert!(
        index.len() < 3_000_000,
        "index.html is {} bytes",
        index.len()
    );
    let total = dir_bytes(&rep);
    assert!(total < 5_000_000, "the report is {total} bytes");
    // One plot per line (x and y), not one per pass, each saying it is reduced.
    assert_eq!(
        report_files(&rep, "line")
            .iter()
            .filter(|n| n.ends_with("_measured.svg"))
            .count(),
        2
    );
    assert!(index.contains("2 passes overlaid"), "passes joined");
    assert!(
        index.contains("points shown as") && index.contains("lowest and highest per x bin kept"),
        "the reduction is stated on the plot"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
