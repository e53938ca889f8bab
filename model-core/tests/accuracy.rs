//! The evaluation guarantees, proptested over random models of realistic
//! size (every term kind, mixtures of them) and the whole envelope:
//! - f32 and fixed point within 1 nm of the f64 reference (`TableSpec::eval_f64`);
//! - outside the travel the position is held at the edge and flagged, and so
//!   are temperatures and the tool arm outside their ranges when the table
//!   reads them;
//! - no panic, no NaN, no overflow for any i32 inputs; corrections never
//!   exceed the envelope's max and are flagged when limited.
#![allow(clippy::needless_range_loop)] // per-output index loops mirror [ex, ey, ez]
mod common;

use common::*;
use model_core::{parse, Flags, Inputs, InputsF64, LargeModel, Model, TableSpec};
use proptest::prelude::*;

fn load(spec: &TableSpec) -> LargeModel {
    let bytes = spec.encode().expect("encode");
    LargeModel::load(&parse(&bytes).expect("parse")).expect("load")
}

fn kinds_strategy() -> impl Strategy<Value = Vec<Kind>> {
    prop::collection::vec(prop::sample::select(ALL_KINDS.to_vec()), 1..5)
}

/// Worst |eval − reference| over `n` random inputs inside the envelope.
fn worst_errors(spec: &TableSpec, model: &LargeModel, seed: u64, n: usize) -> (f64, f64) {
    let mut rng = Rng(seed);
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..n {
        let inp = random_inputs(&mut rng, spec, false);
        let r = spec.eval_f64(&InputsF64::from(&inp));
        let f = model.eval_f32(&inp);
        let q = model.eval_fixed(&inp);
        assert!(
            f.flags.is_empty() && q.flags.is_empty(),
            "flags inside the envelope: {f:?} {q:?}"
        );
        for o in 0..3 {
            worst.0 = worst.0.max((f.corr_nm[o] as f64 - r[o]).abs());
            worst.1 = worst.1.max((q.corr_nm[o] as f64 - r[o]).abs());
        }
    }
    worst
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn f32_and_fixed_within_1nm_of_f64(seed in any::<u64>(), kinds in kinds_strategy(), in_seed in any::<u64>()) {
        let spec = random_spec(seed, &kinds);
        let model = load(&spec);
        let (wf, wq) = worst_errors(&spec, &model, in_seed, 300);
        prop_assert!(wf <= 1.0, "f32 off by {wf} nm for {kinds:?}");
        prop_assert!(wq <= 1.0, "fixed off by {wq} nm for {kinds:?}");
    }

    #[test]
    fn held_at_edge_and_flagged_outside_travel(seed in any::<u64>(), kinds in kinds_strategy(), in_seed in any::<u64>()) {
        let spec = random_spec(seed, &kinds);
        let model = load(&spec);
        let mut rng = Rng(in_seed);
        for _ in 0..100 {
            let inp = random_inputs_beyond(&mut rng, &spec);
            let held = held_inputs(&spec, &inp);
            // Temperatures and the tool arm are held and flagged only when
            // the table reads them.
            let expect = expected_edge_flags(&spec, &inp);
            let edge_flags = Flags::TEMP_OUT_OF_RANGE | Flags::TOOL_OUT_OF_RANGE
                | Flags::out_of_travel(0) | Flags::out_of_travel(1) | Flags::out_of_travel(2);
            for (out, out_held) in [(model.eval_f32(&inp), model.eval_f32(&held)), (model.eval_fixed(&inp), model.eval_fixed(&held))] {
                // Held at the edge: the same correction as at the edge itself.
                prop_assert_eq!(out.corr_nm, out_held.corr_nm);
                // Exactly the inputs that were held (and the table reads) are flagged.
                prop_assert_eq!(Flags::from_bits(out.flags.bits() & edge_flags.bits()), expect, "{:?} for {:?}", out.flags, inp);
                prop_assert!(out_held.flags.is_empty());
            }
        }
    }

    #[test]
    fn any_inputs_no_panic_and_bounded(seed in any::<u64>(), kinds in kinds_strategy(),
                                      pos in any::<[i32; 3]>(), rev in any::<[i32; 3]>(),
                                      temp in any::<[i32; 4]>(), tool in any::<i32>(), max_corr in 0i32..300_000) {
        let mut spec = random_spec(seed, &kinds);
        spec.envelope.max_corr_nm = [max_corr; 3];
        let model = load(&spec);
        let inp = Inputs { pos_nm: pos, rev_q30: rev, temp_mc: temp, tool_nm: tool };
        for out in [model.eval_f32(&inp), model.eval_fixed(&inp)] {
            for o in 0..3 {
                prop_assert!(out.corr_nm[o].abs() <= max_corr);
            }
        }
    }
}

/// Deterministic, larger sweep per kind (fixed seeds): the same bound on
/// 20 000 inputs each, so a regression in one kind shows by name.
#[test]
fn per_kind_sweep_within_1nm() {
    for (n, kind) in ALL_KINDS.iter().enumerate() {
        for s in 0..4u64 {
            let spec = random_spec(0xACC0 + 16 * n as u64 + s, &[*kind]);
            let model = load(&spec);
            let (wf, wq) = worst_errors(&spec, &model, 99 + s, 5000);
            assert!(
                wf <= 1.0 && wq <= 1.0,
                "{kind:?} seed {s}: f32 {wf} nm, fixed {wq} nm"
            );
        }
    }
}

/// The tool arm (Abbe terms) beyond its range is held at the edge and flagged
/// `TOOL_OUT_OF_RANGE`, in f32 and fixed point; a table without Abbe terms
/// ignores the arm and never raises the flag.
#[test]
fn tool_arm_held_at_edge_and_flagged() {
    let mut seen = 0;
    for s in 0..8u64 {
        let spec = random_spec(0x7001 + s, &[Kind::Cubic19, Kind::Abbe]);
        let model = load(&spec);
        let env = spec.envelope;
        let inside = random_inputs(&mut Rng(s), &spec, false);
        for (tool, edge) in [
            (env.tool_min_nm - 1, env.tool_min_nm),
            (env.tool_max_nm + 1, env.tool_max_nm),
            (i32::MIN, env.tool_min_nm),
            (i32::MAX, env.tool_max_nm),
        ] {
            let inp = Inputs {
                tool_nm: tool,
                ..inside
            };
            let at_edge = Inputs {
                tool_nm: edge,
                ..inside
            };
            for (out, want) in [
                (model.eval_f32(&inp), model.eval_f32(&at_edge)),
                (model.eval_fixed(&inp), model.eval_fixed(&at_edge)),
            ] {
                assert_eq!(out.corr_nm, want.corr_nm, "tool {tool} held at {edge}");
                assert_eq!(out.flags, Flags::TOOL_OUT_OF_RANGE, "tool {tool}");
                assert!(want.flags.is_empty());
            }
            // The arm matters: at the edge the correction differs from a
            // mid-range arm's (else holding it would go untested).
            let mid = Inputs {
                tool_nm: (env.tool_min_nm + env.tool_max_nm) / 2,
                ..inside
            };
            if model.eval_fixed(&mid).corr_nm != model.eval_fixed(&at_edge).corr_nm {
                seen += 1;
            }
        }
        // Without Abbe terms the arm is not read: no flag, no change.
        let spec = random_spec(0x7001 + s, &[Kind::Cubic19]);
        let model = load(&spec);
        let far = Inputs {
            tool_nm: i32::MIN,
            ..inside
        };
        assert_eq!(model.eval_fixed(&far), model.eval_fixed(&inside));
        assert_eq!(model.eval_f32(&far), model.eval_f32(&inside));
    }
    assert!(
        seen >= 16,
        "the arm changed the correction in only {seen} of 32 cases"
    );
}

#[test]
fn clamped_and_flagged_at_max_correction() {
    let mut spec = random_spec(5, &[Kind::Cubic19]);
    spec.envelope.max_corr_nm = [10, 10, 10];
    let model = load(&spec);
    let mut rng = Rng(1);
    let mut seen = false;
    for _ in 0..200 {
        let inp = random_inputs(&mut rng, &spec, false);
        let r = spec.eval_f64(&InputsF64::from(&inp));
        for out in [model.eval_f32(&inp), model.eval_fixed(&inp)] {
            for o in 0..3 {
                assert!(out.corr_nm[o].abs() <= 10);
                if r[o].abs() > 11.0 {
                    assert!(out.flags.contains(Flags::CLAMPED));
                    assert_eq!(out.corr_nm[o], 10 * r[o].signum() as i32);
                    seen = true;
                }
            }
        }
    }
    assert!(seen);
}

#[test]
fn nan_coefficients_are_rejected_and_huge_ones_are_typed_errors() {
    let mut spec = random_spec(3, &[Kind::Cubic19]);
    if let model_core::TermSpec::Poly { coefs, .. } = &mut spec.terms[0] {
        coefs[0].1 = f64::NAN;
    }
    assert!(matches!(
        spec.encode(),
        Err(model_core::EncodeError::Invalid(
            model_core::TableError::NotFinite { .. }
        ))
    ));
    let mut spec = random_spec(3, &[Kind::Cubic19]);
    if let model_core::TermSpec::Poly { coefs, .. } = &mut spec.terms[0] {
        coefs[0].1 = 1e12;
    }
    let bytes = spec.encode().unwrap();
    assert!(matches!(
        Model::load(&parse(&bytes).unwrap()),
        Err(model_core::LoadError::CoefficientRange { .. })
    ));
}

#[test]
fn capacity_exceeded_is_a_typed_error_and_large_alias_fits_17x11x11x3() {
    let mut rng = Rng(11);
    let mut spec = base_spec(&mut rng, 1);
    for o in 0..3u8 {
        let axes = [
            model_core::GridAxisSpec {
                nodes: 17,
                origin_nm: spec.envelope.travel_min_nm[0],
                step_nm: 1_000_000,
            },
            model_core::GridAxisSpec {
                nodes: 11,
                origin_nm: spec.envelope.travel_min_nm[1],
                step_nm: 1_000_000,
            },
            model_core::GridAxisSpec {
                nodes: 11,
                origin_nm: spec.envelope.travel_min_nm[2],
                step_nm: 1_000_000,
            },
        ];
        spec.terms
            .push(model_core::TermSpec::Grid(model_core::GridSpec {
                output: o,
                axes,
                values_nm: (0..17 * 11 * 11).map(|_| rng.sym(20_000.0)).collect(),
            }));
    }
    let bytes = spec.encode().unwrap();
    let table = parse(&bytes).unwrap();
    assert!(matches!(
        Model::load(&table),
        Err(model_core::LoadError::GridCapacity { needed: 6171, .. })
    ));
    assert!(LargeModel::load(&table).is_ok());
    // The default model stays small enough for the MCU's 128 KiB of RAM.
    eprintln!(
        "Model: {} bytes, LargeModel: {} bytes",
        core::mem::size_of::<Model>(),
        core::mem::size_of::<LargeModel>()
    );
    assert!(
        core::mem::size_of::<Model>() <= 40 * 1024,
        "Model is {} bytes",
        core::mem::size_of::<Model>()
    );
    assert!(
        core::mem::size_of::<LargeModel>() <= 48 * 1024,
        "LargeModel is {} bytes",
        core::mem::size_of::<LargeModel>()
    );
}

#[test]
fn dir_tracker_ramps_without_steps() {
    let mut t = model_core::DirTracker::new();
    assert_eq!(t.update(0, 1000), 0);
    // 250 nm forward from unknown: a quarter of a full swing → 0.5.
    assert_eq!(t.update(250, 1000), 1 << 29);
    assert_eq!(t.update(1000, 1000), 1 << 30); // saturated at +1
    assert_eq!(t.update(500, 1000), 0); // 500 back: half a swing
    assert_eq!(t.update(-10_000_000, 1000), -(1 << 30));
    // Extreme moves never overflow.
    assert_eq!(t.update(i32::MAX, 1), 1 << 30);
    assert_eq!(t.update(i32::MIN, i32::MAX), -(1 << 30));
    // Small steps: the change per step is bounded by the step's share of the swing.
    let mut t = model_core::DirTracker::new();
    t.update(0, 5000);
    let mut prev = 0i64;
    for p in 1..20_000 {
        let r = t.update(p, 5000) as i64;
        assert!((r - prev).abs() <= (1i64 << 31) / 5000 + 1);
        prev = r;
    }
}

/// Tables at the edges of what load accepts (`common::extreme_spec`: huge
/// grid values, coefficient sums just under the fixed-point limit, large
/// amplitudes, steep MLPs):
/// evaluating them with any inputs must not overflow (this test is meant to
/// run in debug, where integer overflow panics).
#[test]
fn extreme_but_valid_models_never_overflow() {
    let mut rng = Rng(4242);
    let mut loaded = 0;
    for round in 0..40 {
        let spec = extreme_spec(round, &mut rng);
        let bytes = match spec.encode() {
            Ok(b) => b,
            Err(e) => {
                eprintln!("round {round}: {e}");
                continue;
            }
        };
        let table = parse(&bytes).unwrap();
        let model = match LargeModel::load(&table) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("round {round}: {e}");
                continue;
            }
        };
        loaded += 1;
        for _ in 0..200 {
            let inp = random_inputs(&mut rng, &spec, true);
            let _ = model.eval_f32(&inp);
            let _ = model.eval_fixed(&inp);
        }
        for v in [i32::MIN, -1, 0, 1, i32::MAX] {
            let inp = Inputs {
                pos_nm: [v; 3],
                rev_q30: [v; 3],
                temp_mc: [v; 4],
                tool_nm: v,
            };
            let _ = model.eval_f32(&inp);
            let _ = model.eval_fixed(&inp);
        }
    }
    assert!(loaded >= 20, "only {loaded} of 40 extreme models loaded");
}

#[test]
fn load_into_reuses_a_static_and_a_failed_load_leaves_it_empty() {
    static EMPTY: Model = Model::empty();
    let mut m = EMPTY.clone();
    let spec = random_spec(8, &[Kind::Cubic19, Kind::Periodic]);
    let bytes = spec.encode().unwrap();
    m.load_into(&parse(&bytes).unwrap()).unwrap();
    let inp = random_inputs(&mut Rng(3), &spec, false);
    let reference = LargeModel::load(&parse(&bytes).unwrap()).unwrap();
    assert_eq!(m.eval_fixed(&inp), reference.eval_fixed(&inp));
    // A table that does not fit: typed error, and the model is empty, not half-loaded.
    let mut big = random_spec(9, &[Kind::Grid]);
    if let model_core::TermSpec::Grid(g) = &mut big.terms[0] {
        g.axes = [model_core::GridAxisSpec {
            nodes: 20,
            origin_nm: 0,
            step_nm: 1000,
        }; 3];
        g.values_nm = vec![1.0; 8000];
    }
    let bytes = big.encode().unwrap();
    assert!(matches!(
        m.load_into(&parse(&bytes).unwrap()),
        Err(model_core::LoadError::GridCapacity { .. })
    ));
    assert_eq!(m.outputs_mask(), 0);
    assert_eq!(m.eval_fixed(&inp).corr_nm, [0; 3]);
    assert_eq!(m.eval_f32(&inp).corr_nm, [0; 3]);
}

/// A polynomial-only table with absent outputs takes the fixed-point
/// polynomial kernel (priced as it: `cost`'s POLY3_FIXED, 500) and stays
/// within 1 nm of f64 — an absent output's empty block once sent such
/// tables to the general path.
#[test]
fn polynomial_table_with_absent_outputs_takes_the_kernel() {
    for seed in 0..8 {
        let mut spec = random_spec(0x5100 + seed, &[Kind::Cubic19]);
        let keep = (seed % 3) as u8;
        spec.terms
            .retain(|t| matches!(t, model_core::TermSpec::Poly { output, .. } if *output == keep));
        spec.outputs = core::array::from_fn(|o| o as u8 == keep);
        let bytes = spec.encode().expect("encode");
        let table = parse(&bytes).expect("parse");
        assert_eq!(
            model_core::cost::estimate(&table).fixed_instr,
            500,
            "seed {seed}"
        );
        let model = load(&spec);
        let (wf, wq) = worst_errors(&spec, &model, seed, 500);
        assert!(
            wf <= 1.0 && wq <= 1.0,
            "seed {seed}: f32 {wf} nm, fixed {wq} nm"
        );
    }
}
