//! Levenberg–Marquardt training of the network, as MATLAB's `trainlm`: the
//! Nguyen–Widrow initialisation, the scaled samples, the Jacobian by
//! backpropagation and JᵀJ from its block structure, and one early-stopped
//! run (`run_lm`). The options, the split and the restarts are in the
//! parent module.

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use nalgebra::{Cholesky, DMatrix, DMatrixView, DVector};
use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Epoch, NnOptions};
use crate::model::nn::Net;

impl Net {
    /// Nguyen–Widrow initialisation for inputs in [−1, 1].
    pub(super) fn init(nin: usize, nh: usize, nout: usize, seed: u64) -> Net {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Uniform in [lo, hi) from 53 random bits (no `rand` dependency needed).
        let mut uniform = |lo: f64, hi: f64| {
            lo + (hi - lo) * ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
        };
        let mut net = Net {
            nin,
            nh,
            nout,
            p: vec![0.0; Net::n_params(nin, nh, nout)],
        };
        let beta = 0.7 * (nh as f64).powf(1.0 / nin as f64);
        for j in 0..nh {
            let mut row: Vec<f64> = (0..nin).map(|_| uniform(-1.0, 1.0)).collect();
            let norm = row.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
            for v in &mut row {
                *v *= beta / norm;
            }
            net.p[j * nin..(j + 1) * nin].copy_from_slice(&row);
            net.p[nh * nin + j] = uniform(-beta, beta);
        }
        let w2 = net.w2_off();
        for k in w2..net.p.len() {
            net.p[k] = uniform(-0.5, 0.5);
        }
        net
    }
}

/// tanh through one `exp` for training: 1 − 2/(e^{2x} + 1), within a few
/// 1e-16 of `f64::tanh` in absolute terms (which is all a weight update
/// needs) and half its cost — glibc's tanh goes through expm1 and was a
/// quarter of all training instructions. ±∞ and NaN come out as tanh's.
/// `predict` (what is exported and compared) keeps `f64::tanh`.
pub(super) fn tanh_fast(x: f64) -> f64 {
    1.0 - 2.0 / ((2.0 * x).exp() + 1.0)
}

/// Scaled data of one set: inputs n × nin (row-major) and, per output, the
/// residual entries (sample, scaled target, √weight) in sample order. Kept
/// output by output so that the Jacobian's output-layer columns of one
/// output form one contiguous block (see [`Lm::normal_equations`]).
pub(super) struct Samples {
    pub(super) n: usize,
    pub(super) x: Vec<f64>,
    pub(super) by_out: Vec<Vec<(usize, f64, f64)>>,
}

impl Samples {
    pub(super) fn n_entries(&self) -> usize {
        self.by_out.iter().map(Vec::len).sum()
    }

    /// Hidden activations (n × nh) and outputs (n × nout) of every sample.
    /// The training loop's hot path (one call per μ trial): slices instead
    /// of indexed parameters, and [`tanh_fast`].
    pub(super) fn forward(&self, net: &Net, act: &mut [f64], out: &mut [f64]) {
        let (nin, nh, nout) = (net.nin, net.nh, net.nout);
        let (w1, rest) = net.p.split_at(nh * nin);
        let (b1, rest) = rest.split_at(nh);
        let (w2, b2) = rest.split_at(nout * nh);
        for ((x, a), y) in self
            .x
            .chunks_exact(nin)
            .zip(act.chunks_exact_mut(nh))
            .zip(out.chunks_exact_mut(nout))
        {
            for ((aj, wj), bj) in a.iter_mut().zip(w1.chunks_exact(nin)).zip(b1) {
                *aj = tanh_fast(wj.iter().zip(x).fold(*bj, |s, (w, xi)| s + w * xi));
            }
            for ((yo, w2o), bo) in y.iter_mut().zip(w2.chunks_exact(nh)).zip(b2) {
                *yo = w2o.iter().zip(a.iter()).fold(*bo, |s, (w, aj)| s + w * aj);
            }
        }
    }

    /// Sum of squared weighted residuals from the outputs of `forward`.
    pub(super) fn sse_of(&self, out: &[f64], nout: usize) -> f64 {
        let mut sse = 0.0;
        for (o, es) in self.by_out.iter().enumerate() {
            for &(s, t, sw) in es {
                let e = sw * (out[s * nout + o] - t);
                sse += e * e;
            }
        }
        sse
    }

    /// Jacobian (entries × params, entries output by output) and residuals,
    /// dense. The training loop never forms it (see [`Lm`]); it is the
    /// reference the tests check the LM normal equations against.
    #[cfg(test)]
    pub(super) fn jacobian(&self, net: &Net) -> (DMatrix<f64>, DVector<f64>) {
        let np = net.p.len();
        let m = self.n_entries();
        let mut j = DMatrix::zeros(m, np);
        let mut e = DVector::zeros(m);
        let mut act = vec![0.0; self.n * net.nh];
        let mut out = vec![0.0; self.n * net.nout];
        self.forward(net, &mut act, &mut out);
        let (w2o, b2o, b1o) = (net.w2_off(), net.b2_off(), net.nh * net.nin);
        let mut row = 0;
        for (o, es) in self.by_out.iter().enumerate() {
            for &(s, t, sw) in es {
                let x = &self.x[s * net.nin..(s + 1) * net.nin];
                let a = &act[s * net.nh..(s + 1) * net.nh];
                e[row] = sw * (out[s * net.nout + o] - t);
                for h in 0..net.nh {
                    let d = sw * net.w2(o, h) * (1.0 - a[h] * a[h]);
                    for (i, xi) in x.iter().enumerate() {
                        j[(row, h * net.nin + i)] = d * xi;
                    }
                    j[(row, b1o + h)] = d;
                    j[(row, w2o + o * net.nh + h)] = sw * a[h];
                }
                j[(row, b2o + o)] = sw;
                row += 1;
            }
        }
        (j, e)
    }
}

/// Workspace of Levenberg–Marquardt on one training set, allocated once per
/// training and reused every epoch and restart.
///
/// JᵀJ is formed from the structure of J rather than as a dense product. The
/// row of J for sample s and output o is √w_s · [w2[o,h]·g_h·x̃_i (hidden
/// weights and biases, g = 1 − a², x̃ = (x, 1)) | ã = (a, 1) in the columns
/// of output o only]. So with z_s = g ⊗ x̃ (the hidden part without the
/// output weight) and the outputs measured on s written as its pattern p:
///
/// - HᵀH[k,k'] = Σₚ Wₚ[h(k),h(k')] · Σ_{s∈p} w_s z_s[k] z_s[k'], where
///   Wₚ[h,h'] = Σ_{o∈p} w2[o,h]·w2[o,h'] — the sum over outputs moves out of
///   the sum over samples;
/// - the hidden × output-o block is w2[o,h(k)] · Σ_{s∋o} w_s z_s[k] ã_s[r];
/// - the output-o block is Σ_{s∋o} w_s ã_s ã_sᵀ; outputs do not couple.
///
/// All three are blocks of one Gram matrix of the per-sample vectors
/// m_s = √w_s (z_s, ã_s), one per measurement pattern (usually a single
/// one: every target measured on every row), formed by GEMMs of its upper
/// block triangle, mirrored. For 3-16-3 on 1581 samples that is at most
/// 81² × 1581 = 10 M multiply-adds (2/3 of it with the 3 × 3 blocks) where the
/// product over the 4 743 rows of J takes 63 M (26 M when only its
/// hidden/own-output blocks are multiplied), with Jᵀe from the same vectors.
/// The weight of a sample is the same for all its outputs (u_um is per
/// row), which is what lets the outputs share one Gram matrix.
pub(super) struct Lm {
    /// Hidden neuron of each hidden parameter (weights h·nin + i, then
    /// biases): nz = nh·(nin + 1) entries, the z part of m_s.
    pub(super) hid: Vec<usize>,
    /// Samples grouped by measurement pattern: (bitmask of outputs, first
    /// column, end column) of `mt`.
    pub(super) groups: Vec<(u32, usize, usize)>,
    /// Sample index of each column of `mt`.
    pub(super) order: Vec<usize>,
    /// √w of each sample, targets per (sample, output) (NaN: not measured).
    pub(super) sw: Vec<f64>,
    pub(super) target: Vec<f64>,
    /// m_s per column (nm × samples, column-major: each sample contiguous);
    /// nm = nz + nh + 1 rows, z then ã.
    pub(super) mt: DMatrix<f64>,
    /// One Gram matrix (nm × nm) per group.
    pub(super) gram: Vec<DMatrix<f64>>,
    pub(super) jtj: DMatrix<f64>,
    pub(super) g: DVector<f64>,
    /// Activations and outputs of the current network on the training set.
    pub(super) act: Vec<f64>,
    pub(super) out: Vec<f64>,
    /// Per-sample scratch: residuals by output (NaN: not measured) and
    /// Σₒ w2[o,h]·e_o by hidden neuron.
    e: Vec<f64>,
    q: Vec<f64>,
    /// JᵀJ + μI, factored in place (reused by every μ trial).
    pub(super) a: DMatrix<f64>,
    pub(super) delta: DVector<f64>,
}

impl Lm {
    pub(super) fn new(train: &Samples, nin: usize, nh: usize, nout: usize) -> Lm {
        let nz = nh * (nin + 1);
        let nm = nz + nh + 1;
        let n = train.n;
        let mut mask = vec![0u32; n];
        let mut sw = vec![0.0; n];
        let mut target = vec![f64::NAN; n * nout];
        for (o, es) in train.by_out.iter().enumerate() {
            for &(s, t, w) in es {
                mask[s] |= 1 << o;
                sw[s] = w;
                target[s * nout + o] = t;
            }
        }
        let mut order: Vec<usize> = (0..n).filter(|&s| mask[s] != 0).collect();
        order.sort_by_key(|&s| mask[s]);
        let mut groups: Vec<(u32, usize, usize)> = Vec::new();
        for (c, &s) in order.iter().enumerate() {
            match groups.last_mut() {
                Some(g) if g.0 == mask[s] => g.2 = c + 1,
                _ => groups.push((mask[s], c, c + 1)),
            }
        }
        let np = Net::n_params(nin, nh, nout);
        Lm {
            hid: (0..nz)
                .map(|k| if k < nh * nin { k / nin } else { k - nh * nin })
                .collect(),
            gram: vec![DMatrix::zeros(nm, nm); groups.len()],
            mt: DMatrix::zeros(nm, order.len()),
            groups,
            order,
            sw,
            target,
            jtj: DMatrix::zeros(np, np),
            g: DVector::zeros(np),
            act: vec![0.0; n * nh],
            out: vec![0.0; n * nout],
            e: vec![0.0; nout],
            q: vec![0.0; nh],
            a: DMatrix::zeros(np, np),
            delta: DVector::zeros(np),
        }
    }

    /// JᵀJ and g = Jᵀe at `net`, whose activations on `train` are in
    /// `self.act` / `self.out`.
    pub(super) fn normal_equations(&mut self, train: &Samples, net: &Net) {
        let (nin, nh, nout) = (net.nin, net.nh, net.nout);
        let (nz, nm) = (self.hid.len(), self.mt.nrows());
        let (w2o, b2o) = (net.w2_off(), net.b2_off());
        let w2 = &net.p[w2o..b2o];
        let hid = &self.hid;
        let pidx = |o: usize, r: usize| if r < nh { w2o + o * nh + r } else { b2o + o };
        self.g.fill(0.0);
        {
            // Slices split once per sample instead of indexed (bounds-checked)
            // accesses: this loop touches every sample and every parameter.
            // The sums run in the same order as the indexed form did.
            let mt = self.mt.as_mut_slice();
            let (g_hid, g_out) = self.g.as_mut_slice().split_at_mut(nz);
            let (g_w1, g_b1) = g_hid.split_at_mut(nh * nin);
            let (g_w2, g_b2) = g_out.split_at_mut(nout * nh);
            let q = &mut self.q;
            let e = &mut self.e;
            for (c, &s) in self.order.iter().enumerate() {
                let x = &train.x[s * nin..(s + 1) * nin];
                let a = &self.act[s * nh..(s + 1) * nh];
                let sw = self.sw[s];
                let col = &mut mt[c * nm..(c + 1) * nm];
                let (z, at) = col.split_at_mut(nz);
                let (zw, zb) = z.split_at_mut(nh * nin);
                // Jᵀe: e_{s,o} = √w (y − t) on the measured outputs.
                let targets = &self.target[s * nout..(s + 1) * nout];
                let outs = &self.out[s * nout..(s + 1) * nout];
                for o in 0..nout {
                    e[o] = if targets[o].is_nan() {
                        f64::NAN
                    } else {
                        sw * (outs[o] - targets[o])
                    };
                }
                q.fill(0.0);
                for o in 0..nout {
                    let eo = e[o];
                    if eo.is_nan() {
                        continue;
                    }
                    for (qh, w) in q.iter_mut().zip(&w2[o * nh..(o + 1) * nh]) {
                        *qh += w * eo;
                    }
                }
                for (h, ((zwh, zbh), ah)) in zw
                    .chunks_exact_mut(nin)
                    .zip(zb.iter_mut())
                    .zip(a)
                    .enumerate()
                {
                    let d = sw * (1.0 - ah * ah);
                    for (zi, xi) in zwh.iter_mut().zip(x) {
                        *zi = d * xi;
                    }
                    *zbh = d;
                    at[h] = sw * ah;
                }
                at[nh] = sw;
                for o in 0..nout {
                    let eo = e[o];
                    if eo.is_nan() {
                        continue;
                    }
                    for (gk, ak) in g_w2[o * nh..(o + 1) * nh].iter_mut().zip(&at[..nh]) {
                        *gk += ak * eo;
                    }
                    g_b2[o] += at[nh] * eo;
                }
                for ((gk, zk), qh) in g_w1
                    .chunks_exact_mut(nin)
                    .zip(zw.chunks_exact(nin))
                    .zip(q.iter())
                {
                    for (gi, zi) in gk.iter_mut().zip(zk) {
                        *gi += zi * qh;
                    }
                }
                for ((gk, zk), qh) in g_b1.iter_mut().zip(zb.iter()).zip(q.iter()) {
                    *gk += zk * qh;
                }
            }
        }
        for (gi, &(_, c0, c1)) in self.groups.iter().enumerate() {
            // mtᵀ read as its transpose (a strided view, no copy).
            let cols = &self.mt.as_slice()[c0 * nm..c1 * nm];
            let len = c1 - c0;
            let tview = DMatrixView::from_slice_with_strides(cols, len, nm, nm, 1);
            // Symmetric: only the blocks on and above the diagonal of a
            // 3 × 3 block partition are multiplied (6 of the 9 blocks: 2/3 of
            // the products), the rest mirrored.
            let gram = &mut self.gram[gi];
            let cuts = [0, nm / 3, 2 * nm / 3, nm];
            for b in 0..3 {
                let (r0, r1) = (cuts[b], cuts[b + 1]);
                gram.view_mut((r0, r0), (r1 - r0, nm - r0)).gemm(
                    1.0,
                    &self.mt.view((r0, c0), (r1 - r0, len)),
                    &tview.columns(r0, nm - r0),
                    0.0,
                );
            }
            gram.fill_lower_triangle_with_upper_triangle();
        }
        self.jtj.fill(0.0);
        let mut wp = vec![0.0; nh * nh];
        for (gi, &(mask, _, _)) in self.groups.iter().enumerate() {
            let gram = &self.gram[gi];
            wp.fill(0.0);
            for o in (0..nout).filter(|o| mask & (1 << o) != 0) {
                let w2o = &w2[o * nh..(o + 1) * nh];
                for h in 0..nh {
                    for h2 in 0..nh {
                        wp[h * nh + h2] += w2o[h] * w2o[h2];
                    }
                }
                for r in 0..=nh {
                    let pr = pidx(o, r);
                    for k in 0..nz {
                        let v = w2o[hid[k]] * gram[(k, nz + r)];
                        self.jtj[(k, pr)] += v;
                        self.jtj[(pr, k)] += v;
                    }
                    for r2 in 0..=nh {
                        self.jtj[(pr, pidx(o, r2))] += gram[(nz + r, nz + r2)];
                    }
                }
            }
            for k2 in 0..nz {
                for k in 0..nz {
                    self.jtj[(k, k2)] += wp[hid[k] * nh + hid[k2]] * gram[(k, k2)];
                }
            }
        }
    }
}

/// The outcome of one LM run from one initialisation.
pub(super) struct Run {
    /// Weights of the kept (best validation) epoch.
    pub(super) net: Net,
    pub(super) epochs: usize,
    pub(super) best_epoch: usize,
    pub(super) stop: String,
    /// Validation MSE (scaled units) of the kept weights; the training MSE
    /// when there is no validation set.
    pub(super) score: f64,
}

/// One trainlm run from `net` (see the module docs); `report` sees every
/// epoch's network. With `to_beat` (the kept restart's validation MSE) the
/// run stops at its first validation failure while its best validation MSE
/// is above it (see [`NnOptions::abandon`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn run_lm(
    train: &Samples,
    val: &Samples,
    lm: &mut Lm,
    mut net: Net,
    opts: &NnOptions,
    restart: usize,
    to_beat: Option<f64>,
    report: &mut dyn FnMut(&Epoch, &Net),
) -> Run {
    let (np, nh, nout) = (net.p.len(), net.nh, net.nout);
    let mut trial = net.clone();
    let (mut t_act, mut t_out) = (vec![0.0; lm.act.len()], vec![0.0; lm.out.len()]);
    let (mut v_act, mut v_out) = (vec![0.0; val.n * nh], vec![0.0; val.n * nout]);
    let (n_train, n_val) = (train.n_entries(), val.n_entries());
    let has_val = n_val > 0;
    let mut val_sse = |net: &Net| {
        val.forward(net, &mut v_act, &mut v_out);
        val.sse_of(&v_out, nout)
    };
    train.forward(&net, &mut lm.act, &mut lm.out);
    let mut sse = train.sse_of(&lm.out, nout);
    let mut mu = opts.mu;
    let mut best_val = if has_val {
        val_sse(&net)
    } else {
        f64::INFINITY
    };
    let mut best = net.p.clone();
    let mut best_epoch = 0;
    let mut fails = 0;
    let mut stop = "max_epochs".to_string();
    let mut epochs = 0;
    for epoch in 1..=opts.max_epochs {
        epochs = epoch;
        lm.normal_equations(train, &net);
        if lm.g.norm() < opts.min_grad {
            stop = "min_grad".into();
            epochs = epoch - 1;
            break;
        }
        let mut improved = false;
        let sse_before = sse;
        while mu <= opts.mu_max {
            // The factor overwrites `lm.a` in place: no allocation per trial.
            let mut a = std::mem::replace(&mut lm.a, DMatrix::zeros(0, 0));
            a.copy_from(&lm.jtj);
            for k in 0..np {
                a[(k, k)] += mu;
            }
            let factored = Cholesky::new(a);
            let ok = factored.is_some();
            if let Some(ch) = &factored {
                lm.delta.copy_from(&lm.g);
                ch.solve_mut(&mut lm.delta);
                for k in 0..np {
                    trial.p[k] = net.p[k] - lm.delta[k];
                }
            }
            lm.a = factored.map_or_else(|| DMatrix::zeros(np, np), Cholesky::unpack_dirty);
            if ok {
                train.forward(&trial, &mut t_act, &mut t_out);
                let s_new = train.sse_of(&t_out, nout);
                if s_new.is_finite() && s_new < sse {
                    // Accept: the trial's activations are the next epoch's.
                    std::mem::swap(&mut net, &mut trial);
                    std::mem::swap(&mut lm.act, &mut t_act);
                    std::mem::swap(&mut lm.out, &mut t_out);
                    sse = s_new;
                    mu *= opts.mu_dec;
                    improved = true;
                    break;
                }
            }
            mu *= opts.mu_inc;
        }
        let v = if has_val { val_sse(&net) } else { f64::NAN };
        if has_val {
            if v < best_val {
                best_val = v;
                best.clone_from(&net.p);
                best_epoch = epoch;
                fails = 0;
            } else {
                fails += 1;
            }
        } else {
            best.clone_from(&net.p);
            best_epoch = epoch;
        }
        let info = Epoch {
            restart,
            epoch,
            train_mse: sse / n_train.max(1) as f64,
            val_mse: v / n_val.max(1) as f64,
            mu,
        };
        report(&info, &net);
        if !improved {
            stop = "mu_max".into();
            break;
        }
        if has_val && fails >= opts.max_fail {
            stop = "validation".into();
            break;
        }
        // Abandon a losing restart once it has settled: a validation
        // failure, its best above the kept one's, and training error no
        // longer falling fast (under 1 % this epoch — during LM's steep
        // descent validation error can rise for an epoch and then fall far).
        if has_val
            && fails > 0
            && sse > 0.99 * sse_before
            && to_beat.is_some_and(|k| best_val / n_val as f64 > k)
        {
            stop = "abandoned".into();
            break;
        }
    }
    let score = if has_val {
        best_val / n_val as f64
    } else {
        sse / n_train.max(1) as f64
    };
    net.p = best;
    Run {
        net,
        epochs,
        best_epoch,
        stop,
        score,
    }
}
