//! The measurement CSV of docs/cli.md § Measurement CSV: reader with located errors, and a
//! writer whose output the reader turns back into the same [`Dataset`].
//!
//! Columns are recognised by name. A name whose stem is a contract quantity
//! but whose unit suffix is not the contract's (`x_in`, `ex_nm`, `T_bed_F`)
//! is an error rather than an auxiliary channel: silently treating `ex_nm`
//! as an unknown column would drop the errors the user meant to fit.

use std::io::{Read, Write};

use anyhow::Context;

use super::dialect::{dialect, utf16_text};
use super::{shown, ImportError};
use crate::data::{
    is_unit, AuxChannel, Dataset, SkippedRow, TempChannel, ANGLES, ANGLE_PLAUSIBLE_URAD, AXES,
    ERR_PLAUSIBLE_UM, POS_PLAUSIBLE_MM, TARGETS, TEMP_PLAUSIBLE_C,
};

/// What a column means.
#[derive(Clone, Debug, PartialEq)]
enum Col {
    Pos(usize),
    Err(usize),
    Time,
    Dir(usize),
    Temp(String),
    Tool,
    Pass,
    Session,
    U,
    Aux,
    /// `tool_x_mm` (0), `tool_y_mm` (1).
    ToolLat(usize),
    Setup,
    /// `ea_urad`, `eb_urad`, `ec_urad`.
    Angle(usize),
    /// `beam_x`, `beam_y`, `beam_z`.
    BeamDir(usize),
    /// `e_beam_um`.
    BeamErr,
}

/// The volumetric columns' stems and units (docs/volumetric.md): a unit
/// suffix other than the contract's is refused (`ea_mrad`), any other
/// suffix stays auxiliary, as for `t`, `tool` and `u`.
const VOLUMETRIC_STEMS: [(&str, &str); 6] = [
    ("ea", "urad"),
    ("eb", "urad"),
    ("ec", "urad"),
    ("e_beam", "um"),
    ("tool_x", "mm"),
    ("tool_y", "mm"),
];

/// Quantity stems and the one unit suffix the contract gives each.
const STEMS: [(&str, &str); 9] = [
    ("x", "mm"),
    ("y", "mm"),
    ("z", "mm"),
    ("ex", "um"),
    ("ey", "um"),
    ("ez", "um"),
    ("t", "s"),
    ("tool", "mm"),
    ("u", "um"),
];

/// Unit suffixes recognised as units (lower case), so that `t_min` or
/// `tool_in` is reported as a wrong unit rather than kept as an unknown
/// column.
const UNITS: [&str; 22] = [
    "m", "dm", "cm", "mm", "um", "µm", "nm", "in", "inch", "mil", "ft", "s", "ms", "min", "h",
    "hr", "us", "mrad", "urad", "rad", "deg", "arcsec",
];

/// Classifies a header cell; `Err` carries the message for a bad name.
fn classify(name: &str) -> Result<Col, String> {
    for a in 0..3 {
        if name == format!("{}_mm", AXES[a]) {
            return Ok(Col::Pos(a));
        }
        if name == format!("{}_um", TARGETS[a]) {
            return Ok(Col::Err(a));
        }
        if name == format!("dir_{}", AXES[a]) {
            return Ok(Col::Dir(a));
        }
    }
    match name {
        "t_s" => return Ok(Col::Time),
        "tool_mm" => return Ok(Col::Tool),
        "pass_id" => return Ok(Col::Pass),
        "session_id" => return Ok(Col::Session),
        "u_um" => return Ok(Col::U),
        "tool_x_mm" => return Ok(Col::ToolLat(0)),
        "tool_y_mm" => return Ok(Col::ToolLat(1)),
        "setup_id" => return Ok(Col::Setup),
        "ea_urad" => return Ok(Col::Angle(0)),
        "eb_urad" => return Ok(Col::Angle(1)),
        "ec_urad" => return Ok(Col::Angle(2)),
        "beam_x" => return Ok(Col::BeamDir(0)),
        "beam_y" => return Ok(Col::BeamDir(1)),
        "beam_z" => return Ok(Col::BeamDir(2)),
        "e_beam_um" => return Ok(Col::BeamErr),
        _ => {}
    }
    if let Some(rest) = name.strip_prefix("T_") {
        if let Some(sensor) = rest.strip_suffix("_C") {
            if sensor.is_empty() {
                return Err(format!(
                    "column `{}`: expected a sensor name, as in `T_bed_C`",
                    shown(name)
                ));
            }
            return Ok(Col::Temp(sensor.to_string()));
        }
        if let Some((sensor, unit)) = rest.rsplit_once('_') {
            return Err(format!(
                "column `{}`: unknown unit suffix `_{}` for a temperature; expected `T_{}_C` (°C)",
                shown(name),
                shown(unit),
                shown(sensor)
            ));
        }
    }
    let lower = name.to_ascii_lowercase();
    for (stem, unit) in STEMS {
        let canonical = format!("{stem}_{unit}");
        if lower == canonical {
            return Err(format!(
                "column `{}`: expected `{canonical}` (column names are case-sensitive)",
                shown(name)
            ));
        }
        if name == stem {
            return Err(format!(
                "column `{}` has no unit suffix; expected `{canonical}`",
                shown(name)
            ));
        }
        if let Some(unit_found) = name.strip_prefix(stem).and_then(|r| r.strip_prefix('_')) {
            // Positions and errors: any suffix is a unit mistake (`x_in`,
            // `ex_nm`, `x_ref`…). For `t`, `tool` and `u` only a suffix that
            // is a unit is, so that `t_start` or `u_raw` stay auxiliary.
            let strict = matches!(stem, "x" | "y" | "z" | "ex" | "ey" | "ez");
            if strict || UNITS.contains(&unit_found.to_ascii_lowercase().as_str()) {
                return Err(format!(
                    "column `{}`: unknown unit suffix `_{}`; expected `{canonical}`",
                    shown(name),
                    shown(unit_found)
                ));
            }
        }
    }
    for (stem, unit) in VOLUMETRIC_STEMS {
        let canonical = format!("{stem}_{unit}");
        if lower == canonical {
            return Err(format!(
                "column `{}`: expected `{canonical}` (column names are case-sensitive)",
                shown(name)
            ));
        }
        if let Some(unit_found) = name.strip_prefix(stem).and_then(|r| r.strip_prefix('_')) {
            if UNITS.contains(&unit_found.to_ascii_lowercase().as_str()) {
                return Err(format!(
                    "column `{}`: unknown unit suffix `_{}`; expected `{canonical}`",
                    shown(name),
                    shown(unit_found)
                ));
            }
        }
    }
    for fixed in ["setup_id", "beam_x", "beam_y", "beam_z"] {
        if lower == fixed {
            return Err(format!(
                "column `{}`: expected `{fixed}` (column names are case-sensitive)",
                shown(name)
            ));
        }
    }
    // The other names differing only in case are refused like `X_mm`: a
    // `dir_X` kept as an auxiliary channel would silently drop the
    // directions the user meant to give.
    for fixed in ["dir_x", "dir_y", "dir_z", "pass_id", "session_id"] {
        if lower == fixed {
            return Err(format!(
                "column `{}`: expected `{fixed}` (column names are case-sensitive)",
                shown(name)
            ));
        }
    }
    if lower.len() > 4 && lower.starts_with("t_") && lower.ends_with("_c") {
        return Err(format!(
            "column `{}`: expected `T_{}_C` (column names are case-sensitive)",
            shown(name),
            shown(&name[2..name.len() - 2])
        ));
    }
    Ok(Col::Aux)
}

/// The contract column an auxiliary column's name probably meant, when it
/// differs from one by more than case (which [`classify`] refuses): by
/// spaces, brackets or other punctuation, a `µ` for `u`, or a missing unit
/// suffix — `ey [um]`, `ey(um)`, `y (mm)`, `Ex` → `ex_um`; `T_bed`,
/// `T_bed [C]`, `temp bed` → `T_bed_C`. `None` for a name like none of them
/// (`feed`, `t_start`).
pub fn probable_column(name: &str) -> Option<String> {
    let mut canon = String::new();
    for c in name.chars() {
        let c = match c {
            'µ' | 'μ' => 'u',
            c => c.to_ascii_lowercase(),
        };
        if c.is_ascii_alphanumeric() {
            canon.push(c);
        } else if !canon.is_empty() && !canon.ends_with('_') {
            canon.push('_');
        }
    }
    let canon = canon.trim_end_matches('_');
    let fixed = ["dir_x", "dir_y", "dir_z", "pass_id", "session_id"];
    for (stem, unit) in STEMS {
        if canon == stem || canon == format!("{stem}_{unit}") {
            return Some(format!("{stem}_{unit}"));
        }
    }
    if let Some(f) = fixed.iter().find(|f| **f == canon) {
        return Some(f.to_string());
    }
    let sensor = if let Some(mid) = canon.strip_prefix("t_").and_then(|r| r.strip_suffix("_c")) {
        Some(mid)
    } else if name.starts_with("T_") {
        canon.strip_prefix("t_")
    } else {
        canon
            .strip_prefix("temperature_")
            .or_else(|| canon.strip_prefix("temp_"))
            .map(|r| r.strip_suffix("_c").unwrap_or(r))
    };
    sensor.filter(|s| !s.is_empty()).map(|s| format!("T_{s}_C"))
}

/// The header's names that are probably contract columns written another
/// way, as "; the header has `x (mm)` → x_mm, `ex [um]` → ex_um — rename
/// them" (empty when none is): a header that misses the contract names
/// is answered with the closest ones (issue 28).
fn closest_names(names: &[String]) -> String {
    let pairs: Vec<String> = names
        .iter()
        .filter_map(|n| {
            probable_column(n)
                .filter(|p| p != n)
                .map(|p| format!("`{n}` → {p}"))
        })
        .collect();
    if pairs.is_empty() {
        String::new()
    } else {
        format!(
            "; the header has {} — rename {} so",
            pairs.join(", "),
            if pairs.len() == 1 { "it" } else { "them" }
        )
    }
}

/// Parses a finite number or says what was expected. With `decimal_comma`
/// (a `;`-separated file, as Excel writes it where the comma is the
/// decimal mark) `1,5` reads as 1.5.
fn parse_num(cell: &str, col_name: &str, decimal_comma: bool) -> Result<f64, String> {
    let t = cell.trim();
    let dotted;
    let t = if decimal_comma && t.matches(',').count() == 1 && !t.contains('.') {
        dotted = t.replacen(',', ".", 1);
        dotted.as_str()
    } else {
        t
    };
    let v: f64 = t.parse().map_err(|_| {
        format!(
            "column `{}`: expected a number, found `{}`",
            shown(col_name),
            shown(cell)
        )
    })?;
    if !v.is_finite() {
        return Err(format!(
            "column `{}`: expected a finite number, found `{}`",
            shown(col_name),
            shown(cell)
        ));
    }
    Ok(v)
}

/// Parses a number and checks |value| ≤ `limit` (a position or an error
/// beyond it is a unit mistake or a broken reading, not a measurement).
fn parse_bounded(
    cell: &str,
    col_name: &str,
    decimal_comma: bool,
    limit: f64,
    what: &str,
) -> Result<f64, String> {
    let v = parse_num(cell, col_name, decimal_comma)?;
    if v.abs() > limit {
        return Err(format!(
            "column `{}`: expected {what} between -{limit} and {limit}, found `{}` — check the column's unit (and the instrument's reading at this line)",
            shown(col_name),
            shown(cell)
        ));
    }
    Ok(v)
}

/// Parses a temperature in °C and checks that it is plausible
/// ([`TEMP_PLAUSIBLE_C`]); a value in 250…400 is named as likely kelvin.
fn parse_temp(cell: &str, col_name: &str, decimal_comma: bool) -> Result<f64, String> {
    let v = parse_num(cell, col_name, decimal_comma)?;
    let (lo, hi) = TEMP_PLAUSIBLE_C;
    if !(lo..=hi).contains(&v) {
        let hint = if (250.0..=400.0).contains(&v) {
            format!(
                " — {v} looks like kelvin ({:.2} °C); convert the column to °C (°C = K − 273.15)",
                v - 273.15
            )
        } else {
            String::new()
        };
        return Err(format!(
            "column `{}`: expected a temperature in °C between {lo} and {hi}, found `{}`{hint}",
            shown(col_name),
            shown(cell)
        ));
    }
    Ok(v)
}

/// Reads the measurement CSV from `reader`; `name` labels messages (the
/// path, or e.g. `<stdin>`). Fails on the first bad cell with
/// `name:line:column: what was expected`. The result has passed
/// [`Dataset::validate`].
pub fn read_csv<R: Read>(mut reader: R, name: &str) -> anyhow::Result<Dataset> {
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {name}"))?;
    let mut note = None;
    let text = match utf16_text(&bytes, name)? {
        Some(t) => t,
        None => match String::from_utf8(bytes) {
            Ok(t) => t,
            // Excel's "CSV" in a Western European locale (German, French,
            // …) is Windows-1252: `°C`, `µm`, `ü` as single bytes that are
            // not UTF-8; a Cyrillic one is Windows-1251. Read as that, and
            // say so (issue 28: refused without a hint).
            Err(e) => {
                let (text, how) = super::legacy::decode(e.as_bytes());
                if let Some((page, line)) = how {
                    note = Some(super::legacy::note(page, line));
                }
                text.into_owned()
            }
        },
    };
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let mut ds = parse(text, name)?;
    if let Some(n) = note {
        ds.metadata.push((ENCODING_NOTE.into(), n));
    }
    ds.validate()?;
    Ok(ds)
}

/// The metadata key under which the reader says it decoded the file as
/// Windows-1252 (the CLI prints it as a note).
pub const ENCODING_NOTE: &str = "encoding";

/// Windows-1252 bytes as text: ASCII and 0xA0–0xFF are Latin-1 (the code
/// point is the byte); 0x80–0x9F are the code page's own (€, ‚, „, …, ™);
/// the five bytes it leaves undefined become U+FFFD.
pub fn windows_1252(bytes: &[u8]) -> String {
    const HIGH: [char; 32] = [
        '€', '\u{fffd}', '‚', 'ƒ', '„', '…', '†', '‡', 'ˆ', '‰', 'Š', '‹', 'Œ', '\u{fffd}', 'Ž',
        '\u{fffd}', '\u{fffd}', '‘', '’', '“', '”', '•', '–', '—', '˜', '™', 'š', '›', 'œ',
        '\u{fffd}', 'ž', 'Ÿ',
    ];
    bytes
        .iter()
        .map(|&b| match b {
            0x80..=0x9f => HIGH[usize::from(b - 0x80)],
            b => char::from(b),
        })
        .collect()
}

fn parse(text: &str, name: &str) -> Result<Dataset, ImportError> {
    let mut ds = Dataset {
        source: name.to_string(),
        ..Dataset::default()
    };
    // Metadata: `#` lines (and blank lines) before the header.
    let mut offset = 0;
    let mut header_line = 1;
    for raw in text.split_inclusive('\n') {
        let line = raw.trim_end_matches(['\n', '\r']);
        let trimmed = line.trim_start();
        if let Some(meta) = trimmed.strip_prefix('#') {
            let meta = meta.trim();
            match meta.split_once(':') {
                Some((k, v)) => ds
                    .metadata
                    .push((k.trim().to_string(), v.trim().to_string())),
                None => ds.metadata.push((String::new(), meta.to_string())),
            }
        } else if !trimmed.is_empty() {
            break;
        }
        offset += raw.len();
        header_line += 1;
    }
    let body = &text[offset..];
    if body.trim().is_empty() {
        return Err(ImportError::at(
            name,
            header_line,
            None,
            "expected a header row (x_mm, ex_um, …), found end of file",
        ));
    }
    let (delimiter, dc) = dialect(body);
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(delimiter)
        .from_reader(body.as_bytes());
    let mut records = rdr.records();
    // The file line of a record from its byte offset. csv's own line count
    // lags by one after a CRLF (the record is cut at `\r`, the `\n` is
    // consumed later), so count newlines instead; an offset that sits on
    // the `\n` of a CRLF belongs to the next line.
    let newlines: Vec<usize> = body
        .bytes()
        .enumerate()
        .filter(|(_, b)| *b == b'\n')
        .map(|(i, _)| i)
        .collect();
    let bytes = body.as_bytes();
    let file_line = |pos: Option<&csv::Position>| -> usize {
        pos.map_or(header_line, |p| {
            let mut at = p.byte() as usize;
            while at < bytes.len() && (bytes[at] == b'\n' || bytes[at] == b'\r') {
                at += 1;
            }
            header_line + newlines.partition_point(|&nl| nl < at)
        })
    };
    let csv_err = |e: csv::Error| {
        let line = file_line(e.position());
        ImportError::at(name, line, None, format!("malformed CSV: {e}"))
    };
    let header = match records.next() {
        Some(r) => r.map_err(csv_err)?,
        None => {
            return Err(ImportError::at(
                name,
                header_line,
                None,
                "expected a header row",
            ))
        }
    };
    let mut names: Vec<String> = header.iter().map(|h| h.trim().to_string()).collect();
    // Empty columns at the end (a spreadsheet's `;;` after the data) are
    // not columns: dropped here, their cells must be empty in every row.
    let used = names
        .iter()
        .rposition(|n| !n.is_empty())
        .map_or(0, |i| i + 1);
    let trailing = names.len() - used;
    names.truncate(used);
    let mut cols = Vec::with_capacity(names.len());
    for (i, h) in names.iter().enumerate() {
        if let Some(first) = names[..i].iter().position(|p| p == h) {
            return Err(ImportError::at(
                name,
                header_line,
                Some(i + 1),
                format!(
                    "duplicate column `{}` (first at column {})",
                    shown(h),
                    first + 1
                ),
            ));
        }
        if h.is_empty() {
            return Err(ImportError::at(
                name,
                header_line,
                Some(i + 1),
                "empty column name; expected a name such as x_mm or ex_um",
            ));
        }
        cols.push(classify(h).map_err(|m| ImportError::at(name, header_line, Some(i + 1), m))?);
    }
    if !cols.iter().any(|c| matches!(c, Col::Pos(_))) {
        // A time series written without positions (a thermal test at one
        // point): say how to give it one rather than only what is missing.
        let hint = if cols.iter().any(|c| matches!(c, Col::Time)) {
            "; a time series measured at one point (a thermal test) still needs the point: add it as a constant column, e.g. x_mm with the same value on every row"
        } else {
            ""
        };
        return Err(ImportError::at(
            name,
            header_line,
            None,
            format!(
                "no position column; expected at least one of x_mm, y_mm, z_mm{hint}{}",
                closest_names(&names)
            ),
        ));
    }
    if !cols
        .iter()
        .any(|c| matches!(c, Col::Err(_) | Col::Angle(_) | Col::BeamErr))
    {
        return Err(ImportError::at(
            name,
            header_line,
            None,
            format!(
                "no error column; expected at least one of ex_um, ey_um, ez_um{}",
                closest_names(&names)
            ),
        ));
    }
    // A beam reading and its direction come together: all four columns or
    // none.
    let beam_cols: Vec<usize> = (0..3)
        .filter_map(|k| cols.iter().position(|c| *c == Col::BeamDir(k)))
        .collect();
    let beam_err_col = cols.iter().position(|c| *c == Col::BeamErr);
    if (beam_err_col.is_some() || !beam_cols.is_empty())
        && (beam_err_col.is_none() || beam_cols.len() != 3)
    {
        let at = beam_err_col.or(beam_cols.first().copied()).map(|i| i + 1);
        return Err(ImportError::at(
            name,
            header_line,
            at,
            "a beam reading needs all four columns e_beam_um, beam_x, beam_y, beam_z (the reading and its unit direction)",
        ));
    }

    // Column storage, filled row by row.
    let mut pos: [Option<Vec<f64>>; 3] = Default::default();
    let mut err: [Option<Vec<Option<f64>>>; 3] = Default::default();
    let mut dir: [Option<Vec<i8>>; 3] = Default::default();
    let mut t_s = None::<Vec<f64>>;
    let mut tool = None::<Vec<f64>>;
    let mut u = None::<Vec<f64>>;
    let mut pass = None::<Vec<i64>>;
    let mut session = None::<Vec<i64>>;
    let mut setup = None::<Vec<i64>>;
    let mut tool_lat: [Option<Vec<f64>>; 2] = Default::default();
    let mut angle: [Option<Vec<Option<f64>>>; 3] = Default::default();
    let mut beam_dir: Option<Vec<Option<[f64; 3]>>> = None;
    let mut beam_um = None::<Vec<Option<f64>>>;
    let mut temps: Vec<TempChannel> = Vec::new();
    let mut aux: Vec<AuxChannel> = Vec::new();
    for (c, h) in cols.iter().zip(&names) {
        match c {
            Col::Pos(a) => pos[*a] = Some(Vec::new()),
            Col::Err(a) => err[*a] = Some(Vec::new()),
            Col::Dir(a) => dir[*a] = Some(Vec::new()),
            Col::Time => t_s = Some(Vec::new()),
            Col::Tool => tool = Some(Vec::new()),
            Col::U => u = Some(Vec::new()),
            Col::Pass => pass = Some(Vec::new()),
            Col::Session => session = Some(Vec::new()),
            Col::Setup => setup = Some(Vec::new()),
            Col::ToolLat(k) => tool_lat[*k] = Some(Vec::new()),
            Col::Angle(k) => angle[*k] = Some(Vec::new()),
            Col::BeamDir(_) => beam_dir = Some(Vec::new()),
            Col::BeamErr => beam_um = Some(Vec::new()),
            Col::Temp(s) => temps.push(TempChannel {
                name: s.clone(),
                temp_c: Vec::new(),
            }),
            Col::Aux => aux.push(AuxChannel {
                name: h.clone(),
                cells: Vec::new(),
            }),
        }
    }

    /// One parsed cell, held until the whole row is known to be kept.
    enum Cell {
        F(f64),
        OptF(Option<f64>),
        D(i8),
        I(i64),
        S(String),
    }
    let mut row_cells: Vec<Cell> = Vec::with_capacity(cols.len());
    for rec in records {
        let rec = rec.map_err(csv_err)?;
        let line = file_line(rec.position());
        if rec.iter().all(|c| c.trim().is_empty()) {
            ds.skipped.push(SkippedRow {
                line,
                reason: "empty row".into(),
            });
            continue;
        }
        if rec.get(0).is_some_and(|c| c.trim_start().starts_with('#')) {
            ds.skipped.push(SkippedRow {
                line,
                reason: "comment line after the header".into(),
            });
            continue;
        }
        let extra_empty = rec.len() > cols.len()
            && rec.len() <= cols.len() + trailing
            && rec.iter().skip(cols.len()).all(|c| c.trim().is_empty());
        if rec.len() != cols.len() && !extra_empty {
            return Err(ImportError::at(
                name,
                line,
                Some(rec.len().min(cols.len()) + 1),
                format!(
                    "expected {} cells as in the header, found {}",
                    cols.len(),
                    rec.len()
                ),
            ));
        }
        row_cells.clear();
        let mut skip_reason: Option<String> = None;
        for (i, (c, cell)) in cols.iter().zip(rec.iter()).enumerate() {
            let at = |m: String| ImportError::at(name, line, Some(i + 1), m);
            let h = &names[i];
            let empty = cell.trim().is_empty();
            let needs_value = !matches!(
                c,
                Col::Err(_) | Col::Aux | Col::Angle(_) | Col::BeamDir(_) | Col::BeamErr
            );
            if empty && needs_value {
                skip_reason.get_or_insert_with(|| format!("empty `{}` cell", shown(h)));
                row_cells.push(Cell::F(0.0));
                continue;
            }
            row_cells.push(match c {
                Col::Err(_) | Col::Angle(_) | Col::BeamDir(_) | Col::BeamErr if empty => {
                    Cell::OptF(None)
                }
                Col::Angle(_) => Cell::OptF(Some(
                    parse_bounded(cell, h, dc, ANGLE_PLAUSIBLE_URAD, "an angle in µrad")
                        .map_err(at)?,
                )),
                Col::BeamErr => Cell::OptF(Some(
                    parse_bounded(cell, h, dc, ERR_PLAUSIBLE_UM, "an error in µm").map_err(at)?,
                )),
                Col::BeamDir(_) => Cell::OptF(Some(
                    parse_bounded(cell, h, dc, 1.0 + 1e-3, "a direction cosine").map_err(at)?,
                )),
                Col::Err(_) => Cell::OptF(Some(
                    parse_bounded(cell, h, dc, ERR_PLAUSIBLE_UM, "an error in µm").map_err(at)?,
                )),
                Col::Dir(_) => {
                    let v = cell.trim();
                    match v {
                        "1" | "+1" | "1.0" | "+1.0" => Cell::D(1),
                        "-1" | "-1.0" => Cell::D(-1),
                        _ => {
                            return Err(at(format!(
                                "column `{}`: expected -1 or +1, found `{}`",
                                shown(h),
                                shown(cell)
                            )))
                        }
                    }
                }
                Col::Pass | Col::Session | Col::Setup => {
                    Cell::I(cell.trim().parse().map_err(|_| {
                        at(format!(
                            "column `{}`: expected an integer, found `{}`",
                            shown(h),
                            shown(cell)
                        ))
                    })?)
                }
                Col::U => {
                    let v = parse_num(cell, h, dc).map_err(at)?;
                    if v <= 0.0 {
                        return Err(at(format!(
                            "column `{}`: expected a positive uncertainty, found `{}`",
                            shown(h),
                            shown(cell)
                        )));
                    }
                    Cell::F(v)
                }
                Col::Aux => Cell::S(cell.to_string()),
                Col::Temp(_) => Cell::F(parse_temp(cell, h, dc).map_err(at)?),
                Col::Pos(_) => Cell::F(
                    parse_bounded(cell, h, dc, POS_PLAUSIBLE_MM, "a position in mm").map_err(at)?,
                ),
                Col::Time | Col::Tool => Cell::F(parse_num(cell, h, dc).map_err(at)?),
                Col::ToolLat(_) => Cell::F(
                    parse_bounded(cell, h, dc, POS_PLAUSIBLE_MM, "an offset in mm").map_err(at)?,
                ),
            });
        }
        // The beam direction of this row: all three cells or none, a unit
        // vector, and given wherever e_beam_um is.
        let mut row_beam: Option<[f64; 3]> = None;
        if let Some(ei) = beam_err_col {
            let cell = |i: usize| match row_cells.get(i) {
                Some(Cell::OptF(v)) => *v,
                _ => None,
            };
            let d: Vec<Option<f64>> = beam_cols.iter().map(|&i| cell(i)).collect();
            let first_empty = beam_cols.iter().zip(&d).find(|(_, v)| v.is_none());
            if d.iter().all(Option::is_some) {
                let d = [
                    d[0].unwrap_or(0.0),
                    d[1].unwrap_or(0.0),
                    d[2].unwrap_or(0.0),
                ];
                if !is_unit(d) {
                    return Err(ImportError::at(
                        name,
                        line,
                        Some(beam_cols[0] + 1),
                        format!(
                            "beam direction ({}, {}, {}) has length {:.6}; expected a unit vector (direction cosines, length 1 within {})",
                            d[0],
                            d[1],
                            d[2],
                            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
                            crate::data::BEAM_UNIT_TOL
                        ),
                    ));
                }
                row_beam = Some(d);
            } else if cell(ei).is_some() || d.iter().any(Option::is_some) {
                let i = first_empty.map_or(ei, |(i, _)| *i);
                return Err(ImportError::at(
                    name,
                    line,
                    Some(i + 1),
                    format!(
                        "column `{}`: expected a number — a row with a beam reading needs its direction in beam_x, beam_y, beam_z",
                        shown(&names[i])
                    ),
                ));
            }
        }
        if skip_reason.is_none()
            && cols.iter().zip(&row_cells).all(|(c, v)| {
                !matches!(
                    (c, v),
                    (
                        Col::Err(_) | Col::Angle(_) | Col::BeamErr,
                        Cell::OptF(Some(_))
                    )
                )
            })
        {
            skip_reason = Some("no error value on this row".into());
        }
        if let Some(reason) = skip_reason {
            ds.skipped.push(SkippedRow { line, reason });
            continue;
        }
        let (mut ti, mut ai) = (0, 0);
        for (c, v) in cols.iter().zip(row_cells.drain(..)) {
            match (c, v) {
                (Col::Pos(a), Cell::F(x)) => pos[*a].as_mut().map(|p| p.push(x)),
                (Col::Err(a), Cell::OptF(x)) => err[*a].as_mut().map(|p| p.push(x)),
                (Col::Dir(a), Cell::D(d)) => dir[*a].as_mut().map(|p| p.push(d)),
                (Col::Time, Cell::F(x)) => t_s.as_mut().map(|p| p.push(x)),
                (Col::Tool, Cell::F(x)) => tool.as_mut().map(|p| p.push(x)),
                (Col::U, Cell::F(x)) => u.as_mut().map(|p| p.push(x)),
                (Col::Pass, Cell::I(x)) => pass.as_mut().map(|p| p.push(x)),
                (Col::Session, Cell::I(x)) => session.as_mut().map(|p| p.push(x)),
                (Col::Setup, Cell::I(x)) => setup.as_mut().map(|p| p.push(x)),
                (Col::ToolLat(k), Cell::F(x)) => tool_lat[*k].as_mut().map(|p| p.push(x)),
                (Col::Angle(k), Cell::OptF(x)) => angle[*k].as_mut().map(|p| p.push(x)),
                (Col::BeamErr, Cell::OptF(x)) => beam_um.as_mut().map(|p| p.push(x)),
                (Col::BeamDir(k), Cell::OptF(_)) => {
                    if *k == 0 {
                        if let Some(p) = beam_dir.as_mut() {
                            p.push(row_beam);
                        }
                    }
                    None
                }
                (Col::Temp(_), Cell::F(x)) => {
                    temps[ti].temp_c.push(x);
                    ti += 1;
                    None
                }
                (Col::Aux, Cell::S(s)) => {
                    aux[ai].cells.push(s);
                    ai += 1;
                    None
                }
                // Each column kind produces exactly its own cell kind above.
                _ => unreachable!("cell kind matches its column"),
            };
        }
        ds.line.push(line);
    }
    // Every writer of this format ends each row with a line end (trueaxis
    // always does; spreadsheets do). A last row without one is where a
    // write or copy that did not finish cut the file: its last cell may be
    // a number cut short (`35` → `3`), which reads as a valid value. It is
    // refused, never fitted (docs/cli.md § Measurement CSV).
    if !body.ends_with(['\n', '\r']) {
        let tail = body[body.rfind('\n').map_or(0, |i| i + 1)..].trim();
        let line = header_line + newlines.len();
        if line > header_line && !tail.is_empty() && !tail.starts_with('#') {
            return Err(ImportError::at(
                name,
                line,
                None,
                "the last row has no line end: the file looks cut off in this row (a write or copy that did not finish), so its last cell may be cut short — if the row is whole, end the file with a line break",
            ));
        }
    }
    if ds.line.is_empty() {
        let last = text.lines().count().max(header_line);
        return Err(ImportError::at(
            name,
            last,
            None,
            format!(
                "no data rows after the header ({} rows left out)",
                ds.skipped.len()
            ),
        ));
    }
    ds.pos_mm = pos;
    ds.err_um = err;
    ds.dir = dir;
    ds.t_s = t_s;
    ds.tool_mm = tool;
    ds.u_um = u;
    ds.pass_id = pass;
    ds.session_id = session;
    ds.setup_id = setup;
    ds.tool_lat_mm = tool_lat;
    ds.angle_urad = angle;
    ds.beam_dir = beam_dir;
    ds.beam_um = beam_um;
    ds.temps = temps;
    ds.aux = aux;
    Ok(ds)
}

/// The header `write_csv` writes for `data`, in order.
pub fn column_names(data: &Dataset) -> Vec<String> {
    let mut h = Vec::new();
    h.extend(
        (0..3)
            .filter(|&a| data.pos_mm[a].is_some())
            .map(|a| format!("{}_mm", AXES[a])),
    );
    h.extend(
        (0..3)
            .filter(|&t| data.err_um[t].is_some())
            .map(|t| format!("{}_um", TARGETS[t])),
    );
    h.extend(
        (0..3)
            .filter(|&a| data.angle_urad[a].is_some())
            .map(|a| format!("{}_urad", ANGLES[a])),
    );
    if data.beam_um.is_some() {
        h.extend(["e_beam_um", "beam_x", "beam_y", "beam_z"].map(String::from));
    }
    if data.t_s.is_some() {
        h.push("t_s".into());
    }
    h.extend(
        (0..3)
            .filter(|&a| data.dir[a].is_some())
            .map(|a| format!("dir_{}", AXES[a])),
    );
    h.extend(data.temps.iter().map(|c| format!("T_{}_C", c.name)));
    for (present, name) in [
        (data.tool_mm.is_some(), "tool_mm"),
        (data.tool_lat_mm[0].is_some(), "tool_x_mm"),
        (data.tool_lat_mm[1].is_some(), "tool_y_mm"),
        (data.pass_id.is_some(), "pass_id"),
        (data.session_id.is_some(), "session_id"),
        (data.setup_id.is_some(), "setup_id"),
        (data.u_um.is_some(), "u_um"),
    ] {
        if present {
            h.push(name.into());
        }
    }
    h.extend(data.aux.iter().map(|c| c.name.clone()));
    h
}

/// Writes `data` as the measurement CSV: metadata lines, then the contract
/// columns in a fixed order (positions, errors, t_s, dir_*, T_*_C, tool_mm,
/// pass_id, session_id, u_um), then auxiliary channels. Numbers use Rust's
/// shortest round-trip form, so reading the file back gives the same values
/// bit for bit. Line endings are `\n`.
// One column per axis/target index, named through AXES/TARGETS.
#[allow(clippy::needless_range_loop)]
pub fn write_csv<W: Write>(data: &Dataset, mut out: W) -> anyhow::Result<()> {
    // The reader's note on the encoding is about the file read, not the
    // UTF-8 one written.
    for (k, v) in data.metadata.iter().filter(|(k, _)| k != ENCODING_NOTE) {
        if k.is_empty() {
            writeln!(out, "# {v}")?;
        } else {
            writeln!(out, "# {k}: {v}")?;
        }
    }
    let n = data.len();
    let mut header: Vec<String> = Vec::new();
    type Getter<'a> = Box<dyn Fn(usize) -> String + 'a>;
    let mut getters: Vec<Getter<'_>> = Vec::new();
    for a in 0..3 {
        if let Some(v) = &data.pos_mm[a] {
            header.push(format!("{}_mm", AXES[a]));
            getters.push(Box::new(move |r| v[r].to_string()));
        }
    }
    for t in 0..3 {
        if let Some(v) = &data.err_um[t] {
            header.push(format!("{}_um", TARGETS[t]));
            getters.push(Box::new(move |r| {
                v[r].map_or(String::new(), |x| x.to_string())
            }));
        }
    }
    for a in 0..3 {
        if let Some(v) = &data.angle_urad[a] {
            header.push(format!("{}_urad", ANGLES[a]));
            getters.push(Box::new(move |r| {
                v[r].map_or(String::new(), |x| x.to_string())
            }));
        }
    }
    if let Some(v) = &data.beam_um {
        header.push("e_beam_um".into());
        getters.push(Box::new(move |r| {
            v[r].map_or(String::new(), |x| x.to_string())
        }));
        let dirs = data.beam_dir.as_deref().unwrap_or(&[]);
        for (k, axis) in AXES.iter().enumerate() {
            header.push(format!("beam_{axis}"));
            getters.push(Box::new(move |r| {
                dirs.get(r)
                    .copied()
                    .flatten()
                    .map_or(String::new(), |d| d[k].to_string())
            }));
        }
    }
    if let Some(v) = &data.t_s {
        header.push("t_s".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    for a in 0..3 {
        if let Some(v) = &data.dir[a] {
            header.push(format!("dir_{}", AXES[a]));
            getters.push(Box::new(move |r| v[r].to_string()));
        }
    }
    for c in &data.temps {
        header.push(format!("T_{}_C", c.name));
        getters.push(Box::new(move |r| c.temp_c[r].to_string()));
    }
    if let Some(v) = &data.tool_mm {
        header.push("tool_mm".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    for (k, name) in ["tool_x_mm", "tool_y_mm"].into_iter().enumerate() {
        if let Some(v) = &data.tool_lat_mm[k] {
            header.push(name.into());
            getters.push(Box::new(move |r| v[r].to_string()));
        }
    }
    if let Some(v) = &data.pass_id {
        header.push("pass_id".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    if let Some(v) = &data.session_id {
        header.push("session_id".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    if let Some(v) = &data.setup_id {
        header.push("setup_id".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    if let Some(v) = &data.u_um {
        header.push("u_um".into());
        getters.push(Box::new(move |r| v[r].to_string()));
    }
    for c in &data.aux {
        header.push(c.name.clone());
        getters.push(Box::new(move |r| c.cells[r].clone()));
    }
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(out);
    debug_assert_eq!(header, column_names(data));
    w.write_record(&header)?;
    let mut row: Vec<String> = Vec::with_capacity(header.len());
    for r in 0..n {
        row.clear();
        row.extend(getters.iter().map(|g| g(r)));
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classify_names() {
        assert_eq!(classify("x_mm"), Ok(Col::Pos(0)));
        assert_eq!(classify("ez_um"), Ok(Col::Err(2)));
        assert_eq!(classify("T_bed_C"), Ok(Col::Temp("bed".into())));
        assert_eq!(classify("feed"), Ok(Col::Aux));
        assert_eq!(classify("T_max"), Ok(Col::Aux));
        assert!(classify("x_in")
            .unwrap_err()
            .contains("unknown unit suffix `_in`"));
        assert!(classify("ex_nm").unwrap_err().contains("expected `ex_um`"));
        assert!(classify("T_bed_F").unwrap_err().contains("T_bed_C"));
        assert!(classify("X_mm").unwrap_err().contains("case-sensitive"));
        assert!(classify("t").unwrap_err().contains("no unit suffix"));
        assert!(classify("t_min").unwrap_err().contains("expected `t_s`"));
        assert!(classify("tool_in")
            .unwrap_err()
            .contains("expected `tool_mm`"));
        assert_eq!(classify("t_start"), Ok(Col::Aux));
        assert_eq!(classify("u_raw"), Ok(Col::Aux));
        assert!(classify("x_ref").is_err(), "position stems are strict");
        // Every contract name in the wrong case is refused the same way.
        for (bad, want) in [
            ("dir_X", "dir_x"),
            ("Dir_x", "dir_x"),
            ("DIR_Z", "dir_z"),
            ("Pass_ID", "pass_id"),
            ("session_ID", "session_id"),
            ("t_bed_C", "T_bed_C"),
            ("t_bed_c", "T_bed_C"),
        ] {
            assert_eq!(
                classify(bad),
                Err(format!(
                    "column `{bad}`: expected `{want}` (column names are case-sensitive)"
                )),
            );
        }
        assert_eq!(classify("t_calib"), Ok(Col::Aux));
    }

    #[test]
    fn probable_column_names_the_contract_column() {
        for (aux, want) in [
            ("ey [um]", Some("ey_um")),
            ("ey(um)", Some("ey_um")),
            ("ey [µm]", Some("ey_um")),
            ("Ex", Some("ex_um")),
            ("y (mm)", Some("y_mm")),
            ("X mm", Some("x_mm")),
            ("T_bed", Some("T_bed_C")),
            ("T_bed [C]", Some("T_bed_C")),
            ("temp bed", Some("T_bed_C")),
            ("Temperature_spindle (C)", Some("T_spindle_C")),
            ("dir x", Some("dir_x")),
            ("pass id", Some("pass_id")),
            ("feed", None),
            ("t_start", None),
            ("u_raw", None),
            ("operator note", None),
        ] {
            assert_eq!(probable_column(aux).as_deref(), want, "{aux}");
            // Every one of them is an auxiliary column for the reader.
            assert_eq!(classify(aux), Ok(Col::Aux), "{aux}");
        }
    }

    #[test]
    fn round_trip_keeps_everything() {
        let text = "# machine: XHK-715\n# free note\nx_mm,ex_um,ey_um,feed,dir_x,T_bed_C\n\
                    0,0.5,,\"a,b\",1,20.1\n10.25,-0.125,3,b,-1,20.2\n";
        let a = parse(text, "a.csv").unwrap();
        let mut buf = Vec::new();
        write_csv(&a, &mut buf).unwrap();
        let b = parse(std::str::from_utf8(&buf).unwrap(), "a.csv").unwrap();
        assert_eq!(a.columns_differing(&b), Vec::<&str>::new());
        assert_eq!(a.aux[0].cells[0], "a,b");
    }

    #[test]
    fn volumetric_columns_round_trip() {
        let text = "x_mm,y_mm,z_mm,ex_um,ea_urad,ec_urad,e_beam_um,beam_x,beam_y,beam_z,tool_mm,tool_x_mm,tool_y_mm,setup_id\n\
                    0,0,0,1.5,,,,,,,100,0,0,1\n\
                    10,5,0,,12.5,-3,,,,,100,25,-25,2\n\
                    10,10,10,,,,0.75,0.6,0.8,0,0,0,0,3\n";
        let a = parse(text, "v.csv").unwrap();
        assert_eq!(a.setup_id, Some(vec![1, 2, 3]));
        assert_eq!(a.tool_lat_mm[0], Some(vec![0.0, 25.0, 0.0]));
        assert_eq!(a.angle_urad[0], Some(vec![None, Some(12.5), None]));
        assert_eq!(a.angle_urad[1], None);
        assert_eq!(a.beam_um, Some(vec![None, None, Some(0.75)]));
        assert_eq!(a.beam_dir, Some(vec![None, None, Some([0.6, 0.8, 0.0])]));
        a.validate().unwrap();
        let mut buf = Vec::new();
        write_csv(&a, &mut buf).unwrap();
        let b = parse(std::str::from_utf8(&buf).unwrap(), "v.csv").unwrap();
        assert_eq!(
            a,
            Dataset {
                line: a.line.clone(),
                ..b
            }
        );
    }

    #[test]
    fn a_file_of_beam_readings_alone_is_data() {
        let text = "x_mm,y_mm,z_mm,e_beam_um,beam_x,beam_y,beam_z\n\
                    100,100,100,1.25,0.57735,0.57735,0.57735\n";
        let d = parse(text, "diag.csv").unwrap();
        d.validate().unwrap();
        assert!(d.targets().is_empty());
        assert!(d.has_volumetric_readings());
    }

    #[test]
    fn bad_volumetric_cells_are_located() {
        let err = |text: &str| parse(text, "b.csv").unwrap_err().to_string();
        let head = "x_mm,e_beam_um,beam_x,beam_y,beam_z\n";
        let e = err(&format!("{head}0,1,0.6,0.8,0\n5,1,1,1,1\n"));
        assert!(
            e.starts_with(
                "b.csv:3:3: beam direction (1, 1, 1) has length 1.732051; expected a unit vector"
            ),
            "{e}"
        );
        let e = err(&format!("{head}0,1,0.6,,0\n"));
        assert!(
            e.starts_with("b.csv:2:4: column `beam_y`: expected a number"),
            "{e}"
        );
        let e = err("x_mm,e_beam_um,beam_x\n0,1,1\n");
        assert!(
            e.contains("b.csv:1:2: a beam reading needs all four columns"),
            "{e}"
        );
        let e = err("x_mm,ea_mrad\n0,1\n");
        assert!(
            e.contains("unknown unit suffix `_mrad`; expected `ea_urad`"),
            "{e}"
        );
        let e = err("x_mm,ea_urad,setup_id\n0,1,a\n");
        assert!(
            e.contains("b.csv:2:3: column `setup_id`: expected an integer"),
            "{e}"
        );
        let e = err("x_mm,ea_urad\n0,1e6\n");
        assert!(e.contains("expected an angle in µrad"), "{e}");
        // An old file's auxiliary columns that only look like the new
        // stems stay auxiliary.
        let d = parse("x_mm,ex_um,ea_note,beam\n0,1,a,b\n", "o.csv").unwrap();
        assert_eq!(d.aux.len(), 2);
    }

    #[test]
    fn windows_1252_bytes_read_as_excel_wrote_them() {
        assert_eq!(
            windows_1252(b"\x80 \xb5m \xb0C \xfc \x96 \x81"),
            "€ µm °C ü – \u{fffd}"
        );
    }
}
