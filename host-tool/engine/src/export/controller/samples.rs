//! The error of one axis sampled along its travel: what every one-axis
//! controller table holds (LinuxCNC, Sinumerik LEC, and the formats to
//! come), evaluated with the host's own f64 model at a fixed state — the
//! other axes at the centre of their travel, temperatures at the
//! reference, tool length 0, time 0 — with what a table that coarse cannot
//! hold left out and warned, and what interpolating it loses measured.

use anyhow::{anyhow, bail};

use crate::data::{AXES, TARGETS};
use crate::export::checks::FileError;
use crate::export::{
    at_reference, axis_travel_mm, predict_points, thermal_channels, Point, Warning,
};
use crate::features::Feature;
use crate::model::{FittedModel, ModelFile};

/// The error of one axis sampled along its travel, for the controller
/// formats: both approach directions, at the fixed state described in the
/// module docs.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisSamples {
    /// Axis index (0 = x).
    pub axis: usize,
    /// Nominal positions, ascending, mm.
    pub nominal_mm: Vec<f64>,
    /// Predicted error after a positive approach, µm.
    pub err_fwd_um: Vec<f64>,
    /// Predicted error after a negative approach, µm.
    pub err_rev_um: Vec<f64>,
    /// Where the other axes stood, mm.
    pub at_mm: [f64; 3],
    /// What was left out of the model and why.
    pub warnings: Vec<Warning>,
    /// Largest difference between linear interpolation of the samples and
    /// the full model (left-out periodic and drift terms included) at the
    /// same state, on a sweep at least 16× finer than the table and fine
    /// enough for the shortest period, µm — what the controller's table
    /// loses against the model.
    pub max_interp_error_um: f64,
}

impl AxisSamples {
    /// The distance between neighbouring points, mm.
    pub fn step_mm(&self) -> f64 {
        let n = self.nominal_mm.len();
        (self.nominal_mm[n - 1] - self.nominal_mm[0]) / (n - 1) as f64
    }

    /// The mean reversal over the points, forward − reverse, µm (never
    /// −0: a minus sign on a zero reads as a direction).
    pub fn backlash_mean_um(&self) -> f64 {
        let backlash: Vec<f64> = self
            .err_fwd_um
            .iter()
            .zip(&self.err_rev_um)
            .map(|(f, r)| f - r)
            .collect();
        backlash.iter().sum::<f64>() / backlash.len() as f64 + 0.0
    }
}

/// Samples the error of `axis` along its travel at `points` evenly spaced
/// nominal positions. Periodic terms along the axis whose period is shorter
/// than 4 sample steps are left out with a warning: a controller table that
/// coarse would alias them into a wrong, longer wave (worse than nothing).
pub fn sample_axis(file: &ModelFile, axis: usize, points: usize) -> Result<AxisSamples, FileError> {
    if points < 2 {
        return Err(anyhow!("a compensation table needs at least 2 points, got {points}").into());
    }
    let Some((lo, hi)) = axis_travel_mm(&file.model, axis) else {
        return Err(FileError::AxisNotUsed {
            axis,
            fitted: (0..3)
                .filter(|&a| axis_travel_mm(&file.model, a).is_some())
                .collect(),
        });
    };
    Ok(sample_travel(file, axis, points, (lo, hi))?)
}

/// [`sample_axis`] over the travel `lo`…`hi` the model was fitted on.
fn sample_travel(
    file: &ModelFile,
    axis: usize,
    points: usize,
    (lo, hi): (f64, f64),
) -> anyhow::Result<AxisSamples> {
    let target = axis; // the positioning error of an axis is along itself
    if !file.model.targets().contains(&target) {
        bail!(
            "the model has no {} (the error along {}); a one-axis controller table needs it",
            TARGETS[target],
            AXES[axis]
        );
    }
    if hi <= lo {
        bail!(
            "the model's travel on {} is a single position ({lo} mm)",
            AXES[axis]
        );
    }
    let step = (hi - lo) / (points - 1) as f64;
    let mut warnings = Vec::new();
    let mut model = file.model.clone();
    if let FittedModel::Linear(m) = &mut model {
        for o in &mut m.outputs {
            for (f, c) in o.features.iter().zip(o.coef_um.iter_mut()) {
                match f {
                    Feature::Periodic {
                        axis: a,
                        period_mm,
                        harmonic,
                        ..
                    } if *a == axis && period_mm / f64::from(*harmonic) < 4.0 * step => {
                        if *c != 0.0 && o.target == target {
                            warnings.push(Warning::new(
                                "periodic_left_out",
                                format!(
                                    "{f} ({:.3} µm) left out: its period {:.3} mm is shorter than 4 table steps of {step:.3} mm; use more points or the firmware table",
                                    c.abs(),
                                    period_mm / f64::from(*harmonic)
                                ),
                            ));
                        }
                        *c = 0.0;
                    }
                    Feature::Drift { .. } if *c != 0.0 && o.target == target => {
                        warnings.push(Warning::new(
                            "drift_left_out",
                            format!("{f} left out: drift describes the measurement session, not the machine"),
                        ));
                        *c = 0.0;
                    }
                    _ => {}
                }
            }
        }
    }
    let mut at_mm = [0.0; 3];
    for (a, at) in at_mm.iter_mut().enumerate() {
        if a != axis {
            if let Some((l, h)) = axis_travel_mm(&model, a) {
                *at = 0.5 * (l + h);
            }
        }
    }
    let chans = thermal_channels(&model);
    let names: Vec<String> = chans.iter().map(|c| c.0.clone()).collect();
    warnings.extend(at_reference(&chans, "a one-axis controller table"));
    // A reference outside the temperatures the data were measured at: the
    // file holds the model extrapolated there.
    if let Some(ranges) = &file.data.temp_range_c {
        for (c, t) in &chans {
            if let Some(&[lo, hi]) = ranges.get(c) {
                if *t < lo || *t > hi {
                    warnings.push(Warning::new(
                        "thermal_reference_outside_data",
                        format!(
                            "T_{c}_C = {t} °C, where the file is evaluated, is outside the {lo}…{hi} °C the data were measured at: the values are the model extrapolated to it — measure at the reference temperature, or fit with t_ref_c inside the measured range"
                        ),
                    ));
                }
            }
        }
    }
    // At least 16 sweep points per table step and 16 per shortest period
    // (so a left-out short wave is seen at its full amplitude), at most
    // about 200 000 points in all.
    let shortest_mm =
        crate::export::table::shortest_period_mm(&file.model, axis).unwrap_or(f64::INFINITY);
    let fine =
        ((16.0 * step / shortest_mm).ceil() as usize).clamp(16, (100_000 / (points - 1)).max(16));
    let n_fine = (points - 1) * fine + 1;
    let mut pts = Vec::with_capacity(2 * n_fine);
    for dir in [1i8, -1] {
        for i in 0..n_fine {
            let mut pos = at_mm;
            pos[axis] = if i + 1 == n_fine {
                hi
            } else {
                lo + (hi - lo) * i as f64 / (n_fine - 1) as f64
            };
            pts.push(Point {
                pos_mm: pos,
                dir: [dir; 3],
                temp_c: chans.iter().map(|c| c.1).collect(),
                tool_mm: 0.0,
            });
        }
    }
    let pred = predict_points(&model, &names, &pts)?;
    let Some(e) = &pred[target] else {
        bail!("the model predicts no {}", TARGETS[target]);
    };
    // The full model at the same points (what was left out included).
    let full = predict_points(&file.model, &names, &pts)?;
    let Some(e_full) = &full[target] else {
        bail!("the model predicts no {}", TARGETS[target]);
    };
    let (fwd_fine, rev_fine) = e.split_at(n_fine);
    let (fwd_full, rev_full) = e_full.split_at(n_fine);
    let take = |v: &[f64]| -> Vec<f64> { v.iter().step_by(fine).copied().collect() };
    let nominal_mm: Vec<f64> = pts[..n_fine]
        .iter()
        .step_by(fine)
        .map(|p| p.pos_mm[axis])
        .collect();
    let err_fwd_um = take(fwd_fine);
    let err_rev_um = take(rev_fine);
    // Interpolation loss: linear between the table's points vs the full
    // model (`predict_points` has refused non-finite values).
    let mut max_interp_error_um = 0.0f64;
    for (fine_v, coarse) in [(fwd_full, &err_fwd_um), (rev_full, &err_rev_um)] {
        for (i, v) in fine_v.iter().enumerate() {
            let k = (i / fine).min(points - 2);
            let t = (i - k * fine) as f64 / fine as f64;
            let interp = coarse[k] + t * (coarse[k + 1] - coarse[k]);
            max_interp_error_um = max_interp_error_um.max((interp - v).abs());
        }
    }
    Ok(AxisSamples {
        axis,
        nominal_mm,
        err_fwd_um,
        err_rev_um,
        at_mm,
        warnings,
        max_interp_error_um,
    })
}
