//! The noise floor against the true noise of simulated data (issue 12):
//! across every kind of plan `simulate` makes and the presets, the floor
//! estimated on a cubic19 fit's residual lands within 0.7–1.4× of the
//! simulated σ (fixed seeds).

use trueaxis_engine::diagnose::noise::noise_floor;
use trueaxis_engine::fit::{fit, FitOptions};
use trueaxis_engine::model::Seed;
use trueaxis_engine::simulate::{simulate, Effect, SimConfig};

fn sim(
    preset: &str,
    plans: &[&str],
    effects: &[&str],
    noise_um: f64,
    seed: u64,
) -> trueaxis_engine::data::Dataset {
    let mut cfg = SimConfig::preset(preset).unwrap();
    cfg.plans = plans.iter().map(|p| p.parse().unwrap()).collect();
    cfg.effects = effects
        .iter()
        .map(|e| e.parse::<Effect>().unwrap())
        .collect();
    cfg.noise_um = noise_um;
    cfg.seed = seed;
    cfg.check().unwrap();
    simulate(&cfg)
}

/// Floor per target of the cubic19 residual.
fn floors(data: &trueaxis_engine::data::Dataset) -> Vec<(usize, Option<f64>, String)> {
    let m = fit(data, "cubic19", &[], &FitOptions::default()).unwrap();
    let res = m.model.residuals(data).unwrap();
    let mut out = Vec::new();
    for (t, r) in res.iter().enumerate() {
        let Some(r) = r else { continue };
        let (rows, resid): (Vec<usize>, Vec<f64>) = r.iter().copied().unzip();
        let nf = noise_floor(data, &rows, &resid);
        out.push((
            t,
            nf.map(|n| n.sigma_um),
            format!("{:?}", nf.map(|n| n.method)),
        ));
    }
    out
}

#[test]
fn the_floor_is_the_simulated_noise_across_plans_and_presets() {
    let cases: Vec<(&str, Vec<&str>, Vec<&str>)> = vec![
        ("mill800", vec!["grid:50"], vec![]),
        ("mill800-wavy", vec!["grid:50"], vec![]),
        ("mill800-wavy", vec!["grid:25"], vec![]),
        ("mill800", vec!["line:y:0.5,x=400,z=250,bidir"], vec![]),
        ("mill800-wavy", vec!["line:x:0.5,bidir"], vec![]),
        ("mill800-wavy", vec!["line:x:25,bidir"], vec![]),
        ("mill800-wavy", vec!["grid:100", "line:x:1,bidir"], vec![]),
        ("mill800", vec!["iso230:x"], vec![]),
        (
            "mill800-wavy",
            vec![
                "grid:100",
                "point:x=400,y=250,z=250,repeats=40",
                "point:x=100,y=50,z=450,repeats=40",
            ],
            vec![],
        ),
        (
            "mill800",
            vec!["grid:100,runs=3"],
            vec!["abbe:angle_urad=48.5,tools_mm=0/100/150"],
        ),
        (
            "mill800-wavy",
            vec!["grid:50"],
            vec!["periodic:axis=y,period_mm=5.08,amp_um=3"],
        ),
        (
            "mill800-wavy",
            vec!["grid:50"],
            vec!["thermal:channel=bed,target=ex,times=x"],
        ),
    ];
    let mut bad = Vec::new();
    for (preset, plans, effects) in &cases {
        for (sigma, seed) in [(0.2, 3), (0.5, 11)] {
            let data = sim(preset, plans, effects, sigma, seed);
            for (t, f, how) in floors(&data) {
                let ratio = f.map_or(f64::NAN, |f| f / sigma);
                eprintln!("{preset} {plans:?} {effects:?} σ={sigma} target {t}: {ratio:.2} {how}");
                if !(0.7..=1.4).contains(&ratio) {
                    bad.push(format!(
                        "{preset} {plans:?} {effects:?} σ={sigma} target {t}: {ratio:.2} ({how})"
                    ));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{bad:#?}");
}

/// A guide bump (issue 12: neighbour differences along a 25–50 mm line
/// counted it as noise, 0.30 against 0.15 µm): a 1.5 µm straightness bump of
/// ey along x, 40 mm wide at half height, at x = 400 (and a narrower one at
/// x = 260) — no cubic follows it. On every plan the floor is measured
/// within 0.7–1.4× of the simulated σ, or (on lines coarser than 10 mm,
/// where differences cannot tell the bump from noise) it is said to be an
/// upper bound and is not below the noise.
#[test]
fn the_floor_is_the_simulated_noise_with_a_guide_bump() {
    let bump = [
        "bump:target=ey,axis=x,at_mm=400,width_mm=40,amp_um=1.5",
        "bump:target=ey,axis=x,at_mm=260,width_mm=20,amp_um=1",
    ];
    let plans: Vec<Vec<&str>> = vec![
        vec!["line:x:0.5,bidir"],
        vec!["line:x:25,bidir"],
        vec!["line:x:50,bidir"],
        vec!["grid:50"],
        vec!["grid:100", "line:x:1,bidir"],
    ];
    let mut bad = Vec::new();
    let mut measured = 0;
    for plans in &plans {
        for (sigma, seed) in [(0.15, 3), (0.5, 11)] {
            let data = sim("mill800", plans, &bump, sigma, seed);
            for (t, f, how) in floors(&data) {
                let ratio = f.map_or(f64::NAN, |f| f / sigma);
                let bound = how.contains("SparseDifferences");
                eprintln!("bump {plans:?} σ={sigma} target {t}: {ratio:.2} {how}");
                if t == 1 && !bound {
                    measured += 1;
                }
                // An upper bound is not below the noise — up to the
                // scatter of a few dozen differences (±15 %).
                let ok = if bound {
                    ratio >= 0.6
                } else {
                    (0.7..=1.4).contains(&ratio)
                };
                if !ok {
                    bad.push(format!(
                        "bump {plans:?} σ={sigma} target {t}: {ratio:.2} ({how})"
                    ));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{bad:#?}");
    // The dense line and the grid plans do measure ey's floor.
    assert!(measured >= 6, "ey measured on {measured} plan/σ pairs");
}

/// `at_noise_floor` only when every target is within 1.3× its floor: the
/// wavy preset's long waves (~1 µm against 0.2 µm of noise) are left by
/// cubic19 and no candidate names them, so the verdict is
/// `above_noise_floor` with the targets, ratios and worst cells; the plain
/// preset, which cubic19 holds, is at the floor.
#[test]
fn at_noise_floor_only_when_the_residual_is_at_the_floor() {
    use trueaxis_engine::diagnose::{diagnose, Options, Verdict};
    let wavy = sim("mill800-wavy", &["grid:50"], &[], 0.2, 5);
    let d = diagnose(&wavy, &Options::seed(Seed::Cubic19)).unwrap();
    assert_eq!(d.verdict, Verdict::AboveNoiseFloor, "{:#?}", d.unexplained);
    assert!(d.candidates.iter().all(|c| !c.significant));
    let left: Vec<&str> = d.unexplained.iter().map(|u| u.target.as_str()).collect();
    assert!(left.contains(&"ex") && left.contains(&"ey"), "{left:?}");
    for u in &d.unexplained {
        assert!(u.ratio > 1.3 && u.region.is_some(), "{u:?}");
        let nf = d.noise_floor_um[&u.target].unwrap();
        assert!((0.7..=1.4).contains(&(nf / 0.2)), "{nf}");
    }
    assert_eq!(
        serde_json::to_value(&d).unwrap()["verdict"],
        "above_noise_floor"
    );

    // improve stops there and says so, with the worst cell.
    let out = std::env::temp_dir().join(format!("trueaxis-noise-{}.json", std::process::id()));
    let imp = trueaxis_engine::improve::improve(&wavy, Seed::Cubic19, &out, false, |_| {}).unwrap();
    let last = imp.steps.last().unwrap();
    assert_eq!(imp.verdict, Verdict::AboveNoiseFloor);
    let outcome = last.outcome();
    assert!(
        outcome.starts_with("no significant candidate left, but above the noise floor: ex ")
            && outcome.contains("worst in x "),
        "{outcome}"
    );
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_file(trueaxis_engine::history::history_path(&out));

    let plain = sim("mill800", &["grid:50"], &[], 0.2, 5);
    let d = diagnose(&plain, &Options::seed(Seed::Cubic19)).unwrap();
    assert_eq!(d.verdict, Verdict::AtNoiseFloor, "{:#?}", d.unexplained);
    assert!(d.unexplained.is_empty());
}
