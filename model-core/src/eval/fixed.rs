//! The integer-only fixed-point evaluation path: [`ModelCap::eval_fixed`],
//! bit-exact between the host and thumbv7em because it is the same integer
//! code. Positions nm (i32), normalised positions and monomials Q30, sin/cos
//! and tanh Q30, corrections accumulated in i64 Q16 nm and rounded to nm at
//! the end; every coefficient set carries the binary scale the loader chose
//! so the accumulations cannot overflow inside the envelope.

use super::kernels::{
    grid_cell, mlp_source, mono20_q30, mono56_q30, mul_q30, phase_turns, rshr, rshr_var,
};
use super::{
    Factor, Flags, GridAxis, Inputs, ModelCap, Outputs, PolyKind, Term, BLK_CAP, FQ_CAP, MAX_TEMPS,
    VP_CAP,
};
use crate::limits::{MAX_HIDDEN_UNITS, MAX_MLP_INPUTS};
use crate::math::{sincos_q30, tanh_q30, ONE_Q30, TANH_IN_FRAC};

impl<const P: usize, const G: usize> ModelCap<P, G> {
    #[inline(never)]
    fn grid_fixed(&self, axes: &[GridAxis; 3], start: usize, pos: &[i32; 3]) -> i64 {
        let mut idx = [0usize; 3];
        let mut nxt = [0usize; 3];
        let mut t = [0i64; 3];
        for a in 0..3 {
            let (i, frac) = grid_cell(&axes[a], pos[a]);
            idx[a] = i;
            nxt[a] = if (i + 1) < axes[a].nodes as usize {
                i + 1
            } else {
                i
            };
            t[a] = axes[a].t_scale.apply(frac) as i64;
        }
        let nx = axes[0].nodes as usize;
        let nxy = nx * axes[1].nodes as usize;
        // Values in Q8 nm with |v| ≤ 2^30 (checked at load), so (b − a)·t < 2^61.
        let g = |x: usize, y: usize, z: usize| {
            self.grid
                .get(start + x + nx * y + nxy * z)
                .copied()
                .unwrap_or(0) as i64
        };
        let lerp = |a: i64, b: i64, t: i64| a + rshr((b - a) * t, 30);
        let c00 = lerp(g(idx[0], idx[1], idx[2]), g(nxt[0], idx[1], idx[2]), t[0]);
        let c10 = lerp(g(idx[0], nxt[1], idx[2]), g(nxt[0], nxt[1], idx[2]), t[0]);
        let c01 = lerp(g(idx[0], idx[1], nxt[2]), g(nxt[0], idx[1], nxt[2]), t[0]);
        let c11 = lerp(g(idx[0], nxt[1], nxt[2]), g(nxt[0], nxt[1], nxt[2]), t[0]);
        let c0 = lerp(c00, c10, t[1]);
        let c1 = lerp(c01, c11, t[1]);
        lerp(c0, c1, t[2]) << 8 // Q8 → Q16
    }

    /// Evaluate in integer-only fixed point (bit-exact on every target).
    pub fn eval_fixed(&self, inp: &Inputs) -> Outputs {
        match self.poly_fixed {
            PolyKind::Linear => self.eval_poly_fixed::<1>(inp),
            PolyKind::Cubic => self.eval_poly_fixed::<3>(inp),
            PolyKind::None => self.eval_general_fixed(inp),
        }
    }

    /// A polynomial-only table of degree ≤ `D` (1 or 3): the same
    /// integers as the general path (the same Q30 monomials, exact i64
    /// sums, the same two roundings folded into one bias and one shift,
    /// see `load`), in straight-line code. A position outside the travel
    /// takes [`ModelCap::eval_poly_held_fixed`].
    #[inline(never)]
    fn eval_poly_fixed<const D: u8>(&self, inp: &Inputs) -> Outputs {
        let p = inp.pos_nm;
        if !self.inside_travel(p) {
            return self.eval_poly_held_fixed::<D>(p);
        }
        self.poly_fixed::<D>(p, Flags::empty())
    }

    #[inline(never)]
    fn eval_poly_held_fixed<const D: u8>(&self, p: [i32; 3]) -> Outputs {
        let mut flags = Flags::empty();
        let pos = self.hold_pos(p, &mut flags);
        self.poly_fixed::<D>(pos, flags)
    }

    /// Σ c·m per output over the Q30 monomials of `mono20_q30`.
    #[inline(always)]
    fn poly_fixed<const D: u8>(&self, pos: [i32; 3], mut flags: Flags) -> Outputs {
        let u = self.u_q30(&pos);
        let mut acc = self.poly_bias_q;
        // Monomial 0 (the constant) is in the bias.
        if D == 1 {
            for o in 0..3 {
                let c = &self.poly_q[o];
                acc[o] += c[1] as i64 * u[0] as i64
                    + c[2] as i64 * u[1] as i64
                    + c[3] as i64 * u[2] as i64;
            }
        } else {
            // Through memory on purpose: read back as i32, every product is
            // one SMLAL; kept as values, LLVM loses that the monomials are
            // sign-extended i32 and multiplies in full 64 bits (measured:
            // 796 instead of ~300 instructions for cubic19).
            let mv = core::hint::black_box(mono20_q30(u));
            // One output at a time over its own coefficient row (memory
            // order, no bounds checks).
            for o in 0..3 {
                let mut a = acc[o];
                for (&c, &m) in self.poly_q[o][1..].iter().zip(&mv[1..]) {
                    a += c as i64 * m as i64;
                }
                acc[o] = a;
            }
        }
        let mut corr = [0i32; 3];
        for o in 0..3 {
            // nm = the high word shifted (the shift is < 32).
            let v = ((acc[o] >> 32) as i32) >> (self.poly_shift[o] & 31);
            let max = self.env.max_corr_nm[o];
            corr[o] = if (v.wrapping_add(max) as u32) <= (2 * max) as u32 {
                v
            } else {
                flags.insert(Flags::CLAMPED);
                if v > max {
                    max
                } else {
                    -max
                }
            };
        }
        Outputs {
            corr_nm: corr,
            flags,
        }
    }

    /// The normalised positions, Q30.
    #[inline(always)]
    fn u_q30(&self, pos: &[i32; 3]) -> [i32; 3] {
        [
            self.u_scale[0].apply(pos[0].wrapping_sub(self.centre_nm[0])),
            self.u_scale[1].apply(pos[1].wrapping_sub(self.centre_nm[1])),
            self.u_scale[2].apply(pos[2].wrapping_sub(self.centre_nm[2])),
        ]
    }

    /// Every other table: the monomial vector, the block and the terms.
    #[inline(never)]
    fn eval_general_fixed(&self, inp: &Inputs) -> Outputs {
        let mut flags = Flags::empty();
        let pos = self.hold_pos_fast(inp.pos_nm, &mut flags);
        // |p − c| ≤ half-span, so |u| ≤ 2^30 (+1 from rounding) fits i32.
        // Computed only when the table has polynomials.
        let u = || {
            [
                self.u_scale[0].apply(pos[0].wrapping_sub(self.centre_nm[0])),
                self.u_scale[1].apply(pos[1].wrapping_sub(self.centre_nm[1])),
                self.u_scale[2].apply(pos[2].wrapping_sub(self.centre_nm[2])),
            ]
        };
        let out = if self.hr.on() {
            // Separable, degree ≥ 4: rows instead of the monomial vector.
            self.horner_fixed(&pos, inp, &mut flags)
        } else if self.vp_n > 0 {
            // Few monomials: only those the block reads (and their parents).
            let v = self.mono_vp_q30(u());
            let mut out = self.block_vp(&v);
            if self.fq_n > 0 {
                self.terms_flat_fixed(&v, inp, &mut flags, &mut out);
            } else if !self.terms.is_empty() {
                self.terms_fixed(&v, &pos, inp, &mut flags, &mut out);
            }
            out
        } else if self.terms.is_empty() {
            match self.n_monos {
                0 => [0; 3],
                1..=20 => self.block_any(&mono20_q30(u())),
                _ => self.block_any(&mono56_q30(u())),
            }
        } else {
            // The monomials are handed to the thermal/Abbe terms.
            match self.n_monos {
                0 => {
                    let mut out = [0; 3];
                    self.terms_fixed(&[], &pos, inp, &mut flags, &mut out);
                    out
                }
                1..=20 => {
                    let mv = mono20_q30(u());
                    let mut out = self.block_any(&mv);
                    self.terms_fixed(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
                _ => {
                    let mv = mono56_q30(u());
                    let mut out = self.block_any(&mv);
                    self.terms_fixed(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
            }
        };
        let mut corr = [0i32; 3];
        for o in 0..3 {
            let max = self.env.max_corr_nm[o];
            let v = rshr(out[o], 16);
            // Inside [−max, max] (0 ≤ max < 2^22, validated): v fits i32 and
            // (v + max) as u32 ≤ 2·max — one window test, else the clamp.
            let lo = v as i32;
            if v == lo as i64 && lo.wrapping_add(max) as u32 <= (2 * max) as u32 {
                corr[o] = lo;
                continue;
            }
            let max = max as i64;
            corr[o] = if v > max {
                flags.insert(Flags::CLAMPED);
                max
            } else if v < -max {
                flags.insert(Flags::CLAMPED);
                -max
            } else {
                v
            } as i32;
        }
        Outputs {
            corr_nm: corr,
            flags,
        }
    }

    /// The vector v of the few-monomial path (`vp_*`, set at load): 1, x,
    /// y, z, then each product `mul_q30(v[parent], u[axis])` in the order
    /// of `vp_step` — the same integers as `mono20_q30`'s entries.
    #[inline(always)]
    fn mono_vp_q30(&self, u: [i32; 3]) -> [i32; VP_CAP] {
        // Straight-line over all VP_CAP entries: an entry beyond `vp_n`
        // has no coefficient, whatever it holds.
        let mut v = [ONE_Q30, u[0], u[1], u[2], 0, 0, 0, 0];
        for k in 4..VP_CAP {
            // (the parent's position, the axis's: 1 + axis), both in v.
            let (p, a) = self.vp_step[k];
            v[k] = mul_q30(v[p as usize & (VP_CAP - 1)], v[a as usize & (VP_CAP - 1)]);
        }
        v
    }

    /// The block over v (rows `vp_q`), Q16 nm: as [`Self::block_fixed`]
    /// (the same exact sums, without the monomials no output reads).
    #[inline(always)]
    fn block_vp(&self, v: &[i32; VP_CAP]) -> [i64; 3] {
        // By monomial: each entry of v loaded once (read back as i32, so
        // every product is one SMLAL) for the three sums.
        let v = core::hint::black_box(v);
        let mut a = self.block_round;
        for (&m, c) in v.iter().zip(&self.vp_q) {
            let m = m as i64;
            a[0] += c[0] as i64 * m;
            a[1] += c[1] as i64 * m;
            a[2] += c[2] as i64 * m;
        }
        core::array::from_fn(|o| a[o] >> (self.block_shift[o] & 63))
    }

    /// The shared polynomial block, Q16 nm: by monomial when the model
    /// has it so (`blk_n` > 0), else by output row.
    #[inline(always)]
    fn block_any<const N: usize>(&self, mv: &[i32; N]) -> [i64; 3] {
        if self.blk_n > 0 {
            self.block_gather_fixed(mv)
        } else {
            self.block_fixed(mv)
        }
    }

    /// [`Self::block_fixed`] one monomial at a time: each monomial some
    /// output reads is loaded once and multiplied into the three sums
    /// (three SMLALs), the others are skipped. The same exact i64 sums
    /// (the skipped products are 0, and the order of an exact sum does not
    /// change it), so the same integers.
    #[inline(always)]
    fn block_gather_fixed<const N: usize>(&self, mv: &[i32; N]) -> [i64; 3] {
        let mv = core::hint::black_box(mv);
        let n = (self.blk_n as usize).min(BLK_CAP);
        let mut a = self.block_round;
        for c in &self.blk_q[..n] {
            // Index < n_monos ≤ N (load); the clamp is branchless, unlike a bounds check.
            let m = mv[(c[3] as u32 as usize).min(N - 1)] as i64;
            a[0] += c[0] as i64 * m;
            a[1] += c[1] as i64 * m;
            a[2] += c[2] as i64 * m;
        }
        core::array::from_fn(|o| a[o] >> (self.block_shift[o] & 63))
    }

    /// The shared polynomial block, Q16 nm.
    #[inline(always)]
    fn block_fixed<const N: usize>(&self, mv: &[i32; N]) -> [i64; 3] {
        if !self.has_block {
            return [0; 3];
        }
        // Σ|c_q| ≤ 2^31 − 1 and |m| ≤ 2^30 + 1: each sum stays below
        // 2^61 + 2^31, with the rounding term (≤ 2^61) below 2^63 (exact, so
        // the order of the sum does not change it; test
        // `block_is_the_rounded_exact_sum_at_the_limits`). One output at a time
        // over its coefficient row, the monomials read back from memory as
        // i32 (black_box, as in `poly_fixed`): one SMLAL per product.
        let mv = core::hint::black_box(mv);
        core::array::from_fn(|o| {
            // rshr(Σ, s) with its rounding term as the sum's start.
            let mut a = self.block_round[o];
            for (&c, &m) in self.block_q[o].iter().zip(mv.iter()) {
                a += c as i64 * m as i64;
            }
            a >> (self.block_shift[o] & 63)
        })
    }

    /// [`Self::terms_fixed`] over the flat terms (`fq`): the same values
    /// added in the same order (reversal: amp·rev; thermal/Abbe: the
    /// factor times the polynomial over v[0..4], whose dense coefficients
    /// give the pool's exact sum).
    #[inline(never)]
    fn terms_flat_fixed(
        &self,
        v: &[i32; VP_CAP],
        inp: &Inputs,
        flags: &mut Flags,
        out: &mut [i64; 3],
    ) {
        let (temp, tool) = self.hold_aux(inp, flags);
        let n = (self.fq_n as usize).min(FQ_CAP);
        for t in &self.fq[..n] {
            let val = if t.kind == 0 {
                let r = inp.rev_q30[(t.src as usize).min(2)].clamp(-ONE_Q30, ONE_Q30);
                rshr_var(t.k as i64 * r as i64, t.shift)
            } else {
                let s = t.c[0] as i64 * v[0] as i64
                    + t.c[1] as i64 * v[1] as i64
                    + t.c[2] as i64 * v[2] as i64
                    + t.c[3] as i64 * v[3] as i64;
                let f = if t.kind == 1 {
                    temp[t.src as usize & 3] as i64 - t.k as i64
                } else {
                    tool as i64
                };
                rshr_var(rshr(s, 30) * f, t.shift)
            };
            let o = (t.output as usize).min(2);
            out[o] = out[o].saturating_add(val);
        }
    }

    #[inline(never)]
    fn terms_fixed(
        &self,
        mv: &[i32],
        pos: &[i32; 3],
        inp: &Inputs,
        flags: &mut Flags,
        out: &mut [i64; 3],
    ) {
        let (temp, tool) = self.hold_aux(inp, flags);
        for t in self.terms.iter() {
            let (o, v) = match t {
                Term::Factored { output, .. } => (*output, self.factored_fixed(t, mv, &temp, tool)),
                Term::Periodic { output, shift, .. } => {
                    (*output, rshr_var(self.periodic_fixed(t, pos), *shift))
                }
                Term::Reversal {
                    output,
                    axis,
                    amp_q,
                    shift,
                    ..
                } => {
                    // (axis < 3 is validated; `min` keeps the index in
                    // range in two instructions where `% 3` takes six.)
                    let r = inp.rev_q30[(*axis as usize).min(2)].clamp(-ONE_Q30, ONE_Q30);
                    (*output, rshr_var(*amp_q as i64 * r as i64, *shift))
                }
                Term::Grid {
                    output,
                    axes,
                    start,
                } => (*output, self.grid_fixed(axes, *start as usize, pos)),
                Term::Mlp { .. } => {
                    self.mlp_fixed(t, pos, &temp, out);
                    continue;
                }
            };
            let o = (o as usize).min(2);
            out[o] = out[o].saturating_add(v);
        }
    }

    /// factor × polynomial, Q16 nm.
    #[inline(never)]
    fn factored_fixed(&self, t: &Term, mv: &[i32], temp: &[i32; MAX_TEMPS], tool: i32) -> i64 {
        let Term::Factored {
            factor,
            start,
            len,
            shift,
            ..
        } = *t
        else {
            return 0;
        };
        let (s, e) = (start as usize, start as usize + len as usize);
        let mut v = 0i64;
        if let (Some(c), Some(idx)) = (self.pq.get(s..e), self.pidx.get(s..e)) {
            for (&c, &i) in c.iter().zip(idx) {
                v += c as i64 * mv.get(i as usize).copied().unwrap_or(0) as i64;
            }
        }
        let f = match factor {
            Factor::Temp { ch, t_ref_mc } => temp[ch as usize & 3] as i64 - t_ref_mc as i64,
            Factor::Tool => tool as i64,
        };
        rshr_var(rshr(v, 30) * f, shift)
    }

    /// Σ a_k sin kθ + b_k cos kθ in Q(q+30): the first harmonic from the
    /// table, the others by the angle-addition recurrence in Q30.
    #[inline(never)]
    fn periodic_fixed(&self, t: &Term, pos: &[i32; 3]) -> i64 {
        let Term::Periodic {
            axis,
            harmonics,
            period_nm,
            turns,
            start,
            ..
        } = *t
        else {
            return 0;
        };
        let theta = phase_turns(pos[(axis as usize).min(2)], period_nm, turns);
        let (s1, c1) = sincos_q30(theta);
        let c = &self.pq[start as usize..start as usize + 2 * harmonics as usize];
        let (mut s, mut co) = (s1, c1);
        let mut v = 0i64;
        for ab in c.chunks_exact(2) {
            v += ab[0] as i64 * s as i64 + ab[1] as i64 * co as i64;
            let sn = ((s as i64 * c1 as i64 + co as i64 * s1 as i64 + (1 << 29)) >> 30) as i32;
            co = ((co as i64 * c1 as i64 - s as i64 * s1 as i64 + (1 << 29)) >> 30) as i32;
            s = sn;
        }
        v
    }

    /// The MLP in fixed point (same structure as [`Self::mlp_f32`]); the
    /// integer sums are exact, so fusing the output layer changes nothing.
    #[inline(never)]
    fn mlp_fixed(&self, t: &Term, pos: &[i32; 3], temp: &[i32; MAX_TEMPS], out: &mut [i64; 3]) {
        let Term::Mlp {
            outputs,
            n_in,
            n_layers,
            widths,
            n_out,
            in_start,
            start,
            q,
            ..
        } = *t
        else {
            return;
        };
        let n_in = (n_in as usize).min(MAX_MLP_INPUTS);
        let n_out = (n_out as usize).min(3);
        // Layer-1 inputs in Q28 (|x| ≤ 7 checked at load), later ones Q30.
        let mut x = [0i32; MAX_MLP_INPUTS];
        for (xi, mi) in x
            .iter_mut()
            .zip(&self.mlp_in[in_start as usize..in_start as usize + n_in])
        {
            *xi = mi
                .k_q28
                .apply(mlp_source(mi.src, pos, temp).wrapping_sub(mi.mid));
        }
        let x = &x[..n_in];
        let mut k = start as usize;
        let h1: [i32; MAX_HIDDEN_UNITS];
        let (src, prev, in_frac): (&[i32], usize, u32) = if n_layers >= 2 {
            let width = (widths[0] as usize).min(MAX_HIDDEN_UNITS);
            let (w, rest) = self.pq[k..].split_at(width * n_in);
            let b = &rest[..width];
            let ql = q[0] as u32;
            h1 = core::array::from_fn(|j| match (w.get(j * n_in..(j + 1) * n_in), b.get(j)) {
                (Some(row), Some(&bj)) => tanh_q26_of(((bj as i64) << 28) + dot_q(row, x), ql + 28),
                _ => 0,
            });
            k += width * n_in + width;
            (&h1[..width], width, 30)
        } else {
            (x, n_in, 28)
        };
        let last = (n_layers as usize).clamp(1, 2) - 1;
        let width = (widths[last] as usize).min(MAX_HIDDEN_UNITS);
        let (ql, qo) = (q[last] as u32 + in_frac, q[2] as u32);
        let blk = self.pq.get(k..).unwrap_or(&[]);
        let acc = match (prev, n_out) {
            (3, 3) => fused_q::<3, 3>(blk, src, width, in_frac, ql),
            (4, 3) => fused_q::<4, 3>(blk, src, width, in_frac, ql),
            (3, 1) => fused_q::<3, 1>(blk, src, width, in_frac, ql),
            (16, 3) => fused_q::<16, 3>(blk, src, width, in_frac, ql),
            _ => fused_q_dyn(blk, src, width, n_out, in_frac, ql),
        };
        let mut j = 0;
        for (o, a) in out.iter_mut().enumerate() {
            if outputs & (1 << o) != 0 {
                // acc is Q(q_out + 30).
                *a = a.saturating_add(rshr(acc[j % 3], qo + 14));
                j += 1;
            }
        }
    }
}

/// The fused last hidden + output layer in fixed point: `x` has `in_frac`
/// fractional bits, hidden pre-activations `ql` (= q + in_frac); the result
/// is Q(q_out + 30).
#[inline(always)]
fn fused_q<const NI: usize, const NO: usize>(
    blk: &[i32],
    x: &[i32],
    width: usize,
    in_frac: u32,
    ql: u32,
) -> [i64; 3] {
    let mut acc = [0i64; 3];
    let Ok(x) = <&[i32; NI]>::try_from(x) else {
        return acc;
    };
    let stride = 1 + NI + NO;
    let (Some(units), Some(bo)) = (
        blk.get(..width * stride),
        blk.get(width * stride..width * stride + NO),
    ) else {
        return acc;
    };
    let mut a = [0i64; NO];
    for (ai, &b) in a.iter_mut().zip(bo) {
        *ai = (b as i64) << 30;
    }
    for u in units.chunks_exact(stride) {
        let (b, w, wo) = (u[0], &u[1..1 + NI], &u[1 + NI..]);
        let (Ok(w), Ok(wo)) = (<&[i32; NI]>::try_from(w), <&[i32; NO]>::try_from(wo)) else {
            continue;
        };
        let mut z = (b as i64) << in_frac;
        for i in 0..NI {
            z += w[i] as i64 * x[i] as i64;
        }
        let h = tanh_q26_of(z, ql) as i64;
        for o in 0..NO {
            a[o] += wo[o] as i64 * h;
        }
    }
    for (ac, ai) in acc.iter_mut().zip(a) {
        *ac = ai;
    }
    acc
}

/// [`fused_q`] for any shape.
fn fused_q_dyn(
    blk: &[i32],
    x: &[i32],
    width: usize,
    n_out: usize,
    in_frac: u32,
    ql: u32,
) -> [i64; 3] {
    let mut acc = [0i64; 3];
    let stride = 1 + x.len() + n_out;
    let (Some(units), Some(bo)) = (
        blk.get(..width * stride),
        blk.get(width * stride..width * stride + n_out),
    ) else {
        return acc;
    };
    for (a, &b) in acc.iter_mut().zip(bo) {
        *a = (b as i64) << 30;
    }
    for u in units.chunks_exact(stride) {
        let (w, wo) = u[1..].split_at(x.len());
        let h = tanh_q26_of(((u[0] as i64) << in_frac) + dot_q(w, x), ql) as i64;
        for (a, &wj) in acc.iter_mut().zip(wo) {
            *a += wj as i64 * h;
        }
    }
    acc
}

/// Integer dot product (exact), the common tiny input counts unrolled.
#[inline(always)]
fn dot_q(row: &[i32], x: &[i32]) -> i64 {
    let m = |a: i32, b: i32| a as i64 * b as i64;
    match (row, x) {
        ([a, b, c], [p, q, r, ..]) => m(*a, *p) + m(*b, *q) + m(*c, *r),
        ([a, b, c, d], [p, q, r, s, ..]) => m(*a, *p) + m(*b, *q) + m(*c, *r) + m(*d, *s),
        _ => row.iter().zip(x).fold(0, |z, (w, v)| z + m(*w, *v)),
    }
}

/// tanh of a pre-activation `z` with `frac` fractional bits, Q30 out.
#[inline(always)]
fn tanh_q26_of(z: i64, frac: u32) -> i32 {
    let z26 = rshr(z, frac - TANH_IN_FRAC);
    tanh_q30(z26.clamp(-(16 << TANH_IN_FRAC), 16 << TANH_IN_FRAC) as i32)
}

#[cfg(test)]
mod tests {
    use super::super::kernels::MONO_EXPS;
    use super::super::{Inputs, Model};
    use crate::limits::MAX_MONOMIALS;
    use crate::spec::{TableSpec, TermSpec};
    use crate::table::{Envelope, InputScaling};

    /// A seeded table of sparse polynomials (degree ≤ 3, or ≤ 5 on some
    /// draws) with reversal and thermal/Abbe terms of degree ≤ 1 or ≤ 2,
    /// like the simulated board's sample table.
    fn sparse_spec(rng: &mut trueaxis_test_support::XorShift64) -> TableSpec {
        let mut env = Envelope::default();
        let mut sc = InputScaling::default();
        for a in 0..3 {
            let half = rng.range(50_000_000, 1_000_000_000) as i32;
            sc.half_span_nm[a] = half;
            env.travel_min_nm[a] = -half;
            env.travel_max_nm[a] = half;
            // Small on some draws, so that the clamp is taken too.
            env.max_corr_nm[a] = [60_000, 500, 4_000_000][rng.range(0, 2) as usize];
        }
        env.max_slew_nm_per_ms = 500;
        env.temp_max_mc = [50_000, 50_000, 0, 0];
        env.tool_max_nm = 300_000_000;
        let top = if rng.range(0, 4) == 0 { 56 } else { 20 };
        let mut terms = Vec::new();
        // A few monomials the outputs share (as a fitted table's do), each
        // output taking some of them.
        let n = rng.range(1, 7) as usize;
        let mut pool: Vec<usize> = (0..n).map(|_| rng.range(0, top - 1) as usize).collect();
        pool.sort_unstable();
        pool.dedup();
        for output in 0..3u8 {
            let mut coefs = Vec::new();
            for &i in &pool {
                if rng.range(0, 3) > 0 {
                    coefs.push((MONO_EXPS[i], (rng.range(-10_000, 10_000) as f64) * 0.7));
                }
            }
            if !coefs.is_empty() {
                terms.push(TermSpec::Poly { output, coefs });
            }
        }
        let deg = rng.range(1, 2) as usize;
        let low = |rng: &mut trueaxis_test_support::XorShift64| {
            let i = rng.range(1, [0, 4, 10][deg] - 1) as usize;
            vec![(MONO_EXPS[0], 900.0), (MONO_EXPS[i], 400.0)]
        };
        terms.push(TermSpec::Reversal {
            output: 0,
            axis: 0,
            transition_nm: 20_000,
            amplitude_nm: 2500.0,
        });
        terms.push(TermSpec::Thermal {
            output: 1,
            channel: 0,
            t_ref_mc: 20_000,
            coefs_nm_per_k: low(rng),
        });
        if rng.range(0, 2) == 0 {
            terms.push(TermSpec::Abbe {
                output: 2,
                coefs: low(rng),
            });
        }
        TableSpec {
            created_unix_s: 1_700_000_000,
            source_hash: [0; 32],
            channels: vec!["bed".into(), "air".into()],
            envelope: env,
            scaling: sc,
            outputs: [true; 3],
            terms,
        }
    }

    /// The few-monomial path (`vp_*`, with its flat terms `fq` when every
    /// term is a reversal or a thermal/Abbe term) and the block by monomial
    /// (`blk_*`) give the dense general path's integers and flags (the term
    /// loop `terms_fixed`), bit for bit, on
    /// seeded sparse tables and inputs inside and beyond the envelope
    /// (positions, temperatures, tool arm), clamped and not. Both paths
    /// must be taken often (else the test proves nothing).
    #[test]
    fn few_monomial_paths_equal_the_dense_general_path() {
        let mut rng = trueaxis_test_support::XorShift64(0x1f83_d9ab_fb41_bd6bu64);
        let (mut vp, mut fq, mut blk, mut clamped) = (0, 0, 0, 0);
        for _ in 0..300 {
            let bytes = sparse_spec(&mut rng).encode().unwrap();
            let table = crate::parse(&bytes).unwrap();
            let m = Model::load(&table).unwrap();
            // The cost estimate prices the path the loader chose.
            let f = crate::cost::Features::of(&table);
            assert_eq!(
                (f.vp, f.fq, f.blk),
                (m.vp_n > 0, m.fq_n > 0, m.vp_n == 0 && m.blk_n > 0)
            );
            let mut dense = m.clone();
            dense.vp_n = 0;
            dense.blk_n = 0;
            vp += (m.vp_n > 0) as u32;
            fq += (m.vp_n > 0 && m.fq_n > 0) as u32;
            blk += (m.vp_n == 0 && m.blk_n > 0) as u32;
            for _ in 0..50 {
                let env = m.envelope();
                let pos_nm = core::array::from_fn(|a| {
                    let h = env.travel_max_nm[a] as i64;
                    rng.range(-h - h / 5, h + h / 5) as i32
                });
                let inp = Inputs {
                    pos_nm,
                    rev_q30: core::array::from_fn(|_| {
                        rng.range(-(1 << 30) - 5, (1 << 30) + 5) as i32
                    }),
                    temp_mc: core::array::from_fn(|_| rng.range(-10_000, 60_000) as i32),
                    tool_nm: rng.range(-1_000_000, 310_000_000) as i32,
                };
                let (a, b) = (m.eval_fixed(&inp), dense.eval_fixed(&inp));
                assert_eq!(a, b, "{inp:?}");
                clamped += a.flags.contains(crate::Flags::CLAMPED) as u32;
            }
        }
        assert!(
            vp > 50 && fq > 50 && blk > 50 && clamped > 1000,
            "{vp} {fq} {blk} {clamped}"
        );
    }

    /// The block kernel against the exact sum (i128) rounded by `rshr`'s
    /// rule, floor((Σ + 2^(s−1)) / 2^s), at the ends of its ranges: Σ|c| =
    /// 2^31 − 1 per output, monomials at ±(2^30 + 1) and seeded values
    /// between, shifts 14 (the smallest load gives) … 62 (the largest).
    /// Fails if the rounding term or the rows were wrong, or if a sum
    /// wrapped. Also checks the loader's rounding term on a real table.
    #[test]
    fn block_is_the_rounded_exact_sum_at_the_limits() {
        let table = crate::parse(include_bytes!("../../tests/golden/cubic19.bin")).unwrap();
        let mut m = Model::load(&table).unwrap();
        for o in 0..3 {
            assert_eq!(m.block_round[o], 1i64 << (m.block_shift[o] - 1));
        }
        let mut rng = trueaxis_test_support::XorShift64(0x6a09_e667_f3bc_c909u64);
        let lim = (1i64 << 30) + 1;
        for run in 0..400 {
            let mut mv = [0i32; MAX_MONOMIALS];
            for v in mv.iter_mut() {
                *v = match rng.range(0, 3) {
                    0 => lim as i32,
                    1 => -lim as i32,
                    _ => rng.range(-lim, lim) as i32,
                };
            }
            for o in 0..3 {
                // A row whose Σ|c| is exactly 2^31 − 1, signs at random:
                // all on one coefficient, or spread over the row.
                let mut left = i32::MAX as i64;
                let row = &mut m.block_q[o];
                row.fill(0);
                let spread = run % 4 != 0;
                for (i, c) in row.iter_mut().enumerate() {
                    let take = if !spread || i == MAX_MONOMIALS - 1 {
                        left
                    } else {
                        rng.range(0, left + 1) / 4
                    };
                    left -= take;
                    *c = if rng.range(0, 2) == 0 { take } else { -take } as i32;
                    if left == 0 {
                        break;
                    }
                }
                let s = [14u32, 62, 14 + (run % 49) as u32][o];
                m.block_shift[o] = s;
                m.block_round[o] = 1i64 << (s - 1);
            }
            m.has_block = true;
            let mv20: [i32; 20] = core::array::from_fn(|i| mv[i]);
            for (n, got) in [(20, m.block_fixed(&mv20)), (56, m.block_fixed(&mv))] {
                for o in 0..3 {
                    let exact: i128 = (0..n)
                        .map(|i| m.block_q[o][i] as i128 * mv[i] as i128)
                        .sum();
                    let s = m.block_shift[o];
                    let want = (exact + (1i128 << (s - 1))) >> s;
                    assert_eq!(got[o] as i128, want, "run {run} n {n} output {o}");
                }
            }
        }
    }
}
