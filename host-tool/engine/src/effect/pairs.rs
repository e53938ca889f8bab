//! The one `key=value` grammar of the tool's specs: the pairs after an
//! `--add` string's `<family>:`, after simulate's `--effect <family>:` and
//! after a plan's kind (`--plan line:y:0.5,x=400,bidir`), with the getters
//! that read a value as a number, a count, an axis or a target and say in
//! their errors which key held what and what was expected.

use std::cell::Cell;

use anyhow::{anyhow, bail, Result};

use super::{Axis, Target};

/// The pairs after a spec's `<family>:` (or a plan's kind), split at `,`
/// and `=`: keys and values trimmed, in the order written, a key at most
/// once — the one `key=value` grammar of the `--add` strings and of
/// simulate's `--effect` and `--plan`. The getters name the key and what
/// was expected in their errors, and mark the key as used for
/// [`Pairs::finish`].
#[derive(Debug)]
pub struct Pairs<'a> {
    pairs: Vec<(&'a str, Option<&'a str>)>,
    used: Vec<Cell<bool>>,
}

impl<'a> Pairs<'a> {
    /// `key=value` parts only (an effect); empty parts (a trailing comma)
    /// are skipped.
    pub fn parse(s: &'a str) -> Result<Pairs<'a>> {
        let mut pairs = Vec::new();
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| anyhow!("`{part}`: expected key=value"))?;
            Self::push(&mut pairs, k.trim(), Some(v.trim()))?;
        }
        Ok(Self::with(pairs))
    }

    /// An effect, `<family>:<key>=<value>,…`, split at its first `:` into
    /// the family's name as written and its pairs; `expected` is the
    /// message without a `:`.
    pub fn of_effect(s: &'a str, expected: &str) -> Result<(&'a str, Pairs<'a>)> {
        let (family, rest) = s.split_once(':').ok_or_else(|| anyhow!("{expected}"))?;
        Ok((family, Pairs::parse(rest)?))
    }

    /// `key=value` parts and bare flags (`bidir`: a plan's options); blank
    /// parts are skipped.
    pub fn parse_with_flags(s: &'a str) -> Result<Pairs<'a>> {
        let mut pairs = Vec::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            match part.split_once('=') {
                Some((k, v)) => Self::push(&mut pairs, k.trim(), Some(v.trim()))?,
                None => Self::push(&mut pairs, part, None)?,
            }
        }
        Ok(Self::with(pairs))
    }

    fn push(
        pairs: &mut Vec<(&'a str, Option<&'a str>)>,
        k: &'a str,
        v: Option<&'a str>,
    ) -> Result<()> {
        if pairs.iter().any(|(k2, _)| *k2 == k) {
            bail!("key `{k}` given twice");
        }
        pairs.push((k, v));
        Ok(())
    }

    fn with(pairs: Vec<(&'a str, Option<&'a str>)>) -> Pairs<'a> {
        let used = pairs.iter().map(|_| Cell::new(false)).collect();
        Pairs { pairs, used }
    }

    /// The keys, in the order written.
    pub fn keys(&self) -> impl Iterator<Item = &'a str> + '_ {
        self.pairs.iter().map(|(k, _)| *k)
    }

    /// The value of `key`, if given (a bare flag asked for a value is an
    /// error).
    pub fn get(&self, key: &str) -> Result<Option<&'a str>> {
        let Some(i) = self.pairs.iter().position(|(k, _)| *k == key) else {
            return Ok(None);
        };
        self.used[i].set(true);
        match self.pairs[i].1 {
            Some(v) => Ok(Some(v)),
            None => bail!("`{key}`: expected `{key}=<value>`"),
        }
    }

    /// The value of `key`, which must be given.
    pub fn need(&self, key: &str) -> Result<&'a str> {
        self.get(key)?.ok_or_else(|| anyhow!("missing `{key}=`"))
    }

    /// A bare flag or `key=0/1` (`true`/`false`); false when absent.
    pub fn flag(&self, key: &str) -> Result<bool> {
        let Some(i) = self.pairs.iter().position(|(k, _)| *k == key) else {
            return Ok(false);
        };
        self.used[i].set(true);
        match self.pairs[i].1 {
            None | Some("1") | Some("true") => Ok(true),
            Some("0") | Some("false") => Ok(false),
            Some(v) => bail!("`{key}={v}`: expected a bare `{key}` or {key}=0/1"),
        }
    }

    /// A finite number, if given.
    pub fn f64(&self, key: &str) -> Result<Option<f64>> {
        self.get(key)?.map(|v| parse_f64(v, key)).transpose()
    }

    /// A finite number that must be given.
    pub fn need_f64(&self, key: &str) -> Result<f64> {
        parse_f64(self.need(key)?, key)
    }

    /// A count, if given.
    pub fn usize(&self, key: &str) -> Result<Option<usize>> {
        self.get(key)?
            .map(|v| {
                v.parse::<usize>()
                    .map_err(|_| anyhow!("`{key}={v}`: expected a non-negative integer"))
            })
            .transpose()
    }

    /// An integer in `lo..=hi`, if given.
    pub fn u8_in(&self, key: &str, lo: u8, hi: u8) -> Result<Option<u8>> {
        self.get(key)?.map(|v| parse_u8(v, key, lo, hi)).transpose()
    }

    /// An axis name, if given.
    pub fn axis(&self, key: &str) -> Result<Option<Axis>> {
        self.get(key)?.map(|v| parse_axis(v, key)).transpose()
    }

    /// An axis name that must be given.
    pub fn need_axis(&self, key: &str) -> Result<Axis> {
        parse_axis(self.need(key)?, key)
    }

    /// `target=`, if given.
    pub fn target(&self) -> Result<Option<Target>> {
        self.get("target")?
            .map(|v| {
                v.parse::<Target>()
                    .map_err(|_| anyhow!("`target={v}`: expected ex, ey or ez"))
            })
            .transpose()
    }

    /// Fails on any key nobody asked for, listing the ones allowed.
    pub fn finish(&self, allowed: &str) -> Result<()> {
        if let Some(i) = self.used.iter().position(|u| !u.get()) {
            bail!("unknown key `{}` (expected {allowed})", self.pairs[i].0);
        }
        Ok(())
    }

    /// The pairs as written (an effect's canonical form).
    pub(super) fn written(&self) -> Vec<(String, String)> {
        self.pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.unwrap_or_default().to_string()))
            .collect()
    }
}

/// A finite number: "`key=v`: expected a number" (or "a finite number").
pub fn parse_f64(v: &str, key: &str) -> Result<f64> {
    let x: f64 = v
        .parse()
        .map_err(|_| anyhow!("`{key}={v}`: expected a number"))?;
    if !x.is_finite() {
        bail!("`{key}={v}`: expected a finite number");
    }
    Ok(x)
}

fn parse_u8(v: &str, key: &str, lo: u8, hi: u8) -> Result<u8> {
    let x: u8 = v
        .parse()
        .map_err(|_| anyhow!("`{key}={v}`: expected an integer {lo}..={hi}"))?;
    if !(lo..=hi).contains(&x) {
        bail!("`{key}={v}`: expected an integer {lo}..={hi}");
    }
    Ok(x)
}

/// An axis name: "`key=v`: expected x, y or z".
pub fn parse_axis(v: &str, key: &str) -> Result<Axis> {
    v.parse::<Axis>()
        .map_err(|_| anyhow!("`{key}={v}`: expected x, y or z"))
}
