//! Export a fitted model (MODEL.json) to what a machine runs, with every
//! decision that takes — defaults, sign conventions, what is left out,
//! what is refused — made here, typed, and tested; the command line only
//! turns flags into the options below and prints the result.
//!
//! - [`table`]: the trueaxis firmware table, with the accuracy check
//!   ([`table::export`] → [`table::TableExport`] or a
//!   [`table::TableError`]).
//! - [`controller`]: a controller's compensation file — LinuxCNC screw
//!   compensation, Sinumerik LEC — one file per format behind the
//!   [`controller::ControllerFormat`] trait ([`controller::export`] →
//!   [`controller::ControllerExport`] or a [`checks::FileError`]).
//! - [`mesh`]: a 3-D printer's bed mesh, RepRapFirmware or Klipper
//!   ([`mesh::export`] → [`mesh::MeshExport`] or a
//!   [`checks::FileError`]).
//! - [`skew`]: the squarenesses of a rigid21 model as a firmware's skew
//!   correction — Klipper, Marlin `M852`, LinuxCNC `matrixkins` —
//!   with what it leaves out ([`skew::export`] → [`skew::SkewExport`] or
//!   a [`checks::FileError`]).
//! - [`checks`]: what every export checks before it writes (tiny
//!   corrections, the max |correction| limit, a file that cannot clamp)
//!   and the typed refusals.
//!
//! Sign conventions (docs/export-formats.md): the model predicts the
//! *error* e = actual − nominal in µm. A compensation must move the axis by
//! −e. The firmware table and LinuxCNC store that correction (−e, added to
//! the commanded position); Sinumerik stores +e because its controller moves
//! the axis in the negative direction for a positive value; a bed mesh
//! stores the height −ez. Each writer converts once, from the model's
//! error.
//!
//! Messages name no command-line flag: they say what is wrong in the
//! options' terms, and refusals carry their numbers, so that the CLI can
//! word them with its flags.
//!
//! This module holds what the formats share: evaluating any model kind
//! (linear, nn, grid, local) at given states with the host's own f64 code
//! (`FittedModel::predict`), the travel a model was fitted on, and the
//! number format of the files.

pub mod checks;
pub mod controller;
#[cfg(test)]
mod fixtures;
pub mod mesh;
pub mod skew;
pub mod table;

use anyhow::{bail, Result};

use crate::data::{Dataset, TempChannel, TARGETS};
pub use crate::features::feature_uses_axis;
use crate::features::Feature;
use crate::model::FittedModel;

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
        FittedModel::Rigid21(m) => m.travel_mm[axis].map(|[lo, hi]| (lo, hi)),
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

/// The warning `outside_travel` of every export of a model fitted without
/// rows outside its travel (MODEL.json `data.outside_travel`,
/// `crate::travel`): the rows named again, and that the export covers the
/// travel the model was fitted on, not those rows.
pub fn outside_travel(file: &crate::model::ModelFile) -> Option<Warning> {
    crate::travel::summary(&file.data.source, &file.data.outside_travel).map(|s| {
        Warning::new(
            "outside_travel",
            format!("{s}; the export covers the travel the model was fitted on, not these rows"),
        )
    })
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

/// The warning `thermal_at_reference` of a file evaluated at the reference
/// temperatures `chans` (from [`thermal_channels`]; `None` without
/// thermal terms): `holder` (`a bed mesh`) has no temperature input.
pub(crate) fn at_reference(chans: &[(String, f64)], holder: &str) -> Option<Warning> {
    (!chans.is_empty()).then(|| {
        Warning::new(
            "thermal_at_reference",
            format!(
                "evaluated at the reference temperature ({}): {holder} has no temperature input",
                chans
                    .iter()
                    .map(|(c, t)| format!("T_{c}_C = {t} °C"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })
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

/// Standard CRC-32 (IEEE, as zlib and the table format use), hex `0x…`.
pub fn crc32_hex(bytes: &[u8]) -> String {
    format!("0x{:08x}", model_core::table::CRC32.checksum(bytes))
}
