//! The fixed-point path of separable tables (issue 26, `eval`'s Horner
//! rows): every polynomial, thermal and Abbe monomial one axis to a power
//! times at most one linear factor of another (u_a^n, u_a^n·u_b), degree
//! ≥ 4 — the shape of a rigid21 table. Proptested like `accuracy.rs`:
//! within 1 nm of the f64 reference over the whole envelope (travel
//! corners, where |u| = 1, included), held at the edge and flagged beyond
//! it; and at the limits of the types (Σ|c| at the path's headroom, the
//! tool arm at ±2^31) without overflow in debug.
#![allow(clippy::needless_range_loop)] // per-output index loops mirror [ex, ey, ez]
mod common;

use common::Rng;
use common::*;
use model_core::cost::Features;
use model_core::eval::MONO_EXPS;
use model_core::{parse, Inputs, InputsF64, LargeModel, TableSpec, TermSpec};
use proptest::prelude::*;

/// Whether `m` is u_a^n or u_a^n·u_b (n ≥ 1).
fn is_separable(m: [u8; 3]) -> bool {
    let nz = m.iter().filter(|&&e| e > 0).count();
    nz == 1 || (nz == 2 && m.contains(&1))
}

/// A random subset of the separable monomials of degree ≤ `deg` (the
/// constant among them), at most `cross` of the six (axis, other axis)
/// pairs with a linear factor, one monomial of degree `deg` at least.
fn monomials(rng: &mut Rng, deg: u8, cross: usize) -> Vec<[u8; 3]> {
    let mut pairs: Vec<(usize, usize)> = (0..3)
        .flat_map(|a| (0..3).filter(move |&b| b != a).map(move |b| (a, b)))
        .collect();
    while pairs.len() > cross {
        pairs.remove(rng.int(0, pairs.len() as i64 - 1) as usize);
    }
    // The axis whose power the row runs over: the larger exponent (x for xy).
    let row_of = |m: [u8; 3]| {
        let nz: Vec<usize> = (0..3).filter(|&a| m[a] > 0).collect();
        match nz.as_slice() {
            [a, b] if m[*b] == 1 => Some((*a, *b)),
            [a, b] => Some((*b, *a)),
            _ => None,
        }
    };
    let mut set: Vec<[u8; 3]> = MONO_EXPS
        .iter()
        .copied()
        .filter(|&m| m.iter().sum::<u8>() <= deg && is_separable(m) || m == [0, 0, 0])
        .filter(|&m| row_of(m).is_none_or(|p| pairs.contains(&p)))
        .filter(|_| rng.unit() < 0.6)
        .collect();
    let a = rng.int(0, 2) as usize;
    let mut top = [0u8; 3];
    top[a] = deg;
    if !set.contains(&top) {
        set.push(top);
    }
    set
}

/// A random separable table: the three outputs' polynomials of degree 4
/// or 5 (≤ 200 µm), up to two Abbe terms (µrad, degree ≤ 4) and a
/// thermal term (nm/K, degree ≤ 2) on some draws.
fn separable_spec(seed: u64) -> TableSpec {
    let mut rng = Rng(seed);
    let channels = rng.int(1, 2) as usize;
    let mut spec = base_spec(&mut rng, channels);
    let deg = rng.int(4, 5) as u8;
    // At most 5 rows per output, 4 per Abbe term, 3 for the thermal term
    // (taken with at most one Abbe term): ≤ 23 rows (the path takes 24).
    for o in 0..3u8 {
        let set = monomials(&mut rng, deg, 2);
        let amp = rng.range(100.0, 40_000.0);
        let coefs = set.iter().map(|&m| (m, rng.sym(amp))).collect();
        spec.terms.push(TermSpec::Poly { output: o, coefs });
    }
    let abbe = rng.int(0, 2);
    for _ in 0..abbe {
        let set = monomials(&mut rng, 4, 1);
        spec.terms.push(TermSpec::Abbe {
            output: rng.int(0, 2) as u8,
            coefs: set.iter().map(|&m| (m, rng.sym(3e-5))).collect(),
        });
    }
    if abbe < 2 && rng.unit() < 0.6 {
        let set = monomials(&mut rng, 2, 0);
        spec.terms.push(TermSpec::Thermal {
            output: rng.int(0, 2) as u8,
            channel: rng.int(0, spec.channels.len() as i64 - 1) as u8,
            t_ref_mc: 20_000,
            coefs_nm_per_k: set.iter().map(|&m| (m, rng.sym(300.0))).collect(),
        });
    }
    spec
}

/// The model and whether fixed point takes the separable path.
fn load(spec: &TableSpec) -> (LargeModel, bool) {
    let bytes = spec.encode().expect("encode");
    let table = parse(&bytes).expect("parse");
    let horner = Features::of(&table).horner;
    (LargeModel::load(&table).expect("load"), horner)
}

/// Inputs inside the envelope, the positions at a travel end on some axes.
fn corner_inputs(rng: &mut Rng, spec: &TableSpec) -> Inputs {
    let mut inp = random_inputs(rng, spec, false);
    let env = &spec.envelope;
    for a in 0..3 {
        match rng.int(0, 3) {
            0 => inp.pos_nm[a] = env.travel_min_nm[a],
            1 => inp.pos_nm[a] = env.travel_max_nm[a],
            _ => {}
        }
    }
    if rng.unit() < 0.3 {
        inp.tool_nm = env.tool_max_nm;
    }
    inp
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn separable_tables_within_1nm_of_f64(seed in any::<u64>(), in_seed in any::<u64>()) {
        let spec = separable_spec(seed);
        let (model, horner) = load(&spec);
        prop_assert!(horner, "the separable path was not taken");
        let mut rng = Rng(in_seed);
        for _ in 0..300 {
            let inp = corner_inputs(&mut rng, &spec);
            let r = spec.eval_f64(&InputsF64::from(&inp));
            let q = model.eval_fixed(&inp);
            prop_assert!(q.flags.is_empty(), "{:?}", q.flags);
            for o in 0..3 {
                prop_assert!((q.corr_nm[o] as f64 - r[o]).abs() <= 1.0, "{} vs {} at {:?}", q.corr_nm[o], r[o], inp);
            }
        }
    }

    #[test]
    fn separable_tables_held_at_edge_and_flagged(seed in any::<u64>(), in_seed in any::<u64>()) {
        let spec = separable_spec(seed);
        let (model, _) = load(&spec);
        let mut rng = Rng(in_seed);
        for _ in 0..100 {
            let inp = random_inputs_beyond(&mut rng, &spec);
            let held = held_inputs(&spec, &inp);
            let expect = expected_edge_flags(&spec, &inp);
            let (out, out_held) = (model.eval_fixed(&inp), model.eval_fixed(&held));
            prop_assert_eq!(out.corr_nm, out_held.corr_nm);
            prop_assert_eq!(out.flags, expect, "{:?}", inp);
            prop_assert!(out_held.flags.is_empty());
        }
    }
}

/// At the limits: every sum's Σ|c_k|·2^k scaled to just inside the path's
/// headroom (block 2^30 nm, Abbe 2^14 rad) and the tool arm's
/// range to ±(2^31 − 1), evaluated in debug (an i32 or i64 overflow
/// panics) at the travel corners (|u| = 2^30, +1 from rounding) and
/// random points, the tool at its ends. Corrections stay within the
/// envelope, and where unclamped within the rows' rounding (q = 0: a few
/// nm) of the f64 reference. Just beyond the headroom the table takes the
/// monomial vector instead.
#[test]
fn extreme_separable_tables_do_not_overflow() {
    let (mut taken, mut compared) = (0, 0);
    for seed in 0..48u64 {
        let mut spec = separable_spec(0xE7_0000 + seed);
        spec.envelope.max_corr_nm = [model_core::table::MAX_CORR_LIMIT_NM; 3];
        spec.envelope.tool_min_nm = -i32::MAX;
        spec.envelope.tool_max_nm = i32::MAX;
        let over = seed % 8 == 7;
        let limit = |abbe: bool| {
            let l = if abbe { 16_384.0 } else { 1_073_741_824.0 };
            if over {
                l * 1.001
            } else {
                l * (1.0 - 1e-6)
            }
        };
        for t in spec.terms.iter_mut() {
            let (coefs, abbe) = match t {
                TermSpec::Poly { coefs, .. } => (coefs, false),
                TermSpec::Abbe { coefs, .. } => (coefs, true),
                // (the thermal term stays realistic)
                _ => continue,
            };
            // The path's sum: Horner runs on u/2, so the coefficient of
            // w·u_a^k counts 2^k times (k = the row axis' exponent − 1).
            let weight = |m: [u8; 3]| f64::from(1u32 << m.iter().max().unwrap().saturating_sub(1));
            let sum: f64 = coefs.iter().map(|c| c.1.abs() * weight(c.0)).sum();
            for c in coefs.iter_mut() {
                c.1 *= limit(abbe) / sum;
            }
        }
        let (model, horner) = load(&spec);
        assert_eq!(horner, !over, "seed {seed}");
        taken += horner as u32;
        let max = model_core::table::MAX_CORR_LIMIT_NM;
        let mut rng = Rng(seed);
        for k in 0..2_000 {
            let mut inp = corner_inputs(&mut rng, &spec);
            inp.tool_nm = [i32::MAX, -i32::MAX, i32::MIN, inp.tool_nm][k % 4];
            let q = model.eval_fixed(&inp);
            let r = spec.eval_f64(&InputsF64::from(&held_inputs(&spec, &inp)));
            for o in 0..3 {
                assert!(q.corr_nm[o].abs() <= max);
                if horner && r[o].abs() < max as f64 - 1000.0 {
                    let err = (q.corr_nm[o] as f64 - r[o]).abs();
                    assert!(err <= 64.0, "seed {seed} output {o}: {err} nm");
                    compared += 1;
                }
            }
        }
    }
    assert!(taken >= 40 && compared > 1_000, "{taken} {compared}");
}

/// Separable tables at the edges the definition check (issue 25) sees:
/// each term scaled by 10^−6 … 10^9, the tool arm's range up to ±2^31 nm
/// on half the draws, nothing clamped. Every one that takes the path and
/// that `board::check` accepts evaluates in fixed point within the bound
/// at 300 inputs of its envelope (the check's static bound uses the
/// path's own scales, `Plan::factored_q`); some are refused (else the
/// test proved nothing).
#[test]
fn separable_edge_tables_the_check_accepts_are_within_the_bound() {
    use model_core::board::{check, LimitError};
    use model_core::definition::{definition_nm, DEFINITION_BOUND_NM};
    let (mut refused, mut accepted) = (0, 0);
    for seed in 0..300u64 {
        let mut spec = separable_spec(0x5E9A_0000 + seed);
        let mut rng = Rng(seed ^ 0xED6E);
        spec.envelope.max_corr_nm = [model_core::table::MAX_CORR_LIMIT_NM; 3];
        if rng.unit() < 0.5 {
            let arm = (10f64.powf(rng.range(3.0, 9.34)) as i64).min(i32::MAX as i64) as i32;
            spec.envelope.tool_min_nm = -arm;
            spec.envelope.tool_max_nm = arm;
        }
        for t in spec.terms.iter_mut() {
            let s = 10f64.powf(rng.range(-6.0, 9.0));
            if let TermSpec::Poly { coefs, .. }
            | TermSpec::Abbe { coefs, .. }
            | TermSpec::Thermal {
                coefs_nm_per_k: coefs,
                ..
            } = t
            {
                for c in coefs.iter_mut() {
                    c.1 *= s;
                }
            }
        }
        let Ok(bytes) = spec.encode() else { continue };
        let table = parse(&bytes).expect("parse");
        let Ok(model) = LargeModel::load(&table) else {
            continue;
        };
        if !Features::of(&table).horner {
            continue;
        }
        match check(&table) {
            Err(LimitError::OffDefinition(_)) => {
                refused += 1;
                continue;
            }
            Ok(()) => accepted += 1,
            Err(_) => continue,
        }
        for _ in 0..300 {
            let inp = corner_inputs(&mut rng, &spec);
            let def = definition_nm(&table, &inp);
            let q = model.eval_fixed(&inp).corr_nm;
            for o in 0..3 {
                let d = (q[o] as f64 - def[o]).abs();
                assert!(d <= DEFINITION_BOUND_NM as f64, "seed {seed}: {d} nm off");
            }
        }
    }
    assert!(refused >= 5 && accepted >= 30, "{refused} {accepted}");
}
