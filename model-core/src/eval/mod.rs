//! Evaluation of a prepared model: the RAM-resident [`Model`] the firmware
//! runs every cycle, in f32 ([`ModelCap::eval_f32`]) and in integer-only fixed
//! point ([`ModelCap::eval_fixed`], bit-exact between the host and
//! thumbv7em because it is the same integer code), plus the per-axis
//! reversal tracker [`DirTracker`].
//!
//! Why a prepared model: decoding little-endian f64 fields with bounds checks
//! per coefficient would blow the MCU budget (~300 instructions for a 3-output
//! cubic19 update), so [`ModelCap::load`] converts a validated table once into
//! fixed-size arrays: a dense coefficient block over the graded monomial list
//! (so the monomials are computed once per update and shared by the three
//! outputs and by every thermal/Abbe polynomial), per-term parameters in
//! parameter pools, and grid values in Q8 nm. Loading also does the
//! fixed-point range analysis: every coefficient set gets its own binary
//! scale q chosen so that Σ|c|·2^q < 2^31, which guarantees that the i64
//! accumulations below cannot overflow for any input inside the envelope.
//!
//! Fixed-point formats: positions nm (i32); normalised positions and
//! monomials Q30 (|u| ≤ 1 is guaranteed by the table validation); sin/cos,
//! tanh and the reversal state Q30; corrections are accumulated in i64 Q16 nm
//! and rounded to nm at the end.
//!
//! The module is split along its concerns: `load` turns a
//! validated table into a prepared model (one function per table section),
//! `f32` and `fixed` are the two evaluation paths, and `kernels` holds what
//! both share (the graded monomial list, the fixed-point helpers, the
//! monomial vectors, grid cells and MLP input sources).

// Index loops over parallel fixed arrays mirror the equations (and keep the
// hot loops' shape obvious in the disassembly); iterator chains would not help.
#![allow(clippy::needless_range_loop)]

use core::num::NonZeroU32;

use heapless::Vec;

use crate::limits::{MAX_HIDDEN_LAYERS, MAX_MONOMIALS};
use crate::math::ONE_Q30;
use crate::table::Envelope;

pub use crate::limits::{MAX_MLP_INPUTS_TOTAL, MAX_TEMPS, MAX_TERMS};
use kernels::{hold, Mul32, Turns};
pub use kernels::{mono_index, MONO_EXPS};

mod f32;
mod fixed;
mod horner;
mod kernels;
mod load;

/// What the firmware feeds the model each cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Inputs {
    /// x, y, z machine position, nm (encoder counts × scale).
    pub pos_nm: [i32; 3],
    /// Reversal state per axis, Q1.30: −2^30 = fully after a negative move,
    /// +2^30 fully after a positive one, 0 unknown / mid-transition.
    pub rev_q30: [i32; 3],
    /// Temperature channels, m°C, indexed as the table's channel list.
    pub temp_mc: [i32; MAX_TEMPS],
    /// Abbe arm (tool length / probe offset), nm.
    pub tool_nm: i32,
}

/// Flags raised by one evaluation (a small hand-rolled bitset).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Flags(u16);

impl Flags {
    /// x was outside the travel and was held at the edge.
    pub const OUT_OF_TRAVEL_X: Flags = Flags(1 << 0);
    /// y was outside the travel and was held at the edge.
    pub const OUT_OF_TRAVEL_Y: Flags = Flags(1 << 1);
    /// z was outside the travel and was held at the edge.
    pub const OUT_OF_TRAVEL_Z: Flags = Flags(1 << 2);
    /// A correction was limited to the envelope's max |correction|.
    pub const CLAMPED: Flags = Flags(1 << 3);
    /// A temperature was outside its channel's range and was held at the edge.
    pub const TEMP_OUT_OF_RANGE: Flags = Flags(1 << 4);
    /// The f32 evaluation produced NaN/inf; that output was forced to 0.
    pub const NOT_FINITE: Flags = Flags(1 << 5);
    /// The tool arm was outside its range and was held at the edge.
    pub const TOOL_OUT_OF_RANGE: Flags = Flags(1 << 6);

    /// No flag.
    pub const fn empty() -> Flags {
        Flags(0)
    }
    /// The raw bits.
    pub const fn bits(self) -> u16 {
        self.0
    }
    /// From raw bits (unknown bits kept).
    pub const fn from_bits(bits: u16) -> Flags {
        Flags(bits)
    }
    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }
    /// Whether no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Set the bits of `other`.
    pub fn insert(&mut self, other: Flags) {
        self.0 |= other.0;
    }
    /// The out-of-travel flag of `axis`.
    pub const fn out_of_travel(axis: usize) -> Flags {
        Flags(1 << (axis & 3))
    }
    /// Name of each bit, bit 0 first (`docs/cli.md`, `trueaxis status`).
    pub const NAMES: [&'static str; 7] = [
        "out_of_travel_x",
        "out_of_travel_y",
        "out_of_travel_z",
        "clamped",
        "temp_out_of_range",
        "not_finite",
        "tool_out_of_range",
    ];
    /// The names of the set bits, bit 0 first (bits without a name are
    /// left out; compare with [`Flags::bits`] to see them).
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Flags::NAMES
            .into_iter()
            .enumerate()
            .filter(move |(i, _)| self.0 & (1 << i) != 0)
            .map(|(_, n)| n)
    }
}

impl core::ops::BitOr for Flags {
    type Output = Flags;
    fn bitor(self, rhs: Flags) -> Flags {
        Flags(self.0 | rhs.0)
    }
}

/// The result of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Outputs {
    /// Corrections for ex, ey, ez, nm (0 where the table has no such output).
    pub corr_nm: [i32; 3],
    /// What happened on the way.
    pub flags: Flags,
}

/// Reversal state of one axis, integer-only.
///
/// The state moves linearly from −1 to +1 (Q30) over `transition_nm` of
/// travel in the positive direction (and back over the same distance in the
/// negative one), so a reversal term's correction ramps instead of stepping.
/// The first update only records the position (state 0 = unknown).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DirTracker {
    last_pos_nm: i32,
    rev_q30: i32,
    started: bool,
}

impl DirTracker {
    /// A tracker in the unknown state.
    pub const fn new() -> Self {
        DirTracker {
            last_pos_nm: 0,
            rev_q30: 0,
            started: false,
        }
    }
    /// The current state, Q30.
    pub fn rev_q30(&self) -> i32 {
        self.rev_q30
    }
    /// Feed the new position; returns the reversal state in Q30.
    /// `transition_nm` ≤ 0 means an immediate switch.
    pub fn update(&mut self, pos_nm: i32, transition_nm: i32) -> i32 {
        self.update_with(pos_nm, &Transition::new(transition_nm))
    }

    /// [`DirTracker::update`] with the transition's constants made once
    /// ([`Transition::new`], e.g. when a table is activated) instead of on
    /// every update: the same states, without the per-update division of
    /// 2^31 by the transition. A move that continues towards the end the
    /// state already holds (±1) returns at once — the clamp would give the
    /// same state — so steady motion in one direction costs no division.
    #[inline]
    pub fn update_with(&mut self, pos_nm: i32, tr: &Transition) -> i32 {
        if !self.started {
            self.started = true;
            self.last_pos_nm = pos_nm;
            return self.rev_q30;
        }
        // The difference in i32, with the same results as the i64 one: a
        // saturated difference still has the right sign and clamps to the
        // same ±transition.
        let delta = pos_nm.saturating_sub(self.last_pos_nm);
        self.last_pos_nm = pos_nm;
        let end = if delta > 0 { ONE_Q30 } else { -ONE_Q30 };
        if delta == 0 || self.rev_q30 == end {
            return self.rev_q30;
        }
        let next = if tr.t <= 0 {
            end
        } else {
            // A full swing (2.0 = 2^31 in Q30) per transition_nm.
            // (t > 0 here: max then min is the clamp, without its
            // bounds assertion.)
            let d = delta.max(-tr.t).min(tr.t);
            let next = self.rev_q30 as i64 + tr.swing(d as i64);
            next.clamp(-ONE_Q30 as i64, ONE_Q30 as i64) as i32
        };
        self.rev_q30 = next.clamp(-ONE_Q30, ONE_Q30);
        self.rev_q30
    }
}

/// A reversal transition length with the constants of its swing step
/// (2^31 = k·t + r, r < t) made once, for [`DirTracker::update_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Transition {
    /// The length, nm (≤ 0: an immediate switch).
    t: i32,
    k: u32,
    r: u32,
}

impl Transition {
    /// The constants of `transition_nm` (≤ 0: switch at once).
    pub const fn new(transition_nm: i32) -> Self {
        if transition_nm <= 0 {
            return Transition {
                t: transition_nm,
                k: 0,
                r: 0,
            };
        }
        let t = transition_nm as u32;
        let k = (1u32 << 31) / t;
        Transition {
            t: transition_nm,
            k,
            r: (1u32 << 31) - k * t,
        }
    }

    /// The length, nm.
    pub const fn nm(&self) -> i32 {
        self.t
    }

    /// d · 2^31 / t truncated toward zero, for 0 < t and |d| ≤ t: the
    /// reversal state's change. Exactly the i64 division it replaces, but
    /// without it in the common case (an i64 division is a library call of
    /// ~60–100 instructions on the M4, once per axis per tick): with
    /// 2^31 = K·t + R (R < t, made in [`Transition::new`]), |d|·2^31 / t =
    /// |d|·K + |d|·R / t, and |d|·R fits u32 — one UDIV — whenever the move
    /// per tick or the transition is short; otherwise the u64 division.
    #[inline]
    fn swing(&self, d: i64) -> i64 {
        let (m, t) = (d.unsigned_abs() as u32, self.t as u32);
        // m·k ≤ t·(2^31 / t) ≤ 2^31 fits u32.
        let q = match m.checked_mul(self.r) {
            Some(mr) => (m * self.k + mr / t) as u64,
            None => ((m as u64) << 31) / t as u64,
        };
        if d < 0 {
            -(q as i64)
        } else {
            q as i64
        }
    }
}

/// [`Transition::swing`] of `transition_nm` (tests).
#[cfg(test)]
fn swing_step(d: i64, transition_nm: i32) -> i64 {
    Transition::new(transition_nm).swing(d)
}

/// Why a valid table cannot become a [`Model`] of this capacity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadError {
    /// More terms than [`MAX_TERMS`].
    TooManyTerms { count: u32 },
    /// The parameter pool (coefficients, weights) is too small.
    ParamCapacity { needed: u32, capacity: u32 },
    /// The grid value store is too small (use a larger-capacity alias such as [`LargeModel`]).
    GridCapacity { needed: u32, capacity: u32 },
    /// More MLP inputs in total than [`MAX_MLP_INPUTS_TOTAL`].
    MlpInputCapacity,
    /// A term's coefficients are too large for the fixed-point representation (Σ|c| ≥ 2^31 in its units).
    CoefficientRange { term: u32 },
    /// A grid value exceeds ±4.1 mm (the Q8 nm range with interpolation headroom).
    GridValueRange { term: u32 },
    /// An MLP's input scaling maps the envelope beyond ±7 (the fixed-point input range),
    /// or its min-max range is narrower than 1 nm / 1 m°C.
    MlpInputRange { term: u32 },
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooManyTerms { count } => {
                write!(f, "{count} terms exceed the model capacity of {MAX_TERMS}")
            }
            Self::ParamCapacity { needed, capacity } => {
                write!(f, "model needs {needed} parameters, capacity is {capacity}")
            }
            Self::GridCapacity { needed, capacity } => {
                write!(
                    f,
                    "model needs {needed} grid values, capacity is {capacity}"
                )
            }
            Self::MlpInputCapacity => write!(f, "too many MLP inputs in total"),
            Self::CoefficientRange { term } => {
                write!(f, "coefficients of term {term} too large for fixed point")
            }
            Self::GridValueRange { term } => write!(f, "grid value of term {term} exceeds ±4.1 mm"),
            Self::MlpInputRange { term } => {
                write!(
                    f,
                    "MLP term {term}: the envelope maps outside ±7 of the input scaling"
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LoadError {}

/// Parameter pool capacity of [`Model`].
pub const DEFAULT_PARAMS: usize = 1536;
/// Grid value capacity of [`Model`] (e.g. one 17×11×11 grid, or three 2-D grids).
pub const DEFAULT_GRID: usize = 2048;
/// Grid value capacity of [`LargeModel`] (three 17×11×11 grids = 6171 values).
pub const LARGE_GRID: usize = 6400;

/// The default model (about 26 KiB of RAM).
pub type Model = ModelCap<DEFAULT_PARAMS, DEFAULT_GRID>;
/// A model for full 3-axis grids on all outputs (about 43 KiB of RAM).
pub type LargeModel = ModelCap<DEFAULT_PARAMS, LARGE_GRID>;

// ---------------------------------------------------------------------------
// The prepared model.

#[derive(Clone, Copy, Debug, PartialEq)]
enum Factor {
    Temp { ch: u8, t_ref_mc: i32 },
    Tool,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct GridAxis {
    nodes: u16,
    origin_nm: i32,
    step_nm: i32,
    inv_step_f32: f32,
    t_scale: Mul32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct MlpInput {
    src: u8,
    mid: i32,
    /// The scale k in fixed point (f32: folded into the first layer's weights).
    k_q28: Mul32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Term {
    /// factor × Σ c·monomial; pool [start, start+len) holds c (nm per factor unit) and the monomial indices.
    Factored {
        output: u8,
        factor: Factor,
        start: u16,
        len: u16,
        shift: u32,
    },
    /// Σ a_k sin + b_k cos; pool holds (a, b) pairs, nm.
    Periodic {
        output: u8,
        axis: u8,
        harmonics: u8,
        period_nm: i32,
        turns: Turns,
        start: u16,
        shift: u32,
    },
    /// amplitude × rev.
    Reversal {
        output: u8,
        axis: u8,
        transition_nm: i32,
        amp_f32: f32,
        amp_q: i32,
        shift: u32,
    },
    /// MLP: inputs in `mlp_in[in_start..]`, weights in the pool from `start`.
    Mlp {
        outputs: u8,
        n_in: u8,
        n_layers: u8,
        widths: [u8; MAX_HIDDEN_LAYERS],
        n_out: u8,
        in_start: u8,
        start: u16,
        q: [u8; 3],
        /// Every unit of the fused last layer has |z| ≤ 8 for every input
        /// the hold lets through (bound set at load): its f32 activation
        /// skips the saturation test (which would never fire, |z| ≤ 8.5).
        bounded: bool,
    },
    /// Grid on up to three axes, values (Q8 nm) in `grid[start..]`.
    Grid {
        output: u8,
        axes: [GridAxis; 3],
        start: u32,
    },
}

/// A periodic term laid out for the f32 fast path (coefficients inline).
#[derive(Clone, Copy, Debug, PartialEq)]
struct PeriodicF32 {
    output: u8,
    axis: u8,
    harmonics: u8,
    /// The period, nm (> 0).
    period: NonZeroU32,
    /// A multiple of the period at or below the travel minimum (truncated to
    /// i32: the held position minus it, wrapping, is the exact u32 offset).
    base_nm: i32,
    turns: Turns,
    /// (a_k, b_k) for k = 1 … harmonics, zero beyond.
    ab: [[f32; 2]; 4],
}

/// A thermal/Abbe term of degree ≤ 1 laid out for the f32 fast path:
/// factor × (c₀ + c₁x + c₂y + c₃z), read straight from the normalised
/// position (no monomial vector in memory).
#[derive(Clone, Copy, Debug, PartialEq)]
struct FactoredF32 {
    output: u8,
    /// 0…3 temperature channel, 4 the tool arm.
    src: u8,
    /// Subtracted from the factor (t_ref for thermal, 0 for Abbe).
    offset: i32,
    /// Coefficients of 1, x, y, z (the first four graded monomials).
    c: [f32; 4],
}

/// Whether the fixed-point polynomial fast path takes a block whose
/// per-output Σ|c| (in nm, normalised monomials) are `sum_abs`: it needs
/// every block shift s = q + 14 in [16, 46] (`load`) — Σ|c| between
/// ~0.25 nm and ~0.5 m — or an output without coefficients.
/// [`crate::cost`] asks the same to pick the path's cost.
/// The binary scale q of a thermal or Abbe term's coefficients (Σ|c| ≤
/// `sum_abs`): the largest with Σ|c|·2^q < 2^31, at least 16 (`None`: the
/// loader refuses the term). Shared with `definition`'s static bound.
pub(crate) fn factored_q(sum_abs: f64) -> Option<i32> {
    kernels::choose_q(sum_abs, 16)
}

/// The binary scale q of an MLP layer whose largest row has Σ|w| + |b| =
/// `worst` (`load::mlp_term`); `None`: the loader refuses the term.
pub(crate) fn mlp_layer_q(worst: f64) -> Option<i32> {
    kernels::choose_q(worst, 0)
}

pub(crate) fn poly_fixed_takes(sum_abs: [f64; 3]) -> bool {
    sum_abs.iter().all(|&s| {
        s == 0.0 || kernels::choose_q(s, 0).is_some_and(|q| poly_fixed_shift_ok((q + 14) as u32))
    })
}

/// The few-monomial path's vector for the block monomials marked in `need`
/// (graded, degree ≤ 3): marks 1, x, y, z and every parent `mono20_q30`
/// makes a marked monomial from, and returns the number of products (the
/// marked monomials of degree ≥ 2). The loader takes the path for at most
/// `VP_STEPS` of them; [`crate::cost`] asks the same.
pub(crate) fn vp_products(need: &mut [bool; 20]) -> usize {
    need[..4].fill(true);
    // Parents come before their children: walking down closes the set.
    for i in (4..20).rev() {
        if need[i] {
            need[kernels::MONO20_FROM[i].0 as usize] = true;
        }
    }
    need[4..].iter().filter(|&&n| n).count()
}

/// Most products the few-monomial path takes (see [`vp_products`]).
pub(crate) const VP_MAX_PRODUCTS: usize = VP_STEPS;
/// Most terms its flat term loop takes.
pub(crate) const FQ_MAX_TERMS: usize = FQ_CAP;
/// Most monomials the block by monomial takes.
pub(crate) const BLK_MAX: usize = BLK_CAP;
pub(crate) use horner::plan as horner_plan;

/// See [`poly_fixed_takes`].
const fn poly_fixed_shift_ok(shift: u32) -> bool {
    shift >= 16 && shift <= 46
}

/// Which straight-line f32 kernel evaluates a table that is nothing but a
/// polynomial block (no other term).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PolyKind {
    /// Not such a table: the general path.
    None,
    /// Degree ≤ 1: c₀ + c₁x + c₂y + c₃z per output.
    Linear,
    /// Degree ≤ 3: the 20-coefficient Horner scheme.
    Cubic,
}

/// A prepared, RAM-resident model with capacity `P` parameters and `G` grid
/// values. Use the aliases [`Model`] and [`LargeModel`].
///
/// `repr(C)` with the fields the per-update fast paths read first: the
/// M4's `vldr` reaches 1 KiB from its base register and `ldr` 4 KiB, so
/// behind the parameter pools each of them would cost an extra address
/// computation.
#[derive(Clone, Debug)]
#[repr(C)]
pub struct ModelCap<const P: usize, const G: usize> {
    /// 2^(block_shift − 1): the block's rounding, made at load (the shift is
    /// ≥ 14, so no zero case), so the kernel has one variable shift, not two.
    block_round: [i64; 3],
    /// The travel per axis as (minimum, span): a position p is inside when
    /// `(p − min) as u32 ≤ span` — one subtraction and one unsigned compare
    /// per axis per update (precomputed at load, [`ModelCap::hold_pos_fast`]).
    hold_nm: [(i32, u32); 3],
    /// The window of rounded corrections that certainly need no clamp,
    /// n ∈ [−(max−1), max−1] as `(n + max − 1) as u32 < 2·max − 1`
    /// (0 when max is 0: every value takes the exact test).
    round_lim: [i32; 3],
    round_win: [u32; 3],
    /// f32 fast path of a table that is only a polynomial block
    /// ([`PolyKind`]), and its coefficients in the order the Horner scheme
    /// of [`ModelCap::poly3_f32`] reads them, per output, each divided by
    /// the half spans' powers of its monomial (the kernels read p − centre).
    poly: PolyKind,
    horner_f32: [[f32; 20]; 3],
    /// Fixed-point fast path of a polynomial-only table (`PolyKind::None`
    /// when a block scale is outside what it handles, see
    /// [`ModelCap::poly_fixed`]): the accumulators start at
    /// `poly_bias_q` (both roundings and the constant coefficient) and the
    /// result in nm is the high word shifted right by `poly_shift`.
    poly_fixed: PolyKind,
    poly_bias_q: [i64; 3],
    poly_shift: [u32; 3],
    /// The block's fixed-point coefficients of degree ≤ 3 per output, graded order
    /// (a copy of `block_q`'s: `poly_fixed` is faster reading its own rows).
    poly_q: [[i32; 20]; 3],
    centre_nm: [i32; 3],
    inv_half_f32: [f32; 3],
    env: Envelope,
    outputs: u8,
    n_channels: u8,
    u_scale: [Mul32; 3],
    /// Number of graded monomials needed (0 = no polynomial at all).
    n_monos: u8,
    block_f32: [[f32; 3]; MAX_MONOMIALS],
    /// The block's fixed-point coefficients per output (one row each, graded
    /// order): the kernels run one output at a time over its row.
    block_q: [[i32; MAX_MONOMIALS]; 3],
    block_shift: [u32; 3],
    has_block: bool,
    /// Some term reads temperatures / the tool arm (so they are held and flagged).
    reads_temp: bool,
    reads_tool: bool,
    /// Some term is a thermal/Abbe polynomial (needs the monomials).
    has_factored: bool,
    /// max |correction| per output as f32 (exact: ≤ MAX_CORR_LIMIT_NM < 2^22).
    max_corr_f32: [f32; 3],
    terms: Vec<Term, MAX_TERMS>,
    pf: Vec<f32, P>,
    pq: Vec<i32, P>,
    pidx: Vec<u8, P>,
    mlp_in: Vec<MlpInput, MAX_MLP_INPUTS_TOTAL>,
    grid: Vec<i32, G>,
    /// f32 fast path: every term is a reversal, a periodic term or a
    /// thermal/Abbe term of degree ≤ 1, laid out per kind below (no per-term
    /// dispatch, no pool slicing, no monomial vector in memory).
    flat: bool,
    /// Σ reversal amplitudes (× 2^-30) per [axis][output].
    rev_f32: [[f32; 3]; 3],
    has_rev: bool,
    per_f32: Vec<PeriodicF32, MAX_TERMS>,
    fac_f32: Vec<FactoredF32, MAX_TERMS>,
    /// The half span of the travel per axis, nm (the input scaling; read at
    /// load only, so last).
    half_nm: [i32; 3],
    /// The fixed block by monomial (`blk_n` > 0): the monomials some output
    /// of the block reads (graded indices, < `n_monos`) and their three
    /// coefficients, so each monomial is loaded once for three SMLALs and
    /// the ones no output reads are skipped (`block_gather_fixed`). 0 when
    /// the block has more than [`BLK_CAP`] such monomials (the rows of
    /// `block_q` then). Last, so the fields above keep their offsets.
    blk_n: u8,
    /// Per monomial read: its three coefficients, then its graded index
    /// (< `n_monos`), so one LDM reads all four and the three sums stay
    /// in registers (rigid21_fixed 1 443 → 1 392, BENCHMARKS.md).
    blk_q: [[i32; 4]; BLK_CAP],
    /// Fixed point with few monomials (`vp_n` > 0, see `prepare_vp`): the
    /// vector v of the monomials the block reads and their parents — 1, x,
    /// y, z, then one entry per product — built by `vp_step` (for k ≥ 4,
    /// (parent, 1 + axis): v[k] = v[parent] · v[1 + axis], the products of
    /// `mono20_q30`), and the
    /// block's three coefficients of each entry of v. Thermal/Abbe terms read only v[0..4], which are
    /// the graded monomials 0..4.
    vp_n: u8,
    vp_step: [(u8, u8); VP_CAP],
    vp_q: [[i32; 3]; VP_CAP],
    /// The terms of a few-monomial table laid out flat (`fq_n` > 0, set by
    /// `prepare_vp` when every term is a reversal or a thermal/Abbe term
    /// and there are at most [`FQ_CAP`]): no per-term dispatch on [`Term`],
    /// no pool slices, the polynomial dense over 1, x, y, z.
    fq_n: u8,
    fq: [TermQ; FQ_CAP],
    /// The fixed path of a separable table of degree ≥ 4 (`horner`: rows
    /// instead of the 56-entry monomial vector; off unless `hr.on()`).
    hr: horner::HornerQ,
}

/// A reversal or a thermal/Abbe term of degree ≤ 1 for the flat fixed path:
/// the same integers as `terms_fixed` computes for it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct TermQ {
    output: u8,
    /// 0 reversal, 1 thermal, 2 Abbe.
    kind: u8,
    /// The reversal's axis or the thermal term's channel.
    src: u8,
    shift: u32,
    /// The reversal's amplitude (Q) or the thermal term's T_ref, m°C.
    k: i32,
    /// Coefficients of 1, x, y, z (Q; the pool's, summed per monomial).
    c: [i32; 4],
}

/// Most terms the flat fixed path takes.
const FQ_CAP: usize = 8;

/// Most monomials the fixed block sums by monomial (every block of degree
/// ≤ 3 has at most 20; 28 is half of the 56 of degree ≤ 5, the most the
/// rule "at most half of the vector's" lets through — a rigid21:4 table's
/// block reads 25, docs/volumetric.md "On the board").
const BLK_CAP: usize = 28;
/// Size of the vector v of `vp_*` (1, x, y, z and up to 4 products; a
/// power of two, so an index is one AND). The kernels run over all of it
/// in straight-line code (fixed trip counts, no loop overhead).
const VP_CAP: usize = 8;
/// Most products `prepare_vp` takes.
const VP_STEPS: usize = VP_CAP - 4;

impl<const P: usize, const G: usize> ModelCap<P, G> {
    /// An empty model (no outputs: every evaluation returns zeros). `const`,
    /// so it can initialise a `static` that [`ModelCap::load_into`] fills.
    pub const fn empty() -> Self {
        ModelCap {
            env: Envelope {
                travel_min_nm: [0; 3],
                travel_max_nm: [0; 3],
                max_corr_nm: [0; 3],
                max_slew_nm_per_ms: 0,
                temp_min_mc: [0; MAX_TEMPS],
                temp_max_mc: [0; MAX_TEMPS],
                tool_min_nm: 0,
                tool_max_nm: 0,
            },
            outputs: 0,
            n_channels: 0,
            centre_nm: [0; 3],
            inv_half_f32: [0.0; 3],
            u_scale: [Mul32 { k: 0 }; 3],
            n_monos: 0,
            block_f32: [[0.0; 3]; MAX_MONOMIALS],
            block_q: [[0; MAX_MONOMIALS]; 3],
            poly_q: [[0; 20]; 3],
            block_shift: [0; 3],
            block_round: [0; 3],
            has_block: false,
            reads_temp: false,
            reads_tool: false,
            has_factored: false,
            max_corr_f32: [0.0; 3],
            hold_nm: [(0, 0); 3],
            round_lim: [0; 3],
            round_win: [0; 3],
            poly: PolyKind::None,
            horner_f32: [[0.0; 20]; 3],
            poly_fixed: PolyKind::None,
            poly_bias_q: [0; 3],
            poly_shift: [0; 3],
            terms: Vec::new(),
            pf: Vec::new(),
            pq: Vec::new(),
            pidx: Vec::new(),
            mlp_in: Vec::new(),
            grid: Vec::new(),
            flat: false,
            rev_f32: [[0.0; 3]; 3],
            has_rev: false,
            per_f32: Vec::new(),
            fac_f32: Vec::new(),
            half_nm: [0; 3],
            blk_n: 0,
            blk_q: [[0; 4]; BLK_CAP],
            vp_n: 0,
            vp_step: [(0, 0); VP_CAP],
            vp_q: [[0; 3]; VP_CAP],
            fq_n: 0,
            fq: [TermQ {
                output: 0,
                kind: 0,
                src: 0,
                shift: 0,
                k: 0,
                c: [0; 4],
            }; FQ_CAP],
            hr: horner::HornerQ::EMPTY,
        }
    }

    /// The table's envelope (travel, max |correction|, slew limit for the engine).
    pub fn envelope(&self) -> &Envelope {
        &self.env
    }

    /// Outputs present: bit 0 ex, 1 ey, 2 ez.
    pub fn outputs_mask(&self) -> u8 {
        self.outputs
    }

    /// The transition length of the reversal terms on `axis`, for the
    /// firmware's [`DirTracker`] (None if no reversal term uses that axis).
    /// All of them have this length: `parse` refuses a table where two
    /// differ (`TableError::ReversalTransitionMismatch`).
    pub fn reversal_transition_nm(&self, axis: usize) -> Option<i32> {
        self.terms.iter().find_map(|t| match *t {
            Term::Reversal {
                axis: a,
                transition_nm,
                ..
            } if a as usize == axis => Some(transition_nm),
            _ => None,
        })
    }

    /// The positions held inside the travel: the common case (every axis
    /// inside) is three subtract-and-compare pairs against the load-time
    /// (minimum, span); only a position outside takes [`ModelCap::hold_pos`],
    /// which holds it at the edge and raises its flag.
    #[inline(always)]
    fn hold_pos_fast(&self, p: [i32; 3], flags: &mut Flags) -> [i32; 3] {
        if self.inside_travel(p) {
            p
        } else {
            self.hold_pos_slow(p, flags)
        }
    }

    /// Every axis inside the travel.
    #[inline(always)]
    fn inside_travel(&self, p: [i32; 3]) -> bool {
        let inside = |a: usize| p[a].wrapping_sub(self.hold_nm[a].0) as u32 <= self.hold_nm[a].1;
        inside(0) && inside(1) && inside(2)
    }

    #[inline(never)]
    fn hold_pos_slow(&self, p: [i32; 3], flags: &mut Flags) -> [i32; 3] {
        self.hold_pos(p, flags)
    }

    /// Hold the positions inside the travel, raising the per-axis flags.
    #[inline(always)]
    fn hold_pos(&self, p: [i32; 3], flags: &mut Flags) -> [i32; 3] {
        let mut pos = p;
        for a in 0..3 {
            pos[a] = hold(
                p[a],
                self.env.travel_min_nm[a],
                self.env.travel_max_nm[a],
                flags,
                Flags::out_of_travel(a),
            );
        }
        pos
    }

    /// Hold the temperatures and the tool arm the terms read (the reversal
    /// state is clamped where it is used). Their flags are raised only when
    /// the table reads them.
    #[inline(always)]
    fn hold_aux(&self, inp: &Inputs, flags: &mut Flags) -> ([i32; MAX_TEMPS], i32) {
        let mut temp = inp.temp_mc;
        if self.reads_temp {
            for ch in 0..(self.n_channels as usize).min(MAX_TEMPS) {
                temp[ch] = hold(
                    temp[ch],
                    self.env.temp_min_mc[ch],
                    self.env.temp_max_mc[ch],
                    flags,
                    Flags::TEMP_OUT_OF_RANGE,
                );
            }
        }
        let tool = if self.reads_tool {
            hold(
                inp.tool_nm,
                self.env.tool_min_nm,
                self.env.tool_max_nm,
                flags,
                Flags::TOOL_OUT_OF_RANGE,
            )
        } else {
            inp.tool_nm
        };
        (temp, tool)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flag_names_follow_the_bits() {
        assert!(Flags::from_bits(0x7f).names().eq(Flags::NAMES));
        let f = Flags::TEMP_OUT_OF_RANGE | Flags::OUT_OF_TRAVEL_Y;
        assert!(f.names().eq(["out_of_travel_y", "temp_out_of_range"]));
        assert_eq!(Flags::from_bits(1 << 9).names().count(), 0);
    }

    #[test]
    fn swing_step_is_the_i64_division() {
        let mut rng = trueaxis_test_support::XorShift64(0x9e37_79b9_7f4a_7c15u64);
        let mut next = || rng.next_u64();
        let mut long = 0;
        for i in 0..200_000u32 {
            // Transitions from 1 nm to 2^31 − 1, moves up to the transition.
            let t = match i % 4 {
                0 => (next() % 100) as i32 + 1,
                1 => (next() % 100_000) as i32 + 1,
                _ => (next() % i32::MAX as u64) as i32 + 1,
            };
            let d = (next() % (2 * t as u64 + 1)) as i64 - t as i64;
            let d = if i % 7 == 0 { t as i64 } else { d };
            long += (d.unsigned_abs() * ((1u64 << 31) % t as u64) > u32::MAX as u64) as u32;
            assert_eq!(swing_step(d, t), d * (1i64 << 31) / t as i64, "d {d} t {t}");
        }
        assert!(long > 1000, "the u64 division was taken {long} times");
    }

    /// The tracker as it was in i64 (before the i32 version).
    fn reference_update(t: &mut (i32, i32, bool), pos_nm: i32, transition_nm: i32) -> i32 {
        let (last, rev, started) = t;
        if !*started {
            *started = true;
            *last = pos_nm;
            return *rev;
        }
        let delta = pos_nm as i64 - *last as i64;
        *last = pos_nm;
        if delta == 0 {
            return *rev;
        }
        let one = ONE_Q30 as i64;
        let next = if transition_nm <= 0 {
            if delta > 0 {
                one
            } else {
                -one
            }
        } else {
            let t = transition_nm as i64;
            let d = delta.clamp(-t, t);
            *rev as i64 + d * (1i64 << 31) / t
        };
        *rev = next.clamp(-one, one) as i32;
        *rev
    }

    #[test]
    fn dir_tracker_in_i32_is_the_i64_tracker() {
        let mut rng = trueaxis_test_support::XorShift64(0x0123_4567_89ab_cdefu64);
        let mut next = || rng.next_u64();
        let mut saturated_on = 0;
        for run in 0..400 {
            let transition = match run % 5 {
                0 => 0,
                1 => -5,
                2 => (next() % 1000) as i32 + 1,
                3 => (next() % 200_000) as i32 + 1,
                _ => (next() % i32::MAX as u64) as i32 + 1,
            };
            let (mut t, mut r) = (DirTracker::new(), (0, 0, false));
            let mut pos = (next() as i32) / 2;
            for step in 0..500 {
                // Small moves, reversals, and jumps across the whole i32 range.
                pos = match (next() % 10, step % 50) {
                    (_, 0) => next() as i32,
                    (0, _) => pos,
                    (1..=4, _) => pos.saturating_add((next() % 600) as i32),
                    _ => pos.saturating_sub((next() % 600) as i32),
                };
                // The early return of `update_with`: at ±1 and moving on
                // towards it.
                let (before, last) = (r.1, r.0);
                saturated_on +=
                    (pos != last && before == if pos > last { ONE_Q30 } else { -ONE_Q30 }) as u32;
                assert_eq!(
                    t.update(pos, transition),
                    reference_update(&mut r, pos, transition),
                    "run {run} step {step} transition {transition}"
                );
            }
        }
        assert!(saturated_on > 10_000, "{saturated_on}");
    }

    /// Sets max |correction| on every field that carries it.
    fn set_max(m: &mut Model, max: i32) {
        m.env.max_corr_nm = [max; 3];
        m.max_corr_f32 = [max as f32; 3];
        m.round_lim = [(max - 1).max(0); 3];
        m.round_win = [(2 * max - 1).max(0) as u32; 3];
    }

    /// The polynomial-only kernels (straight-line f32 Horner, fixed point
    /// with the folded roundings) against the general paths on the same
    /// model: fixed point bit for bit, f32 within 1 nm with the same flags —
    /// inside and beyond the travel, unclamped and clamped.
    #[test]
    fn polynomial_fast_paths_equal_the_general_paths() {
        let table = crate::parse(include_bytes!("../../tests/golden/cubic19.bin")).unwrap();
        let cubic = Model::load(&table).unwrap();
        assert_eq!(
            (cubic.poly, cubic.poly_fixed),
            (PolyKind::Cubic, PolyKind::Cubic)
        );
        // Its degree ≤ 1 part: the same model with the higher coefficients zeroed.
        let mut linear = cubic.clone();
        for i in 4..MAX_MONOMIALS {
            linear.block_f32[i] = [0.0; 3];
        }
        for o in 0..3 {
            linear.block_q[o][4..].fill(0);
            linear.poly_q[o][4..].fill(0);
            for (h, &i) in linear.horner_f32[o]
                .iter_mut()
                .zip(kernels::HORNER20.iter())
            {
                if i >= 4 {
                    *h = 0.0;
                }
            }
        }
        linear.poly = PolyKind::Linear;
        linear.poly_fixed = PolyKind::Linear;
        let env = *cubic.envelope();
        let mut rng = trueaxis_test_support::XorShift64(0x2545_f491_4f6c_dd1du64);
        let mut next = |lo: i64, hi: i64| rng.range(lo, hi);
        let (mut clamped, mut held) = (0, 0);
        for mut fast in [cubic, linear] {
            for max in [env.max_corr_nm[0], 2_000, 0] {
                set_max(&mut fast, max);
                let mut general = fast.clone();
                general.poly = PolyKind::None;
                general.poly_fixed = PolyKind::None;
                for _ in 0..2000 {
                    let pos_nm = core::array::from_fn(|a| {
                        let (lo, hi) = (env.travel_min_nm[a] as i64, env.travel_max_nm[a] as i64);
                        let margin = (hi - lo) / 5;
                        next(lo - margin, hi + margin) as i32
                    });
                    let inp = Inputs {
                        pos_nm,
                        ..Inputs::default()
                    };
                    let (a, b) = (fast.eval_fixed(&inp), general.eval_fixed(&inp));
                    assert_eq!(a, b, "{inp:?}");
                    let (a, b) = (fast.eval_f32(&inp), general.eval_f32(&inp));
                    assert_eq!(a.flags, b.flags, "{inp:?}");
                    for o in 0..3 {
                        assert!(
                            a.corr_nm[o].abs_diff(b.corr_nm[o]) <= 1,
                            "{inp:?} {a:?} {b:?}"
                        );
                    }
                    clamped += a.flags.contains(Flags::CLAMPED) as u32;
                    held += (a.flags.bits() & 7 != 0) as u32;
                }
            }
        }
        // Both exact fallbacks were taken many times.
        assert!(clamped > 1000 && held > 1000, "{clamped} {held}");
    }
}
