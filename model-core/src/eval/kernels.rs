//! The kernels both evaluation paths and the loader share: the graded
//! monomial list (built at compile time), the load-time fixed-point helpers
//! (choosing a coefficient set's binary scale, the constant-shift
//! multipliers), the monomial vectors in f32 and Q30, the position hold, the
//! integer phase of a periodic term, the source of an MLP input and the cell
//! of a grid. Everything here is `pub(super)`: the module's public surface is
//! [`MONO_EXPS`] and [`mono_index`], re-exported by `eval`.

use super::{Flags, GridAxis, MAX_TEMPS};
use crate::limits::MAX_MONOMIALS;
use crate::math::ONE_Q30;

// ---------------------------------------------------------------------------
// Graded monomial ordering, built at compile time: 1; x, y, z; x², xy, xz,
// y², yz, z²; … up to degree 5. Every monomial i ≥ 1 is its parent times one
// normalised coordinate, so the whole vector costs one multiply per entry.

const fn build_monos() -> (
    [[u8; 3]; MAX_MONOMIALS],
    [u8; MAX_MONOMIALS],
    [u8; MAX_MONOMIALS],
) {
    let mut exps = [[0u8; 3]; MAX_MONOMIALS];
    let mut parent = [0u8; MAX_MONOMIALS];
    let mut axis = [0u8; MAX_MONOMIALS];
    let mut n = 0;
    let mut deg = 0u8;
    while deg <= 5 {
        let mut a = deg as i32;
        while a >= 0 {
            let mut b = deg as i32 - a;
            while b >= 0 {
                let c = deg as i32 - a - b;
                exps[n] = [a as u8, b as u8, c as u8];
                if n > 0 {
                    let ax = if a > 0 {
                        0
                    } else if b > 0 {
                        1
                    } else {
                        2
                    };
                    let mut p = exps[n];
                    p[ax] -= 1;
                    let mut j = 0;
                    while j < n {
                        if exps[j][0] == p[0] && exps[j][1] == p[1] && exps[j][2] == p[2] {
                            parent[n] = j as u8;
                        }
                        j += 1;
                    }
                    axis[n] = ax as u8;
                }
                n += 1;
                b -= 1;
            }
            a -= 1;
        }
        deg += 1;
    }
    (exps, parent, axis)
}

const MONOS: (
    [[u8; 3]; MAX_MONOMIALS],
    [u8; MAX_MONOMIALS],
    [u8; MAX_MONOMIALS],
) = build_monos();
/// Exponents of the graded monomial list.
pub const MONO_EXPS: [[u8; 3]; MAX_MONOMIALS] = MONOS.0;
pub(super) const MONO_PARENT: [u8; MAX_MONOMIALS] = MONOS.1;
pub(super) const MONO_AXIS: [u8; MAX_MONOMIALS] = MONOS.2;
/// Number of monomials of total degree ≤ d, for d = 0..=5.
pub(super) const MONOS_UP_TO: [usize; 6] = [1, 4, 10, 20, 35, 56];

/// The graded monomials of degree ≤ 3 in the order the f32 Horner scheme
/// reads their coefficients (`ModelCap::poly3_f32`):
/// x²(c₄ + c₁₀x + c₁₁y + c₁₂z), xy(c₅ + c₁₃y + c₁₄z), xz(c₆ + c₁₅z), then
/// x(c₁ + …); y²(c₇ + c₁₆y + c₁₇z), yz(c₈ + c₁₈z), y(c₂ + …);
/// z²(c₉ + c₁₉z), z(c₃ + …); and c₀ last.
pub(super) const HORNER20: [u8; 20] = [
    4, 10, 11, 12, 5, 13, 14, 6, 15, 1, 7, 16, 17, 8, 18, 2, 9, 19, 3, 0,
];

/// Index of a monomial in the graded list.
pub fn mono_index(m: [u8; 3]) -> Option<usize> {
    MONO_EXPS.iter().position(|&e| e == m)
}

// ---------------------------------------------------------------------------
// Load-time helpers (f64 arithmetic is fine here: building may be slow, and
// IEEE basic operations give the same bits on the host and on the MCU's
// soft-float, so a model loaded on either side is identical).

pub(super) fn pow2(q: i32) -> f64 {
    f64::from_bits(((1023 + q) as u64) << 52)
}

pub(super) fn round_i64(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        (x - 0.5) as i64
    }
}

const Q_MAX: i32 = 48;
const SUM_LIMIT: f64 = 2_147_483_647.0;

/// Largest q ≤ Q_MAX with sum_abs · 2^q ≤ 2^31 − 1, or None below `q_min`.
pub(super) fn choose_q(sum_abs: f64, q_min: i32) -> Option<i32> {
    let mut q = Q_MAX;
    while sum_abs * pow2(q) > SUM_LIMIT {
        q -= 1;
        if q < q_min {
            return None;
        }
    }
    Some(q)
}

pub(super) fn to_q(c: f64, q: i32) -> i32 {
    round_i64(c * pow2(q)).clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

/// x ↦ round(x · factor · 2^frac) as (x·k + 2^31) >> 32: a constant shift,
/// so on the M4 it is one SMULL/MLA pair and an add — no variable 64-bit
/// shift. Valid while |x · k| < 2^63 (callers keep |x| ≤ 1/factor).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Mul32 {
    pub(super) k: i64,
}

impl Mul32 {
    pub(super) fn new(factor: f64, frac: i32) -> Mul32 {
        Mul32 {
            k: round_i64(factor * pow2(frac + 32)),
        }
    }
    #[inline(always)]
    pub(super) fn apply(self, x: i32) -> i32 {
        ((x as i64 * self.k + (1 << 31)) >> 32) as i32
    }
}

/// The phase increment per nm as a fraction of a turn (2^32 = one turn),
/// split into integer and fractional parts so the phase of r nm is
/// `r·int + hi32(r·frac)` — a MUL and a UMULL, exact to 1 LSB.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Turns {
    pub(super) int: u32,
    pub(super) frac: u32,
}

impl Turns {
    pub(super) fn new(period_nm: i32) -> Turns {
        let p = period_nm.max(1) as u64;
        let int = (1u64 << 32) / p;
        let rem = (1u64 << 32) % p;
        // frac = round(rem / p · 2^32), computed exactly in u128.
        let frac = (((rem as u128) << 32) + (p as u128 / 2)) / p as u128;
        Turns {
            int: int as u32,
            frac: frac.min(u32::MAX as u128) as u32,
        }
    }
}

/// Rounding arithmetic shift right.
#[inline(always)]
pub(super) fn rshr(x: i64, s: u32) -> i64 {
    if s == 0 {
        x
    } else {
        (x + (1i64 << (s - 1))) >> s
    }
}

/// [`rshr`] as ((x >> (s − 1)) + 1) >> 1: the same integer
/// (floor((floor(x / 2^(s−1)) + 1) / 2) = floor((x + 2^(s−1)) / 2^s)), with
/// one variable 64-bit shift instead of a variable shift and a variable
/// power of two (test `rshr_var_is_rshr`). Used where the shift is a
/// term's (the block's rounding term is made at load instead).
#[inline(always)]
pub(super) fn rshr_var(x: i64, s: u32) -> i64 {
    if s == 0 {
        x
    } else {
        ((x >> (s - 1)) + 1) >> 1
    }
}

/// `v` held inside [lo, hi] (lo ≤ hi is validated), raising `f` when it was outside.
#[inline(always)]
pub(super) fn hold(v: i32, lo: i32, hi: i32, flags: &mut Flags, f: Flags) -> i32 {
    if v < lo {
        flags.insert(f);
        lo
    } else if v > hi {
        flags.insert(f);
        hi
    } else {
        v
    }
}

/// The 20 graded monomials of degree ≤ 3 (order of [`MONO_EXPS`]), f32.
#[inline(always)]
pub(super) fn mono20_f32(u: [f32; 3]) -> [f32; 20] {
    let [x, y, z] = u;
    let (x2, y2, z2) = (x * x, y * y, z * z);
    let xy = x * y;
    [
        1.0,
        x,
        y,
        z,
        x2,
        xy,
        x * z,
        y2,
        y * z,
        z2,
        x2 * x,
        x2 * y,
        x2 * z,
        x * y2,
        xy * z,
        x * z2,
        y2 * y,
        y2 * z,
        y * z2,
        z2 * z,
    ]
}

/// All 56 graded monomials (degree ≤ 5), f32.
pub(super) fn mono56_f32(u: [f32; 3]) -> [f32; MAX_MONOMIALS] {
    let mut mv = [0.0f32; MAX_MONOMIALS];
    mv[0] = 1.0;
    for i in 1..MAX_MONOMIALS {
        mv[i] = mv[MONO_PARENT[i] as usize] * u[MONO_AXIS[i] as usize];
    }
    mv
}

/// Q30 × Q30 → Q30, truncated toward −∞ (SMULL and a funnel shift; the
/// 2^-30 bias per product is far below the 1 nm bound and keeps the
/// monomials at 3 instructions each on the M4).
#[inline(always)]
pub(super) fn mul_q30(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64) >> 30) as i32
}

/// How [`mono20_q30`] makes each monomial i ≥ 4: (parent, axis), the
/// monomial being `mul_q30(mv[parent], u[axis])` (entries 0…3 are 1, x, y,
/// z themselves; test `mono20_from_is_mono20_q30`).
pub(super) const MONO20_FROM: [(u8, u8); 20] = [
    (0, 0),
    (0, 0),
    (0, 1),
    (0, 2),
    (1, 0),
    (1, 1),
    (1, 2),
    (2, 1),
    (2, 2),
    (3, 2),
    (4, 0),
    (4, 1),
    (4, 2),
    (5, 1),
    (5, 2),
    (6, 2),
    (7, 1),
    (7, 2),
    (8, 2),
    (9, 2),
];

/// The 20 graded monomials of degree ≤ 3, Q30 (same rounding as [`mono56_q30`]).
#[inline(always)]
pub(super) fn mono20_q30(u: [i32; 3]) -> [i32; 20] {
    let [x, y, z] = u;
    let (x2, y2, z2) = (mul_q30(x, x), mul_q30(y, y), mul_q30(z, z));
    let (xy, xz, yz) = (mul_q30(x, y), mul_q30(x, z), mul_q30(y, z));
    [
        ONE_Q30,
        x,
        y,
        z,
        x2,
        xy,
        xz,
        y2,
        yz,
        z2,
        mul_q30(x2, x),
        mul_q30(x2, y),
        mul_q30(x2, z),
        mul_q30(xy, y),
        mul_q30(xy, z),
        mul_q30(xz, z),
        mul_q30(y2, y),
        mul_q30(y2, z),
        mul_q30(yz, z),
        mul_q30(z2, z),
    ]
}

/// All 56 graded monomials (degree ≤ 5), Q30: each its parent times one
/// coordinate, as the loop over [`MONO_PARENT`] and [`MONO_AXIS`] would
/// make them (the same integers), but straight-line with the indices
/// constant — one SMULL and a funnel shift per monomial, no table loads or
/// loop (issue 26: the monomial vector of a rigid21 table, degree 5, was
/// the largest part of its tick).
#[inline(always)]
pub(super) fn mono56_q30(u: [i32; 3]) -> [i32; MAX_MONOMIALS] {
    let mut mv = [0i32; MAX_MONOMIALS];
    mv[0] = ONE_Q30;
    mv[1] = u[0];
    mv[2] = u[1];
    mv[3] = u[2];
    macro_rules! products {
        ($($i:literal)*) => {
            $(mv[$i] = mul_q30(mv[MONO_PARENT[$i] as usize], u[MONO_AXIS[$i] as usize]);)*
        };
    }
    products!(4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29
        30 31 32 33 34 35 36 37 38 39 40 41 42 43 44 45 46 47 48 49 50 51 52 53 54 55);
    mv
}

/// Phase of `pos` along a period as a fraction of a turn (2^32 = one turn),
/// computed in integers so it stays exact at any position.
#[inline(always)]
pub(super) fn phase_turns(pos_nm: i32, period_nm: i32, turns: Turns) -> u32 {
    let r = pos_nm.rem_euclid(period_nm) as u32;
    r.wrapping_mul(turns.int)
        .wrapping_add(((r as u64 * turns.frac as u64) >> 32) as u32)
}

#[inline(always)]
pub(super) fn mlp_source(src: u8, pos: &[i32; 3], temp: &[i32; MAX_TEMPS]) -> i32 {
    match src {
        0..=2 => pos[src as usize],
        s => temp[(s as usize - 3) & 3],
    }
}

/// Cell index and offset (nm) of `p` on a grid axis, held at the grid's edges.
#[inline(always)]
pub(super) fn grid_cell(ax: &GridAxis, p: i32) -> (usize, i32) {
    if ax.nodes < 2 {
        return (0, 0);
    }
    // The validated grid ends at or below i32::MAX, so the span and the offset
    // fit in u32 and the division is the hardware's 32-bit UDIV.
    let span = (ax.nodes as i64 - 1) * ax.step_nm as i64;
    let d = (p as i64 - ax.origin_nm as i64).clamp(0, span) as u32;
    let step = ax.step_nm as u32;
    let i = d / step;
    if i as usize >= ax.nodes as usize - 1 {
        (ax.nodes as usize - 2, ax.step_nm)
    } else {
        (i as usize, (d - i * step) as i32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_order_and_parents() {
        assert_eq!(
            &MONO_EXPS[..4],
            &[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
        );
        for i in 1..MAX_MONOMIALS {
            let mut p = MONO_EXPS[i];
            p[MONO_AXIS[i] as usize] -= 1;
            assert_eq!(MONO_EXPS[MONO_PARENT[i] as usize], p);
            assert!((MONO_PARENT[i] as usize) < i);
        }
        assert_eq!(MONO_EXPS[55], [0, 0, 5]);
    }

    /// `rshr_var` against `rshr` at the ends of the i64 range and the
    /// shifts 0 … 63, and on seeded values.
    #[test]
    fn rshr_var_is_rshr() {
        let mut rng = trueaxis_test_support::XorShift64(0x9b05_688c_2b3e_6c1fu64);
        let ends = [
            0i64,
            1,
            -1,
            2,
            -2,
            i64::MAX / 2,
            i64::MIN / 2,
            i64::MIN,
            i64::MAX - (1 << 62),
        ];
        for s in 0..64u32 {
            for &x in &ends {
                for x in [x, x.wrapping_add(1), x.wrapping_sub(1)] {
                    // rshr's own sum must not overflow (its contract).
                    if s > 0 && x.checked_add(1i64 << (s - 1)).is_none() {
                        continue;
                    }
                    assert_eq!(rshr_var(x, s), rshr(x, s), "{x} >> {s}");
                }
            }
            for _ in 0..2000 {
                let x = (rng.next_u64() as i64) >> rng.range(0, 63);
                if s > 0 && x.checked_add(1i64 << (s - 1)).is_none() {
                    continue;
                }
                assert_eq!(rshr_var(x, s), rshr(x, s), "{x} >> {s}");
            }
        }
    }

    /// The straight-line `mono56_q30` gives the integers of the loop over
    /// the parent table it unrolls (every entry, at the Q30 limits too).
    #[test]
    fn mono56_q30_is_the_parent_loop() {
        let mut rng = trueaxis_test_support::XorShift64(0x9b05_688c_2b3e_6c1fu64);
        let lim = (1i64 << 30) + 1;
        for k in 0..20_000 {
            let u: [i32; 3] = core::array::from_fn(|a| match (k + a) % 5 {
                0 => lim as i32,
                1 => -lim as i32,
                _ => rng.range(-lim, lim + 1) as i32,
            });
            let mut want = [0i32; MAX_MONOMIALS];
            want[0] = ONE_Q30;
            for i in 1..MAX_MONOMIALS {
                want[i] = mul_q30(want[MONO_PARENT[i] as usize], u[MONO_AXIS[i] as usize]);
            }
            assert_eq!(mono56_q30(u), want, "{u:?}");
        }
    }

    /// Every product of `mono20_q30` is the one `MONO20_FROM` names, bit
    /// for bit (the few-monomial fixed path rebuilds them from it).
    #[test]
    fn mono20_from_is_mono20_q30() {
        let mut rng = trueaxis_test_support::XorShift64(0x510e_527f_ade6_82d1u64);
        let lim = (1i64 << 30) + 1;
        for k in 0..20_000 {
            let u: [i32; 3] = core::array::from_fn(|a| match (k + a) % 5 {
                0 => lim as i32,
                1 => -lim as i32,
                _ => rng.range(-lim, lim + 1) as i32,
            });
            let mv = mono20_q30(u);
            for i in 4..20 {
                let (p, ax) = MONO20_FROM[i];
                assert_eq!(mv[i], mul_q30(mv[p as usize], u[ax as usize]), "{u:?} {i}");
                // The parent is one degree lower along that axis.
                let mut e = MONO_EXPS[i];
                e[ax as usize] -= 1;
                assert_eq!(MONO_EXPS[p as usize], e);
            }
        }
    }

    #[test]
    fn straight_line_monomials_match_the_table() {
        for (k, u) in [[0.3f64, -0.7, 0.99], [-1.0, 1.0, -1.0], [0.0, 0.5, -0.25]]
            .iter()
            .enumerate()
        {
            let uf = u.map(|v| v as f32);
            let uq = u.map(|v| (v * (1u64 << 30) as f64) as i32);
            let (a, b) = (mono20_f32(uf), mono56_f32(uf));
            let (c, d) = (mono20_q30(uq), mono56_q30(uq));
            for i in 0..20 {
                let exact: f64 = (0..3)
                    .map(|ax| u[ax].powi(MONO_EXPS[i][ax] as i32))
                    .product();
                assert!(
                    (a[i] as f64 - exact).abs() < 1e-6 && (b[i] as f64 - exact).abs() < 1e-6,
                    "{k} {i}"
                );
                assert!((c[i] - d[i]).abs() <= 2, "{k} {i}");
                assert!(
                    (c[i] as f64 / (1u64 << 30) as f64 - exact).abs() < 4e-9,
                    "{k} {i}"
                );
            }
        }
    }
}
