//! The loop is followable: diagnose's `next:` command runs as printed and
//! continues the history of the model that was diagnosed (issue 13: it
//! had no `-o`, so `fit` refused it, and the history stayed at one step).

mod common;

use common::{json, run, s, tmp_dir};

#[test]
fn the_next_command_runs_as_printed_and_continues_the_history() {
    // A dir with a space: the command must quote it.
    let dir = tmp_dir("next", "a b");
    let data = dir.join("grid lead.csv");
    common::simulate(
        &[
            "--plan",
            "grid:100",
            "--plan",
            "line:x:1,bidir",
            "--effect",
            "periodic:axis=x,period_mm=10,amp_um=2",
            "--seed",
            "3",
        ],
        &data,
    );
    let model = dir.join("m.json");
    json(&common::cubic19("fit", &data, &model, &[]));
    let d = json(&run(&[
        "diagnose",
        s(&data),
        "--model",
        s(&model),
        "--json",
    ]));
    let cmd = d["next_command"].as_str().unwrap_or_else(|| panic!("{d}"));
    assert!(cmd.contains("periodic"), "{cmd}");
    assert!(cmd.ends_with(&format!("-o '{}'", model.display())), "{cmd}");
    // The text output prints the same command.
    let text = run(&["diagnose", s(&data), "--model", s(&model)]);
    assert!(
        String::from_utf8_lossy(&text.stdout).contains(&format!("next: {cmd}\n")),
        "{}",
        String::from_utf8_lossy(&text.stdout)
    );
    // Run it as a user would paste it into a shell.
    let bin = env!("CARGO_BIN_EXE_trueaxis");
    let line = cmd.replacen("trueaxis", &format!("'{bin}'"), 1);
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(&line)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{line}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let h = json(&run(&["history", s(&model), "--json"]));
    let steps = h["steps"].as_array().unwrap_or_else(|| panic!("{h}"));
    assert_eq!(steps.len(), 2, "{h}");
}
