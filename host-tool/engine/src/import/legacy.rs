//! Text of files written by Windows measurement software in a legacy code
//! page (issue 24: a Renishaw `.rtl` whose operator and machine names were
//! Windows-1251 came out as `Ð˜Ð²Ð°Ð½Ð¾Ð²`-like noise). UTF-8 is read as it
//! is; anything else is Windows-1251 when its bytes above 0x7F form words
//! (Cyrillic: every letter is such a byte, so they come in runs), else
//! Windows-1252 (Western Europe: `µ`, `°`, `ü` single between ASCII
//! letters). The guess is said, with the line where the file stops being
//! UTF-8, so a wrong one is seen.

use std::borrow::Cow;

/// A run of at least this many bytes ≥ 0xC0 counts as a Cyrillic word.
const WORD_RUN: usize = 3;

/// The two legacy code pages a file is read as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodePage {
    /// Cyrillic (Russian, Ukrainian, Bulgarian Windows).
    Windows1251,
    /// Western European Windows; Excel's "CSV" there.
    Windows1252,
}

impl CodePage {
    /// The name said to the user.
    pub fn name(self) -> &'static str {
        match self {
            CodePage::Windows1251 => "Windows-1251",
            CodePage::Windows1252 => "Windows-1252",
        }
    }
}

/// The code page of bytes that are not UTF-8: Windows-1251 when at least
/// half of the bytes ≥ 0x80 stand in runs of [`WORD_RUN`] or more bytes
/// ≥ 0xC0 (Cyrillic letters are 0xC0–0xFF), else Windows-1252.
pub fn guess(bytes: &[u8]) -> CodePage {
    let high = bytes.iter().filter(|&&b| b >= 0x80).count();
    let mut in_words = 0;
    let mut run = 0;
    for &b in bytes.iter().chain(std::iter::once(&0u8)) {
        if b >= 0xC0 {
            run += 1;
        } else {
            if run >= WORD_RUN {
                in_words += run;
            }
            run = 0;
        }
    }
    if high > 0 && 2 * in_words >= high {
        CodePage::Windows1251
    } else {
        CodePage::Windows1252
    }
}

/// `bytes` as text and, when they were not UTF-8, the code page read and
/// the line (1-based) where the first non-UTF-8 byte stands.
pub fn decode(bytes: &[u8]) -> (Cow<'_, str>, Option<(CodePage, usize)>) {
    match std::str::from_utf8(bytes) {
        Ok(t) => (Cow::Borrowed(t), None),
        Err(e) => {
            let line = bytes[..e.valid_up_to()]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1;
            let page = guess(bytes);
            let text = match page {
                CodePage::Windows1251 => encoding_rs::WINDOWS_1251
                    .decode_without_bom_handling(bytes)
                    .0
                    .into_owned(),
                CodePage::Windows1252 => super::csv_io::windows_1252(bytes),
            };
            (Cow::Owned(text), Some((page, line)))
        }
    }
}

/// The note a reader files under [`super::ENCODING_NOTE`] for a file read
/// as `page` from `line` on.
pub fn note(page: CodePage, line: usize) -> String {
    match page {
        CodePage::Windows1252 => format!(
            "not valid UTF-8 (from line {line}): read as {}, the encoding Excel's \"CSV\" uses in Western Europe — save as \"CSV UTF-8\" to be sure of `°` and `µ`",
            page.name()
        ),
        CodePage::Windows1251 => format!(
            "not valid UTF-8 (from line {line}): read as {} (Cyrillic: its bytes above 0x7F form words) — save as UTF-8 to be sure of the names",
            page.name()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyrillic_words_are_windows_1251_and_western_letters_1252() {
        // "Оператор: Иванов" in Windows-1251.
        let ru: Vec<u8> = b"Operator: "
            .iter()
            .copied()
            .chain([0xC8, 0xE2, 0xE0, 0xED, 0xEE, 0xE2])
            .collect();
        assert_eq!(guess(&ru), CodePage::Windows1251);
        let (t, how) = decode(&ru);
        assert_eq!(t, "Operator: Иванов");
        assert_eq!(how, Some((CodePage::Windows1251, 1)));
        // "Prüfer: Müller, 20 °C, 5 µm" in Windows-1252.
        let de = b"x\nPr\xfcfer: M\xfcller, 20 \xb0C, 5 \xb5m";
        assert_eq!(guess(de), CodePage::Windows1252);
        let (t, how) = decode(de);
        assert_eq!(t, "x\nPrüfer: Müller, 20 °C, 5 µm");
        assert_eq!(how, Some((CodePage::Windows1252, 2)));
        // UTF-8 stays as it is, borrowed.
        let (t, how) = decode("Иванов µm".as_bytes());
        assert!(matches!(t, Cow::Borrowed("Иванов µm")) && how.is_none());
        // One accented capital pair (ÄÖ) is no Cyrillic word.
        assert_eq!(guess(b"\xc4\xd6 a b c \xfc"), CodePage::Windows1252);
    }
}
