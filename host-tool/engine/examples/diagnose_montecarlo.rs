//! Monte Carlo benchmark of `diagnose` (issue 4; run through
//! `bench/diagnose/run.sh`, which also runs the peers). For every hidden
//! effect family at amplitude ×1 and ×0.3, and for controls with nothing
//! hidden, each ideal and with 0.5 µm of smooth misfit outside the seed's
//! span, `--trials` data sets are simulated (fixed seeds) and diagnosed.
//! Each trial's candidate library (seed-partialled residual and candidate
//! columns, f32) and our result are written to `--out` so that the peers
//! choose among exactly the same columns on exactly the same data.
//!
//! Files per trial: `trial_NNNN.json` (scenario, our result, the layout of
//! the binary) and `trial_NNNN.bin` (per target: the residual, then every
//! column of every group, `rows` little-endian f32 each).

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result};
use serde_json::json;
use trueaxis_engine::diagnose::{diagnose, library, Options};
use trueaxis_engine::simulate::synth::{generate, Hidden, SynthConfig};

const NOISE_UM: f64 = 0.3;

#[derive(Clone, Copy, Debug)]
struct Scenario {
    hidden: Option<Hidden>,
    amplitude: f64,
    misfit_um: f64,
}

fn scenarios() -> Vec<Scenario> {
    let mut v = Vec::new();
    for misfit_um in [0.0, 0.5] {
        v.push(Scenario {
            hidden: None,
            amplitude: 0.0,
            misfit_um,
        });
        for h in Hidden::ALL {
            for amplitude in [1.0, 0.3] {
                v.push(Scenario {
                    hidden: Some(h),
                    amplitude,
                    misfit_um,
                });
            }
        }
    }
    v
}

fn run_trial(id: usize, sc: Scenario, trial: usize, out: &std::path::Path) -> Result<String> {
    let seed = 1_000_003 * (id as u64 + 1) + trial as u64;
    let cfg = SynthConfig {
        seed,
        noise_um: NOISE_UM,
        hidden: sc.hidden.into_iter().collect(),
        amplitude: sc.amplitude,
        misfit_um: sc.misfit_um,
        ..SynthConfig::default()
    };
    let data = generate(&cfg);
    let model = sc.hidden.map_or("cubic19", |h| h.seed());
    let opts = Options::seed(model.parse()?);
    let t0 = std::time::Instant::now();
    let d = diagnose(&data, &opts)?;
    let secs = t0.elapsed().as_secs_f64();
    let best = d
        .best()
        .map(|c| json!({"effect": c.effect, "target": c.target, "axis": c.axis, "add": c.add}));
    let expected = sc.hidden.map(|h| h.expected());
    let correct = match (expected, d.best()) {
        (Some((f, t, a)), Some(c)) => c.effect == f && c.target == t && c.axis.as_deref() == a,
        _ => false,
    };
    // RMS after: the expected target's residual at the end of the path
    // (controls: the worst target's).
    let final_rms = |t: &str| {
        d.path
            .iter()
            .rfind(|s| s.target == t)
            .map_or(d.rms_um[t], |s| s.rms_um)
    };
    let rms_after = match expected {
        Some((_, t, _)) => final_rms(t),
        None => ["ex", "ey", "ez"]
            .iter()
            .map(|t| final_rms(t))
            .fold(0.0, f64::max),
    };
    let lib = library(&data, &opts)?;
    let mut bin = std::io::BufWriter::new(std::fs::File::create(
        out.join(format!("trial_{id:04}.bin")),
    )?);
    let mut layout = Vec::new();
    for tl in &lib {
        for v in &tl.resid_um {
            bin.write_all(&(*v as f32).to_le_bytes())?;
        }
        let mut groups = Vec::new();
        for g in &tl.groups {
            for c in &g.columns {
                for v in c {
                    bin.write_all(&(*v as f32).to_le_bytes())?;
                }
            }
            groups.push(
                json!({"add": g.add, "effect": g.effect, "axis": g.axis, "ncols": g.columns.len()}),
            );
        }
        layout.push(json!({"target": tl.target, "rows": tl.resid_um.len(), "groups": groups}));
    }
    bin.flush()?;
    let meta = json!({
        "id": id,
        "family": sc.hidden.map(|h| h.name()),
        "expected": expected.map(|(f, t, a)| json!({"effect": f, "target": t, "axis": a})),
        "amplitude": sc.amplitude,
        "misfit_um": sc.misfit_um,
        "seed_model": model,
        "noise_um": NOISE_UM,
        "trial": trial,
        "ours": {
            "verdict": d.verdict.as_str(),
            "best": best,
            "correct": correct,
            "path": d.path.iter().map(|s| s.add.clone()).collect::<Vec<_>>(),
            "rms_after_um": rms_after,
            "seconds": secs,
        },
        "targets": layout,
    });
    std::fs::write(
        out.join(format!("trial_{id:04}.json")),
        serde_json::to_string(&meta)?,
    )?;
    Ok(format!(
        "{id:4} {:>12} ×{:<3} misfit {:.1}: {} {}",
        sc.hidden.map_or("control", |h| h.name()),
        sc.amplitude,
        sc.misfit_um,
        if correct { "ok " } else { "-- " },
        d.best()
            .map_or("at_noise_floor".to_string(), |c| c.add.clone())
    ))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let trials: usize = arg("--trials")
        .map_or(Ok(20), |v| v.parse())
        .context("--trials N")?;
    let out = PathBuf::from(arg("--out").context("--out DIR")?);
    let threads: usize = arg("--threads")
        .map_or(Ok(2), |v| v.parse())
        .context("--threads N")?;
    // For iterating on one cell: `--only control|abbe|…`, `--misfit 0.5`
    // and `--amplitude 1` (hidden effects only) keep those scenarios; ids
    // and seeds stay those of the full run.
    let only = arg("--only");
    let amplitude: Option<f64> = arg("--amplitude")
        .map(|v| v.parse())
        .transpose()
        .context("--amplitude A")?;
    let misfit: Option<f64> = arg("--misfit")
        .map(|v| v.parse())
        .transpose()
        .context("--misfit UM")?;
    std::fs::create_dir_all(&out)?;
    let jobs: Vec<(usize, Scenario, usize)> = scenarios()
        .into_iter()
        .flat_map(|s| (0..trials).map(move |t| (s, t)))
        .enumerate()
        .map(|(i, (s, t))| (i, s, t))
        .filter(|(_, s, _)| {
            only.as_deref()
                .is_none_or(|o| o == s.hidden.map_or("control", |h| h.name()))
                && misfit.is_none_or(|m| (m - s.misfit_um).abs() < 1e-9)
                && amplitude.is_none_or(|a| s.hidden.is_some() && (a - s.amplitude).abs() < 1e-9)
        })
        .collect();
    let next = AtomicUsize::new(0);
    let t0 = std::time::Instant::now();
    std::thread::scope(|scope| {
        let hs: Vec<_> = (0..threads.max(1))
            .map(|_| {
                scope.spawn(|| -> Result<()> {
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&(id, sc, t)) = jobs.get(i) else {
                            return Ok(());
                        };
                        let line = run_trial(id, sc, t, &out)?;
                        eprintln!("{line}");
                    }
                })
            })
            .collect();
        for h in hs {
            h.join().expect("worker panicked")?;
        }
        Ok::<(), anyhow::Error>(())
    })?;
    eprintln!(
        "{} trials in {:.0} s",
        jobs.len(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
