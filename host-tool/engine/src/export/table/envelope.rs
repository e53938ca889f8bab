//! The table's envelope (the **Envelope** of the module docs): the travel
//! and input scaling from the fitted data's span, the temperature and
//! tool-arm ranges, and the max |correction| and max slew measured on the
//! accuracy sweep; and the envelope in readable units for the JSON.

use std::collections::BTreeMap;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use model_core::table::{Envelope, InputScaling, MAX_SLEW_LIMIT_NM_PER_MS};
use model_core::MAX_TEMPS;

use super::{mc, nm, Clamped, TableError, TableOptions, Warning, UNBOUNDED_NM};
use crate::data::{AXES, TARGETS};
use crate::export::checks::{max_corr_limit_nm, MaxCorrError};
use crate::export::{axis_travel_mm, Point};
use crate::features::Feature;
use crate::model::{FittedModel, ModelFile};

/// The envelope in readable units for JSON.
#[derive(Clone, Debug, Serialize)]
pub struct EnvelopeJson {
    /// Per axis `[min, max]`, mm (`null` = unbounded).
    pub travel_mm: [Option<[f64; 2]>; 3],
    /// Per output, µm.
    pub max_corr_um: [f64; 3],
    /// nm/ms.
    pub max_slew_nm_per_ms: i32,
    /// °C: the lowest and highest end over the channels the table reads
    /// (`null` when it reads none and no range was given).
    pub temp_range_c: Option<[f64; 2]>,
    /// °C, per channel the table reads.
    pub temp_range_c_by_channel: BTreeMap<String, [f64; 2]>,
    /// mm.
    pub tool_range_mm: [f64; 2],
}

/// Per axis the travel in whole nm, `None` for an axis the model does not
/// use (unbounded).
pub(super) type Travel = [Option<(i32, i32)>; 3];

/// What bounds the inputs: per axis the travel in whole nm (`None` = an
/// axis the model does not use, unbounded), per channel the temperature
/// range, °C, and the tool-arm range, mm.
pub(super) struct Ranges {
    pub(super) travel: Travel,
    pub(super) temps_c: Vec<(f64, f64)>,
    pub(super) tool_mm: (f64, f64),
}

/// Travel on every axis the model uses (the fitted data's span, no margin)
/// and the input scaling: the model's own normalisation where it has one,
/// rounded to whole nm and widened to hold the travel.
// Per-axis arrays are indexed together; index loops read clearer.
#[allow(clippy::needless_range_loop)]
pub(super) fn travel_and_scaling(model: &FittedModel) -> Result<(Travel, InputScaling)> {
    let mut travel: Travel = [None; 3];
    let mut scaling = InputScaling {
        centre_nm: [0; 3],
        half_span_nm: [UNBOUNDED_NM; 3],
    };
    for a in 0..3 {
        if let Some((lo, hi)) = axis_travel_mm(model, a) {
            let (lo_nm, hi_nm) = (nm(lo)?, nm(hi)?);
            if hi_nm < lo_nm {
                bail!("empty travel on {}", AXES[a]);
            }
            travel[a] = Some((lo_nm, hi_nm));
            // Centre and half-span from the model's own normalisation when
            // it has one (so u is the same number on both sides).
            let (c, h) = match model {
                FittedModel::Linear(m) => (m.norm.centre_mm[a], m.norm.half_span_mm[a]),
                _ => (0.5 * (lo + hi), 0.5 * (hi - lo)),
            };
            let (c_nm, h_nm) = (nm(c)?, ((h * 1e6).round() as i64).max(1));
            // The travel must lie inside centre ± half-span after rounding.
            let h_nm = h_nm
                .max(c_nm as i64 - lo_nm as i64)
                .max(hi_nm as i64 - c_nm as i64);
            scaling.centre_nm[a] = c_nm;
            scaling.half_span_nm[a] = i32::try_from(h_nm).context("half-span")?;
        }
    }
    Ok((travel, scaling))
}

/// The fallback temperature range of a model file that does not record the
/// measured one (written before it was recorded), °C.
const FALLBACK_TEMP_RANGE_C: (f64, f64) = (10.0, 40.0);

/// The temperature range of each of `channels`, °C: `given` for every
/// channel, else the range measured in the fitted data (rounded outwards to
/// the table's 1 m°C), else 10…40 °C with the warning `temp_range_unknown`.
pub(super) fn temp_ranges(
    file: &ModelFile,
    channels: &[String],
    given: Option<(f64, f64)>,
    warnings: &mut Vec<Warning>,
) -> Result<Vec<(f64, f64)>> {
    if let Some((lo, hi)) = given {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            bail!("temperature range {lo}…{hi} °C is empty");
        }
        return Ok(vec![(lo, hi); channels.len()]);
    }
    let mut out = Vec::with_capacity(channels.len());
    let mut unknown = Vec::new();
    for c in channels {
        match file.data.temp_range_c.as_ref().and_then(|m| m.get(c)) {
            Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && lo <= hi => {
                out.push((
                    (lo * 1000.0).floor() / 1000.0,
                    (hi * 1000.0).ceil() / 1000.0,
                ));
            }
            _ => {
                unknown.push(format!("T_{c}_C"));
                out.push(FALLBACK_TEMP_RANGE_C);
            }
        }
    }
    if !unknown.is_empty() {
        let (lo, hi) = FALLBACK_TEMP_RANGE_C;
        warnings.push(Warning::new(
            "temp_range_unknown",
            format!(
                "the model file does not record the temperatures measured on {} (written by an older trueaxis): the table accepts {lo}…{hi} °C there, which may extrapolate the thermal terms beyond the data — refit the model, or give the measured range",
                unknown.join(", ")
            ),
        ));
    }
    Ok(out)
}

/// The tool-arm range, mm: `given`, else 0…300 with an Abbe term, else 0…0.
pub(super) fn tool_range(given: Option<(f64, f64)>, has_abbe: bool) -> Result<(f64, f64)> {
    let (tool_lo, tool_hi) = given.unwrap_or(if has_abbe { (0.0, 300.0) } else { (0.0, 0.0) });
    if tool_lo.is_nan() || tool_hi.is_nan() || tool_lo > tool_hi {
        bail!("tool range {tool_lo}…{tool_hi} mm is empty");
    }
    Ok((tool_lo, tool_hi))
}

/// Max |correction| per output, nm: 1.5 × the largest on the sweep
/// (`host`, nm), or `given_um`; a limit below the model's is warned
/// (`max_corr_below_model`) and returned as [`Clamped`].
pub(super) fn max_corr_nm(
    host: &[Option<Vec<f64>>; 3],
    given_um: Option<f64>,
    warnings: &mut Vec<Warning>,
) -> Result<([i32; 3], Vec<Clamped>), MaxCorrError> {
    let mut max_corr_nm = [0i32; 3];
    let mut clamped = Vec::new();
    for (t, h) in host.iter().enumerate() {
        let Some(h) = h else { continue };
        let m = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let limit = max_corr_limit_nm(t, m, given_um)?;
        if limit < m {
            warnings.push(Warning::new(
                "max_corr_below_model",
                format!(
                    "{}: the max |correction| limit {} µm is below the model's {:.3} µm: the firmware will clamp",
                    TARGETS[t],
                    limit / 1000.0,
                    m / 1000.0
                ),
            ));
            clamped.push(Clamped {
                target: t,
                limit_nm: limit,
                model_max_nm: m,
            });
        }
        max_corr_nm[t] = limit.ceil() as i32;
    }
    Ok((max_corr_nm, clamped))
}

/// Max correction slew, nm/ms: `opts.max_slew_nm_per_ms`, else 1.5 × the
/// largest gradient on the sweep's lines (`host` at `points`, nm), and of a
/// reversal's ramp over `transition_nm`, × the maximum feed.
pub(super) fn max_slew_nm_per_ms(
    model: &FittedModel,
    points: &[Point],
    host: &[Option<Vec<f64>>; 3],
    has_rev: bool,
    transition_nm: i32,
    opts: &TableOptions,
) -> Result<i32, TableError> {
    // Gradient along each axis from neighbouring points on the dense lines
    // (consecutive points that differ on one axis only).
    let mut grad_nm_per_mm = 0.0f64;
    for h in host.iter().flatten() {
        for i in 1..points.len() {
            let (p, q) = (&points[i - 1], &points[i]);
            if p.dir != q.dir || p.temp_c != q.temp_c || p.tool_mm != q.tool_mm {
                continue;
            }
            let d: Vec<f64> = (0..3).map(|a| q.pos_mm[a] - p.pos_mm[a]).collect();
            let moved = d.iter().filter(|v| v.abs() > 0.0).count();
            let dist = d.iter().map(|v| v.abs()).sum::<f64>();
            if moved == 1 && dist > 0.0 {
                grad_nm_per_mm = grad_nm_per_mm.max((h[i] - h[i - 1]).abs() / dist);
            }
        }
    }
    if has_rev && transition_nm > 0 {
        if let Some(m) = super::mapping::linear_part(model) {
            for o in &m.outputs {
                for (f, c) in o.features.iter().zip(&o.coef_um) {
                    if matches!(f, Feature::Reversal { .. }) {
                        // A swing of 2·|amp| over the transition length.
                        let g = 2.0 * c.abs() * 1000.0 / (f64::from(transition_nm) * 1e-6);
                        grad_nm_per_mm = grad_nm_per_mm.max(g);
                    }
                }
            }
        }
    }
    let feed_mm_per_ms = opts.max_feed_mm_per_min / 60_000.0;
    let limit = f64::from(MAX_SLEW_LIMIT_NM_PER_MS);
    let slew = match opts.max_slew_nm_per_ms {
        Some(s) => {
            if !(s.is_finite() && s >= 1.0) {
                return Err(TableError::SlewBelowOne { given_nm_per_ms: s });
            }
            if s > limit {
                return Err(TableError::SlewAboveTableLimit { given_nm_per_ms: s });
            }
            s
        }
        None => {
            if !(opts.max_feed_mm_per_min.is_finite() && opts.max_feed_mm_per_min > 0.0) {
                return Err(TableError::BadFeed {
                    given_mm_per_min: opts.max_feed_mm_per_min,
                });
            }
            // Capped at the format's limit: the board reduces any slew to
            // what its pulses can follow anyway.
            (1.5 * grad_nm_per_mm * feed_mm_per_ms).clamp(1.0, limit)
        }
    };
    Ok(slew.ceil() as i32)
}

/// The envelope written into the table.
pub(super) fn envelope(
    ranges: &Ranges,
    max_corr_nm: [i32; 3],
    max_slew_nm_per_ms: i32,
) -> Result<Envelope> {
    let (tool_lo, tool_hi) = ranges.tool_mm;
    let mut env = Envelope {
        travel_min_nm: [0; 3],
        travel_max_nm: [0; 3],
        max_corr_nm,
        max_slew_nm_per_ms,
        temp_min_mc: [0; MAX_TEMPS],
        temp_max_mc: [0; MAX_TEMPS],
        tool_min_nm: nm(tool_lo)?,
        tool_max_nm: nm(tool_hi)?,
    };
    for (a, t) in ranges.travel.iter().enumerate() {
        let (lo, hi) = t.unwrap_or((-UNBOUNDED_NM, UNBOUNDED_NM));
        env.travel_min_nm[a] = lo;
        env.travel_max_nm[a] = hi;
    }
    for (ch, &(lo, hi)) in ranges.temps_c.iter().enumerate() {
        env.temp_min_mc[ch] = mc(lo)?;
        env.temp_max_mc[ch] = mc(hi)?;
    }
    Ok(env)
}

/// The envelope in readable units for the JSON: `given_temp_c` (the
/// `temp_range_c` option) or the span of every channel's range.
pub(super) fn json(
    ranges: &Ranges,
    channels: &[String],
    given_temp_c: Option<(f64, f64)>,
    max_corr_nm: [i32; 3],
    max_slew_nm_per_ms: i32,
) -> EnvelopeJson {
    let (tool_lo, tool_hi) = ranges.tool_mm;
    let travel_mm = ranges
        .travel
        .map(|t| t.map(|(lo, hi)| [f64::from(lo) * 1e-6, f64::from(hi) * 1e-6]));
    EnvelopeJson {
        travel_mm,
        max_corr_um: max_corr_nm.map(|v| f64::from(v) / 1000.0),
        max_slew_nm_per_ms,
        temp_range_c: match given_temp_c {
            Some((lo, hi)) => Some([lo, hi]),
            None => ranges
                .temps_c
                .iter()
                .copied()
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
                .map(|(lo, hi)| [lo, hi]),
        },
        temp_range_c_by_channel: channels
            .iter()
            .zip(&ranges.temps_c)
            .map(|(c, &(lo, hi))| (c.clone(), [lo, hi]))
            .collect(),
        tool_range_mm: [tool_lo, tool_hi],
    }
}
