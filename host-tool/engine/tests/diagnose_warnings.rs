//! The diagnosis' identifiability and design warnings on synthetic data
//! built to trigger each one (issue 4): `in_model_span` with the issue's own
//! example — an Abbe error linear in y when the Abbe arm grows with z, which
//! cubic19's y·z and y already contain — and squareness under cubic19;
//! `constant_temperature` for a sensor that does not change. Each test also
//! checks the case that must not warn.

use trueaxis_engine::diagnose::{diagnose, Diagnosis, Options};
use trueaxis_engine::model::Seed;
use trueaxis_engine::simulate::synth::{generate, SynthConfig};

fn warned(d: &Diagnosis, code: &str, needle: &str) -> bool {
    d.warnings
        .iter()
        .any(|w| w.code == code && w.detail.contains(needle))
}

#[test]
fn effects_in_the_model_span_are_kept_unidentifiable_and_warned() {
    let mut data = generate(&SynthConfig {
        seed: 7,
        ..SynthConfig::default()
    });
    // The Abbe arm grows with z (a measuring offset along the ram): the
    // column tool·u_y = z·u_y is a combination of cubic19's y·z and y.
    data.tool_mm = data.pos_mm[2].clone();
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    for (add, fix) in [
        ("abbe:target=ex,times=y", "two or more tool lengths"),
        (
            "squareness:target=ex,axis=y",
            "a seed without linear cross terms",
        ),
    ] {
        let c = d
            .candidates
            .iter()
            .find(|c| c.add == add)
            .unwrap_or_else(|| panic!("{add} is not a candidate"));
        assert!(
            !c.identifiable && !c.significant && c.gain.is_none() && c.delta_bic.is_none(),
            "{add}: {c:?}"
        );
        assert!(c.out_of_span_share < 1e-6, "{add}: {}", c.out_of_span_share);
        assert!(
            warned(
                &d,
                "in_model_span",
                &format!("`{add}` cannot be told from it")
            ) && warned(&d, "in_model_span", fix),
            "{add}: {:?}",
            d.warnings
        );
    }
    // With the synthetic plan's tool lengths (0/75/150 mm by pass), the same
    // Abbe column is outside the span; kinematic has no linear cross terms,
    // so squareness is identifiable there.
    let data = generate(&SynthConfig {
        seed: 7,
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Kinematic)).unwrap();
    for add in ["abbe:target=ex,times=y", "squareness:target=ex,axis=y"] {
        let c = d.candidates.iter().find(|c| c.add == add).unwrap();
        assert!(c.identifiable, "{add}");
        assert!(!warned(&d, "in_model_span", &format!("`{add}`")));
    }
}

#[test]
fn a_constant_temperature_is_warned_and_not_tested() {
    let mut data = generate(&SynthConfig {
        seed: 7,
        ..SynthConfig::default()
    });
    let n = data.len();
    data.temps[1].temp_c = (0..n)
        .map(|i| 20.5 + 0.01 * ((i % 7) as f64 / 7.0))
        .collect();
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert!(
        warned(&d, "constant_temperature", "T_air_C spans only"),
        "{:?}",
        d.warnings
    );
    assert!(!warned(&d, "constant_temperature", "T_bed_C"));
    assert!(d
        .candidates
        .iter()
        .all(|c| c.channel.as_deref() != Some("T_air_C")));
    assert!(d
        .candidates
        .iter()
        .any(|c| c.channel.as_deref() == Some("T_bed_C")));
    // With temperature columns present, no `no_temperature` warning (the
    // counterpart of the next test).
    assert!(d.warnings.iter().all(|w| w.code != "no_temperature"));
}

#[test]
fn data_without_a_temperature_says_thermal_cannot_be_tested() {
    let mut data = generate(&SynthConfig {
        seed: 7,
        ..SynthConfig::default()
    });
    data.temps.clear();
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert!(
        warned(&d, "no_temperature", "thermal effects cannot be tested"),
        "{:?}",
        d.warnings
    );
    assert!(d.candidates.iter().all(|c| c.effect != "thermal"));
    // With the sensors there, no such warning: checked on the previous
    // test's data (same campaign, one sensor constant), which saves a
    // diagnosis of its own.
}
