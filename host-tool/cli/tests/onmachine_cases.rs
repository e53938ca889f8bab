//! On-machine measurement on cases made independently of the campaign
//! (issue 27; engine `onmachine::simulate::cases`, fixed seeds): the
//! spindle's ISO 230-7 error motion the same from three probes and from
//! the multi-step method at 360, 512 and 1024 samples per turn and 5, 7 and
//! 8 steps, within 10 % of the truth and inside both intervals; no
//! estimate whose interval misses the truth because a sum was claimed as a
//! part; outlier contacts named by their line; nothing refused that a
//! spindle analyser or a probing cycle writes (time-sampled logs with an
//! index pulse, encoder counts, a speed, clock times, touch-trigger
//! positions, probes on rows of their own, campaign files without
//! `session_id`).

mod common;

use std::path::Path;

use common::onmachine::pv_line_removed;
use common::{json, run, s, tmp_dir};
use serde_json::Value;
use trueaxis_engine::onmachine::probe;
use trueaxis_engine::onmachine::simulate::cases::{at, BallCase, PartArc, SpindleCase};

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn harmonics(v: &Value) -> Vec<usize> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_u64().unwrap() as usize)
        .collect()
}

/// `[lo, hi]` holds `want`.
fn holds(ci: &Value, want: f64) -> bool {
    f(&ci[0]) <= want && want <= f(&ci[1])
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

fn spindle(samples: usize, steps: usize, turns: usize, part_lobe: usize) -> SpindleCase {
    SpindleCase {
        samples,
        turns,
        steps,
        probe_angles_deg: [0.0, 99.84, 202.5],
        // A 3-lobe part with the lobe the steps cannot separate.
        part: vec![(3, 1.5, 0.2), (part_lobe, 0.6, 1.0), (11, 0.3, 0.5)],
        spindle_x: vec![(2, 0.5, 0.3), (3, 0.25, 1.2), (4, 0.2, 0.0), (9, 0.08, 2.0)],
        spindle_y: vec![(2, 0.4, 1.8), (3, 0.2, 0.1), (6, 0.1, 0.0)],
        centring_um: 3.0,
        async_um: 0.03,
        noise_um: 0.01,
    }
}

#[test]
fn three_probes_and_the_multi_step_method_give_the_same_error_motion() {
    let dir = tmp_dir("cases", "error-motion");
    for (samples, steps, turns, lobe) in [(360, 5, 8, 5), (512, 7, 8, 7), (1024, 8, 4, 8)] {
        let c = spindle(samples, steps, turns, lobe);
        let tag = format!("{samples}x{steps}");
        let three = write(&dir, &format!("three-{tag}.csv"), &c.three_probe_csv(11));
        let multi = write(&dir, &format!("multi-{tag}.csv"), &c.multi_step_csv(12));
        let t = json(&run(&[
            "separate",
            "three-probe",
            &three,
            "--angles-deg",
            "0,99.84,202.5",
            "-o",
            &write(&dir, &format!("t-{tag}.out"), ""),
            "--json",
        ]));
        let m = json(&run(&[
            "separate",
            "multi-step",
            &multi,
            "-o",
            &write(&dir, &format!("m-{tag}.out"), ""),
            "--json",
        ]));
        assert_eq!(t["samples"], samples, "{t}");
        assert_eq!(m["samples"], samples, "{m}");
        assert_eq!(m["steps"], steps, "{m}");
        let truth = c.error_motion_um(&[]);
        let (te, me) = (&t["error_motion"], &m["error_motion"]);
        let (tv, mv) = (f(&te["synchronous_um"]), f(&me["synchronous_um"]));
        eprintln!(
            "{tag}: error motion three-probe {tv:.4} {}, multi-step {mv:.4} {}, truth {truth:.4}",
            te["synchronous_ci95_um"], me["synchronous_ci95_um"]
        );
        for (name, e, v) in [("three-probe", te, tv), ("multi-step", me, mv)] {
            assert!(
                (v - truth).abs() < 0.1 * truth,
                "{tag} {name}: {v} vs {truth}"
            );
            assert!(holds(&e["synchronous_ci95_um"], truth), "{tag} {name}: {e}");
            assert!(
                f(&e["total_um"]) >= v && f(&e["asynchronous_um"]) > 0.0,
                "{e}"
            );
        }
        let (a, b) = (&te["synchronous_ci95_um"], &me["synchronous_ci95_um"]);
        assert!(f(&a[0]) <= f(&b[1]) && f(&b[0]) <= f(&a[1]), "{a} {b}");
        // The part's centring (3 µm, once per turn) is not error motion:
        // reported apart.
        assert!((f(&te["centring_um"]) - 3.0).abs() < 0.05, "{te}");
        // The part: each method claims what it separates, its interval
        // holding that; the multi-step's lobe at a multiple of the steps
        // given as part + spindle together (the spindle has none there).
        let unseen = harmonics(&t["unseen_harmonics"]);
        let insep = harmonics(&m["inseparable_harmonics"]);
        assert!(insep.contains(&lobe), "{insep:?}");
        let tp = c.part_pv_um(&unseen);
        let mp = c.part_pv_um(&insep);
        eprintln!(
            "{tag}: part three-probe {} {}, vs {tp:.4}; multi-step {} {} vs {mp:.4}; sum at {lobe}: {}",
            t["part_pv_um"], t["part_ci95_um"], m["part_pv_um"], m["part_ci95_um"], me["excluded_pv_um"]
        );
        assert!(holds(&t["part_ci95_um"], tp), "{tag}: {t}");
        assert!(holds(&m["part_ci95_um"], mp), "{tag}: {m}");
        assert!((f(&me["excluded_pv_um"]) - 1.2).abs() < 0.05, "{me}");
    }
}

#[test]
fn a_time_sampled_log_with_an_index_pulse_gives_the_same_error_motion() {
    let dir = tmp_dir("cases", "log");
    let c = spindle(512, 5, 10, 5);
    // 600 rev/min sampled at 5123 Hz: 512.3 samples a turn, the speed
    // wandering ±1 % — no angle read twice.
    let log = write(&dir, "log.csv", &c.three_probe_log(600.0, 5123.0, 21));
    let t = json(&run(&[
        "separate",
        "three-probe",
        &log,
        "--angles-deg",
        "0,99.84,202.5",
        "-o",
        &write(&dir, "t.out", ""),
        "--json",
    ]));
    assert_eq!(t["angle_from"], "index", "{t}");
    let truth = c.error_motion_um(&[]);
    let e = &t["error_motion"];
    eprintln!(
        "log: {} {} vs {truth}",
        e["synchronous_um"], e["synchronous_ci95_um"]
    );
    assert!((f(&e["synchronous_um"]) - truth).abs() < 0.1 * truth, "{e}");
    assert!(holds(&e["synchronous_ci95_um"], truth), "{e}");
    // The same log with clock times instead of seconds.
    let text = std::fs::read_to_string(&log).unwrap();
    let clock: String = text
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                format!("{l}\n")
            } else if let Some(rest) = l.strip_prefix("t_s,") {
                format!("time,{rest}\n")
            } else {
                let (ts, rest) = l.split_once(',').unwrap();
                let sec: f64 = ts.parse().unwrap();
                format!("2024-03-05T10:00:{:09.6}Z,{rest}\n", sec)
            }
        })
        .collect();
    let t2 = json(&run(&[
        "separate",
        "three-probe",
        &write(&dir, "clock.csv", &clock),
        "--angles-deg",
        "0,99.84,202.5",
        "-o",
        &write(&dir, "t2.out", ""),
        "--json",
    ]));
    assert!(
        (f(&t2["error_motion"]["synchronous_um"]) - f(&e["synchronous_um"])).abs() < 0.01,
        "{t2}"
    );
}

#[test]
fn nothing_a_spindle_analyser_writes_is_refused() {
    let dir = tmp_dir("cases", "formats");
    let c = spindle(1024, 7, 3, 7);
    let text = c.three_probe_csv(31);
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect();
    // Encoder counts (1024 a turn), then the same with each probe on rows
    // of its own, then a speed and time stamps only.
    let mut enc = String::from("encoder,p1_um,p2_um,p3_um\n");
    let mut sparse = String::from("c_deg,p1_um,p2_um,p3_um\n");
    let mut speed = String::from("t_s,rpm,p1_um,p2_um,p3_um\n");
    for (i, r) in rows.iter().enumerate() {
        let (c_deg, rest) = r.split_once(',').unwrap();
        enc.push_str(&format!("{i},{rest}\n"));
        let p: Vec<&str> = rest.split(',').collect();
        for (k, v) in p.iter().enumerate() {
            let mut cells = [""; 3];
            cells[k] = v;
            sparse.push_str(&format!("{c_deg},{}\n", cells.join(",")));
        }
        // 60 rev/min: a turn a second.
        speed.push_str(&format!("{},60,{rest}\n", i as f64 / 1024.0));
    }
    let truth = c.error_motion_um(&[]);
    for (name, text, extra) in [
        ("enc.csv", enc, vec!["--counts-per-turn", "1024"]),
        ("sparse.csv", sparse, vec![]),
        ("speed.csv", speed, vec![]),
    ] {
        let path = write(&dir, name, &text);
        let mut args = vec![
            "separate",
            "three-probe",
            &path,
            "--angles-deg",
            "0,99.84,202.5",
            "--json",
        ];
        let out = write(&dir, &format!("{name}.out"), "");
        args.extend(["-o", &out]);
        args.extend(extra.iter());
        let t = json(&run(&args));
        let v = f(&t["error_motion"]["synchronous_um"]);
        assert!((v - truth).abs() < 0.1 * truth, "{name}: {v} vs {truth}");
    }
    // Encoder counts without the counts per turn: the flag named.
    let e = run(&[
        "separate",
        "three-probe",
        &write(&dir, "enc2.csv", "encoder,p1_um,p2_um,p3_um\n0,1,2,3\n"),
        "--angles-deg",
        "0,99.84,202.5",
        "-o",
        &write(&dir, "e.out", ""),
    ]);
    assert!(String::from_utf8_lossy(&e.stderr).contains("--counts-per-turn"));
    // 7 steps of 1024 samples (a step not a whole number of samples).
    let m = json(&run(&[
        "separate",
        "multi-step",
        &write(&dir, "m7.csv", &c.multi_step_csv(32)),
        "-o",
        &write(&dir, "m7.out", ""),
        "--json",
    ]));
    assert_eq!(m["steps"], 7);
    assert!(
        (f(&m["error_motion"]["synchronous_um"]) - truth).abs() < 0.1 * truth,
        "{m}"
    );
}

/// The radius and form of `ball`'s probe in the calibration's convention
/// over XZ contact angles `theta`: the true radius plus the mean of the
/// form's part on `1, cos θ, sin θ`.
fn radius_in_convention(ball: &BallCase, theta: &[f64]) -> f64 {
    // Least squares on 1, cos θ, sin θ by the normal equations (Cramer).
    let cols = |t: f64| [1.0, t.cos(), t.sin()];
    let (mut m, mut b) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
    for &t in theta {
        let (c, y) = (cols(t), ball.form_nm([t.cos(), 0.0, t.sin()]));
        for i in 0..3 {
            b[i] += c[i] * y;
            for j in 0..3 {
                m[i][j] += c[i] * c[j];
            }
        }
    }
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let mut m0 = m;
    for i in 0..3 {
        m0[i][0] = b[i];
    }
    ball.probe_radius_mm + det(m0) / det(m) * 1e-6
}

#[test]
fn balls_and_probes_of_other_sizes_name_their_outliers_by_line() {
    let dir = tmp_dir("cases", "balls");
    for (k, (ball_d, probe_r, quantum)) in [(25.4, 1.0, 0.0), (6.0, 0.25, 0.0), (12.7, 1.5, 1e-4)]
        .into_iter()
        .enumerate()
    {
        let ball = BallCase {
            ball_diameter_mm: ball_d,
            probe_radius_mm: probe_r,
            // A kinematic probe: 3-lobe pre-travel and its 6-lobe overtone.
            lobes: vec![(3, 80.0, 0.3), (6, 20.0, 1.0)],
            polar_nm: 15.0,
            noise_nm: 4.0,
            outliers: vec![(60, 380.0), (250, -240.0)],
            quantum_mm: quantum,
        };
        let arc = write(
            &dir,
            &format!("arc{k}.csv"),
            &ball.arc_csv(10.0, 170.0, 401, 40 + k as u64),
        );
        let cal = json(&run(&[
            "probe",
            "calibrate",
            &arc,
            "--ball-diameter-mm",
            &ball_d.to_string(),
            "-o",
            &write(&dir, &format!("p{k}.json"), ""),
            "--json",
        ]));
        // Rows 60 and 250 are lines 63 and 253 (a comment, the header).
        let o = &cal["outliers"];
        assert_eq!(o.as_array().unwrap().len(), 2, "{cal}");
        assert_eq!(
            (o[0]["line"].as_u64(), o[1]["line"].as_u64()),
            (Some(63), Some(253)),
            "{o}"
        );
        // Their size, within the noise and the rounding of the coordinates
        // (±½ quantum in each of two).
        let tol = 30.0 + 0.71 * quantum * 1e6;
        assert!((f(&o[0]["residual_nm"]) - 380.0).abs() < tol, "{o}");
        assert!((f(&o[1]["residual_nm"]) + 240.0).abs() < tol, "{o}");
        assert!(
            cal["warnings"].to_string().contains("line 63"),
            "{}",
            cal["warnings"]
        );
        let theta: Vec<f64> = (0..401)
            .map(|i| (10.0 + 0.4 * i as f64).to_radians())
            .collect();
        let r = radius_in_convention(&ball, &theta);
        let p = &cal["probe"];
        let (got, ci) = (f(&p["probe_radius_mm"]), f(&p["probe_radius_ci95_mm"]));
        eprintln!(
            "ball {ball_d}/{probe_r}: radius {got} ± {ci} vs {r}; order {}",
            p["order"]
        );
        assert!((got - r).abs() <= ci.max(2e-6), "{got} ± {ci} vs {r}");
        if quantum > 0.0 {
            assert_eq!(f(&p["quantum_mm"]), quantum);
            assert!(ci >= quantum, "{ci}");
        } else {
            assert!(p.get("quantum_mm").is_none(), "{p}");
        }
        // In 3-D over the ball: the same outliers named.
        let sph = write(
            &dir,
            &format!("sph{k}.csv"),
            &ball.sphere_csv(85.0, 50 + k as u64),
        );
        let cal3 = json(&run(&[
            "probe",
            "calibrate",
            &sph,
            "--ball-diameter-mm",
            &ball_d.to_string(),
            "--plane",
            "xyz",
            "-o",
            &write(&dir, &format!("p3{k}.json"), ""),
            "--json",
        ]));
        let lines: Vec<u64> = cal3["outliers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o["line"].as_u64().unwrap())
            .collect();
        assert_eq!(lines, vec![63, 253], "{}", cal3["outliers"]);
    }
}

/// Deviation PV of points from their least-squares circle, nm.
fn circle_pv(p: &[[f64; 2]]) -> f64 {
    trueaxis_engine::onmachine::separate::pv(&probe::form_deviation_nm(p, true).unwrap())
}

#[test]
fn an_arc_with_the_probe_says_part_plus_slides_as_a_sum_that_holds_the_truth() {
    let dir = tmp_dir("cases", "arc");
    let ball = BallCase {
        ball_diameter_mm: 8.0,
        probe_radius_mm: 0.75,
        lobes: vec![(3, 60.0, 0.0)],
        polar_nm: 0.0,
        noise_nm: 3.0,
        outliers: vec![],
        quantum_mm: 0.0,
    };
    let probe = dir.join("probe.json");
    json(&run(&[
        "probe",
        "calibrate",
        &write(&dir, "ball.csv", &ball.arc_csv(5.0, 175.0, 501, 61)),
        "--ball-diameter-mm",
        "8",
        "-o",
        s(&probe),
        "--json",
    ]));
    let part = PartArc {
        radius_mm: 40.0,
        lobes: vec![(5, 120.0, 0.4)],
        outside: true,
        arc_deg: [30.0, 150.0],
        points: 401,
        slide_nm: 90.0,
    };
    let (scan, seen) = part.scan(&ball, 62);
    let d = json(&run(&[
        "diagnose-part",
        &write(&dir, "part.csv", &scan),
        "--probe",
        s(&probe),
        "--json",
    ]));
    let part_form = common::find_in(&d["findings"], |f| f["source"] == "part_form");
    assert_eq!(part_form["status"], "cannot_know", "{part_form}");
    let sum = &d["combined"][0];
    assert_eq!(
        sum["sources"],
        serde_json::json!(["part_form", "slide_straightness"])
    );
    let truth = circle_pv(&seen);
    let part_alone: Vec<[f64; 2]> = (0..=400)
        .map(|i| {
            let t = (30.0 + 0.3 * i as f64).to_radians();
            let r = 40.0 + at(&part.lobes, t, &[]) * 1e-6;
            [r * t.cos(), r * t.sin()]
        })
        .collect();
    eprintln!(
        "arc: sum {} {} vs {truth:.1}; the part alone {:.1}",
        sum["pv"],
        sum["ci95"],
        circle_pv(&part_alone)
    );
    assert!(holds(&sum["ci95"], truth), "{sum}");
    assert!((f(&sum["pv"]) - truth).abs() < 0.1 * truth, "{sum}");
    // The part alone is not what this sum holds: claiming it as the part
    // would have been wrong (the slide is 90 nm).
    assert!(!holds(&sum["ci95"], circle_pv(&part_alone)), "{sum}");

    // A full bore probed from inside: normals along the radii, the form
    // from a probe file of the same stylus (no slides here).
    let bore = PartArc {
        radius_mm: 15.0,
        lobes: vec![(3, 150.0, 0.0), (7, 60.0, 1.0)],
        outside: false,
        arc_deg: [0.0, 360.0],
        points: 720,
        slide_nm: 0.0,
    };
    let full = BallCase {
        lobes: vec![],
        ..ball.clone()
    };
    let probe0 = dir.join("round.json");
    json(&run(&[
        "probe",
        "calibrate",
        &write(&dir, "ball0.csv", &full.arc_csv(5.0, 175.0, 501, 63)),
        "--ball-diameter-mm",
        "8",
        "-o",
        s(&probe0),
        "--json",
    ]));
    let (scan, seen) = bore.scan(&full, 64);
    let c = json(&run(&[
        "probe",
        "correct",
        &write(&dir, "bore.csv", &scan),
        "--probe",
        s(&probe0),
        "--side",
        "in",
        "-o",
        &write(&dir, "bore.out", ""),
        "--json",
    ]));
    assert_eq!(c["normals"], "circle");
    let truth = circle_pv(&seen);
    assert!(
        (f(&c["form_pv_nm"]) - truth).abs() < 0.1 * truth,
        "{c} vs {truth}"
    );
}

#[test]
fn touch_trigger_positions_campaign_columns_and_clock_times_are_read() {
    let dir = tmp_dir("cases", "touch");
    // A reversal by a touch-trigger probe: z where it touched, along x.
    let part = |x: f64| 1.2 * (x / 40.0).sin();
    let slide = |x: f64| 0.8 * (x / 25.0 + 1.0).cos();
    let (mut r0, mut r180) = (String::from("x_mm,z_mm\n"), String::from("x_mm,z_mm\n"));
    for i in 0..=100 {
        let x = 2.0 * i as f64;
        // Touched from above (the surface faces +z), then from below.
        r0.push_str(&format!("{x},{:.6}\n", 50.0 + (part(x) + slide(x)) * 1e-3));
        r180.push_str(&format!("{x},{:.6}\n", 30.0 - (part(x) - slide(x)) * 1e-3));
    }
    let rev = json(&run(&[
        "separate",
        "reversal",
        &write(&dir, "r0.csv", &r0),
        &write(&dir, "r180.csv", &r180),
        "--side",
        "+z",
        "-o",
        &write(&dir, "rev.out", ""),
        "--json",
    ]));
    let xs: Vec<f64> = (0..=200).map(|i| i as f64).collect();
    let pv = |g: &dyn Fn(f64) -> f64| pv_line_removed(&xs, g);
    assert!(
        (f(&rev["part_pv_um"]) - pv(&part)).abs() < 0.02,
        "{rev} vs {}",
        pv(&part)
    );
    assert!((f(&rev["slide_pv_um"]) - pv(&slide)).abs() < 0.02, "{rev}");

    // A campaign file of ball contacts only: no `d_um`, recognised by its
    // columns; without `session_id` it is one session.
    let ball = BallCase {
        ball_diameter_mm: 4.0,
        probe_radius_mm: 0.5,
        lobes: vec![(3, 50.0, 0.0)],
        polar_nm: 0.0,
        noise_nm: 4.0,
        outliers: vec![],
        quantum_mm: 0.0,
    };
    let arc = ball.arc_csv(10.0, 170.0, 201, 70);
    let mut camp = String::from("session_id,x_mm,z_mm,probe_id\n");
    let mut single = String::from("probe_id,x_mm,z_mm\n");
    for l in arc.lines().filter(|l| !l.starts_with('#')).skip(1) {
        camp.push_str(&format!("4,{l},T2\n"));
        single.push_str(&format!("T2,{l}\n"));
    }
    let small = json(&run(&[
        "probe",
        "calibrate",
        &write(&dir, "arc.csv", &arc),
        "--ball-diameter-mm",
        "4",
        "-o",
        &write(&dir, "a.json", ""),
        "--json",
    ]));
    for (name, text, session) in [("camp.csv", camp, Some("4")), ("single.csv", single, None)] {
        let path = write(&dir, name, &text);
        let mut args = vec![
            "probe",
            "calibrate",
            &path,
            "--ball-diameter-mm",
            "4",
            "--json",
        ];
        let out = write(&dir, &format!("{name}.json"), "");
        args.extend(["-o", &out]);
        if let Some(sn) = session {
            args.extend(["--session", sn]);
        }
        let c = json(&run(&args));
        assert_eq!(c["probe"], small["probe"], "{name}");
    }

    // A timed roundness turn with clock times: the drift as with `t_s`.
    let mut timed = String::from("c_deg,p_um,time\n");
    for i in 0..=360 {
        let t = (i as f64).to_radians();
        let v = 2.0 * (3.0 * t).cos() + 0.05 * (2 * i) as f64 / 60.0;
        // From 23:55:00, 2 s a degree: past midnight.
        let sec = (23 * 3600 + 55 * 60 + 2 * i) % 86_400;
        timed.push_str(&format!(
            "{i},{v:.4},{:02}:{:02}:{:02}\n",
            sec / 3600,
            sec / 60 % 60,
            sec % 60
        ));
    }
    let d = json(&run(&[
        "diagnose-part",
        &write(&dir, "timed.csv", &timed),
        "--json",
    ]));
    let drift = d["findings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["source"] == "thermal_drift")
        .unwrap();
    assert_eq!(drift["status"], "estimated", "{drift}");
    assert!((f(&drift["value"]) - 0.05).abs() < 0.005, "{drift}");
}
