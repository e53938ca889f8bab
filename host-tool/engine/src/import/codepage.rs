//! Text of an instrument file that is not UTF-8: the legacy Windows code
//! page its PC wrote it in. A Renishaw `.rtl` from a Russian or Ukrainian
//! shop carries its USER-TEXT (machine, operator, place) in Windows-1251,
//! one from Western Europe in Windows-1252; read as UTF-8 either comes out
//! as `�` (issue 24). Cyrillic is told from Western text by its runs of
//! letters: three or more bytes in 0xC0–0xFF in a row are a Cyrillic word
//! (А–я), while Western text has an accented letter here and there.

use super::windows_1252;

/// The text of `bytes` and, when they are not UTF-8, the code page they
/// were read as (`Windows-1251` or `Windows-1252`).
pub fn decode(bytes: &[u8]) -> (String, Option<&'static str>) {
    match std::str::from_utf8(bytes) {
        Ok(t) => (t.to_string(), None),
        Err(_) if is_cyrillic(bytes) => (windows_1251(bytes), Some("Windows-1251")),
        Err(_) => (windows_1252(bytes), Some("Windows-1252")),
    }
}

/// Whether some run of 3 or more bytes lies in 0xC0–0xFF (a Cyrillic word
/// in Windows-1251).
fn is_cyrillic(bytes: &[u8]) -> bool {
    bytes.split(|b| *b < 0xc0).any(|run| run.len() >= 3)
}

/// Windows-1251 bytes as text: ASCII as is, 0xC0–0xFF the Russian
/// alphabet А–я (U+0410–U+044F), 0x80–0xBF the code page's table (Ё, ё,
/// Ukrainian and Serbian letters, punctuation; 0x98 undefined → U+FFFD).
pub fn windows_1251(bytes: &[u8]) -> String {
    const HIGH: [char; 64] = [
        'Ђ', 'Ѓ', '‚', 'ѓ', '„', '…', '†', '‡', '€', '‰', 'Љ', '‹', 'Њ', 'Ќ', 'Ћ', 'Џ', //
        'ђ', '‘', '’', '“', '”', '•', '–', '—', '\u{fffd}', '™', 'љ', '›', 'њ', 'ќ', 'ћ',
        'џ', //
        '\u{a0}', 'Ў', 'ў', 'Ј', '¤', 'Ґ', '¦', '§', 'Ё', '©', 'Є', '«', '¬', '\u{ad}', '®',
        'Ї', //
        '°', '±', 'І', 'і', 'ґ', 'µ', '¶', '·', 'ё', '№', 'є', '»', 'ј', 'Ѕ', 'ѕ', 'ї',
    ];
    bytes
        .iter()
        .map(|&b| match b {
            0x00..=0x7f => char::from(b),
            0x80..=0xbf => HIGH[usize::from(b - 0x80)],
            _ => char::from_u32(0x410 + u32::from(b - 0xc0)).expect("in the Cyrillic block"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyrillic_and_western_code_pages_are_told_apart() {
        // "Станок ВМЦ-1, оператор Иванов, 20 °C" in Windows-1251.
        let cp1251: &[u8] = b"\xd1\xf2\xe0\xed\xee\xea \xc2\xcc\xd6-1, \xee\xef\xe5\xf0\xe0\xf2\xee\xf0 \xc8\xe2\xe0\xed\xee\xe2, 20 \xb0C";
        assert_eq!(
            decode(cp1251),
            (
                "Станок ВМЦ-1, оператор Иванов, 20 °C".to_string(),
                Some("Windows-1251")
            )
        );
        assert_eq!(windows_1251(b"\xa8\xb8\xb9\x98"), "Ёё№\u{fffd}");
        // "Prüfung Müller, 20 °C" in Windows-1252: no run of three.
        let cp1252: &[u8] = b"Pr\xfcfung M\xfcller, 20 \xb0C";
        assert_eq!(
            decode(cp1252),
            ("Prüfung Müller, 20 °C".to_string(), Some("Windows-1252"))
        );
        assert_eq!(decode("Станок".as_bytes()), ("Станок".to_string(), None));
    }
}
