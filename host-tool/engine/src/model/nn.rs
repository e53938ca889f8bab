//! The tanh network model (`nn:<hidden>`): its weights and scaling as saved
//! in MODEL.json, the network's forward pass (which training in
//! `fit::nn` also runs) and its evaluation on a data set.

// Index loops mirror the formulas (and the firmware kernels) term by term.
#![allow(clippy::needless_range_loop)]

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::check::{check_finite, check_indices, check_len, need, Check};
use crate::data::{Dataset, AXES, TARGETS};

/// A tanh MLP, one network for all targets: inputs are the axes in
/// `inputs`, min-max scaled to [−1, 1]; outputs are the targets in
/// `outputs`, scaled back from [−1, 1]. y = W2·tanh(W1·x + b1) + b2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NnModel {
    /// Axis index per input.
    pub inputs: Vec<usize>,
    /// Target index per output.
    pub outputs: Vec<usize>,
    /// Input range per input (mm) mapped to [−1, 1].
    pub in_min_mm: Vec<f64>,
    /// Upper end of each input range (mm).
    pub in_max_mm: Vec<f64>,
    /// Output range per output (µm) mapped to [−1, 1].
    pub out_min_um: Vec<f64>,
    /// Upper end of each output range (µm).
    pub out_max_um: Vec<f64>,
    /// Hidden neurons.
    pub hidden: usize,
    /// Hidden weights, row-major hidden × inputs.
    pub w1: Vec<f64>,
    /// Hidden biases.
    pub b1: Vec<f64>,
    /// Output weights, row-major outputs × hidden.
    pub w2: Vec<f64>,
    /// Output biases.
    pub b2: Vec<f64>,
    /// Training summary.
    pub training: NnTraining,
}

/// How a network was trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NnTraining {
    /// Epochs run.
    pub epochs: usize,
    /// Epoch whose weights were kept (best validation error).
    pub best_epoch: usize,
    /// Why training stopped (`validation` after 6 failures, `max_epochs`, `mu_max`, `min_grad`).
    pub stop: String,
    /// RNG seed of the Nguyen–Widrow initialisation and the split.
    pub seed: u64,
    /// Rows used for training / validation (early stopping) / test (held-out RMS).
    pub split_rows: [usize; 3],
}

pub(crate) fn check_nn(m: &NnModel) -> Check {
    let (nin, nh, nout) = (m.inputs.len(), m.hidden, m.outputs.len());
    need(
        nin >= 1,
        || "model.inputs".into(),
        || "empty, expected at least one axis".into(),
    )?;
    need(
        nout >= 1,
        || "model.outputs".into(),
        || "empty, expected at least one target".into(),
    )?;
    need(
        nh >= 1,
        || "model.hidden".into(),
        || "0, expected at least 1 neuron".into(),
    )?;
    check_indices(&m.inputs, &AXES, "model.inputs")?;
    check_indices(&m.outputs, &TARGETS, "model.outputs")?;
    let ranges = [
        ("in_min_mm", &m.in_min_mm, nin, "one per input"),
        ("in_max_mm", &m.in_max_mm, nin, "one per input"),
        ("out_min_um", &m.out_min_um, nout, "one per output"),
        ("out_max_um", &m.out_max_um, nout, "one per output"),
        ("w1", &m.w1, nh * nin, "hidden × inputs"),
        ("b1", &m.b1, nh, "one per hidden neuron"),
        ("w2", &m.w2, nout * nh, "outputs × hidden"),
        ("b2", &m.b2, nout, "one per output"),
    ];
    for (name, v, want, of) in ranges {
        let at = format!("model.{name}");
        check_len(v.len(), want, &at, of)?;
        check_finite(v, &at)?;
    }
    // Each range's bounds in order: (name's stem and unit, lows, highs).
    let ranges = [
        ("in", "mm", &m.in_min_mm, &m.in_max_mm),
        ("out", "um", &m.out_min_um, &m.out_max_um),
    ];
    for (side, unit, mins, maxs) in ranges {
        for (k, (lo, hi)) in mins.iter().zip(maxs).enumerate() {
            need(
                lo <= hi,
                || format!("model.{side}_max_{unit}[{k}]"),
                || format!("{hi}, expected ≥ {side}_min_{unit}[{k}] = {lo}"),
            )?;
        }
    }
    Ok(())
}

/// Min-max map to [−1, 1]; a constant maps to 0.
pub(crate) fn scale(v: f64, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        2.0 * (v - lo) / (hi - lo) - 1.0
    } else {
        0.0
    }
}

pub(crate) fn unscale(v: f64, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        (v + 1.0) * 0.5 * (hi - lo) + lo
    } else {
        lo
    }
}

/// Network shape and packed parameters: W1 (h × n_in, row-major), b1 (h),
/// W2 (n_out × h, row-major), b2 (n_out).
#[derive(Clone, Debug)]
pub(crate) struct Net {
    pub(crate) nin: usize,
    pub(crate) nh: usize,
    pub(crate) nout: usize,
    pub(crate) p: Vec<f64>,
}

impl Net {
    pub(crate) fn n_params(nin: usize, nh: usize, nout: usize) -> usize {
        nh * nin + nh + nout * nh + nout
    }
    pub(crate) fn w1(&self, j: usize, i: usize) -> f64 {
        self.p[j * self.nin + i]
    }
    pub(crate) fn b1(&self, j: usize) -> f64 {
        self.p[self.nh * self.nin + j]
    }
    pub(crate) fn w2_off(&self) -> usize {
        self.nh * self.nin + self.nh
    }
    pub(crate) fn w2(&self, o: usize, j: usize) -> f64 {
        self.p[self.w2_off() + o * self.nh + j]
    }
    pub(crate) fn b2_off(&self) -> usize {
        self.w2_off() + self.nout * self.nh
    }

    /// Hidden activations into `a` and outputs into `y` for one input.
    pub(crate) fn forward(&self, x: &[f64], a: &mut [f64], y: &mut [f64]) {
        for j in 0..self.nh {
            let mut s = self.b1(j);
            for (i, xi) in x.iter().enumerate() {
                s += self.w1(j, i) * xi;
            }
            a[j] = s.tanh();
        }
        let b2 = self.b2_off();
        for o in 0..self.nout {
            let mut s = self.p[b2 + o];
            for (j, aj) in a.iter().enumerate() {
                s += self.w2(o, j) * aj;
            }
            y[o] = s;
        }
    }
}

/// Network outputs (µm) per output of the model, per row of `data`.
pub fn predict(m: &NnModel, data: &Dataset) -> Result<Vec<Vec<f64>>> {
    for &a in &m.inputs {
        if data.pos_mm[a].is_none() {
            bail!("the network needs {}_mm", AXES[a]);
        }
    }
    let (nin, nh, nout) = (m.inputs.len(), m.hidden, m.outputs.len());
    let mut p = m.w1.clone();
    p.extend(&m.b1);
    p.extend(&m.w2);
    p.extend(&m.b2);
    if p.len() != Net::n_params(nin, nh, nout) {
        bail!("network weights do not match its shape {nin}-{nh}-{nout}");
    }
    let net = Net { nin, nh, nout, p };
    let mut out = vec![Vec::with_capacity(data.len()); nout];
    let (mut x, mut a, mut y) = (vec![0.0; nin], vec![0.0; nh], vec![0.0; nout]);
    for r in 0..data.len() {
        for (k, &ax) in m.inputs.iter().enumerate() {
            x[k] = scale(data.pos(ax, r), m.in_min_mm[k], m.in_max_mm[k]);
        }
        net.forward(&x, &mut a, &mut y);
        for o in 0..nout {
            out[o].push(unscale(y[o], m.out_min_um[o], m.out_max_um[o]));
        }
    }
    Ok(out)
}
