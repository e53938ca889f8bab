//! `simulate`: a synthetic machine measured along a plan, for tests, demos
//! and benchmarks. The geometric errors come from [`Machine`]; on top of
//! them optional physical [`Effect`]s (lead-screw periodic error, thermal
//! growth, reversal, Abbe via tool length, drift — each family's simulated
//! form lives in its file of `effect/` — and the guide [`Bump`]), then
//! Gaussian noise.
//!
//! Everything is constructible from Rust (the diagnosis tests and the Monte
//! Carlo benchmark build configs directly) and from spec strings (the CLI;
//! `spec.rs`). A fixed seed gives the same [`Dataset`] and therefore a
//! byte-identical CSV: the only randomness is a ChaCha8 stream, turned into
//! floats and normals by hand-written code that no crate upgrade changes.
//!
//! [`synth`] is the diagnosis' small mill with an answer key (hidden
//! effects of known family and place, misfit outside the seed's span by
//! construction), for the diagnosis tests and the Monte Carlo benchmark;
//! it draws from its own SplitMix64 stream (`splitmix.rs`).
//!
//! Output resolution: errors are rounded to 0.1 nm, t_s to 1 ms,
//! temperatures to 1 mK (an instrument's display), and every effect is
//! computed from the rounded temperature the file shows.

mod bump;
mod config;
pub mod instruments;
mod machine;
mod plan;
mod spec;
pub mod spindle_duty;
mod splitmix;
pub mod synth;
pub mod thermal_test;
pub mod volumetric;

use std::f64::consts::TAU;

use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::data::{Dataset, TempChannel};
use crate::effect::SimRows;

pub use bump::Bump;
pub use config::{
    BadSpikes, ConfigError, Effect, Limit, OutOfRange, RefReturn, Setting, SimConfig, Spikes,
    Timing,
};
pub use machine::{AxisErrors, ErrorFn, Machine, Realistic, Squareness, Wave, PRESETS, REALISTIC};
pub use plan::{iso_targets, stations, Plan, Visit};
pub use thermal_test::{scenario, SCENARIOS};

/// The simulated data and what it would be without noise.
#[derive(Clone, Debug, PartialEq)]
pub struct SimOutput {
    /// The measurement data set (as written to CSV).
    pub data: Dataset,
    /// Noise-free errors ex, ey, ez per row, µm (geometry + effects).
    pub truth_um: [Vec<f64>; 3],
    /// The error values that got a spike (`SimConfig::spikes`): (row, target).
    pub spikes: Vec<(usize, usize)>,
}

/// Standard normal from two uniforms (Box–Muller). Hand-written rather than
/// rand_distr so that the stream a seed gives never changes with a crate
/// version: the byte-identical-file promise depends on it.
pub(crate) fn normal(rng: &mut impl RngCore) -> f64 {
    let u1 = 1.0 - plan::unit(rng); // (0, 1]: ln is finite
    let u2 = plan::unit(rng);
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

/// Rounds to `decimals` places. Multiplying and dividing by the power of
/// ten (rather than multiplying by 1e-4) gives the double nearest the
/// decimal, so the CSV shows `0.1214`, not `0.12140000000000001`.
fn round_dec(v: f64, decimals: i32) -> f64 {
    let p = 10f64.powi(decimals);
    (v * p).round() / p
}

/// Simulates the measurement. Call [`SimConfig::check`] first for a clear
/// message on a nonsensical config; `simulate` itself never fails (an empty
/// plan list gives an empty data set).
pub fn simulate(cfg: &SimConfig) -> Dataset {
    simulate_detailed(cfg).data
}

/// As [`simulate`], also returning the noise-free truth.
// Rows are indexed across several parallel columns; index loops read clearer.
#[allow(clippy::needless_range_loop)]
pub fn simulate_detailed(cfg: &SimConfig) -> SimOutput {
    // Separate streams: the targets do not move when the noise level or the
    // number of points changes.
    let mut rng_plan = ChaCha8Rng::seed_from_u64(cfg.seed);
    rng_plan.set_stream(1);
    let mut rng_noise = ChaCha8Rng::seed_from_u64(cfg.seed);
    rng_noise.set_stream(2);

    // 1. Expand plans into visits with global pass ids; a reference visit
    // is a pass of its own, before the first pass and then after every
    // `every_passes` passes, and once more at the end.
    let mut visits: Vec<(Visit, usize)> = Vec::new(); // (visit, global pass)
                                                      // Pauses before visit index i: (idle s, starts a new session).
    let mut pauses: Vec<(usize, f64, bool)> = Vec::new();
    let mut next_pass = 0usize;
    let mut since_ref: Option<usize> = None; // None: not visited yet
    for p in &cfg.plans {
        if let Plan::Pause {
            duration_s,
            new_session,
        } = p
        {
            pauses.push((visits.len(), *duration_s, *new_session));
            continue;
        }
        let mut cur: Option<(usize, usize)> = None; // (local pass, global pass)
        for v in p.visits(cfg.machine.travel_mm, &mut rng_plan) {
            if cur.map(|c| c.0) != Some(v.pass) {
                if let Some(r) = &cfg.reference {
                    if since_ref.is_none_or(|k| k >= r.every_passes) {
                        let rv = Visit {
                            pos_mm: r.pos_mm,
                            via_mm: None,
                            pass: 0,
                        };
                        visits.push((rv, next_pass));
                        next_pass += 1;
                        since_ref = Some(0);
                    }
                }
                cur = Some((v.pass, next_pass));
                next_pass += 1;
                if let Some(k) = since_ref.as_mut() {
                    *k += 1;
                }
            }
            let g = cur.map_or(0, |c| c.1);
            visits.push((v, g));
        }
    }
    if let (Some(r), false) = (&cfg.reference, visits.is_empty()) {
        let rv = Visit {
            pos_mm: r.pos_mm,
            via_mm: None,
            pass: 0,
        };
        visits.push((rv, next_pass));
    }

    // 2. Walk them: time, approach directions, tool length.
    let n = visits.len();
    let abbe_tools: Option<&[f64]> = cfg.effects.iter().find_map(|e| e.form().tools_mm());
    let mut pos = visits.first().map_or([0.0; 3], |v| v.0.pos_mm);
    let mut dir = [1i8; 3];
    let mut t = 0.0f64;
    let mut rows_pos = [
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    ];
    let mut rows_dir = [
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    ];
    let mut rows_t = Vec::with_capacity(n);
    let mut rows_pass = Vec::with_capacity(n);
    let mut rows_tool = Vec::with_capacity(n);
    let mut rows_session = Vec::with_capacity(n);
    let mut session = 1i64;
    let go = |to: [f64; 3], pos: &mut [f64; 3], dir: &mut [i8; 3], t: &mut f64| {
        let mut dist = 0.0f64;
        for a in 0..3 {
            let d = to[a] - pos[a];
            if d.abs() > 1e-9 {
                dir[a] = if d > 0.0 { 1 } else { -1 };
            }
            dist = dist.max(d.abs());
        }
        *t += dist / cfg.timing.feed_mm_s;
        *pos = to;
    };
    for (i, (v, g)) in visits.iter().enumerate() {
        for &(_, idle_s, new_session) in pauses.iter().filter(|p| p.0 == i) {
            t += idle_s;
            if new_session {
                session += 1;
                t = 0.0;
            }
        }
        if let Some(via) = v.via_mm {
            go(via, &mut pos, &mut dir, &mut t);
        }
        go(v.pos_mm, &mut pos, &mut dir, &mut t);
        t += cfg.timing.dwell_s;
        for a in 0..3 {
            rows_pos[a].push(v.pos_mm[a]);
            rows_dir[a].push(dir[a]);
        }
        rows_t.push(round_dec(t, 3));
        rows_pass.push(*g as i64);
        rows_session.push(session);
        rows_tool.push(match abbe_tools {
            Some(tools) if !tools.is_empty() => tools[*g % tools.len()],
            _ => cfg.tool_mm,
        });
    }

    // 3. Temperature channels, in the order the effects name them.
    let mut temps: Vec<TempChannel> = Vec::new();
    for e in &cfg.effects {
        if let Some(sensor) = e.form().sensor() {
            if temps.iter().any(|c| c.name == sensor.name()) {
                continue; // the first effect naming a channel defines its sensor
            }
            let temp_c = rows_t
                .iter()
                .map(|&t| round_dec(sensor.temp_c(t), 3))
                .collect();
            temps.push(TempChannel {
                name: sensor.name().to_string(),
                temp_c,
            });
        }
    }

    // 4. Errors: geometry + effects (truth), then noise.
    let mut truth: [Vec<f64>; 3] = Default::default();
    for r in 0..n {
        let p = [rows_pos[0][r], rows_pos[1][r], rows_pos[2][r]];
        let e = cfg.machine.error_um(p, rows_tool[r]);
        for i in 0..3 {
            truth[i].push(e[i]);
        }
    }
    let rows = SimRows {
        pos_mm: &rows_pos,
        dir: &rows_dir,
        t_s: &rows_t,
        session: &rows_session,
        tool_mm: &rows_tool,
        temps: &temps,
    };
    for eff in &cfg.effects {
        eff.form().add_error(&rows, &mut truth);
    }
    // Spikes from a stream of their own, drawn row by row (one uniform per
    // value, two more per spike), so they change nothing else.
    let mut spike_um = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    let mut spikes = Vec::new();
    if let Some(sp) = cfg.spikes.filter(|sp| sp.frac > 0.0) {
        let mut rng_spike = ChaCha8Rng::seed_from_u64(cfg.seed);
        rng_spike.set_stream(3);
        for r in 0..n {
            for (i, col) in spike_um.iter_mut().enumerate() {
                if plan::unit(&mut rng_spike) < sp.frac {
                    let sign = if plan::unit(&mut rng_spike) < 0.5 {
                        -1.0
                    } else {
                        1.0
                    };
                    col[r] = sign * sp.amp_um * (1.0 + plan::unit(&mut rng_spike));
                    spikes.push((r, i));
                }
            }
        }
    }
    let mut err: [Option<Vec<Option<f64>>>; 3] = Default::default();
    for (i, slot) in err.iter_mut().enumerate() {
        let mut col = Vec::with_capacity(n);
        for r in 0..n {
            let noise = if cfg.noise_um > 0.0 {
                cfg.noise_um * normal(&mut rng_noise)
            } else {
                0.0
            };
            col.push(Some(round_dec(truth[i][r] + noise + spike_um[i][r], 4)));
        }
        *slot = Some(col);
    }

    // 5. Assemble, with the config in the metadata so the file says how it
    // was made.
    let mut metadata = vec![
        ("generator".to_string(), "trueaxis simulate".to_string()),
        (
            "machine".to_string(),
            format!("simulate:{}", cfg.machine.name),
        ),
        ("seed".to_string(), cfg.seed.to_string()),
        ("noise_um".to_string(), cfg.noise_um.to_string()),
    ];
    for p in &cfg.plans {
        metadata.push(("plan".into(), p.to_string()));
    }
    // Everything else that shapes the file, so the metadata alone can
    // reproduce it.
    metadata.push((
        "timing".into(),
        format!(
            "feed_mm_s={},dwell_s={},tool_mm={}",
            cfg.timing.feed_mm_s, cfg.timing.dwell_s, cfg.tool_mm
        ),
    ));
    if let Some(sp) = &cfg.spikes {
        metadata.push(("spikes".into(), sp.to_string()));
    }
    if let Some(r) = &cfg.reference {
        metadata.push((
            "reference".into(),
            format!(
                "x={},y={},z={},every_passes={}",
                r.pos_mm[0], r.pos_mm[1], r.pos_mm[2], r.every_passes
            ),
        ));
    }
    for e in &cfg.effects {
        metadata.push(("effect".into(), e.to_string()));
        if let Some(w) = e.form().warning(&rows) {
            metadata.push(("warning".into(), w));
        }
    }
    let data = Dataset {
        source: format!("simulate:{}", cfg.machine.name),
        metadata,
        pos_mm: rows_pos.map(Some),
        err_um: err,
        t_s: Some(rows_t),
        dir: rows_dir.map(Some),
        temps,
        tool_mm: abbe_tools.map(|_| rows_tool.clone()),
        pass_id: Some(rows_pass),
        session_id: cfg
            .plans
            .iter()
            .any(|p| {
                matches!(
                    p,
                    Plan::Pause {
                        new_session: true,
                        ..
                    }
                )
            })
            .then_some(rows_session),
        ..Dataset::default()
    };
    SimOutput {
        data,
        truth_um: truth,
        spikes,
    }
}
