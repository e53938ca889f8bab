//! The measurement CSV's probe columns (docs/cli.md § Measurement CSV,
//! "Probe data"): the simulated on-machine campaign written as ONE file —
//! one `session_id` per scan, the reading in `d_um`, `orientation_deg`,
//! `probe_no`, `c_deg`, `step_deg`, `t_s`, `probe_id` and the normals —
//! gives every on-machine command the same results as the separate small
//! files; a bad value is placed by file, line and column.

mod common;

use std::path::Path;

use common::onmachine::calibrate_on_4mm_ball;
use common::{expect_exit, json, on_machine_campaign, run, s, tmp_dir};
use serde_json::Value;

const HEAD: &str = "session_id,x_mm,y_mm,z_mm,c_deg,step_deg,orientation_deg,probe_no,d_um,t_s,probe_id,normal_x,normal_y,normal_z,contact_deg";

/// The data rows of a small file, split into cells (text kept as is).
fn cells(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// One row of the campaign CSV: the named cells set, the rest empty.
fn row(session: u32, set: &[(&str, &str)]) -> String {
    let cols: Vec<&str> = HEAD.split(',').collect();
    let mut v = vec![String::new(); cols.len()];
    v[0] = session.to_string();
    for (k, x) in set {
        v[cols.iter().position(|c| c == k).unwrap()] = x.to_string();
    }
    v.join(",")
}

/// The campaign in `camp` as one CSV: sessions 1 ball, 2 ball (3-D), 3 part
/// arc, 4 reversal (both orientations), 5 three probes, 6 multi-step,
/// 7 grinder, 8 the timed roundness turn.
fn one_csv(camp: &Path) -> String {
    let mut out = vec![
        "# one on-machine campaign: a session per scan".to_string(),
        HEAD.to_string(),
    ];
    for r in cells(&camp.join("ball.csv")) {
        out.push(row(
            1,
            &[("x_mm", &r[0]), ("z_mm", &r[1]), ("probe_id", "T1")],
        ));
    }
    for r in cells(&camp.join("ball3d.csv")) {
        out.push(row(
            2,
            &[
                ("x_mm", &r[0]),
                ("y_mm", &r[1]),
                ("z_mm", &r[2]),
                ("probe_id", "T1"),
            ],
        ));
    }
    for r in cells(&camp.join("part.csv")) {
        // The nominal normal and contact angle of the arc (kept, checked).
        let (x, z): (f64, f64) = (r[0].parse().unwrap(), r[1].parse().unwrap());
        let l = x.hypot(z);
        let (nx, nz) = (format!("{}", x / l), format!("{}", z / l));
        let a = format!("{}", z.atan2(x).to_degrees());
        out.push(row(
            3,
            &[
                ("x_mm", &r[0]),
                ("z_mm", &r[1]),
                ("probe_id", "T1"),
                ("normal_x", &nx),
                ("normal_y", "0"),
                ("normal_z", &nz),
                ("contact_deg", &a),
            ],
        ));
    }
    for (file, o) in [("run0.csv", "0"), ("run180.csv", "180")] {
        for r in cells(&camp.join(file)) {
            out.push(row(
                4,
                &[("x_mm", &r[0]), ("d_um", &r[1]), ("orientation_deg", o)],
            ));
        }
    }
    for r in cells(&camp.join("three-probe.csv")) {
        for k in 1..=3 {
            out.push(row(
                5,
                &[
                    ("c_deg", &r[0]),
                    ("probe_no", &k.to_string()),
                    ("d_um", &r[k]),
                ],
            ));
        }
    }
    for r in cells(&camp.join("multi-step.csv")) {
        out.push(row(
            6,
            &[("c_deg", &r[0]), ("step_deg", &r[1]), ("d_um", &r[2])],
        ));
    }
    for r in cells(&camp.join("grinder.csv")) {
        out.push(row(
            7,
            &[("c_deg", &r[0]), ("z_mm", &r[1]), ("d_um", &r[2])],
        ));
    }
    for r in cells(&camp.join("roundness.csv")) {
        out.push(row(8, &[("c_deg", &r[0]), ("d_um", &r[1]), ("t_s", &r[2])]));
    }
    out.join("\n") + "\n"
}

/// Runs `args` with `--json` and drops the keys that name files.
fn doc(args: &[&str]) -> Value {
    let mut a = args.to_vec();
    a.push("--json");
    without_paths(json(&run(&a)))
}

/// A document less the paths it names (which differ between the runs
/// compared).
fn without_paths(mut v: Value) -> Value {
    for k in ["scan", "output", "report", "history"] {
        if let Some(o) = v.as_object_mut() {
            o.remove(k);
        }
    }
    if let Some(f) = v.get_mut("form").and_then(|f| f.as_object_mut()) {
        f.remove("scan");
    }
    v
}

#[test]
fn the_campaign_as_one_measurement_csv_gives_the_same_results_as_its_files() {
    let dir = tmp_dir("probe_csv", "same");
    let (camp, _) = on_machine_campaign(&dir);
    let one = common::file_in(&dir, "campaign.csv", one_csv(&camp));
    let f = |n: &str| camp.join(n);
    let o = |n: &str| dir.join(n);
    let o1 = s(&one);

    // Probe calibration, 2-D and 3-D; the part corrected with the probe.
    let calibrate = |scan: &Path, xyz: bool, out: &str, more: &[&str]| {
        without_paths(calibrate_on_4mm_ball(scan, xyz, &o(out), more))
    };
    let a = calibrate(&f("ball.csv"), false, "p-a.json", &[]);
    let b = calibrate(&one, false, "p-b.json", &["--session", "1"]);
    assert_eq!(a, b);
    assert!(a["probe"]["probe_radius_mm"].as_f64().unwrap() > 0.49);
    let a = calibrate(&f("ball3d.csv"), true, "p3-a.json", &[]);
    let b = calibrate(&one, true, "p3-b.json", &["--session", "2"]);
    assert_eq!(a, b);
    let a = doc(&[
        "probe",
        "correct",
        s(&f("part.csv")),
        "--probe",
        s(&o("p-a.json")),
        "-o",
        s(&o("s-a.csv")),
    ]);
    let b = doc(&[
        "probe",
        "correct",
        o1,
        "--session",
        "3",
        "--probe",
        s(&o("p-a.json")),
        "-o",
        s(&o("s-b.csv")),
    ]);
    // The session gives the nominal normals: the contacts are placed along
    // them, not along the centre path's chords — the same part form to a
    // few nm on this dense arc (the chords' noise is all that differs).
    assert_eq!(a["normals"], "centre_path");
    assert_eq!(b["normals"], "nominal");
    let pv = |v: &Value| v["form_pv_nm"].as_f64().unwrap();
    assert!((pv(&a) - pv(&b)).abs() < 10.0, "{a} {b}");
    let strip = |mut v: Value| {
        for k in ["normals", "form_pv_nm", "form_pv_radius_only_nm"] {
            v.as_object_mut().unwrap().remove(k);
        }
        v
    };
    assert_eq!(strip(a.clone()), strip(b));
    assert!(pv(&a) > 100.0, "{a}");

    // Separation: the reversal pair is one session of both orientations.
    let a = doc(&[
        "separate",
        "reversal",
        s(&f("run0.csv")),
        s(&f("run180.csv")),
        "-o",
        s(&o("r-a.csv")),
    ]);
    let b = doc(&[
        "separate",
        "reversal",
        o1,
        "--session",
        "4",
        "-o",
        s(&o("r-b.csv")),
    ]);
    assert_eq!(a, b);
    assert!(a["slide_pv_um"].as_f64().unwrap() > 1.0, "{a}");
    let a = doc(&[
        "separate",
        "three-probe",
        s(&f("three-probe.csv")),
        "--angles-deg",
        "0,99.84,202.5",
        "-o",
        s(&o("t-a.csv")),
    ]);
    let b = doc(&[
        "separate",
        "three-probe",
        o1,
        "--session",
        "5",
        "--angles-deg",
        "0,99.84,202.5",
        "-o",
        s(&o("t-b.csv")),
    ]);
    assert_eq!(a, b);
    let a = doc(&[
        "separate",
        "multi-step",
        s(&f("multi-step.csv")),
        "-o",
        s(&o("m-a.csv")),
    ]);
    let b = doc(&[
        "separate",
        "multi-step",
        o1,
        "--session",
        "6",
        "-o",
        s(&o("m-b.csv")),
    ]);
    assert_eq!(a, b);

    // The ground part and its correction pass.
    let a = doc(&[
        "workpiece",
        s(&f("grinder.csv")),
        "--pass-csv",
        s(&o("w-a.csv")),
    ]);
    let b = doc(&[
        "workpiece",
        o1,
        "--session",
        "7",
        "--pass-csv",
        s(&o("w-b.csv")),
    ]);
    assert_eq!(a, b);
    assert_eq!(
        std::fs::read_to_string(o("w-a.csv")).unwrap(),
        std::fs::read_to_string(o("w-b.csv")).unwrap()
    );

    // The diagnosis: the timed turn (its drift from t_s), the reversal
    // session (its own pair), the arc.
    let a = doc(&["diagnose-part", s(&f("roundness.csv"))]);
    let b = doc(&["diagnose-part", o1, "--session", "8"]);
    assert_eq!(a, b);
    assert_eq!(a["findings"][5]["status"], "estimated", "{a}");
    let a = doc(&[
        "diagnose-part",
        s(&f("run0.csv")),
        "--reversal",
        s(&f("run180.csv")),
    ]);
    let b = doc(&["diagnose-part", o1, "--session", "4"]);
    assert_eq!(a, b);
    assert_eq!(a["findings"][2]["status"], "estimated", "{a}");
    let a = doc(&[
        "diagnose-part",
        s(&f("part.csv")),
        "--probe",
        s(&o("p-a.json")),
    ]);
    let b = doc(&[
        "diagnose-part",
        o1,
        "--session",
        "3",
        "--probe",
        s(&o("p-a.json")),
    ]);
    assert_eq!(a, b);
}

#[test]
fn a_bad_probe_value_is_placed_and_a_session_must_be_named() {
    let dir = tmp_dir("probe_csv", "bad");
    let (camp, _) = on_machine_campaign(&dir);
    let text = one_csv(&camp);
    let one = common::file_in(&dir, "campaign.csv", &text);
    // Several sessions and none named: which one is asked.
    expect_exit(
        &[
            "separate",
            "multi-step",
            s(&one),
            "-o",
            s(&dir.join("m.csv")),
        ],
        1,
        &["sessions (1, 2, 3, 4, 5, 6, 7, 8): say which with --session"],
    );
    // The first reversal row turned 90°: not a reversal orientation.
    let lines: Vec<&str> = text.lines().collect();
    let k = lines.iter().position(|l| l.starts_with("4,")).unwrap();
    let mut bad: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    bad[k] = bad[k].replace(",0,,", ",90,,");
    let badf = common::file_in(&dir, "bad.csv", bad.join("\n") + "\n");
    expect_exit(
        &[
            "separate",
            "reversal",
            s(&badf),
            "--session",
            "4",
            "-o",
            s(&dir.join("r.csv")),
        ],
        1,
        &[&format!(
            "bad.csv:{}:7: `orientation_deg`: expected 0 or 180",
            k + 1
        )],
    );
    // The part arc's normals on every row but one: refused, that row named.
    let k = lines.iter().position(|l| l.starts_with("3,")).unwrap();
    let mut part: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let mut c: Vec<String> = part[k].split(',').map(str::to_string).collect();
    for cell in &mut c[11..=13] {
        cell.clear();
    }
    part[k] = c.join(",");
    let partf = common::file_in(&dir, "normals.csv", part.join("\n") + "\n");
    calibrate_on_4mm_ball(&camp.join("ball.csv"), false, &dir.join("p.json"), &[]);
    expect_exit(
        &[
            "probe",
            "correct",
            s(&partf),
            "--session",
            "3",
            "--probe",
            s(&dir.join("p.json")),
            "-o",
            s(&dir.join("c.csv")),
        ],
        1,
        &[&format!(
            "normals.csv:{}: no normal on this row, though other rows of the scan give one",
            k + 1
        )],
    );
    // A small file with --session: refused, not read as something else.
    expect_exit(
        &[
            "separate",
            "multi-step",
            s(&camp.join("multi-step.csv")),
            "--session",
            "6",
            "-o",
            s(&dir.join("m2.csv")),
        ],
        1,
        &["is a scan file, not a measurement CSV"],
    );
    // One small run and no RUN180: refused (it would separate nothing).
    expect_exit(
        &[
            "separate",
            "reversal",
            s(&camp.join("run0.csv")),
            "-o",
            s(&dir.join("r2.csv")),
        ],
        1,
        &["give the 180° run"],
    );
}
