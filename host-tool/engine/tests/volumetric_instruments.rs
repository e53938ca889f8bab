//! What ballbar circles, single laser lines and angular readings can tell
//! a rigid21 model (docs/volumetric.md § What the data can tell): the
//! simulator's `mill800-21` measured with each plan, fixed seeds; every
//! answer honest (an estimated error within 4σ of the same plan's
//! noise-free fit, the truth in the gauge) and the `cannot_know` list as
//! the physics says.

use trueaxis_engine::fit::volumetric_check::against_noise_free;
use trueaxis_engine::model::rigid21::{Identifiability, Status};
use trueaxis_engine::simulate::instruments::{ballbar_circles, laser_line, Instrument};
use trueaxis_engine::simulate::Machine;

fn mill() -> Machine {
    Machine::preset("mill800-21").unwrap()
}

/// The noisy plan's answer at `degree` and its residuals, every
/// estimated error within 4σ of the same plan's noise-free fit.
fn honest(
    m: &Machine,
    plan: &[Instrument],
    degree: usize,
    seed: u64,
) -> (Identifiability, Vec<(String, f64, usize)>) {
    let ((_, id, kinds), wrong) = against_noise_free(m, plan, &[0, 1, 2], degree, seed).unwrap();
    assert!(wrong.is_empty(), "{wrong:?}");
    (id, kinds)
}

fn status(id: &Identifiability, name: &str) -> Status {
    id.errors.iter().find(|e| e.name == name).unwrap().status
}

fn unknown(id: &Identifiability) -> Vec<&str> {
    id.errors
        .iter()
        .filter(|e| e.status == Status::CannotKnow)
        .map(|e| e.name.as_str())
        .collect()
}

#[test]
fn a_ballbar_in_three_planes_cannot_tell_squareness_from_straightness_and_angles() {
    let m = mill();
    let plan = ballbar_circles(m.travel_mm, 100.0);
    for degree in [1, 4] {
        let (id, kinds) = honest(&m, &plan, degree, 3);
        let (_, _, n) = kinds.iter().find(|k| k.0 == "e_beam").unwrap();
        assert_eq!(*n, 270);
        // The bar reads relative to its own calibrated length: a scale
        // error of the axes is the same reading as that zero.
        for name in ["EXX", "EYY", "EZZ"] {
            assert_eq!(status(&id, name), Status::CannotKnow, "{degree} {name}");
        }
        // Even with straight-line error functions (the usual ballbar
        // assumption) a squareness is the same reading as a linear angle
        // times its arm.
        for name in ["C0Y", "B0Z", "A0Z"] {
            assert_eq!(status(&id, name), Status::CannotKnow, "{degree} {name}");
        }
        let ms = id.measure.as_ref().expect("a measurement to add");
        assert!(ms.hidden_um_after < id.hidden_um, "{ms:?}");
    }
    // At the default degree nothing at all.
    let (id, _) = honest(&m, &plan, 4, 3);
    assert_eq!(unknown(&id).len(), id.errors.len(), "{:?}", unknown(&id));
    assert!(id.hidden_um > 20.0, "{}", id.hidden_um);
}

#[test]
fn angular_errors_need_an_arm_across_them_or_an_angular_reading() {
    let m = mill();
    let mid = m.travel_mm.map(|t| t * 0.5);
    let angles_xy = ["EAX", "EBX", "ECX", "EAY", "EBY", "ECY"];
    // One line per axis through the middle, tool on the spindle axis:
    // no angle of X or Y, and (Abbe) not X's positioning either.
    let one: Vec<Instrument> = (0..3).map(|a| laser_line(a, mid, 0.0)).collect();
    let (id, _) = honest(&m, &one, 4, 3);
    for name in angles_xy.iter().chain(&["EXX"]) {
        assert_eq!(status(&id, name), Status::CannotKnow, "{name}");
    }
    // An angular line along each axis: all six.
    let mut angular = one.clone();
    angular.extend((0..3).map(|axis| Instrument::Angular {
        axis,
        at_mm: mid,
        points: 21,
    }));
    let (id, _) = honest(&m, &angular, 4, 3);
    for name in angles_xy.iter().chain(&["EXX"]) {
        assert_eq!(status(&id, name), Status::Estimated, "{name}");
    }
    // A parallel line offset along the next axis gives the angle whose
    // arm that offset is: X's yaw (offset in y) and Y's roll (offset in
    // z); X's pitch needs an arm along z (a second tool length).
    let mut two = one.clone();
    for a in 0..3 {
        let mut at = mid;
        at[(a + 1) % 3] = m.travel_mm[(a + 1) % 3] * 0.8;
        two.push(laser_line(a, at, 0.0));
    }
    let (id, _) = honest(&m, &two, 4, 3);
    assert_eq!(status(&id, "ECX"), Status::Estimated);
    assert_eq!(status(&id, "EAY"), Status::Estimated);
    assert_eq!(status(&id, "EBX"), Status::CannotKnow);
    let mut longer = two.clone();
    longer.extend(two.iter().map(|i| match i {
        Instrument::Line { axis, at_mm, .. } => laser_line(*axis, *at_mm, 150.0),
        other => other.clone(),
    }));
    let (id, _) = honest(&m, &longer, 4, 3);
    assert_eq!(status(&id, "EBX"), Status::Estimated);
}
