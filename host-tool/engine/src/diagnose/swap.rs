//! How an effect goes into a model's list of effects ([`swap_in`]): the
//! re-search of an effect already in the model (the same effect up to its
//! nonlinear parameter, `effect::same_effect`) replaces it instead of
//! adding it a second time.

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect::{same_effect, Effect};

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
