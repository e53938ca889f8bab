//! The board table of a rigid21 model with named effects on top
//! (docs/volumetric.md § Effects on top, § On the board): the simulator's
//! `mill800-21` with a 3 µm, 100 mm lead on X, measured by laser lines at
//! tool lengths 0 and 150 mm (5 mm steps on X, seed 11) read as a
//! bidirectional run with a 6 µm backlash on X, fitted with `rigid21 --add
//! periodic:… --add reversal:…` and exported with `export --format
//! table`'s defaults: the export's accuracy gate passes, the table holds a
//! periodic and a reversal term beside the error functions' blocks, and
//! the table evaluated at every measured row equals the model there.

use trueaxis_engine::effect::Effect;
use trueaxis_engine::export::table::{export, TableOptions};
use trueaxis_engine::fit::{fit, FitOptions};
use trueaxis_engine::model::FittedModel;
use trueaxis_engine::simulate::instruments::{laser_lines_along, measure};
use trueaxis_engine::simulate::Machine;

#[test]
fn a_rigid21_table_carries_the_effects_on_top() {
    let m = Machine::preset("mill800-21")
        .unwrap()
        .with_lead(0, 3.0, 100.0, 0.3);
    let plan = laser_lines_along(m.travel_mm, &[0.0, 150.0], 0, 161);
    let mut data = measure(&m, &plan, 11, true);
    // A bidirectional run: rows alternate their approach on X, the
    // backlash shifts ex by ±3 µm.
    let dir: Vec<i8> = (0..data.len())
        .map(|r| if r % 2 == 0 { 1 } else { -1 })
        .collect();
    if let Some(ex) = data.err_um[0].as_mut() {
        for (v, d) in ex.iter_mut().zip(&dir) {
            if let Some(v) = v {
                *v += 3.0 * f64::from(*d);
            }
        }
    }
    data.dir[0] = Some(dir);
    let adds = [
        Effect::parse("periodic:target=ex,axis=x,period_mm=100").unwrap(),
        Effect::parse("reversal:target=ex,axis=x").unwrap(),
    ];
    let file = fit(&data, "rigid21", &adds, &FitOptions::default()).unwrap();
    assert_eq!(file.adds.len(), 2);
    let FittedModel::Rigid21(model) = &file.model else {
        panic!("kind {}", file.model.kind())
    };
    assert!(model.effects.is_some());
    // The file reads back as it was written (its checks: adds and effects
    // agree, the effects' fields are whole).
    let path = std::env::temp_dir().join(format!("rigid21_effects_{}.json", std::process::id()));
    file.save(&path).unwrap();
    let back = trueaxis_engine::model::ModelFile::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(back.model, file.model);
    assert_eq!(back.adds, file.adds);

    let e = export(&file, &TableOptions::default()).unwrap();
    assert!(
        e.max_fixed_error_nm <= 1.0 && e.max_f32_error_nm <= 1.0,
        "{e:?}"
    );
    let t = model_core::parse(&e.table).unwrap();
    let (mut periodic, mut reversal) = (Vec::new(), Vec::new());
    for term in t.terms() {
        match term.view() {
            model_core::table::TermView::Periodic {
                output,
                axis,
                period_nm,
                ..
            } => periodic.push((output, axis, period_nm)),
            model_core::table::TermView::Reversal {
                output,
                axis,
                amplitude_nm,
                ..
            } => reversal.push((output, axis, amplitude_nm)),
            _ => {}
        }
    }
    assert_eq!(periodic, [(0, 0, 100_000_000)]);
    assert_eq!(reversal.len(), 1);
    let (out, axis, amp_nm) = reversal[0];
    assert_eq!((out, axis), (0, 0));
    // Correction = −error: −3 µm per unit of dir_x, within the fit's noise.
    assert!((amp_nm + 3000.0).abs() < 100.0, "{amp_nm}");

    // The table at every measured row (its tool length, its approach) is
    // the model there, effects included.
    let want = file.model.predict(&data).unwrap();
    let want = want[0].as_ref().unwrap();
    let mut worst_nm = 0.0f64;
    for r in 0..data.len() {
        let inp = model_core::Inputs {
            pos_nm: [0, 1, 2].map(|a| (data.pos(a, r) * 1e6).round() as i32),
            rev_q30: [0, 1, 2].map(|a| {
                data.dir[a]
                    .as_ref()
                    .map_or(0, |d| i32::from(d[r]) * (1 << 30))
            }),
            tool_nm: (data.tool(r) * 1e6).round() as i32,
            ..model_core::Inputs::default()
        };
        let got = model_core::definition::eval_f64(&t, &inp);
        worst_nm = worst_nm.max((got[0] + 1000.0 * want[r]).abs());
    }
    assert!(worst_nm <= 0.5, "table f64 vs model: {worst_nm} nm");
}
