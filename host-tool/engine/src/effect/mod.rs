//! Physical effects as types, one room per family. An effect is written
//! `<family>:<key>=<value>,…` (`fit --add`, diagnose's `add`, MODEL.json's
//! `adds`; docs/cli.md § fit) and parsed once here into an [`EffectSpec`]:
//! its [`Target`] and its family's typed parameters ([`Params`]). Strings
//! exist only at the edges; an `EffectSpec` keeps the pairs as written
//! (trimmed, in the order given), so `Display` gives back exactly the
//! string `fit` records, and one the search builds from types is written
//! in the canonical order its family gives.
//!
//! Each family is one file here, holding everything the family *is*: its
//! keys and their parse (typed parameters → the model columns, [`Feature`]s,
//! it adds), the words that explain it ([`EffectSpec::describe`], the one
//! text both reports use), its physical parameter (name, unit, plausible
//! range, how diagnose reads it off the fit: [`PhysicalParam`]), what
//! diagnose's warnings say about it ([`Info`]), and its simulated form
//! (`simulate --effect <family>:…`, [`sim::SimForm`]). The registry at the
//! end of this file — one line per family — makes the [`Family`] enum and
//! the dispatch from it. How the diagnosis *searches* for a family is its
//! file in `diagnose/search/`. Adding a family: docs/host.md § Adding an
//! effect family.
//!
//! The one `key=value` grammar of the tool's specs is [`Pairs`] (`pairs.rs`:
//! the `--add` strings, simulate's `--effect` and `--plan`); what the
//! simulator asks of a family's simulated form is `sim.rs`.

mod pairs;
pub mod sim;

use std::fmt;
use std::str::FromStr;

use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;

use crate::data::{AXES, TARGETS};
use crate::features::Feature;

pub use pairs::{parse_axis, parse_f64, Pairs};
pub use sim::{Limit, SimForm, SimRows};

/// Temperature reference used when an effect does not name one, °C (the
/// ISO 1 reference temperature for dimensional metrology).
pub const T_REF_C: f64 = 20.0;

/// What is known of a family without an effect of it: its name and keys,
/// and what the diagnosis says of every effect of it.
#[derive(Clone, Copy, Debug)]
pub struct Info {
    /// The name in `--add` strings and JSON.
    pub name: &'static str,
    /// The keys an `--add` string of the family may have.
    pub keys: &'static [&'static str],
    /// What to check when the diagnosis accepts an effect of the family
    /// whose physical parameter is implausible (`implausible_parameter`).
    pub check: &'static str,
    /// How to tell it from a seed that already contains its columns
    /// (appended to `in_model_span`; empty for nothing to add).
    pub in_span_hint: &'static str,
    /// Judged by predicting later data from earlier (forward chaining)
    /// rather than by the block hold-out: the error follows time.
    pub time_dependent: bool,
    /// A wave along an axis that a coarse sampling cannot tell from a
    /// lead's alias (`diagnose::aliasing`).
    pub aliasable: bool,
    /// Its simulated form: parses the pairs of `simulate --effect
    /// <name>:…`; None for a family the simulator does not make (the
    /// machine's squareness, a seed's missing degree).
    pub simulate: Option<SimParse>,
}

/// Parses the pairs of `simulate --effect <family>:…` into the family's
/// simulated form.
pub type SimParse = fn(&Pairs) -> Result<Box<dyn SimForm>>;

impl Info {
    /// A family named `name` with `keys`, `check` its words for an
    /// implausible parameter; judged by the block hold-out, no wave, not
    /// simulated — the methods below say otherwise.
    pub const fn new(
        name: &'static str,
        keys: &'static [&'static str],
        check: &'static str,
    ) -> Info {
        Info {
            name,
            keys,
            check,
            in_span_hint: "",
            time_dependent: false,
            aliasable: false,
            simulate: None,
        }
    }

    /// With `hint` appended to its `in_model_span` warning.
    pub const fn in_span_hint(mut self, hint: &'static str) -> Info {
        self.in_span_hint = hint;
        self
    }

    /// Judged by forward chaining: the error follows time.
    pub const fn time_dependent(mut self) -> Info {
        self.time_dependent = true;
        self
    }

    /// A wave along an axis that a coarse sampling can alias.
    pub const fn aliasable(mut self) -> Info {
        self.aliasable = true;
        self
    }

    /// Simulated: `parse` reads `simulate --effect <name>:…`.
    pub const fn simulated(mut self, parse: SimParse) -> Info {
        self.simulate = Some(parse);
        self
    }
}

/// What makes a type a family: its [`Info`] and how an effect of it is
/// read from the pairs of an `--add` string (its keys already checked
/// against [`Info::keys`]; `target` parsed).
pub trait FamilyDef: EffectParams + Clone + PartialEq + Sized + 'static {
    /// The family's name, keys and diagnosis rules.
    const INFO: Info;
    /// The typed parameters, with the errors a user reads (`bad effect …`
    /// is added by the caller).
    fn parse(kv: &Pairs, target: Target) -> Result<Self>;
}

/// What an effect of a family is, from its typed parameters (object safe:
/// [`Params`] dispatches to it).
pub trait EffectParams: fmt::Debug + Send + Sync {
    /// The columns the effect adds to `target`.
    fn features(&self, target: Target) -> Vec<Feature>;
    /// Its pairs after `target=`, in the canonical order, each value as
    /// written back (a spec built by the search is written this way).
    fn pairs(&self) -> Vec<(&'static str, String)>;
    /// The `axis` it runs along, if any.
    fn axis(&self) -> Option<Axis> {
        None
    }
    /// The temperature channel(s) it follows, as written (`bed`,
    /// `housing+column`), if any.
    fn channel(&self) -> Option<&str> {
        None
    }
    /// The axis it grows along (`times=`), if any.
    fn times(&self) -> Option<Axis> {
        None
    }
    /// Its period, mm (periodic): two periods within 10 % are one lead.
    fn period_mm(&self) -> Option<f64> {
        None
    }
    /// The data column(s) it follows (`T_bed_C`, `dir_x`, `tool_mm`,
    /// `t_s`), for a candidate's `channel`.
    fn follows(&self) -> Option<String> {
        None
    }
    /// The effect in words, `target` being its target's name: "a
    /// periodic error of ey along y (lead screw or scale pitch)".
    fn describe(&self, target: &str) -> String;
    /// Its searched parameters (period, harmonics, lag, order, degree),
    /// for a candidate's `params`.
    fn searched_params(&self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// Its physical parameter, and how diagnose reads it off the fit.
    fn physical(&self) -> Option<PhysicalParam>;
}

/// A family's physical parameter: what it is called, its unit, the range
/// taken as plausible in words, and how diagnose reads it off the fitted
/// coefficients ([`Reading`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PhysicalParam {
    /// `cte`, `backlash`, `amplitude`, …
    pub name: &'static str,
    /// Its unit.
    pub unit: &'static str,
    /// The plausible range, in words.
    pub expected: &'static str,
    /// How its value comes from the fit.
    pub reading: Reading,
}

/// How a physical parameter comes from the effect's fitted coefficients β.
#[derive(Clone, Debug, PartialEq)]
pub enum Reading {
    /// β₀ × scale; plausible while |value| ≤ `max_abs`.
    Linear {
        /// The factor from the coefficient to the parameter.
        scale: Scale,
        /// The largest plausible magnitude.
        max_abs: f64,
    },
    /// √(β₀² + β₁²) of a sine/cosine pair, µm; plausible with the period in
    /// `periods_mm` and the amplitude ≤ `max_um`.
    Amplitude {
        /// The effect's period, mm.
        period_mm: f64,
        /// Plausible periods, mm (inclusive).
        periods_mm: [f64; 2],
        /// Largest plausible amplitude, µm.
        max_um: f64,
    },
    /// The mean rate of Σ β_p·(t/1 h)^p over the session's time span, µm/h;
    /// plausible while its magnitude ≤ `max_abs` (none without `t_s`).
    MeanRate {
        /// The largest plausible magnitude.
        max_abs: f64,
    },
    /// The RMS of the fitted component over the rows, µm; any value.
    ComponentRms,
}

/// The factor from a coefficient to a physical parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// A constant factor.
    Fixed(f64),
    /// Per metre of the axis' travel: 1000 / (half the data's span along
    /// the axis, mm) — the coefficient multiplies the normalised position.
    PerMetreAlong(Axis),
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

/// The monomial exponents of one axis to the power `p` ([0, 0, 0] for
/// none): the `exp` of a feature that grows along `axis`.
pub fn exp_along(axis: Option<Axis>, p: u8) -> [u8; 3] {
    let mut e = [0; 3];
    if let Some(a) = axis {
        e[a.index()] = p;
    }
    e
}

/// ` along y` for an axis, empty for none: the words' common tail.
pub fn along_words(axis: Option<Axis>) -> String {
    axis.map_or(String::new(), |a| format!(" along {a}"))
}

/// `a, b or c`.
fn or_list(names: &[&str]) -> String {
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => names.join(""),
    }
}

/// A valid `fit --add` string, typed: the target it corrects and its
/// family's parameters, with the pairs as written.
#[derive(Clone, Debug)]
pub struct EffectSpec {
    target: Target,
    params: Params,
    /// Every `key=value` pair as written (trimmed), in the order given —
    /// `target` included — so that `Display` writes the string back.
    written: Vec<(String, String)>,
}

impl EffectSpec {
    /// An effect on `target` with `params`, written in its family's
    /// canonical order (`target` first).
    pub fn new(target: Target, params: impl Into<Params>) -> EffectSpec {
        let params = params.into();
        let mut written = vec![("target".to_string(), target.name().to_string())];
        written.extend(
            params
                .get()
                .pairs()
                .into_iter()
                .map(|(k, v)| (k.to_string(), v)),
        );
        EffectSpec {
            target,
            params,
            written,
        }
    }

    /// The family.
    pub fn family(&self) -> Family {
        self.params.family()
    }

    /// The target the effect's columns are added to.
    pub fn target(&self) -> Target {
        self.target
    }

    /// The family's typed parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// `axis=` (periodic, reversal, squareness, higher_order).
    pub fn axis(&self) -> Option<Axis> {
        self.params.get().axis()
    }

    /// `channel=` (thermal) as written.
    pub fn channel(&self) -> Option<&str> {
        self.params.get().channel()
    }

    /// `times=` (thermal, abbe): the axis the effect grows along.
    pub fn times(&self) -> Option<Axis> {
        self.params.get().times()
    }

    /// The axis the effect runs or grows along (`axis`, else `times`): a
    /// candidate's `axis`.
    pub fn along(&self) -> Option<Axis> {
        self.axis().or(self.times())
    }

    /// `period_mm=` (periodic).
    pub fn period_mm(&self) -> Option<f64> {
        self.params.get().period_mm()
    }

    /// The data column(s) it follows (`T_bed_C`, `dir_x`, `tool_mm`, `t_s`).
    pub fn follows(&self) -> Option<String> {
        self.params.get().follows()
    }

    /// The value written for `key`, if any.
    pub fn param(&self, key: &str) -> Option<&str> {
        self.written
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The columns it adds to its target.
    pub fn features(&self) -> Vec<Feature> {
        self.params.get().features(self.target)
    }

    /// The effect in words (both reports and `improve` say it so): "a
    /// periodic error of ey along y (lead screw or scale pitch)".
    pub fn describe(&self) -> String {
        self.params.get().describe(self.target.name())
    }

    /// Its searched parameters (period, harmonics, lag, order, degree).
    pub fn searched_params(&self) -> Vec<(&'static str, f64)> {
        self.params.get().searched_params()
    }

    /// Its physical parameter and how it is read off the fit.
    pub fn physical(&self) -> Option<PhysicalParam> {
        self.params.get().physical()
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
        self.family() == o.family()
            && self.target == o.target
            && self.axis() == o.axis()
            && self.channel() == o.channel()
            && self.times() == o.times()
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
        self.family() == family
            && self.axis() == axis
            && self.channel() == channel
            && self.times() == times
    }
}

/// Two specs are equal when their strings are (the canonical forms).
impl PartialEq for EffectSpec {
    fn eq(&self, o: &EffectSpec) -> bool {
        self.family() == o.family() && self.written == o.written
    }
}

impl FromStr for EffectSpec {
    type Err = anyhow::Error;

    /// Parses and checks an `--add` string. Errors say which key is
    /// missing or malformed and what was expected.
    fn from_str(s: &str) -> Result<EffectSpec> {
        parse_spec(s).with_context(|| format!("bad effect `{s}`"))
    }
}

fn parse_spec(s: &str) -> Result<EffectSpec> {
    let (family, kv) = Pairs::of_effect(
        s,
        "expected `<family>:<key>=<value>,…`, e.g. `periodic:target=ey,axis=y,period_mm=5`",
    )?;
    let family: Family = family.parse()?;
    let allowed = family.info().keys;
    if let Some(k) = kv.keys().find(|k| !allowed.contains(k)) {
        bail!(
            "unknown key `{k}` for `{family}` (expected {})",
            allowed.join(", ")
        );
    }
    let target = kv.target()?.ok_or_else(|| anyhow!("missing `target=`"))?;
    let params = family.parse_params(&kv, target)?;
    Ok(EffectSpec {
        target,
        params,
        written: kv.written(),
    })
}

impl fmt::Display for EffectSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.family())?;
        for (i, (k, v)) in self.written.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

/// A physical effect added to a model with `fit --add`: its spec and the
/// columns it adds to its target (docs/cli.md § fit lists each family's
/// keys and columns; each family's file here says how).
#[derive(Clone, Debug, PartialEq)]
pub struct Effect {
    /// What it is.
    pub spec: EffectSpec,
    /// The columns this effect adds to the target.
    pub features: Vec<Feature>,
}

impl Effect {
    /// The effect of `spec`, its columns made.
    pub fn new(spec: EffectSpec) -> Effect {
        let features = spec.features();
        Effect { spec, features }
    }

    /// Parses `--add` syntax ([`EffectSpec::from_str`]).
    pub fn parse(s: &str) -> Result<Effect> {
        s.parse().map(Effect::new)
    }

    /// Target index (0 = ex).
    pub fn target(&self) -> usize {
        self.spec.target.index()
    }
}

impl From<EffectSpec> for Effect {
    fn from(spec: EffectSpec) -> Effect {
        Effect::new(spec)
    }
}

/// The registry: one line per family, `module::Type` (the type
/// implements [`FamilyDef`]). Makes the `mod` of each family's file, the
/// [`Family`] enum (in this order: the docs' and the error messages'),
/// [`Params`] (the typed parameters of any family) and the dispatch from
/// both to the family's code.
macro_rules! families {
    ($($module:ident :: $Kind:ident),+ $(,)?) => {
        $(pub mod $module;)+

        /// A family of physical effects (one file of `effect/` each).
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Family {
            $(
                #[doc = concat!("`", stringify!($module), "`: see [`", stringify!($module), "`].")]
                $Kind
            ),+
        }

        impl Family {
            /// Every family, in the order the docs list them.
            pub const ALL: [Family; [$(stringify!($Kind)),+].len()] = [$(Family::$Kind),+];

            /// Its name, keys and diagnosis rules.
            pub fn info(self) -> &'static Info {
                match self {
                    $(Family::$Kind => &<$module::$Kind as FamilyDef>::INFO),+
                }
            }

            fn parse_params(self, kv: &Pairs, target: Target) -> Result<Params> {
                match self {
                    $(Family::$Kind => <$module::$Kind as FamilyDef>::parse(kv, target).map(Params::$Kind)),+
                }
            }
        }

        /// The typed parameters of an effect, by family.
        #[derive(Clone, Debug, PartialEq)]
        pub enum Params {
            $(
                #[doc = concat!("[`", stringify!($module), "::", stringify!($Kind), "`].")]
                $Kind($module::$Kind)
            ),+
        }

        impl Params {
            /// The family.
            pub fn family(&self) -> Family {
                match self {
                    $(Params::$Kind(_) => Family::$Kind),+
                }
            }

            fn get(&self) -> &dyn EffectParams {
                match self {
                    $(Params::$Kind(p) => p),+
                }
            }
        }

        $(
            impl From<$module::$Kind> for Params {
                fn from(p: $module::$Kind) -> Params {
                    Params::$Kind(p)
                }
            }
        )+
    };
}

families! {
    periodic::Periodic,
    thermal::Thermal,
    reversal::Reversal,
    abbe::Abbe,
    drift::Drift,
    squareness::Squareness,
    higher_order::HigherOrder,
}

impl Family {
    /// The name in `--add` strings and JSON.
    pub fn as_str(self) -> &'static str {
        self.info().name
    }

    /// The keys an `--add` string of this family may have.
    pub fn keys(self) -> &'static [&'static str] {
        self.info().keys
    }

    /// Every family's name, `a, b or c` (for messages).
    pub fn names() -> String {
        let names: Vec<&str> = Family::ALL.iter().map(|f| f.as_str()).collect();
        or_list(&names)
    }

    /// The families with a simulated form, and `extra` after them, `a, b
    /// or c` (simulate's message for an unknown effect).
    pub fn simulated_names(extra: &[&str]) -> String {
        let mut names: Vec<&str> = Family::ALL
            .iter()
            .filter(|f| f.info().simulate.is_some())
            .map(|f| f.as_str())
            .collect();
        names.extend_from_slice(extra);
        or_list(&names)
    }
}

impl FromStr for Family {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Family> {
        Family::ALL
            .into_iter()
            .find(|f| f.as_str() == s)
            .ok_or_else(|| anyhow!("unknown effect family `{s}` (expected {})", Family::names()))
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for Family {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl PartialEq<&str> for Family {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

#[cfg(test)]
mod tests;
