//! Reading a command's measurement file — the one place every command that
//! takes DATA (fit, compare, diagnose, improve, iso230) loads it, so they
//! all keep docs/cli.md § Measurement CSV's promise the same way: nothing is silently
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

use trueaxis_engine::data::Dataset;
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;
use trueaxis_engine::warning::Warning;

/// The JSON key with the number of rows left out on load.
pub const SKIPPED_KEY: &str = "skipped_count";

/// Left-out rows named in the note; the rest are counted.
const NAMED: usize = 3;

/// Loads `path` (CSV or .rtl; `axis` overrides an .rtl file's `Axis:`
/// line) and says on stderr which rows were left out, if any.
pub fn load_data(path: &Path, axis: Option<usize>) -> Result<Dataset> {
    let data = import::load_with_axis(path, axis)?;
    if let Some(note) = encoding_note(&data) {
        eprintln!("{note}");
    }
    if let Some(note) = skipped_note(&data) {
        eprintln!("{note}");
    }
    Ok(data)
}

/// `note: d.csv is not valid UTF-8 …: read as Windows-1252 …` when the
/// reader decoded the file so (docs/cli.md § Measurement CSV).
pub fn encoding_note(data: &Dataset) -> Option<String> {
    data.metadata
        .iter()
        .find(|(k, _)| k == import::ENCODING_NOTE)
        .map(|(_, v)| format!("note: {} is {v}", data.source))
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

/// Reads a MODEL.json as every command does (`ModelFile::load_noting`):
/// checked whole, its checksum included; a file without one loads with a
/// note on stderr (docs/cli.md § fit, MODEL.json).
pub fn load_model(path: &Path) -> Result<ModelFile> {
    let (model, note) = ModelFile::load_noting(path)?;
    if let Some(note) = note {
        eprintln!("{note}");
    }
    Ok(model)
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

/// Every warning about the data themselves that fit, diagnose and improve
/// give: auxiliary columns ([`aux_warnings`]) and units the data probably
/// do not have (`units_suspect`, trueaxis_engine::units).
pub fn data_warnings(data: &Dataset) -> Vec<Warning> {
    let mut w = aux_warnings(data);
    w.extend(duplicate_warning(data));
    w.extend(trueaxis_engine::units::suspect(data));
    w
}

/// Most pairs of lines a `duplicate_rows` warning names (the count says
/// how many there are).
const DUPLICATES_NAMED: usize = 8;

/// The source line of row `r` (the row number when the data did not come
/// from a file).
fn line_of(data: &Dataset, r: usize) -> String {
    data.line
        .get(r)
        .map_or_else(|| format!("row {}", r + 1), |l| format!("line {l}"))
}

/// `duplicate_rows`: rows that repeat an earlier row exactly (every column
/// equal, [`Dataset::duplicate_rows`]), with their lines — a file written
/// twice is not a second reading, and the noise floor does not count them
/// as repeats.
pub fn duplicate_warning(data: &Dataset) -> Option<Warning> {
    let d = data.duplicate_rows();
    if d.is_empty() {
        return None;
    }
    let named: Vec<String> = d
        .iter()
        .take(DUPLICATES_NAMED)
        .map(|&(r, of)| format!("{} = {}", line_of(data, r), line_of(data, of)))
        .collect();
    Some(Warning::new(
        "duplicate_rows",
        format!(
            "{}: {} exactly (every column equal): {}{} — a file written twice or a logger that wrote a reading again; they are kept in the fit but not counted as repeated readings in the noise floor (if they are readings taken again, add a t_s or pass_id column that tells them apart)",
            data.source,
            if d.len() == 1 {
                "1 row repeats an earlier row".to_string()
            } else {
                format!("{} rows repeat an earlier row", d.len())
            },
            named.join(", "),
            if d.len() > DUPLICATES_NAMED { ", …" } else { "" }
        ),
    ))
}

/// What `fit`, `improve` and `diagnose` say about the data's auxiliary
/// columns (docs/cli.md § Measurement CSV: kept and reported):
/// `aux_misspelled` for those whose name looks like a contract column
/// written another way (`ey [um]` → `ey_um`, `T_bed` → `T_bed_C`, see
/// `import::probable_column`), `aux_columns` for the rest. Neither is used
/// by any model; both are written back by `import`.
pub fn aux_warnings(data: &Dataset) -> Vec<Warning> {
    let mut meant = Vec::new();
    let mut other = Vec::new();
    for c in &data.aux {
        match import::probable_column(&c.name) {
            Some(known) => meant.push(format!("`{}` (probably `{known}`)", import::shown(&c.name))),
            None => other.push(format!("`{}`", import::shown(&c.name))),
        }
    }
    let mut w = Vec::new();
    if !meant.is_empty() {
        w.push(Warning::new(
            "aux_misspelled",
            format!(
                "{}: {} kept as auxiliary and not fitted, though the name looks like a contract column written another way: {} — rename the header to the contract name to use it",
                data.source,
                if meant.len() == 1 { "a column is" } else { "columns are" },
                meant.join(", ")
            ),
        ));
    }
    if !other.is_empty() {
        w.push(Warning::new(
            "aux_columns",
            format!(
                "{}: auxiliary {} {} kept, not used by any model: {}",
                data.source,
                if other.len() == 1 {
                    "column"
                } else {
                    "columns"
                },
                if other.len() == 1 { "is" } else { "are" },
                other.join(", ")
            ),
        ));
    }
    w
}

/// True when `a` and `b` name the same existing file (the same path after
/// resolving `..` and symbolic links, or — on Unix — a hard link to it).
pub fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) else {
        // A file that does not exist yet cannot be one that does.
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if ma.dev() == mb.dev() && ma.ino() == mb.ino() {
            return true;
        }
    }
    let _ = (ma, mb);
    matches!(
        (std::fs::canonicalize(a), std::fs::canonicalize(b)),
        (Ok(x), Ok(y)) if x == y
    )
}

/// Refuses, before anything is written, a command whose output would
/// replace one of its inputs (`fit d.csv -o d.csv` put the model JSON where
/// the measurements were; `export m.json -o m.json` the table over the
/// model). `outputs` are (what, path) pairs, e.g. `("-o", …)` or `("the
/// history file", …)`; `inputs` likewise (`("the data file", …)`).
pub fn refuse_overwrite(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    for (what_out, out) in outputs {
        for (what_in, inp) in inputs {
            if same_file(out, inp) {
                anyhow::bail!(
                    "{what_out} {} is {what_in} {}: writing it would destroy the input; nothing was written — choose another output path",
                    out.display(),
                    inp.display()
                );
            }
        }
    }
    Ok(())
}

/// Adds `skipped_count` to a command's JSON document (an object).
pub fn add_skipped_count(doc: &mut serde_json::Value, data: &Dataset) {
    if let Some(obj) = doc.as_object_mut() {
        obj.insert(SKIPPED_KEY.into(), data.skipped.len().into());
    }
}

/// The first line of a CSV that is neither blank nor a comment, split
/// into cells.
pub fn header(text: &str) -> Vec<String> {
    text.trim_start_matches('\u{feff}')
        .lines()
        .map(|l| l.trim_end_matches('\r'))
        .find(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|l| l.split(',').map(|c| c.trim().to_string()).collect())
        .unwrap_or_default()
}

/// The lines in `path` of the rows [`scan_text`] gives for a session of
/// a measurement CSV with probe columns; `None` for a small scan file
/// (its own lines are the rows').
pub fn scan_lines(path: &Path, session: Option<i64>) -> Result<Option<Vec<usize>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !trueaxis_engine::onmachine::probe_csv::is_probe_csv(&text) {
        return Ok(None);
    }
    let t = trueaxis_engine::onmachine::probe_csv::read(&text, &path.display().to_string())?;
    Ok(Some(t.select(session)?.iter().map(|r| r.line).collect()))
}

/// The text of an on-machine command's scan file: the file itself, or —
/// for a measurement CSV with probe columns (`session_id`, `d_um`, …,
/// docs/cli.md § Measurement CSV) — one session of it written as the small
/// file `kind` the command reads (the same values, so the same results).
/// `--session` on a small file is refused.
pub fn scan_text(
    path: &Path,
    session: Option<i64>,
    kind: trueaxis_engine::onmachine::probe_csv::Small,
) -> Result<String> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    if trueaxis_engine::onmachine::probe_csv::is_probe_csv(&text) {
        let t = trueaxis_engine::onmachine::probe_csv::read(&text, &path.display().to_string())?;
        return t.small(session, kind);
    }
    if let Some(s) = session {
        anyhow::bail!(
            "--session {s}: {} is a scan file, not a measurement CSV with `session_id` and `d_um` columns",
            path.display()
        );
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_engine::data::SkippedRow;

    #[test]
    fn aux_columns_are_reported_with_the_column_they_probably_meant() {
        let aux = |name: &str| trueaxis_engine::data::AuxChannel {
            name: name.into(),
            cells: vec![],
        };
        let mut d = Dataset {
            source: "r5.csv".into(),
            ..Dataset::default()
        };
        assert!(aux_warnings(&d).is_empty());
        d.aux = vec![aux("ey [um]"), aux("feed"), aux("T_bed")];
        assert_eq!(
            aux_warnings(&d),
            vec![
                Warning::new(
                    "aux_misspelled",
                    "r5.csv: columns are kept as auxiliary and not fitted, though the name looks like a contract column written another way: `ey [um]` (probably `ey_um`), `T_bed` (probably `T_bed_C`) — rename the header to the contract name to use it"
                ),
                Warning::new(
                    "aux_columns",
                    "r5.csv: auxiliary column is kept, not used by any model: `feed`"
                ),
            ]
        );
    }

    #[test]
    fn an_output_that_is_an_input_is_refused() {
        let dir = std::env::temp_dir().join(format!("trueaxis-input-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let data = dir.join("d.csv");
        std::fs::write(&data, "x_mm,ex_um\n0,1\n").unwrap();
        let other = dir.join("m.json");
        // Not yet existing, or another file: fine.
        assert!(refuse_overwrite(&[("the data file", &data)], &[("-o", &other)]).is_ok());
        std::fs::write(&other, "{}").unwrap();
        assert!(refuse_overwrite(&[("the data file", &data)], &[("-o", &other)]).is_ok());
        // The same file by another spelling of its path.
        let spelled = dir.join("sub").join("..").join("d.csv");
        let e = refuse_overwrite(
            &[("the data file", &data)],
            &[("-o", &other), ("the history file", &spelled)],
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            format!(
                "the history file {} is the data file {}: writing it would destroy the input; nothing was written — choose another output path",
                spelled.display(),
                data.display()
            )
        );
        #[cfg(unix)]
        {
            let link = dir.join("hard.csv");
            let _ = std::fs::remove_file(&link);
            std::fs::hard_link(&data, &link).unwrap();
            assert!(same_file(&link, &data));
            let sym = dir.join("sym.csv");
            let _ = std::fs::remove_file(&sym);
            std::os::unix::fs::symlink(&data, &sym).unwrap();
            assert!(same_file(&sym, &data));
        }
        assert_eq!(std::fs::read_to_string(&data).unwrap(), "x_mm,ex_um\n0,1\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }

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
