//! Fixtures of the export tests (`export_cli.rs`, `export_controllers_cli.rs`):
//! the hand-made x line and its formula, a warming-bed line, fitted models,
//! the host model's prediction, and independent readers of the files
//! (CRC-32, LinuxCNC's comp file).

use std::path::{Path, PathBuf};

use serde_json::Value;
use trueaxis_engine::data::{Dataset, TempChannel};
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

use super::{fit, golden_file, grid_cubic19, CUBIC19_REVERSAL_X};

pub fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// CRC-32 (IEEE 802.3, reflected 0xEDB88320, as zlib), bit by bit — an
/// implementation independent of the `crc` crate model-core uses.
pub fn crc32_ieee(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// The preset mill on a 100 mm grid (324 points, ex ey ez), seed 7, fitted
/// with cubic19. Returns (data, model).
pub fn grid_model(dir: &Path) -> (PathBuf, PathBuf) {
    let (csv, model, _) = grid_cubic19(dir, "grid", 7);
    (csv, model)
}

/// The checked-in hand-made x line (tests/golden/line_x.csv).
pub fn line_csv() -> PathBuf {
    golden_file("line_x.csv")
}

/// The error the hand-made line was generated from, µm (see its header).
pub fn line_truth_um(x_mm: f64, dir: f64) -> f64 {
    1.3137 + 0.0213457 * x_mm - 3.1e-4 * x_mm * x_mm + 7.7e-7 * x_mm * x_mm * x_mm + 2.4 * dir
}

/// cubic19 + reversal fitted to the hand-made line (ex over x only).
pub fn line_model(dir: &Path) -> PathBuf {
    let model = dir.join("line.model.json");
    let v = fit(&line_csv(), CUBIC19_REVERSAL_X, &model);
    assert_eq!(v["terms"], 5, "1, x, x², x³ and dir_x: {v}");
    model
}

/// A hand-made x line with a warming bed: ex = cubic(x) + reversal +
/// 0.0115 µm/(K·mm)·(T_bed − 20)·x + 0.5 µm/h drift, 6 bidirectional runs
/// of 21 points, 4 s per point. Deterministic pseudo-noise ±0.02 µm.
pub fn thermal_csv(dir: &Path) -> PathBuf {
    let (mut x, mut ex, mut t, mut d, mut temp) = (vec![], vec![], vec![], vec![], vec![]);
    let mut row = 0usize;
    for run in 0..12 {
        let dir_x: i8 = if run % 2 == 0 { 1 } else { -1 };
        for i in 0..=20 {
            let p = if dir_x > 0 { i * 10 } else { 200 - i * 10 } as f64;
            let t_s = 4.0 * row as f64;
            let bed = 20.0 + 4.0 * (1.0 - (-t_s / 1800.0).exp());
            let noise = ((row * 7919) % 41) as f64 / 1000.0 - 0.02;
            let e = line_truth_um(p, f64::from(dir_x)) - 2.4 * f64::from(dir_x)
                + 1.5 * f64::from(dir_x)
                + 0.0115 * (bed - 20.0) * p
                + 0.5 * t_s / 3600.0
                + noise;
            x.push(p);
            ex.push(Some((e * 1e4).round() / 1e4));
            t.push(t_s);
            d.push(dir_x);
            temp.push((bed * 1e3).round() / 1e3);
            row += 1;
        }
    }
    let data = Dataset {
        source: "thermal line".into(),
        pos_mm: [Some(x), None, None],
        err_um: [Some(ex), None, None],
        t_s: Some(t),
        dir: [Some(d), None, None],
        temps: vec![TempChannel {
            name: "bed".into(),
            temp_c: temp,
        }],
        ..Dataset::default()
    };
    let csv = dir.join("thermal.csv");
    import::write_csv(&data, std::fs::File::create(&csv).unwrap()).unwrap();
    csv
}

/// The host model's error prediction for target ex at `x_mm` after an
/// approach in `dir`, at t = 0 and the given bed temperature, µm.
pub fn predict_ex(model: &ModelFile, x_mm: &[f64], dir: i8, bed_c: Option<f64>) -> Vec<f64> {
    let n = x_mm.len();
    let data = Dataset {
        source: "test".into(),
        pos_mm: [Some(x_mm.to_vec()), None, None],
        t_s: Some(vec![0.0; n]),
        dir: [Some(vec![dir; n]), None, None],
        temps: bed_c
            .map(|c| {
                vec![TempChannel {
                    name: "bed".into(),
                    temp_c: vec![c; n],
                }]
            })
            .unwrap_or_default(),
        ..Dataset::default()
    };
    model.model.predict(&data).unwrap()[0].clone().unwrap()
}

/// Reads a COMP_FILE_TYPE 1 file the way LinuxCNC does: every line must be
/// exactly three numbers (LinuxCNC stops at the first that is not), nominal
/// strictly ascending, at most 256 entries.
pub fn read_linuxcnc(text: &str) -> Vec<[f64; 3]> {
    assert!(text.ends_with('\n'), "last line terminated");
    let mut out: Vec<[f64; 3]> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let cells: Vec<&str> = line.split(' ').collect();
        assert_eq!(cells.len(), 3, "line {}: `{line}`", i + 1);
        let v: Vec<f64> = cells
            .iter()
            .map(|c| {
                assert!(
                    c.chars()
                        .all(|ch| ch.is_ascii_digit() || ch == '-' || ch == '.'),
                    "line {}: `{c}` is not a plain decimal",
                    i + 1
                );
                c.parse::<f64>().unwrap()
            })
            .collect();
        if let Some(prev) = out.last() {
            assert!(v[0] > prev[0], "line {}: not ascending", i + 1);
        }
        out.push([v[0], v[1], v[2]]);
    }
    assert!(!out.is_empty() && out.len() <= 256, "{} entries", out.len());
    out
}

/// `fit thermal.csv` with reversal + thermal (no lag) on ex.
pub fn thermal_model(dir: &Path) -> (PathBuf, PathBuf) {
    let csv = thermal_csv(dir);
    let model = dir.join("thermal_nolag.model.json");
    fit(
        &csv,
        &[
            "--model",
            "cubic19",
            "--add",
            "reversal:target=ex,axis=x",
            "--add",
            "thermal:target=ex,channel=bed,times=x",
        ],
        &model,
    );
    (csv, model)
}
