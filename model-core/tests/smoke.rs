//! A quick end-to-end check of every term kind: spec → encode → parse →
//! load → eval (f32 and fixed) against the f64 reference.
#![allow(clippy::needless_range_loop)] // per-output index loops mirror [ex, ey, ez]
mod common;

use common::*;
use model_core::{parse, InputsF64, LargeModel};

#[test]
fn every_kind_round_trips_and_matches_reference() {
    for (n, kind) in ALL_KINDS.iter().enumerate() {
        let spec = random_spec(1000 + n as u64, &[*kind]);
        let bytes = spec.encode().unwrap_or_else(|e| panic!("{kind:?}: {e}"));
        let table = parse(&bytes).unwrap();
        let model = LargeModel::load(&table).unwrap_or_else(|e| panic!("{kind:?}: {e}"));
        let mut rng = Rng(7 + n as u64);
        let mut worst = (0.0f64, 0.0f64);
        for _ in 0..2000 {
            let inp = random_inputs(&mut rng, &spec, false);
            let r = spec.eval_f64(&InputsF64::from(&inp));
            let f = model.eval_f32(&inp);
            let q = model.eval_fixed(&inp);
            for o in 0..3 {
                worst.0 = worst.0.max((f.corr_nm[o] as f64 - r[o]).abs());
                worst.1 = worst.1.max((q.corr_nm[o] as f64 - r[o]).abs());
            }
        }
        eprintln!(
            "{kind:?}: worst f32 {:.3} nm, fixed {:.3} nm",
            worst.0, worst.1
        );
        assert!(worst.0 <= 1.0 && worst.1 <= 1.0, "{kind:?}: {worst:?}");
    }
}
