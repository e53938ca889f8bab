//! Issue 12, "aliasing is an answer, not a footnote": on a grid too coarse
//! to see a 5.08 mm lead along y, the lead aliases into a ~300 mm wave,
//! and `improve` used to add `higher_order:target=ey,axis=y` for it — a
//! model *worse* between the measured points than cubic19 alone. Here
//! every campaign is judged where the fit never looked: dense 0.5 mm lines
//! along x, y and z through positions no grid plane passes (simulated
//! separately, another noise seed, the same machine), on which the model
//! `improve` ends with must never be worse than the cubic19 it started
//! from. The campaigns:
//!
//! - the reproducer (grid + a dense line along x, the lead on y):
//!   nothing along y is added, the lead's alias is held back with the
//!   periods that would look the same (5.08 mm among them) and the line to
//!   measure — in the improve and diagnose text and JSON;
//! - a real 300 mm wave on the same grid: on these points it looks the
//!   same as the alias, so it is not added either — but named with the
//!   line to measure, and the verdict is not `at_noise_floor`; with that
//!   line measured, it is found and the model is better between points;
//! - the lead with a dense line along y: the periodic term is found and
//!   added (the check does not stop a wave the sampling resolves).

mod common;

use std::path::{Path, PathBuf};

use common::{json, run, s, tmp_dir};
use serde_json::Value;

const LEAD: &str = "periodic:axis=y,period_mm=5.08,amp_um=3";
const LONG_WAVE: &str = "periodic:axis=y,period_mm=300,amp_um=3";
/// The reproducer's grid, coarser than the 20 mm (four times fewer
/// points, the same ~300 mm alias: 1/5.08 − 8/40 ≈ 1/317 as 1/5.08 − 4/20).
const GRID: &str = "grid:40";

fn simulate(dir: &Path, name: &str, plans: &[&str], effect: &str, seed: &str) -> PathBuf {
    let csv = dir.join(name);
    let mut args = vec!["simulate"];
    for p in plans {
        args.extend(["--plan", p]);
    }
    args.extend(["--effect", effect, "--seed", seed, "-o", s(&csv), "--json"]);
    json(&run(&args));
    csv
}

fn improve(csv: &Path, model: &Path) -> Value {
    json(&common::cubic19("improve", csv, model, &[]))
}

/// RMS per (line axis, target) of `model` on dense 0.5 mm lines along x,
/// y and z, bidirectional, at y = 253, x = 317, z = 137 mm — on no grid
/// plane of any plan here, and for the lead not on a multiple of 5 mm
/// either (where the alias equals the lead) — with noise seed 9.
fn dense_rms(dir: &Path, effect: &str, model: &Path) -> Vec<(String, String, f64)> {
    let mut out = Vec::new();
    for (a, at) in [
        ("x", "y=253,z=137"),
        ("y", "x=317,z=137"),
        ("z", "x=317,y=253"),
    ] {
        let csv = dir.join(format!("dense_{a}.csv"));
        if !csv.exists() {
            let plan = format!("line:{a}:0.5,{at},bidir");
            simulate(dir, &format!("dense_{a}.csv"), &[&plan], effect, "9");
        }
        let c = json(&run(&["compare", s(&csv), "--model", s(model), "--json"]));
        for (t, v) in c["rms_um"].as_object().unwrap() {
            out.push((a.to_string(), t.clone(), v.as_f64().unwrap()));
        }
    }
    out
}

/// The model `improve` ended with is nowhere worse than cubic19 fitted to
/// the same data, on the dense lines the fit never saw (by more than 2 %
/// or 0.02 µm: the two fits' noise).
fn assert_never_worse(
    improved: &[(String, String, f64)],
    start: &[(String, String, f64)],
) -> Vec<String> {
    let mut lines = Vec::new();
    for ((a, t, after), (a0, t0, before)) in improved.iter().zip(start) {
        assert_eq!((a, t), (a0, t0));
        lines.push(format!("line {a} {t}: {before:.3} → {after:.3} µm"));
        assert!(
            *after <= before * 1.02 + 0.02,
            "the improved model is worse between the measured points: on the dense line along {a}, {t} {after:.3} µm against cubic19's {before:.3} µm"
        );
    }
    lines
}

fn adds(model: &Path) -> Vec<String> {
    let m: Value = serde_json::from_str(&std::fs::read_to_string(model).unwrap()).unwrap();
    m["adds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect()
}

/// A wave term along y (periodic or higher_order) for ey.
fn wave_along_y(add: &str) -> bool {
    (add.starts_with("periodic:") || add.starts_with("higher_order:"))
        && add.contains("target=ey")
        && add.contains("axis=y")
}

#[test]
fn the_reproducer_adds_no_alias_and_says_what_to_measure() {
    let dir = tmp_dir("aliasing", "lead");
    let csv = simulate(&dir, "d.csv", &[GRID, "line:x:0.5,bidir"], LEAD, "1");
    let model = dir.join("m.json");
    let imp = improve(&csv, &model);
    let c19 = dir.join("c19.json");
    common::fit_cubic19(&csv, &c19);
    // Never worse between the points (on main, with
    // `higher_order:target=ey,axis=y,degree=4` added: the line along y
    // 2.52 → 3.02 µm, x 4.63 → 5.51, z 4.54 → 5.49).
    let start = dense_rms(&dir, LEAD, &c19);
    let end = dense_rms(&dir, LEAD, &model);
    eprintln!("{}", assert_never_worse(&end, &start).join("\n"));
    // No term along the coarse axis in the model.
    let kept = adds(&model);
    assert!(!kept.iter().any(|a| wave_along_y(a)), "{kept:?}");
    // Why it stopped, with the line to measure.
    let held = imp["held_back"].as_array().expect("held_back");
    let h = held
        .iter()
        .find(|h| h["target"] == "ey")
        .unwrap_or_else(|| panic!("nothing held back for ey: {imp:#}"));
    assert!(wave_along_y(h["add"].as_str().unwrap()), "{h}");
    let why = h["why"].as_str().unwrap();
    assert!(why.contains("y is sampled every 40 mm"), "{why}");
    assert!(
        h["measure"]
            .as_str()
            .unwrap()
            .starts_with("y from 0 to 480 mm every 0.5 mm"),
        "{h}"
    );
    assert_ne!(imp["verdict"], "at_noise_floor");

    // diagnose says the same, next to the candidate: JSON …
    let d = json(&run(&["diagnose", s(&csv), "--model", "cubic19", "--json"]));
    assert_eq!(d["verdict"], "above_noise_floor");
    let c = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["held_back"] == true)
        .unwrap_or_else(|| panic!("no held-back candidate: {:#}", d["candidates"]));
    assert_eq!(c["aliasing_suspect"], true);
    assert_eq!(c["significant"], false);
    assert_eq!(d["held_back"][0], c["add"]);
    // The true lead is among the periods that look the same on the grid.
    let periods = common::f64s(&c["alias_periods_mm"]);
    assert!(
        periods.iter().any(|p| (p - 5.08).abs() < 0.05),
        "{periods:?}"
    );
    assert!(periods.iter().all(|p| (2.0..=40.0).contains(p)));
    assert_eq!(c["aliasing"]["axis"], "y");
    assert_eq!(c["aliasing"]["sampling_mm"], 40.0);
    assert!(d["next_command"].is_null(), "{}", d["next_command"]);
    // … and text: the aliasing line right under the candidate, the verdict
    // naming it, the line to measure instead of a `next:` fit.
    let out = run(&["diagnose", s(&csv), "--model", "cubic19"]);
    let text = String::from_utf8_lossy(&out.stdout);
    let add = c["add"].as_str().unwrap();
    assert!(
        text.contains(&format!("held back (aliasing-suspect, not added): `{add}`")),
        "{text}"
    );
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.contains(&format!(". {add}")))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        lines[at + 2]
            .trim_start()
            .starts_with("aliasing: ey varies along y"),
        "{text}"
    );
    assert!(
        text.contains("measure first: a dense line: y from 0 to 480 mm every 0.5 mm"),
        "{text}"
    );
    assert!(!text.contains("\nnext: "), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_real_long_wave_on_a_coarse_grid_is_named_and_found_once_the_line_is_measured() {
    let dir = tmp_dir("aliasing", "wave");
    // On the grid alone a true 300 mm wave looks like the lead's alias.
    let csv = simulate(
        &dir,
        "grid.csv",
        &[GRID, "line:x:0.5,bidir"],
        LONG_WAVE,
        "1",
    );
    let model = dir.join("m.json");
    let imp = improve(&csv, &model);
    let c19 = dir.join("c19.json");
    common::fit_cubic19(&csv, &c19);
    assert!(!adds(&model).iter().any(|a| wave_along_y(a)));
    // Not silently lost: named, with the line, and not "at the noise floor".
    let held = imp["held_back"].as_array().expect("held_back");
    assert!(
        held.iter().any(|h| h["target"] == "ey"
            && h["why"].as_str().unwrap().contains("varies along y")
            && h["measure"].as_str().unwrap().contains("every 0.5 mm")),
        "{imp:#}"
    );
    assert_ne!(imp["verdict"], "at_noise_floor");
    let start = dense_rms(&dir, LONG_WAVE, &c19);
    let end = dense_rms(&dir, LONG_WAVE, &model);
    eprintln!("{}", assert_never_worse(&end, &start).join("\n"));

    // The line asked for, measured: the wave is resolved, added, and the
    // model is better between the points, far from the line too.
    let csv = simulate(
        &dir,
        "grid_and_line.csv",
        &[GRID, "line:x:0.5,bidir", "line:y:0.5,bidir"],
        LONG_WAVE,
        "1",
    );
    let model = dir.join("m2.json");
    let imp = improve(&csv, &model);
    let c19 = dir.join("c19_2.json");
    common::fit_cubic19(&csv, &c19);
    assert!(adds(&model).iter().any(|a| wave_along_y(a)), "{imp:#}");
    let start = dense_rms(&dir, LONG_WAVE, &c19);
    let end = dense_rms(&dir, LONG_WAVE, &model);
    eprintln!("{}", assert_never_worse(&end, &start).join("\n"));
    let y = |v: &[(String, String, f64)]| {
        v.iter()
            .find(|(a, t, _)| a == "y" && t == "ey")
            .map(|x| x.2)
            .unwrap()
    };
    assert!(y(&end) < 0.5 * y(&start), "{} vs {}", y(&end), y(&start));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn with_a_dense_line_along_y_the_lead_is_found_and_added() {
    let dir = tmp_dir("aliasing", "line");
    let csv = simulate(
        &dir,
        "d.csv",
        &[GRID, "line:x:0.5,bidir", "line:y:0.5,bidir"],
        LEAD,
        "1",
    );
    let model = dir.join("m.json");
    let imp = improve(&csv, &model);
    let c19 = dir.join("c19.json");
    common::fit_cubic19(&csv, &c19);
    let kept = adds(&model);
    let lead = kept
        .iter()
        .find(|a| a.starts_with("periodic:target=ey,axis=y,"))
        .unwrap_or_else(|| panic!("{kept:?}"));
    let period: f64 = lead
        .split("period_mm=")
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((period - 5.08).abs() < 0.01, "{lead}");
    assert_eq!(imp["held_back"], serde_json::json!([]), "{imp:#}");
    let start = dense_rms(&dir, LEAD, &c19);
    let end = dense_rms(&dir, LEAD, &model);
    eprintln!("{}", assert_never_worse(&end, &start).join("\n"));
    // Between the points, far from the measured line: to the noise.
    for (a, t, v) in &end {
        assert!(*v < 0.3, "line {a} {t}: {v} µm");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A look-alike of a public ISO 230-2 run (ecmc's example, 5 targets
/// 15…55 mm, 5 bidirectional cycles, an axis whose error swings by tens of
/// µm between neighbouring targets): a lead error of 6.25 mm (15 µm) seen
/// at 10 mm steps, 1.4 µm of backlash, 0.3 µm noise. With 5 positions a
/// quartic passes through every target mean; the block hold-out keeps
/// every position in training, so before issue 12's check `improve` added
/// `higher_order … degree=4` as "significant" — an interpolation, a claim
/// about the shape between the targets the data cannot make. Now the
/// wave is held back as aliasing-suspect with the line to measure along x
/// (and, while it is the target's strongest signal, the weaker backlash is
/// not claimed either: docs/diagnose.md § Aliasing).
#[test]
fn five_iso230_targets_get_no_interpolating_term() {
    let dir = tmp_dir("aliasing", "iso230");
    let mut rng = trueaxis_test_support::SplitMix64::new(230);
    let mut csv = String::from("x_mm,ex_um,dir_x,pass_id\n");
    let mut pass = 0;
    for _cycle in 0..5 {
        for (dir, order) in [
            (1, [15.0, 25.0, 35.0, 45.0, 55.0]),
            (-1, [55.0, 45.0, 35.0, 25.0, 15.0]),
        ] {
            pass += 1;
            for x in order {
                let e = 15.0 * (2.0 * std::f64::consts::PI * x / 6.25).sin()
                    + 0.7 * f64::from(dir)
                    + 0.3 * rng.normal();
                csv.push_str(&format!("{x},{e:.4},{dir},{pass}\n"));
            }
        }
    }
    let data = common::file_in(&dir, "iso230.csv", csv);
    let model = dir.join("m.json");
    let imp = improve(&data, &model);
    let added = adds(&model);
    assert!(
        added
            .iter()
            .all(|a| !a.starts_with("higher_order") && !a.starts_with("periodic")),
        "an interpolating term was added: {added:?}"
    );
    let held = imp["held_back"].as_array().expect("held_back");
    assert!(!held.is_empty(), "{imp:#}");
    assert_ne!(imp["verdict"], "at_noise_floor");
    let why = held[0]["why"].as_str().unwrap();
    assert!(why.contains("x is sampled every 10 mm"), "{why}");
    assert!(held[0]["measure"]
        .as_str()
        .unwrap()
        .contains("every 0.5 mm"));
}
