//! `simulate`: determinism (same seed → identical bytes, different seed →
//! different), physics sanity (each effect alone on a perfect machine gives
//! its formula), plan shapes (the seed's 17 × 11 × 11 grid, serpentine,
//! ISO cycles, reference returns), noise level, and the CLI's JSON.

// Rows are checked across several parallel columns; index loops read clearer.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::PathBuf;

use common::{assert_success, json, run, s};

use trueaxis_engine::data::Dataset;
use trueaxis_engine::import;
use trueaxis_engine::iso230;
use trueaxis_engine::simulate::{
    self, ConfigError, Effect, Machine, Plan, RefReturn, Setting, SimConfig,
};

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("trueaxis-sim-{}-{name}", std::process::id()))
}

/// A perfect 800 × 500 × 500 machine, no noise, with `plans` and `effects`.
fn perfect(plans: &[&str], effects: &[&str]) -> SimConfig {
    let mut cfg = SimConfig::preset("perfect800").unwrap();
    cfg.plans = plans.iter().map(|p| p.parse().unwrap()).collect();
    cfg.effects = effects.iter().map(|e| e.parse().unwrap()).collect();
    cfg.check().unwrap();
    cfg
}

fn col(d: &Dataset, t: usize) -> Vec<f64> {
    d.err_um[t]
        .as_ref()
        .unwrap()
        .iter()
        .map(|v| v.unwrap())
        .collect()
}

/// Output is rounded to 0.1 nm.
const RES: f64 = 0.5e-4 + 1e-12;

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let args = |seed: &str, out: &PathBuf| {
        let o = run(&[
            "simulate",
            "--plan",
            "grid:100",
            "iso230:x",
            "--effect",
            "periodic:axis=y,period_mm=5.08,amp_um=3",
            "--effect",
            "thermal:channel=bed,rise_c=2,lag_s=600",
            "--noise-um",
            "0.3",
            "--seed",
            seed,
            "-o",
            s(out),
        ]);
        assert_success(&o);
        std::fs::read(out).unwrap()
    };
    let (a, b, c) = (tmp("a.csv"), tmp("b.csv"), tmp("c.csv"));
    let (ba, bb, bc) = (args("42", &a), args("42", &b), args("43", &c));
    assert_eq!(ba, bb, "same seed, same bytes");
    assert_ne!(ba, bc, "different seed, different noise");
    for p in [a, b, c] {
        let _ = std::fs::remove_file(p);
    }
}

#[test]
fn written_file_reads_back_identically() {
    let mut cfg = SimConfig::preset("mill800").unwrap();
    cfg.plans = vec!["grid:100".parse().unwrap()];
    cfg.effects = vec!["abbe:angle_urad=48.5,tools_mm=0/100".parse().unwrap()];
    cfg.noise_um = 0.2;
    let d = simulate::simulate(&cfg);
    let mut buf = Vec::new();
    import::write_csv(&d, &mut buf).unwrap();
    let back = import::read_csv(buf.as_slice(), "mem").unwrap();
    assert_eq!(back.columns_differing(&d), Vec::<&str>::new());
    assert_eq!(
        trueaxis_engine::import::content_hash(&back),
        trueaxis_engine::import::content_hash(&d)
    );
}

#[test]
fn seed_grid_is_17_by_11_by_11_serpentine() {
    let d = simulate::simulate(&perfect(&["grid:50"], &[]));
    assert_eq!(d.len(), 2057);
    let pass = d.pass_id.as_ref().unwrap();
    assert_eq!(*pass.last().unwrap(), 120, "one pass per x line: 11 × 11");
    let x = d.pos_mm[0].as_ref().unwrap();
    let dir_x = d.dir[0].as_ref().unwrap();
    // First line forward, second line backward: serpentine.
    assert_eq!(&x[..3], &[0.0, 50.0, 100.0]);
    assert_eq!(&x[17..20], &[800.0, 750.0, 700.0]);
    assert_eq!(dir_x[18], -1);
    let t = d.t_s.as_ref().unwrap();
    assert!(t.windows(2).all(|w| w[1] > w[0]), "time advances");
}

#[test]
fn squareness_only_gives_minus_angle_times_position() {
    let mut cfg = perfect(&["grid:100"], &[]);
    cfg.machine = Machine::perfect([800.0, 500.0, 500.0]);
    cfg.machine.squareness.xy_urad = 30.0;
    cfg.machine.squareness.yz_urad = -20.0;
    let d = simulate::simulate(&cfg);
    let (ex, ey, ez) = (col(&d, 0), col(&d, 1), col(&d, 2));
    for r in 0..d.len() {
        let (y, z) = (d.pos(1, r), d.pos(2, r));
        // ex = −S_xy·y, ey = −S_yz·z (µrad · mm · 1e-3 = µm).
        assert!(
            (ex[r] - (-30.0 * y * 1e-3)).abs() < RES,
            "row {r}: {}",
            ex[r]
        );
        assert!(
            (ey[r] - (20.0 * z * 1e-3)).abs() < RES,
            "row {r}: {}",
            ey[r]
        );
        assert_eq!(ez[r], 0.0);
    }
    // And with the library's unrounded evaluation, exactly.
    assert_eq!(
        cfg.machine.error_um([100.0, 400.0, 0.0], 0.0)[0],
        -30.0 * 400.0 * 1e-3
    );
}

/// `perfect` runs of an x line (4 runs, every 50 mm) under the thermal
/// `effect`, simulated.
fn warming_line(effect: &str) -> trueaxis_engine::data::Dataset {
    simulate::simulate(&perfect(&["line:x:50,runs=4"], &[effect]))
}

#[test]
fn thermal_growth_is_cte_times_delta_t_times_position() {
    let d = warming_line("thermal:channel=bed,cte_um_per_m_k=11.5,start_c=20,rise_c=3,tau_s=120");
    let temp = &d.temp("bed").expect("T_bed_C column").temp_c;
    assert!(
        temp[0] < 20.1 && *temp.last().unwrap() > 22.0,
        "the sensor warms up"
    );
    let ex = col(&d, 0);
    for r in 0..d.len() {
        let want = 11.5 * (temp[r] - 20.0) * d.pos(0, r) * 1e-3;
        assert!((ex[r] - want).abs() < RES, "row {r}: {} vs {want}", ex[r]);
    }
    // 800 mm at +3 K ≈ 27.6 µm: the realistic order of magnitude.
    assert!(ex.iter().cloned().fold(0.0, f64::max) > 20.0);
}

#[test]
fn thermal_lag_follows_features_lagged() {
    let d = warming_line("thermal:channel=bed,rise_c=3,tau_s=600,lag_s=900");
    let temp = &d.temp("bed").unwrap().temp_c;
    let lagged = trueaxis_engine::features::lagged(temp, d.t_s.as_ref().unwrap(), None, 900.0);
    let ex = col(&d, 0);
    for r in 0..d.len() {
        let want = 11.5 * (lagged[r] - 20.0) * d.pos(0, r) * 1e-3;
        assert!((ex[r] - want).abs() < RES, "row {r}");
    }
    assert!(
        lagged.last().unwrap() < temp.last().unwrap(),
        "the structure lags the sensor"
    );
}

#[test]
fn periodic_error_has_the_given_period_and_amplitude() {
    let d = simulate::simulate(&perfect(
        &["line:y:0.5,x=400,z=250"],
        &["periodic:axis=y,period_mm=5.08,amp_um=3"],
    ));
    assert_eq!(d.len(), 1001);
    let ey = col(&d, 1);
    for r in 0..d.len() {
        let want = 3.0 * (std::f64::consts::TAU * d.pos(1, r) / 5.08).sin();
        assert!((ey[r] - want).abs() < RES);
    }
    assert_eq!(col(&d, 0).iter().map(|v| v.abs()).fold(0.0, f64::max), 0.0);
}

#[test]
fn reversal_shows_as_iso230_b() {
    let d = simulate::simulate(&perfect(&["iso230:x"], &["reversal:axis=x,backlash_um=8"]));
    assert_eq!(d.len(), 11 * 2 * 5, "11 targets, 5 bidirectional runs");
    let r = iso230::evaluate(&d, 0).unwrap();
    assert_eq!(r.targets, 11);
    assert_eq!(r.runs, 5);
    assert!(
        (r.b_um - 8.0).abs() < 1e-9 && (r.b_mean_um - 8.0).abs() < 1e-9,
        "{}",
        r.b_um
    );
    assert!(r.r_up_um.abs() < 1e-9, "no noise, no repeatability spread");
    // Irregular targets: not all gaps equal.
    let p: Vec<f64> = r.per_target.iter().map(|t| t.pos_mm).collect();
    let gaps: Vec<f64> = p.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(gaps.iter().any(|g| (g - gaps[0]).abs() > 1.0), "{gaps:?}");
}

#[test]
fn abbe_and_drift() {
    let d = simulate::simulate(&perfect(
        &["line:x:100,runs=3"],
        &[
            "abbe:angle_urad=48.5,tools_mm=0/100/150,target=ey",
            "drift:um_per_h=2,target=ez",
        ],
    ));
    let tool = d.tool_mm.as_ref().expect("tool_mm column");
    let pass = d.pass_id.as_ref().unwrap();
    let (ey, ez) = (col(&d, 1), col(&d, 2));
    let t = d.t_s.as_ref().unwrap();
    for r in 0..d.len() {
        assert_eq!(tool[r], [0.0, 100.0, 150.0][pass[r] as usize % 3]);
        assert!((ey[r] - 48.5 * tool[r] * 1e-3).abs() < RES);
        assert!((ez[r] - 2.0 * t[r] / 3600.0).abs() < RES);
    }
    assert!(ey.contains(&4.85), "48.5 µrad × 100 mm = 4.85 µm");
}

#[test]
fn reference_returns_and_noise_level() {
    let mut cfg = SimConfig::preset("mill800").unwrap();
    cfg.plans = vec![Plan::Raster {
        axes: vec![0, 1, 2],
        step_mm: 50.0,
        at_mm: [None; 3],
        bidir: false,
        runs: 1,
    }];
    cfg.noise_um = 0.5;
    cfg.seed = 9;
    cfg.reference = Some(RefReturn {
        pos_mm: [0.0, 0.0, 0.0],
        every_passes: 11,
    });
    cfg.check().unwrap();
    let out = simulate::simulate_detailed(&cfg);
    let d = &out.data;
    // 121 lines, a reference visit before every 11th line (11) and at the end.
    assert_eq!(d.len(), 2057 + 11 + 1);
    let mut sum2 = 0.0;
    let mut n = 0;
    for t in 0..3 {
        for (r, v) in col(d, t).iter().enumerate() {
            sum2 += (v - out.truth_um[t][r]).powi(2);
            n += 1;
        }
    }
    let sigma = (sum2 / n as f64).sqrt();
    assert!((sigma - 0.5).abs() < 0.03, "noise σ = {sigma}");
}

#[test]
fn one_direction_reversal_is_flagged() {
    let d = simulate::simulate(&perfect(
        &["line:x:100"],
        &["reversal:axis=x,backlash_um=5"],
    ));
    assert!(d
        .metadata
        .iter()
        .any(|(k, v)| k == "warning" && v.contains("one direction")));
}

#[test]
fn cli_json_shape_and_bad_specs() {
    let out_csv = tmp("cli.csv");
    let o = run(&[
        "simulate",
        "--plan",
        "grid:50",
        "--seed",
        "3",
        "-o",
        s(&out_csv),
        "--json",
    ]);
    let v = json(&o);
    assert_eq!(v["rows"], 2057);
    assert_eq!(v["passes"], 121);
    assert_eq!(v["preset"], "mill800");
    assert_eq!(v["plans"], serde_json::json!(["grid:50"]));
    assert_eq!(v["noise_um"], 0.2);
    assert_eq!(
        v["columns"],
        serde_json::json!([
            "x_mm", "y_mm", "z_mm", "ex_um", "ey_um", "ez_um", "t_s", "dir_x", "dir_y", "dir_z",
            "pass_id"
        ])
    );
    let d = import::load(&out_csv).unwrap();
    assert_eq!(
        v["sha256"].as_str().unwrap(),
        trueaxis_engine::import::content_hash(&d)
    );
    let _ = std::fs::remove_file(&out_csv);

    let bad = run(&[
        "simulate",
        "--plan",
        "grid:50",
        "--effect",
        "periodic:axis=w,period_mm=5,amp_um=1",
        "-o",
        s(&out_csv),
    ]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("`axis=w`: expected x, y or z"));
    let bad = run(&["simulate", "--plan", "line:y:1,x=900", "-o", s(&out_csv)]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("outside the travel"));
    // A 1 mm grid of the preset would be 2·10⁸ rows: refused, not attempted.
    let bad = run(&["simulate", "--plan", "grid:1", "-o", s(&out_csv)]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("coarser step"));
}

#[test]
fn effects_are_constructible_from_rust() {
    let mut cfg = perfect(&["line:x:10"], &[]);
    cfg.effects
        .push(Effect::new(trueaxis_engine::effect::periodic::Sim {
            target: 0,
            axis: 0,
            period_mm: 20.0,
            amp_um: 1.0,
            harmonics: 2,
            phase_deg: 0.0,
        }));
    let d = simulate::simulate(&cfg);
    let ex = col(&d, 0);
    // x = 5: sin(π/2) + ½·sin(π) = 1.
    let want = |x: f64| {
        let a = std::f64::consts::TAU * x / 20.0;
        a.sin() + 0.5 * (2.0 * a).sin()
    };
    for r in 0..d.len() {
        assert!((ex[r] - want(d.pos(0, r))).abs() < RES);
    }
    assert!(d
        .metadata
        .iter()
        .any(|(k, v)| k == "effect" && v.starts_with("periodic:axis=x,period_mm=20")));
}

/// Residual RMS of the least-squares projection of `y` onto `cols`
/// (modified Gram–Schmidt, twice for stability).
fn residual_rms(cols: &[Vec<f64>], y: &[f64]) -> f64 {
    let mut q: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let mut v = c.clone();
        for _ in 0..2 {
            for qk in &q {
                let d: f64 = qk.iter().zip(&v).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(qk).for_each(|(vi, qi)| *vi -= d * qi);
            }
        }
        let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if n > 1e-9 {
            q.push(v.into_iter().map(|a| a / n).collect());
        }
    }
    let mut r = y.to_vec();
    for qk in &q {
        let d: f64 = qk.iter().zip(&r).map(|(a, b)| a * b).sum();
        r.iter_mut().zip(qk).for_each(|(ri, qi)| *ri -= d * qi);
    }
    (r.iter().map(|a| a * a).sum::<f64>() / r.len() as f64).sqrt()
}

#[test]
fn plain_preset_is_inside_cubic19_and_wavy_is_not() {
    // The module doc promises: cubic translations and quadratic angles keep
    // every component in the span of the seed's 19 terms, so the plain
    // preset fits to the output rounding; the wavy preset does not.
    let rms = |preset: &str| -> f64 {
        let mut cfg = SimConfig::preset(preset).unwrap();
        cfg.plans = vec!["grid:50".parse().unwrap()];
        cfg.tool_mm = 120.0;
        let d = simulate::simulate(&cfg);
        let u = |a: usize, r: usize| d.pos(a, r) / cfg.machine.travel_mm[a];
        let cols: Vec<Vec<f64>> = trueaxis_engine::features::CUBIC19
            .iter()
            .map(|e| {
                (0..d.len())
                    .map(|r| (0..3).map(|a| u(a, r).powi(e[a] as i32)).product())
                    .collect()
            })
            .collect();
        (0..3)
            .map(|t| residual_rms(&cols, &col(&d, t)))
            .fold(0.0, f64::max)
    };
    let plain = rms("mill800");
    assert!(plain < 1e-4, "mill800 cubic19 residual {plain} µm");
    let wavy = rms("mill800-wavy");
    assert!(wavy > 0.1, "mill800-wavy cubic19 residual {wavy} µm");
}

#[test]
fn pauses_and_new_sessions_restart_time_and_temperature() {
    let d = simulate::simulate(&perfect(
        &[
            "line:x:100",
            "pause:1800",
            "line:x:100",
            "pause:0,new_session",
            "line:x:100",
        ],
        &["thermal:channel=bed,rise_c=4,tau_s=900,lag_s=300"],
    ));
    assert_eq!(d.len(), 27);
    let t = d.t_s.as_ref().unwrap();
    let session = d
        .session_id
        .as_ref()
        .expect("session_id column with a new session");
    assert_eq!(&session[..], &[[1; 18].as_slice(), &[2; 9]].concat()[..]);
    // The idle half hour shows in t_s; the new session starts again at 0.
    assert!(t[9] - t[8] > 1800.0);
    // (35 s: the 800 mm move back to x = 0 at 25 mm/s, then the 3 s read.)
    assert!(t[18] < t[17] && (t[18] - 35.0).abs() < 1e-9, "{}", t[18]);
    let temp = &d.temp("bed").unwrap().temp_c;
    assert!(
        temp[17] > 23.0 && temp[18] < 20.2,
        "cold start each session"
    );
    // The structure's lag restarts with the session, as fit models it.
    let lagged = trueaxis_engine::features::lagged(temp, t, Some(session), 300.0);
    let ex = col(&d, 0);
    for r in 0..d.len() {
        let want = 11.5 * (lagged[r] - 20.0) * d.pos(0, r) * 1e-3;
        assert!((ex[r] - want).abs() < RES, "row {r}");
    }
}

#[test]
fn thermal_swing_makes_temperature_go_up_and_down() {
    let d = simulate::simulate(&perfect(
        &["line:x:10,runs=6"],
        &["thermal:channel=air,rise_c=0,swing_c=0.5,swing_period_s=600"],
    ));
    let temp = &d.temp("air").unwrap().temp_c;
    let t = d.t_s.as_ref().unwrap();
    for r in 0..d.len() {
        let want = 20.0 + 0.5 * (std::f64::consts::TAU * t[r] / 600.0).sin();
        assert!((temp[r] - want).abs() <= 0.0005 + 1e-12, "row {r}");
    }
    let (lo, hi) = temp
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(lo < 19.55 && hi > 20.45, "a full swing: {lo}..{hi}");
}

#[test]
fn golden_hash_pins_the_random_stream_and_the_format() {
    // A seed must give the same file across crate upgrades and refactors
    // (diagnosis benchmarks and published examples quote seeds). If this
    // fails after an intended change of the preset, plans or CSV format,
    // update the hash and say so in the commit; otherwise the change broke
    // reproducibility.
    let mut cfg = SimConfig::preset("mill800").unwrap();
    cfg.plans = vec![
        "iso230:x".parse().unwrap(),
        "line:y:25,bidir".parse().unwrap(),
    ];
    cfg.effects = vec![
        "periodic:axis=x,period_mm=5.08,amp_um=2".parse().unwrap(),
        "thermal:channel=bed,rise_c=1.5,lag_s=300,swing_c=0.2"
            .parse()
            .unwrap(),
    ];
    cfg.noise_um = 0.25;
    cfg.seed = 2024;
    let d = simulate::simulate(&cfg);
    assert_eq!(trueaxis_engine::import::content_hash(&d), GOLDEN);
}

/// sha256 of the canonical CSV. (libm's sin/exp may differ by an ulp
/// between platforms; the 0.1 nm output rounding hides that except at exact
/// rounding ties.)
const GOLDEN: &str = "0ad4a2a2bf1965f4fdf89eec1a8005d795e2b0c4e3cb9ee05d32fabe3395df1a";

#[test]
fn two_thermal_effects_share_one_sensor() {
    let d = simulate::simulate(&perfect(
        &["line:x:100,runs=3"],
        &[
            "thermal:channel=bed,rise_c=2,tau_s=300",
            // Spindle growth in z from the same sensor; its own trajectory
            // keys are ignored because `bed` is already defined.
            "thermal:channel=bed,target=ez,times=none,cte_um_per_m_k=0,offset_um_per_k=-1.5,rise_c=9",
        ],
    ));
    assert_eq!(d.temps.len(), 1);
    let temp = &d.temp("bed").unwrap().temp_c;
    let (ex, ez) = (col(&d, 0), col(&d, 2));
    for r in 0..d.len() {
        let dt = temp[r] - 20.0;
        assert!((ex[r] - 11.5e-3 * dt * d.pos(0, r)).abs() < RES);
        assert!((ez[r] - -1.5 * dt).abs() < RES);
    }
    assert!(*temp.last().unwrap() < 22.0, "the first effect's 2 K rise");
}

/// Every number `simulate` takes is checked before anything is written:
/// not finite, or outside a physically sensible range → exit 1 with the
/// option's name and the range, and no file (a NaN tool length used to
/// write a file of NaN errors that `import` then refused; 1e300 mm wrote
/// errors of 2e300 µm).
#[test]
fn every_numeric_option_is_validated() {
    let out_csv = tmp("bad-number.csv");
    let _ = std::fs::remove_file(&out_csv);
    let o = out_csv.to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (
            &["--tool-mm", "nan"],
            "--tool-mm = NaN: expected a finite value",
        ),
        (&["--tool-mm", "1e300"], "--tool-mm = 1e300"),
        (&["--tool-mm=-inf"], "--tool-mm = -inf"),
        (&["--noise-um", "nan"], "--noise-um = NaN"),
        (
            &["--noise-um=-0.1"],
            "--noise-um = -0.1: expected a finite value ≥ 0 µm",
        ),
        (
            &["--noise-um", "1e9"],
            "--noise-um = 1000000000.0: expected a finite value ≥ 0 µm and ≤ 100 µm",
        ),
        (
            &["--feed-mm-s", "0"],
            "--feed-mm-s = 0.0: expected a finite value > 0 mm/s",
        ),
        (&["--feed-mm-s", "inf"], "--feed-mm-s = inf"),
        (&["--dwell-s", "nan"], "--dwell-s = NaN"),
        (&["--dwell-s=-1"], "--dwell-s = -1.0"),
        (
            &["--effect", "periodic:axis=x,period_mm=5,amp_um=1e300"],
            "effect `periodic`: amp_um = 1e300",
        ),
        (
            &["--effect", "thermal:channel=bed,cte_um_per_m_k=1e9"],
            "cte_um_per_m_k = 1000000000.0",
        ),
        (
            &["--effect", "thermal:channel=bed,start_c=-300"],
            "start_c = -300.0: expected a finite value ≥ -50 °C and ≤ 100 °C",
        ),
        (
            &["--effect", "reversal:axis=x,backlash_um=5e6"],
            "backlash_um = 5000000.0",
        ),
        (
            &["--effect", "abbe:angle_urad=48.5,tools_mm=0/1e9"],
            "tools_mm = 1000000000.0",
        ),
        (&["--effect", "drift:um_per_h=1e200"], "um_per_h = 1e200"),
    ];
    for (extra, needle) in cases {
        let mut args = vec!["simulate", "--plan", "grid:100", "-o", o];
        args.extend_from_slice(extra);
        let out = run(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {err}");
        assert!(
            err.contains(needle),
            "{extra:?}: expected `{needle}` in {err}"
        );
        assert!(!out_csv.exists(), "{extra:?}: a file was written");
    }
    // A pause far beyond any measurement campaign.
    let out = run(&["simulate", "--plan", "grid:100", "pause:1e300", "-o", o]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("plan `pause`: duration = 1e300"));
    // From Rust too: check() refuses what the CLI refuses, in its own
    // words (the field), which the CLI says with the flag.
    let mut cfg = SimConfig::preset("mill800").unwrap();
    cfg.plans = vec!["grid:100".parse().unwrap()];
    cfg.tool_mm = f64::NAN;
    let e = cfg.check().unwrap_err();
    assert!(
        matches!(
            e.downcast_ref::<ConfigError>(),
            Some(ConfigError::Setting {
                setting: Setting::ToolMm,
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().starts_with("tool_mm = NaN"), "{e}");
    assert!(trueaxis::cmd::flags::render(&e).starts_with("--tool-mm = NaN"));
    cfg.tool_mm = 100.0;
    cfg.check().unwrap();
    // The edges of the ranges are allowed.
    let out = run(&[
        "simulate",
        "--plan",
        "line:x:100",
        "--tool-mm=-1000",
        "--noise-um",
        "0",
        "-o",
        o,
    ]);
    assert_success(&out);
    let _ = std::fs::remove_file(&out_csv);
}

/// `bidir` directly (not only through a golden hash): every line is run
/// forward, then backward, as two passes; positions ascend then descend;
/// the backward pass approaches from above (dir −1) except its first
/// reading, taken where the forward pass stopped (still approached from
/// below — the reason ISO 230-2 plans overrun the end targets).
#[test]
fn bidir_runs_each_line_forward_then_backward() {
    let d = simulate::simulate(&perfect(&["line:x:200,bidir"], &[]));
    let x = d.pos_mm[0].as_ref().unwrap();
    let dir = d.dir[0].as_ref().unwrap();
    let pass = d.pass_id.as_ref().unwrap();
    assert_eq!(
        x,
        &vec![0.0, 200.0, 400.0, 600.0, 800.0, 800.0, 600.0, 400.0, 200.0, 0.0]
    );
    assert_eq!(pass, &vec![0, 0, 0, 0, 0, 1, 1, 1, 1, 1]);
    assert_eq!(dir, &vec![1, 1, 1, 1, 1, 1, -1, -1, -1, -1]);
    // The other axes sit still at mid-travel, and time runs on.
    assert!(d.pos_mm[1].as_ref().unwrap().iter().all(|&y| y == 250.0));
    let t = d.t_s.as_ref().unwrap();
    assert!(t.windows(2).all(|w| w[1] > w[0]), "{t:?}");
    // A plane with bidir (x 0, 400, 800 on the lines y = 0 and 400): each
    // line both ways, 2 passes per line.
    let d = simulate::simulate(&perfect(&["plane:xy:400,bidir"], &[]));
    assert_eq!(d.len(), 3 * 2 * 2);
    let pass = d.pass_id.as_ref().unwrap();
    assert_eq!(pass.iter().max(), Some(&3));
    let dir = d.dir[0].as_ref().unwrap();
    for p in 0..4i64 {
        let rows: Vec<usize> = (0..d.len()).filter(|&r| pass[r] == p).collect();
        let xs: Vec<f64> = rows.iter().map(|&r| d.pos(0, r)).collect();
        if p % 2 == 0 {
            assert_eq!(xs, [0.0, 400.0, 800.0], "pass {p}");
        } else {
            assert_eq!(xs, [800.0, 400.0, 0.0], "pass {p}");
            assert_eq!(dir[rows[1]], -1);
            assert_eq!(dir[rows[2]], -1);
        }
    }
}

/// Returns to a reference point directly: before the first pass, after
/// every N passes and at the end, each a pass of its own at exactly the
/// reference position, approached the way the machine came.
#[test]
fn reference_point_rows_where_and_when_expected() {
    let mut cfg = perfect(&["line:x:400,runs=3"], &[]);
    cfg.reference = Some(RefReturn {
        pos_mm: [0.0, 0.0, 0.0],
        every_passes: 2,
    });
    cfg.check().unwrap();
    let d = simulate::simulate(&cfg);
    let at_ref: Vec<usize> = (0..d.len())
        .filter(|&r| (0..3).all(|a| d.pos(a, r) == 0.0))
        .collect();
    // 3 lines of 3 points; the reference before line 1, after line 2
    // (every 2 passes) and at the end.
    assert_eq!(d.len(), 9 + 3);
    assert_eq!(at_ref, vec![0, 7, 11]);
    let pass = d.pass_id.as_ref().unwrap();
    assert_eq!(pass, &vec![0, 1, 1, 1, 2, 2, 2, 3, 4, 4, 4, 5]);
    // Each reference visit is its own pass: no line row shares its id.
    for &r in &at_ref {
        assert_eq!(pass.iter().filter(|&&p| p == pass[r]).count(), 1);
    }
    // Coming down from (800, 250, 250) every axis approaches from above.
    for a in 0..3 {
        assert_eq!(d.dir[a].as_ref().unwrap()[7], -1);
        assert_eq!(d.dir[a].as_ref().unwrap()[0], 1, "the start counts as +1");
    }
    let t = d.t_s.as_ref().unwrap();
    assert!(t.windows(2).all(|w| w[1] > w[0]));
}
