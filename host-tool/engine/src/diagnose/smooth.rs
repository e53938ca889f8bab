//! The generic smooth alternative a candidate must beat to be named as a
//! physical effect (issue 12, "misfit without false alarms").
//!
//! Every real machine has some smooth error that no seed fits (a guide bump,
//! a sag): a few tenths of a micrometre left after cubic19. Such a residual
//! correlates by chance with some named candidate — `abbe … times=y` when
//! the tool length changes by pass, a `higher_order` along one axis — and
//! that candidate then passes ΔBIC and the block hold-out, which a smooth
//! shape cannot fail (held-out passes lie between measured ones). Naming it
//! as a physical cause is a confident wrong answer. So a candidate is also
//! compared with what a generic smooth shape does with the same number of
//! columns: the best `k` monomials of degree 4 and 5 in the measured axes
//! (the polynomial degrees after the cubic seed), chosen greedily against
//! the same residual, the candidate's own monomials left out. A physical
//! effect (a lead, a reversal, a tool length, a temperature, a drift in
//! time, a pure one-axis straightness) is not a smooth function of the
//! position and beats it clearly; a smooth misfit does not, and is then
//! reported as smooth error that no named effect explains.

use crate::effect::Effect;
use crate::features::Feature;

use super::target::{State, TargetData};
use super::IN_SPAN_SHARE;
use crate::linalg::basis::{dot, small_fit};

/// The best generic smooth alternative found.
pub(super) struct SmoothAlternative {
    /// Its ΔBIC against the same model (k·ln n charged, as a candidate's
    /// columns are).
    pub(super) dbic: f64,
    /// Its terms (`x^2*z^2`, …).
    pub(super) terms: Vec<String>,
}

/// Lowest and highest total degree of the smooth alternative's monomials.
const DEGREES: (u8, u8) = (4, 5);

/// The best `k`-column smooth alternative to candidate `add` at model `st`,
/// or None when there is none (no measured axis, every monomial in the
/// model's span or the candidate's own).
pub(super) fn alternative(
    td: &TargetData,
    st: &State,
    add: &str,
    k: usize,
) -> Option<SmoothAlternative> {
    let own: Vec<Feature> = Effect::parse(add).map(|e| e.features).unwrap_or_default();
    let axes = td.data.varying_axes();
    if axes.is_empty() || k == 0 {
        return None;
    }
    let mut pool: Vec<(String, Vec<f64>)> = Vec::new();
    for exp in monomials(&axes) {
        let f = Feature::Monomial { exp };
        if own.contains(&f) {
            continue;
        }
        let Ok(col) = td.col(&f) else {
            continue;
        };
        let part = st.basis.residual(&col);
        let (cc, pp) = (dot(&col, &col), dot(&part, &part));
        if cc == 0.0 || pp < IN_SPAN_SHARE * cc {
            continue;
        }
        pool.push((f.to_string(), part));
    }
    if pool.is_empty() {
        return None;
    }
    // Greedy forward selection by residual sum of squares.
    let mut chosen: Vec<(String, Vec<f64>)> = Vec::new();
    while chosen.len() < k && !pool.is_empty() {
        let mut cols: Vec<Vec<f64>> = chosen.iter().map(|c| c.1.clone()).collect();
        let mut best: Option<(usize, f64)> = None;
        for (i, (_, c)) in pool.iter().enumerate() {
            cols.push(c.clone());
            let rss = small_fit(&cols, &st.resid).rss;
            cols.pop();
            if best.is_none_or(|(_, b)| rss < b) {
                best = Some((i, rss));
            }
        }
        let (i, _) = best?;
        chosen.push(pool.swap_remove(i));
    }
    let cols: Vec<Vec<f64>> = chosen.iter().map(|c| c.1.clone()).collect();
    let fit = small_fit(&cols, &st.resid);
    let n = td.rows.len() as f64;
    let dbic = n * (fit.rss.max(1e-300) / st.rss.max(1e-300)).ln() + fit.rank as f64 * n.ln();
    Some(SmoothAlternative {
        dbic,
        terms: chosen.into_iter().map(|c| c.0).collect(),
    })
}

/// Every monomial of total degree `DEGREES` in `axes`.
fn monomials(axes: &[usize]) -> Vec<[u8; 3]> {
    let mut out = Vec::new();
    let top = DEGREES.1;
    for a in 0..=top {
        for b in 0..=top - a {
            for c in 0..=top - a - b {
                let exp = [a, b, c];
                let deg = a + b + c;
                let on_axes = (0..3).all(|ax| exp[ax] == 0 || axes.contains(&ax));
                if (DEGREES.0..=DEGREES.1).contains(&deg) && on_axes {
                    out.push(exp);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_of_degree_four_and_five_on_the_measured_axes() {
        // 3 axes: 15 of degree 4 and 21 of degree 5.
        assert_eq!(monomials(&[0, 1, 2]).len(), 36);
        // One axis: x^4, x^5 only.
        assert_eq!(monomials(&[0]), vec![[4, 0, 0], [5, 0, 0]]);
    }
}
