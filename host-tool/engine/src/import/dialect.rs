//! What spreadsheets write besides the plain CSV: the text of a UTF-16
//! file (Excel's "Unicode text"), and the separator and decimal mark a
//! header line shows (`,`; `;` with decimal commas; tabs).

use super::ImportError;

/// The text of a UTF-16 file (as Excel's "Unicode text" and some Windows
/// tools write it): a byte order mark FF FE / FE FF, or — without one — a
/// zero byte in every other place of the first line. `None` for anything
/// else (read as UTF-8).
pub(super) fn utf16_text(bytes: &[u8], name: &str) -> Result<Option<String>, ImportError> {
    let le = match bytes {
        [0xFF, 0xFE, ..] => Some((true, 2)),
        [0xFE, 0xFF, ..] => Some((false, 2)),
        [a, 0, b, 0, ..] if *a != 0 && *b != 0 => Some((true, 0)),
        [0, a, 0, b, ..] if *a != 0 && *b != 0 => Some((false, 0)),
        _ => None,
    };
    let Some((le, skip)) = le else {
        return Ok(None);
    };
    let body = &bytes[skip..];
    if !body.len().is_multiple_of(2) {
        let line = body.iter().filter(|&&b| b == b'\n').count() + 1;
        return Err(ImportError::at(
            name,
            line,
            None,
            "expected UTF-16 text (an even number of bytes); the file is cut",
        ));
    }
    let units = body.chunks_exact(2).map(|c| {
        if le {
            u16::from_le_bytes([c[0], c[1]])
        } else {
            u16::from_be_bytes([c[0], c[1]])
        }
    });
    let mut out = String::with_capacity(body.len() / 2);
    for ch in char::decode_utf16(units) {
        match ch {
            Ok(c) => out.push(c),
            Err(_) => {
                let line = out.matches('\n').count() + 1;
                return Err(ImportError::at(name, line, None, "expected UTF-16 text"));
            }
        }
    }
    Ok(Some(out))
}

/// Whether `mark` stands between two digits somewhere in `body` (`1.5`).
fn between_digits(body: &str, mark: u8) -> bool {
    body.as_bytes()
        .windows(3)
        .any(|w| w[0].is_ascii_digit() && w[1] == mark && w[2].is_ascii_digit())
}

/// The dialect of a CSV file (`body`: the header line and the rows): the
/// separator from the header line — `,`, `;` or tab — and whether `,` is
/// the decimal mark. It is for a `;`-separated file (as Excel writes it
/// where the comma is the decimal mark), and for a tab-separated one that
/// writes `1,5` (Excel's "Unicode text" there), unless some number in it is
/// written with a decimal point: then a comma in a number could be a thousands
/// separator (`1,234`), and such a cell is refused as not a number rather
/// than read as 1.234. A header holding both `,` and `;` is split by `;`
/// unless only `,` splits the first row into as many cells (then the `;`
/// is part of a name).
pub(super) fn dialect(body: &str) -> (u8, bool) {
    let header = body.lines().next().unwrap_or("");
    let first_row = body.lines().skip(1).find(|l| !l.trim().is_empty());
    // A `;` in a header that is split by `,` (a name holding `;`) and whose
    // first row agrees with `,` is no separator.
    let cells = |line: &str, sep: char| line.split(sep).count();
    let comma_fits = first_row.is_some_and(|r| cells(r, ',') == cells(header, ','));
    let semicolon_fits = first_row.is_some_and(|r| cells(r, ';') == cells(header, ';'));
    if header.contains(',') && (!header.contains(';') || (comma_fits && !semicolon_fits)) {
        (b',', false)
    } else if header.contains(';') {
        (b';', !between_digits(body, b'.'))
    } else if header.contains('\t') {
        // Excel's "Unicode text" in a German locale: tabs and `1,5` (a
        // comma in a tab-separated file is no separator).
        (
            b'\t',
            !between_digits(body, b'.') && between_digits(body, b','),
        )
    } else {
        (b',', false)
    }
}

#[cfg(test)]
mod tests {
    use super::dialect;

    #[test]
    fn a_semicolon_in_a_comma_separated_name_is_no_separator() {
        // `;` inside a column name, rows split by `,`.
        assert_eq!(dialect("x_mm,ex_a;b\n0,1\n").0, b',');
        // Excel in a comma-decimal locale: `;` separates, `,` is the mark.
        assert_eq!(dialect("x_mm;ex_um\n0;1,5\n"), (b';', true));
        // Both split the first row alike: `;` as before.
        assert_eq!(dialect("x_mm;e,x\n0;1,5\n").0, b';');
        // A header alone: `;` as before.
        assert_eq!(dialect("x_mm,ex;um\n").0, b';');
    }
}
