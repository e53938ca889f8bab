//! The volumetric instruments (issue 26, docs/volumetric.md): laser
//! positioning/straightness lines at tool offsets, angular lines, body and
//! face diagonals (ISO 230-6), ballbar circles (ISO 230-4) and tracker
//! stations with unknown frames, each reading relative to its own set-up
//! (zero, alignment, frame, centre) with its instrument's noise
//! (ARCHITECTURE.md): laser positioning 0.2 µm, straightness 0.5 µm,
//! angular 0.5 µrad, diagonal 0.3 µm, ballbar 0.2 µm, tracker 0.5 µm.
//! Every set-up gets its own `setup_id`; `u_um` is the instrument's noise
//! in the row's reading unit.

use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::plan::unit;
use super::{normal, Machine};
use crate::data::Dataset;

/// Laser positioning noise, µm.
pub const LASER_UM: f64 = 0.2;
/// Straightness noise, µm.
pub const STRAIGHTNESS_UM: f64 = 0.5;
/// Angular line noise, µrad.
pub const ANGULAR_URAD: f64 = 0.5;
/// Diagonal (ISO 230-6) noise, µm.
pub const DIAGONAL_UM: f64 = 0.3;
/// Ballbar noise per reading, µm.
pub const BALLBAR_UM: f64 = 0.2;
/// Tracker noise per coordinate, µm.
pub const TRACKER_UM: f64 = 0.5;

/// One instrument set-up.
#[derive(Clone, Debug, PartialEq)]
pub enum Instrument {
    /// A laser line along `axis` through `at_mm` (the other axes' positions)
    /// with the target at `tool_mm` and `tool_lat_mm`: positioning (zeroed)
    /// and, with `straightness`, the two straightnesses (zeroed and
    /// aligned: each reading's own zero and slope are lost).
    Line {
        /// Moving axis.
        axis: usize,
        /// Positions of the axes (the moving one is ignored), mm.
        at_mm: [f64; 3],
        /// Tool length, mm.
        tool_mm: f64,
        /// Lateral target offset, mm.
        tool_lat_mm: [f64; 2],
        /// Also the two straightness readings.
        straightness: bool,
        /// Points along the travel (≥ 2).
        points: usize,
    },
    /// An angular line (roll/pitch/yaw readings, each zeroed) along `axis`.
    Angular {
        /// Moving axis.
        axis: usize,
        /// Positions of the axes (the moving one is ignored), mm.
        at_mm: [f64; 3],
        /// Points along the travel.
        points: usize,
    },
    /// A diagonal from `from_mm` to `to_mm` (all axes moving together), the
    /// displacement along it, zeroed.
    Diagonal {
        /// Start, mm.
        from_mm: [f64; 3],
        /// End, mm.
        to_mm: [f64; 3],
        /// Points.
        points: usize,
    },
    /// A ballbar circle (ISO 230-4) in the plane of axes `plane` about
    /// `centre_mm`, radius `radius_mm`, with the tool ball at `tool_mm`:
    /// the change of the bar's length, n · (e(p) − e(c)) with n the bar's
    /// direction, read relative to the bar's own calibrated length (a zero)
    /// and a centre ball set where the machine put it (an offset in the
    /// plane).
    Ballbar {
        /// The two axes of the circle's plane.
        plane: [usize; 2],
        /// Centre, mm.
        centre_mm: [f64; 3],
        /// Radius, mm.
        radius_mm: f64,
        /// Tool length, mm.
        tool_mm: f64,
        /// Points around the circle.
        points: usize,
    },
    /// A tracker station: points spread over the volume, each at every
    /// tool length and lateral offset, in the station's own frame (an
    /// unknown rigid-body placement: up to 50 µm, 100 µrad).
    Tracker {
        /// Tool lengths, mm.
        tools_mm: Vec<f64>,
        /// Lateral offsets, mm.
        lateral_mm: Vec<[f64; 2]>,
        /// Points over the volume.
        points: usize,
    },
}

/// A laser line along `axis` through `at_mm` at tool length `tool_mm`,
/// no lateral offset: positioning and straightness at 21 points (each of
/// [`laser_lines`]).
pub fn laser_line(axis: usize, at_mm: [f64; 3], tool_mm: f64) -> Instrument {
    Instrument::Line {
        axis,
        at_mm,
        tool_mm,
        tool_lat_mm: [0.0, 0.0],
        straightness: true,
        points: 21,
    }
}

/// The plans a `mill800`-sized machine is measured with in tests and
/// examples: laser lines (positioning and straightness) along each axis at
/// two tool lengths and two parallel offsets.
pub fn laser_lines(travel_mm: [f64; 3], tools_mm: &[f64]) -> Vec<Instrument> {
    let mut out = Vec::new();
    for axis in 0..3 {
        for &tool in tools_mm {
            for side in [0.2, 0.8] {
                let mut at = travel_mm.map(|t| t * 0.5);
                // Parallel offsets along the next axis.
                at[(axis + 1) % 3] = travel_mm[(axis + 1) % 3] * side;
                out.push(laser_line(axis, at, tool));
            }
        }
    }
    out
}

/// [`laser_lines`] with `points` readings on each line along `axis` (161
/// on 800 mm: 5 mm steps, fine enough to see a 100 mm lead).
pub fn laser_lines_along(
    travel_mm: [f64; 3],
    tools_mm: &[f64],
    axis: usize,
    points: usize,
) -> Vec<Instrument> {
    let mut plan = laser_lines(travel_mm, tools_mm);
    for inst in &mut plan {
        if let Instrument::Line {
            axis: a, points: p, ..
        } = inst
        {
            if *a == axis {
                *p = points;
            }
        }
    }
    plan
}

/// The four body diagonals of the volume (ISO 230-6).
pub fn body_diagonals(travel_mm: [f64; 3]) -> Vec<Instrument> {
    let mut out = Vec::new();
    for (sy, sz) in [(false, false), (true, false), (false, true), (true, true)] {
        let from = [
            0.0,
            if sy { travel_mm[1] } else { 0.0 },
            if sz { travel_mm[2] } else { 0.0 },
        ];
        let to = [
            travel_mm[0],
            if sy { 0.0 } else { travel_mm[1] },
            if sz { 0.0 } else { travel_mm[2] },
        ];
        out.push(Instrument::Diagonal {
            from_mm: from,
            to_mm: to,
            points: 21,
        });
    }
    out
}

/// Ballbar circles (ISO 230-4) in the XY, YZ and ZX planes about the
/// centre of the volume, radius 150 mm (or 40 % of the shorter travel of
/// the plane when that is less), 90 points each, at tool length `tool_mm`.
pub fn ballbar_circles(travel_mm: [f64; 3], tool_mm: f64) -> Vec<Instrument> {
    [[0, 1], [1, 2], [2, 0]]
        .into_iter()
        .map(|plane: [usize; 2]| Instrument::Ballbar {
            plane,
            centre_mm: travel_mm.map(|t| t * 0.5),
            radius_mm: (0.4 * travel_mm[plane[0]].min(travel_mm[plane[1]])).min(150.0),
            tool_mm,
            points: 90,
        })
        .collect()
}

/// One row being built.
#[derive(Default)]
struct Row {
    pos: [f64; 3],
    tool: f64,
    lat: [f64; 2],
    setup: i64,
    e: [Option<f64>; 3],
    a: [Option<f64>; 3],
    beam: Option<([f64; 3], f64)>,
    u: f64,
}

/// Measures `machine` with `plan` (set-ups numbered from 1 in order);
/// `seed` fixes the noise and the trackers' frames; `noise` false gives
/// the exact readings (set-up zeros and frames still applied).
pub fn measure(machine: &Machine, plan: &[Instrument], seed: u64, noise: bool) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Noise from its own stream, so that the same seed gives the same
    // points, zeros and frames with and without noise.
    let mut nrng = ChaCha8Rng::seed_from_u64(seed ^ 0x05ee_d0f4_015e);
    let mut rows: Vec<Row> = Vec::new();
    let tr = machine.travel_mm;
    for (i, inst) in plan.iter().enumerate() {
        let setup = i as i64 + 1;
        // An arbitrary zero per reading column and set-up.
        let zero = |rng: &mut ChaCha8Rng| 20.0 * (unit(rng) - 0.5);
        match inst {
            Instrument::Line {
                axis,
                at_mm,
                tool_mm,
                tool_lat_mm,
                straightness,
                points,
            } => {
                let z: [f64; 3] = [zero(&mut rng), zero(&mut rng), zero(&mut rng)];
                let slope: [f64; 3] = [0, 1, 2].map(|_| 40.0 * (unit(&mut rng) - 0.5));
                for j in 0..*points {
                    let mut pos = *at_mm;
                    pos[*axis] = tr[*axis] * j as f64 / (*points - 1).max(1) as f64;
                    let e = machine.error_at_um(pos, *tool_mm, *tool_lat_mm);
                    let mut row = Row {
                        pos,
                        tool: *tool_mm,
                        lat: *tool_lat_mm,
                        setup,
                        u: if *straightness {
                            STRAIGHTNESS_UM
                        } else {
                            LASER_UM
                        },
                        ..Row::default()
                    };
                    for c in 0..3 {
                        if c == *axis {
                            row.e[c] = Some(e[c] + z[c] + jitter(noise, LASER_UM, &mut nrng));
                        } else if *straightness {
                            row.e[c] = Some(
                                e[c] + z[c]
                                    + slope[c] * 1e-3 * pos[*axis]
                                    + jitter(noise, STRAIGHTNESS_UM, &mut nrng),
                            );
                        }
                    }
                    rows.push(row);
                }
            }
            Instrument::Angular {
                axis,
                at_mm,
                points,
            } => {
                let z: [f64; 3] = [zero(&mut rng), zero(&mut rng), zero(&mut rng)];
                for j in 0..*points {
                    let mut pos = *at_mm;
                    pos[*axis] = tr[*axis] * j as f64 / (*points - 1).max(1) as f64;
                    let w = machine.angle_urad(pos);
                    let mut row = Row {
                        pos,
                        setup,
                        u: ANGULAR_URAD,
                        ..Row::default()
                    };
                    for c in 0..3 {
                        row.a[c] = Some(w[c] + z[c] + jitter(noise, ANGULAR_URAD, &mut nrng));
                    }
                    rows.push(row);
                }
            }
            Instrument::Diagonal {
                from_mm,
                to_mm,
                points,
            } => {
                let d = [0, 1, 2].map(|k| to_mm[k] - from_mm[k]);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let n_dir = d.map(|v| v / len);
                let z0 = zero(&mut rng);
                for j in 0..*points {
                    let f = j as f64 / (*points - 1).max(1) as f64;
                    let pos = [0, 1, 2].map(|k| from_mm[k] + f * d[k]);
                    let e = machine.error_um(pos, 0.0);
                    let v: f64 = (0..3).map(|k| n_dir[k] * e[k]).sum();
                    let n = jitter(noise, DIAGONAL_UM, &mut nrng);
                    rows.push(Row {
                        pos,
                        setup,
                        beam: Some((n_dir, v + z0 + n)),
                        u: DIAGONAL_UM,
                        ..Row::default()
                    });
                }
            }
            Instrument::Ballbar {
                plane,
                centre_mm,
                radius_mm,
                tool_mm,
                points,
            } => {
                let z0 = zero(&mut rng);
                let e_c = machine.error_at_um(*centre_mm, *tool_mm, [0.0, 0.0]);
                for j in 0..*points {
                    let th = std::f64::consts::TAU * j as f64 / *points as f64;
                    let mut n_dir = [0.0; 3];
                    n_dir[plane[0]] = th.cos();
                    n_dir[plane[1]] = th.sin();
                    let pos = [0, 1, 2].map(|k| centre_mm[k] + radius_mm * n_dir[k]);
                    let e = machine.error_at_um(pos, *tool_mm, [0.0, 0.0]);
                    let v: f64 = (0..3).map(|k| n_dir[k] * (e[k] - e_c[k])).sum();
                    let n = jitter(noise, BALLBAR_UM, &mut nrng);
                    rows.push(Row {
                        pos,
                        tool: *tool_mm,
                        setup,
                        beam: Some((n_dir, v + z0 + n)),
                        u: BALLBAR_UM,
                        ..Row::default()
                    });
                }
            }
            Instrument::Tracker {
                tools_mm,
                lateral_mm,
                points,
            } => {
                let t: [f64; 3] = [0, 1, 2].map(|_| 100.0 * (unit(&mut rng) - 0.5));
                let w: [f64; 3] = [0, 1, 2].map(|_| 200.0 * (unit(&mut rng) - 0.5));
                for _ in 0..*points {
                    let pos = [0, 1, 2].map(|k| tr[k] * unit(&mut rng));
                    for &tool in tools_mm {
                        for &lat in lateral_mm {
                            let e = machine.error_at_um(pos, tool, lat);
                            let p = [pos[0] + lat[0], pos[1] + lat[1], pos[2] - tool];
                            // The station's frame: reading = e + t + ω × p.
                            let wp = [
                                (w[1] * p[2] - w[2] * p[1]) * 1e-3,
                                (w[2] * p[0] - w[0] * p[2]) * 1e-3,
                                (w[0] * p[1] - w[1] * p[0]) * 1e-3,
                            ];
                            let mut row = Row {
                                pos,
                                tool,
                                lat,
                                setup,
                                u: TRACKER_UM,
                                ..Row::default()
                            };
                            for c in 0..3 {
                                row.e[c] = Some(
                                    e[c] + t[c] + wp[c] + jitter(noise, TRACKER_UM, &mut nrng),
                                );
                            }
                            rows.push(row);
                        }
                    }
                }
            }
        }
    }
    let n = rows.len();
    let col = |f: &dyn Fn(&Row) -> Option<f64>| -> Option<Vec<Option<f64>>> {
        rows.iter()
            .any(|r| f(r).is_some())
            .then(|| rows.iter().map(f).collect())
    };
    let err_um = [0, 1, 2].map(|c| col(&|r: &Row| r.e[c]));
    let angle_urad = [0, 1, 2].map(|c| col(&|r: &Row| r.a[c]));
    let beam_um = col(&|r: &Row| r.beam.map(|b| b.1));
    let beam_dir = beam_um
        .as_ref()
        .map(|_| rows.iter().map(|r| r.beam.map(|b| b.0)).collect());
    let any_lat = rows.iter().any(|r| r.lat != [0.0; 2]);
    Dataset {
        source: format!("simulate:{}", machine.name),
        pos_mm: [0, 1, 2].map(|k| Some(rows.iter().map(|r| r.pos[k]).collect())),
        err_um,
        tool_mm: Some(rows.iter().map(|r| r.tool).collect()),
        tool_lat_mm: [0, 1].map(|k| any_lat.then(|| rows.iter().map(|r| r.lat[k]).collect())),
        setup_id: Some(rows.iter().map(|r| r.setup).collect()),
        angle_urad,
        beam_um,
        beam_dir,
        u_um: Some(rows.iter().map(|r| r.u).collect()),
        line: Vec::new(),
        ..Dataset::default()
    }
    .with_len_checked(n)
}

/// A reading's noise: σ·N(0, 1) from `rng` when `noise` (a draw), else 0
/// (no draw).
fn jitter(noise: bool, sigma: f64, rng: &mut ChaCha8Rng) -> f64 {
    if noise {
        sigma * normal(rng)
    } else {
        0.0
    }
}

impl Dataset {
    /// `self`, asserting it has `n` rows and passes [`Dataset::validate`]
    /// (the simulator's own output).
    fn with_len_checked(self, n: usize) -> Dataset {
        debug_assert_eq!(self.len(), n);
        debug_assert!(self.validate().is_ok(), "{:?}", self.validate());
        self
    }
}
