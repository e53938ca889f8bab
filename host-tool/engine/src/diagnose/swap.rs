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
}
