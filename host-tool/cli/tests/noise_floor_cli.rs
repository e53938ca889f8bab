//! The noise floor of a coarse bed map (issue 12, stop 18): on a real
//! RepRapFirmware 9 × 9 map (25 mm grid) the floor came from third
//! differences of the bed's own shape and was taken as probe noise. Here a
//! synthetic map of the same layout — a wavy bed of ±60 µm, 1.5 µm probe
//! noise from a fixed seed, heights written to the file's 1 µm — must get
//! a floor that says it is an upper bound, and what to re-probe.

mod common;

use common::{json, run, s, tmp_dir};
use trueaxis_test_support::SplitMix64;

/// A RepRapFirmware v2 height map, 9 × 9 nodes 25 mm apart from (25, 10):
/// 60·sin(2πx/160)·cos(2πy/220) µm plus a tilt — waves of 160–220 mm, smooth
/// to the eye but not over the 4–6 nodes a difference spans — and
/// N(0, `noise_um`²) per node.
fn wavy_map(noise_um: f64, seed: u64) -> String {
    let mut rng = SplitMix64::new(seed);
    let mut s = String::from(
        "RepRapFirmware height map file v2 generated at 2026-11-26 10:00, min error -0.1, max error 0.1, mean 0, deviation 0.05\n\
         xmin,xmax,ymin,ymax,radius,xspacing,yspacing,xnum,ynum\n\
         25.00,225.00,10.00,210.00,-1.00,25.00,25.00,9,9\n",
    );
    for j in 0..9 {
        let y = 10.0 + 25.0 * f64::from(j);
        let row: Vec<String> = (0..9)
            .map(|i| {
                let x = 25.0 + 25.0 * f64::from(i);
                let shape = 60.0
                    * (std::f64::consts::TAU * x / 160.0).sin()
                    * (std::f64::consts::TAU * y / 220.0).cos()
                    + 0.1 * x;
                let um = shape + noise_um * rng.normal();
                // Height in mm (the map's sign is the error's opposite; the
                // floor does not care).
                format!("{:7.3}", um / 1000.0)
            })
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

#[test]
fn a_coarse_wavy_bed_map_gets_an_upper_bound_and_what_to_reprobe() {
    let dir = tmp_dir("noise-floor", "rrf");
    let map = common::file_in(&dir, "heightmap.csv", wavy_map(1.5, 18));
    let d = json(&run(&["diagnose", s(&map), "--model", "cubic19", "--json"]));
    assert_eq!(d["noise_method"]["ez"], "sparse_differences", "{d}");
    // An upper bound of 1.5 µm of noise: not below it, and far below the
    // third differences of the shape that main reported (≈ 8 µm here).
    let nf = d["noise_floor_um"]["ez"].as_f64().unwrap();
    assert!((1.0..4.0).contains(&nf), "floor {nf}");
    let w = common::find_warning(&d, "noise_floor_upper_bound")
        .unwrap_or_else(|| panic!("no noise_floor_upper_bound warning: {d}"));
    let detail = w["detail"].as_str().unwrap();
    assert!(
        detail.starts_with("ez: the noise floor is an upper bound")
            && detail.contains("re-probe 20 of its 81 points (or repeat the whole map)"),
        "{detail}"
    );
    // The text says it too.
    let out = run(&["diagnose", s(&map), "--model", "cubic19"]);
    common::assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("the noise floor is an upper bound"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Repeating the map within minutes turns the bound into a measurement:
/// the same wavy bed probed twice (fresh noise) gives `repeats`, the
/// probe's own 1.5 µm.
#[test]
fn a_repeated_map_measures_the_noise() {
    let dir = tmp_dir("noise-floor", "rrf-twice");
    let (a, b) = (dir.join("a.csv"), dir.join("b.csv"));
    std::fs::write(&a, wavy_map(1.5, 18)).unwrap();
    std::fs::write(&b, wavy_map(1.5, 19)).unwrap();
    let (ca, cb) = (dir.join("a_ez.csv"), dir.join("b_ez.csv"));
    for (src, dst) in [(&a, &ca), (&b, &cb)] {
        common::assert_success(&run(&["import", s(src), "-o", s(dst)]));
    }
    // One CSV of both runs (the second's header dropped).
    let both = dir.join("both.csv");
    let first = std::fs::read_to_string(&ca).unwrap();
    let second = std::fs::read_to_string(&cb).unwrap();
    let body: Vec<&str> = second
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect();
    std::fs::write(&both, format!("{}{}\n", first, body.join("\n"))).unwrap();
    let d = json(&run(&[
        "diagnose",
        s(&both),
        "--model",
        "cubic19",
        "--json",
    ]));
    assert_eq!(d["noise_method"]["ez"], "repeats", "{d}");
    let nf = d["noise_floor_um"]["ez"].as_f64().unwrap();
    assert!((0.7 * 1.5..1.4 * 1.5).contains(&nf), "floor {nf}");
    assert!(
        common::find_warning(&d, "noise_floor_upper_bound").is_none(),
        "{d}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
