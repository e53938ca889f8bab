//! The checks `ModelFile::validate` runs on a model file's fields: each
//! names the JSON path of a bad value and what was expected, so a hand-edited
//! or truncated MODEL.json is refused with a message a user can act on.

pub(crate) type Check = std::result::Result<(), String>;

/// `Err("<at>: <value>, expected <want>")` unless `ok`.
pub(crate) fn need(ok: bool, at: impl FnOnce() -> String, what: impl FnOnce() -> String) -> Check {
    if ok {
        Ok(())
    } else {
        Err(format!("{}: {}", at(), what()))
    }
}

pub(crate) fn check_finite(v: &[f64], at: &str) -> Check {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(i) => Err(format!("{at}[{i}]: {}, expected a finite number", v[i])),
    }
}

pub(crate) fn check_len(len: usize, want: usize, at: &str, of: &str) -> Check {
    need(
        len == want,
        || at.to_string(),
        || format!("{len} entries, expected {want} ({of})"),
    )
}

/// An index into `names` (axes or targets).
pub(crate) fn check_index(i: usize, names: &[&str], at: impl FnOnce() -> String) -> Check {
    need(i < names.len(), at, || {
        let list: Vec<String> = names
            .iter()
            .enumerate()
            .map(|(k, n)| format!("{k} ({n})"))
            .collect();
        format!("{i}, expected {}", list.join(", "))
    })
}

/// Indices in range and none twice.
pub(crate) fn check_indices(v: &[usize], names: &[&str], at: &str) -> Check {
    for (k, &i) in v.iter().enumerate() {
        check_index(i, names, || format!("{at}[{k}]"))?;
        need(
            !v[..k].contains(&i),
            || format!("{at}[{k}]"),
            || format!("{} ({}) appears twice", i, names[i]),
        )?;
    }
    Ok(())
}

/// `Vec<f64>` with NaN written as JSON null and read back as NaN (serde_json
/// writes non-finite floats as null but cannot read null into an f64).
pub(crate) mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let o: Vec<Option<f64>> = v.iter().map(|x| x.is_finite().then_some(*x)).collect();
        o.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let o: Vec<Option<f64>> = Vec::deserialize(d)?;
        Ok(o.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
    }
}
