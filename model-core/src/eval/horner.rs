//! The fixed-point path of separable polynomials ("Horner rows", issue
//! 26): a table whose every polynomial, thermal and Abbe monomial is one
//! axis to a power times at most one linear factor of another axis
//! (u_a^n, u_a^n·u_b — the shape a rigid-body chain such as `rigid21`
//! produces) is evaluated row by row instead of through the 56-entry
//! monomial vector. For each (sum, axis a, weight w) the loader gathers
//! the monomials u_a^n·(1 | u_b) as w · H(u_a), w ∈ {x, y, z, xy, xz, yz}
//! (w = u_a for the pure powers: u_a^n = u_a · u_a^(n−1); the products
//! u_a·u_b once per call) and H = Σ c_k·u_a^k a polynomial of degree ≤ 4.
//! The constant goes into the sum's start. A sum is an output's share of
//! the block or one thermal/Abbe term's polynomial.
//!
//! H is evaluated by Horner's rule on u/2, each step one SMMLA (h ←
//! c'_k + ⌊h·u' / 2^32⌋, u' = 2u in Q30 saturated to i32, i.e. u/2 in Q32),
//! with the coefficients c'_k = c_k·2^k in Q(q); then the row adds h·w
//! (Q(q+30), exact) into its sum, which stays in registers over the
//! sum's rows (the rows are sorted by sum).
//!
//! Ranges: each sum's scale q is chosen with one bit of headroom,
//! Σ|c'|·2^q < 2^30 ([`plan`]). A step adds at most |h|/2 + 1 in
//! magnitude, so every partial value stays below Σ|c'_q| + 4 < 2^31
//! (i32), and a sum Σ h·w (|w| ≤ 2^30 + 2) plus its start (rounding ≤
//! 2^61, constant ≤ 2^60) stays below 2^62 (i64; test
//! `extreme_separable_tables_do_not_overflow`). Errors, in units of 2^-q
//! of the sum: ≤ 4 per row from the truncated steps, ½ per coefficient,
//! 2 per row from the truncated product w — far below 1 nm for any table
//! whose outputs fit ±4 mm (`tests/separable.rs`).
//!
//! [`plan`] is the one decision: the loader, [`crate::cost`] and
//! [`crate::definition`] all ask it.

use super::kernels::{choose_q, mul_q30, rshr, rshr_var, to_q};
use super::{factored_q, Inputs, ModelCap, MAX_TERMS};
use crate::table::{Table, TermView};

/// Most rows the path takes (a rigid21:4 table has 21).
pub(crate) const HR_CAP: usize = 24;
/// Most thermal/Abbe terms it takes.
pub(crate) const HF_CAP: usize = 4;
/// Sums: the three outputs' blocks, then one per thermal/Abbe term.
const SLOTS: usize = 3 + HF_CAP;
/// Coefficients of H per row (u_a^0 … u_a^4).
const HC: usize = 5;

/// A thermal/Abbe term's factor on this path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct HFac {
    output: u8,
    /// 0…3 a temperature channel (minus `k` = T_ref), 4 the tool arm.
    src: u8,
    k: i32,
    /// From Q(q + 16) (the sum's Q(q+30) rounded to Q(q), times the
    /// factor) to Q16 nm: q − 16.
    shift: u32,
}

/// The prepared path (`n` = 0: off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct HornerQ {
    n: u8,
    /// Horner steps per row (the highest power of H in use, 2…4).
    steps: u8,
    nf: u8,
    /// The block sums' shift to Q16 nm (q + 14; each start holds the
    /// rounding 2^(shift−1)).
    shift: [u32; 3],
    /// Each sum's start: rounding and constant coefficient (× 2^30).
    init: [i64; SLOTS],
    /// The rows of sum j are rows `end[j − 1]..end[j]`.
    end: [u8; SLOTS],
    fac: [HFac; HF_CAP],
    /// Where the rows' coefficients start in the parameter pool: row i
    /// is `pq[base + 5i ..][..5]` (c'_0 … c'_4, Q(q)) — in the pool, so
    /// the model grows by this header only (a model on a 40 KiB stack,
    /// as the tick bench has it, had no room for 500 bytes more).
    base: u16,
    /// Row i's (axis, w index, its sum, the next row's sum — or 0xFF
    /// while the next row adds into the same sum).
    ix: [[u8; 4]; HR_CAP],
}

impl HornerQ {
    pub(super) const EMPTY: HornerQ = HornerQ {
        n: 0,
        steps: 0,
        nf: 0,
        shift: [0; 3],
        init: [0; SLOTS],
        end: [0; SLOTS],
        fac: [HFac {
            output: 0,
            src: 0,
            k: 0,
            shift: 0,
        }; HF_CAP],
        base: 0,
        ix: [[0; 4]; HR_CAP],
    };

    /// Whether the path is taken.
    pub(super) fn on(&self) -> bool {
        self.n > 0
    }

    /// Off, every field zero, in place.
    pub(super) fn clear(&mut self) {
        self.n = 0;
        self.steps = 0;
        self.nf = 0;
        self.shift = [0; 3];
        self.init = [0; SLOTS];
        self.end = [0; SLOTS];
        self.fac.fill(HFac::default());
        self.base = 0;
        self.ix = [[0; 4]; HR_CAP];
    }
}

/// A monomial u_a^n·(1 | u_b), n ≥ 1, as (a, n − 1, w index): w = a for
/// a pure power, 3 + the pair (xy 3, xz 4, yz 5) with a factor. `None`:
/// the constant, or not separable (three axes, or two above degree 1).
fn split(m: [u8; 3]) -> Option<(usize, usize, usize)> {
    let nz: heapless::Vec<usize, 3> = (0..3).filter(|&a| m[a] > 0).collect();
    let pair = |a: usize, b: usize| 3 + a.min(b) + a.max(b) - 1;
    match nz.as_slice() {
        [a] => Some((*a, m[*a] as usize - 1, *a)),
        [a, b] if m[*b] == 1 => Some((*a, m[*a] as usize - 1, pair(*a, *b))),
        [a, b] if m[*a] == 1 => Some((*b, m[*b] as usize - 1, pair(*a, *b))),
        _ => None,
    }
}

/// What [`plan`] found: the rows' (sum, axis, w index) sorted by sum,
/// the constants and the sums' scales (a few hundred bytes: it is made on
/// the board too, at load and by the cost estimate).
pub(crate) struct Plan {
    keys: [(u8, u8, u8); HR_CAP],
    /// Rows used.
    pub n: usize,
    /// Horner steps per row (see [`HornerQ`]).
    pub steps: usize,
    /// Thermal/Abbe terms: (output, src, T_ref m°C).
    fac: [(u8, u8, i32); HF_CAP],
    /// Their number.
    pub nf: usize,
    c0: [f64; SLOTS],
    /// Each sum's binary scale q.
    q: [i32; SLOTS],
}

impl Plan {
    /// The binary scale of the `j`-th thermal/Abbe term (table order).
    pub(crate) fn factored_q(&self, j: usize) -> i32 {
        self.q[(3 + j).min(SLOTS - 1)]
    }

    /// The row of a non-constant separable monomial in sum `slot`.
    fn row(&self, slot: usize, m: [u8; 3]) -> Option<(usize, usize)> {
        let (a, k, wi) = split(m)?;
        let key = (slot as u8, a as u8, wi as u8);
        let i = self.keys[..self.n].iter().position(|&r| r == key)?;
        Some((i, k))
    }
}

/// The thermal/Abbe terms' factors: (output, src, T_ref m°C) each, and
/// their number.
type Factors = ([(u8, u8, i32); HF_CAP], usize);

/// Every (sum, monomial, coefficient) of `table`'s polynomial, thermal
/// (per m°C) and Abbe terms, in table order, and the thermal/Abbe terms'
/// factors; `None` when a term of another kind or more than [`HF_CAP`]
/// thermal/Abbe terms, or when `f` says no.
fn each_monomial(
    table: &Table<'_>,
    mut f: impl FnMut(usize, [u8; 3], f64) -> Option<()>,
) -> Option<Factors> {
    let mut fac = [(0, 0, 0); HF_CAP];
    let mut nf = 0;
    if table.term_count() > MAX_TERMS {
        return None;
    }
    for t in table.terms() {
        let (slot, coefs, per_mc) = match t.view() {
            TermView::Poly { output, coefs } => (output % 3, coefs, false),
            TermView::Thermal {
                output,
                channel,
                t_ref_mc,
                coefs,
            } => {
                *fac.get_mut(nf)? = (output as u8, channel as u8 & 3, t_ref_mc);
                nf += 1;
                (2 + nf, coefs, true)
            }
            TermView::Abbe { output, coefs } => {
                *fac.get_mut(nf)? = (output as u8, 4, 0);
                nf += 1;
                (2 + nf, coefs, false)
            }
            _ => return None,
        };
        for (m, c) in coefs.iter() {
            f(slot, m, if per_mc { c / 1000.0 } else { c })?;
        }
    }
    Some((fac, nf))
}

/// The Horner-row plan of `table`, or `None` when the fixed path keeps
/// the monomial vector: a term that is not a polynomial, thermal or Abbe
/// term, a monomial that is not separable, no monomial of degree ≥ 4 (the
/// paths of degree ≤ 3 are cheaper), more than [`HR_CAP`] rows or
/// [`HF_CAP`] thermal/Abbe terms, or a sum whose Σ|c_k|·2^k (over the
/// table's coefficients, before two terms' are added: an upper bound)
/// leaves no scale with the headroom (Σ·2^q < 2^30; thermal/Abbe q ≥ 16).
/// Out of line (load time, the cost estimate and the definition check).
#[inline(never)]
pub(crate) fn plan(table: &Table<'_>) -> Option<Plan> {
    let mut p = Plan {
        keys: [(0, 0, 0); HR_CAP],
        n: 0,
        steps: 0,
        fac: [(0, 0, 0); HF_CAP],
        nf: 0,
        c0: [0.0; SLOTS],
        q: [0; SLOTS],
    };
    let mut max_deg = 0;
    let mut sum = [0.0f64; SLOTS];
    let (fac, nf) = each_monomial(table, |slot, m, c| {
        max_deg = max_deg.max(m[0] + m[1] + m[2]);
        if m == [0, 0, 0] {
            p.c0[slot] += c;
            sum[slot] += c.abs();
            return Some(());
        }
        let (a, k, wi) = split(m)?;
        let key = (slot as u8, a as u8, wi as u8);
        if !p.keys[..p.n].contains(&key) {
            *p.keys.get_mut(p.n)? = key;
            p.n += 1;
        }
        sum[slot] += c.abs() * f64::from(1u32 << k);
        if c != 0.0 {
            p.steps = p.steps.max(k);
        }
        Some(())
    })?;
    if max_deg < 4 {
        return None;
    }
    (p.fac, p.nf) = (fac, nf);
    // The rows by sum (their order within a sum changes no exact sum).
    p.keys[..p.n].sort_unstable();
    p.steps = p.steps.clamp(2, HC - 1);
    for s in 0..SLOTS {
        p.q[s] = if s < 3 {
            choose_q(2.0 * sum[s], 0)?
        } else if s < 3 + p.nf {
            factored_q(2.0 * sum[s])?
        } else {
            0
        };
    }
    Some(p)
}

impl<const P: usize, const G: usize> ModelCap<P, G> {
    /// Set the path from `table`'s [`plan`] (off when there is none).
    /// Out of line: load time only.
    #[inline(never)]
    pub(super) fn prepare_horner(&mut self, table: &Table<'_>) {
        self.hr.clear();
        let Some(p) = plan(table) else {
            return;
        };
        // The rows' coefficients in the pools, after every term's parameters.
        let base = self.pq.len();
        if base + HC * p.n > P.min(u16::MAX as usize) {
            return;
        }
        for (i, &(j, a, wi)) in p.keys[..p.n].iter().enumerate() {
            for _ in 0..HC {
                let (_, _, _) = (self.pf.push(0.0), self.pq.push(0), self.pidx.push(0));
            }
            let next = if i + 1 < p.n { p.keys[i + 1].0 } else { j };
            let last = i + 1 == p.n || next != j;
            self.hr.ix[i] = [a, wi, j, if last { next } else { 0xFF }];
            for e in self.hr.end[j as usize..].iter_mut() {
                *e += 1;
            }
        }
        // Each coefficient rounded on its own (½ unit each): the sum of
        // the magnitudes is within the plan's bound plus n/2 units.
        let rows = self.pq.get_mut(base..).unwrap_or(&mut []);
        let filled = each_monomial(table, |slot, m, c| {
            if let Some((i, k)) = p.row(slot, m) {
                let v = rows.get_mut(HC * i + k)?;
                *v = v.saturating_add(to_q(c * f64::from(1u32 << k), p.q[slot]));
            }
            Some(())
        });
        if filled.is_none() {
            self.pf.truncate(base);
            self.pq.truncate(base);
            self.pidx.truncate(base);
            self.hr.clear();
            return;
        }
        self.hr.base = base as u16;
        let h = &mut self.hr;
        for s in 0..SLOTS {
            h.init[s] = (to_q(p.c0[s], p.q[s]) as i64) << 30;
            if s < 3 {
                h.shift[s] = (p.q[s] + 14) as u32;
                h.init[s] += 1i64 << (p.q[s] + 13);
            }
        }
        for (j, (f, pf)) in h.fac.iter_mut().zip(&p.fac[..p.nf]).enumerate() {
            *f = HFac {
                output: pf.0,
                src: pf.1,
                k: pf.2,
                shift: (p.q[3 + j] - 16) as u32,
            };
        }
        h.nf = p.nf as u8;
        h.steps = p.steps as u8;
        h.n = p.n as u8;
    }

    /// The block and the thermal/Abbe terms by rows, Q16 nm per output
    /// (`pos` held inside the travel). Out of line, so that the general
    /// path keeps its registers (inlined, the other fixed-point benches
    /// took 4–8 instructions more).
    #[inline(never)]
    pub(super) fn horner_fixed(
        &self,
        pos: &[i32; 3],
        inp: &Inputs,
        flags: &mut super::Flags,
    ) -> [i64; 3] {
        let h = &self.hr;
        let u: [i32; 3] =
            core::array::from_fn(|a| self.u_scale[a].apply(pos[a].wrapping_sub(self.centre_nm[a])));
        // u/2 in Q32 (2u in Q30; +1 saturates to 2^31 − 1, 2^-31 off).
        let uh = [
            u[0].saturating_add(u[0]),
            u[1].saturating_add(u[1]),
            u[2].saturating_add(u[2]),
            0,
        ];
        let w = [
            u[0],
            u[1],
            u[2],
            mul_q30(u[0], u[1]),
            mul_q30(u[0], u[2]),
            mul_q30(u[1], u[2]),
            0,
            0,
        ];
        let rows = self.pq.get(h.base as usize..).unwrap_or(&[]).as_chunks().0;
        let s = match h.steps {
            4 => h.sums::<4>(rows, &uh, &w),
            3 => h.sums::<3>(rows, &uh, &w),
            _ => h.sums::<2>(rows, &uh, &w),
        };
        let mut out: [i64; 3] = core::array::from_fn(|o| s[o] >> (h.shift[o] & 63));
        if h.nf > 0 {
            let (temp, tool) = self.hold_aux(inp, flags);
            for (j, f) in h.fac[..(h.nf as usize).min(HF_CAP)].iter().enumerate() {
                // Held temperatures and T_ref are within ±200 °C: i32.
                let v = if f.src < 4 {
                    temp[f.src as usize & 3].wrapping_sub(f.k)
                } else {
                    tool
                };
                // |sum| < 2^61: rounded to Q(q) it fits i32.
                let poly = rshr(s[3 + j], 30) as i32;
                let val = rshr_var(poly as i64 * v as i64, f.shift);
                let o = (f.output as usize).min(2);
                out[o] = out[o].saturating_add(val);
            }
        }
        out
    }
}

impl HornerQ {
    /// Every sum: its start plus its rows, each `S` Horner steps (the
    /// coefficients above S are 0) times its weight — exact i64 products.
    #[inline(always)]
    fn sums<const S: usize>(
        &self,
        rows: &[[i32; HC]],
        uh: &[i32; 4],
        w: &[i32; 8],
    ) -> [i64; SLOTS] {
        // One pass over the rows (sorted by sum): the running sum stays in
        // registers and is stored when the next row starts another sum.
        let mut s = self.init;
        let n = (self.n as usize).min(HR_CAP);
        let mut acc = s[(self.ix[0][2] as usize).min(SLOTS - 1)];
        for (r, ix) in rows.iter().zip(&self.ix[..n]) {
            let ua = uh[ix[0] as usize & 3] as i64;
            let mut x = r[S];
            for k in (0..S).rev() {
                x = ((x as i64 * ua) >> 32) as i32 + r[k];
            }
            acc += x as i64 * w[ix[1] as usize & 7] as i64;
            if ix[3] != 0xFF {
                s[(ix[2] as usize).min(SLOTS - 1)] = acc;
                acc = s[(ix[3] as usize).min(SLOTS - 1)];
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Inputs, Model};
    use super::*;
    use crate::spec::{InputsF64, TableSpec};

    /// The engine's rigid21:4 export takes the path (21 rows, its two Abbe
    /// terms, 3 Horner steps) and stays within 1 nm of the f64 reference
    /// and of the monomial-vector path it replaces, inside the envelope
    /// (travel corners, where |u| = 1, among the inputs) and held beyond
    /// it, with the same flags. Fails if a row, a scale or a factor were
    /// wrong (e.g. the Abbe terms dropped: ≈ 7 µm at a 150 mm tool).
    #[test]
    fn rigid21_rows_match_the_reference_and_the_vector_path() {
        let bytes = include_bytes!("../../../tests/golden/rigid21.bin");
        let table = crate::parse(bytes).unwrap();
        let m = Model::load(&table).unwrap();
        assert_eq!((m.hr.n, m.hr.nf, m.hr.steps), (21, 2, 3));
        assert_eq!(m.hr.end, [6, 11, 15, 18, 21, 21, 21]);
        let mut vector = m.clone();
        vector.hr = HornerQ::EMPTY;
        let spec = TableSpec::from_table(&table);
        let env = *m.envelope();
        let mut rng = trueaxis_test_support::XorShift64(0x2626_7e11_a5b1_0c3du64);
        let (mut worst_ref, mut worst_vec, mut held) = (0.0f64, 0i64, 0);
        for k in 0..20_000u64 {
            let pos_nm = core::array::from_fn(|a| {
                let (lo, hi) = (env.travel_min_nm[a] as i64, env.travel_max_nm[a] as i64);
                (match (k + a as u64) % 7 {
                    0 => lo,
                    1 => hi,
                    2 => rng.range(hi, hi + 1_000_000),
                    _ => rng.range(lo, hi),
                }) as i32
            });
            let tool_nm = match k % 5 {
                0 => env.tool_max_nm,
                1 => rng.range(env.tool_max_nm as i64, i32::MAX as i64) as i32,
                _ => rng.range(env.tool_min_nm as i64, env.tool_max_nm as i64) as i32,
            };
            let inp = Inputs {
                pos_nm,
                tool_nm,
                ..Inputs::default()
            };
            let (a, b) = (m.eval_fixed(&inp), vector.eval_fixed(&inp));
            assert_eq!(a.flags, b.flags, "{inp:?}");
            held += !a.flags.is_empty() as u32;
            let h = Inputs {
                pos_nm: core::array::from_fn(|a| {
                    pos_nm[a].clamp(env.travel_min_nm[a], env.travel_max_nm[a])
                }),
                tool_nm: tool_nm.clamp(env.tool_min_nm, env.tool_max_nm),
                ..inp
            };
            let r = spec.eval_f64(&InputsF64::from(&h));
            for o in 0..3 {
                worst_ref = worst_ref.max((a.corr_nm[o] as f64 - r[o]).abs());
                worst_vec = worst_vec.max((a.corr_nm[o] as i64 - b.corr_nm[o] as i64).abs());
            }
        }
        assert!(
            worst_ref <= 1.0 && worst_vec <= 1,
            "{worst_ref} {worst_vec}"
        );
        assert!(held > 5_000, "{held}");
    }

    /// The split of a monomial into (axis, power − 1, weight): every
    /// separable monomial of degree ≤ 5 is w·u_a^k with the same
    /// exponents, the others (three axes, two above degree 1) are not.
    #[test]
    fn split_keeps_the_exponents() {
        let mut separable = 0;
        for m in super::super::MONO_EXPS.iter().copied().skip(1) {
            let Some((a, k, wi)) = split(m) else {
                let nz = m.iter().filter(|&&e| e > 0).count();
                assert!(
                    nz == 3 || m.iter().filter(|&&e| e > 1).count() == 2,
                    "{m:?}"
                );
                continue;
            };
            separable += 1;
            let mut e = [0u8; 3];
            e[a] += k as u8;
            match wi {
                0..=2 => e[wi] += 1,
                3 => (e[0], e[1]) = (e[0] + 1, e[1] + 1),
                4 => (e[0], e[2]) = (e[0] + 1, e[2] + 1),
                _ => (e[1], e[2]) = (e[1] + 1, e[2] + 1),
            }
            assert_eq!(e, m);
        }
        // 3 axes × 5 powers + 6 ordered pairs × 4 powers − the 3 xy/xz/yz counted twice.
        assert_eq!(separable, 15 + 24 - 3);
    }
}
