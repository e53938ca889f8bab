//! The files users of other stacks already have: a RepRapFirmware
//! `heightmap.csv`, a Klipper `printer.cfg` with two saved bed meshes, an
//! ecmc `*_ISO230.dat` run — small files written by the project in each
//! format (tests/data; generators' formulas in the assertions below).

mod common;

use common::{data_file as data, json, run, s, tmp_dir};

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The `ez_um` of the node at (x, y) in an imported map's CSV.
fn node(csv: &str, x: f64, y: f64) -> f64 {
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(csv.as_bytes());
    for rec in r.records() {
        let rec = rec.unwrap();
        let (rx, ry): (f64, f64) = (rec[0].parse().unwrap(), rec[1].parse().unwrap());
        if (rx - x).abs() < 1e-6 && (ry - y).abs() < 1e-6 {
            return rec[2].parse().unwrap();
        }
    }
    panic!("no node at {x}, {y}");
}

#[test]
fn a_reprapfirmware_map_becomes_a_z_error_map_with_the_compensation_sign() {
    let dir = tmp_dir("maps", "rrf");
    let out_csv = dir.join("bed.csv");
    let map = data("bed_heightmap.csv");
    let doc = json(&run(&["import", s(&map), "-o", s(&out_csv), "--json"]));
    assert_eq!(doc["rows"], 80, "{doc}");
    assert_eq!(doc["columns"], serde_json::json!(["x_mm", "y_mm", "ez_um"]));
    // The bare `0` of the last node is "not probed", listed with its line.
    assert_eq!(doc["skipped_count"], 1);
    assert_eq!(doc["skipped"][0]["line"], 12);
    let csv = std::fs::read_to_string(&out_csv).unwrap();
    // Line 5 (second row, y = 10 + 185/8 = 33.125 mm), first node x = 25:
    // height −0.061 mm → the tool stands 61 µm high → ez = +61 µm.
    assert!((node(&csv, 25.0, 33.125) - 61.0).abs() < 1e-9);
    // Line 4, node 8 (x = 200): height 0.051 mm → ez = −51 µm.
    assert!((node(&csv, 200.0, 10.0) + 51.0).abs() < 1e-9);
    // The probed `0.000` (line 4, node 5) is a zero, not a gap; the last row reaches
    // ymax = 195 mm although the file writes the spacing as 23.12 (line 12,
    // node 8: −0.037 mm).
    assert_eq!(node(&csv, 125.0, 10.0), 0.0);
    assert!((node(&csv, 25.0, 10.0) - 70.0).abs() < 1e-9);
    assert!((node(&csv, 200.0, 195.0) - 37.0).abs() < 1e-9);
    // fit reads it directly and says which row it left out.
    let model = dir.join("m.json");
    let fit = common::cubic19("fit", &map, &model, &[]);
    assert!(stderr(&fit).contains("line 12"), "{}", stderr(&fit));
    let f = json(&fit);
    // The map is mostly a tilted dish: a cubic follows it to a few µm of a
    // −170…+67 µm surface (the rest is a cos(πx)·y warp a cubic cannot
    // follow). Swapped axes or rows read in the wrong order would not.
    assert_eq!(f["rows"]["ez"], 80, "{f}");
    let rms = f["rms_um"]["ez"].as_f64().unwrap_or_else(|| panic!("{f}"));
    assert!(rms < 5.0, "{f}");
}

#[test]
fn a_klipper_config_with_two_meshes_needs_a_profile() {
    let cfg = data("klipper_printer.cfg");
    let profiles = "2 bed mesh profiles (default, hot)";
    common::expect_exit(&["import", s(&cfg)], 1, &[profiles, "--profile"]);
    let dir = tmp_dir("maps", "klipper");
    let out_csv = dir.join("hot.csv");
    let doc = json(&run(&[
        "import",
        s(&cfg),
        "--profile",
        "hot",
        "-o",
        s(&out_csv),
        "--json",
    ]));
    assert_eq!(doc["rows"], 25);
    let csv = std::fs::read_to_string(&out_csv).unwrap();
    // Profile `hot` at the centre node (x = y = 117.5): 0.030 mm → −30 µm;
    // at (34, 34): 0.03 − 0.05 + 0.02 − 0.08 = −0.08 mm → +80 µm.
    assert!((node(&csv, 117.5, 117.5) + 30.0).abs() < 1e-9);
    assert!((node(&csv, 34.0, 34.0) - 80.0).abs() < 1e-9);
    let out = run(&["import", s(&cfg), "--profile", "cold"]);
    common::assert_has(&stderr(&out), &["no bed mesh profile `cold`"]);
    let out = run(&["import", s(&data("good.csv")), "--profile", "hot"]);
    assert_eq!(out.status.code(), Some(1));
    common::assert_has(&stderr(&out), &["expected a .cfg file"]);
}

#[test]
fn an_ecmc_iso230_run_gives_the_iso230_figures_it_was_made_with() {
    let dat = data("axis1_ISO230.dat");
    common::expect_exit(&["iso230", s(&dat)], 1, &["pass --axis x|y|z"]);
    // Made with a 3 µm backlash (backward reads 3 µm short) and noise that
    // averages to zero over the 5 cycles at every target: B = 3 µm, and the
    // forward mean at 15 mm is 12e-6·15 mm + 1 µm·sin(2π·15/50) = 1.131 µm.
    let doc = json(&run(&["iso230", s(&dat), "--axis", "x", "--json"]));
    assert!((doc["B_um"].as_f64().unwrap() - 3.0).abs() < 0.01, "{doc}");
    let first = &doc["per_target"][0];
    assert_eq!(first["pos_mm"], 15.0);
    assert_eq!(
        (first["n_up"].as_u64(), first["n_down"].as_u64()),
        (Some(5), Some(5))
    );
    assert!(
        (first["mean_up_um"].as_f64().unwrap() - 1.131).abs() < 0.011,
        "{first}"
    );
}

#[test]
fn a_mesh_exported_from_a_fit_of_a_mesh_gives_the_mesh_back() {
    // Profile `hot` is a quadratic surface, which cubic19 follows exactly:
    // import → fit → export as a Klipper profile and as a RepRapFirmware
    // map → import again must give the measured heights back (to the
    // 1e-6 mm and 1e-3 mm the two formats write), at the same nodes.
    let dir = tmp_dir("maps", "roundtrip");
    let cfg = data("klipper_printer.cfg");
    let hot = dir.join("hot.csv");
    json(&run(&[
        "import",
        s(&cfg),
        "--profile",
        "hot",
        "-o",
        s(&hot),
        "--json",
    ]));
    let model = dir.join("m.json");
    json(&common::cubic19("fit", &hot, &model, &[]));
    let measured = std::fs::read_to_string(&hot).unwrap();
    for (format, file, tol_um) in [
        ("klipper-mesh", "back.cfg", 1e-3),
        ("rrf-heightmap", "back_heightmap.csv", 0.5 + 1e-9),
    ] {
        let out = dir.join(file);
        let doc = json(&run(&[
            "export",
            s(&model),
            "--format",
            format,
            "--mesh-points",
            "5",
            "-o",
            s(&out),
            "--json",
        ]));
        assert_eq!(doc["nodes"], serde_json::json!([5, 5]), "{doc}");
        assert!(doc["max_interp_error_um"].as_f64().unwrap() < 40.0, "{doc}");
        let back_csv = dir.join(format!("{file}.csv"));
        json(&run(&["import", s(&out), "-o", s(&back_csv), "--json"]));
        let back = std::fs::read_to_string(&back_csv).unwrap();
        for (x, y) in [
            (34.0, 34.0),
            (75.75, 117.5),
            (201.0, 201.0),
            (117.5, 159.25),
        ] {
            let (a, b) = (node(&measured, x, y), node(&back, x, y));
            assert!(
                (a - b).abs() <= tol_um,
                "{format} at ({x}, {y}): {a} vs {b}"
            );
        }
    }
    // A flag of another format is a usage error, not ignored.
    let out = run(&[
        "export",
        s(&model),
        "--format",
        "klipper-mesh",
        "--points",
        "5",
        "-o",
        s(&dir.join("x.cfg")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    // A one-axis model is not a bed mesh.
    let line = dir.join("line.csv");
    common::simulate(&["--plan", "line:x:10"], &line);
    let lm = dir.join("line.json");
    json(&common::cubic19("fit", &line, &lm, &[]));
    let l_csv = dir.join("l.csv");
    let rrf = common::export_args(&lm, &["--format", "rrf-heightmap"], &l_csv);
    common::expect_exit(&rrf, 1, &["a bed mesh"]);
}

/// The real delta-printer heightmap imported into a fresh `maps-NAME`
/// directory and fitted with cubic19: (dir, bed.csv, bed.json, fit's JSON).
fn real_bed_cubic(
    name: &str,
) -> (
    std::path::PathBuf,
    std::path::PathBuf,
    std::path::PathBuf,
    serde_json::Value,
) {
    let dir = tmp_dir("maps", name);
    let csv = dir.join("bed.csv");
    json(&run(&[
        "import",
        s(&data("bed_heightmap.csv")),
        "-o",
        s(&csv),
        "--json",
    ]));
    let model = dir.join("bed.json");
    let fit = json(&common::cubic19("fit", &csv, &model, &[]));
    (dir, csv, model, fit)
}

#[test]
fn a_bed_is_spoken_of_as_a_bed() {
    // Issue 28: a printer's heightmap was told to measure ball-screw leads
    // forward and backward, coloured with high = blue and captioned with a
    // plane z = 0 it does not have.
    let (dir, csv, model, _) = real_bed_cubic("bed-words");
    let report = dir.join("diag");
    let d = common::diagnose_report(&csv, s(&model), &report);
    let text = d["warnings"].to_string();
    assert!(text.contains("bed_model"), "{text}");
    for machine_tool in ["ball-screw", "one_direction", "no_temperature", "ISO 230-2"] {
        assert!(!text.contains(machine_tool), "{machine_tool}: {text}");
    }
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(
        html.contains("--model grid:") && html.contains("--format klipper-mesh"),
        "the card proposes a grid and a mesh"
    );
    // The compare page draws the bed's height, high = warm, over x–y.
    let cmp = dir.join("cmp");
    json(&run(&[
        "compare",
        s(&csv),
        "--model",
        s(&model),
        "--report",
        s(&cmp),
        "--json",
    ]));
    let html = std::fs::read_to_string(cmp.join("index.html")).unwrap();
    assert!(html.contains("bed height"), "no bed height on the page");
    assert!(html.contains("as Klipper and Mainsail colour a mesh"));
    assert!(!html.contains("plane z = 0"), "an invented plane z = 0");
}

#[test]
fn an_exported_mesh_is_checked_at_the_probed_points() {
    // Issue 28: a Klipper mesh from a cubic fit of a real delta bed departed
    // from the probed points by tens of µm while export spoke only of the
    // interpolation against the model. Export now compares the mesh, as the
    // firmware interpolates it, with every probed reading.
    let (dir, csv, model, fit) = real_bed_cubic("probed");
    let worst_fit = fit["max_abs_um"]["ez"].as_f64().unwrap();
    let out = dir.join("m.cfg");
    let args = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "export",
            s(&model),
            "--format",
            "klipper-mesh",
            "-o",
            s(&out),
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        v.extend(extra.iter().map(|a| a.to_string()));
        v
    };
    let run_v = |v: &[String]| run(&v.iter().map(String::as_str).collect::<Vec<_>>());
    let doc = json(&run_v(&args(&["--max-departure-um", "1000", "--json"])));
    let c = &doc["probed_points"];
    assert_eq!(c["fitted_data"], true, "{doc}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows = text.lines().filter(|l| !l.starts_with('#')).count() - 1;
    assert_eq!(c["points"].as_u64(), Some(rows as u64), "{doc}");
    let dep = c["max_departure_um"].as_f64().unwrap();
    // The mesh's worst departure is at least the model's own worst miss
    // less what the mesh's nodes move it, and above the interpolation
    // figure alone when the model misses readings.
    assert!(
        dep > 0.5 * worst_fit,
        "{dep} vs the fit's {worst_fit}: {doc}"
    );
    assert!(dep > doc["max_interp_error_um"].as_f64().unwrap(), "{doc}");
    // Below that departure the mesh is refused, naming the reading, and not
    // written.
    std::fs::remove_file(&out).unwrap();
    let limit = format!("{:.3}", 0.5 * dep);
    let refused = run_v(&args(&["--max-departure-um", &limit]));
    assert_eq!(refused.status.code(), Some(1));
    let err = stderr(&refused);
    common::assert_has(
        &err,
        &["departs from the reading", "line ", "--max-departure-um"],
    );
    assert!(!out.exists());
    // The data moved away: exported, with the check said to be missing.
    std::fs::rename(&csv, dir.join("moved.csv")).unwrap();
    let doc = json(&run_v(&args(&["--max-departure-um", "1000", "--json"])));
    assert!(doc.get("probed_points").is_none(), "{doc}");
    assert!(
        doc["warnings"]
            .to_string()
            .contains("probed_points_unchecked"),
        "{doc}"
    );
    // Given with --data, it is checked again.
    let moved = dir.join("moved.csv");
    let doc = json(&run_v(&args(&[
        "--data",
        s(&moved),
        "--max-departure-um",
        "1000",
        "--json",
    ])));
    assert_eq!(
        doc["probed_points"]["max_departure_um"].as_f64(),
        Some(dep),
        "{doc}"
    );
    // A flag of the meshes given to a controller file is a usage error.
    let usage = run(&[
        "export",
        s(&model),
        "--format",
        "table",
        "--data",
        s(&moved),
        "-o",
        s(&dir.join("t.bin")),
    ]);
    assert_eq!(usage.status.code(), Some(2));
}
