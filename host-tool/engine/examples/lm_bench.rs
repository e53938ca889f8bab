//! Levenberg–Marquardt side of `bench/nn_vs_sklearn`: trains the 3-16-3
//! network of `trueaxis fit --model nn:16` on the 2601-sample lathe set
//! (`fit::bench_data::lathe_plane`), writes the data and the block split it
//! used to `<out>/lathe.csv` so scikit-learn trains on exactly the same rows,
//! and prints one JSON line per epoch: wall time since the start of training
//! (excluding the time spent here measuring held-out error), training MSE and
//! the validation / test RMS in µm.
//!
//! `cargo run --release -p trueaxis-engine --example lm_bench -- <out_dir> [seed] [hidden] [max_fail] [max_epochs] [restarts]`
//! (max_fail 6 and max_epochs 1000 are trainlm's defaults and `fit`'s;
//! restarts defaults to `fit`'s `nn::RESTARTS`). The epoch lines of all
//! restarts share one clock, so the final line's time is the whole training
//! — every restart counted — and its held-out RMS is the kept network's.

use std::io::Write;
use std::time::{Duration, Instant};

use trueaxis_engine::data::Dataset;
use trueaxis_engine::fit::{bench_data, nn};
use trueaxis_engine::model::{FittedModel, NnModel};

fn rms_on(m: &NnModel, data: &Dataset, rows: &[usize]) -> f64 {
    let sub = trueaxis_engine::data::subset(data, rows);
    let pred = FittedModel::Nn(m.clone())
        .predict(&sub)
        .expect("prediction");
    let mut ss = 0.0;
    let mut n = 0usize;
    for (p, e) in pred.iter().zip(&sub.err_um) {
        if let (Some(p), Some(e)) = (p, e) {
            for (pv, ev) in p.iter().zip(e) {
                if let Some(ev) = ev {
                    ss += (ev - pv).powi(2);
                    n += 1;
                }
            }
        }
    }
    (ss / n.max(1) as f64).sqrt()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let out = std::path::PathBuf::from(args.get(1).map_or("/tmp/lm_bench", String::as_str));
    let seed: u64 = args.get(2).map_or(Ok(1), |s| s.parse())?;
    let hidden: usize = args.get(3).map_or(Ok(16), |s| s.parse())?;
    std::fs::create_dir_all(&out)?;
    let data = bench_data::lathe_plane(1);
    let split = nn::split(&data, 5);

    // The data with its split, for scikit-learn.
    let mut f = std::io::BufWriter::new(std::fs::File::create(out.join("lathe.csv"))?);
    writeln!(f, "x_mm,y_mm,z_mm,ex_um,ey_um,ez_um,set")?;
    for (set, rows) in [
        ("train", &split.train),
        ("val", &split.val),
        ("test", &split.test),
    ] {
        for &r in rows.iter() {
            let e = |t: usize| {
                data.err_um[t]
                    .as_ref()
                    .and_then(|c| c[r])
                    .unwrap_or(f64::NAN)
            };
            writeln!(
                f,
                "{},{},{},{},{},{},{set}",
                data.pos(0, r),
                data.pos(1, r),
                data.pos(2, r),
                e(0),
                e(1),
                e(2)
            )?;
        }
    }
    f.flush()?;

    let max_fail: usize = args.get(4).map_or(Ok(6), |s| s.parse())?;
    let max_epochs: usize = args.get(5).map_or(Ok(1000), |s| s.parse())?;
    let restarts: usize = args.get(6).map_or(Ok(nn::RESTARTS), |s| s.parse())?;
    let opts = nn::NnOptions {
        seed,
        max_fail,
        max_epochs,
        restarts,
        ..Default::default()
    };
    let start = Instant::now();
    let mut measuring = Duration::ZERO;
    let trained = nn::train_restarts(
        &data,
        hidden,
        &opts,
        &split,
        &Default::default(),
        &mut |ep, m| {
            let t0 = Instant::now();
            let train_time = t0 - start - measuring;
            let val = rms_on(m, &data, &split.val);
            let test = rms_on(m, &data, &split.test);
            println!(
            "{{\"restart\": {}, \"epoch\": {}, \"t_s\": {:.6}, \"train_mse\": {:.6e}, \"val_rms_um\": {:.6}, \"test_rms_um\": {:.6}, \"mu\": {:.1e}}}",
            ep.restart,
            ep.epoch,
            train_time.as_secs_f64(),
            ep.train_mse,
            val,
            test,
            ep.mu
        );
            measuring += t0.elapsed();
        },
    )?;
    let total = start.elapsed() - measuring;
    let model = &trained.model;
    println!(
        "{{\"final\": true, \"t_s\": {:.6}, \"restarts\": {}, \"kept\": {}, \"val_mse_scaled\": {:?}, \"epochs\": {}, \"best_epoch\": {}, \"stop\": \"{}\", \"val_rms_um\": {:.6}, \"test_rms_um\": {:.6}, \"split\": [{}, {}, {}]}}",
        total.as_secs_f64(),
        restarts,
        trained.kept,
        trained.scores,
        model.training.epochs,
        model.training.best_epoch,
        model.training.stop,
        rms_on(model, &data, &split.val),
        rms_on(model, &data, &split.test),
        split.train.len(),
        split.val.len(),
        split.test.len()
    );
    Ok(())
}
