//! Physical effects as types: the `fit --add` grammar
//! (`<family>:<key>=<value>,…`, docs/cli.md § fit) parsed once into
//! [`EffectSpec`] — [`Family`], [`Target`], [`Axis`], channel, `times` and
//! the remaining parameters — and into the model columns an [`Effect`]
//! adds. Strings exist only at the edges (the command line, MODEL.json's
//! `adds`, diagnose's `add`); their canonical form is the pairs as written,
//! trimmed, in the order given, so `Display` gives back exactly the string
//! `fit` records.

use std::fmt;
use std::str::FromStr;

use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::data::{AXES, TARGETS};
use crate::features::{Feature, Phase};

/// A family of physical effects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Periodic lead error of a screw (or a scale's pitch) along an axis.
    Periodic,
    /// Thermal growth following a temperature channel.
    Thermal,
    /// Reversal error (backlash) of an axis.
    Reversal,
    /// Abbe error through the tool length.
    Abbe,
    /// Drift with time.
    Drift,
    /// Out-of-squareness: a linear cross term.
    Squareness,
    /// Polynomial terms of degree 4–5 along one axis.
    HigherOrder,
}

impl Family {
    /// Every family, in the order the docs list them.
    pub const ALL: [Family; 7] = [
        Family::Periodic,
        Family::Thermal,
        Family::Reversal,
        Family::Abbe,
        Family::Drift,
        Family::Squareness,
        Family::HigherOrder,
    ];

    /// The name in `--add` strings and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Family::Periodic => "periodic",
            Family::Thermal => "thermal",
            Family::Reversal => "reversal",
            Family::Abbe => "abbe",
            Family::Drift => "drift",
            Family::Squareness => "squareness",
            Family::HigherOrder => "higher_order",
        }
    }

    /// The keys an `--add` string of this family may have.
    pub fn keys(self) -> &'static [&'static str] {
        match self {
            Family::Periodic => &["target", "axis", "period_mm", "harmonics"],
            Family::Thermal => &["target", "channel", "times", "offset", "lag_s", "t_ref_c"],
            Family::Reversal | Family::Squareness => &["target", "axis"],
            Family::Abbe => &["target", "times"],
            Family::Drift => &["target", "order"],
            Family::HigherOrder => &["target", "axis", "degree"],
        }
    }
}

impl FromStr for Family {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Family> {
        Family::ALL.into_iter().find(|f| f.as_str() == s).ok_or_else(|| {
            anyhow!(
                "unknown effect family `{s}` (expected periodic, thermal, reversal, abbe, drift, squareness or higher_order)"
            )
        })
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl PartialEq<&str> for Family {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

/// A closed set of names indexing the data set's x/y/z columns (axes and
/// targets): `ALL`, the column index both ways, the name, `FromStr` and
/// `Display`.
macro_rules! column_enum {
    ($(#[$doc:meta])* $name:ident, $names:expr, $expected:literal, [$($(#[$vdoc:meta])* $v:ident),+]) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $name {
            $($(#[$vdoc])* $v),+
        }

        impl $name {
            /// Every value, in column order.
            pub const ALL: [$name; 3] = [$($name::$v),+];

            /// The index into the data set's columns (0, 1, 2).
            pub fn index(self) -> usize {
                self as usize
            }

            /// The value of column index `i` (0..3).
            pub fn from_index(i: usize) -> Option<$name> {
                $name::ALL.get(i).copied()
            }

            /// The name in CSV columns, `--add` strings and JSON.
            pub fn name(self) -> &'static str {
                $names[self.index()]
            }
        }

        impl FromStr for $name {
            type Err = anyhow::Error;

            fn from_str(s: &str) -> Result<$name> {
                $name::ALL
                    .into_iter()
                    .find(|a| a.name() == s)
                    .ok_or_else(|| anyhow!(concat!("`{}`: expected ", $expected), s))
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

column_enum!(
    /// A machine axis.
    Axis,
    AXES,
    "x, y or z",
    [
        /// x.
        X,
        /// y.
        Y,
        /// z.
        Z
    ]
);

column_enum!(
    /// An error component the model corrects: the error along x, y or z.
    Target,
    TARGETS,
    "ex, ey or ez",
    [
        /// Error along x.
        Ex,
        /// Error along y.
        Ey,
        /// Error along z.
        Ez
    ]
);

/// A valid `fit --add` string, typed: what an effect is (its family, the
/// target it corrects, the axis, channel and `times` it follows) and its
/// parameters as written.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectSpec {
    /// The family.
    pub family: Family,
    /// The target the effect's columns are added to.
    pub target: Target,
    /// `axis=` (periodic, reversal, squareness, higher_order).
    pub axis: Option<Axis>,
    /// `channel=` (thermal): the temperature channel's name.
    pub channel: Option<String>,
    /// `times=` (thermal, abbe): the axis the effect grows along.
    pub times: Option<Axis>,
    /// Every `key=value` pair as written (trimmed), in the order given —
    /// the typed fields' keys included, so `Display` writes the string back.
    pub params: Vec<(String, String)>,
}

impl EffectSpec {
    /// The value written for `key`, if any.
    pub fn param(&self, key: &str) -> Option<&str> {
        self.params
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// `period_mm=` as a number (periodic).
    pub fn period_mm(&self) -> Option<f64> {
        self.param("period_mm").and_then(|v| v.parse().ok())
    }

    /// The same effect up to its nonlinear parameter (lag, order, degree,
    /// harmonics): family, target, axis, channel and `times` equal, and
    /// periods, where both have one, within 10 % (a lead re-found more
    /// exactly; farther apart they are two effects, a screw lead and a
    /// scale pitch).
    pub fn same_effect(&self, o: &EffectSpec) -> bool {
        let period_ok = match (self.period_mm(), o.period_mm()) {
            (Some(a), Some(b)) => (a / b - 1.0).abs() <= 0.1,
            _ => true,
        };
        self.family == o.family
            && self.target == o.target
            && self.axis == o.axis
            && self.channel == o.channel
            && self.times == o.times
            && period_ok
    }

    /// Whether an effect of `family` along `axis`, following `channel`,
    /// times `times` could be this one (on any target, with any parameter).
    pub fn admits(
        &self,
        family: Family,
        axis: Option<Axis>,
        channel: Option<&str>,
        times: Option<Axis>,
    ) -> bool {
        self.family == family
            && self.axis == axis
            && self.channel.as_deref() == channel
            && self.times == times
    }
}

impl FromStr for EffectSpec {
    type Err = anyhow::Error;

    /// Parses and checks an `--add` string, with `Effect::parse`'s errors
    /// (the one parse: [`Effect::parse`] gives the columns as well).
    fn from_str(s: &str) -> Result<EffectSpec> {
        Effect::parse_both(s).map(|(_, spec)| spec)
    }
}

impl fmt::Display for EffectSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.family)?;
        for (i, (k, v)) in self.params.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

/// Whether two `fit --add` strings are the same effect up to its nonlinear
/// parameter ([`EffectSpec::same_effect`]); false when either does not
/// parse. The second then replaces the first rather than adding to it.
pub fn same_effect(a: &str, b: &str) -> bool {
    match (a.parse::<EffectSpec>(), b.parse::<EffectSpec>()) {
        (Ok(x), Ok(y)) => x.same_effect(&y),
        _ => false,
    }
}

/// A physical effect added to a model with `fit --add`, in the syntax
/// `<family>:<key>=<value>,…` that `diagnose` prints in its `add` field.
///
/// | family | keys | columns added to `target` |
/// | --- | --- | --- |
/// | `periodic` | target, axis, period_mm, harmonics (1..4, default 1) | sin, cos(2πk·p/period), k = 1..harmonics |
/// | `thermal` | target, channel (or several joined by `+`), [times=x\|y\|z], [offset=0\|1], [lag_s, one per channel joined by `+`, or one for all], [t_ref_c] | per channel ΔT, or ΔT·u_axis (and ΔT with offset=1: expansion about an unknown fixed point) |
/// | `reversal` | target, axis | dir_axis |
/// | `abbe` | target, [times=x\|y\|z] | tool_mm, or tool_mm·u_axis |
/// | `drift` | target, [order=1..3] | (t/1 h)^p, p = 1..order |
/// | `squareness` | target, axis | u_axis (linear cross term) |
/// | `higher_order` | target, axis, degree (4..5) | u_axis^4 … u_axis^degree |
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Effect {
    /// The family (`periodic`, `thermal`, …).
    pub family: Family,
    /// Target index (0 = ex).
    pub target: usize,
    /// The columns this effect adds to the target.
    pub features: Vec<Feature>,
    /// The string it was parsed from (canonical form).
    pub spec: String,
}

/// Temperature reference used when an effect does not name one, °C (the
/// ISO 1 reference temperature for dimensional metrology).
pub const T_REF_C: f64 = 20.0;

fn parse_axis(v: &str, key: &str) -> Result<usize> {
    AXES.iter()
        .position(|a| *a == v)
        .ok_or_else(|| anyhow!("`{key}={v}`: expected x, y or z"))
}

fn parse_f64(v: &str, key: &str) -> Result<f64> {
    let x: f64 = v
        .parse()
        .map_err(|_| anyhow!("`{key}={v}`: expected a number"))?;
    if !x.is_finite() {
        bail!("`{key}={v}`: expected a finite number");
    }
    Ok(x)
}

fn parse_u8(v: &str, key: &str, lo: u8, hi: u8) -> Result<u8> {
    let x: u8 = v
        .parse()
        .map_err(|_| anyhow!("`{key}={v}`: expected an integer {lo}..={hi}"))?;
    if !(lo..=hi).contains(&x) {
        bail!("`{key}={v}`: expected an integer {lo}..={hi}");
    }
    Ok(x)
}

/// The grammar of an `--add` string, `<family>:<key>=<value>,…`, split into
/// its family and trimmed key/value pairs (a key given twice is an error).
/// `Effect::parse` gives the pairs their meaning; `diagnose` compares
/// effects by them.
pub fn split_spec(s: &str) -> Result<(&str, Vec<(&str, &str)>)> {
    let (family, rest) = s.split_once(':').ok_or_else(|| {
        anyhow!("expected `<family>:<key>=<value>,…`, e.g. `periodic:target=ey,axis=y,period_mm=5`")
    })?;
    let mut kv: Vec<(&str, &str)> = Vec::new();
    for part in rest.split(',').filter(|p| !p.is_empty()) {
        let (k, v) = part
            .split_once('=')
            .ok_or_else(|| anyhow!("`{part}`: expected key=value"))?;
        if kv.iter().any(|(k2, _)| *k2 == k.trim()) {
            bail!("key `{}` given twice", k.trim());
        }
        kv.push((k.trim(), v.trim()));
    }
    Ok((family, kv))
}

impl Effect {
    /// Parses `--add` syntax. Errors say which key is missing or malformed
    /// and what was expected.
    pub fn parse(s: &str) -> Result<Effect> {
        Self::parse_both(s).map(|(e, _)| e)
    }

    /// The effect and its typed spec from one parse.
    fn parse_both(s: &str) -> Result<(Effect, EffectSpec)> {
        Self::parse_inner(s).with_context(|| format!("bad effect `{s}`"))
    }

    fn parse_inner(s: &str) -> Result<(Effect, EffectSpec)> {
        let (family, kv) = split_spec(s)?;
        let get = |key: &str| kv.iter().find(|(k, _)| *k == key).map(|(_, v)| *v);
        let need = |key: &str| get(key).ok_or_else(|| anyhow!("missing `{key}=`"));
        let family: Family = family.parse()?;
        let allowed = family.keys();
        if let Some((k, _)) = kv.iter().find(|(k, _)| !allowed.contains(k)) {
            bail!(
                "unknown key `{k}` for `{family}` (expected {})",
                allowed.join(", ")
            );
        }
        let target = {
            let v = need("target")?;
            TARGETS
                .iter()
                .position(|t| *t == v)
                .ok_or_else(|| anyhow!("`target={v}`: expected ex, ey or ez"))?
        };
        let times = |key: &str| -> Result<[u8; 3]> {
            let mut e = [0; 3];
            if let Some(v) = get(key) {
                e[parse_axis(v, key)?] = 1;
            }
            Ok(e)
        };
        let features = match family {
            Family::Periodic => {
                let axis = parse_axis(need("axis")?, "axis")?;
                let period_mm = parse_f64(need("period_mm")?, "period_mm")?;
                if period_mm <= 0.0 {
                    bail!("`period_mm={period_mm}`: expected a positive period");
                }
                let harmonics =
                    get("harmonics").map_or(Ok(1), |v| parse_u8(v, "harmonics", 1, 4))?;
                (1..=harmonics)
                    .flat_map(|k| {
                        [Phase::Sin, Phase::Cos].map(|phase| Feature::Periodic {
                            axis,
                            period_mm,
                            harmonic: k,
                            phase,
                        })
                    })
                    .collect()
            }
            Family::Thermal => {
                // Several sensors in one effect (`channel=housing+column`,
                // `lag_s=600+0`, one lag per channel or one for all): a
                // multi-sensor thermal model, when no one sensor follows the
                // structure's growth.
                let channels: Vec<String> = need("channel")?
                    .split('+')
                    .map(|c| c.trim().to_string())
                    .collect();
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
                let lags: Vec<f64> = match get("lag_s") {
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
                if let Some(l) = lags.iter().find(|l| **l < 0.0) {
                    bail!("`lag_s={l}`: expected ≥ 0");
                }
                let t_ref_c = get("t_ref_c").map_or(Ok(T_REF_C), |v| parse_f64(v, "t_ref_c"))?;
                let exp = times("times")?;
                // A screw or scale expands about its fixed end, which is
                // rarely the travel's centre: `offset=1` adds the plain ΔT
                // column so that the fixed point is fitted too.
                let offset = get("offset").map_or(Ok(0), |v| parse_u8(v, "offset", 0, 1))?;
                let mut f = Vec::new();
                for (channel, &lag_s) in channels.into_iter().zip(&lags) {
                    f.push(Feature::Thermal {
                        channel: channel.clone(),
                        t_ref_c,
                        lag_s,
                        exp,
                    });
                    if offset == 1 && exp != [0, 0, 0] {
                        f.push(Feature::Thermal {
                            channel,
                            t_ref_c,
                            lag_s,
                            exp: [0, 0, 0],
                        });
                    }
                }
                f
            }
            Family::Reversal => vec![Feature::Reversal {
                axis: parse_axis(need("axis")?, "axis")?,
            }],
            Family::Abbe => vec![Feature::Abbe {
                exp: times("times")?,
            }],
            Family::Drift => {
                let order = get("order").map_or(Ok(1), |v| parse_u8(v, "order", 1, 3))?;
                (1..=order).map(|power| Feature::Drift { power }).collect()
            }
            Family::Squareness => {
                let axis = parse_axis(need("axis")?, "axis")?;
                if axis == target {
                    bail!("squareness of {} against itself: `axis` must differ from the target's axis", AXES[axis]);
                }
                let mut exp = [0; 3];
                exp[axis] = 1;
                vec![Feature::Monomial { exp }]
            }
            Family::HigherOrder => {
                let axis = parse_axis(need("axis")?, "axis")?;
                let degree = parse_u8(need("degree")?, "degree", 4, 5)?;
                (4..=degree)
                    .map(|p| {
                        let mut exp = [0; 3];
                        exp[axis] = p;
                        Feature::Monomial { exp }
                    })
                    .collect()
            }
        };
        // Every value is checked above: the typed fields parse.
        let axis_of = |key: &str| get(key).map(Axis::from_str).transpose();
        let typed = EffectSpec {
            family,
            target: Target::from_index(target).context("target index")?,
            axis: axis_of("axis")?,
            channel: get("channel").map(str::to_string),
            times: axis_of("times")?,
            params: kv
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        };
        let effect = Effect {
            family,
            target,
            features,
            spec: typed.to_string(),
        };
        Ok((effect, typed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thermal_effect_may_follow_several_channels() {
        let e = Effect::parse("thermal:target=ez,channel=housing+column,lag_s=600+0").unwrap();
        assert_eq!(
            e.spec,
            "thermal:target=ez,channel=housing+column,lag_s=600+0"
        );
        let ch: Vec<(String, f64)> = e
            .features
            .iter()
            .map(|f| match f {
                Feature::Thermal { channel, lag_s, .. } => (channel.clone(), *lag_s),
                _ => panic!("{f:?}"),
            })
            .collect();
        assert_eq!(ch, vec![("housing".into(), 600.0), ("column".into(), 0.0)]);
        let e = Effect::parse("thermal:target=ex,channel=a+b,times=x,offset=1,lag_s=60").unwrap();
        assert_eq!(e.features.len(), 4);
        for bad in [
            "thermal:target=ez,channel=a+b,lag_s=1+2+3",
            "thermal:target=ez,channel=a+a",
            "thermal:target=ez,channel=a+",
            "thermal:target=ez,channel=a+b,lag_s=1+-2",
        ] {
            assert!(Effect::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn effect_parsing() {
        let e = Effect::parse("periodic:target=ey,axis=y,period_mm=5.08,harmonics=2").unwrap();
        assert_eq!(e.target, 1);
        assert_eq!(e.features.len(), 4);
        assert_eq!(
            e.features[2],
            Feature::Periodic {
                axis: 1,
                period_mm: 5.08,
                harmonic: 2,
                phase: Phase::Sin
            }
        );
        let e = Effect::parse("thermal:target=ex,channel=bed,times=x").unwrap();
        assert_eq!(
            e.features,
            vec![Feature::Thermal {
                channel: "bed".into(),
                t_ref_c: 20.0,
                lag_s: 0.0,
                exp: [1, 0, 0]
            }]
        );
        assert_eq!(Effect::parse(&e.spec).unwrap(), e);
        for bad in [
            "periodic",
            "periodic:target=ey,axis=q,period_mm=5",
            "periodic:target=ey,axis=y",
            "periodic:target=ey,axis=y,period_mm=-1",
            "periodic:target=ey,axis=y,period_mm=5,harmonics=9",
            "wobble:target=ex",
            "reversal:target=ex,axis=x,extra=1",
            "squareness:target=ex,axis=x",
            "drift:target=ex,target=ey",
        ] {
            let err = format!("{:#}", Effect::parse(bad).unwrap_err());
            assert!(err.contains(bad), "{err}");
        }
    }

    #[test]
    fn specs_keep_the_string_as_written_and_type_its_parts() {
        for s in [
            "periodic:target=ey,axis=y,period_mm=5.08,harmonics=2",
            "thermal:target=ex,times=x,channel=bed,lag_s=600",
            "abbe:target=ez",
            "higher_order:target=ex,axis=y,degree=5",
        ] {
            let spec: EffectSpec = s.parse().unwrap();
            assert_eq!(spec.to_string(), s);
        }
        let t: EffectSpec = "thermal:target=ex, channel = bed ,times=x".parse().unwrap();
        assert_eq!(t.family, Family::Thermal);
        assert_eq!(t.target, Target::Ex);
        assert_eq!(t.channel.as_deref(), Some("bed"));
        assert_eq!(t.times, Some(Axis::X));
        assert_eq!(t.axis, None);
        assert_eq!(t.to_string(), "thermal:target=ex,channel=bed,times=x");
        let e = "wobble:target=ex".parse::<EffectSpec>().unwrap_err();
        assert!(
            format!("{e:#}").contains("unknown effect family `wobble`"),
            "{e:#}"
        );
        assert_eq!(
            "higher_order".parse::<Family>().unwrap(),
            Family::HigherOrder
        );
        assert_eq!(Family::HigherOrder.to_string(), "higher_order");
        assert_eq!("y".parse::<Axis>().unwrap().index(), 1);
        assert_eq!(Target::from_index(2), Some(Target::Ez));
        assert_eq!(Target::from_index(3), None);
        let e = "q".parse::<Axis>().unwrap_err().to_string();
        assert_eq!(e, "`q`: expected x, y or z");
        assert_eq!("ez".parse::<Target>().unwrap().to_string(), "ez");
    }

    #[test]
    fn same_effect_reads_specs_with_effect_parse_grammar() {
        // Spaces around keys and values, key order: the same effect.
        assert!(same_effect(
            "thermal:target=ex,channel=bed,lag_s=3600",
            "thermal: lag_s = 600 , channel=bed,target=ex"
        ));
        // Another channel, target or `times`: another effect.
        assert!(!same_effect(
            "thermal:target=ex,channel=bed,lag_s=0",
            "thermal:target=ex,channel=spindle,lag_s=0"
        ));
        assert!(same_effect(
            "thermal:target=ex,channel=bed,times=x,lag_s=600",
            "thermal:target=ex,times=x,channel=bed"
        ));
        assert!(!same_effect("abbe:target=ex,times=y", "abbe:target=ex"));
        // Periods within 10 % are one lead re-found; farther, two effects.
        let p = |mm: &str| format!("periodic:target=ey,axis=y,period_mm={mm}");
        assert!(same_effect(&p("5"), &p("5.4")));
        assert!(!same_effect(&p("5"), &p("10")));
        // What Effect::parse refuses is nobody's duplicate.
        let twice = "reversal:target=ex,axis=x,axis=y";
        assert!(Effect::parse(twice).is_err());
        assert!(!same_effect(twice, "reversal:target=ex,axis=x"));
        assert!(!same_effect("reversal", "reversal"));
    }
}
