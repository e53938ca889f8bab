//! Table format robustness: random and mutated bytes never panic and every
//! corruption is a typed error. The CRC catches almost every random change,
//! so the structural validators are exercised separately by corrupting a
//! field and then re-computing a *correct* CRC.
#![allow(clippy::needless_range_loop)] // per-output index loops mirror [ex, ey, ez]
mod common;

use common::*;
use model_core::table::{layout, CRC32, CRC_LEN, FIXED_LEN};
use model_core::{parse, Inputs, LargeModel, TableError};
use proptest::prelude::*;

fn golden(name: &str) -> Vec<u8> {
    golden_specs()
        .into_iter()
        .find(|(n, _)| *n == name)
        .unwrap()
        .1
        .encode()
        .unwrap()
}

fn all_golden() -> Vec<Vec<u8>> {
    golden_specs()
        .into_iter()
        .map(|(_, s)| s.encode().unwrap())
        .collect()
}

/// Re-seal: write a correct CRC for the (modified) bytes.
fn reseal(b: &mut [u8]) {
    let n = b.len();
    let crc = CRC32.checksum(&b[..n - CRC_LEN]);
    b[n - CRC_LEN..].copy_from_slice(&crc.to_le_bytes());
}

/// Parse; if valid, load and evaluate with hostile inputs: nothing may panic.
fn exercise(b: &[u8]) -> Result<(), TableError> {
    let t = parse(b)?;
    for term in t.terms() {
        // Decode every view accessor the firmware or host might call.
        match term.view() {
            model_core::table::TermView::Mlp { net, .. } => {
                for i in 0..net.n_inputs() {
                    let _ = net.input(i);
                }
            }
            model_core::table::TermView::Grid { grid, .. } => {
                let _ = (0..grid.len()).map(|i| grid.value(i)).sum::<f64>();
            }
            v => {
                for k in [0, 1, 2, 3, 4, 5, usize::MAX] {
                    let _ = v.harmonic(k);
                }
            }
        }
    }
    if let Ok(m) = LargeModel::load(&t) {
        for inp in [
            Inputs::default(),
            Inputs {
                pos_nm: [i32::MAX; 3],
                rev_q30: [i32::MIN; 3],
                temp_mc: [i32::MAX; 4],
                tool_nm: i32::MIN,
            },
            Inputs {
                pos_nm: [i32::MIN; 3],
                rev_q30: [i32::MAX; 3],
                temp_mc: [i32::MIN; 4],
                tool_nm: i32::MAX,
            },
        ] {
            let _ = m.eval_f32(&inp);
            let _ = m.eval_fixed(&inp);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_are_typed_errors(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        prop_assert!(exercise(&bytes).is_err());
    }

    #[test]
    fn random_bytes_with_valid_header_and_crc_never_panic(
        which in 0usize..5, body in prop::collection::vec(any::<u8>(), 0..1024)) {
        // A plausible header, random rest, correct length and CRC.
        let g = &all_golden()[which];
        let mut b = g[..FIXED_LEN.min(g.len())].to_vec();
        b.extend_from_slice(&body);
        b.extend_from_slice(&[0; CRC_LEN]);
        let n = b.len() as u32;
        b[layout::TOTAL_LEN..layout::TOTAL_LEN + 4].copy_from_slice(&n.to_le_bytes());
        reseal(&mut b);
        let _ = exercise(&b);
    }

    #[test]
    fn single_bit_flips_are_caught(which in 0usize..5, bit in any::<prop::sample::Index>()) {
        let mut b = all_golden()[which].clone();
        let i = bit.index(b.len() * 8);
        b[i / 8] ^= 1 << (i % 8);
        prop_assert!(exercise(&b).is_err());
    }

    #[test]
    fn multi_byte_mutations_are_caught(which in 0usize..5,
        edits in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..8)) {
        let mut b = all_golden()[which].clone();
        for (at, x) in edits {
            let i = at.index(b.len());
            b[i] ^= x;
        }
        prop_assert!(exercise(&b).is_err());
    }

    #[test]
    fn truncations_and_extensions_are_caught(which in 0usize..5, cut in any::<prop::sample::Index>(), extra in prop::collection::vec(any::<u8>(), 1..64)) {
        let g = &all_golden()[which];
        let n = cut.index(g.len());
        prop_assert!(exercise(&g[..n]).is_err());
        let mut longer = g.clone();
        longer.extend_from_slice(&extra);
        prop_assert!(exercise(&longer).is_err());
    }

    #[test]
    fn length_field_changes_are_caught(which in 0usize..5, len in any::<u32>()) {
        let mut b = all_golden()[which].clone();
        prop_assume!(len as usize != b.len());
        b[layout::TOTAL_LEN..layout::TOTAL_LEN + 4].copy_from_slice(&len.to_le_bytes());
        prop_assert!(exercise(&b).is_err());
        // Even with a re-computed CRC.
        reseal(&mut b);
        prop_assert!(exercise(&b).is_err());
    }

    /// Structural fuzzing past the CRC: mutate, re-seal, and require that
    /// parse → load → eval never panics (the result may be valid or a typed error).
    #[test]
    fn resealed_mutations_never_panic(which in 0usize..5,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)) {
        let mut b = all_golden()[which].clone();
        let n = b.len();
        for (at, x) in edits {
            b[at.index(n - CRC_LEN)] = x;
        }
        reseal(&mut b);
        let _ = exercise(&b);
    }
}

fn set_u8(b: &mut [u8], off: usize, v: u8) {
    b[off] = v;
}
fn set_i32(b: &mut [u8], off: usize, v: i32) {
    b[off..off + 4].copy_from_slice(&v.to_le_bytes());
}
fn set_f64(b: &mut [u8], off: usize, v: f64) {
    b[off..off + 8].copy_from_slice(&v.to_le_bytes());
}

/// Apply `edit`, re-seal, and return the parse error.
fn invalid(name: &str, edit: impl FnOnce(&mut Vec<u8>)) -> TableError {
    let mut b = golden(name);
    edit(&mut b);
    reseal(&mut b);
    match parse(&b) {
        Ok(_) => panic!("edit was accepted"),
        Err(e) => e,
    }
}

/// An edit of a golden table (see [`invalid`]).
type Edit = Box<dyn Fn(&mut Vec<u8>)>;

/// Each `(golden table, edit, error)`: the edit, re-sealed, gives the error.
fn assert_invalid(cases: Vec<(&str, Edit, TableError)>) {
    for (i, (name, edit, want)) in cases.into_iter().enumerate() {
        assert_eq!(invalid(name, edit), want, "case {i} ({name})");
    }
}

const T0: usize = layout::TERMS; // first term header
const B0: usize = layout::TERMS + 8; // first term body

#[test]
fn structurally_invalid_tables_with_correct_crc() {
    use TableError as E;
    assert_invalid(vec![
        ("cubic19", Box::new(|b| b[0] = b'X'), E::BadMagic),
        (
            "cubic19",
            Box::new(|b| b[layout::VERSION] = 2),
            E::UnsupportedVersion { version: 2 },
        ),
        (
            "cubic19",
            Box::new(|b| b[layout::RESERVED0] = 1),
            E::ReservedNonZero { offset: 6 },
        ),
        (
            "cubic19",
            Box::new(|b| set_u8(b, layout::UNITS, 1)),
            E::UnsupportedUnits { code: 1 },
        ),
        (
            "cubic19",
            Box::new(|b| set_u8(b, layout::CHANNEL_COUNT, 5)),
            E::BadChannelCount { count: 5 },
        ),
        (
            "cubic19",
            Box::new(|b| set_u8(b, layout::CHANNEL_COUNT, 2)),
            E::BadChannelName { channel: 1 },
        ),
        (
            "cubic19",
            Box::new(|b| b[layout::CHANNEL_NAMES] = 0xFF),
            E::BadChannelName { channel: 0 },
        ),
        (
            "cubic19",
            Box::new(|b| b[layout::CHANNEL_NAMES + 5] = b'x'),
            E::BadChannelName { channel: 0 },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::TRAVEL_MIN, 500_000_000)),
            E::BadEnvelope {
                offset: layout::TRAVEL_MIN as u32,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::MAX_CORR + 4, -1)),
            E::BadEnvelope {
                offset: layout::MAX_CORR as u32 + 4,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::MAX_SLEW, 0)),
            E::BadEnvelope {
                offset: layout::MAX_SLEW as u32,
            },
        ),
    ]);
    // The slew's upper bound (issue 14: a slew of 400 000 000 nm/ms once
    // crashed the board): one past it is refused, the bound itself loads.
    for slew in [
        model_core::table::MAX_SLEW_LIMIT_NM_PER_MS + 1,
        400_000_000,
        i32::MAX,
    ] {
        assert_eq!(
            invalid("cubic19", |b| set_i32(b, layout::MAX_SLEW, slew)),
            E::BadEnvelope {
                offset: layout::MAX_SLEW as u32
            }
        );
    }
    let mut at_bound = golden("cubic19");
    set_i32(
        &mut at_bound,
        layout::MAX_SLEW,
        model_core::table::MAX_SLEW_LIMIT_NM_PER_MS,
    );
    reseal(&mut at_bound);
    assert!(parse(&at_bound).is_ok());
    assert_invalid(vec![
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::TEMP_MIN, 50_000)),
            E::BadEnvelope {
                offset: layout::TEMP_MIN as u32,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::TEMP_MIN + 8, 1)),
            E::BadEnvelope {
                offset: layout::TEMP_MIN as u32 + 8,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::TOOL_MIN, i32::MAX)),
            E::BadEnvelope {
                offset: layout::TOOL_MIN as u32,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::HALF_SPAN + 4, 0)),
            E::BadScaling { axis: 1 },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::HALF_SPAN, 1000)),
            E::TravelOutsideScaling { axis: 0 },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, layout::CENTRE + 8, 1)),
            E::TravelOutsideScaling { axis: 2 },
        ),
        (
            "cubic19",
            Box::new(|b| set_u8(b, layout::OUTPUTS, 0x0F)),
            E::BadOutputs {
                offset: layout::OUTPUTS as u32,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_u8(b, layout::RESERVED1 + 2, 9)),
            E::ReservedNonZero {
                offset: layout::RESERVED1 as u32 + 2,
            },
        ),
        // Terms.
        (
            "cubic19",
            Box::new(|b| b[T0] = 99),
            E::UnknownTermKind {
                offset: T0 as u32,
                kind: 99,
            },
        ),
        (
            "cubic19",
            Box::new(|b| b[T0 + 1] = 0b011),
            E::BadTermOutputs {
                offset: T0 as u32 + 1,
            },
        ),
        (
            "cubic19",
            Box::new(|b| b[T0 + 1] = 0),
            E::BadTermOutputs {
                offset: T0 as u32 + 1,
            },
        ),
        (
            "grid_17x11",
            Box::new(|b| b[T0 + 1] = 0b010),
            E::BadTermOutputs {
                offset: T0 as u32 + 1,
            },
        ),
        (
            "cubic19",
            Box::new(|b| b[T0 + 2] = 1),
            E::BadTermField {
                offset: T0 as u32 + 2,
            },
        ),
        (
            "cubic19",
            Box::new(|b| b[T0 + 3] = 1),
            E::ReservedNonZero {
                offset: T0 as u32 + 3,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, T0 + 4, 1 << 20)),
            E::TermTruncated { offset: T0 as u32 },
        ),
        (
            "cubic19",
            Box::new(|b| set_i32(b, T0 + 4, 4)),
            E::TermLengthMismatch { offset: B0 as u32 },
        ),
        (
            "cubic19",
            Box::new(|b| b[B0] = 0),
            E::BadTermField { offset: B0 as u32 },
        ),
        (
            "cubic19",
            Box::new(|b| b[B0] = 57),
            E::BadTermField { offset: B0 as u32 },
        ),
        (
            "cubic19",
            Box::new(|b| b[B0] = 18),
            E::TermLengthMismatch { offset: B0 as u32 },
        ),
        // Monomial 0 is [0,0,0]; make it degree 6, then a duplicate of monomial 1 ([1,0,0]).
        (
            "cubic19",
            Box::new(|b| b[B0 + 4] = 6),
            E::BadTermField {
                offset: B0 as u32 + 4,
            },
        ),
        (
            "cubic19",
            Box::new(|b| b[B0 + 4 + 12] = 0),
            E::DuplicateMonomial {
                offset: B0 as u32 + 16,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_f64(b, B0 + 8, f64::NAN)),
            E::NotFinite {
                offset: B0 as u32 + 8,
            },
        ),
        (
            "cubic19",
            Box::new(|b| set_f64(b, B0 + 8, f64::INFINITY)),
            E::NotFinite {
                offset: B0 as u32 + 8,
            },
        ),
        // Term count vs. bytes.
        (
            "cubic19",
            Box::new(|b| b[layout::TERM_COUNT] = 2),
            E::TrailingBytes { offset: 0 }.with_offset_of(&golden("cubic19"), 2),
        ),
    ]);
    assert!(matches!(
        invalid("cubic19", |b| b[layout::TERM_COUNT] = 4),
        E::TermTruncated { .. }
    ));
}

trait WithOffset {
    fn with_offset_of(self, b: &[u8], after_terms: usize) -> Self;
}
impl WithOffset for TableError {
    /// The TrailingBytes offset expected after `after_terms` terms of `b`.
    fn with_offset_of(self, b: &[u8], after_terms: usize) -> Self {
        let mut off = layout::TERMS;
        for _ in 0..after_terms {
            off += 8 + u32::from_le_bytes(b[off + 4..off + 8].try_into().unwrap()) as usize;
        }
        TableError::TrailingBytes { offset: off as u32 }
    }
}

/// Kind-specific validators, located through the table's own term iterator.
#[test]
fn term_kind_validators_with_correct_crc() {
    use TableError as E;
    let b = golden("all_kinds");
    let t = parse(&b).unwrap();
    let find =
        |kind: model_core::table::TermKind| t.terms().find(|x| x.kind == kind).unwrap().offset;
    use model_core::table::TermKind as K;
    let per = find(K::Periodic);
    let th = find(K::Thermal);
    let rev = find(K::Reversal);
    let mlp = find(K::Mlp);
    let grid = find(K::Grid);
    let abbe = find(K::Abbe);
    let field = |o: usize| E::BadTermField { offset: o as u32 };
    let not_finite = |o: usize| E::NotFinite { offset: o as u32 };
    let length = |o: usize| E::TermLengthMismatch { offset: o as u32 };
    assert_invalid(vec![
        (
            "all_kinds",
            Box::new(move |b| b[per + 2] = 3),
            field(per + 2),
        ),
        (
            "all_kinds",
            Box::new(move |b| set_i32(b, per + 8, 0)),
            field(per + 8),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[per + 12] = 5),
            field(per + 12),
        ),
        ("all_kinds", Box::new(move |b| b[per + 12] = 3), length(per)),
        ("all_kinds", Box::new(move |b| b[th + 2] = 2), field(th + 2)),
        (
            "all_kinds",
            Box::new(move |b| set_i32(b, th + 8, 300_000)),
            field(th + 8),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[rev + 2] = 7),
            field(rev + 2),
        ),
        (
            "all_kinds",
            Box::new(move |b| set_i32(b, rev + 8, -5)),
            field(rev + 8),
        ),
        (
            "all_kinds",
            Box::new(move |b| set_f64(b, rev + 16, f64::NAN)),
            not_finite(rev + 16),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[abbe + 2] = 1),
            field(abbe + 2),
        ),
        // MLP body: n_in, n_layers, h1, h2.
        (
            "all_kinds",
            Box::new(move |b| b[mlp + 8] = 0),
            field(mlp + 8),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[mlp + 9] = 3),
            field(mlp + 9),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[mlp + 10] = 33),
            field(mlp + 10),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[mlp + 10] = 15),
            length(mlp + 8),
        ),
        // Input 3 is the temperature channel 0 (source 3); channel 9 does not exist.
        (
            "all_kinds",
            Box::new(move |b| b[mlp + 12 + 60] = 12),
            field(mlp + 72),
        ),
        // Input 0: min ≥ max.
        (
            "all_kinds",
            Box::new(move |b| set_f64(b, mlp + 16, 1e9)),
            field(mlp + 16),
        ),
        // Grid: nodes 0, step 0, value NaN.
        (
            "all_kinds",
            Box::new(move |b| b[grid + 8] = 0),
            field(grid + 8),
        ),
        (
            "all_kinds",
            Box::new(move |b| set_i32(b, grid + 16, 0)),
            field(grid + 16),
        ),
        (
            "all_kinds",
            Box::new(move |b| set_f64(b, grid + 44, f64::NAN)),
            not_finite(grid + 44),
        ),
        (
            "all_kinds",
            Box::new(move |b| b[grid + 8] = 6),
            length(grid),
        ),
    ]);
}

#[test]
fn parse_prefix_reads_a_table_at_the_start_of_a_slot() {
    let g = golden("full");
    let mut slot = g.clone();
    slot.resize(128 * 1024, 0xFF); // erased flash after the table
    let t = model_core::table::parse_prefix(&slot).unwrap();
    assert_eq!(t.bytes(), &g[..]);
    assert!(model_core::table::parse_prefix(&[0xFF; 4096]).is_err());
    assert!(model_core::table::parse_prefix(&[]).is_err());
}

#[test]
fn errors_display_something_useful() {
    let e = parse(&[0u8; 10]).unwrap_err();
    assert_eq!(e, TableError::TooShort { len: 10 });
    assert!(e.to_string().contains("10 bytes"));
    let mut g = golden("cubic19");
    g[100] ^= 1;
    assert!(matches!(parse(&g), Err(TableError::CrcMismatch { .. })));
    assert!(parse(&g).unwrap_err().to_string().contains("CRC32"));
}

#[test]
fn harmonic_accessor_is_total() {
    // `all_kinds` has a periodic term with 4 harmonics (sin 2000, 500, −250,
    // 100; cos −700, 300, 120, −50), `full` one with 2.
    for (name, want) in [
        (
            "all_kinds",
            vec![
                (2_000.0, -700.0),
                (500.0, 300.0),
                (-250.0, 120.0),
                (100.0, -50.0),
            ],
        ),
        ("full", vec![(3_000.0, 1_200.0), (-800.0, 400.0)]),
    ] {
        let g = golden(name);
        let t = parse(&g).unwrap();
        let v = t
            .terms()
            .map(|term| term.view())
            .find(|v| matches!(v, model_core::table::TermView::Periodic { .. }))
            .unwrap();
        for (k, w) in want.iter().enumerate() {
            assert_eq!(v.harmonic(k + 1), *w, "{name} harmonic {}", k + 1);
        }
        // Outside 1..=harmonics: zero, never a panic (k = 0 used to underflow).
        for k in [0, want.len() + 1, 5, usize::MAX / 16, usize::MAX] {
            assert_eq!(v.harmonic(k), (0.0, 0.0), "{name} harmonic {k}");
        }
    }
}

#[test]
fn reversal_terms_of_one_axis_share_one_transition() {
    use model_core::{EncodeError, Model, TermSpec};
    let mut spec = golden_specs()
        .into_iter()
        .find(|(n, _)| *n == "full")
        .unwrap()
        .1;
    // `full` has a reversal on x (ex, 20 µm). Another one on x for ey with
    // the same length is fine, and so is one with another length on y.
    let rev = |output, axis, transition_nm| TermSpec::Reversal {
        output,
        axis,
        transition_nm,
        amplitude_nm: 1_500.0,
    };
    spec.terms.push(rev(1, 0, 20_000));
    spec.terms.push(rev(2, 1, 50_000));
    let bytes = spec.encode().unwrap();
    let m = Model::load(&parse(&bytes).unwrap()).unwrap();
    assert_eq!(m.reversal_transition_nm(0), Some(20_000));
    assert_eq!(m.reversal_transition_nm(1), Some(50_000));
    assert_eq!(m.reversal_transition_nm(2), None);
    // A second length on x would be run on the first one's ramp: refused.
    spec.terms.push(rev(2, 0, 50_000));
    let e = spec.encode().unwrap_err();
    assert!(
        matches!(
            e,
            EncodeError::Invalid(TableError::ReversalTransitionMismatch { .. })
        ),
        "{e:?}"
    );
    // The same bytes sealed by hand (not through encode) are refused by parse
    // at the offending field.
    let mut ok = spec.clone();
    ok.terms.pop();
    ok.terms.push(rev(2, 0, 20_000));
    let mut b = ok.encode().unwrap();
    let last = parse(&b).unwrap().terms().last().unwrap().offset;
    let field = last + model_core::table::TERM_HEADER_LEN;
    set_i32(&mut b, field, 50_000);
    reseal(&mut b);
    assert_eq!(
        parse(&b).unwrap_err(),
        TableError::ReversalTransitionMismatch {
            offset: field as u32
        }
    );
    assert!(parse(&b).unwrap_err().to_string().contains("transition"));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// `TableSpec::from_table` inverts `encode`: the decoded spec equals the
    /// original (every f64 bit for bit) and re-encodes to the same bytes.
    #[test]
    fn from_table_inverts_encode(
        seed in any::<u64>(),
        kinds in prop::collection::vec(prop::sample::select(ALL_KINDS.to_vec()), 1..6),
    ) {
        let spec = random_spec(seed, &kinds);
        let bytes = spec.encode().unwrap();
        let back = model_core::TableSpec::from_table(&parse(&bytes).unwrap());
        prop_assert_eq!(&back, &spec);
        prop_assert_eq!(back.encode().unwrap(), bytes);
    }
}

/// The checked-in golden tables (every term kind, 1 and 2 hidden layers,
/// 1-, 2- and 3-axis grids, absent outputs) decode to the specs they were
/// made from, so a `.bin` evaluates in f64 on the host like its spec.
#[test]
fn golden_tables_decode_to_their_specs() {
    for (name, spec) in golden_specs() {
        let stored = std::fs::read(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/golden")
                .join(format!("{name}.bin")),
        )
        .unwrap();
        let back = model_core::TableSpec::from_table(&parse(&stored).unwrap());
        assert_eq!(back, spec, "{name}");
        let inp = model_core::InputsF64::from(&random_inputs(&mut Rng(7), &spec, false));
        assert_eq!(back.eval_f64(&inp), spec.eval_f64(&inp), "{name}");
    }
}

/// A hidden layer wider than the format's 32 units is refused by `encode`
/// with what the limit is, not by the parse of the bytes it wrote ("term
/// field at offset … out of range").
#[test]
fn an_mlp_wider_than_32_units_is_refused_at_encode() {
    use model_core::{EncodeError, TermSpec};
    let (_, mut spec) = golden_specs()
        .into_iter()
        .find(|(_, s)| s.terms.iter().any(|t| matches!(t, TermSpec::Mlp(_))))
        .expect("a golden spec with an MLP");
    let m = spec
        .terms
        .iter_mut()
        .find_map(|t| match t {
            TermSpec::Mlp(m) => Some(m),
            _ => None,
        })
        .unwrap();
    let (n_in, units) = (m.inputs.len(), 33);
    m.hidden[0].weights = vec![0.01; units * n_in];
    m.hidden[0].bias = vec![0.0; units];
    let next = m.hidden.get_mut(1).unwrap_or(&mut m.output);
    next.weights = vec![0.01; next.bias.len() * units];
    let e = spec.encode().unwrap_err();
    assert!(
        matches!(e, EncodeError::Shape { what, .. } if what.contains("at most 32 units")),
        "{e:?}"
    );
}
