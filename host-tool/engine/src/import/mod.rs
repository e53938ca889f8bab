//! Measurement import: the CSV of docs/cli.md § Measurement CSV (read and write),
//! Renishaw `.rtl` linear-laser files, ecmc ISO 230-2 `.dat` runs and the bed
//! maps of RepRapFirmware (`heightmap.csv`) and Klipper (`[bed_mesh]` in
//! `printer.cfg`), all into [`Dataset`].
//!
//! Every error names the file, the line and (where there is one) the column,
//! and says what was expected; the commands turn it into exit code 1. Rows
//! that are left out are recorded in [`Dataset::skipped`] with the reason —
//! nothing is silently dropped (docs/cli.md § Measurement CSV).

mod bedmesh;
mod codepage;
mod csv_io;
mod dialect;
mod ecmc;
mod rtl;

use std::fmt;
use std::path::Path;

use anyhow::Context;

use crate::data::Dataset;

pub use bedmesh::{klipper_profiles, read_klipper_mesh, read_rrf_heightmap};
pub use csv_io::{column_names, probable_column, read_csv, windows_1252, write_csv, ENCODING_NOTE};
pub use ecmc::read_ecmc;
pub use rtl::read_rtl;

/// SHA-256 (hex) of the data set's canonical CSV ([`write_csv`]): the same
/// measurements give the same hash whatever file they came from, so a
/// MODEL.json can name the data it was fitted to.
pub fn content_hash(data: &Dataset) -> String {
    use sha2::{Digest, Sha256};
    let mut buf = Vec::new();
    // Writing to a Vec cannot fail.
    write_csv(data, &mut buf).expect("writing CSV to memory");
    Sha256::digest(&buf)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The most characters of an input cell, header or line a message quotes.
pub const SHOWN_CHARS: usize = 80;

/// An input cell, header or line as a message quotes it — every import
/// error and every warning or note that echoes input goes through here:
/// control characters (an escape sequence that would reach the terminal, a
/// NUL, a carriage return) and the invisible bidirectional controls
/// escaped as `\u{1b}`, and a text of more than [`SHOWN_CHARS`]
/// characters cut there with `… (N bytes)` (N its whole length), so a
/// 50 MB cell is not echoed whole (docs/cli.md § Measurement CSV).
pub fn shown(s: &str) -> String {
    let mut out = String::new();
    let mut chars = s.chars();
    for c in chars.by_ref().take(SHOWN_CHARS) {
        push_escaped(&mut out, c);
    }
    if chars.next().is_some() {
        out.push_str(&format!("… ({} bytes)", s.len()));
    }
    out
}

/// `text` (a whole message) with its control characters escaped as in
/// [`shown`], line ends and tabs kept: what the CLI prints on the
/// terminal, whatever an input slipped into it.
pub fn escape_controls(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c == '\n' || c == '\t' {
            out.push(c);
        } else {
            push_escaped(&mut out, c);
        }
    }
    out
}

/// `c`, or its `\u{…}` escape when it is a control character or a
/// bidirectional control (which reorder the text a terminal shows).
fn push_escaped(out: &mut String, c: char) {
    let bidi = matches!(c, '\u{200e}' | '\u{200f}' | '\u{061c}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}');
    if c.is_control() || bidi {
        out.extend(c.escape_unicode());
    } else {
        out.push(c);
    }
}

/// A problem in an input file, located as precisely as the format allows.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct ImportError {
    /// The file name as given (or a label for in-memory data).
    pub file: String,
    /// 1-based line number.
    pub line: usize,
    /// 1-based column (CSV cell index, or the field's position on an .rtl
    /// line); `None` when the problem is the whole line or file.
    pub column: Option<usize>,
    /// What was wrong and what was expected.
    pub message: String,
    /// The choice the file leaves to its reader's caller, when that is
    /// what is missing (a caller names its own way of giving it: the CLI,
    /// a flag).
    pub needs: Option<Needs>,
}

/// What a file does not say and its reader must be told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Needs {
    /// The machine axis of an ecmc ISO230 file (it never names it).
    EcmcAxis,
    /// The machine axis of an .rtl file without an `Axis:` line.
    RtlAxis,
    /// Which of a Klipper config's bed mesh profiles to read.
    Profile {
        /// The profiles the file saves.
        profiles: Vec<String>,
    },
}

impl ImportError {
    /// `file:line` or `file:line:column`, as the message is prefixed.
    pub fn location(&self) -> String {
        match self.column {
            Some(c) => format!("{}:{}:{}", self.file, self.line, c),
            None => format!("{}:{}", self.file, self.line),
        }
    }

    /// The error, as one that the caller's choice `n` would avoid.
    pub(crate) fn needing(mut self, n: Needs) -> Self {
        self.needs = Some(n);
        self
    }
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.location(), self.message)
    }
}

/// A load option that does not fit the file (a caller names its own way
/// of giving it: the CLI, a flag).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LoadError {
    /// A bed mesh profile named for a file that is no Klipper config.
    #[error("{file}: a bed mesh profile is named, which only a Klipper config holds; expected a .cfg file")]
    ProfileNotCfg {
        /// The file as given.
        file: String,
    },
}

impl ImportError {
    pub(crate) fn at(
        file: &str,
        line: usize,
        column: Option<usize>,
        msg: impl Into<String>,
    ) -> Self {
        ImportError {
            file: file.to_string(),
            line,
            column,
            message: msg.into(),
            needs: None,
        }
    }
}

/// Loads a measurement file, choosing the reader by extension and content
/// (docs/cli.md § import). The result has passed [`Dataset::validate`].
pub fn load(path: &Path) -> anyhow::Result<Dataset> {
    load_with(path, &LoadOptions::default())
}

/// As [`load`], but for `.rtl` files `axis` (0 = x) overrides the axis named
/// in the file's `USER-TEXT::` section (needed when that line is missing).
pub fn load_with_axis(path: &Path, axis: Option<usize>) -> anyhow::Result<Dataset> {
    load_with(
        path,
        &LoadOptions {
            axis,
            profile: None,
        },
    )
}

/// What a file may need beyond its bytes.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// The machine axis (0 = x) of a one-axis file: an `.rtl` without an
    /// `Axis:` line (overrides it), an ecmc `*_ISO230.dat` (required).
    pub axis: Option<usize>,
    /// The Klipper bed mesh profile to read when a config holds several.
    pub profile: Option<String>,
}

/// Loads a measurement file: `.csv` (the contract CSV, or a
/// RepRapFirmware `heightmap.csv` recognised by its first line), `.rtl`
/// (Renishaw), `.dat` (ecmc ISO 230-2), `.cfg` (a Klipper config with a
/// saved bed mesh). The result has passed [`Dataset::validate`].
pub fn load_with(path: &Path, opts: &LoadOptions) -> anyhow::Result<Dataset> {
    let name = path.display().to_string();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {name}"))?;
    let text = || String::from_utf8_lossy(&bytes);
    if opts.profile.is_some() && ext != "cfg" {
        return Err(LoadError::ProfileNotCfg { file: name }.into());
    }
    let ds = match ext.as_str() {
        "csv" if bedmesh::is_rrf_heightmap(&text()) => read_rrf_heightmap(&text(), &name)?,
        // Excel's "Unicode text" (.txt, UTF-16, tab-separated) and tab-
        // separated files (.tsv) are the CSV with another delimiter, which
        // the reader detects (issue 28: "unknown file type").
        "csv" | "txt" | "tsv" => read_csv(bytes.as_slice(), &name)?,
        "rtl" => {
            // Metadata in a legacy code page (Windows-1251/1252) decoded,
            // and said (issue 24: garbled Cyrillic USER-TEXT).
            let (text, code_page) = codepage::decode(&bytes);
            let mut ds = read_rtl(&text, &name, opts.axis)?;
            if let Some(cp) = code_page {
                ds.metadata.push((
                    ENCODING_NOTE.into(),
                    format!("not valid UTF-8: read as {cp}, the code page of the PC that wrote it"),
                ));
            }
            ds
        }
        "dat" if ecmc::is_ecmc_iso230(&text()) => read_ecmc(&text(), &name, opts.axis)?,
        "dat" => anyhow::bail!(
            "{name}: a .dat file without TGT_DATA[i]= lines; expected an ecmc ISO230 file (TGT_DATA, REF_DATA_FWD, REF_DATA_BWD)"
        ),
        "cfg" => read_klipper_mesh(&text(), &name, opts.profile.as_deref())?,
        other => anyhow::bail!(
            "{name}: unknown file type `.{other}` (expected .csv, .txt/.tsv (tab-separated, Excel's \"Unicode text\"), .rtl, .dat (ecmc ISO 230-2) or .cfg (Klipper bed mesh))"
        ),
    };
    ds.validate()?;
    Ok(ds)
}

/// Reads two named numeric columns of a small CSV: [`read_table`] for two
/// columns.
pub fn read_columns(
    text: &str,
    name: &str,
    columns: [&str; 2],
    what: &str,
) -> anyhow::Result<Vec<[f64; 2]>> {
    Ok(read_table(text, name, &columns, what)?
        .into_iter()
        .map(|r| [r[0], r[1]])
        .collect())
}

/// The data lines of a comma-separated text: (line number, the line, its
/// cells trimmed), past a byte-order mark, with blank lines and `#`
/// comments skipped.
pub(crate) fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str, Vec<&str>)> {
    text.trim_start_matches('\u{feff}')
        .lines()
        .enumerate()
        .filter_map(|(i, raw)| {
            let line = raw.trim_end_matches('\r');
            (!(line.trim().is_empty() || line.trim_start().starts_with('#')))
                .then(|| (i + 1, line, line.split(',').map(str::trim).collect()))
        })
}

/// Reads named numeric columns of a small CSV (a header line, `#` comment
/// lines, other columns ignored): probe scans, reversal runs, workpiece
/// scans (docs/on-machine.md). A `*_mm` value must lie within ±10 000 mm, a
/// `*_um` value within ±10 000 µm (the measurement CSV's plausibility
/// limits), a `*_deg` value within ±3600°, a `*_s` time stamp within
/// ±3.2·10⁷ s; `what` says what the columns
/// are in the message for a header without them. Returns one row per line
/// with the values in the order of `columns` and, last, the line number.
/// Errors name the file, line and column.
pub fn read_table(
    text: &str,
    name: &str,
    columns: &[&str],
    what: &str,
) -> anyhow::Result<Vec<Vec<f64>>> {
    let mut rows = Vec::new();
    let mut cols: Option<Vec<usize>> = None;
    for (ln, line, cells) in data_lines(text) {
        let Some(c) = &cols else {
            let found: Option<Vec<usize>> = columns
                .iter()
                .map(|h| cells.iter().position(|c| c == h))
                .collect();
            match found {
                Some(f) => cols = Some(f),
                None => anyhow::bail!(
                    "{name}:{ln}: the header needs {} ({what}), found `{}`",
                    columns
                        .iter()
                        .map(|c| format!("`{c}`"))
                        .collect::<Vec<_>>()
                        .join(" and "),
                    shown(line)
                ),
            }
            continue;
        };
        let mut v = Vec::with_capacity(columns.len() + 1);
        for (k, &j) in c.iter().enumerate() {
            let cell = cells.get(j).copied().unwrap_or("");
            let (limit, unit) = if columns[k].ends_with("_um") {
                (crate::data::ERR_PLAUSIBLE_UM, "µm")
            } else if columns[k].ends_with("_deg") {
                (3600.0, "°")
            } else if columns[k].ends_with("_s") {
                // Time stamps: up to a year of seconds.
                (3.2e7, "s")
            } else {
                (crate::data::POS_PLAUSIBLE_MM, "mm")
            };
            v.push(match cell.parse::<f64>() {
                Ok(x) if x.is_finite() && x.abs() <= limit => x,
                _ => anyhow::bail!(
                    "{name}:{ln}:{}: `{}`: expected a finite number within ±{limit} {unit}, found `{}`",
                    j + 1,
                    columns[k],
                    shown(cell)
                ),
            });
        }
        v.push(ln as f64);
        rows.push(v);
    }
    if cols.is_none() {
        anyhow::bail!("{name}: no header line; expected {}", columns.join(","));
    }
    Ok(rows)
}
