//! Numbers and ranges that start with a minus sign are values, not flags
//! (docs/cli.md): `--tool-mm -50` is a documented tool length, and
//! `--noise-um -1` reaches simulate's own range check (exit 1, the option
//! and its range named) instead of clap's "unexpected argument" (exit 2).
//! (export's numeric flags carry the same attributes; its tests cover them.)

mod common;

use common::{expect_exit, s, tmp_dir};
use trueaxis_engine::import;
use trueaxis_engine::simulate::SimConfig;

#[test]
fn simulate_takes_a_negative_tool_length() {
    let dir = tmp_dir("negative-numbers", "tool");
    let csv = dir.join("x.csv");
    let v = common::simulate(
        &["--plan", "grid:100", "--tool-mm", "-50", "--noise-um", "0"],
        &csv,
    );
    assert_eq!(v["rows"], 324, "{v}");
    // The errors are the preset machine's with a −50 mm Abbe arm (the arm
    // lengthens its angular errors; it is not written as a column).
    let data = import::load(&csv).unwrap();
    let machine = SimConfig::preset("mill800").unwrap().machine;
    for r in [1, 40, 200] {
        let p = [0, 1, 2].map(|a| data.pos(a, r));
        let want = machine.error_um(p, -50.0);
        let at_zero = machine.error_um(p, 0.0);
        for (t, want) in want.iter().enumerate() {
            let got = data.err_um[t].as_ref().unwrap()[r].unwrap();
            assert!((got - want).abs() < 1e-3, "row {r} {t}: {got} vs {want}");
        }
        assert!((want[0] - at_zero[0]).abs() > 0.01 || (want[1] - at_zero[1]).abs() > 0.01);
    }
}

#[test]
fn out_of_range_negative_values_meet_our_own_checks() {
    let dir = tmp_dir("negative-numbers", "ranges");
    let csv = dir.join("x.csv");
    let err = expect_exit(
        &[
            "simulate",
            "--plan",
            "grid:100",
            "--noise-um",
            "-1",
            "-o",
            s(&csv),
        ],
        1,
        &["--noise-um = -1.0: expected a finite value ≥ 0 µm and ≤ 100 µm"],
    );
    assert!(!err.contains("unexpected argument"), "{err}");
    assert!(!csv.exists());
    // A negative reference coordinate is a value too: outside the travel.
    expect_exit(
        &[
            "simulate",
            "--plan",
            "grid:100",
            "--ref",
            "-10,0,0",
            "-o",
            s(&csv),
        ],
        1,
        &["x=-10 mm is outside the travel"],
    );
    // A negative seed is a usage error about its value, not a stray flag.
    expect_exit(
        &[
            "simulate",
            "--plan",
            "grid:100",
            "--seed",
            "-1",
            "-o",
            s(&csv),
        ],
        2,
        &["invalid value '-1' for '--seed <SEED>'"],
    );
}
