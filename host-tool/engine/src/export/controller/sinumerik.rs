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

use super::{AxisSamples, ControllerFile, ControllerFormat};
use crate::export::fmt_no_neg_zero;

/// The format: 200 points by default (the most a Sinumerik 808D takes),
/// axis `AX1` unless named; the table holds the mean of both directions
/// and the reversal goes to MD32450 (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Sinumerik;

/// The axis name when none is given.
const DEFAULT_AXIS: &str = "AX1";

impl ControllerFormat for Sinumerik {
    fn name(&self) -> &'static str {
        "sinumerik"
    }

    fn default_points(&self) -> usize {
        200
    }

    fn default_axis_name(&self) -> Option<&'static str> {
        Some(DEFAULT_AXIS)
    }

    fn write(&self, s: &AxisSamples, axis_name: Option<&str>) -> Result<ControllerFile> {
        let n = s.nominal_mm.len();
        let mean: Vec<f64> = s
            .err_fwd_um
            .iter()
            .zip(&s.err_rev_um)
            .map(|(f, r)| 0.5 * (f + r))
            .collect();
        let step_mm = s.step_mm();
        let body = write(
            axis_name.unwrap_or(DEFAULT_AXIS),
            s.nominal_mm[0],
            step_mm,
            &mean,
        )?;
        // What the file says: _MIN/_STEP are rounded to the written 1 nm
        // and _MAX follows from them (see `write`).
        let (min_mm, step_mm) = (written_mm(s.nominal_mm[0]), written_mm(step_mm));
        // Siemens enters MD32450 positive when "the encoder is leading the
        // machine part (normal situation)": the slide falls short in the
        // direction of travel, e_fwd < 0 < e_rev. So the value is rev − fwd,
        // the opposite sign of the reversal fwd − rev, in mm; rounded to the
        // 1 nm the value is given in, without a −0.
        let md32450_mm = written_mm(-s.backlash_mean_um() * 1e-3) + 0.0;
        Ok(ControllerFile {
            body,
            min_mm,
            step_mm,
            max_mm: min_mm + step_mm * (n - 1) as f64,
            machine_data: [("md32450_backlash_mm", md32450_mm)].into(),
            note: Some(format!(
                "the table holds the mean of both directions; set MD32450 $MA_BACKLASH = {} mm (rev − fwd: positive when the axis falls short in the direction of travel, Siemens' normal case)",
                fmt_no_neg_zero(md32450_mm, 6)
            )),
        })
    }
}

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
    fmt_no_neg_zero(v, 6)
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
