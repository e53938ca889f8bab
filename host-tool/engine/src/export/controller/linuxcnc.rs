//! LinuxCNC screw-error compensation file, `COMP_FILE_TYPE = 1`, for one
//! joint: lines `nominal fwd_trim rev_trim` in machine units (mm).
//!
//! What LinuxCNC does with it (src/emc/motion/usrmotintf.cc `usrmotLoadComp`
//! and control.c `compute_screw_comp`, checked against the source): each
//! line is read with `sscanf("%lf %lf %lf")` and reading **stops at the first
//! line that does not give three numbers** — so the file has no comment or
//! header lines at all. At most 256 entries (`EMCMOT_COMP_SIZE`), nominal
//! positions strictly ascending. For type 1 the trims are used as they are:
//! the forward trim (joint moving in +) or the reverse trim (moving in −),
//! interpolated linearly between entries, is **added** to the commanded
//! joint position to make the motor command. So a trim is the correction,
//! −e (e = actual − nominal): a machine that overshoots by +3 µm gets
//! −0.003. (The INI help text's example reads as if the sign were the
//! other way; the code above is what runs.) Forward and reverse differ by
//! the model's reversal (backlash) term.

use anyhow::{bail, Result};

use super::{AxisSamples, ControllerFile, ControllerFormat};
use crate::export::checks::FileError;

/// LinuxCNC's table size (`EMCMOT_COMP_SIZE`).
pub const MAX_ENTRIES: usize = 256;

/// The format: 201 points by default (a step of 1/200 of the travel), at
/// most [`MAX_ENTRIES`]; both directions' trims, so the reversal is in the
/// file and LinuxCNC needs no backlash setting beside it.
#[derive(Clone, Copy, Debug)]
pub struct Linuxcnc;

impl ControllerFormat for Linuxcnc {
    fn name(&self) -> &'static str {
        "linuxcnc"
    }

    fn default_points(&self) -> usize {
        201
    }

    fn check_points(&self, points: usize) -> Result<(), FileError> {
        if points > MAX_ENTRIES {
            return Err(FileError::TooManyPoints {
                controller: "LinuxCNC",
                points,
                max: MAX_ENTRIES,
            });
        }
        Ok(())
    }

    fn write(&self, s: &AxisSamples, _axis_name: Option<&str>) -> Result<ControllerFile> {
        let n = s.nominal_mm.len();
        Ok(ControllerFile {
            body: write(&s.nominal_mm, &s.err_fwd_um, &s.err_rev_um)?,
            min_mm: s.nominal_mm[0],
            step_mm: s.step_mm(),
            max_mm: s.nominal_mm[n - 1],
            machine_data: Default::default(),
            note: None,
        })
    }
}

/// Writes the file from nominal positions (mm, ascending) and the errors
/// after a positive and a negative approach (µm). The trims written are
/// −error in mm, with 6 decimals (1 nm).
pub fn write(nominal_mm: &[f64], err_fwd_um: &[f64], err_rev_um: &[f64]) -> Result<String> {
    let n = nominal_mm.len();
    if n != err_fwd_um.len() || n != err_rev_um.len() {
        bail!(
            "LinuxCNC table: {n} positions but {} forward and {} reverse values",
            err_fwd_um.len(),
            err_rev_um.len()
        );
    }
    if n == 0 || n > MAX_ENTRIES {
        bail!("LinuxCNC table: {n} entries, LinuxCNC reads 1..={MAX_ENTRIES}");
    }
    let mut out = String::with_capacity(n * 40);
    let mut last = f64::NEG_INFINITY;
    for i in 0..n {
        let (p, f, r) = (nominal_mm[i], err_fwd_um[i], err_rev_um[i]);
        if !(p.is_finite() && f.is_finite() && r.is_finite()) {
            bail!("LinuxCNC table: entry {i} is not finite");
        }
        let line = format!(
            "{} {} {}\n",
            fmt_mm(p),
            fmt_mm(-f * 1e-3),
            fmt_mm(-r * 1e-3)
        );
        // Ascending after rounding to the written precision.
        let written: f64 = line
            .split(' ')
            .next()
            .unwrap_or("")
            .parse()
            .unwrap_or(f64::NAN);
        if written.is_nan() || written <= last {
            bail!("LinuxCNC table: nominal positions must be strictly ascending (entry {i} at {p} mm)");
        }
        last = written;
        out.push_str(&line);
    }
    Ok(out)
}

/// A number in mm with 6 decimals, without a negative zero.
fn fmt_mm(v: f64) -> String {
    crate::export::fmt_no_neg_zero(v, 6)
}

/// Reads a file the way LinuxCNC does (three numbers per line, stop at the
/// first line that is not), and also checks what LinuxCNC's motion module
/// requires of the result (ascending nominal, ≤ 256 entries). Returns the
/// entries and, when reading stopped early, the 1-based line where it did —
/// for a file we wrote that is always an error.
pub fn read_like_linuxcnc(text: &str) -> Result<Vec<(f64, f64, f64)>> {
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let mut it = line.split_whitespace().map(parse_c_double);
        let triple = match (it.next(), it.next(), it.next()) {
            (Some(Some(a)), Some(Some(b)), Some(Some(c))) => (a, b, c),
            _ => bail!(
                "line {}: `{line}` is not three numbers — LinuxCNC stops reading here and ignores the {} line(s) after it",
                i + 1,
                lines.len() - i - 1
            ),
        };
        if let Some(&(prev, _, _)) = out.last() {
            if triple.0 <= prev {
                bail!("line {}: nominal {} is not above {prev}", i + 1, triple.0);
            }
        }
        out.push(triple);
    }
    if out.is_empty() {
        bail!("no entries");
    }
    if out.len() > MAX_ENTRIES {
        bail!("{} entries, LinuxCNC keeps {MAX_ENTRIES}", out.len());
    }
    Ok(out)
}

/// A whole token as C's `%lf` would take it in our files (plain decimal or
/// exponent notation; no hex floats, no inf/nan since we never write them).
fn parse_c_double(tok: &str) -> Option<f64> {
    let ok = !tok.is_empty()
        && tok
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'e' | 'E'));
    if !ok {
        return None;
    }
    tok.parse::<f64>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trims_are_minus_the_error() {
        let text = write(&[0.0, 10.0], &[3.0, -1.5], &[1.0, -2.5]).unwrap();
        assert_eq!(
            text,
            "0.000000 -0.003000 -0.001000\n10.000000 0.001500 0.002500\n"
        );
        let back = read_like_linuxcnc(&text).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[1], (10.0, 0.0015, 0.0025));
    }

    #[test]
    fn refuses_what_linuxcnc_would_not_read() {
        assert!(write(&[1.0, 1.0], &[0.0, 0.0], &[0.0, 0.0]).is_err());
        assert!(write(&[2.0, 1.0], &[0.0, 0.0], &[0.0, 0.0]).is_err());
        assert!(write(&[1.0, 1.0000001], &[0.0, 0.0], &[0.0, 0.0]).is_err()); // equal once written
        assert!(write(&[0.0], &[f64::NAN], &[0.0]).is_err());
        let many: Vec<f64> = (0..257).map(f64::from).collect();
        assert!(write(&many, &many, &many).is_err());
        assert!(write(&many[..256], &many[..256], &many[..256]).is_ok());
    }

    #[test]
    fn reader_stops_like_linuxcnc() {
        let err = read_like_linuxcnc("0 0 0\n# comment\n1 0 0\n").unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        assert!(read_like_linuxcnc("0 0\n").is_err());
        assert!(read_like_linuxcnc("1 0 0\n0 0 0\n").is_err());
        assert!(read_like_linuxcnc("").is_err());
        assert_eq!(
            read_like_linuxcnc("0 1e-3 -2E-3\n").unwrap(),
            vec![(0.0, 0.001, -0.002)]
        );
    }
}
