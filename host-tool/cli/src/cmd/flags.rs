//! The engine's refusals in the command line's words. The engine says what
//! is wrong in its own terms and as a typed error (`local fit: …`,
//! `noise_um = …`, `expected the one to read`); here each is said with the
//! flag that fixes it (`--local: …`, `--noise-um = …`, `choose one:
//! trueaxis import FILE --profile NAME …`). `main` prints every error
//! through [`render`], so every command says the same thing the same way.

use trueaxis_engine::fit::FitError;
use trueaxis_engine::import::{ImportError, LoadError, Needs};
use trueaxis_engine::iso230::{axis_names, AxisChoice};
use trueaxis_engine::onmachine::probe_csv::SessionNeeded;
use trueaxis_engine::onmachine::spindle_log::Missing;
use trueaxis_engine::onmachine::workpiece::PassGridError;
use trueaxis_engine::simulate::{BadSpikes, ConfigError, Setting};
use trueaxis_engine::travel::TravelError;

/// `e` with its causes, as `{e:#}` writes it (`outer: inner: root`), each
/// typed engine error in the command line's words.
pub fn render(e: &anyhow::Error) -> String {
    e.chain()
        .map(|c| words(c).unwrap_or_else(|| c.to_string()))
        .collect::<Vec<_>>()
        .join(": ")
}

/// The flag of a simulation setting.
fn setting_flag(s: Setting) -> &'static str {
    match s {
        Setting::NoiseUm => "--noise-um",
        Setting::ToolMm => "--tool-mm",
        Setting::FeedMmS => "--feed-mm-s",
        Setting::DwellS => "--dwell-s",
        Setting::SpikeFrac => "--spikes FRAC",
        Setting::SpikeAmpUm => "--spikes AMP_UM",
    }
}

/// The command line's words for one error of a chain; `None` to keep the
/// engine's.
fn words(e: &(dyn std::error::Error + 'static)) -> Option<String> {
    if let Some(f) = e.downcast_ref::<FitError>() {
        return Some(match f {
            FitError::LocalWithEffects => {
                "--add is not supported with --local (the local patches use the seed's own terms)"
                    .to_string()
            }
            FitError::NotPolynomial { seed } => format!(
                "--local applies to the polynomial seeds (cubic19, kinematic), --add to those and rigid21, not to {seed}"
            ),
            FitError::Local(why) => format!("--local: {why}"),
        });
    }
    if let Some(c) = e.downcast_ref::<ConfigError>() {
        return Some(match c {
            ConfigError::NoPlan => {
                "no measurement plan (expected at least one --plan, e.g. grid:50)".to_string()
            }
            ConfigError::Setting { setting, range } => {
                format!("{} = {range}", setting_flag(*setting))
            }
        });
    }
    if let Some(t) = e.downcast_ref::<TravelError>() {
        return Some(match t {
            TravelError::Empty { axis, lo, hi } => {
                format!("--travel {axis}={lo}..{hi}: empty (expected finite LO ≤ HI)")
            }
            TravelError::NoAxis { axis } => {
                format!("--travel {axis}: the data has no {axis}_mm column")
            }
            TravelError::NothingInside { axis, lo, hi } => {
                format!("every row lies outside --travel {axis}={lo}..{hi}")
            }
        });
    }
    if let Some(s) = e.downcast_ref::<BadSpikes>() {
        return Some(format!("--spikes {s}"));
    }
    if let Some(i) = e.downcast_ref::<ImportError>() {
        let loc = i.location();
        return i.needs.as_ref().map(|n| match n {
            Needs::EcmcAxis => format!(
                "{loc}: an ecmc ISO230 file does not name its machine axis; pass --axis x|y|z (convert once: trueaxis import FILE.dat --axis x -o run.csv)"
            ),
            Needs::RtlAxis => {
                format!("{loc}: no `Axis:` line in USER-TEXT:: (expected X, Y or Z; or pass --axis)")
            }
            Needs::Profile { profiles } => format!(
                "{loc}: {} bed mesh profiles ({}); choose one: trueaxis import FILE --profile NAME -o mesh.csv",
                profiles.len(),
                profiles.join(", ")
            ),
        });
    }
    if let Some(LoadError::ProfileNotCfg { file }) = e.downcast_ref::<LoadError>() {
        return Some(format!(
            "{file}: --profile names a Klipper bed mesh; expected a .cfg file"
        ));
    }
    // The on-machine commands.
    if let Some(n) = e.downcast_ref::<SessionNeeded>() {
        return Some(n.text("--session"));
    }
    if e.downcast_ref::<PassGridError>().is_some() {
        return Some(PassGridError::text("--z-steps"));
    }
    if let Some(m) = e.downcast_ref::<Missing>() {
        return Some(match m {
            Missing::CountsPerTurn { .. } => format!("{m}: give them with --counts-per-turn N"),
            Missing::Speed { .. } => format!("{m}: give the speed with --rpm R"),
        });
    }
    if let Some(AxisChoice::Several { file, axes }) = e.downcast_ref::<AxisChoice>() {
        return Some(format!(
            "{file}: several axes could be evaluated ({}); choose one with --axis",
            axis_names(axes)
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;
    use trueaxis_engine::data::Dataset;
    use trueaxis_engine::effect::Effect;
    use trueaxis_engine::fit::{self, FitOptions};
    use trueaxis_engine::import;
    use trueaxis_engine::simulate::{SimConfig, Spikes};

    /// A line along x with errors in x and y (x and y move).
    fn line() -> Dataset {
        let mut t = String::from("x_mm,y_mm,ex_um,ey_um,dir_x,dir_y\n");
        for i in 0..12 {
            t.push_str(&format!("{},{},{},{},1,1\n", 10 * i, i % 2, i, 2 * i));
        }
        import::read_csv(t.as_bytes(), "d.csv").unwrap()
    }

    fn fit_err(seed: &str, adds: &[&str], local: bool) -> String {
        let adds: Vec<Effect> = adds.iter().map(|a| Effect::parse(a).unwrap()).collect();
        let opts = FitOptions {
            local,
            ..FitOptions::default()
        };
        let e = fit::fit(&line(), seed, &adds, &opts)
            .context("d.csv: cannot fit")
            .unwrap_err();
        assert!(
            !format!("{e:#}").contains("--"),
            "the engine names a flag: {e:#}"
        );
        render(&e)
    }

    #[test]
    fn fit_refusals_name_add_and_local() {
        assert_eq!(
            fit_err("cubic19", &["drift:target=ex"], true),
            "d.csv: cannot fit: --add is not supported with --local (the local patches use the seed's own terms)"
        );
        assert_eq!(
            fit_err("nn:4", &[], true),
            "d.csv: cannot fit: --local applies to the polynomial seeds (cubic19, kinematic), --add to those and rigid21, not to nn:4"
        );
        let e = render(&anyhow::Error::new(FitError::Local(
            fit::LocalRefusal::NoTravel,
        )));
        assert_eq!(
            e,
            "--local: every measured point lies at one position; a local fit needs travel on some axis"
        );
    }

    #[test]
    fn simulate_refusals_name_their_flags() {
        let mut cfg = SimConfig::preset("mill800").unwrap();
        let e = cfg.check().unwrap_err();
        assert_eq!(
            render(&e),
            "no measurement plan (expected at least one --plan, e.g. grid:50)"
        );
        cfg.plans = vec!["grid:100".parse().unwrap()];
        cfg.timing.feed_mm_s = 0.0;
        assert_eq!(
            render(&cfg.check().unwrap_err()),
            "--feed-mm-s = 0.0: expected a finite value > 0 mm/s and ≤ 2000 mm/s"
        );
        let e = anyhow::Error::new("0.1".parse::<Spikes>().unwrap_err());
        assert_eq!(
            render(&e),
            "--spikes `0.1`: expected FRAC,AMP_UM, e.g. 0.005,20"
        );
    }

    #[test]
    fn import_refusals_name_axis_and_profile() {
        let two_axes = line();
        let e = anyhow::Error::new(trueaxis_engine::iso230::default_axis(&two_axes).unwrap_err());
        assert_eq!(
            render(&e),
            "d.csv: several axes could be evaluated (x, y); choose one with --axis"
        );
        let needing = |needs| ImportError {
            file: "f".into(),
            line: 7,
            column: None,
            message: "the engine's words".into(),
            needs: Some(needs),
        };
        let say = |needs| render(&anyhow::Error::new(needing(needs)));
        assert_eq!(
            say(Needs::EcmcAxis),
            "f:7: an ecmc ISO230 file does not name its machine axis; pass --axis x|y|z (convert once: trueaxis import FILE.dat --axis x -o run.csv)"
        );
        assert_eq!(
            say(Needs::RtlAxis),
            "f:7: no `Axis:` line in USER-TEXT:: (expected X, Y or Z; or pass --axis)"
        );
        assert_eq!(
            say(Needs::Profile {
                profiles: vec!["default".into(), "hot".into()]
            }),
            "f:7: 2 bed mesh profiles (default, hot); choose one: trueaxis import FILE --profile NAME -o mesh.csv"
        );
        let e = anyhow::Error::new(LoadError::ProfileNotCfg {
            file: "m.csv".into(),
        });
        assert_eq!(
            render(&e),
            "m.csv: --profile names a Klipper bed mesh; expected a .cfg file"
        );
    }
}
