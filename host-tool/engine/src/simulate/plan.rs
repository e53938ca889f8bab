//! Measurement plans: which nominal points the synthetic machine visits, in
//! which order and from which direction. A plan expands into a sequence of
//! [`Visit`]s; `simulate` adds time, tool length, effects and noise.
//!
//! Spec strings (parsed in `spec.rs`, documented in docs/cli.md):
//! `grid:<step_mm>`, `plane:<ab>:<step_mm>`, `line:<a>:<step_mm>` with
//! optional `,x=…,y=…,z=…` (fixed positions, default mid-travel), `,bidir`
//! (every line forward then backward) and `,runs=N`; `iso230:<a>` with
//! `,targets=N,runs=N,overrun_mm=…`; `point:x=…,y=…,z=…[,repeats=N]`;
//! `pause:<s>[,new_session]`.

use rand_chacha::rand_core::RngCore;
use serde::{Deserialize, Serialize};

/// One measurement plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Plan {
    /// A regular raster over `axes` (fastest first) every `step_mm` from 0
    /// to the travel, in serpentine order; the other axes sit at `at_mm`
    /// (mid-travel when `None`). One pass per line of the fastest axis.
    Raster {
        /// Moving axes, fastest first: `[0, 1, 2]` is the full grid.
        axes: Vec<usize>,
        /// Spacing, mm.
        step_mm: f64,
        /// Fixed positions of the axes that do not move (mm).
        at_mm: [Option<f64>; 3],
        /// Each line forward then backward (both approach directions)
        /// instead of serpentine.
        bidir: bool,
        /// How many times the whole raster is repeated.
        runs: usize,
    },
    /// ISO 230-2 bidirectional cycles along `axis`: irregular targets,
    /// `runs` forward+backward runs, an overrun past the end targets before
    /// each reversal so every target is approached from one side.
    Iso230 {
        /// The axis under test.
        axis: usize,
        /// Number of targets (≥ 2).
        targets: usize,
        /// Bidirectional runs (ISO 230-2 asks for 5).
        runs: usize,
        /// Overrun before each reversal, mm.
        overrun_mm: f64,
        /// Fixed positions of the other axes (mid-travel when `None`).
        at_mm: [Option<f64>; 3],
    },
    /// A single point measured `repeats` times (a reference point).
    Point {
        /// The point, mm.
        pos_mm: [f64; 3],
        /// Number of readings.
        repeats: usize,
    },
    /// The machine idles for `duration_s` (temperatures and drift go on);
    /// with `new_session` a new measurement session starts afterwards:
    /// `session_id` increments and `t_s` restarts at 0 (the contract's
    /// "time since the start of the session"), and so do the thermal
    /// sensor trajectories (a cold start, e.g. the next morning).
    Pause {
        /// Idle time, s.
        duration_s: f64,
        /// Start a new session after the pause.
        new_session: bool,
    },
}

/// A point the machine moves to. `via_mm` is an overrun position passed on
/// the way (it sets the approach direction and costs time, nothing is read).
#[derive(Clone, Debug, PartialEq)]
pub struct Visit {
    /// Nominal position, mm.
    pub pos_mm: [f64; 3],
    /// Overrun point visited just before, if any.
    pub via_mm: Option<[f64; 3]>,
    /// Index of the pass within the plan (0-based); a new pass id each time
    /// it changes.
    pub pass: usize,
}

/// Positions 0, step, 2·step, … up to the travel (the travel itself when
/// the step divides it, to within 1 µm).
pub fn stations(travel_mm: f64, step_mm: f64) -> Vec<f64> {
    let n = (travel_mm / step_mm + 1e-6).floor() as usize;
    (0..=n).map(|i| round_um(i as f64 * step_mm)).collect()
}

/// Rounds to 1 nm so that generated positions print short and compare equal.
pub fn round_um(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// Uniform in [0, 1) from 53 random bits (independent of rand's own
/// float conversion, so the output stays the same across rand versions).
pub(crate) fn unit(rng: &mut impl RngCore) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

impl Plan {
    /// The visits of this plan on a machine with `travel_mm`; `rng` draws
    /// the irregular ISO 230-2 targets.
    pub fn visits(&self, travel_mm: [f64; 3], rng: &mut impl RngCore) -> Vec<Visit> {
        let mid = |at: &[Option<f64>; 3], a: usize| at[a].unwrap_or(round_um(travel_mm[a] / 2.0));
        let mut out = Vec::new();
        match self {
            Plan::Raster {
                axes,
                step_mm,
                at_mm,
                bidir,
                runs,
            } => {
                let base: [f64; 3] = [0, 1, 2].map(|a| mid(at_mm, a));
                let st: Vec<Vec<f64>> = axes
                    .iter()
                    .map(|&a| stations(travel_mm[a], *step_mm))
                    .collect();
                let mut pass = 0;
                for _ in 0..*runs {
                    // Outer loops over the slower axes (up to two), each
                    // serpentine: reverse every other sweep.
                    let n1 = st.get(1).map_or(1, Vec::len);
                    let n2 = st.get(2).map_or(1, Vec::len);
                    let mut line_no = 0usize;
                    for i2 in 0..n2 {
                        for j in 0..n1 {
                            let i1 = if i2 % 2 == 0 { j } else { n1 - 1 - j };
                            let mut p = base;
                            if axes.len() > 2 {
                                p[axes[2]] = st[2][i2];
                            }
                            if axes.len() > 1 {
                                p[axes[1]] = st[1][i1];
                            }
                            let fwd: Vec<f64> = st[0].clone();
                            let rev: Vec<f64> = st[0].iter().rev().copied().collect();
                            let sweeps: Vec<&Vec<f64>> = if *bidir {
                                vec![&fwd, &rev]
                            } else if line_no.is_multiple_of(2) {
                                vec![&fwd]
                            } else {
                                vec![&rev]
                            };
                            for sweep in sweeps {
                                for &v in sweep {
                                    let mut q = p;
                                    q[axes[0]] = v;
                                    out.push(Visit {
                                        pos_mm: q,
                                        via_mm: None,
                                        pass,
                                    });
                                }
                                pass += 1;
                            }
                            line_no += 1;
                        }
                    }
                }
            }
            Plan::Iso230 {
                axis,
                targets,
                runs,
                overrun_mm,
                at_mm,
            } => {
                let tg = iso_targets(travel_mm[*axis], *targets, *overrun_mm, rng);
                let base: [f64; 3] = [0, 1, 2].map(|a| mid(at_mm, a));
                let at = |v: f64| {
                    let mut q = base;
                    q[*axis] = v;
                    q
                };
                let (first, last) = (tg[0], tg[tg.len() - 1]);
                let mut pass = 0;
                for _ in 0..*runs {
                    for (i, &v) in tg.iter().enumerate() {
                        let via = (i == 0).then(|| at(round_um(first - overrun_mm)));
                        out.push(Visit {
                            pos_mm: at(v),
                            via_mm: via,
                            pass,
                        });
                    }
                    pass += 1;
                    for (i, &v) in tg.iter().rev().enumerate() {
                        let via = (i == 0).then(|| at(round_um(last + overrun_mm)));
                        out.push(Visit {
                            pos_mm: at(v),
                            via_mm: via,
                            pass,
                        });
                    }
                    pass += 1;
                }
            }
            // Time and sessions are handled by `simulate`; no points.
            Plan::Pause { .. } => {}
            Plan::Point { pos_mm, repeats } => {
                for _ in 0..*repeats {
                    out.push(Visit {
                        pos_mm: *pos_mm,
                        via_mm: None,
                        pass: 0,
                    });
                }
            }
        }
        out
    }
}

/// ISO 230-2 targets: `n` positions from `overrun` to `travel − overrun`
/// (so the overrun stays inside the travel), the inner ones moved at random
/// by up to ±20 % of the mean spacing — irregular spacing keeps periodic
/// errors (lead screw, scale) from hiding between equally spaced targets.
pub fn iso_targets(travel_mm: f64, n: usize, overrun_mm: f64, rng: &mut impl RngCore) -> Vec<f64> {
    let n = n.max(2);
    let lo = overrun_mm;
    let hi = travel_mm - overrun_mm;
    let p = (hi - lo) / (n - 1) as f64;
    (0..n)
        .map(|i| {
            let nominal = lo + i as f64 * p;
            if i == 0 || i == n - 1 {
                round_um(nominal)
            } else {
                // Round to 1 µm: a realistic commanded target.
                ((nominal + (unit(rng) - 0.5) * 0.4 * p) * 1e3).round() / 1e3
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::rand_core::SeedableRng;

    #[test]
    fn seed_grid_has_2057_points_in_serpentine_order() {
        let plan = Plan::Raster {
            axes: vec![0, 1, 2],
            step_mm: 50.0,
            at_mm: [None; 3],
            bidir: false,
            runs: 1,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let v = plan.visits([800.0, 500.0, 500.0], &mut rng);
        assert_eq!(v.len(), 17 * 11 * 11);
        // Serpentine: consecutive points never jump more than one step.
        for w in v.windows(2) {
            let d: f64 = (0..3)
                .map(|a| (w[0].pos_mm[a] - w[1].pos_mm[a]).abs())
                .sum();
            assert!(
                (d - 50.0).abs() < 1e-9,
                "{:?} -> {:?}",
                w[0].pos_mm,
                w[1].pos_mm
            );
        }
        assert_eq!(v.last().unwrap().pass, 11 * 11 - 1);
    }

    #[test]
    fn iso_targets_are_irregular_and_inside() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let t = iso_targets(800.0, 11, 5.0, &mut rng);
        assert_eq!(t.len(), 11);
        assert_eq!(t[0], 5.0);
        assert_eq!(t[10], 795.0);
        let gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(gaps.iter().all(|g| *g > 0.0));
        assert!(gaps.iter().any(|g| (g - 79.0).abs() > 1.0), "{gaps:?}");
    }
}
