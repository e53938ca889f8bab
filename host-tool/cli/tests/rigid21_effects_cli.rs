//! A rigid21 model with a named effect on top, end to end from the command
//! line (docs/volumetric.md § Effects on top, § Diagnose): the simulator's
//! `mill800-21` with a 3 µm, 100 mm lead on X measured by laser lines at
//! tool lengths 0 and 150 mm (5 mm steps on X, seed 11). `diagnose` on the
//! plain `rigid21` model names the lead and its `next:` — the fit with
//! `--add periodic:…` on top — runs as pasted; the model it writes keeps
//! the effect, its ex residual falls to the instrument's noise, `diagnose`
//! on it finds nothing missing and proposes the export, which runs as
//! pasted (its accuracy gate compares the table with the model, effects
//! included), and `compare` evaluates it.

mod common;

use common::{json, paste, run, s, tmp_dir};
use trueaxis_engine::import;
use trueaxis_engine::model::{FittedModel, ModelFile};
use trueaxis_engine::simulate::instruments::{laser_lines_along, measure};
use trueaxis_engine::simulate::Machine;

#[test]
fn diagnose_proposes_the_lead_on_top_and_the_loop_reaches_the_board() {
    let dir = tmp_dir("rigid21-effects", "lead");
    let m = Machine::preset("mill800-21")
        .unwrap()
        .with_lead(0, 3.0, 100.0, 0.3);
    let plan = laser_lines_along(m.travel_mm, &[0.0, 150.0], 0, 161);
    let data = measure(&m, &plan, 11, true);
    let csv = dir.join("lines.csv");
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    let model = dir.join("lines.model.json");
    let before = json(&run(&[
        "fit",
        s(&csv),
        "--model",
        "rigid21",
        "-o",
        s(&model),
        "--json",
    ]));
    let rms_before = before["rms_um"]["ex"].as_f64().unwrap();
    let compared_before = compare_ex_rms(&csv, &model);

    // diagnose names the lead and proposes the fit with it on top.
    let out = run(&["diagnose", s(&csv), "--model", s(&model)]);
    common::assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        text.contains("missing: X positioning EXX: a periodic (lead) error"),
        "{text}"
    );
    let next = text
        .lines()
        .find_map(|l| l.strip_prefix("next: "))
        .expect("a next command")
        .to_string();
    assert!(
        next.contains("--model rigid21:4 --add periodic:target=ex,axis=x,period_mm="),
        "{next}"
    );
    paste(&dir, &next).unwrap();
    let mf = ModelFile::load(&model).unwrap();
    assert_eq!(mf.adds.len(), 1, "{:?}", mf.adds);
    let FittedModel::Rigid21(r) = &mf.model else {
        panic!("kind {}", mf.model.kind())
    };
    assert!(r.effects.is_some());
    let id = mf.stats.volumetric.as_ref().unwrap();
    let amp = id.effects[0].value.unwrap();
    assert!((amp - 3.0).abs() < 0.3, "{amp}");
    // At the period diagnose refined the lead goes: the residual is the
    // instrument's.
    let rms_after = mf.stats.rms_um["ex"];
    assert!(
        rms_before > 1.5 && rms_after < 0.3,
        "ex RMS {rms_before} → {rms_after}"
    );

    // With the lead on top nothing is missing: the export, as pasted.
    let out = run(&["diagnose", s(&csv), "--model", s(&model), "--json"]);
    let doc = json(&out);
    assert_eq!(doc["findings"].as_array().map(Vec::len), Some(0), "{doc}");
    let next = doc["next_command"].as_str().unwrap();
    assert!(next.starts_with("trueaxis export "), "{next}");
    paste(&dir, next).unwrap();
    assert!(dir.join("table.bin").exists());

    // compare reads the effect too: the lead leaves its residual.
    let compared_after = compare_ex_rms(&csv, &model);
    assert!(
        compared_after < 0.5 * compared_before,
        "compare ex RMS {compared_before} → {compared_after}"
    );
}

/// `compare`'s ex residual (after each set-up's own unknowns), µm.
fn compare_ex_rms(csv: &std::path::Path, model: &std::path::Path) -> f64 {
    let c = json(&run(&["compare", s(csv), "--model", s(model), "--json"]));
    let ex = c["readings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["reading"] == "ex")
        .unwrap_or_else(|| panic!("{c}"));
    ex["rms"].as_f64().unwrap()
}
