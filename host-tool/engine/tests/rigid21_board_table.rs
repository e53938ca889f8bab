//! The board table of a fitted rigid21 model (issue 26, "On the board"):
//! the simulator's `mill800-21` (all 21 errors and the spindle tilt at
//! realistic sizes) measured by two tracker stations at tool lengths 0 and
//! 250 mm with lateral offsets (every error estimated), fitted with
//! `rigid21:4` and exported with `export --format table`'s defaults. The
//! bytes are checked in as `tests/golden/rigid21.bin` at the repository
//! root: the QEMU crate's build script evaluates that file on the host at
//! seeded inputs with tool lengths up to 310 mm, the `model_core` suite
//! replays them on the emulated Cortex-M4F bit for bit, and the bench and
//! tick images count its instructions (docs/qemu.md). This test re-exports
//! and requires the same bytes, so the file QEMU runs is the engine's
//! export of today. Regenerate after an intended change with
//! `TRUEAXIS_BLESS=1 cargo test -p trueaxis-engine --test rigid21_board_table`
//! and commit the file (then the QEMU suites run the new one).

use std::path::PathBuf;

use trueaxis_engine::export::table::{export, rigid21_gap_nm, TableOptions};
use trueaxis_engine::fit::{fit, FitOptions};
use trueaxis_engine::model::rigid21::Status;
use trueaxis_engine::model::FittedModel;
use trueaxis_engine::simulate::instruments::{measure, Instrument};
use trueaxis_engine::simulate::Machine;

fn golden() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/golden/rigid21.bin")
}

#[test]
fn the_checked_in_rigid21_table_is_the_engines_export() {
    let m = Machine::preset("mill800-21").unwrap();
    let plan = [
        Instrument::Tracker {
            tools_mm: vec![0.0, 250.0],
            lateral_mm: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
            points: 150,
        },
        Instrument::Tracker {
            tools_mm: vec![0.0, 250.0],
            lateral_mm: vec![[0.0, 0.0], [-100.0, 0.0], [0.0, -100.0]],
            points: 150,
        },
    ];
    let data = measure(&m, &plan, 26, true);
    let file = fit(&data, "rigid21:4", &[], &FitOptions::default()).unwrap();
    let FittedModel::Rigid21(model) = &file.model else {
        panic!("kind {}", file.model.kind())
    };
    assert!(
        model.errors().all(|e| e.status == Status::Estimated),
        "every error estimated from these data"
    );
    let e = export(&file, &TableOptions::default()).unwrap();
    assert!(
        e.max_fixed_error_nm <= 1.0 && e.max_f32_error_nm <= 1.0,
        "{e:?}"
    );
    assert_eq!(e.envelope.tool_range_mm, [0.0, 300.0]);
    assert!(e.board.fits, "the board takes the table: {:?}", e.board);
    eprintln!(
        "rigid21 table: {} bytes, estimate fixed {} / f32 {} instructions",
        e.bytes, e.board.estimate_fixed_instr, e.board.estimate_f32_instr
    );
    // Per target a polynomial block, and an Abbe block (the tool length as
    // the factor) for ex and ey: 5 terms.
    assert_eq!(e.terms, 5);

    // The table at a tool length is the model at that tool length, and the
    // tool length matters (the angles × the tool arm): tens of µm at 250 mm.
    let t = model_core::parse(&e.table).unwrap();
    // Only the monomials the chain produces (X → Y → Z → tool): P0 the
    // error functions (x^n, y^n, z^n, n ≤ 4), X's angles times its arms
    // (x^d·y, x^d·z) and Y's (y^d·z), 25 in all; P1 the angles times the
    // tool arm (x^n, y^n, z^n, n ≤ 4), 13 — not the 56 of degree ≤ 5 the
    // solve runs over (the others are rounding noise, left out).
    let (mut poly_monos, mut abbe_sizes) = (Vec::new(), Vec::new());
    for term in t.terms() {
        match term.view() {
            model_core::table::TermView::Poly { coefs, .. } => {
                poly_monos.extend(coefs.iter().map(|(m, _)| m));
            }
            model_core::table::TermView::Abbe { coefs, .. } => {
                abbe_sizes.push(coefs.iter().count());
            }
            _ => {}
        }
    }
    poly_monos.sort_unstable();
    poly_monos.dedup();
    assert_eq!(poly_monos.len(), 25, "{poly_monos:?}");
    assert_eq!(abbe_sizes, [13, 13]);
    let (mut worst_nm, mut tool_effect_um) = (0.0f64, 0.0f64);
    for i in 0..50 {
        let f = f64::from(i) / 49.0;
        let pos_mm = [
            800.0 * f,
            500.0 * (1.0 - f),
            500.0 * (0.5 + 0.45 * (7.0 * f).sin()),
        ];
        let pos_nm = pos_mm.map(|p| (p * 1e6).round() as i32);
        let mut at_tool = Vec::new();
        for tool_mm in [0.0, 250.0] {
            let (gap, want) = rigid21_gap_nm(&t, model, pos_nm, tool_mm);
            for g in gap {
                worst_nm = worst_nm.max(g.abs());
            }
            at_tool.push(want);
        }
        for (long, short) in at_tool[1].iter().zip(&at_tool[0]) {
            tool_effect_um = tool_effect_um.max((long - short).abs());
        }
    }
    assert!(worst_nm <= 0.5, "table f64 vs model: {worst_nm} nm");
    assert!(
        tool_effect_um > 2.0,
        "tool length effect {tool_effect_um} µm"
    );

    let path = golden();
    if std::env::var_os("TRUEAXIS_BLESS").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &e.table).unwrap();
        return;
    }
    let stored = std::fs::read(&path).unwrap_or_else(|err| {
        panic!(
            "{}: {err} (run with TRUEAXIS_BLESS=1 to create it)",
            path.display()
        )
    });
    assert!(
        stored == e.table,
        "{} differs from today's export of the rigid21 model (run with TRUEAXIS_BLESS=1 if the change is intended)",
        path.display()
    );
}
