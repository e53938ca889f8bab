//! Loading: a validated [`Table`] becomes a prepared [`ModelCap`]. The
//! header sets the envelope and the input scaling, the plain polynomials are
//! summed into one dense coefficient block, and every other term is laid out
//! by its own function (factored thermal/Abbe, periodic, reversal, grid,
//! MLP) into the parameter pools, each coefficient set with the binary scale
//! q chosen so that Σ|c|·2^q < 2^31. The capacities are checked at the end
//! so an error reports the total needed; on any error the model is left
//! empty, never half-loaded.

use core::num::NonZeroU32;

use heapless::Vec;

use super::kernels::{
    choose_q, mono_index, pow2, round_i64, to_q, Mul32, Turns, HORNER20, MONO20_FROM, MONOS_UP_TO,
    MONO_EXPS,
};
use super::{
    poly_fixed_shift_ok, vp_products, Factor, FactoredF32, GridAxis, LoadError, MlpInput, ModelCap,
    PeriodicF32, PolyKind, Term, TermQ, BLK_CAP, FQ_CAP, MAX_MLP_INPUTS_TOTAL, MAX_TERMS, VP_CAP,
    VP_STEPS,
};
use crate::limits::{MAX_HIDDEN_LAYERS, MAX_MLP_INPUTS, MAX_MONOMIALS};
use crate::math::TANH_F32_LEAD;
use crate::table::{Envelope, GridView, MlpView, PolyCoefs, Table, TermView};

struct Pools<'m, const P: usize> {
    pf: &'m mut Vec<f32, P>,
    pq: &'m mut Vec<i32, P>,
    pidx: &'m mut Vec<u8, P>,
    needed: usize,
}

impl<const P: usize> Pools<'_, P> {
    fn push(&mut self, f: f32, q: i32, idx: u8) {
        self.needed += 1;
        // Capacity is checked once at the end (so the error reports the total).
        let _ = self.pf.push(f);
        let _ = self.pq.push(q);
        let _ = self.pidx.push(idx);
    }
}

impl<const P: usize, const G: usize> ModelCap<P, G> {
    /// Prepare a model from a validated table.
    ///
    /// This returns the model by value (tens of KiB); on the MCU prefer
    /// [`ModelCap::load_into`] on a `static`, which needs no stack copy.
    pub fn load(table: &Table<'_>) -> Result<Self, LoadError> {
        let mut m = Self::empty();
        m.load_into(table)?;
        Ok(m)
    }

    /// Prepare the model in place (no large stack temporaries). On error the
    /// model is left empty (every evaluation returns zeros), never half-loaded.
    pub fn load_into(&mut self, table: &Table<'_>) -> Result<(), LoadError> {
        let r = self.load_inner(table);
        if r.is_err() {
            self.clear();
        } else {
            self.prepare_horner(table); // (not under load_inner's 2 KiB frame)
        }
        r
    }

    fn clear(&mut self) {
        self.outputs = 0;
        self.n_monos = 0;
        self.blk_n = 0;
        self.vp_n = 0;
        self.fq_n = 0;
        self.has_block = false;
        self.reads_temp = false;
        self.reads_tool = false;
        self.has_factored = false;
        self.max_corr_f32 = [0.0; 3];
        self.round_lim = [0; 3];
        self.round_win = [0; 3];
        self.poly = PolyKind::None;
        self.poly_fixed = PolyKind::None;
        self.terms.clear();
        self.pf.clear();
        self.pq.clear();
        self.pidx.clear();
        self.mlp_in.clear();
        self.grid.clear();
        self.flat = false;
        self.rev_f32 = [[0.0; 3]; 3];
        self.has_rev = false;
        self.per_f32.clear();
        self.fac_f32.clear();
        self.hr.clear();
    }

    /// Lay the terms out per kind for [`ModelCap::flat_f32`] (sets `flat`
    /// only when every term fits it; otherwise the f32 path keeps the
    /// general term loop).
    fn prepare_flat(&mut self) {
        let mut flat = true;
        for t in self.terms.iter() {
            match *t {
                Term::Reversal {
                    output,
                    axis,
                    amp_f32,
                    ..
                } => {
                    self.rev_f32[axis as usize % 3][output as usize % 3] += amp_f32;
                    self.has_rev = true;
                }
                Term::Periodic {
                    output,
                    axis,
                    harmonics,
                    period_nm,
                    turns,
                    start,
                    ..
                } => {
                    let mut ab = [[0.0f32; 2]; 4];
                    for (k, abk) in ab.iter_mut().enumerate().take(harmonics as usize) {
                        let i = start as usize + 2 * k;
                        *abk = [
                            self.pf.get(i).copied().unwrap_or(0.0),
                            self.pf.get(i + 1).copied().unwrap_or(0.0),
                        ];
                    }
                    // The held position minus a multiple of the period at or
                    // below the travel must fit u32 (so the remainder is one UDIV).
                    let a = axis as usize % 3;
                    let p = period_nm.max(1) as i64;
                    let base = (self.env.travel_min_nm[a] as i64).div_euclid(p) * p;
                    if self.env.travel_max_nm[a] as i64 - base > u32::MAX as i64 {
                        flat = false;
                    }
                    let _ = self.per_f32.push(PeriodicF32 {
                        output,
                        axis: a as u8,
                        harmonics: harmonics.min(4),
                        period: NonZeroU32::new(p as u32).unwrap_or(NonZeroU32::MIN),
                        base_nm: base as i32,
                        turns,
                        ab,
                    });
                }
                Term::Factored {
                    output,
                    factor,
                    start,
                    len,
                    ..
                } => {
                    let (src, offset) = match factor {
                        Factor::Temp { ch, t_ref_mc } => (ch & 3, t_ref_mc),
                        Factor::Tool => (4, 0),
                    };
                    let mut c = [0.0f32; 4];
                    for i in start as usize..start as usize + len as usize {
                        // Graded order: 0 = 1, 1 = x, 2 = y, 3 = z.
                        match self.pidx.get(i) {
                            Some(&k) if k < 4 => {
                                c[k as usize] += self.pf.get(i).copied().unwrap_or(0.0)
                            }
                            _ => flat = false,
                        }
                    }
                    let _ = self.fac_f32.push(FactoredF32 {
                        output,
                        src,
                        offset,
                        c,
                    });
                }
                _ => flat = false,
            }
        }
        self.flat = flat;
    }

    fn load_inner(&mut self, table: &Table<'_>) -> Result<(), LoadError> {
        self.clear();
        self.load_header(table)?;
        self.load_block(table)?;
        let (params_needed, grid_needed) = self.load_terms(table)?;
        if params_needed > P || params_needed > u16::MAX as usize {
            return Err(LoadError::ParamCapacity {
                needed: params_needed as u32,
                capacity: P as u32,
            });
        }
        if grid_needed > G {
            return Err(LoadError::GridCapacity {
                needed: grid_needed as u32,
                capacity: G as u32,
            });
        }
        self.prepare_flat();
        self.prepare_vp();
        self.poly = match (self.terms.is_empty() && self.has_block, self.n_monos) {
            (true, 1..=4) => PolyKind::Linear,
            (true, 5..=20) => PolyKind::Cubic,
            _ => PolyKind::None,
        };
        // rshr(rshr(a, s), 16) = (a + 2^(s−1) + 2^(s+15)) >> (s + 16)
        // exactly (floor((floor(x/A) + B)/C) = floor((x + A·B)/(A·C))), so
        // one bias and one shift replace the two roundings. The fast path
        // takes s + 16 ∈ [32, 62]: the result is the high word shifted, and
        // the bias plus c₀·2^30 plus Σ|c·m| < 2^61 cannot overflow. (s < 16
        // needs Σ|c| ≥ 2^29 nm, s > 46 a block of almost nothing.)
        // An output without coefficients (an absent one) is 0 whatever its
        // scale (its Σ|c| = 0 gives the largest q): bias and shift 0.
        let zero: [bool; 3] = core::array::from_fn(|o| self.block_q[o].iter().all(|&c| c == 0));
        let shifts_ok = (0..3).all(|o| zero[o] || poly_fixed_shift_ok(self.block_shift[o]));
        self.poly_fixed = if shifts_ok { self.poly } else { PolyKind::None };
        for o in 0..3 {
            let s = self.block_shift[o];
            (self.poly_shift[o], self.poly_bias_q[o]) = if shifts_ok && !zero[o] {
                (
                    s - 16,
                    (1i64 << (s - 1)) + (1i64 << (s + 15)) + ((self.block_q[o][0] as i64) << 30),
                )
            } else {
                (0, 0)
            };
        }
        Ok(())
    }

    /// The fixed part: envelope, outputs, temperature channels, the term
    /// count against [`MAX_TERMS`], and the input scaling that maps each
    /// position to u ∈ [−1, 1] (f32 reciprocal and Q30 constant multiplier).
    fn load_header(&mut self, table: &Table<'_>) -> Result<(), LoadError> {
        let env = table.envelope();
        let sc = table.scaling();
        self.env = env;
        self.outputs = table.outputs_mask();
        self.n_channels = table.channel_count() as u8;
        self.centre_nm = sc.centre_nm;
        self.max_corr_f32 = env.max_corr_nm.map(|v| v as f32);
        for a in 0..3 {
            // lo ≤ hi is validated, so the span fits u32.
            self.hold_nm[a] = (
                env.travel_min_nm[a],
                env.travel_max_nm[a].wrapping_sub(env.travel_min_nm[a]) as u32,
            );
            // 0 ≤ max ≤ MAX_CORR_LIMIT_NM is validated.
            let max = env.max_corr_nm[a].max(0);
            self.round_lim[a] = (max - 1).max(0);
            self.round_win[a] = (2 * max - 1).max(0) as u32;
        }
        if table.term_count() > MAX_TERMS {
            return Err(LoadError::TooManyTerms {
                count: table.term_count() as u32,
            });
        }
        self.half_nm = sc.half_span_nm;
        for a in 0..3 {
            let h = sc.half_span_nm[a] as f64;
            self.inv_half_f32[a] = (1.0 / h) as f32;
            self.u_scale[a] = Mul32::new(1.0 / h, 30);
        }
        Ok(())
    }

    /// Pass 1: the shared polynomial block (all plain polynomial terms) and
    /// the highest degree any polynomial needs (thermal and Abbe terms read
    /// the same monomial vector), with one binary scale per output.
    fn load_block(&mut self, table: &Table<'_>) -> Result<(), LoadError> {
        let mut block = [[0.0f64; 3]; MAX_MONOMIALS];
        let mut max_deg = 0usize;
        let mut any_poly = false;
        for t in table.terms() {
            let coefs = match t.view() {
                TermView::Poly { output, coefs } => {
                    self.has_block = true;
                    for (mono, c) in coefs.iter() {
                        if let Some(i) = mono_index(mono) {
                            block[i][output] += c;
                        }
                    }
                    coefs
                }
                TermView::Thermal { coefs, .. } | TermView::Abbe { coefs, .. } => coefs,
                _ => continue,
            };
            any_poly = true;
            for (mono, _) in coefs.iter() {
                max_deg = max_deg.max(mono.iter().map(|&e| e as usize).sum());
            }
        }
        if any_poly {
            self.n_monos = MONOS_UP_TO[max_deg.min(5)] as u8;
        }
        let half = self.half_nm;
        for o in 0..3 {
            let sum: f64 = block.iter().map(|r| r[o].abs()).sum();
            let q = choose_q(sum, 0).ok_or(LoadError::CoefficientRange { term: 0 })?;
            self.block_shift[o] = (q + 14) as u32;
            self.block_round[o] = 1i64 << (q + 13);
            for i in 0..MAX_MONOMIALS {
                self.block_f32[i][o] = block[i][o] as f32;
                self.block_q[o][i] = to_q(block[i][o], q);
            }
            self.poly_q[o].copy_from_slice(&self.block_q[o][..20]);
            // (half spans ≥ 1 nm, validated.)
            // In the units of w = p − centre (nm): c / (h_x^a·h_y^b·h_z^c),
            // so the kernels read w without normalising it (u = w / h).
            for (h, &i) in self.horner_f32[o].iter_mut().zip(HORNER20.iter()) {
                let e = MONO_EXPS[i as usize];
                let scale: f64 = (0..3)
                    .flat_map(|a| (0..e[a]).map(move |_| half[a] as f64))
                    .product();
                *h = (block[i as usize][o] / scale) as f32;
            }
        }
        self.prepare_blk();
        Ok(())
    }

    /// The block by monomial (`blk_*`) from the rows of `block_q`: the
    /// monomials some output reads, when there are at most [`BLK_CAP`] and
    /// at most half of the vector's (a dense block is faster by rows).
    pub(super) fn prepare_blk(&mut self) {
        self.blk_n = 0;
        let n = (self.n_monos as usize).min(MAX_MONOMIALS);
        let used = (0..n).filter(|&i| (0..3).any(|o| self.block_q[o][i] != 0));
        let count = used.clone().count();
        if self.has_block && count <= BLK_CAP && 2 * count <= n {
            for (k, i) in used.enumerate() {
                let q = &self.block_q;
                self.blk_q[k] = [q[0][i], q[1][i], q[2][i], i as i32];
                self.blk_n = k as u8 + 1;
            }
        }
    }

    /// The few-monomial fixed path (`vp_*`): when the monomial vector is the
    /// 20 of degree ≤ 3, every thermal/Abbe term reads only 1, x, y, z,
    /// and the monomials the block reads need at most [`VP_STEPS`] products
    /// (with their parents), v holds exactly those. The block's sums over v
    /// are the dense block's (the monomials left out have no coefficient),
    /// so the integers are the same.
    pub(super) fn prepare_vp(&mut self) {
        self.vp_n = 0;
        self.vp_step = [(0, 0); VP_CAP];
        self.vp_q = [[0; 3]; VP_CAP];
        if !self.has_block || !(1..=20).contains(&self.n_monos) {
            return;
        }
        for t in self.terms.iter() {
            if let Term::Factored { start, len, .. } = *t {
                let (s, e) = (start as usize, start as usize + len as usize);
                if self
                    .pidx
                    .get(s..e)
                    .is_none_or(|ix| ix.iter().any(|&i| i >= 4))
                {
                    return;
                }
            }
        }
        let mut need: [bool; 20] =
            core::array::from_fn(|i| (0..3).any(|o| self.block_q[o][i] != 0));
        if vp_products(&mut need) > VP_STEPS {
            return;
        }
        // Position of each graded monomial in v.
        let mut at = [0u8; 20];
        let mut k = 0;
        for i in 0..20 {
            if !need[i] {
                continue;
            }
            at[i] = k as u8;
            if i >= 4 {
                let (p, ax) = MONO20_FROM[i];
                self.vp_step[k] = (at[p as usize], 1 + ax);
            }
            self.vp_q[k] = core::array::from_fn(|o| self.block_q[o][i]);
            k += 1;
        }
        self.vp_n = k as u8;
        self.prepare_fq();
    }

    /// The flat terms (`fq`) of a few-monomial table: every term a
    /// reversal or a thermal/Abbe term (whose monomials are among 1, x, y,
    /// z, checked above), at most [`FQ_CAP`] of them.
    fn prepare_fq(&mut self) {
        self.fq_n = 0;
        if self.terms.len() > FQ_CAP {
            return;
        }
        for (j, t) in self.terms.iter().enumerate() {
            self.fq[j] = match *t {
                Term::Reversal {
                    output,
                    axis,
                    amp_q,
                    shift,
                    ..
                } => TermQ {
                    output,
                    kind: 0,
                    src: axis,
                    shift,
                    k: amp_q,
                    c: [0; 4],
                },
                Term::Factored {
                    output,
                    factor,
                    start,
                    len,
                    shift,
                } => {
                    let (s, e) = (start as usize, start as usize + len as usize);
                    let (Some(pq), Some(ix)) = (self.pq.get(s..e), self.pidx.get(s..e)) else {
                        return;
                    };
                    // Σ|c| < 2^31 (the term's scale), so the sums fit i32.
                    let mut c = [0i32; 4];
                    for (&q, &i) in pq.iter().zip(ix) {
                        c[i as usize & 3] += q;
                    }
                    let (kind, src, k) = match factor {
                        Factor::Temp { ch, t_ref_mc } => (1, ch, t_ref_mc),
                        Factor::Tool => (2, 0, 0),
                    };
                    TermQ {
                        output,
                        kind,
                        src,
                        shift,
                        k,
                        c,
                    }
                }
                _ => return,
            };
        }
        self.fq_n = self.terms.len() as u8;
    }

    /// Pass 2: every term but the plain polynomials, in table order, each by
    /// the function of its kind. Returns the parameters and the grid values
    /// needed; the caller checks them against the capacity, so the error
    /// reports the total rather than where the pool ran out.
    fn load_terms(&mut self, table: &Table<'_>) -> Result<(usize, usize), LoadError> {
        let mut pools = Pools {
            pf: &mut self.pf,
            pq: &mut self.pq,
            pidx: &mut self.pidx,
            needed: 0,
        };
        let mut grid_needed = 0usize;
        for (ti, t) in table.terms().enumerate() {
            let range_err = LoadError::CoefficientRange { term: ti as u32 };
            let start = pools.needed.min(u16::MAX as usize) as u16;
            let term = match t.view() {
                TermView::Poly { .. } => continue,
                TermView::Thermal {
                    output,
                    channel,
                    t_ref_mc,
                    coefs,
                } => {
                    self.reads_temp = true;
                    self.has_factored = true;
                    let factor = Factor::Temp {
                        ch: channel as u8,
                        t_ref_mc,
                    };
                    factored_term(&mut pools, output, factor, coefs, start, range_err)?
                }
                TermView::Abbe { output, coefs } => {
                    self.reads_tool = true;
                    self.has_factored = true;
                    factored_term(&mut pools, output, Factor::Tool, coefs, start, range_err)?
                }
                view @ TermView::Periodic { .. } => {
                    periodic_term(&mut pools, view, start, range_err)?
                }
                TermView::Reversal {
                    output,
                    axis,
                    transition_nm,
                    amplitude_nm,
                } => {
                    let q = choose_q(amplitude_nm.abs(), 0).ok_or(range_err)?;
                    Term::Reversal {
                        output: output as u8,
                        axis: axis as u8,
                        transition_nm,
                        amp_f32: (amplitude_nm * pow2(-30)) as f32,
                        amp_q: to_q(amplitude_nm, q),
                        shift: (q + 14) as u32,
                    }
                }
                TermView::Grid { output, grid } => {
                    let gstart = grid_needed as u32;
                    grid_needed += grid.len();
                    grid_term(&mut self.grid, output, grid, gstart, ti as u32)?
                }
                TermView::Mlp { outputs, net } => mlp_term(
                    &mut pools,
                    &mut self.mlp_in,
                    &mut self.reads_temp,
                    &self.env,
                    outputs,
                    net,
                    start,
                    ti as u32,
                )?,
            };
            let _ = self.terms.push(term);
        }
        Ok((pools.needed, grid_needed))
    }
}

/// A thermal or Abbe term: its polynomial times a factor read at run time
/// (ΔT of a channel, or the tool arm). A thermal term's coefficients are per
/// °C in the table and go in per m°C, so the factor is the integer ΔT in m°C.
fn factored_term<const P: usize>(
    pools: &mut Pools<'_, P>,
    output: usize,
    factor: Factor,
    coefs: PolyCoefs<'_>,
    start: u16,
    range_err: LoadError,
) -> Result<Term, LoadError> {
    let per_mc = matches!(factor, Factor::Temp { .. });
    let coef = |c: f64| if per_mc { c / 1000.0 } else { c };
    let sum: f64 = coefs.iter().map(|(_, c)| coef(c).abs()).sum();
    let q = super::factored_q(sum).ok_or(range_err)?;
    for (mono, c) in coefs.iter() {
        let idx = mono_index(mono).unwrap_or(0) as u8;
        pools.push(coef(c) as f32, to_q(coef(c), q), idx);
    }
    Ok(Term::Factored {
        output: output as u8,
        factor,
        start,
        len: coefs.len() as u16,
        shift: (q - 16) as u32,
    })
}

/// A periodic term: its harmonics' (sin, cos) amplitudes with one binary
/// scale, and the phase increment per nm as a [`Turns`].
fn periodic_term<const P: usize>(
    pools: &mut Pools<'_, P>,
    view: TermView<'_>,
    start: u16,
    range_err: LoadError,
) -> Result<Term, LoadError> {
    let TermView::Periodic {
        output,
        axis,
        period_nm,
        harmonics,
        ..
    } = view
    else {
        return Err(range_err);
    };
    let mut sum = 0.0;
    for k in 1..=harmonics {
        let (a, b) = view.harmonic(k);
        sum += a.abs() + b.abs();
    }
    let q = choose_q(sum, 0).ok_or(range_err)?;
    for k in 1..=harmonics {
        let (a, b) = view.harmonic(k);
        pools.push(a as f32, to_q(a, q), 0);
        pools.push(b as f32, to_q(b, q), 0);
    }
    Ok(Term::Periodic {
        output: output as u8,
        axis: axis as u8,
        harmonics: harmonics as u8,
        period_nm,
        turns: Turns::new(period_nm),
        start,
        shift: (q + 14) as u32,
    })
}

/// A grid term: its axes (with the f32 and Q30 reciprocal of the step) and
/// its values in Q8 nm appended to the grid pool at `gstart`.
fn grid_term<const G: usize>(
    values: &mut Vec<i32, G>,
    output: usize,
    grid: GridView<'_>,
    gstart: u32,
    term: u32,
) -> Result<Term, LoadError> {
    let mut axes = [GridAxis {
        nodes: 1,
        origin_nm: 0,
        step_nm: 1,
        inv_step_f32: 1.0,
        t_scale: Mul32::default(),
    }; 3];
    for (a, ax) in axes.iter_mut().enumerate() {
        let g = grid.axis(a);
        *ax = GridAxis {
            nodes: g.nodes,
            origin_nm: g.origin_nm,
            step_nm: g.step_nm,
            inv_step_f32: (1.0 / g.step_nm as f64) as f32,
            t_scale: Mul32::new(1.0 / g.step_nm as f64, 30),
        };
    }
    for i in 0..grid.len() {
        let v = grid.value(i) * 256.0;
        if v.abs() > i32::MAX as f64 / 2.0 {
            return Err(LoadError::GridValueRange { term });
        }
        let _ = values.push(round_i64(v) as i32);
    }
    Ok(Term::Grid {
        output: output as u8,
        axes,
        start: gstart,
    })
}

/// An MLP term: its inputs' scaling ([`mlp_inputs`]), then the network's
/// weights — the output scaling folded into the output layer, the inputs'
/// integer-mid offsets into layer 1's biases — one binary scale per layer,
/// laid into the pools in the order the evaluators read them.
#[allow(clippy::too_many_arguments)]
fn mlp_term<const P: usize>(
    pools: &mut Pools<'_, P>,
    mlp_in: &mut Vec<MlpInput, MAX_MLP_INPUTS_TOTAL>,
    reads_temp: &mut bool,
    env: &Envelope,
    outputs: u8,
    net: MlpView<'_>,
    start: u16,
    term: u32,
) -> Result<Term, LoadError> {
    let range_err = LoadError::CoefficientRange { term };
    let shape = net.shape();
    let in_start = mlp_in.len();
    if in_start + shape.n_in > MAX_MLP_INPUTS_TOTAL {
        return Err(LoadError::MlpInputCapacity);
    }
    let (e, x_max) = mlp_inputs(mlp_in, reads_temp, env, net, term)?;
    let n_layers = shape.n_layers;
    let n_out = shape.n_out;
    // (start, inputs, units) of each layer in the table's parameter order.
    let mut lay = [(0usize, 0usize, 0usize); MAX_HIDDEN_LAYERS + 1];
    {
        let (mut k, mut prev) = (0usize, shape.n_in);
        for (layer, l) in lay.iter_mut().enumerate().take(n_layers + 1) {
            let width = if layer == n_layers {
                n_out
            } else {
                shape.hidden[layer]
            };
            *l = (k, prev, width);
            k += width * prev + width;
            prev = width;
        }
    }
    // Effective weights: output scaling folded into the output
    // layer, the inputs' integer-mid offsets into layer 1's biases.
    let eff = |layer: usize, j: usize, l: Option<usize>| -> f64 {
        let (k0, prev, width) = lay[layer];
        let (s, off) = if layer == n_layers {
            let (lo, hi) = net.output_range(j);
            ((hi - lo) / 2.0, (hi + lo) / 2.0)
        } else {
            (1.0, 0.0)
        };
        match l {
            Some(l) => net.param(k0 + j * prev + l) * s,
            None => {
                let mut b = net.param(k0 + width * prev + j);
                if layer == 0 {
                    for (l, el) in e.iter().enumerate().take(prev) {
                        b += net.param(k0 + j * prev + l) * el;
                    }
                }
                b * s + off
            }
        }
    };
    let mut qs = [0u8; 3];
    for layer in 0..=n_layers {
        let (_, prev, width) = lay[layer];
        let mut worst = 0.0f64;
        for j in 0..width {
            let mut s = eff(layer, j, None).abs();
            for l in 0..prev {
                s += eff(layer, j, Some(l)).abs();
            }
            worst = worst.max(s);
        }
        let q = super::mlp_layer_q(worst).ok_or(range_err)?;
        qs[layer.min(2)] = q as u8;
    }
    // Output layer q goes last so the evaluators find it at index 2.
    if n_layers == 1 {
        qs[2] = qs[1];
    }
    let push = |pools: &mut Pools<'_, P>, v: f64, q: u8| pools.push(v as f32, to_q(v, q as i32), 0);
    // Pool layout: [layer 1 rows, layer 1 biases] for a
    // two-layer net; then the last hidden layer fused with the
    // output layer, one record per unit
    // [bias, weights from the previous layer, output weights],
    // then the output biases.
    // f32 only: the first layer's weights × the inputs' scale k, so the
    // f32 evaluator takes x = v − mid without a multiply (fixed point keeps
    // k in its 32-bit shift).
    let mut k_in = [0.0f64; MAX_MLP_INPUTS];
    for (i, k) in k_in.iter_mut().enumerate().take(shape.n_in) {
        let inp = net.input(i);
        *k = input_scale(inp.min, inp.max);
    }
    let push_first = |pools: &mut Pools<'_, P>, v: f64, l: usize, q: u8| {
        pools.push((v * k_in[l]) as f32, to_q(v, q as i32), 0)
    };
    if n_layers == 2 {
        let (_, prev, width) = lay[0];
        for j in 0..width {
            for l in 0..prev {
                push_first(pools, eff(0, j, Some(l)), l, qs[0]);
            }
        }
        for j in 0..width {
            push(pools, eff(0, j, None), qs[0]);
        }
    }
    let last = n_layers - 1;
    let (_, prev, width) = lay[last];
    for j in 0..width {
        push(pools, eff(last, j, None), qs[last]);
        for l in 0..prev {
            if last == 0 {
                push_first(pools, eff(last, j, Some(l)), l, qs[last]);
            } else {
                push(pools, eff(last, j, Some(l)), qs[last]);
            }
        }
        for o in 0..n_out {
            // f32: × TANH_F32_LEAD, the evaluator's activation being
            // tanh / TANH_F32_LEAD (tanh_over_lead_f32).
            let v = eff(n_layers, o, Some(j));
            pools.push((v * TANH_F32_LEAD as f64) as f32, to_q(v, qs[2] as i32), 0);
        }
    }
    for o in 0..n_out {
        push(pools, eff(n_layers, o, None), qs[2]);
    }
    // |z| of every fused unit over the held inputs (the first layer's are
    // within ±x_max, a second layer's within ±1), with 0.5 to spare for
    // f32 rounding below tanh's saturation threshold 8.5.
    let bounded = (0..width).all(|j| {
        let mut z = eff(last, j, None).abs();
        for l in 0..prev {
            let m = if last == 0 { x_max[l] } else { 1.0 };
            z += eff(last, j, Some(l)).abs() * m;
        }
        z <= MLP_BOUNDED_Z
    });
    let mut widths = [0u8; MAX_HIDDEN_LAYERS];
    for (i, w) in widths.iter_mut().enumerate() {
        *w = shape.hidden[i] as u8;
    }
    Ok(Term::Mlp {
        outputs,
        n_in: shape.n_in as u8,
        n_layers: n_layers as u8,
        widths,
        n_out: shape.n_out as u8,
        in_start: in_start as u8,
        start,
        q: qs,
        bounded,
    })
}

/// The bound on a fused unit's |z| under which its f32 activation skips the
/// saturation test (`Term::Mlp::bounded`).
pub(crate) const MLP_BOUNDED_Z: f64 = 8.0;

/// An MLP input's scale: [min, max] → [−1, 1].
fn input_scale(min: f64, max: f64) -> f64 {
    2.0 / (max - min)
}

/// The inputs of an MLP term: x_s = (v − mid)·k + e with an integer mid, so
/// the evaluators take v − mid as an i32 and scale it with a 32-bit constant
/// shift. Returns the residuals e, which the caller folds into the first
/// layer's biases; refuses an input whose scaled range over the envelope
/// breaks those bounds.
fn mlp_inputs(
    mlp_in: &mut Vec<MlpInput, MAX_MLP_INPUTS_TOTAL>,
    reads_temp: &mut bool,
    env: &Envelope,
    net: MlpView<'_>,
    term: u32,
) -> Result<([f64; MAX_MLP_INPUTS], [f64; MAX_MLP_INPUTS]), LoadError> {
    let shape = net.shape();
    let mut e = [0.0f64; MAX_MLP_INPUTS];
    let mut x_max = [0.0f64; MAX_MLP_INPUTS];
    for i in 0..shape.n_in {
        let inp = net.input(i);
        let mid_true = (inp.min + inp.max) / 2.0;
        let mid = round_i64(mid_true).clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        let k = input_scale(inp.min, inp.max);
        e[i] = (mid as f64 - mid_true) * k;
        // Range of the scaled input over the envelope.
        let (lo, hi) = match inp.source {
            s @ 0..=2 => (env.travel_min_nm[s as usize], env.travel_max_nm[s as usize]),
            s => {
                let ch = (s - 3) as usize;
                (env.temp_min_mc[ch], env.temp_max_mc[ch])
            }
        };
        let xs_lo = (lo as f64 - mid as f64) * k;
        let xs_hi = (hi as f64 - mid as f64) * k;
        // The evaluators take v − mid as an i32 and scale it
        // with a 32-bit constant shift: both need these bounds.
        let d_max = (lo as f64 - mid as f64)
            .abs()
            .max((hi as f64 - mid as f64).abs());
        if xs_lo.abs() > 7.0 || xs_hi.abs() > 7.0 || d_max >= 2_147_483_647.0 || k > 2.0 {
            return Err(LoadError::MlpInputRange { term });
        }
        x_max[i] = xs_lo.abs().max(xs_hi.abs());
        *reads_temp |= inp.source >= 3;
        let _ = mlp_in.push(MlpInput {
            src: inp.source,
            mid,
            k_q28: Mul32::new(k, 28),
        });
    }
    Ok((e, x_max))
}
