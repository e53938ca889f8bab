//! Local fits (`--local`), as the seed did it (SEEDS.md: "for a point, fit
//! locally on the cuboid between two measured planes, or on the plane (x, z
//! only), or on the line (x only)"). The exact rule:
//!
//! - The *varying* axes are those with more than one distinct measured
//!   position (to 1 nm).
//! - **Three varying axes → cuboid.** The stacking axis s is the varying
//!   axis with the fewest distinct positions (ties → the later axis, so z on
//!   the seed's 17 × 11 × 11 grid); its distinct positions are the measured
//!   planes c₀ < c₁ < …. For each pair of neighbouring planes (cᵢ, cᵢ₊₁) one
//!   patch is fitted by weighted least squares to the measurements on those
//!   two planes, with the 20 terms P(a, b) + u_s·Q(a, b), P and Q the
//!   10-term plane cubics (1, a, a², a³, b, b², b³, ab, ab², a²b) in the
//!   other two axes. A point uses the patch whose planes bracket its s
//!   (the first / last patch below / above the measured range). The patch
//!   reproduces any cubic19 error exactly on both of its planes and
//!   interpolates linearly in s between them.
//! - **Two varying axes → plane.** One patch: the 10-term plane cubic over
//!   the whole plane.
//! - **One varying axis → line.** One patch: the cubic 1, a, a², a³.
//!
//! Each patch needs at least as many distinct points as terms (20, 10, 4);
//! otherwise the fit stops with the patch named. Data that is not on
//! measured planes (every point at its own s) cannot form cuboids and is
//! refused with that explanation.

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use std::collections::BTreeMap;

use anyhow::Result;

use crate::data::{Dataset, AXES, TARGETS};
use crate::features::{Feature, Norm, CUBIC19};
use crate::fit::{linear, FitError, LocalRefusal};
use crate::holdout;
use crate::model::{FitStats, FittedModel, LocalModel, LocalPatch};
use crate::warning::Warning;

fn distinct_positions(data: &Dataset, axis: usize) -> Vec<f64> {
    let Some(col) = &data.pos_mm[axis] else {
        return Vec::new();
    };
    let mut m: BTreeMap<i64, f64> = BTreeMap::new();
    for &p in col {
        m.entry((p * 1e6).round() as i64).or_insert(p);
    }
    m.into_values().collect()
}

/// Monomials of cubic19 that only involve `axes`.
fn cubic_in(axes: &[usize]) -> Vec<[u8; 3]> {
    CUBIC19
        .iter()
        .copied()
        .filter(|e| (0..3).all(|a| e[a] == 0 || axes.contains(&a)))
        .collect()
}

/// Fits the local model without statistics (used for the fit and for each
/// hold-out refit).
pub fn fit_model(data: &Dataset) -> Result<LocalModel> {
    let norm = Norm::from_data(data);
    let varying: Vec<usize> = (0..3)
        .filter(|&a| distinct_positions(data, a).len() > 1)
        .collect();
    let mono = |exps: Vec<[u8; 3]>| -> Vec<Feature> {
        exps.into_iter()
            .map(|exp| Feature::Monomial { exp })
            .collect()
    };
    let all_rows: Vec<usize> = (0..data.len()).collect();
    let fit_patch = |features: &[Feature],
                     rows: &[usize],
                     label: &str,
                     lo: f64,
                     hi: f64|
     -> Result<LocalPatch> {
        let mut outputs = Vec::new();
        for t in data.targets() {
            let tf = linear::fit_target(
                data,
                &norm,
                features,
                t,
                rows,
                &format!("{}, {label}", TARGETS[t]),
            )?;
            outputs.push(tf.output);
        }
        Ok(LocalPatch {
            lo_mm: lo,
            hi_mm: hi,
            outputs,
        })
    };
    match varying.len() {
        3 => {
            let counts: Vec<(usize, usize)> = varying
                .iter()
                .map(|&a| (distinct_positions(data, a).len(), a))
                .collect();
            // Fewest distinct positions; ties → the later axis.
            let s = counts
                .iter()
                .min_by(|x, y| x.0.cmp(&y.0).then(y.1.cmp(&x.1)))
                .map(|c| c.1)
                .expect("three axes");
            let planes = distinct_positions(data, s);
            if planes.len() * 4 > data.len() {
                return Err(FitError::Local(LocalRefusal::NotOnPlanes {
                    planes: planes.len(),
                    axis: s,
                    points: data.len(),
                })
                .into());
            }
            let others: Vec<usize> = varying.iter().copied().filter(|&a| a != s).collect();
            let base = cubic_in(&others);
            let mut exps = base.clone();
            exps.extend(base.iter().map(|e| {
                let mut e = *e;
                e[s] = 1;
                e
            }));
            let features = mono(exps);
            let col = data.pos_mm[s].as_ref().expect("varying axis present");
            let key = |p: f64| (p * 1e6).round() as i64;
            let mut patches = Vec::new();
            for w in planes.windows(2) {
                let (lo, hi) = (w[0], w[1]);
                let rows: Vec<usize> = all_rows
                    .iter()
                    .copied()
                    .filter(|&r| key(col[r]) == key(lo) || key(col[r]) == key(hi))
                    .collect();
                let label = format!("cuboid {} {lo}…{hi} mm", AXES[s]);
                patches.push(fit_patch(&features, &rows, &label, lo, hi)?);
            }
            Ok(LocalModel {
                shape: "cuboid".into(),
                norm,
                stack_axis: Some(s),
                planes_mm: planes,
                patches,
            })
        }
        2 | 1 => {
            let shape = if varying.len() == 2 { "plane" } else { "line" };
            let features = mono(cubic_in(&varying));
            let names: Vec<&str> = varying.iter().map(|&a| AXES[a]).collect();
            let patch = fit_patch(
                &features,
                &all_rows,
                &format!("{shape} ({})", names.join(", ")),
                0.0,
                0.0,
            )?;
            Ok(LocalModel {
                shape: shape.into(),
                norm,
                stack_axis: None,
                planes_mm: Vec::new(),
                patches: vec![patch],
            })
        }
        _ => Err(FitError::Local(LocalRefusal::NoTravel).into()),
    }
}

/// Fits the local model to every target present, with statistics.
pub fn fit(data: &Dataset, blocks: usize) -> Result<(FittedModel, FitStats)> {
    let m = FittedModel::Local(fit_model(data)?);
    let FittedModel::Local(lm) = &m else {
        unreachable!()
    };
    let mut stats = FitStats {
        terms: lm.patches[0]
            .outputs
            .first()
            .map_or(0, |o| o.features.len()),
        ..Default::default()
    };
    let resid = m.residuals(data)?;
    for t in data.targets() {
        let name = TARGETS[t].to_string();
        let r = resid[t]
            .as_ref()
            .expect("model covers every target of its data");
        stats.terms_per_target.insert(name.clone(), stats.terms);
        stats.rows.insert(name.clone(), r.len());
        stats
            .rms_um
            .insert(name.clone(), holdout::rms(r.iter().map(|x| x.1)));
        stats.max_abs_um.insert(
            name.clone(),
            r.iter().fold(0.0, |m, x| f64::max(m, x.1.abs())),
        );
        // Worst patch condition number: refit is cheap, but we only need it
        // once, so recompute from the design of each patch.
        let mut worst = 0.0f64;
        for p in &lm.patches {
            if let Some(o) = p.outputs.iter().find(|o| o.target == t) {
                let rows: Vec<usize> = match lm.stack_axis {
                    Some(s) => (0..data.len())
                        .filter(|&r| {
                            let v = data.pos(s, r);
                            (v - p.lo_mm).abs() < 1e-6 || (v - p.hi_mm).abs() < 1e-6
                        })
                        .filter(|&r| data.err_um[t].as_ref().is_some_and(|c| c[r].is_some()))
                        .collect(),
                    None => data.measured(t).map(|x| x.0).collect(),
                };
                let a = crate::linalg::lsq::design_matrix(data, &lm.norm, &o.features, &rows)?;
                let b = nalgebra::DVector::zeros(rows.len());
                let w = holdout::weights(data, &rows)?;
                if let Ok(sol) = crate::linalg::lsq::solve(&a, &b, w.as_ref()) {
                    worst = worst.max(sol.condition_number);
                }
            }
        }
        if worst.is_finite() && worst > 0.0 {
            stats.condition_number.insert(name.clone(), worst);
            if worst > crate::linalg::lsq::ILL_CONDITIONED {
                stats.warnings.push(Warning::new(
                    "ill_conditioned",
                    format!(
                        "{name}: a local patch is ill-conditioned (condition number {worst:.3e})"
                    ),
                ));
            }
        }
        // Block hold-out: refit the whole local model without each block.
        let rows: Vec<usize> = data.measured(t).map(|x| x.0).collect();
        let bl = holdout::blocks(data, &rows, blocks);
        if bl.len() < 2 {
            stats.warnings.push(Warning::new(
                "no_held_out",
                format!("{name}: no held-out RMS: a single position or pass"),
            ));
            continue;
        }
        let mut ss = 0.0;
        let mut n = 0usize;
        let mut failed = None;
        for block in &bl {
            let held: std::collections::HashSet<usize> = block.iter().copied().collect();
            let train: Vec<usize> = (0..data.len()).filter(|r| !held.contains(r)).collect();
            let train_data = crate::data::subset(data, &train);
            match fit_model(&train_data) {
                Ok(lm) => {
                    let test = crate::data::subset(data, block);
                    let p = FittedModel::Local(lm).predict(&test)?;
                    let p = p[t].as_ref().expect("target present");
                    for (i, &r) in block.iter().enumerate() {
                        let e = data.err_um[t].as_ref().and_then(|c| c[r]).unwrap_or(0.0) - p[i];
                        ss += e * e;
                        n += 1;
                    }
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        match failed {
            None => {
                stats
                    .held_out_rms_um
                    .insert(name.clone(), (ss / n.max(1) as f64).sqrt());
            }
            Some(e) => stats.warnings.push(Warning::new(
                "no_held_out",
                format!("{name}: no held-out RMS: the local fit without a block fails: {e:#}"),
            )),
        }
        if stats.holdout.is_empty() {
            stats.holdout = holdout::describe(data, &rows, blocks);
        }
    }
    Ok((m, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid3(nx: usize, ny: usize, nz: usize, f: impl Fn([f64; 3]) -> f64) -> Dataset {
        let (mut x, mut y, mut z, mut e) = (vec![], vec![], vec![], vec![]);
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    let p = [i as f64 * 50.0, j as f64 * 50.0, k as f64 * 50.0];
                    x.push(p[0]);
                    y.push(p[1]);
                    z.push(p[2]);
                    e.push(Some(f(p)));
                }
            }
        }
        Dataset {
            source: "grid".into(),
            pos_mm: [Some(x), Some(y), Some(z)],
            err_um: [Some(e), None, None],
            ..Default::default()
        }
    }

    #[test]
    fn cuboid_is_exact_on_a_cubic_at_the_planes_and_linear_between() {
        // P(x, y) + z·Q(x, y) with plane cubics P, Q: exact everywhere.
        let f = |p: [f64; 3]| {
            let (x, y, z) = (p[0] / 400.0, p[1] / 250.0, p[2] / 250.0);
            1.0 + x - 2.0 * x * x * x
                + 0.5 * y * y
                + x * y * y
                + z * (0.3 - y * y * y + 2.0 * x * x * y)
        };
        let d = grid3(9, 6, 5, f);
        let (m, s) = fit(&d, 5).unwrap();
        let FittedModel::Local(lm) = &m else { panic!() };
        assert_eq!(lm.shape, "cuboid");
        // y and z tie at 6 vs 5 — z has fewer: the stack axis.
        assert_eq!(lm.stack_axis, Some(2));
        assert_eq!(lm.patches.len(), 4);
        assert!(s.rms_um["ex"] < 1e-9, "{}", s.rms_um["ex"]);
        // Off-grid points between planes.
        let mut probe = grid3(3, 3, 3, |_| 0.0);
        for c in probe.pos_mm.iter_mut().flatten() {
            for v in c.iter_mut() {
                *v = *v * 1.37 + 11.0;
            }
        }
        let p = m.predict(&probe).unwrap();
        for (r, v) in p[0].as_ref().unwrap().iter().enumerate() {
            let want = f([probe.pos(0, r), probe.pos(1, r), probe.pos(2, r)]);
            assert!((v - want).abs() < 1e-9, "{r}: {v} vs {want}");
        }
    }

    #[test]
    fn cuboid_reproduces_full_cubic19_on_its_planes() {
        let f = |p: [f64; 3]| {
            let (x, y, z) = (p[0] / 400.0, p[1] / 250.0, p[2] / 250.0);
            z * z * z - 2.0 * z * z * x + y * z * z + x * x * x
        };
        let d = grid3(9, 6, 5, f);
        let (_, s) = fit(&d, 5).unwrap();
        assert!(s.rms_um["ex"] < 1e-9, "{}", s.rms_um["ex"]);
    }

    #[test]
    fn line_and_plane_fallbacks() {
        let f = |p: [f64; 3]| 0.5 + p[0] * 0.01 - 3e-7 * p[0].powi(3);
        let d = grid3(12, 1, 1, f);
        let (m, s) = fit(&d, 5).unwrap();
        let FittedModel::Local(lm) = &m else { panic!() };
        assert_eq!(lm.shape, "line");
        assert_eq!(s.terms, 4);
        assert!(s.rms_um["ex"] < 1e-9);
        assert!(s.held_out_rms_um["ex"] < 1e-8);
        let d = grid3(8, 1, 7, |p| p[0] * p[2] * 1e-4 + 1e-7 * p[2].powi(3));
        let (m, s) = fit(&d, 5).unwrap();
        let FittedModel::Local(lm) = &m else { panic!() };
        assert_eq!(lm.shape, "plane");
        assert_eq!(s.terms, 10);
        assert!(s.rms_um["ex"] < 1e-9);
    }

    #[test]
    fn scattered_points_are_refused() {
        let mut d = grid3(4, 4, 4, |_| 0.0);
        for (a, col) in d.pos_mm.iter_mut().flatten().enumerate() {
            for (i, v) in col.iter_mut().enumerate() {
                *v += (i * (a + 1)) as f64 * 0.01;
            }
        }
        let e = fit(&d, 5).unwrap_err();
        assert!(
            matches!(
                e.downcast_ref::<FitError>(),
                Some(FitError::Local(LocalRefusal::NotOnPlanes {
                    points: 64,
                    ..
                }))
            ),
            "{e}"
        );
        // The engine's words name no flag of the command line.
        assert!(
            e.to_string()
                .starts_with("local fit: the data is not on measured planes"),
            "{e}"
        );
    }
}
