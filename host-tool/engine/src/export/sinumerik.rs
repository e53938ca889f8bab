//! Siemens Sinumerik leadscrew / measuring-system error compensation (LEC,
//! function K3 "interpolatory compensation") for one axis, as the
//! part program `%_N_AX_EEC_INI` that loads the table's system variables:
//!
//! ```text
//! $AA_ENC_COMP[0,N,AX1]=value     ; compensation value at point N, mm
//! $AA_ENC_COMP_STEP[0,AX1]=step   ; distance between points, mm
//! $AA_ENC_COMP_MIN[0,AX1]=start   ; position of point 0, mm
//! $AA_ENC_COMP_MAX[0,AX1]=end     ; position of the last point, mm
//! $AA_ENC_COMP_IS_MODULO[0,AX1]=0 ; a linear axis
//! ```
//!
//! Sign: Siemens documents that **a positive compensation value moves the
//! machine axis in the negative direction**. The value to write is
//! therefore the error itself, e = actual − nominal: an axis that
//! overshoots by +3 µm gets +0.003 and is pulled back by 3 µm. LEC is one
//! table per axis with no direction; the reversal (backlash) part belongs in
//! machine data MD32450 `$MA_BACKLASH`, so the value is the mean of the
//! forward and reverse errors and the backlash is reported separately.
//! The table needs MD38000 `$MA_MM_ENC_COMP_MAX_POINTS` ≥ the number of
//! points (808D: at most 200), and is loaded while MD32700
//! `$MA_ENC_COMP_ENABLE` = 0. Outside MIN…MAX the first / last value holds.

use std::fmt::Write as _;

use anyhow::{bail, Result};

/// A position as the file holds it: mm rounded to 6 decimals (1 nm).
pub fn written_mm(v_mm: f64) -> f64 {
    (v_mm * 1e6).round() / 1e6
}

/// Writes the program for axis name `axis` (e.g. `AX1`, `X1`): `errors_um`
/// at `min_mm + i·step_mm`. Values in mm with 6 decimals.
///
/// The control places point N at `_MIN + N·_STEP` and requires `_MAX` to be
/// the last point (Siemens K3: "the end position … ≙ interpolation point
/// k"). So `_MIN` and `_STEP` are rounded to the written 1 nm first and
/// `_MAX` is computed from the rounded values: with 200 points over 200 mm
/// the step 1.005025… is written 1.005025 and `_MAX` is 199.999975, not a
/// 200.000000 that no point sits on. The shift of the points (≤ 0.5 nm ×
/// N) is far below what the values resolve.
pub fn write(axis: &str, min_mm: f64, step_mm: f64, errors_um: &[f64]) -> Result<String> {
    if axis.is_empty() || !axis.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        bail!("Sinumerik axis name `{axis}`: expected letters, digits and `_` (AX1, X1)");
    }
    if errors_um.len() < 2 {
        bail!("a Sinumerik compensation table needs at least 2 points");
    }
    if !(step_mm.is_finite() && step_mm > 0.0 && min_mm.is_finite()) {
        bail!("Sinumerik table: step {step_mm} mm and start {min_mm} mm must be finite, step > 0");
    }
    if let Some(i) = errors_um.iter().position(|v| !v.is_finite()) {
        bail!("Sinumerik table: value {i} is not finite");
    }
    let (min_mm, step_mm) = (written_mm(min_mm), written_mm(step_mm));
    if step_mm <= 0.0 {
        bail!("Sinumerik table: step below the written 1 nm resolution");
    }
    let max_mm = min_mm + step_mm * (errors_um.len() - 1) as f64;
    let mut s = String::new();
    // Program header and a channel selection, as Siemens' own examples.
    s.push_str("%_N_AX_EEC_INI\nCHANDATA(1)\n");
    for (i, e) in errors_um.iter().enumerate() {
        let _ = writeln!(s, "$AA_ENC_COMP[0,{i},{axis}]={}", fmt_mm(e * 1e-3));
    }
    let _ = writeln!(s, "$AA_ENC_COMP_STEP[0,{axis}]={}", fmt_mm(step_mm));
    let _ = writeln!(s, "$AA_ENC_COMP_MIN[0,{axis}]={}", fmt_mm(min_mm));
    let _ = writeln!(s, "$AA_ENC_COMP_MAX[0,{axis}]={}", fmt_mm(max_mm));
    let _ = writeln!(s, "$AA_ENC_COMP_IS_MODULO[0,{axis}]=0");
    s.push_str("M17\n");
    Ok(s)
}

fn fmt_mm(v: f64) -> String {
    super::fmt_no_neg_zero(v, 6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positive_value_for_positive_error() {
        let s = write("AX1", -200.0, 1.0, &[3.0, 10.0, -0.0]).unwrap();
        assert_eq!(
            s,
            "%_N_AX_EEC_INI\nCHANDATA(1)\n$AA_ENC_COMP[0,0,AX1]=0.003000\n$AA_ENC_COMP[0,1,AX1]=0.010000\n$AA_ENC_COMP[0,2,AX1]=0.000000\n$AA_ENC_COMP_STEP[0,AX1]=1.000000\n$AA_ENC_COMP_MIN[0,AX1]=-200.000000\n$AA_ENC_COMP_MAX[0,AX1]=-198.000000\n$AA_ENC_COMP_IS_MODULO[0,AX1]=0\nM17\n"
        );
    }

    #[test]
    fn max_is_the_last_point_of_the_written_step() {
        let s = write("AX1", 0.0, 200.0 / 199.0, &[0.0; 200]).unwrap();
        assert!(s.contains("$AA_ENC_COMP_STEP[0,AX1]=1.005025\n"), "{s}");
        assert!(s.contains("$AA_ENC_COMP_MAX[0,AX1]=199.999975\n"), "{s}");
        assert!(write("AX1", 0.0, 4e-7, &[0.0; 2]).is_err());
    }

    #[test]
    fn rejects_bad_input() {
        assert!(write("AX 1", 0.0, 1.0, &[0.0, 0.0]).is_err());
        assert!(write("AX1", 0.0, 0.0, &[0.0, 0.0]).is_err());
        assert!(write("AX1", 0.0, 1.0, &[0.0]).is_err());
        assert!(write("AX1", 0.0, 1.0, &[0.0, f64::INFINITY]).is_err());
    }
}
