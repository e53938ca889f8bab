//! Diagnosis on simulated machines with fixed seeds (issue 4): each effect
//! family hidden alone is ranked first and, once added, leaves an error of at
//! most 1.3× the noise; a control with nothing hidden is `at_noise_floor`;
//! three effects hidden at once are all found by the path.
//!
//! A diagnosis of the synthetic machine takes ~10 s in a debug build, and
//! several tests look at the same campaign (thermal alone at seed 7 is
//! checked by four of them): `run` diagnoses each campaign once per test
//! binary and hands every test the same result.

use std::sync::{Arc, Mutex, OnceLock};

use trueaxis_engine::diagnose::{diagnose, Diagnosis, Options, Verdict};
use trueaxis_engine::model::Seed;
use trueaxis_engine::simulate::synth::{generate, Hidden, SynthConfig};

const NOISE_UM: f64 = 0.3;

/// A campaign: hidden effects, seed, seed model.
type Campaign = (Vec<Hidden>, u64, &'static str);

/// The diagnosis of a default synthetic campaign with `hidden` at `seed`
/// against `model`, computed once; a test that asks while another computes
/// it waits for that result.
fn run(hidden: Vec<Hidden>, seed: u64, model: &'static str) -> Arc<Diagnosis> {
    type Cell = Arc<OnceLock<Arc<Diagnosis>>>;
    static DONE: Mutex<Vec<(Campaign, Cell)>> = Mutex::new(Vec::new());
    let key = (hidden, seed, model);
    let cell = {
        let mut done = DONE.lock().unwrap_or_else(|e| e.into_inner());
        match done.iter().find(|(k, _)| *k == key) {
            Some((_, c)) => c.clone(),
            None => {
                let c = Cell::default();
                done.push((key.clone(), c.clone()));
                c
            }
        }
    };
    cell.get_or_init(|| {
        let (hidden, seed, model) = key;
        let data = generate(&SynthConfig {
            seed,
            noise_um: NOISE_UM,
            hidden,
            ..SynthConfig::default()
        });
        Arc::new(diagnose(&data, &Options::seed(model.parse().unwrap())).expect("diagnose runs"))
    })
    .clone()
}

fn check_family(h: Hidden) {
    let d = run(vec![h], 7, h.seed());
    let (family, target, axis) = h.expected();
    assert_eq!(
        d.verdict,
        Verdict::MissingEffect,
        "{h:?}: {:#?}",
        d.candidates.first()
    );
    let top = &d.candidates[0];
    assert!(top.significant);
    assert_eq!(
        (
            top.effect.as_str(),
            top.target.as_str(),
            top.axis.as_deref()
        ),
        (family, target, axis),
        "{h:?}: top candidate {}",
        top.evidence
    );
    // After the path the error of that target is at the noise.
    let after = d
        .path
        .iter()
        .rfind(|s| s.target == target)
        .expect("a path step");
    assert!(
        after.rms_um <= 1.3 * NOISE_UM,
        "{h:?}: rms after {} µm vs noise {NOISE_UM}",
        after.rms_um
    );
    // The estimated noise floor is close to the truth once the effect is in.
    let nf = d.noise_floor_um[target].expect("a noise estimate");
    assert!(
        (nf / NOISE_UM - 1.0).abs() < 0.25,
        "{h:?}: noise floor {nf}"
    );
    // Nothing is found on the other targets.
    assert!(
        d.path.iter().all(|s| s.target == target),
        "{h:?}: {:?}",
        d.path
    );
}

#[test]
fn periodic_alone_is_found() {
    let d = run(vec![Hidden::Periodic], 7, "cubic19");
    let top = &d.candidates[0];
    let period = top.params["period_mm"];
    assert!((period - 5.08).abs() < 0.005, "period {period}");
    check_family(Hidden::Periodic);
}

#[test]
fn thermal_alone_is_found() {
    check_family(Hidden::Thermal);
    let d = run(vec![Hidden::Thermal], 7, "cubic19");
    let ph = d.candidates[0].physical.clone().unwrap();
    assert_eq!(ph.name, "cte");
    assert!(
        ph.plausible && (ph.value.abs() - 11.5).abs() < 1.5,
        "{ph:?}"
    );
}

#[test]
fn reversal_alone_is_found() {
    check_family(Hidden::Reversal);
}

#[test]
fn abbe_alone_is_found() {
    check_family(Hidden::Abbe);
}

#[test]
fn drift_alone_is_found() {
    check_family(Hidden::Drift);
}

#[test]
fn squareness_alone_is_found_with_kinematic() {
    check_family(Hidden::Squareness);
}

#[test]
fn higher_order_alone_is_found() {
    check_family(Hidden::HigherOrder);
    // Its size comes with an interval that has a width (it was
    // [value, value]: a certainty the data do not give), about ±1.96 σ/√n.
    let d = run(vec![Hidden::HigherOrder], 7, Hidden::HigherOrder.seed());
    let ph = d.candidates[0].physical.as_ref().expect("component_rms");
    assert_eq!(ph.name, "component_rms");
    let width = ph.ci95[1] - ph.ci95[0];
    assert!(
        width > 0.0 && ph.ci95[0] < ph.value && ph.value < ph.ci95[1],
        "{ph:?}"
    );
    assert!(width < 0.5 * ph.value, "{ph:?}");
}

#[test]
fn control_is_at_noise_floor() {
    for seed in [1, 2, 3] {
        let d = run(vec![], seed, "cubic19");
        assert_eq!(
            d.verdict,
            Verdict::AtNoiseFloor,
            "seed {seed}: {:#?}",
            d.candidates.first()
        );
        assert!(d.candidates.iter().all(|c| !c.significant));
        assert!(d.path.is_empty());
    }
}

#[test]
fn three_effects_at_once_are_all_found() {
    let d = run(
        vec![Hidden::Periodic, Hidden::Reversal, Hidden::Drift],
        11,
        "cubic19",
    );
    for h in [Hidden::Periodic, Hidden::Reversal, Hidden::Drift] {
        let (family, target, _) = h.expected();
        assert!(
            d.path
                .iter()
                .any(|s| s.target == target && s.add.starts_with(family)),
            "{h:?} not on the path {:?}",
            d.path
        );
    }
}

/// On the `simulate` engineer's mill (the demo's machine: a 50 mm grid and
/// ONE dense pass along x, a 5 mm lead error and thermal growth of x) both
/// effects are found, the period to 0.01 %, with no spurious harmonics (on
/// the grid rows a harmonic aliases to a long wave that fits anything
/// smooth), and the error falls to the noise.
#[test]
fn simulated_mill_with_a_single_dense_pass() {
    use trueaxis_engine::simulate::{simulate, SimConfig};
    let mut cfg = SimConfig::preset("mill800").unwrap();
    cfg.plans = ["grid:50", "line:x:0.5,y=250,z=250"]
        .iter()
        .map(|p| p.parse().unwrap())
        .collect();
    cfg.effects = [
        "periodic:axis=x,period_mm=5,amp_um=3",
        "thermal:channel=bed,times=x,cte_um_per_m_k=11.5,rise_c=3,tau_s=3600",
    ]
    .iter()
    .map(|e| e.parse().unwrap())
    .collect();
    cfg.noise_um = 0.2;
    cfg.seed = 7;
    let data = simulate(&cfg);
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    let adds: Vec<&str> = d.path.iter().map(|s| s.add.as_str()).collect();
    let periodic = adds
        .iter()
        .find(|a| a.starts_with("periodic:target=ex,axis=x,"))
        .expect("periodic on the path");
    assert!(!periodic.contains("harmonics"), "{periodic}");
    let p: f64 = periodic
        .split("period_mm=")
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    assert!((p - 5.0).abs() < 5e-4, "{p}");
    assert!(
        adds.iter()
            .any(|a| a.starts_with("thermal:target=ex,channel=bed,times=x")),
        "{adds:?}"
    );
    let last = d.path.iter().rfind(|s| s.target == "ex").unwrap();
    assert!(last.rms_um <= 1.3 * 0.2, "{}", last.rms_um);
}

/// An apparent CTE of 60 µm/m/K (a sensor that sees a fifth of the
/// structure's temperature rise — common with a badly placed sensor) is
/// outside the plausible range, but the effect is what explains the error:
/// it must be found and added, and flagged, never hidden behind
/// `at_noise_floor` while the residual is 30× the noise.
#[test]
fn implausible_cte_is_found_and_flagged_not_hidden() {
    let data = generate(&SynthConfig {
        seed: 7,
        noise_um: NOISE_UM,
        hidden: vec![Hidden::Thermal],
        amplitude: 60.0 / 11.5,
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert_eq!(d.verdict, Verdict::MissingEffect, "{:#?}", d.candidates[0]);
    let top = &d.candidates[0];
    assert!(top.significant, "{}", top.evidence);
    assert_eq!(
        (top.effect.as_str(), top.target.as_str()),
        ("thermal", "ex")
    );
    let ph = top.physical.clone().unwrap();
    assert_eq!(ph.name, "cte");
    assert!(
        !ph.plausible && (ph.value.abs() - 60.0).abs() < 3.0,
        "{ph:?}"
    );
    let w = d
        .warnings
        .iter()
        .find(|w| w.code == "implausible_parameter")
        .expect("an implausible_parameter warning");
    assert!(
        w.detail.contains(&top.add) && w.detail.contains("cte") && w.detail.contains("30 µm/m/K"),
        "{}",
        w.detail
    );
    let after = d.path.iter().rfind(|s| s.target == "ex").unwrap();
    assert!(after.rms_um <= 1.3 * NOISE_UM, "{}", after.rms_um);
    assert!(
        d.warnings.iter().all(|w| w.code != "above_noise_floor"),
        "{:?}",
        d.warnings
    );
    // A plausible CTE raises no such warning.
    let d = run(vec![Hidden::Thermal], 7, "cubic19");
    assert!(d.warnings.iter().all(|w| w.code != "implausible_parameter"));
}

/// When nothing is significant but the residual is clearly above the noise
/// (1 µm RMS of smooth shape that the seed cannot follow and that no named
/// effect fits, seed 5), the verdict is `above_noise_floor` (issue 12:
/// `at_noise_floor` only when it is true), `unexplained` names every
/// target, and a warning per target says that the residual is not at the
/// noise; a control says nothing of the kind and is `at_noise_floor`.
#[test]
fn residual_above_the_noise_is_said_even_without_a_candidate() {
    let data = generate(&SynthConfig {
        seed: 5,
        noise_um: NOISE_UM,
        misfit_um: 1.0,
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert_eq!(d.verdict, Verdict::AboveNoiseFloor, "{:?}", d.path);
    assert!(d.candidates.iter().all(|c| !c.significant));
    let left: Vec<&str> = d.unexplained.iter().map(|u| u.target.as_str()).collect();
    assert_eq!(left, ["ex", "ey", "ez"]);
    for t in ["ex", "ey", "ez"] {
        assert!(
            d.warnings.iter().any(|w| w.code == "above_noise_floor"
                && w.detail
                    .starts_with(&format!("{t}: the residual of the model"))),
            "{t}: rms {:?} noise {:?} warnings {:?}",
            d.rms_um,
            d.noise_floor_um,
            d.warnings
        );
    }
    let d = run(vec![], 5, "cubic19");
    assert!(
        d.warnings.iter().all(|w| w.code != "above_noise_floor"),
        "{:?}",
        d.warnings
    );
    assert_eq!(d.verdict, Verdict::AtNoiseFloor);
}

/// An effect that is already in the model is never added a second time:
/// with a thermal term of the wrong lag (3600 s; the truth is 600 s) in the
/// model, the diagnosis proposes the same effect with its lag searched
/// again, as a replacement (`replaces`), and the path swaps it in — one
/// thermal term on ex, not two lags of one temperature.
#[test]
fn an_effect_already_in_the_model_is_replaced_not_added_twice() {
    let data = generate(&SynthConfig {
        seed: 7,
        noise_um: NOISE_UM,
        hidden: vec![Hidden::Thermal],
        ..SynthConfig::default()
    });
    let old = "thermal:target=ex,channel=bed,times=x,offset=1,lag_s=3600";
    let mut opts = Options::seed(Seed::Cubic19);
    opts.adds = vec![old.parse().unwrap()];
    let d = diagnose(&data, &opts).unwrap();
    let top = &d.candidates[0];
    assert!(top.significant, "{}", top.evidence);
    assert_eq!(top.replaces.as_deref(), Some(old), "{}", top.add);
    assert!(
        top.add
            .starts_with("thermal:target=ex,channel=bed,times=x,offset=1,lag_s="),
        "{}",
        top.add
    );
    let ex: Vec<_> = d.path.iter().filter(|s| s.target == "ex").collect();
    assert_eq!(ex.len(), 1, "{ex:?}");
    assert_eq!(ex[0].replaces.as_deref(), Some(old));
    let lag: f64 = ex[0].add.split("lag_s=").nth(1).unwrap().parse().unwrap();
    assert!((lag - 600.0).abs() <= 100.0, "lag {lag}");
    assert!(ex[0].rms_um <= 1.3 * NOISE_UM, "{}", ex[0].rms_um);
    // No candidate proposes a second thermal × x on the bed sensor for ex.
    assert!(d
        .candidates
        .iter()
        .all(|c| c.replaces.is_some()
            || !c.add.starts_with("thermal:target=ex,channel=bed,times=x,")));
}

/// The thermal lag is found between the search grid's points (600, 900,
/// 1200, 2400, 3600 s): lags of 1000 s and 2900 s are recovered to ±5 %,
/// and the CTE's 95 % interval — which includes the lag's own uncertainty —
/// covers the true 11.5 µm/m/K (the grid alone gave 900 s and an interval
/// [11.74, 12.01] that missed it).
#[test]
fn an_off_grid_thermal_lag_and_its_cte_are_recovered() {
    for lag in [1000.0, 2900.0] {
        let data = generate(&SynthConfig {
            seed: 2,
            noise_um: NOISE_UM,
            hidden: vec![Hidden::Thermal],
            thermal_lag_s: lag,
            ..SynthConfig::default()
        });
        let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
        let top = &d.candidates[0];
        assert!(
            top.significant && top.add.starts_with("thermal:target=ex,channel=bed,times=x"),
            "{}",
            top.add
        );
        let found = top.params["lag_s"];
        assert!((found / lag - 1.0).abs() < 0.05, "lag {lag}: found {found}");
        let ph = top.physical.clone().unwrap();
        assert!(
            ph.ci95[0] <= 11.5 && 11.5 <= ph.ci95[1],
            "lag {lag}: cte {} (95 % {:?})",
            ph.value,
            ph.ci95
        );
    }
}

/// `confounded` only for a pair the data cannot tell apart. With the bed
/// temperature rising linearly in time, a drift of ez and a thermal term on
/// that sensor are the same column: they are named together, and neither is
/// claimed. With the synthetic machine's warm-up curve (not linear in time)
/// thermal growth and drift are told apart by ΔBIC, so no pair is
/// `confounded` — the largest share of one column (the plain ΔT of
/// `thermal…,offset=1` inside `drift:order=3`) used to call them 100 %.
#[test]
fn confounded_only_when_the_data_cannot_separate_the_pair() {
    let mut data = generate(&SynthConfig {
        seed: 7,
        noise_um: NOISE_UM,
        hidden: vec![Hidden::Drift],
        ..SynthConfig::default()
    });
    let t_s = data.t_s.clone().unwrap();
    data.temps[0].temp_c = t_s.iter().map(|t| 20.0 + t / 3600.0).collect();
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    assert!(
        d.warnings.iter().any(|w| w.code == "confounded"
            && w.detail.contains("`drift:target=ez`")
            && w.detail.contains("`thermal:target=ez,channel=bed")),
        "{:?}",
        d.warnings
    );
    let drift = d
        .candidates
        .iter()
        .find(|c| c.add == "drift:target=ez")
        .unwrap();
    assert!(!drift.significant && !drift.confounded_with.is_empty());
    for h in [Hidden::Thermal, Hidden::Drift, Hidden::Abbe] {
        let d = run(vec![h], 7, "cubic19");
        let conf: Vec<_> = d
            .warnings
            .iter()
            .filter(|w| w.code == "confounded")
            .collect();
        assert!(conf.is_empty(), "{h:?}: {conf:?}");
        assert!(d.candidates[0].significant, "{h:?}");
    }
}

/// Three effects on ONE target (a 5 mm lead on x, 8 µm backlash on x and
/// an Abbe error, all on ex) are all found by the path, and the candidate
/// list says so: each is `on_path` and `significant` with the `step` that
/// added it and that step's ΔBIC (not the stale first-step score). The
/// report draws the evidence of the path's steps: the periodogram with its
/// peak, the forward/backward split of the reversal that was added, each
/// step's component + residual, and the residual map before and after.
#[test]
fn three_effects_on_one_target_are_all_found_and_reported() {
    let hidden = vec![Hidden::PeriodicX, Hidden::Reversal, Hidden::Abbe];
    let data = generate(&SynthConfig {
        seed: 11,
        noise_um: NOISE_UM,
        hidden: hidden.clone(),
        ..SynthConfig::default()
    });
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    let ex: Vec<_> = d.path.iter().filter(|s| s.target == "ex").collect();
    for h in &hidden {
        let (family, _, axis) = h.expected();
        let prefix = match axis {
            Some(a) => format!("{family}:target=ex,axis={a}"),
            None => format!("{family}:target=ex"),
        };
        let k = ex
            .iter()
            .position(|s| s.add == prefix || s.add.starts_with(&format!("{prefix},")))
            .unwrap_or_else(|| panic!("{h:?} not on the path {ex:?}"));
        let c = d
            .candidates
            .iter()
            .find(|c| c.add == ex[k].add)
            .expect("the path's effect is a candidate");
        assert!(c.on_path() && c.significant, "{}", c.evidence);
        assert_eq!(c.step, Some(k + 1));
        assert_eq!(c.delta_bic, Some(ex[k].delta_bic));
    }
    // No stale entry of a path effect is left saying "not significant".
    for s in &ex {
        assert_eq!(
            d.candidates.iter().filter(|c| c.add == s.add).count(),
            1,
            "{}",
            s.add
        );
    }
    assert!(ex.last().unwrap().rms_um <= 1.3 * NOISE_UM);
    // Report.
    let dir = std::env::temp_dir().join(format!("trueaxis-diag-report-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    trueaxis::report::diagnose::write(&d, &data, &dir).unwrap();
    let svg = |name: &str| {
        std::fs::read_to_string(dir.join(name)).unwrap_or_else(|_| panic!("{name} missing"))
    };
    let pg = svg("periodogram_ex_x.svg");
    assert!(
        pg.contains("Lomb–Scargle power") && pg.contains("5.00"),
        "no 5 mm peak"
    );
    let rev = svg("reversal_ex_x.svg");
    assert!(rev.contains("dir_x = +1") && rev.contains("dir_x = −1"));
    for k in 1..=ex.len() {
        let c = svg(&format!("component_ex_{k}.svg"));
        assert!(
            c.contains("component + residual")
                && c.contains("fitted component")
                && c.contains(&ex[k - 1].add),
            "component_ex_{k}"
        );
    }
    // Component + residual against the effect's channel.
    let abbe = ex.iter().position(|s| s.add == "abbe:target=ex").unwrap();
    assert!(svg(&format!("component_ex_{}.svg", abbe + 1)).contains("tool length (mm)"));
    let map = svg("residual_map_ex.svg");
    assert!(map.contains("ex residual, cubic19") && map.contains("ex residual after the path"));
    let index = svg("index.html");
    for k in 1..=ex.len() {
        assert!(
            index.contains(&format!("component_ex_{k}.svg")),
            "index lacks step {k}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A drift of order 2 (1.5 µm/h² · t²: no linear part at all) reports as
/// its rate the mean over the session, 1.5 · 2.18 h = 3.27 µm/h, with an
/// interval that covers it — the linear coefficient alone said ≈ 0 — and
/// the magnitude is in `params` too.
#[test]
fn drift_rate_is_the_mean_over_the_session_for_any_order() {
    let mut data = generate(&SynthConfig {
        seed: 7,
        noise_um: NOISE_UM,
        ..SynthConfig::default()
    });
    let t_s = data.t_s.clone().unwrap();
    let ez = data.err_um[2].as_mut().unwrap();
    for (v, t) in ez.iter_mut().zip(&t_s) {
        *v.as_mut().unwrap() += 1.5 * (t / 3600.0).powi(2);
    }
    let truth = 1.5 * t_s.iter().copied().fold(0.0, f64::max) / 3600.0;
    let d = diagnose(&data, &Options::seed(Seed::Cubic19)).unwrap();
    let top = &d.candidates[0];
    assert!(
        top.significant && top.add.starts_with("drift:target=ez,order="),
        "{}",
        top.add
    );
    assert!(top.params["order"] >= 2.0);
    let ph = top.physical.clone().unwrap();
    assert_eq!(ph.name, "rate");
    assert!(
        ph.ci95[0] <= truth && truth <= ph.ci95[1],
        "{truth}: {ph:?}"
    );
    assert_eq!(top.params["rate_um_per_h"], ph.value);
}

/// The smallest effect the held-out gain rule accepts (docs/diagnose.md,
/// "Known limits"; BENCHMARKS.md, the Monte Carlo's fifth-degree term at
/// ×0.3): its part outside cubic19's span is 0.087 µm RMS against 0.3 µm
/// of noise, so ΔBIC is overwhelming but the held-out RMS falls by only
/// ≈ 5 %, below the 10 % the acceptance demands — declined, and the residual
/// is within 1.3× of the noise, so `above_noise_floor` is silent too. The
/// campaign is the Monte Carlo's first trial of that cell (its seed).
#[test]
fn a_weak_fifth_degree_term_is_declined_by_the_gain_rule() {
    use trueaxis_engine::diagnose::{DBIC_SIGNIFICANT, MIN_HELD_OUT_GAIN};
    let cfg = SynthConfig {
        seed: 1_000_003 * 15,
        noise_um: NOISE_UM,
        hidden: vec![Hidden::HigherOrder],
        amplitude: 0.3,
        ..SynthConfig::default()
    };
    // Without noise, the seed's residual on ez is the term's part outside
    // cubic19's span (the base geometry lies inside it).
    let clean = generate(&SynthConfig {
        noise_um: 0.0,
        ..cfg.clone()
    });
    let fit = trueaxis_engine::fit::fit(&clean, "cubic19", &[], &Default::default()).unwrap();
    let outside = fit.stats.rms_um["ez"];
    assert!(
        (outside - 0.087).abs() < 0.001,
        "outside the span: {outside} µm"
    );
    let d = diagnose(&generate(&cfg), &Options::seed(Seed::Cubic19)).unwrap();
    let c = d
        .candidates
        .iter()
        .find(|c| c.add == "higher_order:target=ez,axis=z,degree=5")
        .expect("the fifth-degree candidate");
    let (dbic, gain) = (c.delta_bic.unwrap(), c.gain.unwrap());
    assert!(
        dbic < 20.0 * DBIC_SIGNIFICANT && (0.03..MIN_HELD_OUT_GAIN).contains(&gain),
        "ΔBIC {dbic}, gain {gain}"
    );
    assert!(!c.significant, "{}", c.evidence);
    assert!(
        d.warnings
            .iter()
            .all(|w| !(w.code == "above_noise_floor" && w.detail.starts_with("ez"))),
        "{:?}",
        d.warnings
    );
}
