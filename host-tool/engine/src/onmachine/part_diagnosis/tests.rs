use super::*;

#[test]
fn the_quantile_of_the_largest_of_n_normals() {
    // One point: the usual 1.96; 500 points: about 3.9 (the tables of
    // the normal: P(|N| > 3.89) = 1.0e-4 = 1 − 0.95^(1/500)).
    assert!((z_all(1) - 1.96).abs() < 0.005, "{}", z_all(1));
    assert!((z_all(500) - 3.89).abs() < 0.02, "{}", z_all(500));
    assert!(z_all(100) < z_all(1000));
}

/// A straightness run of part + slide (fixed seed), and its reversal.
fn runs(drift_um_per_s: f64) -> (Scan, Vec<f64>, Vec<(f64, f64)>) {
    let part = |x: f64| 2.0 * ((x - 100.0) / 100.0).powi(2);
    let slide = |x: f64| 1.5 * (x / 30.0).sin();
    let mut rng = trueaxis_test_support::SplitMix64(5);
    // Out and back to the start: 0…200 mm, then 0 again, 2 s a point.
    let mut pos: Vec<f64> = (0..=100).map(|i| 2.0 * i as f64).collect();
    pos.push(0.0);
    let t: Vec<f64> = (0..pos.len()).map(|i| 2.0 * i as f64).collect();
    let d: Vec<f64> = pos
        .iter()
        .zip(&t)
        .map(|(&x, &ts)| part(x) + slide(x) + drift_um_per_s * ts + 0.02 * rng.normal())
        .collect();
    let r180 = (0..=100)
        .map(|i| {
            let x = 2.0 * i as f64;
            (x, part(x) - slide(x) + 0.02 * rng.normal())
        })
        .collect();
    (
        Scan::Straightness {
            pos_mm: pos,
            d_um: d,
        },
        t,
        r180,
    )
}

#[test]
fn one_orientation_says_the_sum_and_a_reversal_splits_it() {
    let (scan, t, r180) = runs(0.0);
    let one = diagnose(&scan, &Evidence::default()).unwrap();
    for s in [Source::PartForm, Source::SlideStraightness] {
        let f = one.get(s);
        assert_eq!(f.status, Status::CannotKnow);
        assert!(f.value.is_none() && f.measure.as_ref().unwrap().gives(Input::Reversal));
    }
    assert_eq!(one.get(Source::ProbeRadius).status, Status::NotInScan);
    assert!(one
        .get(Source::ThermalDrift)
        .measure
        .as_ref()
        .unwrap()
        .to_string()
        .contains("t_s"));
    assert_eq!(one.combined.len(), 1);
    let both = diagnose(
        &scan,
        &Evidence {
            reversal: Some(r180),
            t_s: Some(t),
            ..Default::default()
        },
    )
    .unwrap();
    // Part: a symmetric bow of 2 µm at the ends; its line is flat, so
    // its PV stays 2 µm.
    let part = both.get(Source::PartForm);
    assert_eq!(part.status, Status::Estimated);
    let [lo, hi] = part.ci95.unwrap();
    assert!(lo <= 2.0 && 2.0 <= hi && hi - lo < 0.5, "{part:?}");
    assert_eq!(
        both.get(Source::SlideStraightness).status,
        Status::Estimated
    );
    // The start read again, no drift: estimated, zero inside.
    let th = both.get(Source::ThermalDrift);
    let [lo, hi] = th.ci95.unwrap();
    assert!(lo < 0.0 && hi > 0.0, "{th:?}");
}

#[test]
fn a_drift_during_the_scan_is_measured_from_the_start_read_again() {
    // 0.6 µm/min over the 202 s run: 2 µm at the end.
    let (scan, t, _) = runs(0.01);
    let d = diagnose(
        &scan,
        &Evidence {
            t_s: Some(t),
            ..Default::default()
        },
    )
    .unwrap();
    let th = d.get(Source::ThermalDrift);
    let [lo, hi] = th.ci95.unwrap();
    assert!(lo < 0.6 && 0.6 < hi && hi - lo < 0.1, "{th:?}");
}
