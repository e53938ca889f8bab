//! Two look-alikes of a public spindle thermal test (issue 24), one point
//! read once a minute for two days, readings quantised to 0.25 µm:
//!
//! - `spindle-duty`: 14 partly correlated sensors driven by one spindle
//!   power schedule (each through its own first-order lag) and the shop's
//!   air; the growth (ez) follows three of them, two with a lag of their
//!   own (the housing 1800 s late, the column 3600 s late, the headstock at
//!   once). Day 1: a cold hour, a warm-up at 70 % for 8 h, off; day 2 —
//!   the later half — another duty cycle (2 h at full power, 1 h at 20 %,
//!   three times, then off). Trained on day 1, a model must predict day 2.
//! - `spindle-drift`: the control. The same 14 sensors wander (each an
//!   AR(1) of its own about the air, no spindle), and ez is an AR(1)
//!   instrument drift no sensor causes: no effect may be claimed that
//!   predicts worse than the mean.

use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::data::{Dataset, TempChannel};
use crate::features::lagged;

use super::thermal_test::{ambient_c, NOISE_UM, POINT_MM, QUANTUM_UM, STEP_S, T_REF_C};
use super::{normal, round_dec, SimOutput};

/// `simulate --scenario spindle-duty`.
pub const SPINDLE_DUTY: &str = "spindle-duty";
/// `simulate --scenario spindle-drift` (the control).
pub const SPINDLE_DRIFT: &str = "spindle-drift";

/// Duration, s (two days; the later half is day 2).
pub const DUTY_DURATION_S: f64 = 48.0 * 3600.0;

/// The sensors that drive ez: (name, µm/K, lag of the growth behind the
/// sensor, s).
pub const DUTY_DRIVING: [(&str, f64, f64); 3] = [
    ("spindle_housing", -1.0, 1800.0),
    ("column_front", -0.7, 3600.0),
    ("headstock", -0.4, 0.0),
];

/// Each sensor: name, heating by the spindle at full power (K), time
/// constant of its response to the spindle's heat (s), and to the air (s).
const SENSORS: [(&str, f64, f64, f64); 14] = [
    ("spindle_front", 11.0, 900.0, 1800.0),
    ("spindle_rear", 8.0, 1500.0, 1800.0),
    ("spindle_motor", 15.0, 600.0, 1200.0),
    ("spindle_housing", 9.0, 2400.0, 3600.0),
    ("spindle_oil", 5.0, 1200.0, 2400.0),
    ("coolant_in", 2.0, 300.0, 600.0),
    ("coolant_out", 4.5, 600.0, 900.0),
    ("headstock", 6.0, 4800.0, 5400.0),
    ("column_front", 2.5, 9000.0, 7200.0),
    ("column_rear", 1.2, 12000.0, 9000.0),
    ("table", 0.6, 7200.0, 10800.0),
    ("base", 0.3, 14400.0, 18000.0),
    ("cabinet", 1.5, 3000.0, 2400.0),
    ("ambient", 0.0, 1.0, 1.0),
];

/// Spindle power (share of full) at `t_s`: day 1 cold for an hour, 70 % for
/// 8 h, off; day 2 three cycles of 2 h at full power and 1 h at 20 %, off.
pub fn duty_power(t_s: f64) -> f64 {
    let h = t_s / 3600.0;
    if (1.0..9.0).contains(&h) {
        0.7
    } else if (25.0..34.0).contains(&h) {
        if (h - 25.0) % 3.0 < 2.0 {
            1.0
        } else {
            0.2
        }
    } else {
        0.0
    }
}

/// One reading quantised like the gauge: truth + noise, to [`QUANTUM_UM`].
fn reading(truth: f64, rng: &mut ChaCha8Rng) -> Option<f64> {
    let v = truth + NOISE_UM * normal(rng);
    Some(round_dec((v / QUANTUM_UM).round() * QUANTUM_UM, 4))
}

fn one_point(
    name: &str,
    n: usize,
    t_s: Vec<f64>,
    temps: Vec<TempChannel>,
    ez: Vec<Option<f64>>,
    seed: u64,
    what: &str,
) -> Dataset {
    Dataset {
        source: format!("simulate:{name}"),
        metadata: vec![
            ("generator".to_string(), "trueaxis simulate".to_string()),
            ("scenario".to_string(), name.to_string()),
            ("seed".to_string(), seed.to_string()),
            ("description".to_string(), what.to_string()),
        ],
        pos_mm: POINT_MM.map(|p| Some(vec![p; n])),
        err_um: [None, None, Some(ez)],
        t_s: Some(t_s),
        temps,
        ..Dataset::default()
    }
}

/// The rows' count and times: every `STEP_S` over `DUTY_DURATION_S`.
fn duty_times() -> (usize, Vec<f64>) {
    let n = (DUTY_DURATION_S / STEP_S) as usize + 1;
    (n, (0..n).map(|i| i as f64 * STEP_S).collect())
}

/// Stream `k` of the generator seeded with `seed`.
fn stream(seed: u64, k: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(k);
    rng
}

/// The spindle-duty look-alike (module docs); the same seed gives the same
/// data bit for bit.
pub fn spindle_duty(seed: u64) -> SimOutput {
    let (n, t_s) = duty_times();
    let power: Vec<f64> = t_s.iter().map(|&t| duty_power(t)).collect();
    let air: Vec<f64> = t_s.iter().map(|&t| ambient_c(t)).collect();
    let mut rng = stream(seed, 5);
    let mut temps = Vec::new();
    for (name, gain_k, tau_heat_s, tau_air_s) in SENSORS {
        let heat = lagged(&power, &t_s, None, tau_heat_s);
        let room = lagged(&air, &t_s, None, tau_air_s);
        let temp_c = (0..n)
            .map(|r| round_dec(room[r] + gain_k * heat[r] + 0.005 * normal(&mut rng), 2))
            .collect();
        temps.push(TempChannel {
            name: name.to_string(),
            temp_c,
        });
    }
    let mut ez_true = vec![0.0; n];
    for (name, k, lag) in DUTY_DRIVING {
        let ch = &temps
            .iter()
            .find(|c| c.name == name)
            .expect("listed")
            .temp_c;
        let dt: Vec<f64> = ch.iter().map(|t| t - T_REF_C).collect();
        let col = if lag > 0.0 {
            lagged(&dt, &t_s, None, lag)
        } else {
            dt
        };
        for r in 0..n {
            ez_true[r] += k * col[r];
        }
    }
    let ez = ez_true.iter().map(|&v| reading(v, &mut rng)).collect();
    let what = format!("spindle thermal test at one point, a reading every {STEP_S} s for 48 h, 14 sensors, ez following three of them with lags, day 2 at another duty cycle, readings quantised to {QUANTUM_UM} µm");
    SimOutput {
        data: one_point(SPINDLE_DUTY, n, t_s, temps, ez, seed, &what),
        truth_um: [vec![0.0; n], vec![0.0; n], ez_true],
        spikes: Vec::new(),
    }
}

/// AR(1) coefficient of the control's drift per reading, and its
/// innovation, µm (a wander of about 1.5 µm over hours).
const DRIFT_RHO: f64 = 0.995;
const DRIFT_STEP_UM: f64 = 0.15;

/// The spindle-drift control (module docs).
pub fn spindle_drift(seed: u64) -> SimOutput {
    let (n, t_s) = duty_times();
    let air: Vec<f64> = t_s.iter().map(|&t| ambient_c(t)).collect();
    let mut rng = stream(seed, 6);
    let mut temps = Vec::new();
    for (name, gain_k, _, tau_air_s) in SENSORS {
        let room = lagged(&air, &t_s, None, tau_air_s);
        // Its own wander: an AR(1) over hours, larger where the spindle's
        // heat would be (but the spindle does not run).
        let mut w = 0.0;
        let temp_c = (0..n)
            .map(|r| {
                w = 0.998 * w + (0.01 + 0.005 * gain_k) * normal(&mut rng);
                round_dec(room[r] + w + 0.005 * normal(&mut rng), 2)
            })
            .collect();
        temps.push(TempChannel {
            name: name.to_string(),
            temp_c,
        });
    }
    let mut d = 0.0;
    let ez_true: Vec<f64> = (0..n)
        .map(|_| {
            d = DRIFT_RHO * d + DRIFT_STEP_UM * normal(&mut rng);
            d
        })
        .collect();
    let ez = ez_true.iter().map(|&v| reading(v, &mut rng)).collect();
    let what = format!("control: 48 h at one point, 14 wandering temperatures, ez an AR(1) instrument drift no sensor causes, readings quantised to {QUANTUM_UM} µm");
    SimOutput {
        data: one_point(SPINDLE_DRIFT, n, t_s, temps, ez, seed, &what),
        truth_um: [vec![0.0; n], vec![0.0; n], ez_true],
        spikes: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_look_alikes_are_quantised_one_point_series_of_14_sensors() {
        for out in [spindle_duty(1), spindle_drift(1)] {
            let d = &out.data;
            d.validate().unwrap();
            assert_eq!(d.len(), 2881);
            assert!(d.varying_axes().is_empty());
            assert_eq!(d.temps.len(), 14);
            for v in d.err_um[2].as_ref().unwrap() {
                let q = v.unwrap() / QUANTUM_UM;
                assert!((q - q.round()).abs() < 1e-9, "{q}");
            }
        }
        assert_eq!(spindle_duty(1).data, spindle_duty(1).data);
        // Day 2 runs another duty cycle than day 1.
        assert_eq!(duty_power(5.0 * 3600.0), 0.7);
        assert_eq!(duty_power(26.0 * 3600.0), 1.0);
        assert_eq!(duty_power(27.5 * 3600.0), 0.2);
        // The growth follows the spindle: several µm over the test.
        let ez = &spindle_duty(1).truth_um[2];
        let pv = ez.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - ez.iter().copied().fold(f64::INFINITY, f64::min);
        assert!((5.0..40.0).contains(&pv), "{pv}");
    }
}
