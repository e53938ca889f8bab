//! Measurement import: the CSV of docs/cli.md § Measurement CSV (read and write) and
//! Renishaw `.rtl` linear-laser files, both into [`Dataset`].
//!
//! Every error names the file, the line and (where there is one) the column,
//! and says what was expected; the commands turn it into exit code 1. Rows
//! that are left out are recorded in [`Dataset::skipped`] with the reason —
//! nothing is silently dropped (docs/cli.md § Measurement CSV).

mod csv_io;
mod dialect;
mod rtl;

use std::fmt;
use std::path::Path;

use anyhow::Context;

use crate::data::Dataset;

pub use csv_io::{column_names, probable_column, read_csv, write_csv};
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
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.column {
            Some(c) => write!(f, "{}:{}:{}: {}", self.file, self.line, c, self.message),
            None => write!(f, "{}:{}: {}", self.file, self.line, self.message),
        }
    }
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
        }
    }
}

/// Loads a measurement file, choosing the reader by extension (`.csv`,
/// `.rtl`, case-insensitive). The result has passed [`Dataset::validate`].
pub fn load(path: &Path) -> anyhow::Result<Dataset> {
    load_with_axis(path, None)
}

/// As [`load`], but for `.rtl` files `axis` (0 = x) overrides the axis named
/// in the file's `USER-TEXT::` section (needed when that line is missing).
pub fn load_with_axis(path: &Path, axis: Option<usize>) -> anyhow::Result<Dataset> {
    let name = path.display().to_string();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {name}"))?;
    let ds = match ext.as_str() {
        "csv" => read_csv(bytes.as_slice(), &name)?,
        "rtl" => {
            let text = String::from_utf8_lossy(&bytes);
            read_rtl(&text, &name, axis)?
        }
        other => anyhow::bail!("{name}: unknown file type `.{other}` (expected .csv or .rtl)"),
    };
    ds.validate()?;
    Ok(ds)
}
