//! The engine's one warning type: a stable code for scripts and a detail
//! for people. Every command's result carries its warnings as this type —
//! `diagnose`, `improve`, `compare` and `export` serialise it as
//! `{"code", "detail"}` (docs/cli.md); `fit` keeps only the text in
//! MODEL.json `stats.warnings` and its `--json` (strings, as docs/cli.md
//! says), through [`as_text`].
//!
//! A fit warning's detail is the whole sentence as fit has always written
//! it, its subject first (`ex: ill-conditioned design …`, `nn: training
//! stopped …`, for the data's own warnings their code:
//! `aux_misspelled: d.csv: …`); its code is for the program that reads it.

use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A warning: what happened, with a code that does not change when the
/// words do.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Warning {
    /// Stable machine-readable code (`aliasing`, `data_hash_mismatch`,
    /// `drift_left_out`, `ill_conditioned`, …).
    pub code: String,
    /// What happened and what it means, in words.
    pub detail: String,
}

/// The code of a warning read back from a document that keeps only its
/// text (MODEL.json `stats.warnings`).
pub const FROM_TEXT: &str = "text";

impl Warning {
    /// A warning with a code and a detail.
    pub fn new(code: &str, detail: impl Into<String>) -> Warning {
        Warning {
            code: code.to_string(),
            detail: detail.into(),
        }
    }
}

/// The text form: the detail (what `fit` writes as a string).
impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.detail)
    }
}

/// Warnings kept as their text, for a field whose JSON is a list of
/// strings: `#[serde(with = "crate::warning::as_text")]`. Read back, each
/// has the code [`FROM_TEXT`] (the document does not record one).
pub mod as_text {
    use super::*;

    /// Writes each warning's text.
    pub fn serialize<S: Serializer>(w: &[Warning], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(w.iter().map(|w| w.detail.as_str()))
    }

    /// Reads a list of texts.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Warning>, D::Error> {
        Ok(Vec::<String>::deserialize(d)?
            .into_iter()
            .map(|t| Warning::new(FROM_TEXT, t))
            .collect())
    }

    /// The texts, for a JSON document built by hand.
    pub fn texts(w: &[Warning]) -> Vec<String> {
        w.iter().map(ToString::to_string).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize, Deserialize)]
    struct Doc {
        #[serde(with = "as_text")]
        warnings: Vec<Warning>,
    }

    #[test]
    fn a_warning_is_code_and_detail_in_json_and_its_detail_as_text() {
        let w = Warning::new("ill_conditioned", "ex: ill-conditioned design");
        assert_eq!(
            serde_json::to_string(&w).unwrap(),
            r#"{"code":"ill_conditioned","detail":"ex: ill-conditioned design"}"#
        );
        assert_eq!(w.to_string(), "ex: ill-conditioned design");
        let doc = serde_json::to_string(&Doc {
            warnings: vec![w.clone()],
        })
        .unwrap();
        assert_eq!(doc, r#"{"warnings":["ex: ill-conditioned design"]}"#);
        // Read back: the text is kept, the code is not in the document.
        let back: Doc = serde_json::from_str(&doc).unwrap();
        assert_eq!(back.warnings, [Warning::new(FROM_TEXT, w.detail)]);
        assert_eq!(serde_json::to_string(&back).unwrap(), doc);
    }
}
