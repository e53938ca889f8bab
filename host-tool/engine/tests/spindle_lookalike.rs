//! The spindle thermal look-alikes of issue 24 (`simulate --scenario
//! spindle-duty`, `spindle-drift`), trained on the first half (day 1) and
//! judged on the later half (day 2, another duty cycle): the chosen model's
//! prediction against the true structure refitted on the same half, the
//! first effect, the warm-up rows, the floor; and the control, which may
//! claim nothing that predicts worse than the mean. Fixed seeds.

use nalgebra::{DMatrix, DVector};
use trueaxis_engine::data::{subset, Dataset};
use trueaxis_engine::diagnose::{diagnose, Diagnosis, Options};
use trueaxis_engine::effect::Effect;
use trueaxis_engine::features::{lagged, Norm};
use trueaxis_engine::model::Seed;
use trueaxis_engine::simulate::spindle_duty::{spindle_drift, spindle_duty, DUTY_DRIVING};
use trueaxis_engine::simulate::thermal_test::{spindle_warmup, NOISE_UM, QUANTUM_UM, T_REF_C};

/// Rows of the first day and of the second.
fn halves(data: &Dataset) -> (Vec<usize>, Vec<usize>) {
    let t = data.t_s.as_ref().unwrap();
    (0..t.len()).partition(|&r| t[r] < 24.0 * 3600.0)
}

fn ez(data: &Dataset) -> Vec<f64> {
    data.err_um[2]
        .as_ref()
        .unwrap()
        .iter()
        .map(|v| v.unwrap())
        .collect()
}

/// RMS on `test` of the least-squares fit of `y` on `cols` (and a
/// constant) over `train`.
fn forward_rms(cols: &[Vec<f64>], y: &[f64], train: &[usize], test: &[usize]) -> f64 {
    let k = cols.len() + 1;
    let x = |r: usize, j: usize| if j == 0 { 1.0 } else { cols[j - 1][r] };
    let a = DMatrix::from_fn(train.len(), k, |i, j| x(train[i], j));
    let b = DVector::from_fn(train.len(), |i, _| y[train[i]]);
    let beta = a.svd(true, true).solve(&b, 1e-12).unwrap();
    let se: f64 = test
        .iter()
        .map(|&r| {
            let p: f64 = (0..k).map(|j| x(r, j) * beta[j]).sum();
            (y[r] - p).powi(2)
        })
        .sum();
    (se / test.len() as f64).sqrt()
}

/// The columns of the ez effects on `d`'s path, over all of `data` (a lag
/// runs on from day 1 into day 2, as it would on the machine).
fn path_columns(d: &Diagnosis, data: &Dataset) -> Vec<Vec<f64>> {
    let norm = Norm::from_data(data);
    d.path
        .iter()
        .filter(|s| s.target == "ez")
        .flat_map(|s| Effect::parse(&s.add).unwrap().features)
        .map(|f| f.column(data, &norm).unwrap())
        .collect()
}

fn day1_diagnosis(data: &Dataset) -> Diagnosis {
    let (first, _) = halves(data);
    diagnose(&subset(data, &first), &Options::seed(Seed::Cubic19)).unwrap()
}

#[test]
fn trained_on_day_one_the_chosen_model_predicts_day_two() {
    let sim = spindle_duty(1);
    let data = &sim.data;
    let (first, second) = halves(data);
    let y = ez(data);
    let d = day1_diagnosis(data);
    let path: Vec<&str> = d
        .path
        .iter()
        .filter(|s| s.target == "ez")
        .map(|s| s.add.as_str())
        .collect();
    let t = data.t_s.as_ref().unwrap();
    let truth_cols: Vec<Vec<f64>> = DUTY_DRIVING
        .iter()
        .map(|(name, _, lag)| {
            let dt: Vec<f64> = data
                .temp(name)
                .unwrap()
                .temp_c
                .iter()
                .map(|v| v - T_REF_C)
                .collect();
            if *lag > 0.0 {
                lagged(&dt, t, None, *lag)
            } else {
                dt
            }
        })
        .collect();
    let chosen = forward_rms(&path_columns(&d, data), &y, &first, &second);
    let truth = forward_rms(&truth_cols, &y, &first, &second);
    let mean = forward_rms(&[], &y, &first, &second);
    eprintln!("ez path {path:?}: day 2 RMS chosen {chosen:.3} µm, true structure refitted {truth:.3}, training mean {mean:.3}");
    assert!(
        path.first().is_some_and(|a| a.starts_with("thermal")),
        "first effect {path:?}"
    );
    assert!(
        chosen <= 1.5 * truth,
        "chosen {chosen:.3} vs truth {truth:.3} ({path:?})"
    );
    // No warm-up row is left out as an outlier.
    assert!(
        d.outliers.iter().all(|o| o.target != "ez"),
        "{:?}",
        d.outliers
    );
    // The floor: the gauge noise and the quantum, q/√12.
    let floor = (NOISE_UM.powi(2) + QUANTUM_UM.powi(2) / 12.0).sqrt();
    let got = d.noise_floor_um["ez"].expect("a floor");
    assert!(
        (0.5 * floor..=2.0 * floor).contains(&got),
        "floor {got:.4} vs {floor:.4}"
    );
}

/// The "better than a linear regression on all sensors" (no lags,
/// refitted on day 1): met since the forward check refits the whole model
/// on the earlier hours and predicts every later block (issue 24).
#[test]
fn the_chosen_model_beats_a_regression_on_all_sensors() {
    let sim = spindle_duty(1);
    let data = &sim.data;
    let (first, second) = halves(data);
    let y = ez(data);
    let d = day1_diagnosis(data);
    let all: Vec<Vec<f64>> = data.temps.iter().map(|c| c.temp_c.clone()).collect();
    let chosen = forward_rms(&path_columns(&d, data), &y, &first, &second);
    let regression = forward_rms(&all, &y, &first, &second);
    eprintln!("day 2 RMS: chosen {chosen:.3} µm, regression on all 14 sensors {regression:.3}");
    assert!(chosen < regression, "{chosen:.3} vs {regression:.3}");
}

/// The control: no effect claimed that predicts day 2 worse than day 1's
/// mean (seeds 2–4 added a two- or three-sensor thermal before the forward
/// check refitted the level and predicted every later block).
#[test]
fn the_drift_control_claims_nothing_that_predicts_worse_than_the_mean() {
    let mut bad = Vec::new();
    for seed in [1, 2, 3, 4] {
        let sim = spindle_drift(seed);
        let data = &sim.data;
        let (first, second) = halves(data);
        let y = ez(data);
        let d = day1_diagnosis(data);
        let steps: Vec<String> = d
            .path
            .iter()
            .filter(|s| s.target == "ez")
            .map(|s| {
                format!(
                    "{} (ΔBIC {:.0}, with n_eff {:?}: {:?})",
                    s.add,
                    s.delta_bic,
                    s.effective_n.map(|n| n.round()),
                    s.delta_bic_effective.map(|d| d.round())
                )
            })
            .collect();
        let chosen = forward_rms(&path_columns(&d, data), &y, &first, &second);
        let mean = forward_rms(&[], &y, &first, &second);
        eprintln!(
            "seed {seed}: ez path {steps:?}: day 2 RMS {chosen:.3} µm, training mean {mean:.3}"
        );
        if !steps.is_empty() && chosen > mean {
            bad.push(seed);
        }
    }
    assert!(
        bad.is_empty(),
        "seeds {bad:?} claim an effect that predicts worse than the mean"
    );
}

/// A thermal effect that leaves the residual wandering in time is said
/// unconfirmed, with what would confirm it — and a real growth's sensors,
/// which leave it near white, are not. On the AR(1) control (which now
/// adds nothing, above) a thermal effect, if any, must be flagged; the
/// warm-up look-alike, whose growth follows heat paths no sensor logs,
/// keeps its sensor (it predicts the later hours) and is flagged. Trained
/// on day 1, as a user with one run would.
#[test]
fn a_thermal_effect_that_leaves_the_residual_wandering_is_said_unconfirmed() {
    let codes =
        |d: &Diagnosis| -> Vec<String> { d.warnings.iter().map(|w| w.code.clone()).collect() };
    for seed in [1, 2, 3, 4] {
        let d = day1_diagnosis(&spindle_drift(seed).data);
        let thermal = d.path.iter().any(|s| s.add.starts_with("thermal:"));
        let unconfirmed = codes(&d).iter().any(|c| c == "thermal_unconfirmed");
        assert_eq!(
            thermal,
            unconfirmed,
            "control seed {seed}: {:?} {:?}",
            d.path,
            codes(&d)
        );
    }
    let d = diagnose(&spindle_warmup(1).data, &Options::seed(Seed::Cubic19)).unwrap();
    assert!(
        d.path.iter().any(|s| s.add.starts_with("thermal:"))
            && codes(&d).iter().any(|c| c == "thermal_unconfirmed"),
        "warm-up: {:?} {:?}",
        d.path,
        codes(&d)
    );
    for seed in [1, 2] {
        let d = day1_diagnosis(&spindle_duty(seed).data);
        assert!(d.path.iter().any(|s| s.add.starts_with("thermal:")));
        assert!(
            !codes(&d).iter().any(|c| c == "thermal_unconfirmed"),
            "duty seed {seed}: {:?}",
            codes(&d)
        );
    }
}
