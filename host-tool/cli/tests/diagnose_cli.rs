//! The diagnosis commands end to end through the `trueaxis` binary:
//! `diagnose --json` has the shape of docs/cli.md and its `add` string is
//! accepted verbatim by `fit --add`; `improve` runs the loop to the noise
//! floor and leaves the same steps in the model's history; grid-only data
//! warns `aliasing` and one-direction data warns `one_direction`.

mod common;

use std::path::Path;
use std::process::Output;

use common::{fit, json, run, s};
use serde_json::Value;
use trueaxis_engine::diagnose::{diagnose, Options};
use trueaxis_engine::model::Seed;
use trueaxis_engine::simulate::synth::{generate, Hidden, Plan, SynthConfig};

fn tmp_dir(name: &str) -> std::path::PathBuf {
    common::tmp_dir("diag", name)
}

fn write(cfg: &SynthConfig, path: &Path) {
    let data = generate(cfg);
    let mut f = std::fs::File::create(path).unwrap();
    trueaxis_engine::import::write_csv(&data, &mut f).unwrap();
}

/// `trueaxis diagnose CSV --model MODEL --json`.
fn diagnose_json(csv: &Path, model: &str) -> Output {
    run(&["diagnose", s(csv), "--model", model, "--json"])
}

/// `trueaxis improve CSV --model cubic19 -o MODEL --json`.
fn improve_json(csv: &Path, model: &Path) -> Output {
    common::cubic19("improve", csv, model, &[])
}

/// Stderr of a run that must succeed.
fn stderr_ok(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "exit {:?}: {err}", out.status.code());
    err
}

fn is_num_map(v: &Value) -> bool {
    v.as_object().is_some_and(|m| {
        !m.is_empty()
            && m.keys().all(|k| ["ex", "ey", "ez"].contains(&k.as_str()))
            && m.values().all(|x| x.is_number())
    })
}

#[test]
fn diagnose_json_has_the_contract_shape_and_add_feeds_fit() {
    let dir = tmp_dir("json");
    let csv = dir.join("periodic.csv");
    write(
        &SynthConfig {
            seed: 5,
            hidden: vec![Hidden::Periodic],
            ..SynthConfig::default()
        },
        &csv,
    );
    let v = json(&diagnose_json(&csv, "cubic19"));
    assert_eq!(v["model"], "cubic19");
    assert!(
        is_num_map(&v["rms_um"]) && is_num_map(&v["held_out_rms_um"]),
        "{v}"
    );
    assert!(v["noise_floor_um"]
        .as_object()
        .unwrap()
        .values()
        .all(|x| x.is_number() || x.is_null()));
    assert_eq!(v["verdict"], "missing_effect");
    let cands = v["candidates"].as_array().unwrap();
    assert!(!cands.is_empty());
    // The families docs/cli.md lists are the engine's registry.
    let families: Vec<&str> = trueaxis_engine::effect::Family::ALL
        .iter()
        .map(|f| f.as_str())
        .collect();
    assert!(families.starts_with(&[
        "periodic",
        "thermal",
        "reversal",
        "abbe",
        "drift",
        "squareness",
        "higher_order",
    ]));
    for c in cands {
        assert!(families.contains(&c["effect"].as_str().unwrap()), "{c}");
        assert!(["ex", "ey", "ez"].contains(&c["target"].as_str().unwrap()));
        assert!(c["axis"].is_string() || c["axis"].is_null());
        assert!(c["channel"].is_string() || c["channel"].is_null());
        assert!(c["params"].is_object());
        assert!(c["add"].is_string());
        assert!(c["held_out_rms_um_after"].is_number() || c["held_out_rms_um_after"].is_null());
        assert!(c["gain"].is_number() || c["gain"].is_null());
        assert!(c["identifiable"].is_boolean());
        assert!(c["evidence"].is_string());
        // Extension: on_path is written from the step.
        assert_eq!(c["on_path"].as_bool(), Some(!c["step"].is_null()), "{c}");
    }
    let top = &cands[0];
    assert_eq!(top["effect"], "periodic");
    assert!((top["params"]["period_mm"].as_f64().unwrap() - 5.08).abs() < 0.01);
    // Counts are integers; the fitted magnitude is in params too.
    assert!(top["params"]["harmonics"].is_u64(), "{}", top["params"]);
    assert!((top["params"]["amplitude_um"].as_f64().unwrap() - 2.5).abs() < 0.1);
    for c in cands {
        for k in ["harmonics", "order", "degree"] {
            assert!(
                c["params"].get(k).is_none_or(|v| v.is_u64()),
                "{k} in {}",
                c["params"]
            );
        }
    }
    let codes = [
        "aliasing",
        "one_direction",
        "constant_temperature",
        "in_model_span",
        "confounded",
        "implausible_parameter",
        "above_noise_floor",
        "no_temperature",
    ];
    for w in v["warnings"].as_array().unwrap() {
        assert!(codes.contains(&w["code"].as_str().unwrap()), "{w}");
        assert!(w["detail"].is_string());
    }
    for r in v["worst_regions"].as_array().unwrap() {
        assert!(r["target"].is_string() && r["bbox_mm"].is_object() && r["rms_um"].is_number());
    }
    // The add string goes to fit verbatim, and the fit starts a history.
    let model = dir.join("m.json");
    let add = top["add"].as_str().unwrap();
    let v = fit(&csv, &["--model", "cubic19", "--add", add], &model);
    assert!(v["rms_um"]["ey"].as_f64().unwrap() < 0.4, "{v}");
    let h = json(&run(&["history", s(&model), "--json"]));
    assert_eq!(h["steps"].as_array().unwrap().len(), 1);
    // Its page opens with the verdict, which sends to diagnose on the data
    // the model was fitted to (the history holds no noise floor).
    let hist = dir.join("hist");
    stderr_ok(&run(&["history", s(&model), "--report", s(&hist)]));
    let html = std::fs::read_to_string(hist.join("index.html")).unwrap();
    let body = &html[html.find("</h1>").unwrap() + 5..];
    assert!(body.trim_start().starts_with("<section id=\"verdict\""));
    let next = format!("trueaxis diagnose {} --model {}", s(&csv), s(&model));
    common::assert_has(body, &["One fit so far", &next]);
    // Diagnosing that model with --report shows its history as well.
    let report = dir.join("report");
    stderr_ok(&run(&[
        "diagnose",
        s(&csv),
        "--model",
        s(&model),
        "--report",
        s(&report),
    ]));
    let svg = std::fs::read_to_string(report.join("history.svg")).expect("history.svg");
    assert!(svg.contains("ey RMS") && svg.contains("ey held-out RMS"));
    // The page opens with the verdict card, and it ends with a command.
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    let body = &html[html.find("</h1>").expect("a title") + 5..];
    assert!(
        body.trim_start().starts_with("<section id=\"verdict\""),
        "{}",
        &body[..300.min(body.len())]
    );
    assert!(
        body.contains("<pre class=\"next\">trueaxis "),
        "a next command"
    );
    // A usage error (unknown seed) is exit 1 with a message, not a panic.
    common::expect_exit(
        &["diagnose", s(&csv), "--model", "nn:8"],
        1,
        &["linear seeds"],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn improve_runs_to_the_noise_floor_and_keeps_the_history() {
    let dir = tmp_dir("improve");
    let csv = dir.join("two.csv");
    write(
        &SynthConfig {
            seed: 9,
            hidden: vec![Hidden::Periodic, Hidden::Reversal],
            ..SynthConfig::default()
        },
        &csv,
    );
    let model = dir.join("m.json");
    let v = json(&improve_json(&csv, &model));
    assert_eq!(v["verdict"], "at_noise_floor", "{v}");
    // The two effects are on different targets (fitted independently), so
    // one step adds the best of each: seed, then both.
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2, "{v}");
    let added: Vec<&str> = steps[1]["added_effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["add"].as_str().unwrap())
        .collect();
    assert_eq!(added.len(), 2, "{added:?}");
    // `added` and `evidence` are the first (best) of them; null for the seed.
    assert!(steps[0]["added"].is_null() && steps[0]["evidence"].is_null());
    assert_eq!(steps[1]["added"], added[0]);
    assert_eq!(
        steps[1]["evidence"],
        steps[1]["added_effects"][0]["evidence"]
    );
    assert!(
        added
            .iter()
            .any(|a| a.starts_with("periodic:target=ey,axis=y")),
        "{added:?}"
    );
    assert!(
        added
            .iter()
            .any(|a| a.starts_with("reversal:target=ex,axis=x")),
        "{added:?}"
    );
    let last = &steps[1];
    for t in ["ex", "ey", "ez"] {
        assert!(last["rms_um"][t].as_f64().unwrap() <= 1.3 * 0.3, "{last}");
    }
    // No effect is in the model twice (the same family, target, axis,
    // channel and times — a re-found lag or period replaces the old one).
    let m: Value = serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let adds: Vec<trueaxis_engine::effect::EffectSpec> = m["adds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().parse().unwrap())
        .collect();
    for (i, a) in adds.iter().enumerate() {
        for b in &adds[i + 1..] {
            assert!(!a.same_effect(b), "{a} and {b}");
        }
    }
    let out = run(&["history", s(&model)]);
    stderr_ok(&out);
    let out = String::from_utf8_lossy(&out.stdout);
    common::assert_has(&out, &["2 step(s)", "reversal:target=ex,axis=x"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn grid_only_data_warns_aliasing_with_the_line_to_add() {
    let data = generate(&SynthConfig {
        plan: Plan::GridOnly,
        hidden: vec![Hidden::Periodic],
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    for axis in ["x", "y", "z"] {
        assert!(
            d.warnings.iter().any(|w| w.code == "aliasing"
                && w.detail.contains(&format!("add a dense line along {axis}"))),
            "{:?}",
            d.warnings
        );
    }
    // The 5.08 mm period cannot be seen on a 100 mm grid: no periodic
    // candidate may claim it.
    assert!(d
        .candidates
        .iter()
        .all(|c| !(c.significant && c.effect == "periodic")));
}

#[test]
fn one_direction_data_warns_one_direction() {
    let data = generate(&SynthConfig {
        bidirectional: false,
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert!(
        d.warnings.iter().any(|w| w.code == "one_direction"),
        "{:?}",
        d.warnings
    );
    assert!(d.candidates.iter().all(|c| c.effect != "reversal"));
}

/// Rows the importer leaves out are said on stderr and counted in the
/// JSON (`skipped_count`), by diagnose and by improve.
#[test]
fn rows_left_out_are_counted_and_said() {
    let dir = tmp_dir("skipped");
    let csv = dir.join("grid.csv");
    stderr_ok(&run(&["simulate", "--plan", "grid:100", "-o", s(&csv)]));
    let holed = dir.join("holed.csv");
    let line = common::with_blank_error_row(&csv, &holed);
    let note = format!(
        "note: 1 row of {} was left out (line {line}: no error value on this row)",
        s(&holed)
    );

    let out = diagnose_json(&holed, "cubic19");
    assert_eq!(json(&out)["skipped_count"], 1);
    let err = stderr_ok(&out);
    assert!(err.contains(&note), "{err}");
    let out = diagnose_json(&csv, "cubic19");
    assert_eq!(json(&out)["skipped_count"], 0);
    let err = stderr_ok(&out);
    assert!(!err.contains("left out"), "{err}");

    let out = improve_json(&holed, &dir.join("m.json"));
    assert_eq!(json(&out)["skipped_count"], 1);
    let err = stderr_ok(&out);
    assert!(err.contains(&note), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

/// Every family's `add` string, as diagnose prints it, is accepted verbatim
/// by `fit --add` — including a thermal term with a lag and `times`, a
/// third-order drift and a fifth-degree higher_order — and kept verbatim in
/// the model file.
#[test]
fn fit_add_accepts_every_familys_add_string_verbatim() {
    let dir = tmp_dir("every-add");
    let csv = dir.join("all.csv");
    write(
        &SynthConfig {
            seed: 3,
            hidden: Hidden::ALL.to_vec(),
            ..SynthConfig::default()
        },
        &csv,
    );
    let v = json(&diagnose_json(&csv, "kinematic"));
    let adds: Vec<String> = v["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["identifiable"] == true)
        .map(|c| c["add"].as_str().unwrap().to_string())
        .collect();
    let pick = |what: &str, ok: &dyn Fn(&str) -> bool| -> String {
        adds.iter()
            .find(|a| ok(a))
            .unwrap_or_else(|| panic!("no {what} among {adds:?}"))
            .clone()
    };
    let chosen = [
        pick("periodic", &|a| a.starts_with("periodic:")),
        pick("thermal with lag and times", &|a| {
            a.starts_with("thermal:") && a.contains(",times=") && a.contains(",lag_s=")
        }),
        pick("reversal", &|a| a.starts_with("reversal:")),
        pick("abbe", &|a| a.starts_with("abbe:")),
        pick("drift of order 3", &|a| {
            a.starts_with("drift:") && a.ends_with(",order=3")
        }),
        pick("squareness", &|a| a.starts_with("squareness:")),
        pick("higher_order of degree 5", &|a| {
            a.starts_with("higher_order:") && a.ends_with(",degree=5")
        }),
    ];
    let model = dir.join("m.json");
    let mut args = vec!["fit", s(&csv), "--model", "kinematic"];
    for a in &chosen {
        args.push("--add");
        args.push(a);
    }
    args.extend(["-o", s(&model), "--json"]);
    json(&run(&args));
    let m: Value = serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let kept = common::strs(&m["adds"]);
    assert_eq!(kept, chosen.iter().map(String::as_str).collect::<Vec<_>>());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Too few rows for the seed: exit 1, the file named once ("F: cannot
/// diagnose: ex has …", not "F: cannot diagnose: F: ex has …").
#[test]
fn too_few_rows_name_the_file_once() {
    let dir = tmp_dir("few");
    let csv = common::file_in(
        &dir,
        "few.csv",
        "x_mm,ex_um\n0,1\n10,2\n20,1.5\n30,2.5\n40,3\n",
    );
    let err = common::expect_exit(
        &["diagnose", s(&csv), "--model", "cubic19"],
        1,
        &[&format!(
            "{}: cannot diagnose: ex has 5 measured rows, too few for a model with 4 independent terms",
            s(&csv)
        )],
    );
    assert_eq!(err.matches(s(&csv)).count(), 1, "{err}");
}

/// diagnose and improve are not silent while they work: one stderr line per
/// stage and target, in `--json` mode too (stdout stays one document).
#[test]
fn diagnose_and_improve_say_their_progress_on_stderr() {
    let dir = tmp_dir("progress");
    let csv = dir.join("grid.csv");
    stderr_ok(&run(&["simulate", "--plan", "grid:100", "-o", s(&csv)]));
    let out = diagnose_json(&csv, "cubic19");
    assert!(json(&out).is_object());
    let err = stderr_ok(&out);
    for t in ["ex", "ey", "ez"] {
        for stage in ["fitting the model to 324 rows", "scoring", "done"] {
            assert!(
                err.contains(&format!("diagnose: {t}: {stage}")),
                "{t} {stage}: {err}"
            );
        }
    }
    let out = improve_json(&csv, &dir.join("m.json"));
    assert!(json(&out).is_object());
    let err = stderr_ok(&out);
    assert!(
        err.contains("improve: step 1: fitting cubic19 to 324 rows"),
        "{err}"
    );
    assert!(err.contains("improve: step 1: diagnosing"), "{err}");
    assert!(err.contains("diagnose: ex: scoring"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}
