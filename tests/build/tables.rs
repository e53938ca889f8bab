//! The benchmark and test tables, built on the host with model-core's
//! `TableSpec` (std) so they are always in the current format: a plausible
//! vertical mill (X 800, Y 500, Z 500 mm), coefficients from a fixed-seed
//! generator (the same bytes on every build). Used by the QEMU crate's
//! build script (the bench image) and by the end-to-end runner (the second
//! table of the cut-upload scenario).
//!
//! - `cubic19`: the seed model, 19 monomials on each of ex, ey, ez.
//! - `full`: cubic19 plus a lead-screw periodic term with 2 harmonics (5 mm
//!   pitch on Y, feeding ey), a thermal term (X scale expansion with the
//!   bed temperature, feeding ex) and reversal (backlash) on all three axes.
//! - `nn_3x16x3`: a tanh MLP, 3 position inputs, 16 hidden units, 3 outputs.

use model_core::monomials::CUBIC19;
use model_core::{
    EncodeError, Envelope, InputScaling, LayerSpec, MlpInputSpec, MlpSource, MlpSpec, TableSpec,
    TermSpec,
};

/// Travel, nm.
pub const TRAVEL_MAX_NM: [i32; 3] = [800_000_000, 500_000_000, 500_000_000];

/// splitmix64 (`trueaxis-test-support`): a tiny, well-known generator;
/// fixed seeds make the tables identical on every build.
pub use trueaxis_test_support::SplitMix64 as Rng;

fn envelope() -> Envelope {
    Envelope {
        travel_min_nm: [0; 3],
        travel_max_nm: TRAVEL_MAX_NM,
        max_corr_nm: [200_000; 3],
        max_slew_nm_per_ms: 50,
        temp_min_mc: [10_000, 0, 0, 0],
        temp_max_mc: [40_000, 0, 0, 0],
        tool_min_nm: 0,
        tool_max_nm: 300_000_000,
    }
}

/// The mill's table without terms: one temperature channel (the bed),
/// corrections up to 200 µm; `seed_hash` fills the source hash.
pub fn base(seed_hash: u8) -> TableSpec {
    TableSpec {
        created_unix_s: 1_767_225_600,
        source_hash: [seed_hash; 32],
        channels: vec!["T_bed_C".into()],
        envelope: envelope(),
        scaling: InputScaling {
            centre_nm: TRAVEL_MAX_NM.map(|t| t / 2),
            half_span_nm: TRAVEL_MAX_NM.map(|t| t / 2),
        },
        outputs: [true; 3],
        terms: Vec::new(),
    }
}

/// cubic19 on each output: coefficients that shrink with the degree, a few
/// µm overall (normalised positions are in [-1, 1]).
fn cubic19_terms(rng: &mut Rng) -> Vec<TermSpec> {
    (0..3u8)
        .map(|output| TermSpec::Poly {
            output,
            coefs: CUBIC19
                .iter()
                .map(|&m| {
                    let degree = f64::from(m[0] + m[1] + m[2]);
                    (m, rng.signed_unit() * 8_000.0 / (1.0 + degree * degree))
                })
                .collect(),
        })
        .collect()
}

pub fn cubic19(seed: u64) -> Result<Vec<u8>, EncodeError> {
    let mut rng = Rng::new(seed);
    let mut spec = base(1);
    spec.terms = cubic19_terms(&mut rng);
    spec.encode()
}

pub fn full(seed: u64) -> Result<Vec<u8>, EncodeError> {
    let mut rng = Rng::new(seed);
    let mut spec = base(2);
    spec.terms = cubic19_terms(&mut rng);
    spec.terms.push(TermSpec::Periodic {
        output: 1,
        axis: 1,
        period_nm: 5_000_000,
        sin_nm: vec![1_800.0 * rng.signed_unit(), 600.0 * rng.signed_unit()],
        cos_nm: vec![1_800.0 * rng.signed_unit(), 600.0 * rng.signed_unit()],
    });
    spec.terms.push(TermSpec::Thermal {
        output: 0,
        channel: 0,
        t_ref_mc: 20_000,
        // Steel, 11.5 µm/m/K over a ±400 mm half span: 4.6 µm/K at the ends.
        coefs_nm_per_k: vec![([0, 0, 0], 300.0), ([1, 0, 0], 4_600.0)],
    });
    for axis in 0..3u8 {
        spec.terms.push(TermSpec::Reversal {
            output: axis,
            axis,
            transition_nm: 20_000,
            amplitude_nm: 3_000.0 + 2_000.0 * rng.signed_unit(),
        });
    }
    spec.encode()
}

/// cubic19 plus an Abbe term whose coefficient sum is near the loader's
/// limit (3·10^4 nm per nm of arm: scale q = 16) with a tool-arm range
/// of ±(2^31 − 1) nm: it loads, but its fixed point departs from its own
/// definition by tens of µm (issue 25) — the board must refuse it.
pub fn off_definition(seed: u64) -> Result<Vec<u8>, EncodeError> {
    let mut rng = Rng::new(seed);
    let mut spec = base(4);
    spec.terms = cubic19_terms(&mut rng);
    spec.terms.push(TermSpec::Abbe {
        output: 0,
        coefs: vec![([1, 0, 0], 30_000.0)],
    });
    spec.envelope.tool_min_nm = -i32::MAX;
    spec.envelope.tool_max_nm = i32::MAX;
    spec.envelope.max_corr_nm = [model_core::table::MAX_CORR_LIMIT_NM; 3];
    spec.encode()
}

pub fn nn_3x16x3(seed: u64) -> Result<Vec<u8>, EncodeError> {
    const HIDDEN: usize = 16;
    let mut rng = Rng::new(seed);
    let mut spec = base(3);
    let inputs = (0..3u8)
        .map(|axis| MlpInputSpec {
            source: MlpSource::Pos(axis),
            min: 0.0,
            max: f64::from(TRAVEL_MAX_NM[axis as usize]),
        })
        .collect();
    let hidden = LayerSpec {
        weights: (0..HIDDEN * 3).map(|_| 1.5 * rng.signed_unit()).collect(),
        bias: (0..HIDDEN).map(|_| 0.5 * rng.signed_unit()).collect(),
    };
    let output = LayerSpec {
        weights: (0..3 * HIDDEN).map(|_| 0.4 * rng.signed_unit()).collect(),
        bias: (0..3).map(|_| 0.1 * rng.signed_unit()).collect(),
    };
    spec.terms.push(TermSpec::Mlp(MlpSpec {
        outputs: vec![0, 1, 2],
        inputs,
        hidden: vec![hidden],
        output,
        out_min_nm: vec![-20_000.0; 3],
        out_max_nm: vec![20_000.0; 3],
    }));
    spec.encode()
}

/// Number of i32 words in one vector record (see [`vector_record`]).
pub const RECORD_WORDS: usize = 3 + 3 + model_core::MAX_TEMPS + 1 + 3 + 1 + 3 + 1;

/// Seeded inputs over (and a little beyond) the envelope of the tables:
/// positions up to 2 % outside the travel, both reversal states and
/// mid-transition values, temperatures beyond the channel range, tools
/// beyond the arm range — so the clamps and flags are exercised too.
/// The seed of a bench table's replay vectors, from its name's bytes
/// (FNV-1a, 64 bit): two names of one length get different inputs (the
/// seed was once `0x5EED_0000 + name.len()`, which gave `rigid21` the
/// inputs of `cubic19`).
pub fn vector_seed(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

pub fn vector_inputs(seed: u64, n: usize) -> Vec<model_core::Inputs> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let pos_nm = core::array::from_fn(|a| {
                let t = f64::from(TRAVEL_MAX_NM[a]);
                (t * (0.5 + 0.52 * rng.signed_unit())) as i32
            });
            let rev_q30 = core::array::from_fn(|_| match rng.next_u64() % 4 {
                0 => -(1 << 30),
                1 => 1 << 30,
                2 => 0,
                _ => (rng.signed_unit() * f64::from(1 << 30)) as i32,
            });
            let mut temp_mc = [0; model_core::MAX_TEMPS];
            temp_mc[0] = (25_000.0 + 17_000.0 * rng.signed_unit()) as i32;
            let tool_nm = (150_000_000.0 + 160_000_000.0 * rng.signed_unit()) as i32;
            model_core::Inputs {
                pos_nm,
                rev_q30,
                temp_mc,
                tool_nm,
            }
        })
        .collect()
}

/// One record: the inputs, then the host's fixed-point outputs (corr_nm,
/// flags), then its f32 outputs — what the target must reproduce.
pub fn vector_record(model: &model_core::Model, inp: &model_core::Inputs) -> Vec<i32> {
    let fixed = model.eval_fixed(inp);
    let f32_out = model.eval_f32(inp);
    let mut r = Vec::with_capacity(RECORD_WORDS);
    r.extend_from_slice(&inp.pos_nm);
    r.extend_from_slice(&inp.rev_q30);
    r.extend_from_slice(&inp.temp_mc);
    r.push(inp.tool_nm);
    r.extend_from_slice(&fixed.corr_nm);
    r.push(i32::from(fixed.flags.bits()));
    r.extend_from_slice(&f32_out.corr_nm);
    r.push(i32::from(f32_out.flags.bits()));
    debug_assert_eq!(r.len(), RECORD_WORDS);
    r
}
