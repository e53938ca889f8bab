//! Export a fitted model (MODEL.json) to what a machine runs: the trueaxis
//! firmware table ([`table`]), a LinuxCNC screw-compensation file
//! ([`linuxcnc`]) or a Sinumerik leadscrew-error table ([`sinumerik`]).
//!
//! Sign conventions (docs/export-formats.md): the model predicts the
//! *error* e = actual − nominal in µm. A compensation must move the axis by
//! −e. The firmware table and LinuxCNC store that correction (−e, added to
//! the commanded position); Sinumerik stores +e because its controller moves
//! the axis in the negative direction for a positive value. Each writer
//! converts once, here, from the model's error.
//!
//! This module holds what the controller formats share: evaluating any
//! model kind (linear, nn, grid) along one axis with the host's own f64
//! code (`FittedModel::predict`) at a fixed state (other axes at the centre
//! of the travel, temperatures at the reference, tool length 0, time 0).

pub mod bedmesh;
pub mod linuxcnc;
pub mod sinumerik;
pub mod table;

use anyhow::{bail, Result};

use crate::data::{Dataset, TempChannel, AXES, TARGETS};
pub use crate::features::feature_uses_axis;
use crate::features::Feature;
use crate::model::{FittedModel, ModelFile};

/// A warning in an export's `--json` output and on stderr (codes:
/// `drift_left_out`, `lag_dropped`, `periodic_left_out`, …): the engine's
/// one warning type.
pub use crate::warning::Warning;

/// The travel of `axis` (0 = x) that the model was fitted on, mm, or `None`
/// when the model does not use the axis. Linear: the normalisation's span
/// (the data's span); nn: the input scaling range; grid: the nodes.
pub fn axis_travel_mm(model: &FittedModel, axis: usize) -> Option<(f64, f64)> {
    match model {
        FittedModel::Linear(m) => {
            let used = m
                .outputs
                .iter()
                .flat_map(|o| o.features.iter())
                .any(|f| feature_uses_axis(f, axis));
            used.then(|| {
                (
                    m.norm.centre_mm[axis] - m.norm.half_span_mm[axis],
                    m.norm.centre_mm[axis] + m.norm.half_span_mm[axis],
                )
            })
        }
        FittedModel::Nn(m) => m
            .inputs
            .iter()
            .position(|&a| a == axis)
            .map(|i| (m.in_min_mm[i], m.in_max_mm[i])),
        FittedModel::Grid(m) => m.axes.iter().position(|&a| a == axis).map(|i| {
            (
                m.origin_mm[i],
                m.origin_mm[i] + m.step_mm * (m.counts[i].max(1) - 1) as f64,
            )
        }),
        FittedModel::Local(m) => {
            // Like a linear model: only axes a patch's terms (or the choice
            // of patch) depend on; a line's other axes are not used.
            let used = m.stack_axis == Some(axis)
                || m.patches
                    .iter()
                    .flat_map(|p| p.outputs.iter())
                    .flat_map(|o| o.features.iter())
                    .any(|f| feature_uses_axis(f, axis));
            used.then(|| {
                (
                    m.norm.centre_mm[axis] - m.norm.half_span_mm[axis],
                    m.norm.centre_mm[axis] + m.norm.half_span_mm[axis],
                )
            })
        }
    }
}

/// Temperature channels a linear model reads, with the reference
/// temperature of the first feature that names each.
pub fn thermal_channels(model: &FittedModel) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = Vec::new();
    if let FittedModel::Linear(m) = model {
        for f in m.outputs.iter().flat_map(|o| o.features.iter()) {
            if let Feature::Thermal {
                channel, t_ref_c, ..
            } = f
            {
                if !out.iter().any(|(c, _)| c == channel) {
                    out.push((channel.clone(), *t_ref_c));
                }
            }
        }
    }
    out
}

/// One state of the machine at which a model is evaluated.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// Positions x, y, z, mm.
    pub pos_mm: [f64; 3],
    /// Direction of the last approach per axis, ±1.
    pub dir: [i8; 3],
    /// Temperatures in the order of the channel list, °C.
    pub temp_c: Vec<f64>,
    /// Tool length (Abbe arm), mm.
    pub tool_mm: f64,
}

/// The host model's error prediction (µm) at each point, per target, with
/// the host's own f64 code: the points become a [`Dataset`] (t_s = 0, one
/// session) and go through `FittedModel::predict`.
pub fn predict_points(
    model: &FittedModel,
    channels: &[String],
    points: &[Point],
) -> Result<[Option<Vec<f64>>; 3]> {
    let n = points.len();
    let col = |f: &dyn Fn(&Point) -> f64| -> Vec<f64> { points.iter().map(f).collect() };
    let data = Dataset {
        source: "export sweep".into(),
        pos_mm: [
            Some(col(&|p| p.pos_mm[0])),
            Some(col(&|p| p.pos_mm[1])),
            Some(col(&|p| p.pos_mm[2])),
        ],
        err_um: [None, None, None],
        t_s: Some(vec![0.0; n]),
        dir: [0, 1, 2].map(|a| Some(points.iter().map(|p| p.dir[a]).collect())),
        temps: channels
            .iter()
            .enumerate()
            .map(|(i, name)| TempChannel {
                name: name.clone(),
                temp_c: col(&|p| p.temp_c[i]),
            })
            .collect(),
        tool_mm: Some(col(&|p| p.tool_mm)),
        ..Dataset::default()
    };
    let pred = model.predict(&data)?;
    // A table or controller file cannot hold a non-finite correction, and
    // the envelope and accuracy check would step over NaN (f64::max ignores
    // it): refuse here, naming the point.
    for (t, v) in pred.iter().enumerate() {
        let Some(v) = v else { continue };
        if let Some(i) = v.iter().position(|e| !e.is_finite()) {
            let p = &points[i];
            bail!(
                "{}: the model predicts {} µm at x = {} mm, y = {} mm, z = {} mm — not a finite number; nothing was written",
                TARGETS[t],
                v[i],
                p.pos_mm[0],
                p.pos_mm[1],
                p.pos_mm[2]
            );
        }
    }
    Ok(pred)
}

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

/// Samples the error of `axis` along its travel at `points` evenly spaced
/// nominal positions. Periodic terms along the axis whose period is shorter
/// than 4 sample steps are left out with a warning: a controller table that
/// coarse would alias them into a wrong, longer wave (worse than nothing).
pub fn sample_axis(file: &ModelFile, axis: usize, points: usize) -> Result<AxisSamples> {
    if points < 2 {
        bail!("a compensation table needs at least 2 points, got {points}");
    }
    let target = axis; // the positioning error of an axis is along itself
    let Some((lo, hi)) = axis_travel_mm(&file.model, axis) else {
        bail!(
            "the model does not depend on {} (fitted axes: {}); choose --axis among them",
            AXES[axis],
            (0..3)
                .filter(|&a| axis_travel_mm(&file.model, a).is_some())
                .map(|a| AXES[a])
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
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
    if !chans.is_empty() {
        warnings.push(Warning::new(
            "thermal_at_reference",
            format!(
                "evaluated at the reference temperature ({}): a one-axis controller table has no temperature input",
                chans
                    .iter()
                    .map(|(c, t)| format!("T_{c}_C = {t} °C"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
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
    let shortest_mm = table::shortest_period_mm(&file.model, axis).unwrap_or(f64::INFINITY);
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

/// `v` with `decimals` decimals, never a "−0.000…" for a value that rounds
/// to zero (a minus sign on a zero reads as a direction): the number format
/// of every controller file, bed mesh and export message.
pub fn fmt_no_neg_zero(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// Refuses an export whose largest |correction| on every output is below
/// [`crate::units::TINY_CORRECTION_UM`] unless `accept` (the flag
/// `--accept-tiny-corrections`): such a file compensates nothing a machine
/// notices, and the usual cause is errors in mm written into µm columns (a
/// table 1000× too small). `host` holds each output's corrections, nm.
pub fn refuse_tiny(host: &[Option<Vec<f64>>; 3], accept: bool) -> Result<()> {
    let largest: Vec<(usize, f64)> = host
        .iter()
        .enumerate()
        .filter_map(|(t, h)| {
            h.as_ref()
                .map(|h| (t, h.iter().fold(0.0f64, |m, v| m.max(v.abs()))))
        })
        .collect();
    let tiny_nm = crate::units::TINY_CORRECTION_UM * 1000.0;
    if accept || largest.is_empty() || largest.iter().any(|&(_, m)| m >= tiny_nm) {
        return Ok(());
    }
    let list: Vec<String> = largest
        .iter()
        .map(|(t, m)| format!("{} {:.1} nm", TARGETS[*t], m))
        .collect();
    bail!(
        "the largest correction is tiny ({}, below {} µm on every output): nothing a machine would notice, or errors in mm written into µm columns (a table 1000× too small) — check the data's units; --accept-tiny-corrections exports it anyway",
        list.join(", "),
        crate::units::TINY_CORRECTION_UM
    )
}

/// The largest |correction| any export may hold, µm: the firmware table's
/// limit (`model_core::table::MAX_CORR_LIMIT_NM`), applied to the
/// controller files as well.
pub const MAX_CORR_LIMIT_UM: f64 = model_core::table::MAX_CORR_LIMIT_NM as f64 / 1000.0;

/// The max |correction| limit of output `target`, nm, shared by every
/// format: `given_um` (`--max-corr-um`) when set, else 1.5 × `model_max_nm`
/// (the largest |correction| the export holds), at least 1 µm. Refused
/// (`Err`) when not positive and finite, or above [`MAX_CORR_LIMIT_UM`];
/// the message says which number that is and what to do. Whether a
/// `given_um` below the model's largest is a warning (the firmware table
/// clamps) or a refusal (a controller file cannot) is the caller's.
pub fn max_corr_limit_nm(target: usize, model_max_nm: f64, given_um: Option<f64>) -> Result<f64> {
    let cap = MAX_CORR_LIMIT_UM;
    let name = TARGETS[target];
    match given_um {
        Some(u) => {
            if !(u.is_finite() && u > 0.0) {
                bail!("--max-corr-um must be positive, got {u}");
            }
            if u > cap {
                bail!("{name}: --max-corr-um {u} exceeds the table's limit of {cap} µm");
            }
            Ok(u * 1000.0)
        }
        None => {
            let limit_nm = (1.5 * model_max_nm).max(1000.0);
            if limit_nm > cap * 1000.0 {
                // A wildly wrong model (1e300 µm) reads as 1.5e300, not as
                // 300 digits.
                let um = |x: f64| {
                    if x < 1e6 {
                        format!("{x:.1}")
                    } else {
                        format!("{x:.2e}")
                    }
                };
                let m = um(model_max_nm / 1000.0);
                let why = if model_max_nm / 1000.0 > cap {
                    format!(
                        "the model's own largest correction ({m} µm) is above it — check the model and the data's units (an error column in nm, a temperature in K) before anything else; --max-corr-um (at most {cap}) would clamp it"
                    )
                } else {
                    format!(
                        "give the limit yourself with --max-corr-um (at most {cap}; at or above the model's {m} µm nothing is clamped)"
                    )
                };
                bail!(
                    "{name}: the default max |correction| {} µm (1.5 × the model's largest correction, {m} µm) exceeds the table's limit of {cap} µm; {why}",
                    um(limit_nm / 1000.0)
                );
            }
            Ok(limit_nm)
        }
    }
}

/// Standard CRC-32 (IEEE, as zlib and the table format use), hex `0x…`.
pub fn crc32_hex(bytes: &[u8]) -> String {
    format!("0x{:08x}", model_core::table::CRC32.checksum(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wildly_wrong_model_is_named_in_exponent_form() {
        // 1e300 µm, as a damaged or mis-scaled model file gives: the
        // message stays a line, not 300 digits.
        let e = max_corr_limit_nm(0, 1e303, None).unwrap_err().to_string();
        assert!(
            e.contains("default max |correction| 1.50e300 µm") && e.contains("(1.00e300 µm)"),
            "{e}"
        );
        assert!(e.len() < 400, "{e}");
        // Ordinary sizes keep one decimal.
        let e = max_corr_limit_nm(1, 3_068_000.0, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("ey: the default max |correction| 4602.0 µm")
                && e.contains("largest correction, 3068.0 µm"),
            "{e}"
        );
    }
}
