//! When two `fit --add` strings are the same effect up to its nonlinear
//! parameter ([`same_effect`]), and how an effect goes into a model's list
//! of effects ([`swap_in`]): the re-search of an effect already in the
//! model replaces it instead of adding it a second time.

/// Puts effect `add` into the model's effect list: in the place of
/// `replaces` (the same effect with its nonlinear parameter searched again)
/// when that is in the list, else at the end unless it is there already.
/// Returns whether the list changed. The path, `improve` and the `next:`
/// command all change a model this way.
pub fn swap_in(adds: &mut Vec<String>, add: &str, replaces: Option<&str>) -> bool {
    if let Some(old) = replaces.filter(|o| adds.iter().any(|a| a == o)) {
        for a in adds.iter_mut().filter(|a| *a == old) {
            *a = add.to_string();
        }
        true
    } else if adds.iter().any(|a| a == add) {
        false
    } else {
        adds.push(add.to_string());
        true
    }
}

/// What makes two effects "the same effect" for the path: family, target,
/// axis, channel and `times` — the nonlinear parameter (lag, order, degree)
/// is what a re-search may change. Periodic effects on one axis are the
/// same when their periods are within 10 % (a lead re-found more exactly);
/// farther apart they are two effects (a screw lead and a scale pitch).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct EffectKey {
    pub(super) family: String,
    pub(super) target: String,
    pub(super) axis: Option<String>,
    pub(super) channel: Option<String>,
    pub(super) times: Option<String>,
    pub(super) period_mm: Option<f64>,
}

impl EffectKey {
    /// The key of a `fit --add` string (None when it does not parse): the
    /// pairs as `features::split_spec` reads them, the one grammar.
    pub(super) fn of(spec: &str) -> Option<EffectKey> {
        let (family, kv) = crate::features::split_spec(spec).ok()?;
        let get = |key: &str| {
            kv.iter()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.to_string())
        };
        Some(EffectKey {
            family: family.to_string(),
            target: get("target")?,
            axis: get("axis"),
            channel: get("channel"),
            times: get("times"),
            period_mm: get("period_mm").and_then(|v| v.parse().ok()),
        })
    }

    /// Same effect, up to its nonlinear parameter.
    pub(super) fn matches(&self, o: &EffectKey) -> bool {
        let period_ok = match (self.period_mm, o.period_mm) {
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

    /// Whether a proposal of `family` along `axis` / following `channel` /
    /// times `times` could match (checked before its parameter search).
    pub(super) fn admits(
        &self,
        family: &str,
        axis: Option<&str>,
        channel: Option<&str>,
        times: Option<&str>,
    ) -> bool {
        self.family == family
            && self.axis.as_deref() == axis
            && self.channel.as_deref() == channel
            && self.times.as_deref() == times
    }
}

/// Whether two `fit --add` strings are the same effect up to its nonlinear
/// parameter (family, target, axis, channel, `times`; periods within 10 %):
/// the second replaces the first rather than adding to it.
pub fn same_effect(a: &str, b: &str) -> bool {
    match (EffectKey::of(a), EffectKey::of(b)) {
        (Some(x), Some(y)) => x.matches(&y),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::Effect;

    #[test]
    fn swap_in_replaces_in_place_and_never_adds_twice() {
        let old = "thermal:target=ex,channel=bed,lag_s=3600";
        let new = "thermal:target=ex,channel=bed,lag_s=600";
        let mut adds = vec![old.to_string(), "reversal:target=ex,axis=x".to_string()];
        assert!(swap_in(&mut adds, new, Some(old)));
        assert_eq!(adds, [new, "reversal:target=ex,axis=x"]);
        // Already there: unchanged.
        assert!(!swap_in(&mut adds, "reversal:target=ex,axis=x", None));
        assert_eq!(adds.len(), 2);
        // A new effect goes to the end.
        assert!(swap_in(&mut adds, "drift:target=ez", None));
        assert_eq!(adds.last().map(String::as_str), Some("drift:target=ez"));
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
