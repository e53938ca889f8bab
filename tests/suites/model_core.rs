//! model-core on the target: the same tables evaluated on the Cortex-M4F
//! in QEMU must give the host's results — fixed point bit for bit (the
//! firmware's correction path), f32 within 1 nm — on seeded inputs that
//! also leave the envelope (clamps and flags). Two sources of expected
//! values: model-core's checked-in golden tables and replay vectors
//! (model-core/tests/golden, model-core/tests/vectors, generated on the
//! host by model-core's tests), and the bench tables with vectors computed
//! on the host by this crate's build script (build/tables.rs). Parsing the
//! golden tables cut short or with any single bit flipped must fail with an
//! error, never panic. Also 16 seeded random models of model-core's test
//! generator (every term kind; build/random.rs writes them and their
//! vectors, inside and beyond the envelope, tool arm included), replayed
//! like the golden ones.
#![no_std]
#![no_main]

use trueaxis_qemu as _;

/// Words per record, as written by build/tables.rs (`RECORD_WORDS`).
const RECORD_WORDS: usize = 3 + 3 + model_core::MAX_TEMPS + 1 + 3 + 1 + 3 + 1;

/// One host-evaluated record.
struct Record {
    inputs: model_core::Inputs,
    fixed_nm: [i32; 3],
    fixed_flags: u16,
    f32_nm: [i32; 3],
    f32_flags: u16,
}

fn records(bytes: &'static [u8]) -> impl Iterator<Item = Record> {
    defmt::assert_eq!(bytes.len() % (4 * RECORD_WORDS), 0, "vector file length");
    bytes.chunks_exact(4 * RECORD_WORDS).map(|rec| {
        let w = |i: usize| {
            i32::from_le_bytes([rec[4 * i], rec[4 * i + 1], rec[4 * i + 2], rec[4 * i + 3]])
        };
        let t = model_core::MAX_TEMPS;
        let o = 7 + t;
        Record {
            inputs: model_core::Inputs {
                pos_nm: [w(0), w(1), w(2)],
                rev_q30: [w(3), w(4), w(5)],
                temp_mc: core::array::from_fn(|k| w(6 + k)),
                tool_nm: w(6 + t),
            },
            fixed_nm: [w(o), w(o + 1), w(o + 2)],
            fixed_flags: w(o + 3) as u16,
            f32_nm: [w(o + 4), w(o + 5), w(o + 6)],
            f32_flags: w(o + 7) as u16,
        }
    })
}

/// The tables and their host vectors.
const CASES: [(&str, &[u8], &[u8]); 4] = [
    (
        "cubic19",
        include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.bin")),
        include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.vectors")),
    ),
    (
        "full",
        include_bytes!(concat!(env!("OUT_DIR"), "/full.bin")),
        include_bytes!(concat!(env!("OUT_DIR"), "/full.vectors")),
    ),
    (
        "nn_3x16x3",
        include_bytes!(concat!(env!("OUT_DIR"), "/nn_3x16x3.bin")),
        include_bytes!(concat!(env!("OUT_DIR"), "/nn_3x16x3.vectors")),
    ),
    // The engine's export of a fitted rigid21:4 model (P0 + L·P1: polynomial
    // and Abbe blocks, the tool length as input; tests/golden/rigid21.bin),
    // at tool lengths −10…310 mm.
    (
        "rigid21",
        include_bytes!(concat!(env!("OUT_DIR"), "/rigid21.bin")),
        include_bytes!(concat!(env!("OUT_DIR"), "/rigid21.vectors")),
    ),
];

fn load(name: &str, bytes: &[u8]) -> model_core::Model {
    let table = match model_core::parse(bytes) {
        Ok(t) => t,
        Err(e) => defmt::panic!("{=str}: parse failed: {}", name, defmt::Debug2Format(&e)),
    };
    match model_core::Model::load(&table) {
        Ok(m) => m,
        Err(e) => defmt::panic!("{=str}: load failed: {}", name, defmt::Debug2Format(&e)),
    }
}

/// model-core's golden tables with their replay vectors.
const GOLDEN: [(&str, &[u8], &[u8]); 5] = [
    (
        "cubic19",
        include_bytes!("../../model-core/tests/golden/cubic19.bin"),
        include_bytes!("../../model-core/tests/vectors/cubic19.vec"),
    ),
    (
        "full",
        include_bytes!("../../model-core/tests/golden/full.bin"),
        include_bytes!("../../model-core/tests/vectors/full.vec"),
    ),
    (
        "nn_3x16x3",
        include_bytes!("../../model-core/tests/golden/nn_3x16x3.bin"),
        include_bytes!("../../model-core/tests/vectors/nn_3x16x3.vec"),
    ),
    (
        "grid_17x11",
        include_bytes!("../../model-core/tests/golden/grid_17x11.bin"),
        include_bytes!("../../model-core/tests/vectors/grid_17x11.vec"),
    ),
    (
        "all_kinds",
        include_bytes!("../../model-core/tests/golden/all_kinds.bin"),
        include_bytes!("../../model-core/tests/vectors/all_kinds.vec"),
    ),
];

// `RANDOM_MODELS`: (name, table, vectors) of 16 seeded random models of
// model-core's generator, written by build/random.rs.
include!(concat!(env!("OUT_DIR"), "/random_models.rs"));

/// Words per record of a `.vec` file (model-core/tests/vectors/README.md).
const VEC_WORDS: usize = 18;

fn le_i32(b: &[u8], at: usize) -> i32 {
    i32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Replays a `.vec` file (model-core/tests/vectors/README.md) against its
/// table: `eval_fixed` must equal the host's result bit for bit (and the
/// flags), `eval_f32` lie within 1 nm of the f64 reference.
fn replay(name: &str, table_bytes: &[u8], vec: &[u8]) {
    let table = match model_core::parse(table_bytes) {
        Ok(t) => t,
        Err(e) => defmt::panic!("{=str}: {}", name, defmt::Debug2Format(&e)),
    };
    // Header: magic, version 1, words per record, count, table CRC.
    defmt::assert_eq!(&vec[..4], b"TXVE", "{=str}: vector magic", name);
    defmt::assert_eq!(u16::from_le_bytes([vec[4], vec[5]]), 1);
    defmt::assert_eq!(u16::from_le_bytes([vec[6], vec[7]]) as usize, VEC_WORDS);
    let count = le_i32(vec, 8) as usize;
    defmt::assert_eq!(
        le_i32(vec, 12) as u32,
        table.crc32(),
        "{=str}: vectors belong to another table",
        name
    );
    defmt::assert_eq!(vec.len(), 16 + count * 4 * VEC_WORDS);
    let model = match model_core::Model::load(&table) {
        Ok(m) => m,
        Err(e) => defmt::panic!("{=str}: load: {}", name, defmt::Debug2Format(&e)),
    };
    let env = table.envelope();
    let mask = model.outputs_mask();
    let mut worst_f32_milli_nm = 0i64;
    let mut flagged = 0u32;
    for r in 0..count {
        let w = |i: usize| le_i32(vec, 16 + 4 * (r * VEC_WORDS + i));
        let inputs = model_core::Inputs {
            pos_nm: [w(0), w(1), w(2)],
            rev_q30: [w(3), w(4), w(5)],
            temp_mc: [w(6), w(7), w(8), w(9)],
            tool_nm: w(10),
        };
        let fixed = model.eval_fixed(&inputs);
        let want = [w(11), w(12), w(13)];
        if fixed.corr_nm != want || i32::from(fixed.flags.bits()) != w(14) {
            defmt::panic!(
                "{=str} record {}: target {} flags {=u16:#x}, host {} flags {:#x}",
                name,
                r,
                fixed.corr_nm,
                fixed.flags.bits(),
                want,
                w(14)
            );
        }
        flagged += u32::from(w(14) != 0);
        let f = model.eval_f32(&inputs);
        for o in 0..3 {
            // The f64 reference in Q8 nm, held to the envelope.
            let reference_q8 = if mask & (1 << o) == 0 {
                0
            } else {
                let m = i64::from(env.max_corr_nm[o]) * 256;
                i64::from(w(15 + o)).clamp(-m, m)
            };
            let diff_q8 = (i64::from(f.corr_nm[o]) * 256 - reference_q8).abs();
            worst_f32_milli_nm = worst_f32_milli_nm.max(diff_q8 * 1000 / 256);
            defmt::assert!(
                diff_q8 <= 256,
                "{=str} record {} output {}: f32 {} nm, reference {} / 256 nm",
                name,
                r,
                o,
                f.corr_nm[o],
                reference_q8
            );
        }
    }
    defmt::info!(
        "{=str}: {} vectors ({} flagged), fixed point bit exact, f32 within {} milli-nm of the f64 reference",
        name, count, flagged, worst_f32_milli_nm
    );
}

#[defmt_test::tests]
mod tests {
    use super::*;

    #[test]
    fn golden_vectors_replay_on_the_target() {
        for (name, table_bytes, vec) in GOLDEN {
            replay(name, table_bytes, vec);
        }
    }

    #[test]
    fn random_models_replay_on_the_target() {
        defmt::assert_eq!(RANDOM_MODELS.len(), 16);
        for (name, table_bytes, vec) in RANDOM_MODELS {
            replay(name, table_bytes, vec);
        }
    }

    #[test]
    fn corrupted_golden_tables_are_refused() {
        for (name, bytes, _) in GOLDEN {
            let mut copy = [0u8; 4608];
            defmt::assert!(bytes.len() <= copy.len());
            let copy = &mut copy[..bytes.len()];
            copy.copy_from_slice(bytes);
            // Every truncation.
            for len in 0..bytes.len() {
                defmt::assert!(
                    model_core::parse(&copy[..len]).is_err(),
                    "{=str} cut to {} parsed",
                    name,
                    len
                );
            }
            // Every single-bit flip (CRC-32 detects all of them).
            let mut flips = 0u32;
            for at in 0..bytes.len() {
                for bit in 0..8 {
                    copy[at] ^= 1 << bit;
                    defmt::assert!(
                        model_core::parse(copy).is_err(),
                        "{=str}: bit {} of byte {} flipped still parsed",
                        name,
                        bit,
                        at
                    );
                    copy[at] ^= 1 << bit;
                    flips += 1;
                }
            }
            defmt::assert!(model_core::parse(copy).is_ok());
            defmt::info!(
                "{=str}: {} truncations and {} bit flips refused",
                name,
                bytes.len(),
                flips
            );
        }
    }

    #[test]
    fn fixed_point_is_bit_exact_with_the_host() {
        for (name, table, vectors) in CASES {
            let model = load(name, table);
            let mut n = 0u32;
            let mut flagged = 0u32;
            for r in records(vectors) {
                let out = model.eval_fixed(&r.inputs);
                if out.corr_nm != r.fixed_nm || out.flags.bits() != r.fixed_flags {
                    defmt::panic!(
                        "{=str} record {}: target {} flags {=u16:#x}, host {} flags {=u16:#x}",
                        name,
                        n,
                        out.corr_nm,
                        out.flags.bits(),
                        r.fixed_nm,
                        r.fixed_flags
                    );
                }
                flagged += u32::from(r.fixed_flags != 0);
                n += 1;
            }
            // The inputs must reach the clamps, or the flags went untested.
            defmt::assert!(
                flagged > 0 && flagged < n,
                "{=str}: {} of {} flagged",
                name,
                flagged,
                n
            );
            defmt::info!(
                "{=str}: {} fixed-point evaluations bit exact ({} flagged)",
                name,
                n,
                flagged
            );
        }
    }

    /// The rigid21 table's vectors carry tool lengths, and on the target
    /// the tool length changes the correction (its Abbe blocks are
    /// evaluated): the same records at tool 0 give other values.
    #[test]
    fn rigid21_corrects_for_the_tool_length() {
        let Some((name, table, vectors)) = CASES.iter().find(|c| c.0 == "rigid21") else {
            defmt::panic!("no rigid21 case")
        };
        let model = load(name, table);
        let (mut n, mut long, mut moved) = (0u32, 0u32, 0u32);
        for r in records(vectors) {
            let at_zero = model_core::Inputs {
                tool_nm: 0,
                ..r.inputs
            };
            long += u32::from(r.inputs.tool_nm.abs() >= 100_000_000);
            moved += u32::from(model.eval_fixed(&at_zero).corr_nm != r.fixed_nm);
            n += 1;
        }
        defmt::assert!(long > n / 2, "{} of {} records at a tool ≥ 100 mm", long, n);
        defmt::assert!(
            moved >= long,
            "{} of {} records moved by the tool",
            moved,
            n
        );
        defmt::info!(
            "rigid21: {} of {} records at a tool ≥ 100 mm, {} corrected differently than at tool 0",
            long,
            n,
            moved
        );
    }

    #[test]
    fn f32_is_within_1_nm_of_the_host() {
        for (name, table, vectors) in CASES {
            let model = load(name, table);
            let (mut n, mut worst, mut exact) = (0u32, 0u32, 0u32);
            for r in records(vectors) {
                let out = model.eval_f32(&r.inputs);
                defmt::assert_eq!(
                    out.flags.bits(),
                    r.f32_flags,
                    "{=str} record {}: flags",
                    name,
                    n
                );
                let d = (0..3)
                    .map(|a| out.corr_nm[a].abs_diff(r.f32_nm[a]))
                    .max()
                    .unwrap_or(0);
                defmt::assert!(d <= 1, "{=str} record {}: f32 differs by {} nm", name, n, d);
                worst = worst.max(d);
                exact += u32::from(d == 0);
                n += 1;
            }
            defmt::info!(
                "{=str}: f32 worst difference {} nm, {}/{} bit exact",
                name,
                worst,
                exact,
                n
            );
        }
    }
}
