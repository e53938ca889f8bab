//! Host-side criterion benches of model evaluation: f32 and fixed point per
//! model kind (the golden tables the MCU benches also use, plus one table per
//! single term kind), and parse + load of a table. Run with
//! `cargo bench -p model-core --features std --bench eval`.
//! MCU instruction counts come from `cargo xtask bench-mcu` (QEMU), not here.
#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;

use common::*;
use criterion::{criterion_group, criterion_main, Criterion};
use model_core::{parse, LargeModel};

fn bench_eval(c: &mut Criterion) {
    let mut tables: Vec<(String, model_core::TableSpec)> = golden_specs()
        .into_iter()
        .map(|(n, s)| (n.to_string(), s))
        .collect();
    for (name, kind) in [
        ("kinematic", Kind::Kinematic),
        ("degree5", Kind::Degree5),
        ("periodic", Kind::Periodic),
        ("thermal", Kind::Thermal),
        ("reversal", Kind::Reversal),
        ("abbe", Kind::Abbe),
        ("grid_random", Kind::Grid),
    ] {
        tables.push((name.to_string(), random_spec(77, &[kind])));
    }
    let mut g = c.benchmark_group("eval");
    for (name, spec) in &tables {
        let bytes = spec.encode().unwrap();
        let model = LargeModel::load(&parse(&bytes).unwrap()).unwrap();
        let mut rng = Rng(5);
        let inputs: Vec<_> = (0..64)
            .map(|_| random_inputs(&mut rng, spec, false))
            .collect();
        g.bench_function(format!("{name}_f32"), |b| {
            let mut i = 0;
            b.iter(|| {
                i = (i + 1) & 63;
                black_box(model.eval_f32(black_box(&inputs[i])))
            })
        });
        g.bench_function(format!("{name}_fixed"), |b| {
            let mut i = 0;
            b.iter(|| {
                i = (i + 1) & 63;
                black_box(model.eval_fixed(black_box(&inputs[i])))
            })
        });
    }
    g.finish();
    let mut g = c.benchmark_group("load");
    for (name, spec) in tables
        .iter()
        .filter(|(n, _)| n == "cubic19" || n == "all_kinds")
    {
        let bytes = spec.encode().unwrap();
        g.bench_function(format!("{name}_parse"), |b| {
            b.iter(|| black_box(parse(black_box(&bytes)).unwrap()))
        });
        g.bench_function(format!("{name}_parse_load"), |b| {
            b.iter(|| black_box(LargeModel::load(&parse(black_box(&bytes)).unwrap()).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_eval);
criterion_main!(benches);
