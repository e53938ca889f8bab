//! Extra bench tables, one per evaluation path of model-core and at both
//! ends of each size parameter, so that the instruction counts of the bench
//! image cover everything the static cost estimate (`model_core::cost`)
//! claims to bound: polynomials of degree 1 and 5, periodic terms with 1
//! and 4 harmonics, thermal and Abbe terms on the f32 fast path (degree ≤ 1)
//! and off it (degree 3), reversal on three axes, a 3-D grid, a two-layer
//! MLP and an MLP with a temperature input, and a mix that leaves the f32
//! fast path. Same mill and envelope as build/tables.rs; fixed seeds.

use model_core::board::LimitError;
use model_core::monomials::CUBIC19;
use model_core::spec::PolyCoef;
use model_core::{
    EncodeError, GridAxisSpec, GridSpec, LayerSpec, MlpInputSpec, MlpSource, MlpSpec, TableSpec,
    TermSpec,
};

use crate::tables::{self, Rng, TRAVEL_MAX_NM};

/// build/tables.rs's mill with `channels` temperature channels (10–40 °C)
/// and corrections up to 400 µm.
fn base_with(tag: u8, channels: usize) -> TableSpec {
    let mut s = tables::base(0xC0 ^ tag);
    s.channels = ["T_bed_C", "T_col_C", "T_spindle_C", "T_air_C"][..channels]
        .iter()
        .map(|c| c.to_string())
        .collect();
    s.envelope.max_corr_nm = [400_000; 3];
    for ch in 0..channels {
        s.envelope.temp_min_mc[ch] = 10_000;
        s.envelope.temp_max_mc[ch] = 40_000;
    }
    s
}

/// The extra bench tables' base: two channels.
fn base(tag: u8) -> TableSpec {
    base_with(tag, 2)
}

/// Every monomial of total degree ≤ `deg`, coefficients shrinking with it.
fn poly(rng: &mut Rng, deg: u8, scale: f64) -> Vec<PolyCoef> {
    let mut v = Vec::new();
    for a in 0..=deg {
        for b in 0..=deg - a {
            for c in 0..=deg - a - b {
                let d = f64::from(a + b + c);
                v.push(([a, b, c], rng.signed_unit() * scale / (1.0 + d * d)));
            }
        }
    }
    v
}

/// A cubic19 polynomial on each output, ±3 µm coefficients (drawn output
/// by output, monomial by monomial).
fn cubic19_on_each_output(rng: &mut Rng) -> Vec<TermSpec> {
    (0..3)
        .map(|o| TermSpec::Poly {
            output: o,
            coefs: CUBIC19
                .iter()
                .map(|&m| (m, 3_000.0 * rng.signed_unit()))
                .collect(),
        })
        .collect()
}

fn periodic(rng: &mut Rng, output: u8, axis: u8, harmonics: usize) -> TermSpec {
    TermSpec::Periodic {
        output,
        axis,
        period_nm: 5_000_000 + 1_000_000 * i32::from(axis),
        sin_nm: (0..harmonics)
            .map(|k| 1_500.0 * rng.signed_unit() / (k + 1) as f64)
            .collect(),
        cos_nm: (0..harmonics)
            .map(|k| 1_500.0 * rng.signed_unit() / (k + 1) as f64)
            .collect(),
    }
}

fn mlp(rng: &mut Rng, inputs: Vec<MlpInputSpec>, hidden: &[usize], outputs: Vec<u8>) -> TermSpec {
    let mut prev = inputs.len();
    let mut layers = Vec::new();
    for &h in hidden {
        layers.push(LayerSpec {
            weights: (0..h * prev).map(|_| 1.2 * rng.signed_unit()).collect(),
            bias: (0..h).map(|_| 0.5 * rng.signed_unit()).collect(),
        });
        prev = h;
    }
    let n_out = outputs.len();
    TermSpec::Mlp(MlpSpec {
        output: LayerSpec {
            weights: (0..n_out * prev).map(|_| 0.4 * rng.signed_unit()).collect(),
            bias: (0..n_out).map(|_| 0.1 * rng.signed_unit()).collect(),
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
                amplitude_nm: 2_000.0 * rng.signed_unit(),
            });
        }
    }
    add("reversal_3x3", s)?;

    // Thermal and Abbe of degree ≤ 1 with cubic19 (f32 fast path), then
    // degree 3 (general term loop, monomials handed over).
    let mut s = base(6);
    s.terms = cubic19_on_each_output(&mut rng);
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
        values_nm: (0..729).map(|_| 5_000.0 * rng.signed_unit()).collect(),
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
    s.terms = cubic19_on_each_output(&mut rng);
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
            amplitude_nm: 2_500.0 * rng.signed_unit(),
        });
    }
    s.terms.push(TermSpec::Grid(GridSpec {
        output: 0,
        axes: [ax(0, 5), ax(1, 5), ax(2, 3)],
        values_nm: (0..75).map(|_| 2_000.0 * rng.signed_unit()).collect(),
    }));
    s.terms
        .push(mlp(&mut rng, pos_inputs(), &[16], vec![0, 1, 2]));
    add("mixed", s)?;
    Ok(out)
}

/// Seeded random tables in the calibration set of `cargo xtask bench-mcu
/// --calibrate` (with the bench tables above: the set the ratio of the
/// cost estimate to the count is reported on, BENCHMARKS.md).
pub const CALIBRATION_TABLES: usize = 191;

/// An integer in `lo..=hi`.
fn int(rng: &mut Rng, lo: u32, hi: u32) -> u32 {
    lo + (rng.next_u64() % u64::from(hi - lo + 1)) as u32
}

/// True with probability `p`.
fn chance(rng: &mut Rng, p: f64) -> bool {
    (rng.signed_unit() + 1.0) / 2.0 < p
}

/// Up to `max` monomials of total degree ≤ `deg` (always the highest
/// one, so the term has that degree), coefficients `scale`.
fn sparse_poly(rng: &mut Rng, deg: u8, max: u32, scale: f64) -> Vec<PolyCoef> {
    let mut all = poly(rng, deg, scale);
    // The last monomial of `poly` has degree `deg`; keep it, shuffle the rest.
    let top = all.pop().expect("a polynomial has a monomial");
    for i in (1..all.len()).rev() {
        all.swap(i, rng.next_u64() as usize % (i + 1));
    }
    all.truncate(int(rng, 0, max - 1) as usize);
    all.push(top);
    all
}

/// One random table of the calibration set: every term kind drawn with
/// some probability, at every size the format allows — polynomials of
/// degree 1–5 on 1–3 outputs, 1–4 periodic terms of 1–4 harmonics, 1–6
/// reversals, 1–3 thermal and 1–2 Abbe terms of degree 0–5 with up to 25
/// coefficients, 1–2 grids over 1–3 axes, an MLP with 3–7 inputs, one or
/// two hidden layers of 4–32 units and 1–3 outputs; 1–4 temperature
/// channels.
fn calibration_spec(rng: &mut Rng, tag: u8) -> TableSpec {
    let nch = int(rng, 1, 4) as usize;
    let mut s = base_with(tag, nch);
    let output = |rng: &mut Rng| int(rng, 0, 2) as u8;
    if chance(rng, 0.6) {
        let deg = int(rng, 1, 5) as u8;
        for o in 0..3u8 {
            if o == 0 || chance(rng, 0.7) {
                s.terms.push(TermSpec::Poly {
                    output: o,
                    coefs: poly(rng, deg, 6_000.0),
                });
            }
        }
    }
    if chance(rng, 0.4) {
        for _ in 0..int(rng, 1, 4) {
            let (o, axis, h) = (output(rng), output(rng), int(rng, 1, 4) as usize);
            s.terms.push(periodic(rng, o, axis, h));
        }
    }
    if chance(rng, 0.4) {
        for _ in 0..int(rng, 1, 6) {
            s.terms.push(TermSpec::Reversal {
                output: output(rng),
                axis: output(rng),
                // One transition length per axis (the format requires it).
                transition_nm: 20_000,
                amplitude_nm: 3_000.0 * rng.signed_unit(),
            });
        }
    }
    if chance(rng, 0.35) {
        for _ in 0..int(rng, 1, 3) {
            let deg = int(rng, 0, 5) as u8;
            s.terms.push(TermSpec::Thermal {
                output: output(rng),
                channel: int(rng, 0, nch as u32 - 1) as u8,
                t_ref_mc: 20_000,
                coefs_nm_per_k: sparse_poly(rng, deg, 25, 1_500.0),
            });
        }
    }
    if chance(rng, 0.25) {
        for _ in 0..int(rng, 1, 2) {
            let deg = int(rng, 0, 5) as u8;
            s.terms.push(TermSpec::Abbe {
                output: output(rng),
                coefs: sparse_poly(rng, deg, 25, 30e-6),
            });
        }
    }
    if chance(rng, 0.25) {
        for _ in 0..int(rng, 1, 2) {
            let mut axes = [GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1,
            }; 3];
            let used = int(rng, 1, 3);
            let first = int(rng, 0, 2);
            for k in 0..used {
                let a = ((first + k) % 3) as usize;
                let nodes = int(rng, 2, 9) as u16;
                axes[a] = GridAxisSpec {
                    nodes,
                    origin_nm: 0,
                    step_nm: TRAVEL_MAX_NM[a] / i32::from(nodes - 1),
                };
            }
            let n: usize = axes.iter().map(|a| usize::from(a.nodes)).product();
            s.terms.push(TermSpec::Grid(GridSpec {
                output: output(rng),
                axes,
                values_nm: (0..n).map(|_| 4_000.0 * rng.signed_unit()).collect(),
            }));
        }
    }
    if chance(rng, 0.35) {
        let mut inputs = pos_inputs();
        for ch in 0..int(rng, 0, nch as u32) as u8 {
            inputs.push(MlpInputSpec {
                source: MlpSource::Temp(ch),
                min: 15_000.0,
                max: 30_000.0,
            });
        }
        let layers = int(rng, 1, 2) as usize;
        let hidden: Vec<usize> = (0..layers).map(|_| int(rng, 4, 32) as usize).collect();
        let outputs: Vec<u8> = (0..3u8).filter(|_| chance(rng, 0.6)).collect();
        let outputs = if outputs.is_empty() {
            vec![output(rng)]
        } else {
            outputs
        };
        s.terms.push(mlp(rng, inputs, &hidden, outputs));
    }
    if s.terms.is_empty() {
        s.terms.push(TermSpec::Poly {
            output: 0,
            coefs: poly(rng, 3, 6_000.0),
        });
    }
    s
}

/// (name, table bytes) of the calibration set's random tables: draws the
/// board cannot hold (staging buffer, model capacity) are skipped for the
/// next one — the estimate only has to be right for tables the board can
/// load; those too slow for its loop are kept.
pub fn calibration() -> Result<Vec<(String, Vec<u8>)>, EncodeError> {
    let mut out = Vec::new();
    let mut rng = Rng::new(0xCA1B_0000);
    while out.len() < CALIBRATION_TABLES {
        let i = out.len();
        let bytes = calibration_spec(&mut rng, i as u8).encode()?;
        let table = model_core::parse(&bytes).expect("an encoded table parses");
        match model_core::board::check(&table) {
            Ok(()) | Err(LimitError::TooSlow { .. }) => {
                out.push((format!("cal_{i:03}"), bytes));
            }
            Err(_) => {}
        }
    }
    Ok(out)
}
