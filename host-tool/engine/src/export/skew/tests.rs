//! The skew files read back the way each firmware reads them and applied
//! the way each firmware applies them (the formulas of their sources,
//! written out here independently of the writer): the corrected tool point
//! leaves nothing of the model's squareness but round-off.

use super::*;
use crate::export::fixtures::{file, rigid21};
use crate::model::rigid21::Rigid21Model;

/// The fixture model with its squarenesses set (µrad).
fn model(c0y: f64, b0z: f64, a0z: f64) -> Rigid21Model {
    let mut m = rigid21(4);
    for (name, v) in [("C0Y", c0y), ("B0Z", b0z), ("A0Z", a0z)] {
        m.errors.iter_mut().find(|e| e.name == name).unwrap().coef = Some(vec![v]);
    }
    m
}

fn export_of(m: &Rigid21Model, format: SkewFormat, tool_mm: f64) -> SkewExport {
    let opts = SkewOptions {
        tool_mm,
        profile: None,
    };
    export(&file(FittedModel::Rigid21(m.clone())), format, &opts).unwrap()
}

/// The model's squareness part at axis positions q, µm: the model's own
/// prediction with every other error zeroed.
fn squareness_part(m: &Rigid21Model, q: [f64; 3]) -> [f64; 3] {
    let mut only = m.clone();
    for e in &mut only.errors {
        if e.kind != ErrorKind::Squareness {
            e.coef = e.coef.as_ref().map(|c| vec![0.0; c.len()]);
        }
    }
    only.predict(&ToolPoint {
        pos_mm: q,
        ..ToolPoint::default()
    })
    .e_um
}

/// Where the machine puts the tool, minus the requested p, µm, when the
/// firmware commands `command(p)`: q + S·q − p.
fn miss_um(m: &Rigid21Model, p: [f64; 3], command: impl Fn([f64; 3]) -> [f64; 3]) -> f64 {
    let q = command(p);
    let s = squareness_part(m, q);
    (0..3)
        .map(|i| ((q[i] - p[i]) * 1000.0 + s[i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn volume() -> Vec<[f64; 3]> {
    let mut v = Vec::new();
    for x in [0.0, 333.0, 800.0] {
        for y in [0.0, 250.0, 500.0] {
            for z in [0.0, 123.0, 400.0] {
                v.push([x, y, z]);
            }
        }
    }
    v
}

/// Klipper's skew_correction.py: calc_skew_factor(ac, bd, ad) and
/// calc_skew(pos).
fn klipper_factor(ac: f64, bd: f64, ad: f64) -> f64 {
    let side = (2.0 * ac * ac + 2.0 * bd * bd - 4.0 * ad * ad).sqrt() / 2.0;
    (std::f64::consts::PI / 2.0 - ((ac * ac - side * side - ad * ad) / (2.0 * side * ad)).acos())
        .tan()
}
fn shear_command(f: [f64; 3], p: [f64; 3]) -> [f64; 3] {
    let [xy, xz, yz] = f;
    [
        p[0] - p[1] * xy - p[2] * (xz - xy * yz),
        p[1] - p[2] * yz,
        p[2],
    ]
}

fn value_after<'a>(body: &'a str, key: &str) -> &'a str {
    let line = body
        .lines()
        .find(|l| l.starts_with(key))
        .unwrap_or_else(|| panic!("no `{key}` in\n{body}"));
    line[key.len()..].trim()
}

#[test]
fn klipper_profile_and_set_skew_remove_the_squareness() {
    let m = model(25.0, -30.0, 20.0);
    let e = export_of(&m, SkewFormat::Klipper, 0.0);
    assert!(
        e.body.contains("[skew_correction trueaxis]\n"),
        "{}",
        e.body
    );
    let f =
        ["xy_skew =", "xz_skew =", "yz_skew ="].map(|k| value_after(&e.body, k).parse().unwrap());
    // SET_SKEW XY=ac,bd,ad XZ=… YZ=…, read as Klipper's cmd_SET_SKEW does.
    let set = value_after(&e.body, "# or,");
    let set = &set[set.find("SET_SKEW").unwrap() + 8..];
    let mut g = [0.0; 3];
    for word in set.split_whitespace() {
        let (plane, lengths) = word.split_once('=').unwrap();
        let l: Vec<f64> = lengths.split(',').map(|v| v.parse().unwrap()).collect();
        let i = ["XY", "XZ", "YZ"].iter().position(|p| *p == plane).unwrap();
        g[i] = klipper_factor(l[0], l[1], l[2]);
    }
    let mut uncorrected = 0.0f64;
    for p in volume() {
        assert!(
            miss_um(&m, p, |p| shear_command(f, p)) < 1e-4,
            "profile at {p:?}"
        );
        assert!(
            miss_um(&m, p, |p| shear_command(g, p)) < 1e-3,
            "SET_SKEW at {p:?}"
        );
        uncorrected = uncorrected.max(miss_um(&m, p, |p| p));
    }
    // Without the file the squareness misses by up to 25·500 + 30·400 µrad·mm.
    assert!(uncorrected > 20.0, "{uncorrected}");
    // The signs: Y leaning towards +X (C0Y > 0 gives e_x = −C0Y·y) needs a
    // negative xy factor in Klipper's convention.
    assert!(f[0] < 0.0 && f[1] < 0.0 && f[2] < 0.0, "{f:?}");
    assert!(e.max_written_error_um < 1e-3, "{}", e.max_written_error_um);
    assert_eq!(e.squareness_urad["C0Y"], 25.0);
}

#[test]
fn marlin_m852_removes_the_squareness() {
    let m = model(-12.0, 18.0, 27.0);
    let e = export_of(&m, SkewFormat::Marlin, 0.0);
    let line = value_after(&e.body, "M852");
    let mut f = [0.0; 3];
    for word in line.split_whitespace() {
        let i = ["I", "J", "K"]
            .iter()
            .position(|l| word.starts_with(l))
            .unwrap();
        f[i] = word[1..].parse().unwrap();
    }
    // Marlin's planner skew(): the same shear as Klipper's (Klipper ported it).
    for p in volume() {
        assert!(miss_um(&m, p, |p| shear_command(f, p)) < 2e-3, "{p:?}");
    }
    assert_eq!(f[0], e.factors["xy"]);
    assert!(f[0] > 0.0 && f[1] > 0.0 && f[2] < 0.0, "{f:?}");
}

#[test]
fn matrixkins_joints_remove_the_squareness() {
    let m = model(25.0, -30.0, 20.0);
    let e = export_of(&m, SkewFormat::Matrixkins, 0.0);
    let mut c = [[f64::NAN; 3]; 3];
    for line in e
        .body
        .lines()
        .filter(|l| l.starts_with("setp matrixkins.C_"))
    {
        let mut w = line.split_whitespace().skip(1);
        let name = w.next().unwrap();
        let r = "xyz".find(&name[13..14]).unwrap();
        let k = "xyz".find(&name[14..15]).unwrap();
        c[r][k] = w.next().unwrap().parse().unwrap();
    }
    // kinematicsInverse: j[0] = x·C_xx + y·C_xy + z·C_xz, …
    let joints = |p: [f64; 3]| [0, 1, 2].map(|r| c[r][0] * p[0] + c[r][1] * p[1] + c[r][2] * p[2]);
    for p in volume() {
        assert!(miss_um(&m, p, joints) < 1e-4, "{p:?}");
    }
    assert_eq!(c[1][0], 0.0);
    assert_eq!(c[0][0], 1.0);
}

#[test]
fn a_cannot_know_squareness_is_refused_naming_what_to_measure() {
    let mut m = model(25.0, -30.0, 20.0);
    let b0z = m.errors.iter_mut().find(|e| e.name == "B0Z").unwrap();
    b0z.status = Status::CannotKnow;
    b0z.coef = None;
    for format in [
        SkewFormat::Klipper,
        SkewFormat::Marlin,
        SkewFormat::Matrixkins,
    ] {
        let err = export(
            &file(FittedModel::Rigid21(m.clone())),
            format,
            &SkewOptions::default(),
        )
        .unwrap_err();
        match &err {
            FileError::CannotKnow { names, measure, .. } => {
                assert_eq!(names, &["B0Z".to_string()]);
                assert!(measure.contains("XZ face diagonals"), "{measure}");
            }
            e => panic!("{e}"),
        }
        assert!(!err.to_string().contains("--"), "{err}");
    }
}

#[test]
fn what_the_file_leaves_out_is_the_rest_of_the_model() {
    // Only a linear positioning error of X (EXX = 6 µm · s) and a spindle
    // tilt A0T = 12 µrad beside the squareness.
    let mut m = model(25.0, 0.0, 0.0);
    for e in &mut m.errors {
        if !matches!(e.kind, ErrorKind::Squareness) {
            e.coef = e.coef.as_ref().map(|c| vec![0.0; c.len()]);
        }
    }
    m.errors.iter_mut().find(|e| e.name == "EXX").unwrap().coef = Some(vec![6.0, 0.0, 0.0, 0.0]);
    m.errors.iter_mut().find(|e| e.name == "A0T").unwrap().coef = Some(vec![12.0]);
    let at0 = export_of(&m, SkewFormat::Marlin, 0.0);
    assert!((at0.left_out_by_kind_um["positioning"] - 6.0).abs() < 1e-9);
    assert_eq!(at0.left_out_by_kind_um["tilt"], 0.0);
    assert!((at0.left_out_um - 6.0).abs() < 1e-9, "{at0:?}");
    // C0Y · 500 mm = 12.5 µm at the far end of Y.
    assert!(
        (at0.squareness_um - 12.5).abs() < 1e-9,
        "{}",
        at0.squareness_um
    );
    // The whole model: e_x = 6·s − 25·y·1e-3, largest at x = 0, y = 500.
    assert!((at0.model_um - 18.5).abs() < 1e-9, "{}", at0.model_um);
    // At a 200 mm tool the tilt adds A0T·L = 2.4 µm along y everywhere.
    let at200 = export_of(&m, SkewFormat::Marlin, 200.0);
    assert!((at200.left_out_by_kind_um["tilt"] - 2.4).abs() < 1e-9);
    let want = (6.0f64.powi(2) + 2.4f64.powi(2)).sqrt();
    assert!(
        (at200.left_out_um - want).abs() < 1e-9,
        "{}",
        at200.left_out_um
    );
    let json = serde_json::to_value(&at200).unwrap();
    assert_eq!(json["tool_mm"], 200.0);
    assert!(json.get("body").is_none());
}

#[test]
fn a_model_without_z_writes_only_the_xy_skew_and_says_so() {
    use crate::model::rigid21::Chain;
    let chain = Chain::of_axes(&[0, 1]);
    let mut errors = Rigid21Model::layout(&chain, 2);
    for e in &mut errors {
        e.coef = Some(vec![0.0; e.degrees.len()]);
    }
    errors.iter_mut().find(|e| e.name == "C0Y").unwrap().coef = Some(vec![40.0]);
    let m = Rigid21Model {
        degree: 2,
        chain,
        travel_mm: [Some([0.0, 300.0]), Some([0.0, 300.0]), None],
        errors,
        effects: None,
    };
    m.check().unwrap();
    let k = export_of(&m, SkewFormat::Klipper, 0.0);
    assert!(k.body.contains("SET_SKEW XY="), "{}", k.body);
    assert!(!k.body.contains(" XZ="), "{}", k.body);
    assert_eq!(value_after(&k.body, "xz_skew ="), "0.000000000000");
    assert_eq!(k.warnings[0].code, "squareness_not_in_model");
    let mk = export_of(&m, SkewFormat::Marlin, 0.0);
    assert!(
        value_after(&mk.body, "M852").starts_with("I-0.000040000"),
        "{}",
        mk.body
    );
    assert!(!mk.body.contains(" J"), "{}", mk.body);
}

#[test]
fn another_kind_of_model_is_refused() {
    let lin =
        crate::export::fixtures::linear(0, &[(crate::export::fixtures::mono([1, 0, 0]), 2.0)]);
    let err = export(&lin, SkewFormat::Klipper, &SkewOptions::default()).unwrap_err();
    assert!(err.to_string().contains("rigid21"), "{err}");
}

#[test]
fn a_klipper_profile_is_named_by_one_word() {
    let m = model(25.0, -30.0, 20.0);
    let named = |p: &str| {
        let opts = SkewOptions {
            tool_mm: 0.0,
            profile: Some(p.into()),
        };
        export(
            &file(FittedModel::Rigid21(m.clone())),
            SkewFormat::Klipper,
            &opts,
        )
    };
    let ok = named("mill_1").unwrap();
    assert!(
        ok.body.contains("[skew_correction mill_1]\n"),
        "{}",
        ok.body
    );
    assert!(ok.body.contains("SKEW_PROFILE LOAD=mill_1"), "{}", ok.body);
    for bad in ["my mill", "a]b", ""] {
        let e = named(bad).unwrap_err().to_string();
        assert!(e.contains("one word"), "{bad}: {e}");
    }
}
