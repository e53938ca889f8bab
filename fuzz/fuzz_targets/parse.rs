//! Fuzz `model_core::table::parse` (and everything a valid table leads to):
//! any bytes must give a typed error or a table whose term views decode,
//! which loads into a model (or a typed load error) whose evaluation, with
//! hostile inputs derived from the same bytes, never panics.
//! Random bytes almost never carry a right CRC, so every input is also
//! tried resealed (its trailer replaced by the CRC of the bytes before it):
//! that is what reaches the length, count, range and model checks behind
//! the CRC — a table corrupted before it was sealed.
//! Run: `cd fuzz && cargo +nightly fuzz run parse` (seed the corpus with
//! `model-core/tests/golden/*.bin`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use model_core::{parse, Inputs, LargeModel};
use trueaxis_protocol::FRAME_CRC;

fuzz_target!(|data: &[u8]| {
    check(data);
    if data.len() >= 4 {
        let mut sealed = data.to_vec();
        let body = data.len() - 4;
        let crc = FRAME_CRC.checksum(&data[..body]);
        sealed[body..].copy_from_slice(&crc.to_le_bytes());
        check(&sealed);
    }
});

fn check(data: &[u8]) {
    let _ = model_core::table::parse_prefix(data);
    let Ok(table) = parse(data) else { return };
    let _ = (
        table.crc32(),
        table.envelope(),
        table.channel_name(0),
        table.source_hash(),
    );
    for t in table.terms() {
        let _ = t.view();
    }
    let Ok(model) = LargeModel::load(&table) else {
        return;
    };
    let mut words = data
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .cycle();
    for _ in 0..4 {
        let mut next = || words.next().unwrap_or(0);
        let inp = Inputs {
            pos_nm: [next(), next(), next()],
            rev_q30: [next(), next(), next()],
            temp_mc: [next(), next(), next(), next()],
            tool_nm: next(),
        };
        let env = model.envelope();
        for out in [model.eval_f32(&inp), model.eval_fixed(&inp)] {
            for o in 0..3 {
                assert!(out.corr_nm[o].abs() <= env.max_corr_nm[o]);
            }
        }
    }
}
