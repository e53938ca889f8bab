//! `trueaxis export` of a rigid21 model to the controllers' own
//! volumetric and skew formats (docs/export-formats.md), on the
//! simulator's machine with all 21 errors measured with a fixed seed: the
//! skew files read back and applied the way the firmware applies them
//! remove the model's squareness to round-off and say what they leave out;
//! a squareness the data cannot know is refused, naming what to measure.

mod common;

use common::{expect_exit, export, export_args, run, tmp_dir};
use std::path::{Path, PathBuf};
use trueaxis_engine::model::rigid21::{ErrorKind, Rigid21Model, ToolPoint};
use trueaxis_engine::model::{FittedModel, ModelFile};
use trueaxis_engine::simulate::instruments::{laser_lines, Instrument};
use trueaxis_engine::simulate::Machine;

/// `mill800-21` measured with `plan` (seed 7), written to `DIR/NAME.csv`
/// and fitted with `fit --model rigid21`: the model's path.
fn fitted(dir: &Path, name: &str, plan: &[Instrument]) -> PathBuf {
    let m = Machine::preset("mill800-21").unwrap();
    let (_, model, out) = common::measured_fit(dir, name, &m, plan, 7, "rigid21", &[]);
    common::assert_success(&out);
    model
}

/// One tracker station at two tool lengths with lateral offsets: every
/// squareness is estimated.
fn tracker() -> Vec<Instrument> {
    vec![Instrument::Tracker {
        tools_mm: vec![0.0, 150.0],
        lateral_mm: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
        points: 80,
    }]
}

fn rigid21(model: &Path) -> Rigid21Model {
    match ModelFile::load(model).unwrap().model {
        FittedModel::Rigid21(r) => r,
        other => panic!("kind {}", other.kind()),
    }
}

/// The model's squareness part at axis positions q, µm.
fn squareness_part(m: &Rigid21Model, q: [f64; 3]) -> [f64; 3] {
    let mut only = m.clone();
    for e in &mut only.errors {
        if e.kind != ErrorKind::Squareness {
            e.coef = e.coef.as_ref().map(|c| vec![0.0; c.len()]);
        }
    }
    only.predict(&ToolPoint {
        pos_mm: q,
        ..ToolPoint::default()
    })
    .e_um
}

/// The largest |q + S·q − p| (µm) over the travel when the controller
/// commands q = `command(p)`, and the same without any correction.
fn misses(m: &Rigid21Model, command: impl Fn([f64; 3]) -> [f64; 3]) -> (f64, f64) {
    let tr = m.travel_mm.map(|t| t.unwrap());
    let (mut with, mut without) = (0.0f64, 0.0f64);
    for i in 0..=4 {
        for j in 0..=4 {
            for k in 0..=4 {
                let p = [i, j, k].map(|n| n as f64 / 4.0);
                let p = [0, 1, 2].map(|a| tr[a][0] + p[a] * (tr[a][1] - tr[a][0]));
                for (out, q) in [(&mut with, command(p)), (&mut without, p)] {
                    let sq = squareness_part(m, q);
                    let d: f64 = (0..3)
                        .map(|c| ((q[c] - p[c]) * 1000.0 + sq[c]).powi(2))
                        .sum();
                    *out = out.max(d.sqrt());
                }
            }
        }
    }
    (with, without)
}

/// Klipper's calc_skew / Marlin's planner skew(): the shear of the factors
/// xy, xz, yz.
fn shear(f: [f64; 3]) -> impl Fn([f64; 3]) -> [f64; 3] {
    move |p| {
        [
            p[0] - p[1] * f[0] - p[2] * (f[1] - f[0] * f[2]),
            p[1] - p[2] * f[2],
            p[2],
        ]
    }
}

#[test]
fn skew_files_of_a_fitted_model_remove_its_squareness_and_say_what_they_leave_out() {
    let dir = tmp_dir("rigid21_export", "skew");
    let model = fitted(&dir, "tracker", &tracker());
    let m = rigid21(&model);
    // Klipper: the profile's factors.
    let cfg = dir.join("skew.cfg");
    let klipper = ["--format", "klipper-skew", "--tool-mm", "150"];
    let doc = export(&model, &klipper, &cfg);
    assert_eq!(doc["format"], "klipper-skew");
    let body = std::fs::read_to_string(&cfg).unwrap();
    let f = ["xy_skew =", "xz_skew =", "yz_skew ="].map(|k| {
        let l = body.lines().find(|l| l.starts_with(k)).unwrap();
        l[k.len()..].trim().parse::<f64>().unwrap()
    });
    let (with, without) = misses(&m, shear(f));
    assert!(with < 1e-4, "Klipper leaves {with} µm");
    assert!(without > 5.0, "the machine's squareness is {without} µm");
    // What the doc says: the squarenesses are the model's, the rest is
    // left out and reported.
    for name in ["C0Y", "B0Z", "A0Z"] {
        let v = m.value(m.error(name).unwrap(), [0.0; 3]).unwrap();
        assert_eq!(doc["squareness_urad"][name].as_f64().unwrap(), v);
    }
    assert_eq!(doc["tool_mm"], 150.0);
    let left = doc["left_out_um"].as_f64().unwrap();
    assert!(left > 5.0, "{doc}");
    // The squareness is the larger part of this machine's error: the file
    // lowers the model's worst error.
    assert!(doc["model_um"].as_f64().unwrap() > left + 5.0, "{doc}");
    for kind in ["positioning", "straightness", "angles", "tilt"] {
        assert!(
            doc["left_out_by_kind_um"][kind].as_f64().unwrap() > 0.1,
            "{kind}: {doc}"
        );
    }
    // Marlin: M852 I J K.
    let gcode = dir.join("skew.gcode");
    export(&model, &["--format", "marlin-skew"], &gcode);
    let body = std::fs::read_to_string(&gcode).unwrap();
    let line = body.lines().find(|l| l.starts_with("M852 ")).unwrap();
    let mut g = [0.0; 3];
    for w in line.split_whitespace().skip(1) {
        let i = "IJK".find(&w[..1]).unwrap();
        g[i] = w[1..].parse().unwrap();
    }
    let (with, _) = misses(&m, shear(g));
    assert!(with < 2e-3, "Marlin leaves {with} µm");
    // matrixkins: joints = C · p.
    let hal = dir.join("skew.hal");
    let text = run(&export_args(&model, &["--format", "matrixkins"], &hal));
    common::assert_success(&text);
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(
        stdout.contains("falls to what the file leaves out"),
        "{stdout}"
    );
    let body = std::fs::read_to_string(&hal).unwrap();
    let mut c = [[f64::NAN; 3]; 3];
    for l in body.lines().filter(|l| l.starts_with("setp matrixkins.C_")) {
        let mut w = l.split_whitespace().skip(1);
        let name = w.next().unwrap();
        let (r, k) = (
            "xyz".find(&name[13..14]).unwrap(),
            "xyz".find(&name[14..15]).unwrap(),
        );
        c[r][k] = w.next().unwrap().parse().unwrap();
    }
    let (with, _) = misses(&m, |p| {
        [0, 1, 2].map(|r| (0..3).map(|k| c[r][k] * p[k]).sum())
    });
    assert!(with < 1e-4, "matrixkins leaves {with} µm");
}

#[test]
fn a_squareness_laser_lines_cannot_know_is_refused_naming_what_to_measure() {
    let dir = tmp_dir("rigid21_export", "refused");
    let m = Machine::preset("mill800-21").unwrap();
    let model = fitted(&dir, "lines", &laser_lines(m.travel_mm, &[0.0, 150.0]));
    let out = dir.join("skew.cfg");
    for format in ["klipper-skew", "marlin-skew", "matrixkins"] {
        let args = export_args(&model, &["--format", format], &out);
        let err = expect_exit(
            &args,
            1,
            &["cannot_know", "C0Y", "face diagonals", "not written"],
        );
        assert!(!err.contains("µrad:"), "{err}");
        assert!(!out.exists());
    }
    // --tool-mm belongs to the skew formats only.
    let table = dir.join("t.bin");
    expect_exit(
        &export_args(&model, &["--tool-mm", "100"], &table),
        2,
        &["--tool-mm applies to --format"],
    );
    // A skew file holds factors, not a table of corrections.
    expect_exit(
        &export_args(
            &model,
            &["--format", "marlin-skew", "--max-corr-um", "5"],
            &out,
        ),
        2,
        &[
            "--max-corr-um applies to --format table",
            "not to --format marlin-skew",
        ],
    );
}
