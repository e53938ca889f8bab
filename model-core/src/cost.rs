//! A static estimate of what one evaluation of a table costs on the
//! Cortex-M4F, in instructions — computed from the table alone, before it
//! is loaded, so that the firmware can refuse at commit a table its
//! correction loop cannot evaluate in time, and `trueaxis export` can say
//! so before the table ever leaves the host.
//!
//! The estimate follows the structure of [`crate::eval`]: which monomial
//! vector is built (none, the 20 of degree ≤ 3 in straight-line code, or
//! all 56 — or none on the separable path's Horner rows, priced per row
//! and step), whether the shared polynomial block is summed, whether the f32
//! fast path applies (every non-polynomial term a reversal, a periodic term
//! or a thermal/Abbe term of degree ≤ 1), and then a cost per term by kind
//! and size (coefficients, harmonics, grid, network units and
//! multiply-adds). The weights are calibrated against the instruction
//! counts of the QEMU bench image (`cargo xtask bench-mcu`: firmware
//! release profile, `-icount shift=0`) so that the estimate is an upper
//! bound of every measured table; `cargo xtask test` checks, for every
//! bench table, measured ≤ estimate ≤ 1.5 × measured (BENCHMARKS.md lists
//! the figures). The estimate is deterministic integer arithmetic: host
//! and board get the same number.
//!
//! It is an estimate of *instructions*, like the bench; cycles on the real
//! chip are more (see [`crate::board`] for the margin the loop budget
//! keeps).

use crate::limits::MAX_TERMS;
use crate::table::{Table, TermView};

/// Estimated instructions of one 3-axis evaluation of a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CostEstimate {
    /// `eval_f32`.
    pub f32_instr: u32,
    /// `eval_fixed` (what the firmware's correction loop runs).
    pub fixed_instr: u32,
}

/// What the cost of a table depends on (see the module documentation).
#[doc(hidden)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Features {
    /// Highest total degree of any polynomial, thermal or Abbe monomial
    /// (`None`: the table has none).
    pub max_degree: Option<u8>,
    /// Some plain polynomial term (the shared block is summed).
    pub has_block: bool,
    /// Terms other than plain polynomials.
    pub other_terms: u32,
    /// Some term reads a temperature; channels declared by the table.
    pub reads_temp: bool,
    /// Temperature channels of the table.
    pub channels: u32,
    /// Some term reads the tool arm.
    pub reads_tool: bool,
    /// The f32 fast path applies.
    pub flat: bool,
    /// Thermal and Abbe terms, and their coefficients.
    pub factored: u32,
    /// See `factored`.
    pub factored_coefs: u32,
    /// Periodic terms, and their harmonics.
    pub periodic: u32,
    /// See `periodic`.
    pub harmonics: u32,
    /// Reversal terms.
    pub reversal: u32,
    /// Grid terms.
    pub grid: u32,
    /// MLP terms.
    pub mlp: u32,
    /// MLP inputs (all MLP terms).
    pub mlp_inputs: u32,
    /// MLPs with two hidden layers (their first layer is a separate loop).
    pub mlp_two_layer: u32,
    /// Units of those first layers, and their multiply-adds.
    pub l1_units: u32,
    /// See `l1_units`.
    pub l1_macs: u32,
    /// Of those, in rows without an unrolled dot product (not 3 or 4 inputs).
    pub l1_macs_generic: u32,
    /// Units of the last hidden layer, fused with the output layer.
    pub fused_units: u32,
    /// Their multiply-adds (inputs and outputs of each unit).
    pub fused_macs: u32,
    /// Units and multiply-adds in the generic fused kernel (shapes without
    /// a specialised one).
    pub generic_units: u32,
    /// See `generic_units`.
    pub generic_macs: u32,
    /// The fixed-point polynomial fast path takes the block's scales
    /// (`eval::poly_fixed_takes`; only matters for a polynomial-only table).
    pub poly_fixed_ok: bool,
    /// Monomials with a block coefficient on some output.
    pub block_used: u32,
    /// Every thermal/Abbe monomial is of degree ≤ 1.
    pub factored_deg1: bool,
    /// Fixed point takes the few-monomial path (`eval`'s `vp_*`: a block
    /// of degree ≤ 3 needing at most 4 products, thermal/Abbe terms of
    /// degree ≤ 1).
    pub vp: bool,
    /// … and its flat term loop (every other term a reversal or a
    /// thermal/Abbe term, at most 8).
    pub fq: bool,
    /// Fixed point sums the block by monomial (`blk_*`: at most 28 used
    /// monomials, at most half of the vector's; not on the `vp` path).
    pub blk: bool,
    /// Fixed point takes the separable path (`eval`'s Horner rows, issue
    /// 26: every monomial u_a^n·(1 | u_b), degree ≥ 4, only polynomial,
    /// thermal and Abbe terms; `eval::horner_plan`).
    pub horner: bool,
    /// Its rows, and the Horner steps of each.
    pub horner_rows: u32,
    /// See `horner_rows`.
    pub horner_steps: u32,
}

impl Features {
    /// The features of `table`.
    pub fn of(table: &Table<'_>) -> Features {
        let mut f = Features {
            channels: table.channel_count() as u32,
            flat: true,
            factored_deg1: true,
            ..Features::default()
        };
        // The block as `load` sums it, for its per-output scales.
        let mut block = [[0.0f64; 3]; crate::limits::MAX_MONOMIALS];
        let env = table.envelope();
        let deg = |d: u8, f: &mut Features| {
            f.max_degree = Some(f.max_degree.map_or(d, |m| m.max(d)));
        };
        for t in table.terms().take(MAX_TERMS) {
            let view = t.view();
            if !matches!(view, TermView::Poly { .. }) {
                f.other_terms += 1;
            }
            match view {
                TermView::Poly { coefs, output } => {
                    f.has_block = true;
                    for (m, c) in coefs.iter() {
                        deg(m[0] + m[1] + m[2], &mut f);
                        if let Some(i) = crate::eval::mono_index(m) {
                            block[i][output % 3] += c;
                        }
                    }
                }
                TermView::Thermal { coefs, .. } | TermView::Abbe { coefs, .. } => {
                    if matches!(view, TermView::Thermal { .. }) {
                        f.reads_temp = true;
                    } else {
                        f.reads_tool = true;
                    }
                    f.factored += 1;
                    f.factored_coefs += coefs.len() as u32;
                    for (m, _) in coefs.iter() {
                        let d = m[0] + m[1] + m[2];
                        deg(d, &mut f);
                        f.flat &= d <= 1;
                        f.factored_deg1 &= d <= 1;
                    }
                }
                TermView::Periodic {
                    axis,
                    period_nm,
                    harmonics,
                    ..
                } => {
                    f.periodic += 1;
                    f.harmonics += harmonics as u32;
                    // The fast path needs the travel within 2^32 nm of a
                    // multiple of the period below it (eval's prepare_flat).
                    let p = i64::from(period_nm.max(1));
                    let a = axis % 3;
                    let base = i64::from(env.travel_min_nm[a]).div_euclid(p) * p;
                    f.flat &= i64::from(env.travel_max_nm[a]) - base <= i64::from(u32::MAX);
                }
                TermView::Reversal { .. } => f.reversal += 1,
                TermView::Grid { .. } => {
                    f.grid += 1;
                    f.flat = false;
                }
                TermView::Mlp { net, .. } => {
                    f.flat = false;
                    f.mlp += 1;
                    let n_in = net.n_inputs() as u32;
                    f.mlp_inputs += n_in;
                    f.reads_temp |= (0..net.n_inputs()).any(|i| net.input(i).source >= 3);
                    let hidden = net.hidden();
                    let n_out = net.n_outputs() as u32;
                    let width = hidden.last().copied().unwrap_or(0) as u32;
                    // The fused kernel's inputs: the first hidden layer of a
                    // two-layer net, else the net's inputs.
                    let fused_in = if hidden.len() >= 2 {
                        let w0 = hidden[0] as u32;
                        f.mlp_two_layer += 1;
                        f.l1_units += w0;
                        f.l1_macs += w0 * n_in;
                        if !matches!(n_in, 3 | 4) {
                            f.l1_macs_generic += w0 * n_in;
                        }
                        w0
                    } else {
                        n_in
                    };
                    f.fused_units += width;
                    f.fused_macs += width * (fused_in + n_out);
                    // eval's specialised fused kernels: (inputs, outputs) =
                    // (3, 3), (4, 3), (3, 1), (16, 3).
                    if !matches!((fused_in, n_out), (3, 3) | (4, 3) | (3, 1) | (16, 3)) {
                        f.generic_units += width;
                        f.generic_macs += width * (fused_in + n_out);
                    }
                }
            }
        }
        let sums = [0, 1, 2].map(|o| block.iter().map(|r| r[o].abs()).sum::<f64>());
        f.poly_fixed_ok = crate::eval::poly_fixed_takes(sums);
        // The fixed path's shape as `load` decides it (from the f64 sums: a
        // coefficient that rounds to 0 in fixed point counts as used here,
        // which can only make the estimate larger).
        let n_monos = f
            .max_degree
            .map_or(0, |d| [1, 4, 10, 20, 35, 56][(d as usize).min(5)]);
        let used = |i: usize| block[i].iter().any(|&c| c != 0.0);
        let count = (0..n_monos).filter(|&i| used(i)).count();
        f.block_used = count as u32;
        if f.has_block && (1..=20).contains(&n_monos) && f.factored_deg1 {
            let mut need: [bool; 20] = core::array::from_fn(used);
            f.vp = crate::eval::vp_products(&mut need) <= crate::eval::VP_MAX_PRODUCTS;
        }
        f.fq = f.vp
            && f.other_terms > 0
            && f.other_terms == f.factored + f.reversal
            && f.other_terms as usize <= crate::eval::FQ_MAX_TERMS;
        f.blk = f.has_block && !f.vp && count <= crate::eval::BLK_MAX && 2 * count <= n_monos;
        if let Some(p) = crate::eval::horner_plan(table) {
            f.horner = true;
            f.horner_rows = p.n as u32;
            f.horner_steps = p.steps as u32;
        }
        f
    }

    /// The straight-line kernel of a polynomial-only table of degree ≤ 3
    /// (`eval`'s `PolyKind`): Some(1) for degree ≤ 1, Some(3) else.
    fn poly_kind(&self) -> Option<u8> {
        match (self.has_block && self.other_terms == 0, self.max_degree) {
            (true, Some(0..=1)) => Some(1),
            (true, Some(2..=3)) => Some(3),
            _ => None,
        }
    }
}

/// Instructions of the polynomial-only kernels (degree ≤ 1, ≤ 3), f32 and
/// fixed point: the worst call of the bench tables (`poly_deg1`, `cubic19`)
/// plus the out-of-travel hold and the exact clamp they take on some
/// inputs, rounded up (BENCHMARKS.md, "Instruction counts").
const POLY1_F32: u32 = 136;
const POLY3_F32: u32 = 250;
const POLY1_FIXED: u32 = 185;
const POLY3_FIXED: u32 = 500;

/// Weights of one evaluation path, tenths of an instruction per unit of
/// a feature (tenths keep the per-multiply-add costs exact enough in
/// integers). Fitted by least squares on the bench counts of 200 tables
/// (an earlier random set, not kept),
/// negative weights set to zero, then scaled until every table's estimate
/// was ≥ 1.05 × its count. `cargo xtask bench-mcu --calibrate` prints the
/// estimate against the count on the bench tables and 191 seeded random
/// ones (BENCHMARKS.md, "Static cost estimate").
#[derive(Clone, Copy, Debug)]
struct Weights {
    /// Entry, holding the positions, the output clamp.
    base: u32,
    /// The 20 monomials of degree ≤ 3; all 56.
    mono20: u32,
    mono56: u32,
    /// The shared polynomial block over 20 / 56 monomials.
    block20: u32,
    block56: u32,
    /// Holding the temperatures: once, and per channel; the tool arm.
    temp: u32,
    temp_channel: u32,
    tool: u32,
    /// A grid term (three axes, eight corners, seven interpolations).
    grid: u32,
    /// An MLP term; per input; per two-layer net (its first layer runs
    /// over the 32-unit array whatever the width).
    mlp: u32,
    mlp_input: u32,
    mlp_two_layer: u32,
    /// First layer of a two-layer net: per unit (tanh), per multiply-add,
    /// extra per multiply-add of rows that are not unrolled.
    l1_unit: u32,
    l1_mac: u32,
    l1_mac_generic: u32,
    /// Fused last layer: per unit (tanh), per multiply-add, extra per unit
    /// and multiply-add in the generic kernel.
    fused_unit: u32,
    fused_mac: u32,
    generic_unit: u32,
    generic_mac: u32,
}

/// Weights of the f32 path's general term loop and fixed point's term
/// loop (per kind, per size).
#[derive(Clone, Copy, Debug)]
struct TermWeights {
    /// The term loop's entry (once, if the table has any term that is not
    /// a plain polynomial).
    entry: u32,
    /// A thermal/Abbe term; per coefficient.
    factored: u32,
    factored_coef: u32,
    /// A periodic term; per harmonic.
    periodic: u32,
    harmonic: u32,
    /// A reversal term.
    reversal: u32,
}

/// The f32 fast path (`flat`): every term laid out per kind.
#[derive(Clone, Copy, Debug)]
struct FlatWeights {
    entry: u32,
    /// A thermal/Abbe term of degree ≤ 1.
    factored: u32,
    /// A periodic term; per harmonic.
    periodic: u32,
    harmonic: u32,
    /// Reversal: one 3 × 3 matrix, whatever the number of terms.
    reversal: u32,
}

/// (`mono56`: issue 26 made the Q30 monomial vector of degree ≤ 5
/// straight-line, 494 instructions less on `poly_deg5` and 528 on
/// `all_kinds`; the weight was lowered by ≈ 544, 7598 → 2160, and
/// `--calibrate` keeps all 208 tables within [1.05, 1.42] × the count.)
const FIXED: Weights = Weights {
    base: 1501,
    mono20: 1261,
    mono56: 2160,
    block20: 3797,
    block56: 10600,
    temp: 87,
    temp_channel: 53,
    tool: 0,
    grid: 3830,
    mlp: 83,
    mlp_input: 1013,
    mlp_two_layer: 8152,
    l1_unit: 1215,
    l1_mac: 105,
    l1_mac_generic: 23,
    fused_unit: 1484,
    fused_mac: 46,
    generic_unit: 0,
    generic_mac: 42,
};

/// Fixed point's few-monomial paths (issue 15 round 5), tenths: the
/// few-monomial vector and its block (straight-line, the same whatever the
/// products), its flat term loop (once, per thermal/Abbe term, per
/// reversal), and the block by monomial (once, per used monomial). Set on
/// `cargo xtask bench-mcu --calibrate`'s counts so that every table of the
/// set stays within [1.05, 1.45] × its count (BENCHMARKS.md).
struct FewWeights {
    vp: u32,
    fq_entry: u32,
    fq_factored: u32,
    fq_reversal: u32,
    blk_entry: u32,
    blk_used: u32,
}

const FIXED_FEW: FewWeights = FewWeights {
    vp: 2500,
    fq_entry: 200,
    fq_factored: 450,
    fq_reversal: 950,
    blk_entry: 300,
    blk_used: 270,
};

/// Fixed point's separable path (issue 26), tenths: once (the normalised
/// positions, their three products, the sums' starts and shifts), per row
/// and per Horner step of each row, per thermal/Abbe term (its factor).
/// From an exec trace of `rigid21_fixed` (824 of its 934 instructions in
/// the kernel: ≈ 230 once, ≈ 22 per row of 3 steps, ≈ 50 per Abbe term),
/// each rounded up, so that its estimate is 1.10 × the count (`cargo
/// xtask bench-mcu --calibrate`, BENCHMARKS.md).
struct HornerWeights {
    entry: u32,
    row: u32,
    step: u32,
    factored: u32,
}

const FIXED_HORNER: HornerWeights = HornerWeights {
    entry: 2500,
    row: 125,
    step: 40,
    factored: 550,
};

const FIXED_TERMS: TermWeights = TermWeights {
    entry: 614,
    factored: 1442,
    factored_coef: 118,
    periodic: 1796,
    harmonic: 331,
    reversal: 843,
};

const F32: Weights = Weights {
    base: 1224,
    mono20: 381,
    mono56: 2889,
    block20: 1456,
    block56: 5087,
    temp: 236,
    temp_channel: 10,
    tool: 53,
    grid: 2649,
    mlp: 70,
    mlp_input: 783,
    mlp_two_layer: 7698,
    l1_unit: 170,
    l1_mac: 105,
    l1_mac_generic: 43,
    fused_unit: 266,
    fused_mac: 25,
    generic_unit: 27,
    generic_mac: 50,
};

const F32_TERMS: TermWeights = TermWeights {
    entry: 754,
    factored: 908,
    factored_coef: 98,
    periodic: 1186,
    harmonic: 93,
    reversal: 429,
};

const F32_FLAT: FlatWeights = FlatWeights {
    entry: 1025,
    factored: 272,
    periodic: 497,
    harmonic: 115,
    reversal: 294,
};

impl Features {
    /// Which monomial vector: (degree ≤ 3, degree ≥ 4) as 0/1.
    fn monos(&self) -> (u64, u64) {
        let deg = self.max_degree;
        (
            matches!(deg, Some(0..=3)) as u64,
            matches!(deg, Some(4..)) as u64,
        )
    }

    /// The monomial vector and the block, tenths of an instruction.
    fn mono_block(&self, w: &Weights) -> u64 {
        let (m20, m56) = self.monos();
        let f = |x: u32| u64::from(x);
        m20 * f(w.mono20)
            + m56 * f(w.mono56)
            + self.has_block as u64 * (m20 * f(w.block20) + m56 * f(w.block56))
    }

    /// [`Self::mono_block`] of fixed point, which has the few-monomial
    /// vector and the block by monomial.
    fn fixed_mono_block(&self) -> u64 {
        let f = |x: u32| u64::from(x);
        let (m20, m56) = self.monos();
        if self.horner {
            let h = &FIXED_HORNER;
            f(h.entry) + f(self.horner_rows) * (f(h.row) + f(self.horner_steps) * f(h.step))
        } else if self.vp {
            f(FIXED_FEW.vp)
        } else if self.blk {
            m20 * f(FIXED.mono20)
                + m56 * f(FIXED.mono56)
                + f(FIXED_FEW.blk_entry)
                + f(self.block_used) * f(FIXED_FEW.blk_used)
        } else {
            self.mono_block(&FIXED)
        }
    }

    /// Fixed point's terms: the separable path's factors, the flat loop
    /// or the general one.
    fn fixed_terms(&self) -> u64 {
        let f = |x: u32| u64::from(x);
        if self.horner {
            f(self.factored) * f(FIXED_HORNER.factored)
        } else if self.fq {
            f(FIXED_FEW.fq_entry)
                + f(self.factored) * f(FIXED_FEW.fq_factored)
                + f(self.reversal) * f(FIXED_FEW.fq_reversal)
        } else {
            self.terms(&FIXED_TERMS)
        }
    }

    /// The part both paths share but the monomial vector and the block,
    /// tenths of an instruction.
    fn common(&self, w: &Weights) -> u64 {
        let terms = (self.other_terms > 0) as u64;
        let f = |x: u32| u64::from(x);
        f(w.base)
            + terms
                * (self.reads_temp as u64 * (f(w.temp) + f(self.channels) * f(w.temp_channel))
                    + self.reads_tool as u64 * f(w.tool))
            + f(self.grid) * f(w.grid)
            + f(self.mlp) * f(w.mlp)
            + f(self.mlp_inputs) * f(w.mlp_input)
            + f(self.mlp_two_layer) * f(w.mlp_two_layer)
            + f(self.l1_units) * f(w.l1_unit)
            + f(self.l1_macs) * f(w.l1_mac)
            + f(self.l1_macs_generic) * f(w.l1_mac_generic)
            + f(self.fused_units) * f(w.fused_unit)
            + f(self.fused_macs) * f(w.fused_mac)
            + f(self.generic_units) * f(w.generic_unit)
            + f(self.generic_macs) * f(w.generic_mac)
    }

    /// The general term loop, tenths of an instruction.
    fn terms(&self, w: &TermWeights) -> u64 {
        let f = |x: u32| u64::from(x);
        (self.other_terms > 0) as u64 * f(w.entry)
            + f(self.factored) * f(w.factored)
            + f(self.factored_coefs) * f(w.factored_coef)
            + f(self.periodic) * f(w.periodic)
            + f(self.harmonics) * f(w.harmonic)
            + f(self.reversal) * f(w.reversal)
    }

    /// The f32 fast path's terms, tenths of an instruction.
    fn flat(&self, w: &FlatWeights) -> u64 {
        let f = |x: u32| u64::from(x);
        (self.other_terms > 0) as u64 * f(w.entry)
            + f(self.factored) * f(w.factored)
            + f(self.periodic) * f(w.periodic)
            + f(self.harmonics) * f(w.harmonic)
            + (self.reversal > 0) as u64 * f(w.reversal)
    }

    /// The estimate from these features.
    pub fn estimate(&self) -> CostEstimate {
        let f32_terms = if self.flat {
            self.flat(&F32_FLAT)
        } else {
            self.terms(&F32_TERMS)
        };
        let instr = |tenths: u64| tenths.div_ceil(10).min(u64::from(u32::MAX)) as u32;
        let (f32_instr, fixed_instr) = match self.poly_kind() {
            Some(1) => (POLY1_F32, POLY1_FIXED),
            Some(_) => (POLY3_F32, POLY3_FIXED),
            None => (0, 0),
        };
        CostEstimate {
            f32_instr: if f32_instr > 0 {
                f32_instr
            } else {
                instr(self.common(&F32) + self.mono_block(&F32) + f32_terms)
            },
            fixed_instr: if fixed_instr > 0 && self.poly_fixed_ok {
                fixed_instr
            } else {
                instr(self.common(&FIXED) + self.fixed_mono_block() + self.fixed_terms())
            },
        }
    }
}

/// The estimate for `table` (see the module documentation).
pub fn estimate(table: &Table<'_>) -> CostEstimate {
    Features::of(table).estimate()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(bytes: &[u8]) -> Features {
        Features::of(&crate::parse(bytes).unwrap())
    }

    #[test]
    fn features_follow_the_evaluation_paths() {
        let cubic = features(include_bytes!("../tests/golden/cubic19.bin"));
        assert_eq!(cubic.max_degree, Some(3));
        assert!(cubic.has_block && cubic.other_terms == 0);
        // cubic19 + periodic + thermal of degree 1 + reversal: the f32 fast path.
        let full = features(include_bytes!("../tests/golden/full.bin"));
        assert!(full.flat, "{full:?}");
        assert_eq!((full.periodic, full.harmonics, full.reversal), (1, 2, 1));
        assert_eq!((full.factored, full.factored_coefs), (1, 2));
        // 3-16-3: the specialised fused kernel, no first layer.
        let nn = features(include_bytes!("../tests/golden/nn_3x16x3.bin"));
        assert!(!nn.flat);
        assert_eq!((nn.mlp, nn.fused_units, nn.fused_macs), (1, 16, 16 * 6));
        assert_eq!((nn.mlp_two_layer, nn.generic_units), (0, 0));
        // Degree 5, a grid, a 4-16-16-3 network with a temperature input.
        let all = features(include_bytes!("../tests/golden/all_kinds.bin"));
        assert_eq!(all.max_degree, Some(5));
        assert!(!all.flat && all.reads_temp && all.reads_tool);
        assert_eq!((all.mlp_two_layer, all.l1_units, all.l1_macs), (1, 16, 64));
        assert_eq!(all.grid, 1);
        assert!(!all.horner && !cubic.horner && !full.horner);
        // rigid21:4 (separable, degree 5, two Abbe terms): the Horner rows.
        let rigid = features(include_bytes!("../../tests/golden/rigid21.bin"));
        assert!(rigid.horner, "{rigid:?}");
        assert_eq!((rigid.horner_rows, rigid.horner_steps), (21, 3));
    }

    #[test]
    fn more_work_is_never_estimated_cheaper() {
        let e = |b: &[u8]| estimate(&crate::parse(b).unwrap());
        let cubic = e(include_bytes!("../tests/golden/cubic19.bin"));
        let full = e(include_bytes!("../tests/golden/full.bin"));
        let all = e(include_bytes!("../tests/golden/all_kinds.bin"));
        assert!(cubic.fixed_instr < full.fixed_instr && full.fixed_instr < all.fixed_instr);
        assert!(cubic.f32_instr < full.f32_instr && full.f32_instr < all.f32_instr);
        // Fixed point costs more than f32 on the M4F for these tables.
        assert!(cubic.f32_instr < cubic.fixed_instr);
    }
}
