//! Shared test fixtures: a tiny deterministic RNG (SplitMix64 from
//! `trueaxis-test-support`, so generated
//! models are identical on every run and every machine) and generators of
//! realistic random table specs and inputs — corrections up to ±200 µm,
//! travel up to ±1 m, temperatures 10–40 °C — used by the accuracy
//! proptests, the golden files and the replay vectors; and the replay
//! vector writer. Also compiled into the QEMU crate's build script
//! (`tests/build/random.rs`), which replays seeded random models on the
//! target — so everything here must build with model-core's `std` feature
//! alone.
#![allow(dead_code)]

use model_core::monomials::{kinematic, CUBIC19};
use model_core::spec::PolyCoef;
use model_core::{
    parse, Envelope, GridAxisSpec, GridSpec, InputScaling, Inputs, InputsF64, LayerSpec,
    MlpInputSpec, MlpSource, MlpSpec, Model, TableSpec, TermSpec, MAX_TEMPS,
};

/// SplitMix64, the one copy in `test-support`.
pub use trueaxis_test_support::SplitMix64 as Rng;

/// Which term kinds a generated spec contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Cubic19,
    Kinematic,
    Degree5,
    Periodic,
    Thermal,
    Reversal,
    Abbe,
    Mlp,
    Grid,
}

pub const ALL_KINDS: [Kind; 9] = [
    Kind::Cubic19,
    Kind::Kinematic,
    Kind::Degree5,
    Kind::Periodic,
    Kind::Thermal,
    Kind::Reversal,
    Kind::Abbe,
    Kind::Mlp,
    Kind::Grid,
];

/// A random realistic envelope (max correction set generously: the accuracy
/// tests compare unclamped values).
pub fn base_spec(rng: &mut Rng, n_channels: usize) -> TableSpec {
    let mut env = Envelope::default();
    let mut sc = InputScaling::default();
    for a in 0..3 {
        let half = rng.range(50e6, 1000e6) as i32; // 50 mm … 1 m
        let centre = rng.sym(200e6) as i32;
        sc.centre_nm[a] = centre;
        sc.half_span_nm[a] = half;
        env.travel_min_nm[a] = centre - half;
        env.travel_max_nm[a] = centre + half;
        env.max_corr_nm[a] = 4_000_000;
    }
    env.max_slew_nm_per_ms = 1000;
    for ch in 0..n_channels {
        env.temp_min_mc[ch] = 10_000;
        env.temp_max_mc[ch] = 40_000;
    }
    env.tool_min_nm = 0;
    env.tool_max_nm = 300_000_000;
    TableSpec {
        created_unix_s: 1_763_769_600,
        source_hash: [0x5a; 32],
        channels: (0..n_channels)
            .map(|i| ["bed", "air", "spindle", "column"][i].to_string())
            .collect(),
        envelope: env,
        scaling: sc,
        outputs: [true, true, true],
        terms: Vec::new(),
    }
}

fn poly(rng: &mut Rng, set: &[[u8; 3]], amp: f64) -> Vec<PolyCoef> {
    set.iter().map(|&m| (m, rng.sym(amp))).collect()
}

/// Add one term (or one per output) of `kind`.
pub fn add_kind(rng: &mut Rng, spec: &mut TableSpec, kind: Kind) {
    let nch = spec.channels.len();
    match kind {
        Kind::Cubic19 => {
            for o in 0..3 {
                spec.terms.push(TermSpec::Poly {
                    output: o,
                    coefs: poly(rng, &CUBIC19, 10_000.0),
                });
            }
        }
        Kind::Kinematic => {
            for o in 0..3 {
                spec.terms.push(TermSpec::Poly {
                    output: o,
                    coefs: poly(rng, kinematic(o as usize), 20_000.0),
                });
            }
        }
        Kind::Degree5 => {
            let o = rng.int(0, 2) as u8;
            let set = model_core::monomials::up_to_degree(5);
            spec.terms.push(TermSpec::Poly {
                output: o,
                coefs: poly(rng, set, 3_000.0),
            });
        }
        Kind::Periodic => {
            let h = rng.int(1, 4) as usize;
            spec.terms.push(TermSpec::Periodic {
                output: rng.int(0, 2) as u8,
                axis: rng.int(0, 2) as u8,
                period_nm: rng.range(2e6, 40e6) as i32,
                sin_nm: (0..h).map(|_| rng.sym(8000.0)).collect(),
                cos_nm: (0..h).map(|_| rng.sym(8000.0)).collect(),
            });
        }
        Kind::Thermal => {
            if nch == 0 {
                return;
            }
            let ch = rng.int(0, nch as i64 - 1) as u8;
            // Alone, or times a linear/quadratic position polynomial.
            let set: &[[u8; 3]] = if rng.unit() < 0.5 {
                &[[0, 0, 0]]
            } else {
                &[[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]]
            };
            spec.terms.push(TermSpec::Thermal {
                output: rng.int(0, 2) as u8,
                channel: ch,
                t_ref_mc: 20_000,
                coefs_nm_per_k: poly(rng, set, 2_500.0),
            });
        }
        Kind::Reversal => {
            let output = rng.int(0, 2) as u8;
            let axis = rng.int(0, 2) as u8;
            let mut transition_nm = rng.range(5e3, 100e3) as i32;
            // One transition length per axis (the table format requires it);
            // the draw above is kept so the generated streams stay the same.
            for t in &spec.terms {
                if let TermSpec::Reversal {
                    axis: a,
                    transition_nm: earlier,
                    ..
                } = t
                {
                    if *a == axis {
                        transition_nm = *earlier;
                    }
                }
            }
            spec.terms.push(TermSpec::Reversal {
                output,
                axis,
                transition_nm,
                amplitude_nm: rng.sym(25_000.0),
            })
        }
        Kind::Abbe => spec.terms.push(TermSpec::Abbe {
            output: rng.int(0, 2) as u8,
            coefs: poly(rng, &[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], 5e-5),
        }),
        Kind::Mlp => {
            let mut inputs: Vec<MlpInputSpec> = (0..3)
                .map(|a| MlpInputSpec {
                    source: MlpSource::Pos(a),
                    min: spec.envelope.travel_min_nm[a as usize] as f64 + 1000.5,
                    max: spec.envelope.travel_max_nm[a as usize] as f64 - 333.25,
                })
                .collect();
            if nch > 0 && rng.unit() < 0.5 {
                inputs.push(MlpInputSpec {
                    source: MlpSource::Temp(0),
                    min: 15_000.0,
                    max: 35_000.0,
                });
            }
            let n_layers = if rng.unit() < 0.7 { 1 } else { 2 };
            let mut prev = inputs.len();
            let mut hidden = Vec::new();
            for _ in 0..n_layers {
                let units = rng.int(4, 16) as usize;
                hidden.push(LayerSpec {
                    weights: (0..units * prev).map(|_| rng.sym(1.5)).collect(),
                    bias: (0..units).map(|_| rng.sym(1.0)).collect(),
                });
                prev = units;
            }
            let outputs: Vec<u8> = vec![0, 1, 2];
            let output = LayerSpec {
                weights: (0..3 * prev)
                    .map(|_| rng.sym(1.0 / (prev as f64).sqrt()))
                    .collect(),
                bias: (0..3).map(|_| rng.sym(0.3)).collect(),
            };
            spec.terms.push(TermSpec::Mlp(MlpSpec {
                outputs,
                inputs,
                hidden,
                output,
                out_min_nm: (0..3).map(|_| -rng.range(10e3, 50e3)).collect(),
                out_max_nm: (0..3).map(|_| rng.range(10e3, 50e3)).collect(),
            }));
        }
        Kind::Grid => {
            let mut axes = [GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1,
            }; 3];
            let used = rng.int(1, 3);
            let first = rng.int(0, 2) as usize;
            for k in 0..used as usize {
                let a = (first + k) % 3;
                let nodes = rng.int(2, [17, 11, 11][a]) as u16;
                let (lo, hi) = (
                    spec.envelope.travel_min_nm[a] as f64,
                    spec.envelope.travel_max_nm[a] as f64,
                );
                // Grid slightly inside the travel so the edge hold is exercised too.
                let origin = lo + 0.05 * (hi - lo);
                let step = (0.9 * (hi - lo) / (nodes - 1) as f64).floor();
                axes[a] = GridAxisSpec {
                    nodes,
                    origin_nm: origin as i32,
                    step_nm: step as i32,
                };
            }
            let n: usize = axes.iter().map(|a| a.nodes as usize).product();
            spec.terms.push(TermSpec::Grid(GridSpec {
                output: rng.int(0, 2) as u8,
                axes,
                values_nm: (0..n).map(|_| rng.sym(20_000.0)).collect(),
            }));
        }
    }
}

/// A random spec with the given kinds.
pub fn random_spec(seed: u64, kinds: &[Kind]) -> TableSpec {
    let mut rng = Rng(seed);
    let nch = rng.int(1, MAX_TEMPS as i64) as usize;
    let mut spec = base_spec(&mut rng, nch);
    for &k in kinds {
        add_kind(&mut rng, &mut spec, k);
    }
    spec
}

/// The edge-table generator: a table at the edges of what load accepts
/// (every term kind; huge grid values, coefficient sums just under the
/// fixed-point limit, large amplitudes, steep MLPs), model `round` of the
/// stream `rng` draws (`extreme_but_valid_models_never_overflow`).
pub fn extreme_spec(round: u64, rng: &mut Rng) -> TableSpec {
    let mut spec = random_spec(900 + round, &ALL_KINDS);
    spec.envelope.max_corr_nm = [model_core::table::MAX_CORR_LIMIT_NM; 3];
    let scale = [1.0, 10.0, 100.0, 500.0][round as usize % 4];
    for t in spec.terms.iter_mut() {
        match t {
            TermSpec::Poly { coefs, .. } => {
                let n = coefs.len() as f64;
                for c in coefs.iter_mut() {
                    c.1 = rng.sym(6.0e8 / n);
                }
            }
            TermSpec::Grid(g) => {
                for v in g.values_nm.iter_mut() {
                    *v = rng.sym(4.1e6);
                }
            }
            TermSpec::Reversal { amplitude_nm, .. } => *amplitude_nm = rng.sym(2.0e9),
            TermSpec::Periodic { sin_nm, cos_nm, .. } => {
                for v in sin_nm.iter_mut().chain(cos_nm.iter_mut()) {
                    *v = rng.sym(2.0e8);
                }
            }
            TermSpec::Thermal { coefs_nm_per_k, .. } => {
                for c in coefs_nm_per_k.iter_mut() {
                    c.1 = rng.sym(1e4 * scale);
                }
            }
            TermSpec::Abbe { coefs, .. } => {
                for c in coefs.iter_mut() {
                    c.1 = rng.sym(1e-3 * scale);
                }
            }
            TermSpec::Mlp(m) => {
                for l in m.hidden.iter_mut().chain(std::iter::once(&mut m.output)) {
                    for w in l.weights.iter_mut().chain(l.bias.iter_mut()) {
                        *w *= scale.sqrt();
                    }
                }
                for v in m.out_max_nm.iter_mut() {
                    *v = 5e6;
                }
            }
        }
    }
    spec
}

/// [`extreme_spec`] widened for the definition check (issue 25): a random
/// subset of the term kinds, every term's coefficients scaled by 10^−6 …
/// 10^12 (an MLP's hidden weights by 10^−3 … 10^12), the max |correction|
/// from 100 nm to the format's limit (or at the limit: nothing clamped),
/// and on half the draws a tool-arm range reaching ±2^31 nm — the tables
/// whose fixed point or f32 can depart from their own definition.
pub fn edge_spec(seed: u64) -> TableSpec {
    let mut rng = Rng(seed ^ 0xED6E_5EED);
    let kinds: Vec<Kind> = (0..rng.int(1, 4))
        .map(|_| ALL_KINDS[rng.int(0, 8) as usize])
        .collect();
    let mut spec = random_spec(seed, &kinds);
    let logu = |rng: &mut Rng, lo: f64, hi: f64| 10f64.powf(rng.range(lo, hi));
    let unclamped = rng.unit() < 0.5;
    for a in 0..3 {
        spec.envelope.max_corr_nm[a] = if unclamped {
            model_core::table::MAX_CORR_LIMIT_NM
        } else {
            (logu(&mut rng, 2.0, 6.6) as i32).min(model_core::table::MAX_CORR_LIMIT_NM)
        };
    }
    if rng.unit() < 0.5 {
        let arm = |rng: &mut Rng| (logu(rng, 3.0, 9.34) as i64).min(i32::MAX as i64) as i32;
        spec.envelope.tool_min_nm = -arm(&mut rng);
        spec.envelope.tool_max_nm = arm(&mut rng);
    }
    for t in spec.terms.iter_mut() {
        let s = logu(&mut rng, -6.0, 12.0);
        match t {
            TermSpec::Poly { coefs, .. }
            | TermSpec::Thermal {
                coefs_nm_per_k: coefs,
                ..
            }
            | TermSpec::Abbe { coefs, .. } => {
                for c in coefs.iter_mut() {
                    c.1 *= s;
                }
            }
            TermSpec::Grid(g) => {
                for v in g.values_nm.iter_mut() {
                    *v *= s;
                }
            }
            TermSpec::Reversal { amplitude_nm, .. } => *amplitude_nm *= s,
            TermSpec::Periodic { sin_nm, cos_nm, .. } => {
                for v in sin_nm.iter_mut().chain(cos_nm.iter_mut()) {
                    *v *= s;
                }
            }
            TermSpec::Mlp(m) => {
                let w = logu(&mut rng, -3.0, 12.0);
                for l in m.hidden.iter_mut() {
                    for x in l.weights.iter_mut().chain(l.bias.iter_mut()) {
                        *x *= w;
                    }
                }
                let w2 = logu(&mut rng, -6.0, 9.0);
                for x in m.output.weights.iter_mut().chain(m.output.bias.iter_mut()) {
                    *x *= w2;
                }
            }
        }
    }
    spec
}

/// Random inputs inside the envelope (plus, with `outside`, sometimes beyond it).
pub fn random_inputs(rng: &mut Rng, spec: &TableSpec, outside: bool) -> Inputs {
    let env = &spec.envelope;
    let mut i = Inputs::default();
    for a in 0..3 {
        let (lo, hi) = (env.travel_min_nm[a] as i64, env.travel_max_nm[a] as i64);
        i.pos_nm[a] = if outside && rng.unit() < 0.3 {
            rng.int(i32::MIN as i64, i32::MAX as i64) as i32
        } else {
            rng.int(lo, hi) as i32
        };
        i.rev_q30[a] = rng.int(-(1 << 30), 1 << 30) as i32;
    }
    for ch in 0..spec.channels.len() {
        i.temp_mc[ch] = if outside && rng.unit() < 0.2 {
            rng.int(-100_000, 100_000) as i32
        } else {
            rng.int(env.temp_min_mc[ch] as i64, env.temp_max_mc[ch] as i64) as i32
        };
    }
    i.tool_nm = rng.int(env.tool_min_nm as i64, env.tool_max_nm as i64) as i32;
    i
}

/// Like `random_inputs(rng, spec, true)`, and the tool arm too sometimes
/// outside its range (just beyond an edge, or anywhere in i32). A separate
/// function so the streams of `random_inputs` — and the golden replay
/// vectors drawn from it — stay as they are.
pub fn random_inputs_beyond(rng: &mut Rng, spec: &TableSpec) -> Inputs {
    let mut i = random_inputs(rng, spec, true);
    let env = &spec.envelope;
    let (lo, hi) = (env.tool_min_nm as i64, env.tool_max_nm as i64);
    i.tool_nm = match rng.int(0, 9) {
        0 => rng.int(i32::MIN as i64, i32::MAX as i64) as i32,
        1 => (lo - rng.int(1, 50_000_000)).max(i32::MIN as i64) as i32,
        2 => (hi + rng.int(1, 50_000_000)).min(i32::MAX as i64) as i32,
        _ => i.tool_nm,
    };
    i
}

/// The inputs held at the envelope's edges, as the evaluator holds them:
/// positions to the travel, temperatures to their channel's range, the tool
/// arm to its range (the flags say which were held).
pub fn held_inputs(spec: &TableSpec, inp: &Inputs) -> Inputs {
    let env = &spec.envelope;
    let mut held = *inp;
    for a in 0..3 {
        held.pos_nm[a] = inp.pos_nm[a].clamp(env.travel_min_nm[a], env.travel_max_nm[a]);
    }
    for ch in 0..spec.channels.len() {
        held.temp_mc[ch] = inp.temp_mc[ch].clamp(env.temp_min_mc[ch], env.temp_max_mc[ch]);
    }
    held.tool_nm = inp.tool_nm.clamp(env.tool_min_nm, env.tool_max_nm);
    held
}

/// The edge flags an evaluation of `inp` must raise: each position held
/// to the travel, and the temperatures and the tool arm held only where
/// the table reads them (a thermal term or an MLP temperature input; an
/// Abbe term).
pub fn expected_edge_flags(spec: &TableSpec, inp: &Inputs) -> model_core::Flags {
    use model_core::Flags;
    let held = held_inputs(spec, inp);
    let reads_temp = spec.terms.iter().any(|t| match t {
        TermSpec::Thermal { .. } => true,
        TermSpec::Mlp(m) => m
            .inputs
            .iter()
            .any(|i| matches!(i.source, MlpSource::Temp(_))),
        _ => false,
    });
    let reads_tool = spec
        .terms
        .iter()
        .any(|t| matches!(t, TermSpec::Abbe { .. }));
    let mut expect = Flags::empty();
    for a in 0..3 {
        if held.pos_nm[a] != inp.pos_nm[a] {
            expect.insert(Flags::out_of_travel(a));
        }
    }
    if reads_temp && held.temp_mc != inp.temp_mc {
        expect.insert(Flags::TEMP_OUT_OF_RANGE);
    }
    if reads_tool && held.tool_nm != inp.tool_nm {
        expect.insert(Flags::TOOL_OUT_OF_RANGE);
    }
    expect
}

/// The 800 × 500 × 500 mm vertical mill of the seed (X ±400, Y ±250, Z ±250 mm).
pub fn mill_spec(n_channels: usize) -> TableSpec {
    let mut env = Envelope::default();
    let mut sc = InputScaling::default();
    for (a, half) in [400_000_000, 250_000_000, 250_000_000]
        .into_iter()
        .enumerate()
    {
        sc.half_span_nm[a] = half;
        env.travel_min_nm[a] = -half;
        env.travel_max_nm[a] = half;
        env.max_corr_nm[a] = 250_000;
    }
    env.max_slew_nm_per_ms = 500;
    for ch in 0..n_channels {
        env.temp_min_mc[ch] = 10_000;
        env.temp_max_mc[ch] = 40_000;
    }
    env.tool_min_nm = 0;
    env.tool_max_nm = 250_000_000;
    TableSpec {
        created_unix_s: 1_763_769_600, // 2025-11-22T00:00:00Z
        source_hash: core::array::from_fn(|i| (i as u8).wrapping_mul(37)),
        channels: ["bed", "air", "spindle", "column"][..n_channels]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        envelope: env,
        scaling: sc,
        outputs: [true, true, true],
        terms: Vec::new(),
    }
}

fn mlp_3x16x3(rng: &mut Rng, spec: &TableSpec, with_temp: bool, layers: usize) -> TermSpec {
    let mut inputs: Vec<MlpInputSpec> = (0..3)
        .map(|a| MlpInputSpec {
            source: MlpSource::Pos(a),
            min: spec.envelope.travel_min_nm[a as usize] as f64,
            max: spec.envelope.travel_max_nm[a as usize] as f64,
        })
        .collect();
    if with_temp {
        inputs.push(MlpInputSpec {
            source: MlpSource::Temp(0),
            min: 15_000.0,
            max: 30_000.0,
        });
    }
    let mut prev = inputs.len();
    let mut hidden = Vec::new();
    for _ in 0..layers {
        hidden.push(LayerSpec {
            weights: (0..16 * prev).map(|_| rng.sym(1.5)).collect(),
            bias: (0..16).map(|_| rng.sym(1.0)).collect(),
        });
        prev = 16;
    }
    TermSpec::Mlp(MlpSpec {
        outputs: vec![0, 1, 2],
        inputs,
        hidden,
        output: LayerSpec {
            weights: (0..3 * 16).map(|_| rng.sym(0.25)).collect(),
            bias: vec![0.01, -0.02, 0.03],
        },
        out_min_nm: vec![-40_000.0, -30_000.0, -20_000.0],
        out_max_nm: vec![40_000.0, 30_000.0, 20_000.0],
    })
}

/// The checked-in golden tables (name → spec). Also the tables the MCU
/// benches and the replay vectors use: `cubic19`, `full` (cubic19 + periodic
/// with 2 harmonics + thermal + reversal), `nn_3x16x3`, `grid_17x11`,
/// `all_kinds`.
pub fn golden_specs() -> Vec<(&'static str, TableSpec)> {
    let mut out = Vec::new();
    let mut rng = Rng(19);
    let mut cubic = mill_spec(1);
    for o in 0..3 {
        cubic.terms.push(TermSpec::Poly {
            output: o,
            coefs: poly(&mut rng, &CUBIC19, 8_000.0),
        });
    }
    out.push(("cubic19", cubic.clone()));

    let mut full = cubic.clone();
    full.terms.push(TermSpec::Periodic {
        output: 1,
        axis: 1,
        period_nm: 5_000_000,
        sin_nm: vec![3_000.0, -800.0],
        cos_nm: vec![1_200.0, 400.0],
    });
    full.terms.push(TermSpec::Thermal {
        output: 0,
        channel: 0,
        t_ref_mc: 20_000,
        coefs_nm_per_k: vec![([0, 0, 0], 4_600.0), ([1, 0, 0], 4_600.0)],
    });
    full.terms.push(TermSpec::Reversal {
        output: 0,
        axis: 0,
        transition_nm: 20_000,
        amplitude_nm: 6_000.0,
    });
    out.push(("full", full));

    let mut nn = mill_spec(1);
    let mut rng = Rng(316);
    let t = mlp_3x16x3(&mut rng, &nn, false, 1);
    nn.terms.push(t);
    out.push(("nn_3x16x3", nn));

    let mut grid = mill_spec(0);
    let mut rng = Rng(1711);
    grid.outputs = [true, false, true];
    grid.terms.push(TermSpec::Grid(GridSpec {
        output: 0,
        axes: [
            GridAxisSpec {
                nodes: 17,
                origin_nm: -400_000_000,
                step_nm: 50_000_000,
            },
            GridAxisSpec {
                nodes: 11,
                origin_nm: -250_000_000,
                step_nm: 50_000_000,
            },
            GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1,
            },
        ],
        values_nm: (0..17 * 11).map(|_| rng.sym(15_000.0)).collect(),
    }));
    grid.terms.push(TermSpec::Grid(GridSpec {
        output: 2,
        axes: [
            GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1,
            },
            GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1,
            },
            GridAxisSpec {
                nodes: 11,
                origin_nm: -250_000_000,
                step_nm: 50_000_000,
            },
        ],
        values_nm: (0..11).map(|_| rng.sym(5_000.0)).collect(),
    }));
    out.push(("grid_17x11", grid));

    let mut all = mill_spec(2);
    let mut rng = Rng(777);
    for o in 0..3 {
        all.terms.push(TermSpec::Poly {
            output: o,
            coefs: poly(&mut rng, kinematic(o as usize), 10_000.0),
        });
    }
    all.terms.push(TermSpec::Poly {
        output: 2,
        coefs: poly(
            &mut rng,
            &[[5, 0, 0], [0, 4, 1], [1, 1, 1], [2, 2, 1]],
            2_000.0,
        ),
    });
    all.terms.push(TermSpec::Periodic {
        output: 0,
        axis: 0,
        period_nm: 10_000_000,
        sin_nm: vec![2_000.0, 500.0, -250.0, 100.0],
        cos_nm: vec![-700.0, 300.0, 120.0, -50.0],
    });
    all.terms.push(TermSpec::Thermal {
        output: 2,
        channel: 1,
        t_ref_mc: 20_000,
        coefs_nm_per_k: vec![([0, 0, 0], -1_500.0)],
    });
    all.terms.push(TermSpec::Reversal {
        output: 1,
        axis: 1,
        transition_nm: 10_000,
        amplitude_nm: -3_500.0,
    });
    all.terms.push(TermSpec::Abbe {
        output: 1,
        coefs: vec![([0, 0, 0], 48.5e-6), ([1, 0, 0], -10e-6)],
    });
    let t = mlp_3x16x3(&mut rng, &all, true, 2);
    all.terms.push(t);
    all.terms.push(TermSpec::Grid(GridSpec {
        output: 0,
        axes: [
            GridAxisSpec {
                nodes: 5,
                origin_nm: -400_000_000,
                step_nm: 200_000_000,
            },
            GridAxisSpec {
                nodes: 3,
                origin_nm: -250_000_000,
                step_nm: 250_000_000,
            },
            GridAxisSpec {
                nodes: 3,
                origin_nm: -250_000_000,
                step_nm: 250_000_000,
            },
        ],
        values_nm: (0..45).map(|_| rng.sym(3_000.0)).collect(),
    }));
    out.push(("all_kinds", all));
    out
}

/// Replay vector files (little-endian), see `tests/vectors/README.md`:
/// header `TXVE`, u16 version 1, u16 record size in i32 words (18),
/// u32 record count, u32 CRC32 of the table the vectors belong to;
/// then per record 18 × i32: pos_nm[3], rev_q30[3], temp_mc[4], tool_nm,
/// expected fixed corr_nm[3], expected fixed flags, f64 reference in Q8 nm [3].
pub const VEC_MAGIC: &[u8; 4] = b"TXVE";
/// i32 words per record.
pub const VEC_WORDS: usize = 18;

/// Which inputs a vector file draws.
#[derive(Clone, Copy, Debug)]
pub struct VectorPlan {
    /// Records in all.
    pub records: usize,
    /// The first this many inside the envelope, the rest beyond it.
    pub inside: usize,
    /// Beyond the envelope the tool arm leaves its range too
    /// (`random_inputs_beyond`; otherwise `random_inputs(.., true)`).
    pub tool_beyond: bool,
}

/// The replay vectors of `spec` drawn from `seed`: inputs, the expected
/// fixed-point result (`Model::eval_fixed`) and the f64 reference on the
/// inputs held at the envelope's edges (what the firmware should approach).
pub fn make_vectors(spec: &TableSpec, seed: u64, plan: VectorPlan) -> Vec<u8> {
    let bytes = spec.encode().expect("encode");
    let table = parse(&bytes).expect("parse");
    let model = Model::load(&table).expect("load");
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    out.extend_from_slice(VEC_MAGIC);
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&(VEC_WORDS as u16).to_le_bytes());
    out.extend_from_slice(&(plan.records as u32).to_le_bytes());
    out.extend_from_slice(&table.crc32().to_le_bytes());
    for i in 0..plan.records {
        let inp = if i < plan.inside {
            random_inputs(&mut rng, spec, false)
        } else if plan.tool_beyond {
            random_inputs_beyond(&mut rng, spec)
        } else {
            random_inputs(&mut rng, spec, true)
        };
        let q = model.eval_fixed(&inp);
        let r = spec.eval_f64(&InputsF64::from(&held_inputs(spec, &inp)));
        let words: Vec<i32> = inp
            .pos_nm
            .iter()
            .chain(&inp.rev_q30)
            .chain(&inp.temp_mc)
            .copied()
            .chain([inp.tool_nm])
            .chain(q.corr_nm)
            .chain([q.flags.bits() as i32])
            .chain(
                r.iter()
                    .map(|v| (v * 256.0).round().clamp(i32::MIN as f64, i32::MAX as f64) as i32),
            )
            .collect();
        assert_eq!(words.len(), VEC_WORDS);
        for w in words {
            out.extend_from_slice(&w.to_le_bytes());
        }
    }
    out
}

/// Number of seeded random models replayed on the target.
pub const QEMU_RANDOM_MODELS: usize = 16;

/// The seeded random models the QEMU suite replays (host vs thumbv7em, fixed
/// point bit for bit, f32 within 1 nm of the f64 reference): model i has
/// kind i (every kind at least once) plus 0–3 others drawn from its seed,
/// of realistic size (`random_spec`); a draw that does not fit the MCU's
/// `Model` (grid or parameter capacity) is skipped for the next seed.
/// Name: `random_<i>` and its kinds.
pub fn qemu_random_specs() -> Vec<(String, TableSpec)> {
    let mut out = Vec::new();
    let mut seed = 0x0E_4D00_0000u64;
    while out.len() < QEMU_RANDOM_MODELS {
        seed += 1;
        let i = out.len();
        let mut rng = Rng(seed);
        let mut kinds = vec![ALL_KINDS[i % ALL_KINDS.len()]];
        for _ in 0..rng.int(0, 3) {
            kinds.push(ALL_KINDS[rng.int(0, ALL_KINDS.len() as i64 - 1) as usize]);
        }
        let spec = random_spec(seed, &kinds);
        let fits = spec
            .encode()
            .ok()
            .is_some_and(|b| parse(&b).is_ok_and(|t| Model::load(&t).is_ok()));
        if fits {
            let names: Vec<String> = kinds.iter().map(|k| format!("{k:?}")).collect();
            out.push((format!("random_{i:02} {}", names.join("+")), spec));
        }
    }
    out
}

/// The seed of random model i's vectors.
pub fn qemu_random_vector_seed(i: usize) -> u64 {
    0x0E_4D00_5EED + i as u64
}

/// The vector plan of the random models: 64 records inside the envelope,
/// 32 beyond it (positions, temperatures, tool arm).
pub const QEMU_RANDOM_PLAN: VectorPlan = VectorPlan {
    records: 96,
    inside: 64,
    tool_beyond: true,
};
