//! The f32 evaluation path, the fast path on the Cortex-M4F's FPU:
//! [`ModelCap::eval_f32`] with its flat layout for the common tables (every
//! term a reversal, a periodic term or a thermal/Abbe term of degree ≤ 1),
//! the general term loop, and the per-kind term kernels (factored, periodic,
//! MLP, grid). Results are rounded to whole nm once, at the end.

use super::kernels::{grid_cell, mlp_source, mono20_f32, mono56_f32, phase_turns};
use super::{Factor, Flags, GridAxis, Inputs, ModelCap, Outputs, PolyKind, Term, MAX_TEMPS};
use crate::limits::{MAX_HIDDEN_UNITS, MAX_MLP_INPUTS, MAX_MONOMIALS};
use crate::math::{sincos_f32, tanh_f32, tanh_over_lead_f32, tanh_over_lead_f32_bounded, ONE_Q30};

impl<const P: usize, const G: usize> ModelCap<P, G> {
    /// Evaluate in f32 (the fast path on the Cortex-M4F).
    pub fn eval_f32(&self, inp: &Inputs) -> Outputs {
        // A table that is only a polynomial gets straight-line code with
        // no monomial vector (the common case on the board); each kind is
        // its own function so that none pays for another's registers.
        match self.poly {
            PolyKind::Linear => self.eval_poly_f32::<1>(inp),
            PolyKind::Cubic => self.eval_poly_f32::<3>(inp),
            PolyKind::None => self.eval_general_f32(inp),
        }
    }

    /// A polynomial-only table of degree ≤ `D` (1 or 3). Positions inside
    /// the travel (the common case) go straight through; one outside is
    /// held by [`ModelCap::eval_poly_held_f32`], the same evaluation out of
    /// line.
    #[inline(never)]
    fn eval_poly_f32<const D: u8>(&self, inp: &Inputs) -> Outputs {
        let p = inp.pos_nm;
        if !self.inside_travel(p) {
            return self.eval_poly_held_f32::<D>(p);
        }
        self.poly_f32::<D>(p, Flags::empty())
    }

    #[inline(never)]
    fn eval_poly_held_f32<const D: u8>(&self, p: [i32; 3]) -> Outputs {
        let mut flags = Flags::empty();
        let pos = self.hold_pos(p, &mut flags);
        self.poly_f32::<D>(pos, flags)
    }

    /// The polynomial in w = p − centre, nm: its coefficients are stored
    /// divided by the half spans' powers (load), so no normalisation here.
    #[inline(always)]
    fn poly_f32<const D: u8>(&self, pos: [i32; 3], flags: Flags) -> Outputs {
        let w = self.w_f32(&pos);
        let out = if D == 1 {
            self.poly1_f32(w)
        } else {
            self.poly3_f32(w)
        };
        self.finish_f32(out, flags)
    }

    /// p − centre in f32, nm (|p − c| ≤ half-span < 2^31, validated, so the
    /// wrapping i32 difference is exact).
    #[inline(always)]
    fn w_f32(&self, pos: &[i32; 3]) -> [f32; 3] {
        core::array::from_fn(|a| pos[a].wrapping_sub(self.centre_nm[a]) as f32)
    }

    /// Every other table: the monomial vector, the block and the terms.
    #[inline(never)]
    fn eval_general_f32(&self, inp: &Inputs) -> Outputs {
        let mut flags = Flags::empty();
        let pos = self.hold_pos_fast(inp.pos_nm, &mut flags);
        let out = self.general_f32(|| self.u_f32(&pos), &pos, inp, &mut flags);
        self.finish_f32(out, flags)
    }

    /// The normalised positions u ∈ [−1, 1]. |p − c| ≤ half-span < 2^31
    /// (validated), so the wrapping i32 difference is exact.
    #[inline(always)]
    fn u_f32(&self, pos: &[i32; 3]) -> [f32; 3] {
        [
            pos[0].wrapping_sub(self.centre_nm[0]) as f32 * self.inv_half_f32[0],
            pos[1].wrapping_sub(self.centre_nm[1]) as f32 * self.inv_half_f32[1],
            pos[2].wrapping_sub(self.centre_nm[2]) as f32 * self.inv_half_f32[2],
        ]
    }

    /// Round to whole nm and clamp to ±max per output. Rounding is the
    /// 1.5·2^23 trick (for |v| < 2^22 the sum's mantissa is the integer,
    /// ties to even); results well inside ±max need no clamp, anything
    /// else (near or beyond max, NaN, inf — whose bits land far outside the
    /// window) takes the exact test, [`ModelCap::finish_exact_f32`], out of
    /// line so that no value must live across a call in the common case.
    #[inline(always)]
    fn finish_f32(&self, out: [f32; 3], flags: Flags) -> Outputs {
        let n = out.map(|v| ((v + ROUND_MAGIC).to_bits() as i32).wrapping_sub(ROUND_MAGIC_BITS));
        let ok = |o: usize| (n[o].wrapping_add(self.round_lim[o]) as u32) < self.round_win[o];
        if ok(0) && ok(1) && ok(2) {
            Outputs { corr_nm: n, flags }
        } else {
            self.finish_exact_f32(out[0], out[1], out[2], flags)
        }
    }

    /// The three outputs as separate arguments: they stay in FPU registers
    /// (an array would be stored to the stack and passed by reference).
    #[inline(never)]
    fn finish_exact_f32(&self, o0: f32, o1: f32, o2: f32, mut flags: Flags) -> Outputs {
        let out = [o0, o1, o2];
        let mut corr = [0i32; 3];
        for o in 0..3 {
            let (c, f) = self.clamp_round_f32(out[o], o);
            flags.insert(f);
            corr[o] = c;
        }
        Outputs {
            corr_nm: corr,
            flags,
        }
    }

    /// The exact output test: |v| ≤ max passes, beyond it the output is
    /// held at ±max and flagged, NaN/inf gives 0 and its flag.
    #[inline(always)]
    fn clamp_round_f32(&self, v: f32, o: usize) -> (i32, Flags) {
        let max = self.max_corr_f32[o % 3];
        let (c, f) = if v.abs() <= max {
            (v, Flags::empty()) // NaN fails the comparison
        } else if v > max {
            (max, Flags::CLAMPED)
        } else if v < -max {
            (-max, Flags::CLAMPED)
        } else {
            (0.0, Flags::NOT_FINITE)
        };
        // Exact for |c| < 2^22, which MAX_CORR_LIMIT_NM guarantees.
        (((c + ROUND_MAGIC) - ROUND_MAGIC) as i32, f)
    }

    /// c₀ + c₁x + c₂y + c₃z per output (x, y, z: `w_f32`).
    #[inline(always)]
    fn poly1_f32(&self, u: [f32; 3]) -> [f32; 3] {
        let [x, y, z] = u;
        let h = |c: &[f32; 20]| {
            let (c0, c1, c2, c3) = (c[19], c[9], c[15], c[18]);
            c0 + x * c1 + y * c2 + z * c3
        };
        [
            h(&self.horner_f32[0]),
            h(&self.horner_f32[1]),
            h(&self.horner_f32[2]),
        ]
    }

    /// A polynomial of degree ≤ 3 per output by the Horner scheme of
    /// `kernels::HORNER20`: 19 multiply-adds per output and no monomial products,
    /// the coefficients read in memory order (x, y, z: `w_f32`).
    #[inline(always)]
    fn poly3_f32(&self, u: [f32; 3]) -> [f32; 3] {
        let [x, y, z] = u;
        let h = |c: &[f32; 20]| {
            let a = c[0] + x * c[1] + y * c[2] + z * c[3];
            let b = c[4] + y * c[5] + z * c[6];
            let cc = c[7] + z * c[8];
            let px = c[9] + x * a + y * b + z * cc;
            let d = c[10] + y * c[11] + z * c[12];
            let e = c[13] + z * c[14];
            let py = c[15] + y * d + z * e;
            let f = c[16] + z * c[17];
            let pz = c[18] + z * f;
            c[19] + x * px + y * py + z * pz
        };
        [
            h(&self.horner_f32[0]),
            h(&self.horner_f32[1]),
            h(&self.horner_f32[2]),
        ]
    }

    /// Every table that is not only a polynomial: the monomial vector, the
    /// block and the terms.
    #[inline(always)]
    fn general_f32(
        &self,
        u: impl Fn() -> [f32; 3],
        pos: &[i32; 3],
        inp: &Inputs,
        flags: &mut Flags,
    ) -> [f32; 3] {
        // Monomials up to degree 3 (the common case) are one straight-line
        // expression and the block loop has a constant trip count. All other
        // terms are evaluated out of line (recomputing the monomials they
        // need), so they cost the polynomial path nothing — no spilled
        // monomials, no hoisted constants — when a table has none.
        if self.terms.is_empty() {
            match self.n_monos {
                0 => [0.0; 3],
                1..=20 => self.block_f32(&mono20_f32(u())),
                _ => self.block_f32(&mono56_f32(u())),
            }
        } else if self.flat {
            // The flat terms read u itself, so the monomials stay in registers.
            let uv = u();
            let mut out = match self.n_monos {
                0 => [0.0; 3],
                1..=20 => self.block_f32(&mono20_f32(uv)),
                _ => self.block_f32(&mono56_f32(uv)),
            };
            self.flat_f32(uv, pos, inp, flags, &mut out);
            out
        } else {
            // The monomials are handed to the thermal/Abbe terms.
            match self.n_monos {
                0 => {
                    let mut out = [0.0; 3];
                    self.terms_f32(&[], pos, inp, flags, &mut out);
                    out
                }
                1..=20 => {
                    let mv = mono20_f32(u());
                    let mut out = self.block_f32(&mv);
                    self.terms_f32(&mv, pos, inp, flags, &mut out);
                    out
                }
                _ => {
                    let mv = mono56_f32(u());
                    let mut out = self.block_f32(&mv);
                    self.terms_f32(&mv, pos, inp, flags, &mut out);
                    out
                }
            }
        }
    }

    #[inline(always)]
    fn block_f32<const N: usize>(&self, mv: &[f32; N]) -> [f32; 3] {
        if !self.has_block {
            return [0.0; 3];
        }
        let (mut a0, mut a1, mut a2) = (0.0f32, 0.0f32, 0.0f32);
        for i in 0..N.min(MAX_MONOMIALS) {
            let (m, c) = (mv[i], self.block_f32[i]);
            a0 += c[0] * m;
            a1 += c[1] * m;
            a2 += c[2] * m;
        }
        [a0, a1, a2]
    }

    /// Thermal/Abbe, periodic and reversal terms from their per-kind arrays.
    #[inline(never)]
    fn flat_f32(
        &self,
        u: [f32; 3],
        pos: &[i32; 3],
        inp: &Inputs,
        flags: &mut Flags,
        out: &mut [f32; 3],
    ) {
        let (temp, tool) = self.hold_aux(inp, flags);
        let mut acc = [out[0], out[1], out[2], 0.0f32];
        for f in self.fac_f32.iter() {
            let s = f.c[0] + f.c[1] * u[0] + f.c[2] * u[1] + f.c[3] * u[2];
            let v = if f.src < 4 {
                temp[f.src as usize & 3]
            } else {
                tool
            };
            acc[f.output as usize & 3] += s * v.wrapping_sub(f.offset) as f32;
        }
        for p in self.per_f32.iter() {
            let d = pos
                .get(p.axis as usize)
                .copied()
                .unwrap_or(0)
                .wrapping_sub(p.base_nm) as u32;
            let r = d % p.period;
            let theta = r
                .wrapping_mul(p.turns.int)
                .wrapping_add(((r as u64 * p.turns.frac as u64) >> 32) as u32);
            let (s1, c1) = sincos_f32(theta);
            let (mut s, mut co) = (s1, c1);
            let mut v = 0.0f32;
            for ab in p.ab.iter().take(p.harmonics as usize) {
                v += ab[0] * s + ab[1] * co;
                let sn = s * c1 + co * s1;
                co = co * c1 - s * s1;
                s = sn;
            }
            acc[p.output as usize & 3] += v;
        }
        if self.has_rev {
            // Held to ±1 (the upper bound 1 − 2^-30 makes it one SSAT).
            let r = inp.rev_q30.map(|r| r.clamp(-ONE_Q30, ONE_Q30 - 1) as f32);
            for (ra, rv) in self.rev_f32.iter().zip(r) {
                acc[0] += ra[0] * rv;
                acc[1] += ra[1] * rv;
                acc[2] += ra[2] * rv;
            }
        }
        *out = [acc[0], acc[1], acc[2]];
    }

    #[inline(never)]
    fn terms_f32(
        &self,
        mv: &[f32],
        pos: &[i32; 3],
        inp: &Inputs,
        flags: &mut Flags,
        out: &mut [f32; 3],
    ) {
        // Each kind is its own out-of-line function taking the term by
        // reference: this loop then hoists nothing and costs a few
        // instructions per term.
        let (temp, tool) = self.hold_aux(inp, flags);
        for t in self.terms.iter() {
            let (o, v) = match t {
                Term::Factored { output, .. } => (*output, self.factored_f32(t, mv, &temp, tool)),
                Term::Periodic { output, .. } => (*output, self.periodic_f32(t, pos)),
                Term::Reversal {
                    output,
                    axis,
                    amp_f32,
                    ..
                } => {
                    let r = inp.rev_q30[*axis as usize % 3].clamp(-ONE_Q30, ONE_Q30);
                    (*output, amp_f32 * r as f32)
                }
                Term::Grid {
                    output,
                    axes,
                    start,
                } => (*output, self.grid_f32(axes, *start as usize, pos)),
                Term::Mlp { .. } => {
                    self.mlp_f32(t, pos, &temp, out);
                    continue;
                }
            };
            out[o as usize % 3] += v;
        }
    }

    #[inline(never)]
    fn factored_f32(&self, t: &Term, mv: &[f32], temp: &[i32; MAX_TEMPS], tool: i32) -> f32 {
        let Term::Factored {
            factor, start, len, ..
        } = *t
        else {
            return 0.0;
        };
        let (s, e) = (start as usize, start as usize + len as usize);
        let mut v = 0.0f32;
        if let (Some(c), Some(idx)) = (self.pf.get(s..e), self.pidx.get(s..e)) {
            for (c, &i) in c.iter().zip(idx) {
                v += c * mv.get(i as usize).copied().unwrap_or(0.0);
            }
        }
        let f = match factor {
            Factor::Temp { ch, t_ref_mc } => temp[ch as usize & 3].wrapping_sub(t_ref_mc) as f32,
            Factor::Tool => tool as f32,
        };
        v * f
    }

    /// Σ a_k sin kθ + b_k cos kθ: the first harmonic from the table, the
    /// others by the angle-addition recurrence (4 multiplies each).
    #[inline(never)]
    fn periodic_f32(&self, t: &Term, pos: &[i32; 3]) -> f32 {
        let Term::Periodic {
            axis,
            harmonics,
            period_nm,
            turns,
            start,
            ..
        } = *t
        else {
            return 0.0;
        };
        let theta = phase_turns(pos[axis as usize % 3], period_nm, turns);
        let (s1, c1) = sincos_f32(theta);
        let c = self
            .pf
            .get(start as usize..start as usize + 2 * harmonics as usize)
            .unwrap_or(&[]);
        let (mut s, mut co) = (s1, c1);
        let mut v = 0.0f32;
        for ab in c.chunks_exact(2) {
            v += ab[0] * s + ab[1] * co;
            let sn = s * c1 + co * s1;
            co = co * c1 - s * s1;
            s = sn;
        }
        v
    }

    /// The MLP in f32. The last hidden layer is fused with the linear output
    /// layer (each unit's activation is consumed as soon as it is computed),
    /// so a one-hidden-layer net needs no activation buffer at all.
    #[inline(never)]
    fn mlp_f32(&self, t: &Term, pos: &[i32; 3], temp: &[i32; MAX_TEMPS], out: &mut [f32; 3]) {
        let Term::Mlp {
            outputs,
            n_in,
            n_layers,
            widths,
            n_out,
            in_start,
            start,
            bounded,
            ..
        } = *t
        else {
            return;
        };
        let n_in = (n_in as usize).min(MAX_MLP_INPUTS);
        let n_out = (n_out as usize).min(3);
        let mut x = [0.0f32; MAX_MLP_INPUTS];
        for (xi, mi) in x
            .iter_mut()
            .zip(&self.mlp_in[in_start as usize..in_start as usize + n_in])
        {
            // |v − mid| < 2^31 over the envelope (checked at load); the
            // scale k is folded into the first layer's f32 weights at load.
            *xi = mlp_source(mi.src, pos, temp).wrapping_sub(mi.mid) as f32;
        }
        let x = &x[..n_in];
        let mut k = start as usize;
        let h1: [f32; MAX_HIDDEN_UNITS];
        let (src, prev): (&[f32], usize) = if n_layers >= 2 {
            let width = (widths[0] as usize).min(MAX_HIDDEN_UNITS);
            let (w, rest) = self.pf[k..].split_at(width * n_in);
            let b = &rest[..width];
            h1 = core::array::from_fn(|j| match (w.get(j * n_in..(j + 1) * n_in), b.get(j)) {
                (Some(row), Some(&bj)) => tanh_f32(bj + dot_f32(row, x)),
                _ => 0.0,
            });
            k += width * n_in + width;
            (&h1[..width], width)
        } else {
            (x, n_in)
        };
        let width = (widths[(n_layers as usize).clamp(1, 2) - 1] as usize).min(MAX_HIDDEN_UNITS);
        let blk = self.pf.get(k..).unwrap_or(&[]);
        // Monomorphised (fully unrolled) for the common shapes.
        let acc = match (prev, n_out) {
            (3, 3) => fused_f32::<3, 3, 7>(blk, src, width, bounded),
            (4, 3) => fused_f32::<4, 3, 8>(blk, src, width, bounded),
            (3, 1) => fused_f32::<3, 1, 5>(blk, src, width, bounded),
            (16, 3) => fused_f32::<16, 3, 20>(blk, src, width, bounded),
            _ => fused_f32_dyn(blk, src, width, n_out),
        };
        if outputs == 0b111 {
            // The common case: the net's outputs are x, y, z in order.
            out[0] += acc[0];
            out[1] += acc[1];
            out[2] += acc[2];
            return;
        }
        let mut j = 0;
        for o in 0..3 {
            if outputs & (1 << o) != 0 {
                out[o] += acc[j % 3];
                j += 1;
            }
        }
    }

    #[inline(never)]
    fn grid_f32(&self, axes: &[GridAxis; 3], start: usize, pos: &[i32; 3]) -> f32 {
        let mut idx = [0usize; 3];
        let mut nxt = [0usize; 3];
        let mut t = [0.0f32; 3];
        for a in 0..3 {
            let (i, frac) = grid_cell(&axes[a], pos[a]);
            idx[a] = i;
            nxt[a] = if (i + 1) < axes[a].nodes as usize {
                i + 1
            } else {
                i
            };
            t[a] = frac as f32 * axes[a].inv_step_f32;
        }
        let nx = axes[0].nodes as usize;
        let nxy = nx * axes[1].nodes as usize;
        let g = |x: usize, y: usize, z: usize| {
            self.grid
                .get(start + x + nx * y + nxy * z)
                .copied()
                .unwrap_or(0) as f32
        };
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(g(idx[0], idx[1], idx[2]), g(nxt[0], idx[1], idx[2]), t[0]);
        let c10 = lerp(g(idx[0], nxt[1], idx[2]), g(nxt[0], nxt[1], idx[2]), t[0]);
        let c01 = lerp(g(idx[0], idx[1], nxt[2]), g(nxt[0], idx[1], nxt[2]), t[0]);
        let c11 = lerp(g(idx[0], nxt[1], nxt[2]), g(nxt[0], nxt[1], nxt[2]), t[0]);
        let c0 = lerp(c00, c10, t[1]);
        let c1 = lerp(c01, c11, t[1]);
        lerp(c0, c1, t[2]) * (1.0 / 256.0)
    }
}

/// The last hidden layer fused with the output layer, f32: per unit the
/// record [bias, NI weights, NO output weights × `TANH_F32_LEAD`] (so the
/// unit's activation is [`tanh_over_lead_f32`], one instruction cheaper than
/// `tanh_f32`); then NO output biases.
#[inline(always)]
fn fused_f32<const NI: usize, const NO: usize, const S: usize>(
    blk: &[f32],
    x: &[f32],
    width: usize,
    bounded: bool,
) -> [f32; 3] {
    let mut acc = [0.0f32; 3];
    let Ok(x) = <&[f32; NI]>::try_from(x) else {
        return acc;
    };
    // S = 1 + NI + NO, the record's length (a const parameter: stable Rust
    // cannot write [f32; 1 + NI + NO]); the records as arrays make the loop
    // a pointer walk with constant offsets (no length count, no bounds checks).
    if S != 1 + NI + NO {
        return acc;
    }
    let (Some(units), Some(bo)) = (blk.get(..width * S), blk.get(width * S..width * S + NO)) else {
        return acc;
    };
    let mut a = [0.0f32; NO];
    for (ai, &b) in a.iter_mut().zip(bo) {
        *ai = b;
    }
    let units = units.as_chunks::<S>().0;
    // The output weights were scaled by TANH_F32_LEAD at load. A net whose
    // units have |z| ≤ 8 over the held inputs (`bounded`, set at load)
    // skips the saturation test: the same results, 3 instructions less per unit.
    if bounded {
        fused_units::<NI, NO, S>(units, x, &mut a, tanh_over_lead_f32_bounded);
    } else {
        fused_units::<NI, NO, S>(units, x, &mut a, tanh_over_lead_f32);
    }
    for (ac, ai) in acc.iter_mut().zip(a) {
        *ac = ai;
    }
    acc
}

/// The unit loop of [`fused_f32`] with the activation `act`.
#[inline(always)]
fn fused_units<const NI: usize, const NO: usize, const S: usize>(
    units: &[[f32; S]],
    x: &[f32; NI],
    a: &mut [f32; NO],
    act: impl Fn(f32) -> f32,
) {
    for u in units {
        let mut z = u[0];
        for i in 0..NI {
            z += u[1 + i] * x[i];
        }
        let h = act(z);
        for o in 0..NO {
            a[o] += u[1 + NI + o] * h;
        }
    }
}

/// [`fused_f32`] for any shape.
fn fused_f32_dyn(blk: &[f32], x: &[f32], width: usize, n_out: usize) -> [f32; 3] {
    let mut acc = [0.0f32; 3];
    let stride = 1 + x.len() + n_out;
    let (Some(units), Some(bo)) = (
        blk.get(..width * stride),
        blk.get(width * stride..width * stride + n_out),
    ) else {
        return acc;
    };
    for (a, &b) in acc.iter_mut().zip(bo) {
        *a = b;
    }
    for u in units.chunks_exact(stride) {
        let (w, wo) = u[1..].split_at(x.len());
        let h = tanh_over_lead_f32(u[0] + dot_f32(w, x));
        for (a, &wj) in acc.iter_mut().zip(wo) {
            *a += wj * h;
        }
    }
    acc
}

/// Dot product with the common tiny input counts unrolled.
#[inline(always)]
fn dot_f32(row: &[f32], x: &[f32]) -> f32 {
    match (row, x) {
        ([a, b, c], [p, q, r, ..]) => a * p + b * q + c * r,
        ([a, b, c, d], [p, q, r, s, ..]) => a * p + b * q + c * r + d * s,
        _ => row.iter().zip(x).fold(0.0, |z, (w, v)| z + w * v),
    }
}

/// 1.5 · 2^23: adding and subtracting it rounds an f32 of magnitude < 2^22 to an integer.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// The bits of [`ROUND_MAGIC`]: (v + ROUND_MAGIC)'s bits minus these are round(v) for |v| < 2^22.
const ROUND_MAGIC_BITS: i32 = 0x4B40_0000;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{parse, LargeModel};

    /// A net whose fused units are `bounded` (set at load) evaluates to the
    /// same f32 bits with and without the saturation test on every held
    /// input, the envelope's corners included (golden nn_3x16x3, the bench's
    /// net); all_kinds' net is not bounded (its z reaches beyond 8).
    #[test]
    fn bounded_mlp_equals_the_checked_one_on_held_inputs() {
        let mut rng = trueaxis_test_support::XorShift64(0x2545_f491_4f6c_dd1du64);
        let mut next = || rng.next_u64();
        let (mut tested, mut unbounded) = (0, 0);
        for bytes in [
            &include_bytes!("../../tests/golden/nn_3x16x3.bin")[..],
            &include_bytes!("../../tests/golden/all_kinds.bin")[..],
        ] {
            let m = LargeModel::load(&parse(bytes).unwrap()).unwrap();
            for t in m.terms.iter() {
                let Term::Mlp { bounded, .. } = *t else {
                    continue;
                };
                if !bounded {
                    unbounded += 1;
                    continue;
                }
                let mut checked = *t;
                if let Term::Mlp { bounded, .. } = &mut checked {
                    *bounded = false;
                }
                let env = &m.env;
                let pick = |lo: i32, hi: i32, r: u64| match r % 8 {
                    0 => lo,
                    1 => hi,
                    _ => (lo as i64 + (r >> 3) as i64 % (hi as i64 - lo as i64 + 1)) as i32,
                };
                for _ in 0..20_000 {
                    let pos: [i32; 3] = core::array::from_fn(|a| {
                        pick(env.travel_min_nm[a], env.travel_max_nm[a], next())
                    });
                    let temp: [i32; MAX_TEMPS] = core::array::from_fn(|c| {
                        pick(
                            env.temp_min_mc[c].min(env.temp_max_mc[c]),
                            env.temp_max_mc[c],
                            next(),
                        )
                    });
                    let (mut a, mut b) = ([0.0f32; 3], [0.0f32; 3]);
                    m.mlp_f32(t, &pos, &temp, &mut a);
                    m.mlp_f32(&checked, &pos, &temp, &mut b);
                    assert_eq!(
                        a.map(f32::to_bits),
                        b.map(f32::to_bits),
                        "pos {pos:?} temp {temp:?}"
                    );
                }
                tested += 1;
            }
        }
        // nn_3x16x3's net is bounded, all_kinds' steeper one is not.
        assert_eq!((tested, unbounded), (1, 1));
    }
}
