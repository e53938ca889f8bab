//! How an effect goes into a model's list of effects ([`swap_in`]): the
//! re-search of an effect already in the model (the same effect up to its
//! nonlinear parameter, [`EffectSpec::same_effect`](crate::effect::EffectSpec::same_effect)) replaces it instead of
//! adding it a second time.

/// Puts effect `add` into the model's effect list: in the place of
/// `replaces` (the same effect with its nonlinear parameter searched again)
/// when that is in the list, else at the end unless it is there already.
/// Returns whether the list changed. The path, `improve` and the `next:`
/// command all change a model this way — the engine on [`EffectSpec`](crate::effect::EffectSpec)s,
/// the report's `next:` command on the JSON's `add` strings.
pub fn swap_in<T, Q>(adds: &mut Vec<T>, add: &T, replaces: Option<&Q>) -> bool
where
    T: Clone + PartialEq + PartialEq<Q>,
    Q: ?Sized,
{
    if let Some(old) = replaces.filter(|o| adds.iter().any(|a| a == *o)) {
        for a in adds.iter_mut().filter(|a| **a == *old) {
            *a = add.clone();
        }
        true
    } else if adds.contains(add) {
        false
    } else {
        adds.push(add.clone());
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect::EffectSpec;

    #[test]
    fn swap_in_replaces_in_place_and_never_adds_twice() {
        let s = |a: &str| a.parse::<EffectSpec>().unwrap();
        let old = s("thermal:target=ex,channel=bed,lag_s=3600");
        let new = s("thermal:target=ex,channel=bed,lag_s=600");
        let rev = s("reversal:target=ex,axis=x");
        let mut adds = vec![old.clone(), rev.clone()];
        assert!(swap_in(&mut adds, &new, Some(&old)));
        assert_eq!(adds, [new.clone(), rev.clone()]);
        // Already there: unchanged.
        assert!(!swap_in(&mut adds, &rev, None::<&EffectSpec>));
        assert_eq!(adds.len(), 2);
        // A new effect goes to the end.
        let drift = s("drift:target=ez");
        assert!(swap_in(&mut adds, &drift, None::<&EffectSpec>));
        assert_eq!(adds.last(), Some(&drift));
    }
}
