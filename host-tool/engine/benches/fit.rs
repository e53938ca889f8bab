//! Fit benchmarks (BENCHMARKS.md "Fitting (host tool)"):
//!
//! - `cubic19_solve`: design matrix + weighted column-scaled QR/SVD solve of
//!   cubic19 for one target on the seed's 2057-point 17 × 11 × 11 grid
//!   (goal ≤ 2 ms for the fit);
//! - `cubic19_solve_3_targets`: the same for ex, ey and ez at once (one
//!   design matrix, the distinct-point check, one QR + SVD, three
//!   right-hand sides) — fitting the seed's model;
//! - `cubic19_fit_3_targets`: `fit::fit` end to end for ex, ey, ez, including
//!   the 5-block held-out RMS (5 refits per target) and the data hash;
//! - `lm_3_16_3_epoch`: one Levenberg–Marquardt epoch (Jacobian, JᵀJ,
//!   Cholesky solve) of a 3-16-3 network on the 2601-sample lathe set.
//!
//! Run: `cargo bench -p trueaxis --bench fit`. The side-by-side comparison
//! with scikit-learn is `bench/nn_vs_sklearn/run.sh`.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::DVector;

use trueaxis_engine::data::Dataset;
use trueaxis_engine::features::{seed_monomials, Feature, Norm};
use trueaxis_engine::fit::{self, nn, FitOptions};
use trueaxis_engine::linalg::lsq;

/// The seed's 17 × 11 × 11 grid (50 mm, 800 × 500 × 500 mm) with smooth
/// errors and a deterministic pseudo-noise.
fn mill_grid() -> Dataset {
    let [x, y, z] = trueaxis_engine::data::grid_positions([17, 11, 11], [50.0; 3]);
    let n = x.len();
    let err = |t: usize| -> Vec<Option<f64>> {
        (0..n)
            .map(|r| {
                let (u, v, w) = (x[r] / 400.0 - 1.0, y[r] / 250.0 - 1.0, z[r] / 250.0 - 1.0);
                let noise = ((r * 7919 + t * 104_729) % 1000) as f64 / 1000.0 - 0.5;
                Some(
                    3.0 * u - 2.0 * v * v
                        + 1.5 * u * w
                        + 0.8 * (u * 3.0).sin() * (t as f64 + 1.0)
                        + 0.2 * noise,
                )
            })
            .collect()
    };
    Dataset {
        source: "bench:mill".into(),
        err_um: [Some(err(0)), Some(err(1)), Some(err(2))],
        pos_mm: [Some(x), Some(y), Some(z)],
        ..Default::default()
    }
}

fn bench(c: &mut Criterion) {
    let data = mill_grid();
    let norm = Norm::from_data(&data);
    let features: Vec<Feature> = seed_monomials("cubic19", 0, &[0, 1, 2])
        .unwrap()
        .into_iter()
        .map(|exp| Feature::Monomial { exp })
        .collect();
    let rows: Vec<usize> = (0..data.len()).collect();
    let b = DVector::from_iterator(rows.len(), data.measured(0).map(|(_, v)| v));
    c.bench_function("cubic19_solve", |bch| {
        bch.iter(|| {
            let a = lsq::design_matrix(&data, &norm, &features, &rows).unwrap();
            lsq::solve(&a, &b, None).unwrap()
        })
    });
    // The model's fit proper: one design matrix, one QR + SVD, the three
    // targets as right-hand sides (what `fit` does when ex, ey, ez are
    // measured on the same rows), without the held-out refits.
    let b3 = nalgebra::DMatrix::from_fn(rows.len(), 3, |i, t| {
        data.err_um[t].as_ref().unwrap()[rows[i]].unwrap()
    });
    c.bench_function("cubic19_solve_3_targets", |bch| {
        bch.iter(|| {
            let a = lsq::design_matrix(&data, &norm, &features, &rows).unwrap();
            lsq::distinct_rows(&a);
            lsq::solve_multi(&a, &b3, None).unwrap()
        })
    });
    c.bench_function("cubic19_fit_3_targets", |bch| {
        bch.iter(|| fit::fit(&data, "cubic19", &[], &FitOptions::default()).unwrap())
    });

    let lathe = trueaxis_engine::fit::bench_data::lathe_plane(1);
    let split = nn::split(&lathe, 5);
    let opts = nn::NnOptions {
        max_epochs: 1,
        max_fail: 1000,
        restarts: 1,
        ..Default::default()
    };
    c.bench_function("lm_3_16_3_epoch", |bch| {
        bch.iter(|| {
            nn::train(
                &lathe,
                16,
                &opts,
                &split,
                &Default::default(),
                &mut |_, _| {},
            )
            .unwrap()
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
