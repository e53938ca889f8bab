//! Reading a command's measurement file — the one place every command that
//! takes DATA (fit, compare, diagnose, improve, iso230) loads it, so they
//! all keep CONTRACT.md §1's promise the same way: nothing is silently
//! skipped. Rows the importer left out (an empty row, a row with no error
//! value) are counted and said on stderr (so a script's log shows them in
//! text and `--json` mode alike, without touching stdout's one document),
//! and each command's JSON carries the count as `skipped_count` — the key
//! `import --json` already uses. `trueaxis import DATA` lists every one.
//!
//! The commands that send a table to the board (upload, flash) read it
//! here too, so both refuse the same tables with the same words.

use std::path::Path;

use anyhow::{Context, Result};

use crate::data::Dataset;
use crate::import;

/// The JSON key with the number of rows left out on load.
pub const SKIPPED_KEY: &str = "skipped_count";

/// Left-out rows named in the note; the rest are counted.
const NAMED: usize = 3;

/// Loads `path` (CSV or .rtl; `axis` overrides an .rtl file's `Axis:`
/// line) and says on stderr which rows were left out, if any.
pub fn load_data(path: &Path, axis: Option<usize>) -> Result<Dataset> {
    let data = import::load_with_axis(path, axis)?;
    if let Some(note) = skipped_note(&data) {
        eprintln!("{note}");
    }
    Ok(data)
}

/// `note: 2 rows of d.csv were left out (line 409: no error value on this
/// row; line 410: empty row) — …`, or `None` when none were.
pub fn skipped_note(data: &Dataset) -> Option<String> {
    let n = data.skipped.len();
    if n == 0 {
        return None;
    }
    let mut named: Vec<String> = data
        .skipped
        .iter()
        .take(NAMED)
        .map(|s| format!("line {}: {}", s.line, s.reason))
        .collect();
    if n > NAMED {
        named.push(format!("… {} more", n - NAMED));
    }
    Some(format!(
        "note: {n} {} of {} {} left out ({}) — `trueaxis import {}` lists them",
        if n == 1 { "row" } else { "rows" },
        data.source,
        if n == 1 { "was" } else { "were" },
        named.join("; "),
        data.source
    ))
}

/// Reads the table file at `path` for the board: a valid table
/// (model-core's parser) that the board's own limits admit
/// (`model_core::board`: staging buffer, model capacity, loop budget) —
/// checked before anything touches the board. Returns its bytes.
pub fn load_board_table(path: &Path) -> Result<Vec<u8>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let table = model_core::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a valid table: {e}", path.display()))?;
    model_core::board::check(&table)
        .map_err(|e| anyhow::anyhow!("{}: does not fit the board: {e}", path.display()))?;
    Ok(bytes)
}

/// Adds `skipped_count` to a command's JSON document (an object).
pub fn add_skipped_count(doc: &mut serde_json::Value, data: &Dataset) {
    if let Some(obj) = doc.as_object_mut() {
        obj.insert(SKIPPED_KEY.into(), data.skipped.len().into());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::SkippedRow;

    #[test]
    fn note_names_three_rows_and_counts_the_rest() {
        let mut d = Dataset {
            source: "d.csv".into(),
            ..Dataset::default()
        };
        assert_eq!(skipped_note(&d), None);
        d.skipped.push(SkippedRow {
            line: 409,
            reason: "no error value on this row".into(),
        });
        assert_eq!(
            skipped_note(&d).unwrap(),
            "note: 1 row of d.csv was left out (line 409: no error value on this row) — `trueaxis import d.csv` lists them"
        );
        for line in 410..415 {
            d.skipped.push(SkippedRow {
                line,
                reason: "empty row".into(),
            });
        }
        let note = skipped_note(&d).unwrap();
        assert!(
            note.starts_with("note: 6 rows of d.csv were left out (line 409"),
            "{note}"
        );
        assert!(note.contains("line 411: empty row; … 3 more)"), "{note}");
        let mut v = serde_json::json!({"rms_um": {}});
        add_skipped_count(&mut v, &d);
        assert_eq!(v[SKIPPED_KEY], 6);
    }
}
