//! One module per subcommand; each exposes `Args` (clap) with `run`.

pub mod compare;
pub mod demo;
mod demo_volumetric;
pub mod diagnose;
pub mod diagnose_part;
pub mod export;
pub mod fit;
pub mod flags;
pub mod flash;
pub mod history;
pub mod import;
pub mod improve;
pub mod iso230;
pub mod monitor;
pub mod out;
pub mod probe;
pub mod progress;
pub mod reference;
pub mod rollback;
pub mod separate;
pub mod simulate;
pub mod status;
pub mod upload;
pub mod workpiece;

/// A range `LO..HI` of a flag (`--temp-range-c -10..40`): finite numbers,
/// LO ≤ HI; `what` names the flag in the message.
pub fn parse_range(s: &str, what: &str) -> anyhow::Result<(f64, f64)> {
    use anyhow::Context;
    let (a, b) = s
        .split_once("..")
        .with_context(|| format!("{what} `{s}`: expected LO..HI"))?;
    let lo: f64 = a
        .trim()
        .parse()
        .with_context(|| format!("{what} `{s}`: `{a}` is not a number"))?;
    let hi: f64 = b
        .trim()
        .parse()
        .with_context(|| format!("{what} `{s}`: `{b}` is not a number"))?;
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        anyhow::bail!("{what} `{s}`: expected finite LO ≤ HI");
    }
    Ok((lo, hi))
}

/// `--travel AXIS=LO..HI`: the machine's travel the model is fitted on
/// (`fit`, `improve`; docs/cli.md § fit, "Travel").
#[derive(clap::Args, Debug, Default)]
pub struct TravelArgs {
    /// The travel of an axis, mm, as `x=0..800` (repeatable, one per axis):
    /// rows outside it are left out of the fit and named. Without it an
    /// axis' travel is the data's bulk (a stray row far beyond the rest is
    /// left out and named).
    #[arg(
        long = "travel",
        value_name = "AXIS=LO..HI",
        allow_hyphen_values = true
    )]
    pub travel: Vec<String>,
}

impl TravelArgs {
    /// The travel per axis, as the engine takes it (`travel::Limits`).
    pub fn limits(&self) -> anyhow::Result<trueaxis_engine::travel::Limits> {
        let mut limits: trueaxis_engine::travel::Limits = [None; 3];
        for t in &self.travel {
            let axis = t.split_once('=').and_then(|(a, _)| {
                trueaxis_engine::data::AXES
                    .iter()
                    .position(|x| *x == a.trim())
            });
            let (Some(a), Some((_, range))) = (axis, t.split_once('=')) else {
                anyhow::bail!(
                    "--travel `{t}`: expected AXIS=LO..HI with AXIS x, y or z (e.g. x=0..800)"
                );
            };
            if limits[a].is_some() {
                anyhow::bail!(
                    "--travel: {} is given twice",
                    trueaxis_engine::data::AXES[a]
                );
            }
            limits[a] = Some(parse_range(
                range,
                &format!("--travel {}", trueaxis_engine::data::AXES[a]),
            )?);
        }
        Ok(limits)
    }
}

/// The `--travel` that would keep the rows outside the travel too, as
/// flags: `--travel x=0..1999`.
pub fn travel_keeping(outside: &[trueaxis_engine::travel::OutsideRow]) -> String {
    trueaxis_engine::travel::widened(outside)
        .iter()
        .map(|(a, lo, hi)| format!("--travel {a}={lo}..{hi}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `--port`: the board a link command (`upload`, `rollback`, `status`,
/// `monitor`, `reference`) talks to.
#[derive(clap::Args, Debug)]
pub struct BoardPort {
    /// Serial port of the board (`/dev/ttyACM0`, `COM3`) or `tcp://HOST:PORT`.
    #[arg(long)]
    pub port: String,
}

impl BoardPort {
    /// Opens the link with the default timing (500 ms, 4 tries). A port
    /// that starts with `tcp:` but not `tcp://` is refused with a hint (it
    /// would be opened as a serial device path); a path that is not a
    /// serial device is named as such.
    pub fn open(&self) -> anyhow::Result<crate::link::Client> {
        let port = &self.port;
        if port.starts_with("tcp:") && !port.starts_with("tcp://") {
            anyhow::bail!(
                "cannot open {port}: a TCP port is written tcp://HOST:PORT (two slashes), e.g. tcp://127.0.0.1:4000"
            );
        }
        crate::link::Client::open(port, crate::link::Timing::default()).map_err(|e| {
            let not_serial = !port.starts_with("tcp://")
                && (std::fs::metadata(port).is_ok_and(|m| m.is_file() || m.is_dir())
                    || std::error::Error::source(&e)
                        .is_some_and(|s| s.to_string().contains("Not a typewriter")));
            let e = anyhow::Error::new(e);
            if not_serial {
                e.context(format!(
                    "{port} is not a serial device (a board is /dev/ttyACM0, /dev/ttyUSB0, COM3 or tcp://HOST:PORT)"
                ))
            } else {
                e
            }
        })
    }
}

/// Names of the model output flags set in `bits` (model-core's `Flags`);
/// a bit without a name is `bit_N`, never dropped.
pub fn model_flag_names(bits: u16) -> Vec<String> {
    (0..16)
        .filter(|i| bits & (1 << i) != 0)
        .map(|i| {
            model_core::eval::Flags::NAMES
                .get(i)
                .map_or_else(|| format!("bit_{i}"), |n| n.to_string())
        })
        .collect()
}

/// Telemetry JSON ([`crate::link::telemetry_json`]) with the model flags
/// also by name (`model_flags_names`).
pub fn telemetry_json(t: &trueaxis_protocol::Telemetry) -> serde_json::Value {
    let mut v = crate::link::telemetry_json(t);
    v["model_flags_names"] = serde_json::json!(model_flag_names(t.model_flags));
    v
}

/// Temperatures as text: `20.000 °C` per channel.
pub fn temps_text(temp_mc: &[i32]) -> String {
    temp_mc
        .iter()
        .map(|t| format!("{:.3}", *t as f64 / 1000.0))
        .collect::<Vec<_>>()
        .join(", ")
        + " °C"
}

/// A list of names, or `none`.
pub fn names_or_none<S: AsRef<str>>(names: &[S]) -> String {
    if names.is_empty() {
        "none".into()
    } else {
        names
            .iter()
            .map(AsRef::as_ref)
            .collect::<Vec<_>>()
            .join(", ")
    }
}
