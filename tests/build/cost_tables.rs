//! Extra bench tables, one per evaluation path of model-core and at both
//! ends of each size parameter, so that the instruction counts of the bench
//! image cover everything the static cost estimate (`model_core::cost`)
//! claims to bound: polynomials of degree 1 and 5, periodic terms with 1
//! and 4 harmonics, thermal and Abbe terms on the f32 fast path (degree ≤ 1)
//! and off it (degree 3), reversal on three axes, a 3-D grid, a two-layer
//! MLP and an MLP with a temperature input, and a mix that leaves the f32
//! fast path. Same mill and envelope as build/tables.rs; fixed seeds.

use model_core::monomials::CUBIC19;
use model_core::spec::PolyCoef;
use model_core::{
    EncodeError, Envelope, GridAxisSpec, GridSpec, InputScaling, LayerSpec, MlpInputSpec,
    MlpSource, MlpSpec, TableSpec, TermSpec,
};

use crate::tables::{Rng, TRAVEL_MAX_NM};

fn base(tag: u8) -> TableSpec {
    TableSpec {
        created_unix_s: 1_767_225_600,
        source_hash: [0xC0 ^ tag; 32],
        channels: vec!["T_bed_C".into(), "T_col_C".into()],
        envelope: Envelope {
            travel_min_nm: [0; 3],
            travel_max_nm: TRAVEL_MAX_NM,
            max_corr_nm: [400_000; 3],
            max_slew_nm_per_ms: 50,
            temp_min_mc: [10_000, 10_000, 0, 0],
            temp_max_mc: [40_000, 40_000, 0, 0],
            tool_min_nm: 0,
            tool_max_nm: 300_000_000,
        },
        scaling: InputScaling {
            centre_nm: TRAVEL_MAX_NM.map(|t| t / 2),
            half_span_nm: TRAVEL_MAX_NM.map(|t| t / 2),
        },
        outputs: [true; 3],
        terms: Vec::new(),
    }
}

/// Every monomial of total degree ≤ `deg`, coefficients shrinking with it.
fn poly(rng: &mut Rng, deg: u8, scale: f64) -> Vec<PolyCoef> {
    let mut v = Vec::new();
    for a in 0..=deg {
        for b in 0..=deg - a {
            for c in 0..=deg - a - b {
                let d = f64::from(a + b + c);
                v.push(([a, b, c], rng.sym() * scale / (1.0 + d * d)));
            }
        }
    }
    v
}

fn periodic(rng: &mut Rng, output: u8, axis: u8, harmonics: usize) -> TermSpec {
    TermSpec::Periodic {
        output,
        axis,
        period_nm: 5_000_000 + 1_000_000 * i32::from(axis),
        sin_nm: (0..harmonics)
            .map(|k| 1_500.0 * rng.sym() / (k + 1) as f64)
            .collect(),
        cos_nm: (0..harmonics)
            .map(|k| 1_500.0 * rng.sym() / (k + 1) as f64)
            .collect(),
    }
}

fn mlp(rng: &mut Rng, inputs: Vec<MlpInputSpec>, hidden: &[usize], outputs: Vec<u8>) -> TermSpec {
    let mut prev = inputs.len();
    let mut layers = Vec::new();
    for &h in hidden {
        layers.push(LayerSpec {
            weights: (0..h * prev).map(|_| 1.2 * rng.sym()).collect(),
            bias: (0..h).map(|_| 0.5 * rng.sym()).collect(),
        });
        prev = h;
    }
    let n_out = outputs.len();
    TermSpec::Mlp(MlpSpec {
        output: LayerSpec {
            weights: (0..n_out * prev).map(|_| 0.4 * rng.sym()).collect(),
            bias: (0..n_out).map(|_| 0.1 * rng.sym()).collect(),
        },
        outputs,
        inputs,
        hidden: layers,
        out_min_nm: vec![-20_000.0; n_out],
        out_max_nm: vec![20_000.0; n_out],
    })
}

fn pos_inputs() -> Vec<MlpInputSpec> {
    (0..3u8)
        .map(|axis| MlpInputSpec {
            source: MlpSource::Pos(axis),
            min: 0.0,
            max: f64::from(TRAVEL_MAX_NM[axis as usize]),
        })
        .collect()
}

/// (name, table bytes) of every extra bench table.
pub fn all() -> Result<Vec<(&'static str, Vec<u8>)>, EncodeError> {
    let mut out = Vec::new();
    let mut rng = Rng::new(0xC057_0001);
    let mut add = |name: &'static str, spec: TableSpec| -> Result<(), EncodeError> {
        out.push((name, spec.encode()?));
        Ok(())
    };

    // Polynomials alone: the straight-line degree-3 path with only four
    // monomials used, and the 56-monomial loop on all outputs.
    let mut s = base(1);
    s.terms = (0..3)
        .map(|o| TermSpec::Poly {
            output: o,
            coefs: poly(&mut rng, 1, 5_000.0),
        })
        .collect();
    add("poly_deg1", s)?;
    let mut s = base(2);
    s.terms = (0..3)
        .map(|o| TermSpec::Poly {
            output: o,
            coefs: poly(&mut rng, 5, 8_000.0),
        })
        .collect();
    add("poly_deg5", s)?;

    // Periodic terms only (f32 fast path, no polynomial), 1 and 4 harmonics.
    let mut s = base(3);
    s.terms = vec![periodic(&mut rng, 1, 1, 1)];
    add("periodic_1x1", s)?;
    let mut s = base(4);
    s.terms = (0..3).map(|a| periodic(&mut rng, a, a, 4)).collect();
    add("periodic_3x4", s)?;

    // Reversal on every axis into every output (f32: one 3 × 3 matrix).
    let mut s = base(5);
    for axis in 0..3u8 {
        for output in 0..3u8 {
            s.terms.push(TermSpec::Reversal {
                output,
                axis,
                transition_nm: 20_000,
                amplitude_nm: 2_000.0 * rng.sym(),
            });
        }
    }
    add("reversal_3x3", s)?;

    // Thermal and Abbe of degree ≤ 1 with cubic19 (f32 fast path), then
    // degree 3 (general term loop, monomials handed over).
    let mut s = base(6);
    s.terms = (0..3)
        .map(|o| TermSpec::Poly {
            output: o,
            coefs: CUBIC19.iter().map(|&m| (m, 3_000.0 * rng.sym())).collect(),
        })
        .collect();
    for ch in 0..2u8 {
        for output in 0..3u8 {
            s.terms.push(TermSpec::Thermal {
                output,
                channel: ch,
                t_ref_mc: 20_000,
                coefs_nm_per_k: poly(&mut rng, 1, 2_000.0),
            });
        }
    }
    s.terms.push(TermSpec::Abbe {
        output: 1,
        coefs: vec![([0, 0, 0], 40e-6), ([1, 0, 0], -8e-6), ([0, 0, 1], 5e-6)],
    });
    add("cubic19_thermal1", s)?;
    let mut s = base(7);
    for output in 0..3u8 {
        s.terms.push(TermSpec::Thermal {
            output,
            channel: output % 2,
            t_ref_mc: 20_000,
            coefs_nm_per_k: poly(&mut rng, 3, 2_000.0),
        });
        s.terms.push(TermSpec::Abbe {
            output,
            coefs: poly(&mut rng, 3, 30e-6),
        });
    }
    add("thermal3_abbe3", s)?;

    // A 3-D grid (9 × 9 × 9 = 729 values, within the board's 1024).
    let mut s = base(8);
    let ax = |a: usize, n: u16| GridAxisSpec {
        nodes: n,
        origin_nm: 0,
        step_nm: TRAVEL_MAX_NM[a] / i32::from(n - 1),
    };
    s.terms = vec![TermSpec::Grid(GridSpec {
        output: 2,
        axes: [ax(0, 9), ax(1, 9), ax(2, 9)],
        values_nm: (0..729).map(|_| 5_000.0 * rng.sym()).collect(),
    })];
    add("grid_9x9x9", s)?;

    // MLPs: two hidden layers; and a temperature input with one output
    // (the shapes without a monomorphised kernel).
    let mut s = base(9);
    s.terms = vec![mlp(&mut rng, pos_inputs(), &[8, 8], vec![0, 1, 2])];
    add("nn_3x8x8x3", s)?;
    let mut s = base(10);
    let mut inputs = pos_inputs();
    inputs.push(MlpInputSpec {
        source: MlpSource::Temp(0),
        min: 15_000.0,
        max: 30_000.0,
    });
    s.terms = vec![mlp(&mut rng, inputs, &[12], vec![2])];
    add("nn_4x12x1", s)?;

    // Everything at once off the fast path: cubic19, periodic, thermal of
    // degree 3, reversal, a grid and a network.
    let mut s = base(11);
    s.terms = (0..3)
        .map(|o| TermSpec::Poly {
            output: o,
            coefs: CUBIC19.iter().map(|&m| (m, 3_000.0 * rng.sym())).collect(),
        })
        .collect();
    s.terms.push(periodic(&mut rng, 1, 1, 2));
    s.terms.push(TermSpec::Thermal {
        output: 0,
        channel: 0,
        t_ref_mc: 20_000,
        coefs_nm_per_k: poly(&mut rng, 3, 1_500.0),
    });
    for axis in 0..3u8 {
        s.terms.push(TermSpec::Reversal {
            output: axis,
            axis,
            transition_nm: 20_000,
            amplitude_nm: 2_500.0 * rng.sym(),
        });
    }
    s.terms.push(TermSpec::Grid(GridSpec {
        output: 0,
        axes: [ax(0, 5), ax(1, 5), ax(2, 3)],
        values_nm: (0..75).map(|_| 2_000.0 * rng.sym()).collect(),
    }));
    s.terms
        .push(mlp(&mut rng, pos_inputs(), &[16], vec![0, 1, 2]));
    add("mixed", s)?;
    Ok(out)
}
