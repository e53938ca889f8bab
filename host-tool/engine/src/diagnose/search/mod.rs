//! The candidate search: for one target at the current model, every named
//! effect the data could show, each as a typed `fit --add` spec with the
//! evidence that proposed it ([`Proposal`]). How a family is searched is
//! its own file here (`periodic`: a periodogram on the densest lines;
//! `thermal`: per channel, alone or times each axis, the lag searched on a
//! grid and refined by Brent's method, and the multi-sensor forward
//! selection; `reversal`, `abbe`, `drift`, `squareness`, `higher_order`),
//! registered below one line each; the order of the registry is the order
//! of the candidates. This file holds what they share: the proposal, the
//! driver [`propose`] and the numbers as a spec writes them ([`fmt_num`],
//! [`shown`]). Scoring is `score`'s.

use crate::effect::{Axis, EffectSpec, Family};

use super::target::{State, TargetData};
use super::Evidence;

/// A candidate before scoring: its spec and what the search learned.
#[derive(Clone, Debug)]
pub(super) struct Proposal {
    /// The effect, typed.
    pub(super) spec: EffectSpec,
    /// Nonlinear parameters searched for (period, lag): each costs ln n.
    pub(super) searched: usize,
    /// What proposed it, in words.
    pub(super) note: String,
}

impl Proposal {
    /// The family.
    pub(super) fn family(&self) -> Family {
        self.spec.family()
    }

    /// The axis it runs or grows along (index), if any.
    pub(super) fn axis(&self) -> Option<usize> {
        self.spec.along().map(Axis::index)
    }
}

/// `v` with `decimals` places, trailing zeros dropped (`5.08`, `600`): how
/// a number is written into a spec and a note.
pub(super) fn fmt_num(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `v` as a spec shows it with `decimals` places ([`fmt_num`]): the value
/// the columns of a proposed effect use, so that the spec printed is the
/// effect scored (a period to 10 nm, a lag to 1 s).
pub(super) fn shown(v: f64, decimals: usize) -> f64 {
    fmt_num(v, decimals)
        .parse()
        .expect("a formatted finite number parses")
}

/// What a family's search is given: one target's data and model, where
/// its evidence goes, and which effect it is restricted to.
pub(super) struct Search<'a> {
    /// The target's data.
    pub(super) td: &'a TargetData<'a>,
    /// The current model.
    pub(super) st: &'a State,
    /// Where plot material goes (the periodograms).
    pub(super) ev: &'a mut Evidence,
    /// With `only`, just the candidates that could be that effect (the
    /// re-search of an effect already in the model, against the model
    /// without it).
    pub(super) only: Option<&'a EffectSpec>,
    /// The axes that move: terms in position only along them. One held at
    /// one position (every axis of a thermal test at one point) has no
    /// travel to fit them on — `fit` refuses them — and each would only be
    /// reported as `in_model_span`.
    pub(super) moving: Vec<usize>,
}

impl Search<'_> {
    /// The target's name.
    pub(super) fn tn(&self) -> &'static str {
        crate::data::TARGETS[self.td.t]
    }

    /// The target, typed.
    pub(super) fn target(&self) -> crate::effect::Target {
        crate::effect::Target::from_index(self.td.t).expect("a target index")
    }

    /// Whether an effect of `family` along `axis`, following `channel`,
    /// times `times` is searched for ([`Search::only`]).
    pub(super) fn want(
        &self,
        family: Family,
        axis: Option<usize>,
        channel: Option<&str>,
        times: Option<usize>,
    ) -> bool {
        let ax = |a: Option<usize>| a.and_then(Axis::from_index);
        self.only
            .is_none_or(|k| k.admits(family, ax(axis), channel, ax(times)))
    }
}

/// How the diagnosis searches for one family: its file's `propose` and
/// `researchable`.
struct FamilySearch {
    /// The family it proposes.
    family: Family,
    /// Its proposals for the target at the model.
    propose: fn(&mut Search) -> Vec<Proposal>,
    /// Whether an effect of the family already in the model has a
    /// nonlinear parameter to search again (against the model without it).
    researchable: fn(&TargetData) -> bool,
}

/// The registry: one line per family, `module => Family` (the module has
/// `propose` and `researchable`); the candidates come in this order.
macro_rules! searches {
    ($($module:ident => $family:ident),+ $(,)?) => {
        $(mod $module;)+

        /// Every family's search, in candidate order.
        const SEARCHES: &[FamilySearch] = &[$(FamilySearch {
            family: Family::$family,
            propose: $module::propose,
            researchable: $module::researchable,
        }),+];
    };
}

searches! {
    periodic => Periodic,
    thermal => Thermal,
    reversal => Reversal,
    abbe => Abbe,
    drift => Drift,
    squareness => Squareness,
    higher_order => HigherOrder,
}

/// Builds the candidate library for one target at the current model; with
/// `only`, just the candidates that could be that effect (the re-search of
/// an effect already in the model, against the model without it).
pub(super) fn propose(
    td: &TargetData,
    st: &State,
    ev: &mut Evidence,
    only: Option<&EffectSpec>,
) -> Vec<Proposal> {
    let mut s = Search {
        td,
        st,
        ev,
        only,
        moving: td.data.varying_axes(),
    };
    SEARCHES.iter().flat_map(|f| (f.propose)(&mut s)).collect()
}

/// Whether an effect of `family` already in the model is searched again.
pub(super) fn researchable(family: Family, td: &TargetData) -> bool {
    SEARCHES
        .iter()
        .any(|f| f.family == family && (f.researchable)(td))
}

pub(super) use thermal::unidentified_lags;
