//! The data set of the network benchmark (BENCHMARKS.md, `bench/nn_vs_sklearn`),
//! after SEEDS.md's ultra-precision lathe: a 100 × 100 mm area sampled on a
//! 51 × 51 grid (2 mm, 2601 samples), a lead screw of 5 mm pitch whose
//! period shows in the errors, and a smooth straightness / squareness part.
//! The third input is the height of a freeform surface probed on the
//! machine (z = 8·sin(x/30 mm)·cos(y/40 mm) mm), so the network is 3-16-3.
//!
//! Errors (µm), each with Gaussian noise of 0.02 µm from a fixed seed:
//! - ex = 0.4·(x/50 − 1)² − 0.25·(y/50 − 1) + 0.03·z + 0.08·sin(2πx/5)
//! - ey = 0.3·(x/50 − 1)·(y/50 − 1) + 0.2·(y/50 − 1)³ + 0.06·cos(2πy/5)
//! - ez = 0.5·exp(−((x−50)² + (y−50)²)/2000) − 0.02·z + 0.05·sin(2πx/5)
//!
//! The periodic parts are small next to the smooth ones (as on the lathe:
//! 0.18–0.20 µm of straightness per 100 mm), so a 16-neuron network can
//! learn the smooth part and the held-out error measures how well.

use std::f64::consts::TAU;

use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::data::Dataset;

/// The 51 × 51 lathe plane with errors; `seed` drives the noise only.
pub fn lathe_plane(seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut unit = || ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let mut gauss = move || {
        let (u1, u2) = (unit(), unit());
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    };
    let (mut xs, mut ys, mut zs) = (Vec::new(), Vec::new(), Vec::new());
    let mut e: [Vec<Option<f64>>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let noise_um = 0.02;
    for i in 0..51 {
        for j in 0..51 {
            let x = i as f64 * 2.0;
            // Serpentine, as a probe would traverse it.
            let y = if i % 2 == 0 {
                j as f64 * 2.0
            } else {
                100.0 - j as f64 * 2.0
            };
            let z = 8.0 * (x / 30.0).sin() * (y / 40.0).cos();
            let (u, v) = (x / 50.0 - 1.0, y / 50.0 - 1.0);
            let ex = 0.4 * u * u - 0.25 * v + 0.03 * z + 0.08 * (TAU * x / 5.0).sin();
            let ey = 0.3 * u * v + 0.2 * v * v * v + 0.06 * (TAU * y / 5.0).cos();
            let ez = 0.5 * (-((x - 50.0).powi(2) + (y - 50.0).powi(2)) / 2000.0).exp() - 0.02 * z
                + 0.05 * (TAU * x / 5.0).sin();
            for (k, v) in [ex, ey, ez].into_iter().enumerate() {
                e[k].push(Some(v + noise_um * gauss()));
            }
            xs.push(x);
            ys.push(y);
            zs.push(z);
        }
    }
    let [ex, ey, ez] = e;
    Dataset {
        source: "bench:lathe51x51".into(),
        pos_mm: [Some(xs), Some(ys), Some(zs)],
        err_um: [Some(ex), Some(ey), Some(ez)],
        ..Default::default()
    }
}
