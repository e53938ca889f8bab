//! `thermal`: growth following a temperature channel, alone or times the
//! position along an axis, optionally lagged.
//!
//! `thermal:target=ex,channel=bed[,times=x][,offset=0|1][,lag_s=600][,t_ref_c=20]`
//! adds per channel ΔT (°C above `t_ref_c`, lagged by `lag_s` within each
//! session) or ΔT·u_axis with `times` — and with `offset=1` the plain ΔT as
//! well: a screw or scale expands about its fixed end, which is rarely the
//! travel's centre. Several sensors in one effect (`channel=housing+column`,
//! `lag_s=600+0`: one lag per channel or one for all) make a multi-sensor
//! model, for when no one sensor follows the structure's growth. Its
//! physical parameter is the CTE (with `times`) or the growth per kelvin.
//! Simulated as a sensor warming up (and swinging) and the structure
//! following it with a lag.

use std::f64::consts::TAU;
use std::fmt;

use anyhow::{anyhow, bail, Result};

use super::sim::Sensor;
use super::{
    exp_along, parse_axis, parse_f64, Axis, EffectParams, FamilyDef, Info, Limit, Pairs,
    PhysicalParam, Reading, Scale, SimForm, SimRows, Target, T_REF_C,
};
use crate::data::{AXES, TARGETS};
use crate::features::{lagged, Feature};

/// Thermal growth following one or several temperature channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Thermal {
    /// The channel's name (`bed` for `T_bed_C`), or several joined by `+`,
    /// as written.
    pub channel: String,
    /// The axis the growth is proportional to, if any.
    pub times: Option<Axis>,
    /// With `times`: the plain ΔT column too (the fixed point fitted).
    pub offset: bool,
    /// The lag of each channel, s (0 = none).
    pub lags_s: Vec<f64>,
    /// The temperature at which the growth is zero, °C.
    pub t_ref_c: f64,
}

impl Thermal {
    /// The effect the search proposes: `channel` (one name, or several
    /// joined by `+`), times `times` with the fixed point fitted, each
    /// channel lagged by its entry of `lags_s`, about [`T_REF_C`].
    pub fn new(channel: &str, times: Option<Axis>, lags_s: Vec<f64>) -> Thermal {
        Thermal {
            channel: channel.to_string(),
            times,
            offset: times.is_some(),
            lags_s,
            t_ref_c: T_REF_C,
        }
    }

    /// The channels' names.
    pub fn channels(&self) -> impl Iterator<Item = &str> {
        self.channel.split('+').map(str::trim)
    }
}

impl FamilyDef for Thermal {
    const INFO: Info = Info::new(
        "thermal",
        &["target", "channel", "times", "offset", "lag_s", "t_ref_c"],
        "check the sensor: one that sees only part of the structure's temperature change (placed on a cover, in the air stream, far from the screw nut or scale) makes the apparent coefficient too large; put it on the part that grows or add a second sensor there",
    )
    .time_dependent()
    .simulated(Sim::parse);

    fn parse(kv: &Pairs, _target: Target) -> Result<Thermal> {
        let channel = kv.need("channel")?;
        let channels: Vec<&str> = channel.split('+').map(str::trim).collect();
        if let Some(c) = channels.iter().find(|c| c.is_empty()) {
            bail!("`channel={c}`: expected channel names joined by +, e.g. housing+column");
        }
        if let Some((i, c)) = channels
            .iter()
            .enumerate()
            .find(|(i, c)| channels[..*i].contains(c))
        {
            bail!("`channel=`: {c} is named twice (position {})", i + 1);
        }
        let lags_s: Vec<f64> = match kv.get("lag_s")? {
            None => vec![0.0; channels.len()],
            Some(v) => {
                let l: Vec<f64> = v
                    .split('+')
                    .map(|x| parse_f64(x.trim(), "lag_s"))
                    .collect::<Result<_>>()?;
                match l.len() {
                    1 => vec![l[0]; channels.len()],
                    k if k == channels.len() => l,
                    k => bail!(
                        "`lag_s={v}`: {k} lags for {} channels (expected one, or one per channel)",
                        channels.len()
                    ),
                }
            }
        };
        if let Some(l) = lags_s.iter().find(|l| **l < 0.0) {
            bail!("`lag_s={l}`: expected ≥ 0");
        }
        let t_ref_c = kv.f64("t_ref_c")?.unwrap_or(T_REF_C);
        let times = kv.axis("times")?;
        let offset = kv.u8_in("offset", 0, 1)?.unwrap_or(0) == 1;
        Ok(Thermal {
            channel: channel.to_string(),
            times,
            offset,
            lags_s,
            t_ref_c,
        })
    }
}

impl EffectParams for Thermal {
    fn features(&self, _target: Target) -> Vec<Feature> {
        let exp = exp_along(self.times, 1);
        let mut f = Vec::new();
        for (channel, &lag_s) in self.channels().zip(&self.lags_s) {
            f.push(Feature::Thermal {
                channel: channel.to_string(),
                t_ref_c: self.t_ref_c,
                lag_s,
                exp,
            });
            if self.offset && exp != [0, 0, 0] {
                f.push(Feature::Thermal {
                    channel: channel.to_string(),
                    t_ref_c: self.t_ref_c,
                    lag_s,
                    exp: [0, 0, 0],
                });
            }
        }
        f
    }

    fn pairs(&self) -> Vec<(&'static str, String)> {
        let mut p = vec![("channel", self.channel.clone())];
        if let Some(a) = self.times {
            p.push(("times", a.to_string()));
        }
        if self.offset {
            p.push(("offset", "1".into()));
        }
        if self.lags_s.iter().any(|l| *l > 0.0) {
            let lags: Vec<String> = self.lags_s.iter().map(f64::to_string).collect();
            p.push(("lag_s", lags.join("+")));
        }
        if self.t_ref_c != T_REF_C {
            p.push(("t_ref_c", self.t_ref_c.to_string()));
        }
        p
    }

    fn channel(&self) -> Option<&str> {
        Some(&self.channel)
    }

    fn times(&self) -> Option<Axis> {
        self.times
    }

    fn follows(&self) -> Option<String> {
        let cols: Vec<String> = self.channels().map(|c| format!("T_{c}_C")).collect();
        Some(cols.join("+"))
    }

    fn describe(&self, t: &str) -> String {
        let sensors: Vec<String> = self.channels().map(|c| c.replace('_', " ")).collect();
        format!(
            "thermal growth of {t} with the {} temperature{}",
            sensors.join(" and "),
            self.times
                .map_or(String::new(), |a| format!(", growing along {a}"))
        )
    }

    fn searched_params(&self) -> Vec<(&'static str, f64)> {
        vec![("lag_s", self.lags_s.first().copied().unwrap_or(0.0))]
    }

    fn physical(&self) -> Option<PhysicalParam> {
        Some(match self.times {
            Some(a) => PhysicalParam {
                name: "cte",
                unit: "µm/m/K",
                expected: "|CTE| ≤ 30 µm/m/K (steel 11.5, cast iron 10, aluminium 23)",
                reading: Reading::Linear {
                    scale: Scale::PerMetreAlong(a),
                    max_abs: 30.0,
                },
            },
            None => PhysicalParam {
                name: "offset_per_kelvin",
                unit: "µm/K",
                expected: "≤ 20 µm/K",
                reading: Reading::Linear {
                    scale: Scale::Fixed(1.0),
                    max_abs: 20.0,
                },
            },
        })
    }
}

/// Expansion coefficient (steel 11.5, aluminium 23, Invar ~1).
const CTE: Limit = Limit::closed(-100.0, 100.0, "µm/m/K");
/// Position-independent growth.
const OFFSET_UM_PER_K: Limit = Limit::closed(-100.0, 100.0, "µm/K");
/// A temperature of a machine shop.
const TEMP_C: Limit = Limit::closed(-50.0, 100.0, "°C");
/// A warm-up rise.
const RISE_C: Limit = Limit::closed(-50.0, 50.0, "K");
/// Time constants and lags.
const TIME_CONST_S: Limit = Limit::closed(0.0, 1e7, "s");
/// An air conditioner's swing.
const SWING_C: Limit = Limit::closed(-20.0, 20.0, "K");
/// Its period.
const SWING_PERIOD_S: Limit = Limit::above(0.0, 1e7, "s");

/// Simulated thermal growth following a temperature that is recorded on
/// the channel `T_<channel>_C`: the sensor follows
/// start_c + rise_c·(1 − e^(−t/tau_s)) + swing_c·sin(2π·t/swing_period_s);
/// the structure follows the sensor with a first-order lag `lag_s`
/// (updated per reading, as `features::lagged` models it); the error on
/// `target` is (T_struct − t_ref_c)·(cte_um_per_m_k·1e-3·q_times +
/// offset_um_per_k).
#[derive(Clone, Debug, PartialEq)]
pub struct Sim {
    /// Target index.
    pub target: usize,
    /// Sensor name (`bed` → column `T_bed_C`).
    pub channel: String,
    /// Axis whose position the growth is proportional to; `None` for a
    /// growth that does not depend on position (spindle growth in Z).
    pub times: Option<usize>,
    /// Expansion coefficient, µm/m/K (steel 11.5).
    pub cte_um_per_m_k: f64,
    /// Position-independent growth, µm/K.
    pub offset_um_per_k: f64,
    /// Temperature at which the error is zero, °C.
    pub t_ref_c: f64,
    /// Sensor temperature at t = 0, °C.
    pub start_c: f64,
    /// Sensor rise to its final value, K.
    pub rise_c: f64,
    /// Time constant of the sensor's rise, s (0 = a step at t = 0).
    pub tau_s: f64,
    /// Lag of the structure behind the sensor, s (0 = none).
    pub lag_s: f64,
    /// Amplitude of a periodic swing added to the sensor (an air
    /// conditioner's cycle), K; 0 = none. A swing lets drift (which
    /// follows time only) be told apart from a monotonic warm-up.
    pub swing_c: f64,
    /// Period of the swing, s.
    pub swing_period_s: f64,
}

impl Sim {
    /// `channel`, [`target`, ex by default], [`times`: an axis or `none`,
    /// the target's axis by default], and the sensor's and growth's
    /// numbers, each with its default.
    fn parse(kv: &Pairs) -> Result<Box<dyn SimForm>> {
        let channel = kv
            .get("channel")?
            .ok_or_else(|| anyhow!("missing `channel=` (the sensor: bed → T_bed_C)"))?
            .to_string();
        if channel.is_empty() || channel.contains([',', '"', '\n']) {
            bail!("`channel={channel}`: expected a plain name such as bed");
        }
        let target = kv.target()?.map_or(0, Target::index);
        let times = match kv.get("times")? {
            None => Some(target),
            Some("none") => None,
            Some(v) => Some(parse_axis(v, "times")?.index()),
        };
        let nonneg = |v: f64, k: &str| -> Result<f64> {
            if v < 0.0 {
                bail!("`{k}={v}`: expected a value ≥ 0");
            }
            Ok(v)
        };
        let e = Sim {
            target,
            channel,
            times,
            cte_um_per_m_k: kv.f64("cte_um_per_m_k")?.unwrap_or(11.5),
            offset_um_per_k: kv.f64("offset_um_per_k")?.unwrap_or(0.0),
            t_ref_c: kv.f64("t_ref_c")?.unwrap_or(20.0),
            start_c: kv.f64("start_c")?.unwrap_or(20.0),
            rise_c: kv.f64("rise_c")?.unwrap_or(3.0),
            tau_s: nonneg(kv.f64("tau_s")?.unwrap_or(3600.0), "tau_s")?,
            lag_s: nonneg(kv.f64("lag_s")?.unwrap_or(0.0), "lag_s")?,
            swing_c: kv.f64("swing_c")?.unwrap_or(0.0),
            swing_period_s: match kv.f64("swing_period_s")?.unwrap_or(1800.0) {
                p if p > 0.0 => p,
                p => bail!("`swing_period_s={p}`: expected a positive period"),
            },
        };
        kv.finish("channel, target, times, cte_um_per_m_k, offset_um_per_k, t_ref_c, start_c, rise_c, tau_s, lag_s, swing_c, swing_period_s")?;
        Ok(Box::new(e))
    }
}

impl Sensor for Sim {
    fn name(&self) -> &str {
        &self.channel
    }

    fn temp_c(&self, t: f64) -> f64 {
        let f = if self.tau_s > 0.0 {
            1.0 - (-t / self.tau_s).exp()
        } else {
            1.0
        };
        let swing = self.swing_c * (TAU * t / self.swing_period_s).sin();
        self.start_c + self.rise_c * f + swing
    }
}

impl SimForm for Sim {
    fn valid(&self) -> bool {
        self.tau_s >= 0.0 && self.lag_s >= 0.0 && self.swing_period_s > 0.0
    }

    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()> {
        CTE.check(&what("cte_um_per_m_k"), self.cte_um_per_m_k)?;
        OFFSET_UM_PER_K.check(&what("offset_um_per_k"), self.offset_um_per_k)?;
        TEMP_C.check(&what("t_ref_c"), self.t_ref_c)?;
        TEMP_C.check(&what("start_c"), self.start_c)?;
        RISE_C.check(&what("rise_c"), self.rise_c)?;
        TIME_CONST_S.check(&what("tau_s"), self.tau_s)?;
        TIME_CONST_S.check(&what("lag_s"), self.lag_s)?;
        SWING_C.check(&what("swing_c"), self.swing_c)?;
        SWING_PERIOD_S.check(&what("swing_period_s"), self.swing_period_s)
    }

    fn sensor(&self) -> Option<&dyn Sensor> {
        Some(self)
    }

    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]) {
        let sensor = &rows
            .temps
            .iter()
            .find(|c| c.name == self.channel)
            .expect("the simulator records every effect's sensor")
            .temp_c;
        let structure = if self.lag_s > 0.0 {
            lagged(sensor, rows.t_s, Some(rows.session), self.lag_s)
        } else {
            sensor.clone()
        };
        for (r, s) in structure.iter().enumerate() {
            let arm_mm = self.times.map_or(0.0, |a| rows.pos_mm[a][r]);
            let dt = s - self.t_ref_c;
            truth[self.target][r] += dt * (self.cte_um_per_m_k * 1e-3 * arm_mm + self.offset_um_per_k);
        }
    }
}

impl fmt::Display for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "thermal:channel={},target={},times={},cte_um_per_m_k={},offset_um_per_k={},t_ref_c={},start_c={},rise_c={},tau_s={},lag_s={},swing_c={},swing_period_s={}",
            self.channel,
            TARGETS[self.target],
            self.times.map_or("none", |a| AXES[a]),
            self.cte_um_per_m_k,
            self.offset_um_per_k,
            self.t_ref_c,
            self.start_c,
            self.rise_c,
            self.tau_s,
            self.lag_s,
            self.swing_c,
            self.swing_period_s
        )
    }
}
