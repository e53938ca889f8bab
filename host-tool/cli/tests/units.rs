//! Units a user got wrong pass every range check; the tool must say so
//! (issue 12): errors in mm written into `*_um` columns are warned at fit,
//! diagnose and improve (`units_suspect`), and export refuses the table —
//! 1000× too small — unless told.

mod common;

use common::{json, run, s, simulate_grid, tmp_dir};

/// The simulated grid with every `*_um` cell divided by 1000 (mm typed
/// into µm columns).
fn grid_in_mm(dir: &std::path::Path) -> std::path::PathBuf {
    let csv = simulate_grid(dir, "grid.csv", 5);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut header: Option<Vec<String>> = None;
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if let Some(h) = &header {
            let cells: Vec<String> = line
                .split(',')
                .zip(h)
                .map(
                    |(c, name)| match (name.ends_with("_um"), c.parse::<f64>()) {
                        (true, Ok(v)) => format!("{}", v / 1000.0),
                        _ => c.to_string(),
                    },
                )
                .collect();
            out.push_str(&cells.join(","));
        } else {
            header = Some(line.split(',').map(str::to_string).collect());
            out.push_str(line);
        }
        out.push('\n');
    }
    common::file_in(dir, "grid_mm.csv", out)
}

#[test]
fn errors_in_mm_are_warned_and_their_table_refused_unless_told() {
    let dir = tmp_dir("units", "mm");
    let mm = grid_in_mm(&dir);
    let model = dir.join("m.json");
    let fit = common::cubic19("fit", &mm, &model, &[]);
    let err = String::from_utf8_lossy(&fit.stderr).into_owned();
    common::assert_has(&err, &["units_suspect", "multiply them by 1000"]);
    let doc = json(&fit);
    assert!(
        doc["warnings"].to_string().contains("units_suspect"),
        "{doc}"
    );
    let d = json(&run(&["diagnose", s(&mm), "--model", s(&model), "--json"]));
    let suspect = common::find_warning(&d, "units_suspect");
    assert!(suspect.is_some(), "{}", d["warnings"]);
    let table = dir.join("t.bin");
    let out = run(&["export", s(&model), "-o", s(&table)]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--accept-tiny-corrections"), "{err}");
    assert!(!table.exists(), "a refused table is not written");
    // A controller file is refused the same way.
    let out = run(&[
        "export",
        s(&model),
        "--format",
        "linuxcnc",
        "--axis",
        "x",
        "-o",
        s(&dir.join("x.comp")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("--accept-tiny-corrections"), "{err}");
    json(&run(&[
        "export",
        s(&model),
        "-o",
        s(&table),
        "--accept-tiny-corrections",
        "--json",
    ]));
    assert!(table.exists());
    // The same data in µm: no warning, the table exports.
    let um = simulate_grid(&dir, "grid_um.csv", 5);
    let m2 = dir.join("m2.json");
    let fit = run(&["fit", s(&um), "--model", "cubic19", "-o", s(&m2), "--json"]);
    assert!(!String::from_utf8_lossy(&fit.stderr).contains("units_suspect"));
    json(&run(&[
        "export",
        s(&m2),
        "-o",
        s(&dir.join("t2.bin")),
        "--json",
    ]));
}
