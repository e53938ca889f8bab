//! Levenberg–Marquardt training of the network, as MATLAB's `trainlm`: the
//! Nguyen–Widrow initialisation, the scaled samples, the Jacobian by
//! backpropagation and JᵀJ from its block structure, and one early-stopped
//! run (`run_lm`). The options, the split and the restarts are in the
//! parent module.

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use nalgebra::{DMatrix, DMatrixView, DVector};
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
/// needs). The `exp` is [`exp_fast`], branch-free so that a loop of these
/// vectorises (glibc's tanh and exp are calls, one value at a time; they
/// were a fifth of all training time). ±∞ and NaN come out as tanh's.
/// `predict` (what is exported and compared) keeps `f64::tanh`.
pub(super) fn tanh_fast(x: f64) -> f64 {
    1.0 - 2.0 / (exp_fast(2.0 * x) + 1.0)
}

/// e^x for |x| ≤ 700 (clamped beyond: tanh_fast only needs e^{2x} to be
/// huge or tiny there), within ~2 ulp: x = n·ln 2 + r with |r| ≤ ln 2 / 2,
/// e^r by its Taylor series to r¹³ (remainder < 1e-17 relative), 2ⁿ put
/// into the exponent bits. No branches, no calls, no integer conversions
/// SSE2 lacks: n is rounded by the 1.5·2⁵² trick, whose low mantissa bits
/// are n itself.
pub(super) fn exp_fast(x: f64) -> f64 {
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5 · 2⁵²
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let x = x.clamp(-700.0, 700.0);
    let k = x * std::f64::consts::LOG2_E + ROUND;
    let n = k - ROUND;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    // 1/j! for j = 13 … 2, Horner from the top.
    const C: [f64; 12] = [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
    ];
    let mut p = C[0];
    for c in &C[1..] {
        p = p * r + c;
    }
    let p = (p * r + 1.0) * r + 1.0;
    // The low bits of k's mantissa hold n (two's complement); n + 1023 is
    // in [13, 2033], so shifting it into the exponent field gives 2ⁿ.
    let two_n = f64::from_bits((k.to_bits() << 52).wrapping_add(1023 << 52));
    p * two_n
}

/// Scaled data of one set: inputs nin × n (input-major: one input of all
/// samples contiguous, so the training loops run along the samples and
/// vectorise) and, per output, the residual entries (sample, scaled target,
/// √weight) in sample order. Kept output by output so that the Jacobian's
/// output-layer columns of one output form one contiguous block (see
/// [`Lm::normal_equations`]).
pub(super) struct Samples {
    pub(super) n: usize,
    pub(super) x: Vec<f64>,
    pub(super) by_out: Vec<Vec<(usize, f64, f64)>>,
}

impl Samples {
    pub(super) fn n_entries(&self) -> usize {
        self.by_out.iter().map(Vec::len).sum()
    }

    /// Hidden activations (nh × n, neuron-major) and outputs (nout × n,
    /// output-major) of every sample. The training loop's hot path (one
    /// call per μ trial): each weight is applied along all samples at once
    /// (the same sums in the same order as one sample at a time, so the
    /// same bits), and [`tanh_fast`] over whole rows.
    pub(super) fn forward(&self, net: &Net, act: &mut [f64], out: &mut [f64]) {
        let (nin, nh, nout, n) = (net.nin, net.nh, net.nout, self.n);
        if n == 0 {
            return;
        }
        let (w1, rest) = net.p.split_at(nh * nin);
        let (b1, rest) = rest.split_at(nh);
        let (w2, b2) = rest.split_at(nout * nh);
        for ((a, wj), &bj) in act.chunks_exact_mut(n).zip(w1.chunks_exact(nin)).zip(b1) {
            a.fill(bj);
            for (xi, &w) in self.x.chunks_exact(n).zip(wj) {
                for (av, xv) in a.iter_mut().zip(xi) {
                    *av += w * xv;
                }
            }
            for av in a.iter_mut() {
                *av = tanh_fast(*av);
            }
        }
        for ((y, w2o), &bo) in out.chunks_exact_mut(n).zip(w2.chunks_exact(nh)).zip(b2) {
            y.fill(bo);
            for (a, &w) in act.chunks_exact(n).zip(w2o) {
                for (yv, av) in y.iter_mut().zip(a) {
                    *yv += w * av;
                }
            }
        }
    }

    /// Sum of squared weighted residuals from the outputs of `forward`.
    pub(super) fn sse_of(&self, out: &[f64]) -> f64 {
        let mut sse = 0.0;
        for (o, es) in self.by_out.iter().enumerate() {
            let y = &out[o * self.n..(o + 1) * self.n];
            for &(s, t, sw) in es {
                let e = sw * (y[s] - t);
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
        let (n, nin) = (self.n, net.nin);
        let m = self.n_entries();
        let mut j = DMatrix::zeros(m, np);
        let mut e = DVector::zeros(m);
        let mut act = vec![0.0; n * net.nh];
        let mut out = vec![0.0; n * net.nout];
        self.forward(net, &mut act, &mut out);
        let (w2o, b2o, b1o) = (net.w2_off(), net.b2_off(), net.nh * nin);
        let mut row = 0;
        for (o, es) in self.by_out.iter().enumerate() {
            for &(s, t, sw) in es {
                e[row] = sw * (out[o * n + s] - t);
                for h in 0..net.nh {
                    let a = act[h * n + s];
                    let d = sw * net.w2(o, h) * (1.0 - a * a);
                    for i in 0..nin {
                        j[(row, h * nin + i)] = d * self.x[i * n + s];
                    }
                    j[(row, b1o + h)] = d;
                    j[(row, w2o + o * net.nh + h)] = sw * a;
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
/// block triangle, mirrored. The residuals e_s,o = √w_s (y − t) ride along
/// as nout more entries of m_s, so the same GEMM gives Jᵀe:
/// g[k] = Σₒ w2[o,h(k)] · Σ_s √w_s z_s[k] e_s,o and g[output o, r] =
/// Σ_s √w_s ã_s[r] e_s,o. For 3-16-3 on 1581 samples that is at most
/// 84² × 1581 = 11 M multiply-adds (2/3 of it with the 3 × 3 blocks) where the
/// product over the 4 743 rows of J takes 63 M (26 M when only its
/// hidden/own-output blocks are multiplied). The weight of a sample is the
/// same for all its outputs (u_um is per row), which is what lets the
/// outputs share one Gram matrix.
pub(super) struct Lm {
    /// Hidden neuron of each hidden parameter (weights h·nin + i, then
    /// biases): nz = nh·(nin + 1) entries, the z part of m_s.
    pub(super) hid: Vec<usize>,
    /// Samples grouped by measurement pattern: (bitmask of outputs, first
    /// row, end row) of `m`.
    pub(super) groups: Vec<(u32, usize, usize)>,
    /// Sample index of each row of `m`.
    pub(super) order: Vec<usize>,
    /// Per row of `m`: √w, inputs (nin × rows), targets (nout × rows, NaN:
    /// not measured) of its sample.
    sw: Vec<f64>,
    x: Vec<f64>,
    target: Vec<f64>,
    /// m_s of each sample as rows: rows × (nm + nout), column-major, so
    /// each entry of all samples is contiguous; nm = nz + nh + 1 columns z
    /// then ã, then the nout residuals.
    pub(super) m: DMatrix<f64>,
    /// One Gram matrix mᵀm per group.
    pub(super) gram: Vec<DMatrix<f64>>,
    pub(super) jtj: DMatrix<f64>,
    pub(super) g: DVector<f64>,
    /// Activations (nh × n) and outputs (nout × n) of the current network
    /// on the training set, as [`Samples::forward`] leaves them.
    pub(super) act: Vec<f64>,
    pub(super) out: Vec<f64>,
    /// One activation row in the order of `m`'s rows.
    ap: Vec<f64>,
    /// JᵀJ + μI (np × np, column-major), factored in place by every μ trial.
    pub(super) a: Vec<f64>,
    pub(super) delta: Vec<f64>,
}

impl Lm {
    pub(super) fn new(train: &Samples, nin: usize, nh: usize, nout: usize) -> Lm {
        let nz = nh * (nin + 1);
        let nm = nz + nh + 1;
        let n = train.n;
        let mut mask = vec![0u32; n];
        let mut sw_s = vec![0.0; n];
        let mut target_s = vec![f64::NAN; n * nout];
        for (o, es) in train.by_out.iter().enumerate() {
            for &(s, t, w) in es {
                mask[s] |= 1 << o;
                sw_s[s] = w;
                target_s[o * n + s] = t;
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
        let nc = order.len();
        let gather = |v: &[f64], rows: usize| -> Vec<f64> {
            (0..rows)
                .flat_map(|k| order.iter().map(move |&s| v[k * n + s]))
                .collect()
        };
        let np = Net::n_params(nin, nh, nout);
        Lm {
            hid: (0..nz)
                .map(|k| if k < nh * nin { k / nin } else { k - nh * nin })
                .collect(),
            gram: vec![DMatrix::zeros(nm + nout, nm + nout); groups.len()],
            m: DMatrix::zeros(nc, nm + nout),
            sw: gather(&sw_s, 1),
            x: gather(&train.x, nin),
            target: gather(&target_s, nout),
            groups,
            order,
            jtj: DMatrix::zeros(np, np),
            g: DVector::zeros(np),
            act: vec![0.0; n * nh],
            out: vec![0.0; n * nout],
            ap: vec![0.0; nc],
            a: vec![0.0; np * np],
            delta: vec![0.0; np],
        }
    }

    /// JᵀJ and g = Jᵀe at `net`, whose activations on `train` are in
    /// `self.act` / `self.out`.
    pub(super) fn normal_equations(&mut self, train: &Samples, net: &Net) {
        let (nin, nh, nout, n) = (net.nin, net.nh, net.nout, train.n);
        let nz = self.hid.len();
        let nm = nz + nh + 1;
        let nc = self.order.len();
        let (w2o, b2o) = (net.w2_off(), net.b2_off());
        let w2 = &net.p[w2o..b2o];
        let hid = &self.hid;
        let pidx = |o: usize, r: usize| if r < nh { w2o + o * nh + r } else { b2o + o };
        {
            // The rows of m, one entry of all samples at a time (loops along
            // the samples, which vectorise).
            let (mz, rest) = self.m.as_mut_slice().split_at_mut(nz * nc);
            let (ma, me) = rest.split_at_mut((nh + 1) * nc);
            let (mzw, mzb) = mz.split_at_mut(nh * nin * nc);
            let sw = &self.sw;
            for h in 0..nh {
                let act = &self.act[h * n..(h + 1) * n];
                for (ac, &s) in self.ap.iter_mut().zip(&self.order) {
                    *ac = act[s];
                }
                let zb = &mut mzb[h * nc..(h + 1) * nc];
                let at = &mut ma[h * nc..(h + 1) * nc];
                for c in 0..nc {
                    let a = self.ap[c];
                    zb[c] = sw[c] * (1.0 - a * a);
                    at[c] = sw[c] * a;
                }
                for i in 0..nin {
                    let z = &mut mzw[(h * nin + i) * nc..(h * nin + i + 1) * nc];
                    let x = &self.x[i * nc..(i + 1) * nc];
                    for c in 0..nc {
                        z[c] = zb[c] * x[c];
                    }
                }
            }
            ma[nh * nc..].copy_from_slice(sw);
            for o in 0..nout {
                let e = &mut me[o * nc..(o + 1) * nc];
                let t = &self.target[o * nc..(o + 1) * nc];
                let y = &self.out[o * n..(o + 1) * n];
                for c in 0..nc {
                    // Not measured: 0 (and its group leaves output o out).
                    e[c] = if t[c].is_nan() {
                        0.0
                    } else {
                        sw[c] * (y[self.order[c]] - t[c])
                    };
                }
            }
        }
        let nm2 = nm + nout;
        for (gi, &(_, c0, c1)) in self.groups.iter().enumerate() {
            // mᵀ read as a strided view of m, no copy.
            let len = c1 - c0;
            let mt =
                DMatrixView::from_slice_with_strides(&self.m.as_slice()[c0..], nm2, len, nc, 1);
            let rows = self.m.rows(c0, len);
            // Symmetric: only the blocks on and above the diagonal of a
            // 3 × 3 block partition are multiplied (6 of the 9 blocks: 2/3 of
            // the products), the rest mirrored.
            let gram = &mut self.gram[gi];
            let cuts = [0, nm2 / 3, 2 * nm2 / 3, nm2];
            if nm2 / 3 > 5 && len > 5 {
                for b in 0..3 {
                    let (r0, r1) = (cuts[b], cuts[b + 1]);
                    gram.view_mut((r0, r0), (r1 - r0, nm2 - r0)).gemm(
                        1.0,
                        &mt.rows(r0, r1 - r0),
                        &rows.columns(r0, nm2 - r0),
                        0.0,
                    );
                }
            } else {
                // nalgebra's gemm multiplies a product with a side of 5 or
                // less itself, and reads a strided mᵀ past its rows there:
                // a tiny network's few entries are summed here instead.
                for k2 in 0..nm2 {
                    for k in 0..=k2 {
                        gram[(k, k2)] = rows.column(k).dot(&rows.column(k2));
                    }
                }
            }
            gram.fill_lower_triangle_with_upper_triangle();
        }
        self.jtj.fill(0.0);
        self.g.fill(0.0);
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
                let ce = nm + o;
                for k in 0..nz {
                    self.g[k] += w2o[hid[k]] * gram[(k, ce)];
                }
                for r in 0..=nh {
                    let pr = pidx(o, r);
                    self.g[pr] += gram[(nz + r, ce)];
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

/// Cholesky factor L (LLᵀ = A) of the symmetric n × n matrix `a`
/// (column-major; the lower triangle is read and overwritten by L, the
/// upper one is left as it was). False when A is not positive definite
/// (a pivot ≤ 0 or NaN). Right-looking: each column's update of the
/// columns after it runs down contiguous memory.
pub(super) fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let (left, right) = a.split_at_mut((j + 1) * n);
        let col = &mut left[j * n..];
        let d = col[j];
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let l = d.sqrt();
        col[j] = l;
        for v in &mut col[j + 1..] {
            *v /= l;
        }
        for (k, ck) in right.chunks_exact_mut(n).enumerate() {
            let k = j + 1 + k;
            let f = col[k];
            for (t, &v) in ck[k..].iter_mut().zip(&col[k..]) {
                *t -= f * v;
            }
        }
    }
    true
}

/// Solves LLᵀx = b in place (`b` becomes x) with the factor of
/// [`cholesky_in_place`].
pub(super) fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64]) {
    for j in 0..n {
        let col = &l[j * n..(j + 1) * n];
        b[j] /= col[j];
        let bj = b[j];
        for (bi, &v) in b[j + 1..].iter_mut().zip(&col[j + 1..]) {
            *bi -= v * bj;
        }
    }
    for j in (0..n).rev() {
        let col = &l[j * n..(j + 1) * n];
        let s = col[j + 1..]
            .iter()
            .zip(&b[j + 1..])
            .fold(b[j], |s, (v, x)| s - v * x);
        b[j] = s / col[j];
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
        val.sse_of(&v_out)
    };
    train.forward(&net, &mut lm.act, &mut lm.out);
    let mut sse = train.sse_of(&lm.out);
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
            lm.a.copy_from_slice(lm.jtj.as_slice());
            for k in 0..np {
                lm.a[k * np + k] += mu;
            }
            let ok = cholesky_in_place(&mut lm.a, np);
            if ok {
                lm.delta.copy_from_slice(lm.g.as_slice());
                cholesky_solve(&lm.a, np, &mut lm.delta);
                for k in 0..np {
                    trial.p[k] = net.p[k] - lm.delta[k];
                }
            }
            if ok {
                train.forward(&trial, &mut t_act, &mut t_out);
                let s_new = train.sse_of(&t_out);
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
