//! Rows written twice (issue 24): `import`, `fit` and `diagnose` name the
//! lines that repeat an earlier line exactly, and the noise floor does not
//! take the copies for repeated readings (main: `repeats` floor 0.000 µm
//! and "ex inf× its noise floor", `import` silent).

mod common;

use common::{find_warning, fit_cubic19, json, run, s, simulate_grid, tmp_dir};

/// The simulated grid with every data row written twice.
fn twice(dir: &std::path::Path) -> std::path::PathBuf {
    let src = simulate_grid(dir, "grid.csv", 3);
    let text = std::fs::read_to_string(&src).unwrap();
    let mut out = String::new();
    let mut header = true;
    for line in text.lines() {
        out.push_str(line);
        out.push('\n');
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if header {
            header = false;
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    common::file_in(dir, "twice.csv", out)
}

/// The line of the header (1-based) in `csv`: the data start after it.
fn header_line(csv: &std::path::Path) -> usize {
    let text = std::fs::read_to_string(csv).unwrap();
    1 + text
        .lines()
        .position(|l| !l.starts_with('#') && !l.trim().is_empty())
        .unwrap()
}

#[test]
fn rows_written_twice_are_named_and_not_taken_for_repeats() {
    let dir = tmp_dir("duplicates", "twice");
    let csv = twice(&dir);
    let h = header_line(&csv);

    let out = run(&["import", s(&csv), "--json"]);
    let v = json(&out);
    let dups = v["duplicate_rows"].as_array().unwrap();
    let rows = v["rows"].as_u64().unwrap() as usize;
    assert_eq!(dups.len(), rows / 2);
    assert_eq!(dups[0]["line"], h + 2);
    assert_eq!(dups[0]["of_line"], h + 1);

    let out = run(&["import", s(&csv)]);
    let text = String::from_utf8_lossy(&out.stdout);
    let first = format!("line {} = line {}", h + 2, h + 1);
    assert!(
        text.contains("warning (duplicate_rows)") && text.contains(&first),
        "{text}"
    );

    let out = run(&["diagnose", s(&csv), "--model", "cubic19", "--json"]);
    let v = json(&out);
    let w = find_warning(&v, "duplicate_rows").expect("duplicate_rows warning");
    assert!(w["detail"].as_str().unwrap().contains(&first), "{w}");
    for (t, f) in v["noise_floor_um"].as_object().unwrap() {
        assert!(f.as_f64().is_some_and(|f| f > 0.0), "{t}: {f}");
        assert_ne!(v["noise_method"][t], "repeats", "{t}");
    }
    for u in v["unexplained"].as_array().unwrap() {
        assert!(u["ratio"].as_f64().is_some_and(f64::is_finite), "{u}");
    }

    let model = dir.join("m.json");
    let v = fit_cubic19(&csv, &model);
    let texts: Vec<&str> = v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert!(
        texts
            .iter()
            .any(|t| t.starts_with("duplicate_rows: ") && t.contains(&first)),
        "{texts:?}"
    );
}
