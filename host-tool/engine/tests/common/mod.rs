//! What the engine's integration tests read off a diagnosis, written once.
#![allow(dead_code)]

use trueaxis_engine::diagnose::Diagnosis;

/// The effects the forward path added for `target`, in the order added.
pub fn path_adds<'a>(d: &'a Diagnosis, target: &str) -> Vec<&'a str> {
    let on_target = d.path.iter().filter(|s| s.target == target);
    on_target.map(|s| s.add.as_str()).collect()
}

/// The details of the warnings with `code`, in the order given.
pub fn warning_details<'a>(d: &'a Diagnosis, code: &str) -> Vec<&'a str> {
    d.warnings
        .iter()
        .filter(|w| w.code == code)
        .map(|w| w.detail.as_str())
        .collect()
}
