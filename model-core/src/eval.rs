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

// Index loops over parallel fixed arrays mirror the equations (and keep the
// hot loops' shape obvious in the disassembly); iterator chains would not help.
#![allow(clippy::needless_range_loop)]

use core::num::NonZeroU32;

use heapless::Vec;

use crate::math::{sincos_f32, sincos_q30, tanh_f32, tanh_q30, ONE_Q30, TANH_IN_FRAC};
use crate::table::{Envelope, Table, TermView};

use crate::limits::{MAX_HIDDEN_LAYERS, MAX_HIDDEN_UNITS, MAX_MLP_INPUTS, MAX_MONOMIALS};
pub use crate::limits::{MAX_MLP_INPUTS_TOTAL, MAX_TEMPS, MAX_TERMS};

/// What the firmware feeds the model each cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
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
        if !self.started {
            self.started = true;
            self.last_pos_nm = pos_nm;
            return self.rev_q30;
        }
        let delta = pos_nm as i64 - self.last_pos_nm as i64;
        self.last_pos_nm = pos_nm;
        if delta == 0 {
            return self.rev_q30;
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
            // A full swing (2.0 = 2^31 in Q30) per transition_nm; clamping the
            // move first keeps the product inside i64.
            let d = delta.clamp(-t, t);
            self.rev_q30 as i64 + d * (1i64 << 31) / t
        };
        self.rev_q30 = next.clamp(-one, one) as i32;
        self.rev_q30
    }
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
const MONO_PARENT: [u8; MAX_MONOMIALS] = MONOS.1;
const MONO_AXIS: [u8; MAX_MONOMIALS] = MONOS.2;
/// Number of monomials of total degree ≤ d, for d = 0..=5.
const MONOS_UP_TO: [usize; 6] = [1, 4, 10, 20, 35, 56];

/// Index of a monomial in the graded list.
pub fn mono_index(m: [u8; 3]) -> Option<usize> {
    MONO_EXPS.iter().position(|&e| e == m)
}

// ---------------------------------------------------------------------------
// Load-time helpers (f64 arithmetic is fine here: building may be slow, and
// IEEE basic operations give the same bits on the host and on the MCU's
// soft-float, so a model loaded on either side is identical).

fn pow2(q: i32) -> f64 {
    f64::from_bits(((1023 + q) as u64) << 52)
}

fn round_i64(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        (x - 0.5) as i64
    }
}

const Q_MAX: i32 = 48;
const SUM_LIMIT: f64 = 2_147_483_647.0;

/// Largest q ≤ Q_MAX with sum_abs · 2^q ≤ 2^31 − 1, or None below `q_min`.
fn choose_q(sum_abs: f64, q_min: i32) -> Option<i32> {
    let mut q = Q_MAX;
    while sum_abs * pow2(q) > SUM_LIMIT {
        q -= 1;
        if q < q_min {
            return None;
        }
    }
    Some(q)
}

fn to_q(c: f64, q: i32) -> i32 {
    round_i64(c * pow2(q)).clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

/// x ↦ round(x · factor · 2^frac) as (x·k + 2^31) >> 32: a constant shift,
/// so on the M4 it is one SMULL/MLA pair and an add — no variable 64-bit
/// shift. Valid while |x · k| < 2^63 (callers keep |x| ≤ 1/factor).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Mul32 {
    k: i64,
}

impl Mul32 {
    fn new(factor: f64, frac: i32) -> Mul32 {
        Mul32 {
            k: round_i64(factor * pow2(frac + 32)),
        }
    }
    #[inline(always)]
    fn apply(self, x: i32) -> i32 {
        ((x as i64 * self.k + (1 << 31)) >> 32) as i32
    }
}

/// The phase increment per nm as a fraction of a turn (2^32 = one turn),
/// split into integer and fractional parts so the phase of r nm is
/// `r·int + hi32(r·frac)` — a MUL and a UMULL, exact to 1 LSB.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Turns {
    int: u32,
    frac: u32,
}

impl Turns {
    fn new(period_nm: i32) -> Turns {
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
fn rshr(x: i64, s: u32) -> i64 {
    if s == 0 {
        x
    } else {
        (x + (1i64 << (s - 1))) >> s
    }
}

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
    k_f32: f32,
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

/// A prepared, RAM-resident model with capacity `P` parameters and `G` grid
/// values. Use the aliases [`Model`] and [`LargeModel`].
#[derive(Clone, Debug)]
pub struct ModelCap<const P: usize, const G: usize> {
    env: Envelope,
    outputs: u8,
    n_channels: u8,
    centre_nm: [i32; 3],
    inv_half_f32: [f32; 3],
    u_scale: [Mul32; 3],
    /// Number of graded monomials needed (0 = no polynomial at all).
    n_monos: u8,
    block_f32: [[f32; 3]; MAX_MONOMIALS],
    block_q: [[i32; 3]; MAX_MONOMIALS],
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
}

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
            block_q: [[0; 3]; MAX_MONOMIALS],
            block_shift: [0; 3],
            has_block: false,
            reads_temp: false,
            reads_tool: false,
            has_factored: false,
            max_corr_f32: [0.0; 3],
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
        }
    }

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
        }
        r
    }

    fn clear(&mut self) {
        self.outputs = 0;
        self.n_monos = 0;
        self.has_block = false;
        self.reads_temp = false;
        self.reads_tool = false;
        self.has_factored = false;
        self.max_corr_f32 = [0.0; 3];
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
        let env = table.envelope();
        let sc = table.scaling();
        let m = self;
        m.env = env;
        m.outputs = table.outputs_mask();
        m.n_channels = table.channel_count() as u8;
        m.centre_nm = sc.centre_nm;
        m.max_corr_f32 = env.max_corr_nm.map(|v| v as f32);
        if table.term_count() > MAX_TERMS {
            return Err(LoadError::TooManyTerms {
                count: table.term_count() as u32,
            });
        }
        for a in 0..3 {
            let h = sc.half_span_nm[a] as f64;
            m.inv_half_f32[a] = (1.0 / h) as f32;
            m.u_scale[a] = Mul32::new(1.0 / h, 30);
        }
        // Pass 1: the shared polynomial block (all plain polynomial terms) and
        // the highest degree any polynomial needs.
        let mut block = [[0.0f64; 3]; MAX_MONOMIALS];
        let mut max_deg = 0usize;
        let mut any_poly = false;
        for t in table.terms() {
            let coefs = match t.view() {
                TermView::Poly { output, coefs } => {
                    m.has_block = true;
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
            m.n_monos = MONOS_UP_TO[max_deg.min(5)] as u8;
        }
        for o in 0..3 {
            let sum: f64 = block.iter().map(|r| r[o].abs()).sum();
            let q = choose_q(sum, 0).ok_or(LoadError::CoefficientRange { term: 0 })?;
            m.block_shift[o] = (q + 14) as u32;
            for i in 0..MAX_MONOMIALS {
                m.block_f32[i][o] = block[i][o] as f32;
                m.block_q[i][o] = to_q(block[i][o], q);
            }
        }
        // Pass 2: the other terms.
        let mut pools = Pools {
            pf: &mut m.pf,
            pq: &mut m.pq,
            pidx: &mut m.pidx,
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
                    // Coefficients per m°C, so the factor is the integer ΔT in m°C.
                    m.reads_temp = true;
                    m.has_factored = true;
                    let sum: f64 = coefs.iter().map(|(_, c)| (c / 1000.0).abs()).sum();
                    let q = choose_q(sum, 16).ok_or(range_err)?;
                    for (mono, c) in coefs.iter() {
                        let idx = mono_index(mono).unwrap_or(0) as u8;
                        pools.push((c / 1000.0) as f32, to_q(c / 1000.0, q), idx);
                    }
                    Term::Factored {
                        output: output as u8,
                        factor: Factor::Temp {
                            ch: channel as u8,
                            t_ref_mc,
                        },
                        start,
                        len: coefs.len() as u16,
                        shift: (q - 16) as u32,
                    }
                }
                TermView::Abbe { output, coefs } => {
                    m.reads_tool = true;
                    m.has_factored = true;
                    let sum: f64 = coefs.iter().map(|(_, c)| c.abs()).sum();
                    let q = choose_q(sum, 16).ok_or(range_err)?;
                    for (mono, c) in coefs.iter() {
                        let idx = mono_index(mono).unwrap_or(0) as u8;
                        pools.push(c as f32, to_q(c, q), idx);
                    }
                    Term::Factored {
                        output: output as u8,
                        factor: Factor::Tool,
                        start,
                        len: coefs.len() as u16,
                        shift: (q - 16) as u32,
                    }
                }
                TermView::Periodic {
                    output,
                    axis,
                    period_nm,
                    harmonics,
                    ..
                } => {
                    let view = t.view();
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
                    Term::Periodic {
                        output: output as u8,
                        axis: axis as u8,
                        harmonics: harmonics as u8,
                        period_nm,
                        turns: Turns::new(period_nm),
                        start,
                        shift: (q + 14) as u32,
                    }
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
                    let gstart = grid_needed as u32;
                    grid_needed += grid.len();
                    for i in 0..grid.len() {
                        let v = grid.value(i) * 256.0;
                        if v.abs() > i32::MAX as f64 / 2.0 {
                            return Err(LoadError::GridValueRange { term: ti as u32 });
                        }
                        let _ = m.grid.push(round_i64(v) as i32);
                    }
                    Term::Grid {
                        output: output as u8,
                        axes,
                        start: gstart,
                    }
                }
                TermView::Mlp { outputs, net } => {
                    let shape = net.shape();
                    let in_start = m.mlp_in.len();
                    if in_start + shape.n_in > MAX_MLP_INPUTS_TOTAL {
                        return Err(LoadError::MlpInputCapacity);
                    }
                    // Inputs: x_s = (v − mid)·k + e with an integer mid; e is
                    // folded into the first layer's biases below.
                    let mut e = [0.0f64; MAX_MLP_INPUTS];
                    for i in 0..shape.n_in {
                        let inp = net.input(i);
                        let mid_true = (inp.min + inp.max) / 2.0;
                        let mid =
                            round_i64(mid_true).clamp(i32::MIN as i64, i32::MAX as i64) as i32;
                        let k = 2.0 / (inp.max - inp.min);
                        e[i] = (mid as f64 - mid_true) * k;
                        // Range of the scaled input over the envelope.
                        let (lo, hi) = match inp.source {
                            s @ 0..=2 => {
                                (env.travel_min_nm[s as usize], env.travel_max_nm[s as usize])
                            }
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
                        if xs_lo.abs() > 7.0
                            || xs_hi.abs() > 7.0
                            || d_max >= 2_147_483_647.0
                            || k > 2.0
                        {
                            return Err(LoadError::MlpInputRange { term: ti as u32 });
                        }
                        m.reads_temp |= inp.source >= 3;
                        let _ = m.mlp_in.push(MlpInput {
                            src: inp.source,
                            mid,
                            k_f32: k as f32,
                            k_q28: Mul32::new(k, 28),
                        });
                    }
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
                        let q = choose_q(worst, 0).ok_or(range_err)?;
                        qs[layer.min(2)] = q as u8;
                    }
                    // Output layer q goes last so the evaluators find it at index 2.
                    if n_layers == 1 {
                        qs[2] = qs[1];
                    }
                    let push = |pools: &mut Pools<'_, P>, v: f64, q: u8| {
                        pools.push(v as f32, to_q(v, q as i32), 0)
                    };
                    // Pool layout: [layer 1 rows, layer 1 biases] for a
                    // two-layer net; then the last hidden layer fused with the
                    // output layer, one record per unit
                    // [bias, weights from the previous layer, output weights],
                    // then the output biases.
                    if n_layers == 2 {
                        let (_, prev, width) = lay[0];
                        for j in 0..width {
                            for l in 0..prev {
                                push(&mut pools, eff(0, j, Some(l)), qs[0]);
                            }
                        }
                        for j in 0..width {
                            push(&mut pools, eff(0, j, None), qs[0]);
                        }
                    }
                    let last = n_layers - 1;
                    let (_, prev, width) = lay[last];
                    for j in 0..width {
                        push(&mut pools, eff(last, j, None), qs[last]);
                        for l in 0..prev {
                            push(&mut pools, eff(last, j, Some(l)), qs[last]);
                        }
                        for o in 0..n_out {
                            push(&mut pools, eff(n_layers, o, Some(j)), qs[2]);
                        }
                    }
                    for o in 0..n_out {
                        push(&mut pools, eff(n_layers, o, None), qs[2]);
                    }
                    let mut widths = [0u8; MAX_HIDDEN_LAYERS];
                    for (i, w) in widths.iter_mut().enumerate() {
                        *w = shape.hidden[i] as u8;
                    }
                    Term::Mlp {
                        outputs,
                        n_in: shape.n_in as u8,
                        n_layers: n_layers as u8,
                        widths,
                        n_out: shape.n_out as u8,
                        in_start: in_start as u8,
                        start,
                        q: qs,
                    }
                }
            };
            let _ = m.terms.push(term);
        }
        if pools.needed > P || pools.needed > u16::MAX as usize {
            return Err(LoadError::ParamCapacity {
                needed: pools.needed as u32,
                capacity: P as u32,
            });
        }
        if grid_needed > G {
            return Err(LoadError::GridCapacity {
                needed: grid_needed as u32,
                capacity: G as u32,
            });
        }
        m.prepare_flat();
        Ok(())
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

    /// Evaluate in f32 (the fast path on the Cortex-M4F).
    pub fn eval_f32(&self, inp: &Inputs) -> Outputs {
        let mut flags = Flags::empty();
        let pos = self.hold_pos(inp.pos_nm, &mut flags);
        // |p − c| ≤ half-span < 2^31 (validated), so the wrapping i32
        // difference is exact.
        // Computed only when the table has polynomials.
        let u = || {
            [
                pos[0].wrapping_sub(self.centre_nm[0]) as f32 * self.inv_half_f32[0],
                pos[1].wrapping_sub(self.centre_nm[1]) as f32 * self.inv_half_f32[1],
                pos[2].wrapping_sub(self.centre_nm[2]) as f32 * self.inv_half_f32[2],
            ]
        };
        // Monomials up to degree 3 (the common case) are one straight-line
        // expression and the block loop has a constant trip count. All other
        // terms are evaluated out of line (recomputing the monomials they
        // need), so they cost the polynomial path nothing — no spilled
        // monomials, no hoisted constants — when a table has none.
        let out = if self.terms.is_empty() {
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
            self.flat_f32(uv, &pos, inp, &mut flags, &mut out);
            out
        } else {
            // The monomials are handed to the thermal/Abbe terms.
            match self.n_monos {
                0 => {
                    let mut out = [0.0; 3];
                    self.terms_f32(&[], &pos, inp, &mut flags, &mut out);
                    out
                }
                1..=20 => {
                    let mv = mono20_f32(u());
                    let mut out = self.block_f32(&mv);
                    self.terms_f32(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
                _ => {
                    let mv = mono56_f32(u());
                    let mut out = self.block_f32(&mv);
                    self.terms_f32(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
            }
        };
        let mut corr = [0i32; 3];
        for o in 0..3 {
            // Absent outputs have no coefficients and no terms: they are 0.
            let v = out[o];
            let max = self.max_corr_f32[o];
            let c = if v.abs() <= max {
                v // the common case; NaN fails the comparison
            } else if v > max {
                flags.insert(Flags::CLAMPED);
                max
            } else if v < -max {
                flags.insert(Flags::CLAMPED);
                -max
            } else {
                flags.insert(Flags::NOT_FINITE);
                0.0
            };
            // Round to nearest (ties to even) with the 1.5·2^23 trick: exact
            // for |c| < 2^22, which MAX_CORR_LIMIT_NM guarantees.
            corr[o] = ((c + ROUND_MAGIC) - ROUND_MAGIC) as i32;
        }
        Outputs {
            corr_nm: corr,
            flags,
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
            // |v − mid| < 2^31 over the envelope (checked at load).
            *xi = mlp_source(mi.src, pos, temp).wrapping_sub(mi.mid) as f32 * mi.k_f32;
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
            (3, 3) => fused_f32::<3, 3>(blk, src, width),
            (4, 3) => fused_f32::<4, 3>(blk, src, width),
            (3, 1) => fused_f32::<3, 1>(blk, src, width),
            (16, 3) => fused_f32::<16, 3>(blk, src, width),
            _ => fused_f32_dyn(blk, src, width, n_out),
        };
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
        let mut flags = Flags::empty();
        let pos = self.hold_pos(inp.pos_nm, &mut flags);
        // |p − c| ≤ half-span, so |u| ≤ 2^30 (+1 from rounding) fits i32.
        // Computed only when the table has polynomials.
        let u = || {
            [
                self.u_scale[0].apply(pos[0].wrapping_sub(self.centre_nm[0])),
                self.u_scale[1].apply(pos[1].wrapping_sub(self.centre_nm[1])),
                self.u_scale[2].apply(pos[2].wrapping_sub(self.centre_nm[2])),
            ]
        };
        let out = if self.terms.is_empty() {
            match self.n_monos {
                0 => [0; 3],
                1..=20 => self.block_fixed(&mono20_q30(u())),
                _ => self.block_fixed(&mono56_q30(u())),
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
                    let mut out = self.block_fixed(&mv);
                    self.terms_fixed(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
                _ => {
                    let mv = mono56_q30(u());
                    let mut out = self.block_fixed(&mv);
                    self.terms_fixed(&mv, &pos, inp, &mut flags, &mut out);
                    out
                }
            }
        };
        let mut corr = [0i32; 3];
        for o in 0..3 {
            let max = self.env.max_corr_nm[o] as i64;
            let v = rshr(out[o], 16);
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

    /// The shared polynomial block, Q16 nm.
    #[inline(always)]
    fn block_fixed<const N: usize>(&self, mv: &[i32; N]) -> [i64; 3] {
        if !self.has_block {
            return [0; 3];
        }
        // Σ|c_q| ≤ 2^31 and |m| ≤ 2^30: each sum stays below 2^61.
        let (mut a0, mut a1, mut a2) = (0i64, 0i64, 0i64);
        for i in 0..N.min(MAX_MONOMIALS) {
            let (m, c) = (mv[i] as i64, self.block_q[i]);
            a0 += c[0] as i64 * m;
            a1 += c[1] as i64 * m;
            a2 += c[2] as i64 * m;
        }
        [
            rshr(a0, self.block_shift[0]),
            rshr(a1, self.block_shift[1]),
            rshr(a2, self.block_shift[2]),
        ]
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
                    (*output, rshr(self.periodic_fixed(t, pos), *shift))
                }
                Term::Reversal {
                    output,
                    axis,
                    amp_q,
                    shift,
                    ..
                } => {
                    let r = inp.rev_q30[*axis as usize % 3].clamp(-ONE_Q30, ONE_Q30);
                    (*output, rshr(*amp_q as i64 * r as i64, *shift))
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
            let o = o as usize % 3;
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
        rshr(rshr(v, 30) * f, shift)
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
        let theta = phase_turns(pos[axis as usize % 3], period_nm, turns);
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

/// The last hidden layer fused with the output layer, f32: per unit the
/// record [bias, NI weights, NO output weights]; then NO output biases.
#[inline(always)]
fn fused_f32<const NI: usize, const NO: usize>(blk: &[f32], x: &[f32], width: usize) -> [f32; 3] {
    let mut acc = [0.0f32; 3];
    let Ok(x) = <&[f32; NI]>::try_from(x) else {
        return acc;
    };
    let stride = 1 + NI + NO;
    let (Some(units), Some(bo)) = (
        blk.get(..width * stride),
        blk.get(width * stride..width * stride + NO),
    ) else {
        return acc;
    };
    let mut a = [0.0f32; NO];
    for (ai, &b) in a.iter_mut().zip(bo) {
        *ai = b;
    }
    for u in units.chunks_exact(stride) {
        let (b, w, wo) = (u[0], &u[1..1 + NI], &u[1 + NI..]);
        let (Ok(w), Ok(wo)) = (<&[f32; NI]>::try_from(w), <&[f32; NO]>::try_from(wo)) else {
            continue;
        };
        let mut z = b;
        for i in 0..NI {
            z += w[i] * x[i];
        }
        let h = tanh_f32(z);
        for o in 0..NO {
            a[o] += wo[o] * h;
        }
    }
    for (ac, ai) in acc.iter_mut().zip(a) {
        *ac = ai;
    }
    acc
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
        let h = tanh_f32(u[0] + dot_f32(w, x));
        for (a, &wj) in acc.iter_mut().zip(wo) {
            *a += wj * h;
        }
    }
    acc
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

/// Dot product with the common tiny input counts unrolled.
#[inline(always)]
fn dot_f32(row: &[f32], x: &[f32]) -> f32 {
    match (row, x) {
        ([a, b, c], [p, q, r, ..]) => a * p + b * q + c * r,
        ([a, b, c, d], [p, q, r, s, ..]) => a * p + b * q + c * r + d * s,
        _ => row.iter().zip(x).fold(0.0, |z, (w, v)| z + w * v),
    }
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

/// 1.5 · 2^23: adding and subtracting it rounds an f32 of magnitude < 2^22 to an integer.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// `v` held inside [lo, hi] (lo ≤ hi is validated), raising `f` when it was outside.
#[inline(always)]
fn hold(v: i32, lo: i32, hi: i32, flags: &mut Flags, f: Flags) -> i32 {
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
fn mono20_f32(u: [f32; 3]) -> [f32; 20] {
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
fn mono56_f32(u: [f32; 3]) -> [f32; MAX_MONOMIALS] {
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
fn mul_q30(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64) >> 30) as i32
}

/// The 20 graded monomials of degree ≤ 3, Q30 (same rounding as [`mono56_q30`]).
#[inline(always)]
fn mono20_q30(u: [i32; 3]) -> [i32; 20] {
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

/// All 56 graded monomials (degree ≤ 5), Q30.
fn mono56_q30(u: [i32; 3]) -> [i32; MAX_MONOMIALS] {
    let mut mv = [0i32; MAX_MONOMIALS];
    mv[0] = ONE_Q30;
    for i in 1..MAX_MONOMIALS {
        mv[i] = mul_q30(mv[MONO_PARENT[i] as usize], u[MONO_AXIS[i] as usize]);
    }
    mv
}

/// Phase of `pos` along a period as a fraction of a turn (2^32 = one turn),
/// computed in integers so it stays exact at any position.
#[inline(always)]
fn phase_turns(pos_nm: i32, period_nm: i32, turns: Turns) -> u32 {
    let r = pos_nm.rem_euclid(period_nm) as u32;
    r.wrapping_mul(turns.int)
        .wrapping_add(((r as u64 * turns.frac as u64) >> 32) as u32)
}

#[inline(always)]
fn mlp_source(src: u8, pos: &[i32; 3], temp: &[i32; MAX_TEMPS]) -> i32 {
    match src {
        0..=2 => pos[src as usize],
        s => temp[(s as usize - 3) & 3],
    }
}

/// Cell index and offset (nm) of `p` on a grid axis, held at the grid's edges.
#[inline(always)]
fn grid_cell(ax: &GridAxis, p: i32) -> (usize, i32) {
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
    fn flag_names_follow_the_bits() {
        assert!(Flags::from_bits(0x7f).names().eq(Flags::NAMES));
        let f = Flags::TEMP_OUT_OF_RANGE | Flags::OUT_OF_TRAVEL_Y;
        assert!(f.names().eq(["out_of_travel_y", "temp_out_of_range"]));
        assert_eq!(Flags::from_bits(1 << 9).names().count(), 0);
    }

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
