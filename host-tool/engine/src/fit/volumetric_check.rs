//! How well a rigid21 model predicts a machine whose errors are known (the
//! simulator's): the error at tool points the fit never saw — other tool
//! lengths, other lateral offsets, other places in the volume — before
//! compensation and after it. The demo's volumetric chapter and the tests
//! judge a rigid21 fit by this, not by its residual on its own readings.
//!
//! The model is in the ISO 230-1 gauge (the frame no measurement fixes is
//! fixed by convention), the machine in its own; the two differ by a rigid
//! motion that no compensation can or needs to remove (the work offset and
//! the part's set-up take it). So one rigid frame — three translations,
//! three small rotations — is fitted over all check points, once for the
//! uncompensated error and once for what the model leaves, and the figures
//! are what remains after it.

use nalgebra::{DMatrix, DVector};

use crate::model::rigid21::{Rigid21Model, ToolPoint};
use crate::simulate::instruments::{measure, Instrument};
use crate::simulate::Machine;

/// `plan` measured on `machine` with noise (`seed`), restricted to the
/// axes `keep_axes`, fitted at `degree`, and judged against the same
/// plan's noise-free fit — the truth in the gauge when the degree holds
/// the machine: the noisy fit and every estimated error further than 4σ
/// from the noise-free value, in words (empty: no confident wrong
/// answer).
pub fn against_noise_free(
    machine: &Machine,
    plan: &[Instrument],
    keep_axes: &[usize],
    degree: usize,
    seed: u64,
) -> anyhow::Result<(super::rigid21::Fitted, Vec<String>)> {
    let cut = |mut d: crate::data::Dataset| {
        for a in 0..3 {
            if !keep_axes.contains(&a) {
                d.pos_mm[a] = None;
            }
        }
        d
    };
    let noisy = super::rigid21::fit(&cut(measure(machine, plan, seed, true)), degree)?;
    let (_, exact, _) = super::rigid21::fit(&cut(measure(machine, plan, seed, false)), degree)?;
    let mut wrong = Vec::new();
    for (e, t) in noisy.1.errors.iter().zip(&exact.errors) {
        if let (Some(v), Some(s)) = (e.peak, e.sigma) {
            match t.peak {
                Some(tv) if (v - tv).abs() <= 4.0 * s + 1e-6 => {}
                tv => wrong.push(format!("{}: {v} ± {s}, noise-free {tv:?}", e.name)),
            }
        }
    }
    Ok((noisy, wrong))
}

/// The error at one tool length's check points, µm (vector lengths).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ToolCheck {
    /// Tool length, mm.
    pub tool_mm: f64,
    /// Check points at this tool length.
    pub points: usize,
    /// Uncompensated: RMS and largest error.
    pub before_rms_um: f64,
    /// See `before_rms_um`.
    pub before_max_um: f64,
    /// What the model leaves: RMS and largest.
    pub after_rms_um: f64,
    /// See `after_rms_um`.
    pub after_max_um: f64,
}

/// `model` against the true errors of `machine` at `points` seeded points
/// over the volume, each at every tool length of `tools_mm` and at lateral
/// offsets (0, 0) and (50, −50) mm; one [`ToolCheck`] per tool length.
pub fn against_machine(
    machine: &Machine,
    model: &Rigid21Model,
    tools_mm: &[f64],
    points: usize,
    seed: u64,
) -> Vec<ToolCheck> {
    let at = measure(
        machine,
        &[Instrument::Tracker {
            tools_mm: tools_mm.to_vec(),
            lateral_mm: vec![[0.0, 0.0], [50.0, -50.0]],
            points,
        }],
        seed,
        false,
    );
    let pts: Vec<ToolPoint> = (0..at.len()).map(|r| ToolPoint::of_row(&at, r)).collect();
    let truth: Vec<[f64; 3]> = pts
        .iter()
        .map(|p| machine.error_at_um(p.pos_mm, p.tool_mm, p.tool_lat_mm))
        .collect();
    let left: Vec<[f64; 3]> = pts
        .iter()
        .zip(&truth)
        .map(|(p, e)| {
            let m = model.predict(p).e_um;
            [0, 1, 2].map(|c| e[c] - m[c])
        })
        .collect();
    let before = after_frame(&pts, &truth);
    let after = after_frame(&pts, &left);
    tools_mm
        .iter()
        .map(|&t| {
            let rows: Vec<usize> = (0..pts.len())
                .filter(|&r| (pts[r].tool_mm - t).abs() < 1e-9)
                .collect();
            let (b_rms, b_max) = rms_max(&rows, &before);
            let (a_rms, a_max) = rms_max(&rows, &after);
            ToolCheck {
                tool_mm: t,
                points: rows.len(),
                before_rms_um: b_rms,
                before_max_um: b_max,
                after_rms_um: a_rms,
                after_max_um: a_max,
            }
        })
        .collect()
}

/// The length of each error vector once the best rigid frame (translation
/// and small rotation, least squares over all points) is taken out.
fn after_frame(pts: &[ToolPoint], e: &[[f64; 3]]) -> Vec<f64> {
    let n = pts.len();
    let mut a = DMatrix::zeros(3 * n, 6);
    let mut d = DVector::zeros(3 * n);
    for (r, (pt, e)) in pts.iter().zip(e).enumerate() {
        let p = pt.point_mm();
        for c in 0..3 {
            a[(3 * r + c, c)] = 1.0;
            d[3 * r + c] = e[c];
        }
        // ω × p, ω in µrad, p in mm → µm.
        a[(3 * r, 4)] = p[2] * 1e-3;
        a[(3 * r, 5)] = -p[1] * 1e-3;
        a[(3 * r + 1, 3)] = -p[2] * 1e-3;
        a[(3 * r + 1, 5)] = p[0] * 1e-3;
        a[(3 * r + 2, 3)] = p[1] * 1e-3;
        a[(3 * r + 2, 4)] = -p[0] * 1e-3;
    }
    let x = a
        .clone()
        .svd(true, true)
        .solve(&d, 1e-12)
        .unwrap_or_else(|_| DVector::zeros(6));
    let res = d - a * x;
    (0..n)
        .map(|r| (0..3).map(|c| res[3 * r + c].powi(2)).sum::<f64>().sqrt())
        .collect()
}

/// RMS and largest of `v` over `rows` (0 and 0 for none).
fn rms_max(rows: &[usize], v: &[f64]) -> (f64, f64) {
    if rows.is_empty() {
        return (0.0, 0.0);
    }
    let ss: f64 = rows.iter().map(|&r| v[r] * v[r]).sum();
    let max = rows.iter().map(|&r| v[r]).fold(0.0, f64::max);
    ((ss / rows.len() as f64).sqrt(), max)
}
