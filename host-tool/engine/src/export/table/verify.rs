//! The accuracy check: the host's own f64 model (`FittedModel::predict`,
//! not the table's f64 reference, so the mapping is checked too) against
//! the firmware's f32 and fixed-point evaluation of the parsed table over
//! the sweep, the host value clamped to the envelope's max |correction| as
//! the firmware clamps it.

use anyhow::Result;

use model_core::{Inputs, Model, MAX_TEMPS};

use super::{mc, nm};
use crate::export::{predict_points, Point};
use crate::model::FittedModel;

/// The host's corrections at `points` per output, nm (−1000 × the model's
/// error in µm; `None` for an output the model does not predict).
pub(super) fn host_corrections(
    model: &FittedModel,
    channels: &[String],
    points: &[Point],
) -> Result<[Option<Vec<f64>>; 3]> {
    let pred = predict_points(model, channels, points)?;
    Ok(pred.map(|p| p.map(|v| v.iter().map(|e| -1000.0 * e).collect())))
}

/// The largest |f32 evaluation − host| and |fixed-point evaluation − host|
/// over `points`, nm, the host value clamped to `max_corr_nm`; NaN when a
/// difference is not finite.
// Per-axis and per-output arrays are indexed together; index loops read clearer.
#[allow(clippy::needless_range_loop)]
pub(super) fn max_errors_nm(
    fw: &Model,
    points: &[Point],
    host: &[Option<Vec<f64>>; 3],
    max_corr_nm: &[i32; 3],
) -> Result<(f64, f64)> {
    let mut max_f32 = 0.0f64;
    let mut max_fixed = 0.0f64;
    for (i, p) in points.iter().enumerate() {
        let mut inp = Inputs {
            pos_nm: [0; 3],
            rev_q30: p.dir.map(|d| i32::from(d) * (1 << 30)),
            temp_mc: [0; MAX_TEMPS],
            tool_nm: nm(p.tool_mm)?,
        };
        for a in 0..3 {
            inp.pos_nm[a] = nm(p.pos_mm[a])?;
        }
        for (ch, t) in p.temp_c.iter().enumerate() {
            inp.temp_mc[ch] = mc(*t)?;
        }
        let f32_out = fw.eval_f32(&inp);
        let fixed_out = fw.eval_fixed(&inp);
        for t in 0..3 {
            let Some(h) = &host[t] else { continue };
            // The firmware clamps to the envelope's max |correction| by
            // design; with a `max_corr_um` below the model's (warned by
            // `envelope::max_corr_nm`) the check must compare like with like, or every such
            // export would fail on the clamp rather than on the arithmetic.
            let lim = f64::from(max_corr_nm[t]);
            let want = h[i].clamp(-lim, lim);
            // NaN-sticky (f64::max would drop it): a non-finite
            // difference fails the check instead of reading as 0 nm.
            max_f32 = nan_max(max_f32, (f64::from(f32_out.corr_nm[t]) - want).abs());
            max_fixed = nan_max(max_fixed, (f64::from(fixed_out.corr_nm[t]) - want).abs());
        }
    }
    Ok((max_f32, max_fixed))
}

/// The larger of `a` and `b`, NaN when either is.
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}
