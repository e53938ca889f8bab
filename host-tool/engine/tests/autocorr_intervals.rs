//! Intervals that hold on time series (issue 24): a line along x read
//! over and over, one reading a minute, whose error is a slowly wandering
//! AR(1) (ρ 0.99) with no drift at all. The `drift` rate's 95 % interval
//! computed as if the readings were independent excludes the true rate 0
//! on most seeds; widened by √(n/n_eff) it covers it on most.

use trueaxis_engine::data::Dataset;
use trueaxis_engine::diagnose::{diagnose, Options};
use trueaxis_engine::model::Seed;
use trueaxis_test_support::SplitMix64;

fn wandering(seed: u64) -> Dataset {
    let n = 1500;
    let mut rng = SplitMix64(seed);
    let mut w = 0.0;
    let mut x = Vec::new();
    let mut t = Vec::new();
    let mut ex = Vec::new();
    for i in 0..n {
        w = 0.99 * w + 0.3 * rng.normal();
        x.push((i % 10) as f64 * 50.0);
        t.push(i as f64 * 60.0);
        ex.push(Some(w + 0.05 * rng.normal()));
    }
    Dataset {
        source: "wandering".into(),
        pos_mm: [Some(x), None, None],
        err_um: [Some(ex), None, None],
        t_s: Some(t),
        line: (2..n + 2).collect(),
        ..Default::default()
    }
}

#[test]
fn drift_interval_covers_the_truth_once_widened() {
    let (mut old_cover, mut new_cover, runs) = (0, 0, 12);
    for seed in 0..runs {
        let data = wandering(seed);
        let opts = Options::seed(Seed::Cubic19);
        let d = diagnose(&data, &opts).unwrap();
        let n_eff = d.n_eff["ex"];
        assert!(
            d.lag1_autocorrelation["ex"] > 0.8,
            "{:?}",
            d.lag1_autocorrelation
        );
        assert!(d
            .warnings
            .iter()
            .any(|w| w.code == "autocorrelated_residuals"));
        let ph = d
            .candidates
            .iter()
            .filter(|c| c.add.starts_with("drift"))
            .find_map(|c| c.physical.clone())
            .unwrap_or_else(|| {
                let adds: Vec<&str> = d.candidates.iter().map(|c| c.add.as_str()).collect();
                panic!("no drift rate among {adds:?}")
            });
        let widen = (1500.0 / n_eff).sqrt();
        let half = (ph.ci95[1] - ph.ci95[0]) / 2.0;
        let old = [ph.value - half / widen, ph.value + half / widen];
        old_cover += usize::from(old[0] <= 0.0 && 0.0 <= old[1]);
        new_cover += usize::from(ph.ci95[0] <= 0.0 && 0.0 <= ph.ci95[1]);
    }
    eprintln!("coverage of the true rate 0: {old_cover}/{runs} before, {new_cover}/{runs} widened");
    assert!(
        old_cover * 2 < runs as usize,
        "old intervals covered {old_cover}/{runs}"
    );
    assert!(
        new_cover * 4 >= 3 * runs as usize,
        "widened covered {new_cover}/{runs}"
    );
}
