//! Renishaw `.rtl` import: a hand-made file (CRLF, targets wrapped over two
//! lines, backward runs in descending order) with known values, and broken
//! files that must fail with the line number.

mod common;

use common::{data_file as data, json, run, s};
use trueaxis_engine::import;

#[test]
fn hand_made_file_has_known_values() {
    let path = data("iso_worked.rtl");
    // The file really is CRLF (the .gitattributes keeps it so).
    assert!(std::fs::read_to_string(&path).unwrap().contains("\r\n"));
    let d = import::load(&path).unwrap();
    assert_eq!(d.len(), 12);
    assert_eq!(d.axes(), vec![0]);
    assert_eq!(d.targets(), vec![0]);
    let x = d.pos_mm[0].as_ref().unwrap();
    let ex: Vec<f64> = d.err_um[0]
        .as_ref()
        .unwrap()
        .iter()
        .map(|v| v.unwrap())
        .collect();
    let dir = d.dir[0].as_ref().unwrap();
    let pass = d.pass_id.as_ref().unwrap();
    // Run 1 forward, run 2 backward (targets 3, 2, 1 → 200, 100, 0 mm).
    assert_eq!(&x[..6], &[0.0, 100.0, 200.0, 200.0, 100.0, 0.0]);
    assert_eq!(&ex[..6], &[1.0, 3.0, -1.0, -3.0, 2.0, -1.0]);
    assert_eq!(&dir[..6], &[1, 1, 1, -1, -1, -1]);
    assert_eq!(pass, &vec![1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4]);
    // Source lines of the deviation rows (first at line 21).
    assert_eq!(d.line[0], 21);
    let meta = |k: &str| {
        d.metadata
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.as_str())
    };
    assert_eq!(meta("Machine"), Some("VMC-1"));
    assert_eq!(meta("Serial No"), Some("SN-42"));
    assert_eq!(meta("Location"), Some("Bay 3"));
    assert_eq!(meta("environment Air temp"), Some("20.1 C"));
    assert_eq!(meta("equipment Laser"), Some("XL-80"));
    assert_eq!(meta("axis"), Some("x"));
}

fn fails(file: &str, want: &str) {
    let path = data(file);
    let e = format!("{:#}", import::load(&path).unwrap_err());
    let want = format!("{}:{want}", path.display());
    assert!(e.contains(&want), "expected `{want}` in `{e}`");
}

#[test]
fn broken_files_name_the_line() {
    fails(
        "bad_count.rtl",
        "6: Target-count is 4 but `Targets :` lists 3 positions",
    );
    fails(
        "bad_deviation.rtl",
        "28:3: expected a finite deviation in µm, found `5,0x`",
    );
    fails(
        "bad_order.rtl",
        "25:2: run 2 is a backward run: expected targets in descending order, found 3 after 2",
    );
    fails("truncated.rtl", "30: expected `EOF::` (file truncated?)");
    fails(
        "bad_target.rtl",
        "23:2: expected a target number 1..=3, found `7`",
    );
}

#[test]
fn cli_converts_rtl_to_contract_csv() {
    let out_csv = std::env::temp_dir().join(format!("trueaxis-rtl-{}.csv", std::process::id()));
    let rtl = data("iso_worked.rtl");
    let v = json(&run(&["import", s(&rtl), "-o", s(&out_csv), "--json"]));
    assert_eq!(v["rows"], 12);
    assert_eq!(
        v["columns"],
        serde_json::json!(["x_mm", "ex_um", "dir_x", "pass_id"])
    );
    assert_eq!(v["skipped_count"], 0);
    let text = std::fs::read_to_string(&out_csv).unwrap();
    assert!(
        text.contains("x_mm,ex_um,dir_x,pass_id\n0,1,1,1\n100,3,1,1\n"),
        "{text}"
    );
    // The contract CSV of the same values gives the same data.
    let a = import::load(&out_csv).unwrap();
    let b = import::load(&data("iso_worked.csv")).unwrap();
    assert_eq!(a.pos_mm, b.pos_mm);
    assert_eq!(a.err_um, b.err_um);
    assert_eq!(a.dir, b.dir);
    let _ = std::fs::remove_file(out_csv);
}

#[test]
fn mutated_files_never_panic_and_errors_are_located() {
    use rand_chacha::rand_core::{RngCore, SeedableRng};
    let base = std::fs::read_to_string(data("iso_worked.rtl")).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let specials = [":", "::", " ", "\r\n", "-", "9", "x", "", "1 1 1.0\r\n"];
    let mut errors = 0;
    for _ in 0..3000 {
        let mut v = base.clone();
        for _ in 0..1 + rng.next_u32() % 3 {
            let mut i = rng.next_u32() as usize % (v.len() + 1);
            while !v.is_char_boundary(i) {
                i -= 1;
            }
            let s = specials[rng.next_u32() as usize % specials.len()];
            match rng.next_u32() % 3 {
                0 => v.insert_str(i, s),
                1 => v.truncate(i),
                _ => {
                    let j = (i + 1 + rng.next_u32() as usize % 8).min(v.len());
                    let mut j2 = j;
                    while !v.is_char_boundary(j2) {
                        j2 += 1;
                    }
                    v.replace_range(i..j2, s);
                }
            }
        }
        match import::read_rtl(&v, "m.rtl", None) {
            Ok(d) => d.validate().unwrap(),
            Err(e) => {
                errors += 1;
                assert!(e.to_string().starts_with("m.rtl:"), "unlocated: {e}");
            }
        }
    }
    assert!(errors > 300, "only {errors} of 3000 mutations failed");
}

#[test]
fn label_in_front_of_every_row_is_read_the_same() {
    let a = import::load(&data("iso_worked.rtl")).unwrap();
    let b = import::load(&data("label_per_row.rtl")).unwrap();
    assert_eq!(a.pos_mm, b.pos_mm);
    assert_eq!(a.err_um, b.err_um);
    assert_eq!(a.dir, b.dir);
    assert_eq!(a.pass_id, b.pass_id);
}

/// The worked example with one edit, read from memory.
fn edited(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(data("iso_worked.rtl")).unwrap();
    assert!(text.contains(from), "{from:?}");
    text.replacen(from, to, 1)
}

/// A UTF-8 byte order mark (as Windows editors write it) is skipped, like
/// the CSV reader does — from memory and from a file.
#[test]
fn byte_order_mark_is_skipped() {
    let text = std::fs::read_to_string(data("iso_worked.rtl")).unwrap();
    let plain = import::read_rtl(&text, "a.rtl", None).unwrap();
    let bom = import::read_rtl(&format!("\u{feff}{text}"), "b.rtl", None).unwrap();
    assert_eq!(bom.pos_mm, plain.pos_mm);
    assert_eq!(bom.err_um, plain.err_um);
    assert_eq!(bom.dir, plain.dir);
    let path = std::env::temp_dir().join(format!("trueaxis-bom-{}.rtl", std::process::id()));
    let mut bytes = vec![0xef, 0xbb, 0xbf];
    bytes.extend_from_slice(text.as_bytes());
    std::fs::write(&path, bytes).unwrap();
    assert_eq!(import::load(&path).unwrap().err_um, plain.err_um);
    let _ = std::fs::remove_file(path);
}

/// `Targets` must ascend: forward runs get dir +1 because they move up the
/// list, so a descending list would give every row the wrong direction.
#[test]
fn targets_out_of_order_name_the_line_and_field() {
    let text = edited(
        "Targets :    0.000   100.000\r\n   200.000",
        "Targets :    200.000   100.000\r\n   0.000",
    );
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("d.rtl:6:2: Targets: expected positions in ascending order"),
        "{e}"
    );
    assert!(e.contains("found `100.000` after 200"), "{e}");
    // Also across a wrapped line, and a repeated position.
    let text = edited("   200.000", "   100.000");
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("d.rtl:7:1: Targets: expected positions in ascending order"),
        "{e}"
    );
}

/// A target beyond ±10 m or a deviation beyond ±10 mm is a unit mistake or
/// a broken beam, refused with its line and field (issue 14).
#[test]
fn implausible_targets_and_deviations_are_refused() {
    let text = edited("   200.000", "   2e7");
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(
            "d.rtl:7:1: Targets: expected a position in mm between -10000 and 10000, found `2e7`"
        ),
        "{e}"
    );
    let text = edited("1 2 3.0", "1 2 30000.0");
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(
            "d.rtl:22:3: expected a deviation in µm between -10000 and 10000, found `30000.0`"
        ),
        "{e}"
    );
}

/// A run that stops before visiting every target is refused with the line
/// of its last deviation, not read as a shorter run.
#[test]
fn incomplete_run_names_its_last_line() {
    // Run 3 (lines 27–29) loses its third target.
    let text = edited("3 3 1.0\r\n", "");
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "d.rtl:28: run 3 has 2 of the 3 targets (missing target 3); expected every run to visit every target"
    );
    // A backward run cut after its first reading.
    let text = edited("2 2 2.0\r\n2 1 -1.0\r\n", "");
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("d.rtl:24: run 2 has 1 of the 3 targets (missing target 1, 2)"),
        "{e}"
    );
}

/// A run whose reading is the laser's "no reading" placeholder (−1e20) is
/// left out with its lines and why; the other runs are used (issue 24:
/// the whole file was refused as "a broken beam or another unit").
#[test]
fn a_placeholder_run_is_left_out_and_the_others_used() {
    // Run 3 (lines 27–29), target 2 (line 28) lost the beam.
    let text = edited("3 2 5.0", "3 2 -1e20");
    let d = import::read_rtl(&text, "d.rtl", None).unwrap();
    assert_eq!(d.len(), 9, "three of the four runs");
    assert!(d.pass_id.as_ref().unwrap().iter().all(|&p| p != 3));
    let lines: Vec<usize> = d.skipped.iter().map(|s| s.line).collect();
    assert_eq!(lines, vec![27, 28, 29]);
    assert_eq!(
        d.skipped[1].reason,
        "run 3, target 2: no reading (`-1e20`, the laser's placeholder) — run 3 left out"
    );
    // Every run a placeholder: refused, with the line.
    let mut text = text;
    for (from, to) in [
        ("1 1 1.0", "1 1 -1e20"),
        ("2 3 -3.0", "2 3 -1e20"),
        ("4 3 -2.0", "4 3 1e20"),
    ] {
        text = text.replacen(from, to, 1);
    }
    let e = import::read_rtl(&text, "d.rtl", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("d.rtl:21:3: every run has a placeholder"),
        "{e}"
    );
}

/// An `.rtl` from a Russian-language Windows (issue 24): its metadata in
/// Windows-1251 reads as Cyrillic, not as Latin-1 noise, and the note says
/// which code page was read from which line; a German one (Windows-1252)
/// keeps its umlauts. The readings are the same either way.
#[test]
fn legacy_code_pages_in_rtl_metadata_are_decoded_and_said() {
    let dir = common::tmp_dir("rtl", "codepage");
    let base = std::fs::read(data("iso_worked.rtl")).unwrap();
    let text = String::from_utf8(base).unwrap();
    // "By: A. Tester" → "By: Иванов" (Windows-1251), line 14.
    let mut ru: Vec<u8> = Vec::new();
    let (head, tail) = text.split_at(text.find("A. Tester").unwrap());
    ru.extend(head.as_bytes());
    ru.extend([0xC8, 0xE2, 0xE0, 0xED, 0xEE, 0xE2]);
    ru.extend(&tail.as_bytes()["A. Tester".len()..]);
    let p = common::file_in(&dir, "ru.rtl", &ru);
    let ds = import::load(&p).unwrap();
    let meta = |ds: &trueaxis_engine::data::Dataset, k: &str| {
        ds.metadata
            .iter()
            .find(|(key, _)| key.contains(k))
            .map(|(_, v)| v.clone())
    };
    assert_eq!(
        meta(&ds, "By").as_deref(),
        Some("Иванов"),
        "{:?}",
        ds.metadata
    );
    let note = meta(&ds, "encoding").expect("a note");
    common::assert_has(&note, &["Windows-1251", "line 14"]);
    let out = run(&["import", s(&p), "-o", s(&dir.join("ru.csv"))]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("read as Windows-1251"),
        "{out:?}"
    );
    // "Location: Bay 3" → "Location: Prüfstand" (Windows-1252).
    let de = text.replace("Bay 3", "Pr\u{fc}fstand");
    let de: Vec<u8> = de
        .chars()
        .map(|c| if c == 'ü' { 0xFC } else { c as u8 })
        .collect();
    let p = common::file_in(&dir, "de.rtl", &de);
    let de_ds = import::load(&p).unwrap();
    assert_eq!(meta(&de_ds, "Location").as_deref(), Some("Prüfstand"));
    assert!(meta(&de_ds, "encoding").unwrap().contains("Windows-1252"));
    assert_eq!(de_ds.err_um, ds.err_um);
}
