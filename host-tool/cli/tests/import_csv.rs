//! End-to-end tests of `trueaxis import` on the contract CSV: every class of
//! bad input in docs/cli.md § Measurement CSV exits 1 with `file:line:column` and what was
//! expected; a good file keeps metadata, aux channels and says which rows
//! were left out; writing and reading back gives the same data set.

mod common;

use common::{data_file as data, json, run as trueaxis, s};
use trueaxis_engine::import;

/// Runs `import FILE --json`, expects exit 1 and a stderr message that
/// starts with `<path>:<line>:<column>:` (or `<path>:<line>:` when `col` is
/// None) and contains `expect`.
fn fails_at(file: &str, line: usize, col: Option<usize>, expect: &str) {
    let path = data(file);
    let out = trueaxis(&["import", path.to_str().unwrap(), "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{file}: stderr {stderr}");
    common::assert_no_document(&["import", path.to_str().unwrap(), "--json"], &out);
    let loc = match col {
        Some(c) => format!("{}:{line}:{c}: ", path.display()),
        None => format!("{}:{line}: ", path.display()),
    };
    assert!(
        stderr.contains(&loc),
        "{file}: expected `{loc}` in {stderr}"
    );
    assert!(
        stderr.contains(expect),
        "{file}: expected `{expect}` in {stderr}"
    );
}

#[test]
fn unknown_unit_suffix() {
    fails_at(
        "bad_unit.csv",
        1,
        Some(2),
        "unknown unit suffix `_in`; expected `ex_um`",
    );
}

#[test]
fn non_numeric_cell() {
    // Line 1 is metadata, 2 the header, 4 the bad row; column 2 is ex_um.
    fails_at(
        "bad_number.csv",
        4,
        Some(2),
        "column `ex_um`: expected a number, found `abc`",
    );
}

#[test]
fn nan_and_inf() {
    fails_at(
        "bad_nan.csv",
        4,
        Some(2),
        "expected a finite number, found `NaN`",
    );
    fails_at(
        "bad_inf.csv",
        3,
        Some(2),
        "expected a finite number, found `inf`",
    );
}

#[test]
fn dir_not_plus_minus_one() {
    fails_at(
        "bad_dir.csv",
        3,
        Some(3),
        "column `dir_x`: expected -1 or +1, found `0`",
    );
}

#[test]
fn duplicate_columns() {
    fails_at(
        "dup_cols.csv",
        1,
        Some(3),
        "duplicate column `x_mm` (first at column 1)",
    );
}

#[test]
fn no_error_column() {
    fails_at(
        "no_error.csv",
        1,
        None,
        "no error column; expected at least one of ex_um, ey_um, ez_um",
    );
}

#[test]
fn no_position_column() {
    fails_at("no_position.csv", 1, None, "no position column");
    // It has t_s: the message says how a time series at one point gets its
    // position.
    fails_at(
        "no_position.csv",
        1,
        None,
        "add it as a constant column, e.g. x_mm",
    );
}

#[test]
fn good_file_reports_rows_metadata_aux_and_skipped() {
    let path = data("good.csv");
    let out_csv = std::env::temp_dir().join(format!("trueaxis-import-{}.csv", std::process::id()));
    let out = trueaxis(&["import", s(&path), "-o", s(&out_csv), "--json"]);
    let v = json(&out);
    assert_eq!(v["rows"], 3);
    assert_eq!(
        v["columns"],
        serde_json::json!([
            "x_mm", "y_mm", "ex_um", "ey_um", "t_s", "dir_x", "T_bed_C", "pass_id", "operator"
        ])
    );
    assert_eq!(v["aux"], serde_json::json!(["operator"]));
    assert_eq!(
        v["metadata"][0],
        serde_json::json!({"key": "machine", "value": "XHK-715"})
    );
    assert_eq!(v["skipped_count"], 3);
    let skipped = &v["skipped"];
    assert_eq!(
        skipped[0],
        serde_json::json!({"line": 6, "reason": "no error value on this row"})
    );
    assert_eq!(
        skipped[1],
        serde_json::json!({"line": 7, "reason": "comment line after the header"})
    );
    assert_eq!(
        skipped[2],
        serde_json::json!({"line": 8, "reason": "empty `T_bed_C` cell"})
    );
    assert_eq!(v["sha256"].as_str().map(str::len), Some(64));

    // The written file reads back to the same data, aux cell with a comma
    // and the empty ey cell included.
    let a = import::load(&path).unwrap();
    let b = import::load(&out_csv).unwrap();
    assert_eq!(a.metadata, b.metadata);
    assert_eq!(a.pos_mm, b.pos_mm);
    assert_eq!(a.err_um, b.err_um);
    assert_eq!(a.err_um[1].as_ref().unwrap()[1], None);
    assert_eq!(a.aux, b.aux);
    assert_eq!(a.aux[0].cells[0], "Lee, J.");
    assert_eq!(a.temps, b.temps);
    assert_eq!(import::content_hash(&a), import::content_hash(&b));
    assert_eq!(a.line, vec![4, 5, 9]);
    let _ = std::fs::remove_file(out_csv);
}

#[test]
fn read_csv_in_memory_and_bad_row_length() {
    let ok = import::read_csv("x_mm,ex_um\n1,2\n".as_bytes(), "<mem>").unwrap();
    assert_eq!(ok.len(), 1);
    let e = import::read_csv("x_mm,ex_um\n1,2,3\n".as_bytes(), "<mem>").unwrap_err();
    assert_eq!(
        format!("{e}"),
        "<mem>:2:3: expected 2 cells as in the header, found 3"
    );
    let e = import::read_csv("x_mm,ex_um\n,\n".as_bytes(), "<mem>").unwrap_err();
    assert!(
        format!("{e}").contains("no data rows after the header (1 rows left out)"),
        "{e}"
    );
}

#[test]
fn usage_error_exits_2() {
    let out = trueaxis(&["import"]);
    assert_eq!(out.status.code(), Some(2));
}

/// Deterministic mutations of a valid file (seeded, so a failure replays):
/// flip, insert, delete bytes and truncate.
fn mutations(base: &[u8], seed: u64, n: usize) -> Vec<Vec<u8>> {
    use rand_chacha::rand_core::{RngCore, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let specials = b",\"\r\n#-+.eE0123456789 \xff\xc3";
    (0..n)
        .map(|_| {
            let mut v = base.to_vec();
            for _ in 0..1 + rng.next_u32() % 4 {
                if v.is_empty() {
                    break;
                }
                let i = rng.next_u32() as usize % v.len();
                let c = specials[rng.next_u32() as usize % specials.len()];
                match rng.next_u32() % 4 {
                    0 => v[i] = c,
                    1 => v.insert(i, c),
                    2 => {
                        v.remove(i);
                    }
                    _ => v.truncate(i),
                }
            }
            v
        })
        .collect()
}

#[test]
fn mutated_files_never_panic_and_errors_are_located() {
    let base = std::fs::read(data("good.csv")).unwrap();
    let mut errors = 0;
    for m in mutations(&base, 7, 3000) {
        match import::read_csv(m.as_slice(), "m.csv") {
            Ok(d) => d.validate().unwrap(),
            Err(e) => {
                errors += 1;
                let s = e.to_string();
                assert!(s.starts_with("m.csv:"), "unlocated error: {s}");
            }
        }
    }
    // The mutations must actually exercise the error paths.
    assert!(errors > 300, "only {errors} of 3000 mutations failed");
}

#[test]
fn random_datasets_round_trip_bit_for_bit() {
    use rand_chacha::rand_core::{RngCore, SeedableRng};
    use trueaxis_engine::data::{AuxChannel, Dataset, TempChannel};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut f = |scale: f64| {
        // Any finite double, including tiny, huge and negative zero.
        let v = f64::from_bits(rng.next_u64());
        if v.is_finite() {
            v
        } else {
            (rng.next_u32() as f64 - 2e9) * scale
        }
    };
    for _ in 0..50 {
        let n = 20;
        let mut d = Dataset {
            source: "rt".into(),
            metadata: vec![
                ("machine".into(), "m, with comma".into()),
                (String::new(), "free note".into()),
            ],
            ..Dataset::default()
        };
        // Any double a position or an error may have (±10 000 mm / µm; the
        // importer refuses the rest), with full mantissas, −0, a subnormal
        // and the limits themselves.
        let mut plausible = |i: usize, limit: f64| match i {
            0 => -0.0,
            1 => f64::from_bits(3),
            2 => -limit,
            3 => limit,
            _ => limit * (2.0 * (f(1.0).to_bits() >> 11) as f64 / (1u64 << 53) as f64 - 1.0),
        };
        d.pos_mm[0] = Some((0..n).map(|i| plausible(i, 10_000.0)).collect());
        d.pos_mm[2] = Some((0..n).map(|i| plausible(n - 1 - i, 10_000.0)).collect());
        d.err_um[1] = Some(
            (0..n)
                .map(|i| {
                    if i % 3 == 0 {
                        None
                    } else {
                        Some(plausible(i, 10_000.0))
                    }
                })
                .collect(),
        );
        d.err_um[2] = Some((0..n).map(|i| Some(plausible(i, 10_000.0))).collect());
        d.dir[0] = Some((0..n).map(|i| if i % 2 == 0 { 1 } else { -1 }).collect());
        d.t_s = Some((0..n).map(|_| f(1.0)).collect());
        d.temps = vec![TempChannel {
            name: "bed".into(),
            // Any double a sensor can read (−50…150 °C, the importer
            // refuses the rest), with full mantissas, −0 and a subnormal.
            temp_c: (0..n)
                .map(|i| match i {
                    0 => -0.0,
                    1 => f64::from_bits(3),
                    _ => -50.0 + 200.0 * (f(1.0).to_bits() >> 11) as f64 / (1u64 << 53) as f64,
                })
                .collect(),
        }];
        d.pass_id = Some((0..n).map(|i| i as i64 - 5).collect());
        d.aux = vec![AuxChannel {
            name: "note".into(),
            cells: (0..n).map(|i| format!("a \"q\", {i}\nline")).collect(),
        }];
        let mut buf = Vec::new();
        import::write_csv(&d, &mut buf).unwrap();
        let back = import::read_csv(buf.as_slice(), "rt").unwrap();
        // Every row has an ez value, so none is skipped.
        assert!(back.skipped.is_empty());
        assert_eq!(back.columns_differing(&d), Vec::<&str>::new());
    }
}

#[test]
fn crlf_bom_and_other_separators() {
    let text = "\u{feff}# machine: m\r\nx_mm,ex_um\r\n0,1.5\r\n10,2\r\n";
    let d = import::read_csv(text.as_bytes(), "crlf.csv").unwrap();
    assert_eq!(d.metadata, vec![("machine".to_string(), "m".to_string())]);
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(1.5), Some(2.0)]);
    assert_eq!(d.line, vec![3, 4]);
    // Blank lines between rows do not shift the numbers, with either ending.
    for nl in ["\n", "\r\n"] {
        let text = ["x_mm,ex_um", "0,1", "", "", "10,abc", ""].join(nl);
        let e = import::read_csv(text.as_bytes(), "b.csv").unwrap_err();
        assert!(e.to_string().starts_with("b.csv:5:2: "), "{nl:?}: {e}");
    }
    // `;` (with decimal commas) and tabs are read as Excel writes them.
    let d = import::read_csv("x_mm;ex_um\n0;1,5\n".as_bytes(), "semi.csv").unwrap();
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(1.5)]);
    let d = import::read_csv("x_mm\tex_um\n0\t1.5\n".as_bytes(), "tab.csv").unwrap();
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(1.5)]);
}

/// Excel's "CSV (semicolon)" of a decimal-comma locale (UTF-8 BOM, CRLF,
/// `;`, `1,25`, empty columns after the data) and its "Unicode text"
/// (UTF-16LE with BOM, tabs) are read as written, through the binary.
#[test]
fn excel_files_are_read_as_written() {
    let v = json(&trueaxis(&[
        "import",
        s(&data("excel_semicolon.csv")),
        "--json",
    ]));
    assert_eq!(v["rows"], 3, "{v}");
    let d = import::read_csv(
        std::fs::File::open(data("excel_semicolon.csv")).unwrap(),
        "excel_semicolon.csv",
    )
    .unwrap();
    assert_eq!(d.pos_mm[0].as_ref().unwrap(), &vec![0.0, 100.0, 200.0]);
    assert_eq!(
        d.err_um[0].as_ref().unwrap(),
        &vec![Some(1.25), Some(-0.75), Some(2.0)]
    );
    assert_eq!(d.temp("bed").unwrap().temp_c, vec![20.5, 20.75, 21.0]);
    assert_eq!(d.dir[0].as_ref().unwrap(), &vec![1, -1, 1]);
    assert_eq!(
        d.metadata,
        vec![("machine".to_string(), "VMC-1".to_string())]
    );
    assert_eq!(d.line, vec![3, 4, 5]);
    let d = import::read_csv(
        std::fs::File::open(data("excel_unicode.txt")).unwrap(),
        "excel_unicode.txt",
    )
    .unwrap();
    assert_eq!(d.pos_mm[0].as_ref().unwrap(), &vec![0.0, 50.0]);
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(1.5), Some(-0.25)]);
    // UTF-16BE without a BOM is recognised by its zero bytes.
    let be: Vec<u8> = "x_mm,ex_um\n1,2\n"
        .encode_utf16()
        .flat_map(|u| u.to_be_bytes())
        .collect();
    let d = import::read_csv(be.as_slice(), "be.csv").unwrap();
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(2.0)]);
    // A `;` file whose numbers use the decimal point: there a comma in a
    // number may be a thousands separator, so `1,234` is refused, not read
    // as 1.234.
    let d = import::read_csv("x_mm;ex_um\n0;1.5\n".as_bytes(), "dot.csv").unwrap();
    assert_eq!(d.err_um[0].as_ref().unwrap(), &vec![Some(1.5)]);
    let e = import::read_csv("x_mm;ex_um\n0;1.5\n10;1,234\n".as_bytes(), "mixed.csv").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("mixed.csv:3:2: column `ex_um`: expected a number, found `1,234`"),
        "{e}"
    );
    // A cut UTF-16 file, and a value in a trailing empty column, are errors.
    let e = import::read_csv(&[0xFF, 0xFE, b'x', 0, b'_'][..], "cut.csv").unwrap_err();
    assert!(
        e.to_string().contains("cut.csv:1: expected UTF-16 text"),
        "{e}"
    );
    let e = import::read_csv("x_mm;ex_um;;\n0;1;;\n1;2;3;\n".as_bytes(), "t.csv").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("t.csv:3:3: expected 2 cells as in the header, found 4"),
        "{e}"
    );
}

#[test]
fn implausible_positions_and_errors() {
    // A placeholder 1e308 in a position column, an error of 25 mm: unit
    // mistakes or broken readings, refused where they are (issue 14).
    fails_at(
        "bad_position.csv",
        4,
        Some(1),
        "column `x_mm`: expected a position in mm between -10000 and 10000, found `1e308`",
    );
    fails_at(
        "bad_error.csv",
        3,
        Some(2),
        "column `ey_um`: expected an error in µm between -10000 and 10000, found `25000`",
    );
    // At the limit itself the value is accepted.
    let dir = std::env::temp_dir().join(format!("trueaxis-plausible-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let edge = common::file_in(&dir, "edge.csv", "x_mm,ex_um\n-10000,-10000\n10000,10000\n");
    let out = trueaxis(&["import", edge.to_str().unwrap(), "--json"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn implausible_temperatures() {
    // °C outside −50…150 is a unit mistake; 250…400 is named as kelvin.
    fails_at(
        "bad_kelvin.csv",
        3,
        Some(3),
        "column `T_bed_C`: expected a temperature in °C between -50 and 150, found `293.40` — 293.4 looks like kelvin (20.25 °C)",
    );
    fails_at(
        "bad_temp.csv",
        3,
        Some(4),
        "column `T_spindle_C`: expected a temperature in °C between -50 and 150, found `-60`",
    );
    // Every command that reads data refuses it the same way (fit here).
    let path = data("bad_kelvin.csv");
    let out = trueaxis(&["fit", path.to_str().unwrap(), "--model", "cubic19"]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!("{}:3:3: ", path.display()))
            && stderr.contains("looks like kelvin"),
        "{stderr}"
    );
}

/// Issue 28: Excel's German "CSV" (Windows-1252, `;`, decimal comma), its
/// "Unicode text" saved as `.txt` and a `.tsv` are read; a header that
/// misses the contract names is answered with the closest ones.
#[test]
fn excel_files_from_a_german_desktop_are_read_or_answered_with_the_names_meant() {
    let dir = common::tmp_dir("import", "excel-de");
    // `Temperatur ü` and `°` as single Windows-1252 bytes (0xFC, 0xB0).
    let cp1252 = dir.join("messung.csv");
    std::fs::write(
        &cp1252,
        b"# Pr\xfcfstand: Halle 3, 21 \xb0C\r\nx_mm;ex_um;Temperatur \xfc\r\n0;1,5;20,1\r\n50;-0,25;20,2\r\n",
    )
    .unwrap();
    let out = trueaxis(&["import", cp1252.to_str().unwrap(), "--json"]);
    let doc = json(&out);
    assert_eq!(doc["rows"], 2, "{doc}");
    assert_eq!(doc["aux"][0], "Temperatur ü", "{doc}");
    assert!(
        doc["metadata"].to_string().contains("Halle 3, 21 °C"),
        "{doc}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("read as Windows-1252"), "{err}");
    // Excel's "Unicode text" (UTF-16, tabs) under its own .txt name, and a
    // .tsv with decimal commas.
    let txt = dir.join("unicode.txt");
    std::fs::copy(data("excel_unicode.txt"), &txt).unwrap();
    assert_eq!(
        json(&trueaxis(&["import", txt.to_str().unwrap(), "--json"]))["rows"],
        2
    );
    let tsv = common::file_in(&dir, "d.tsv", "x_mm\tex_um\n0\t1,5\n50\t-0,25\n");
    let out = dir.join("d_out.csv");
    json(&trueaxis(&["import", s(&tsv), "-o", s(&out), "--json"]));
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(written.contains("\n0,1.5\n50,-0.25\n"), "{written}");
    // A header in words: the error names the contract columns meant.
    let words = common::file_in(&dir, "words.csv", "x (mm);ex [um]\n0;1,5\n50;2\n");
    let out = trueaxis(&["import", words.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("`x (mm)` → x_mm, `ex [um]` → ex_um"), "{err}");
}
