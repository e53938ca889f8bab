//! The grid model (`grid:<step_mm>`): node values on a regular grid with
//! (bi/tri)linear interpolation, held at the edge outside it — its saved
//! form, its evaluation and the checks of its fields.

// Index loops mirror the formulas (and the firmware kernels) term by term.
#![allow(clippy::needless_range_loop)]

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::check::{check_finite, check_index, check_indices, check_len, need, Check};
use crate::data::{Dataset, AXES, TARGETS};

/// A grid table over `axes` with (bi/tri)linear interpolation; outside the
/// grid the value is held at the edge (as a controller's table does).
/// Node (i0, i1, …) is at origin + i·step; values are stored with the first
/// listed axis varying fastest: index = i0 + n0·(i1 + n1·i2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridModel {
    /// Axis index per grid dimension (the axes that vary in the data).
    pub axes: Vec<usize>,
    /// First node per dimension, mm.
    pub origin_mm: Vec<f64>,
    /// Node spacing, mm (same on every axis).
    pub step_mm: f64,
    /// Nodes per dimension.
    pub counts: Vec<usize>,
    /// Node values per target.
    pub outputs: Vec<GridOutput>,
}

/// Grid node values of one target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridOutput {
    /// Target index.
    pub target: usize,
    /// One value per node, µm.
    pub values_um: Vec<f64>,
}

pub(crate) fn check_grid(m: &GridModel) -> Check {
    let d = m.axes.len();
    need(
        (1..=3).contains(&d),
        || "model.axes".into(),
        || format!("{d} entries, expected 1 to 3 axes"),
    )?;
    check_indices(&m.axes, &AXES, "model.axes")?;
    check_len(m.origin_mm.len(), d, "model.origin_mm", "one per grid axis")?;
    check_finite(&m.origin_mm, "model.origin_mm")?;
    check_len(m.counts.len(), d, "model.counts", "one per grid axis")?;
    need(
        m.step_mm.is_finite() && m.step_mm > 0.0,
        || "model.step_mm".into(),
        || format!("{}, expected a positive number of mm", m.step_mm),
    )?;
    for (k, &n) in m.counts.iter().enumerate() {
        need(
            n >= 2,
            || format!("model.counts[{k}]"),
            || format!("{n}, expected at least 2 nodes"),
        )?;
    }
    let max = MAX_NODES;
    let nodes = m
        .counts
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= max)
        .ok_or_else(|| {
            format!(
                "model.counts: {:?}, expected at most {max} nodes in all",
                m.counts
            )
        })?;
    need(
        !m.outputs.is_empty(),
        || "model.outputs".into(),
        || "empty, expected one entry per target the model predicts".into(),
    )?;
    let targets: Vec<usize> = m.outputs.iter().map(|o| o.target).collect();
    for (k, o) in m.outputs.iter().enumerate() {
        check_index(o.target, &TARGETS, || format!("model.outputs[{k}].target"))?;
        need(
            !targets[..k].contains(&o.target),
            || format!("model.outputs[{k}].target"),
            || format!("{} ({}) appears twice", o.target, TARGETS[o.target]),
        )?;
        let at = format!("model.outputs[{k}].values_um");
        check_len(
            o.values_um.len(),
            nodes,
            &at,
            "one per node: the product of counts",
        )?;
        check_finite(&o.values_um, &at)?;
    }
    Ok(())
}

/// Largest table accepted (nodes); a finer grid is refused with a message.
pub const MAX_NODES: usize = 2_000_000;

/// Interpolation stencil of one point: up to 8 (node, weight) pairs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Stencil {
    pub(crate) idx: [usize; 8],
    pub(crate) w: [f64; 8],
    pub(crate) n: usize,
}

pub(crate) fn stencil(origin: &[f64], step: f64, counts: &[usize], p: &[f64]) -> Stencil {
    let d = counts.len();
    let mut base = [0usize; 3];
    let mut frac = [0.0f64; 3];
    for k in 0..d {
        let t = ((p[k] - origin[k]) / step).clamp(0.0, (counts[k] - 1) as f64);
        let i = (t.floor() as usize).min(counts[k] - 2);
        base[k] = i;
        frac[k] = t - i as f64;
    }
    let mut s = Stencil {
        idx: [0; 8],
        w: [0.0; 8],
        n: 1 << d,
    };
    for corner in 0..s.n {
        let mut idx = 0usize;
        let mut stride = 1usize;
        let mut w = 1.0;
        for k in 0..d {
            let hi = (corner >> k) & 1 == 1;
            idx += (base[k] + usize::from(hi)) * stride;
            stride *= counts[k];
            w *= if hi { frac[k] } else { 1.0 - frac[k] };
        }
        s.idx[corner] = idx;
        s.w[corner] = w;
    }
    s
}

pub(crate) fn point(data: &Dataset, axes: &[usize], r: usize) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (k, &a) in axes.iter().enumerate() {
        p[k] = data.pos(a, r);
    }
    p
}

/// Evaluates one target of a grid model at every row of `data`.
pub fn predict(m: &GridModel, o: &GridOutput, data: &Dataset) -> Result<Vec<f64>> {
    for &a in &m.axes {
        if data.pos_mm[a].is_none() {
            bail!("the grid model needs {}_mm", AXES[a]);
        }
    }
    Ok((0..data.len())
        .map(|r| {
            let s = stencil(&m.origin_mm, m.step_mm, &m.counts, &point(data, &m.axes, r));
            (0..s.n).map(|k| s.w[k] * o.values_um[s.idx[k]]).sum()
        })
        .collect())
}
