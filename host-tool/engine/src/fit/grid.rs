//! The grid table model `grid:<step_mm>`: node values on a regular grid over
//! the axes that vary in the data, evaluated by (bi/tri)linear interpolation
//! and held at the edge outside — what LinuxCNC's and Sinumerik's
//! compensation tables and model-core's grid term do, so it exports as is.
//!
//! Node values: weighted least squares of the interpolated table against the
//! measurements, min Σ wᵢ(eᵢ − Σ_k φ_k(pᵢ) v_k)² + λ Σ (second differences of
//! v along each grid line)². With measurements at the nodes this is the
//! measurements themselves; between nodes it is the best table in the
//! least-squares sense; nodes no measurement touches take the linear
//! continuation of their neighbours from the (small) bending penalty, which
//! vanishes on any (bi/tri)linear function — so a bilinear error is
//! reproduced exactly. λ = 10⁻³ × the mean data weight per node, small
//! enough not to bias well-measured nodes.
//!
//! The normal equations are sparse (≤ 8 nodes per row, a 5-point bending
//! stencil per axis) and solved matrix-free by Jacobi-preconditioned
//! conjugate gradients, so fine grids over a large travel stay cheap.

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use anyhow::{bail, Result};

use crate::data::{Dataset, AXES, TARGETS};
use crate::holdout;
use crate::model::grid::{point, stencil, Stencil, MAX_NODES};
use crate::model::{FitStats, FittedModel, GridModel, GridOutput};
use crate::warning::Warning;

/// Relative weight of the bending penalty (see module docs).
const LAMBDA_REL: f64 = 1e-3;

/// The grid geometry spanning the data with `step_mm`.
pub fn geometry(data: &Dataset, step_mm: f64) -> Result<(Vec<usize>, Vec<f64>, Vec<usize>)> {
    let mut axes = Vec::new();
    let mut origin = Vec::new();
    let mut counts = Vec::new();
    // Nodes only along axes that move (an axis held at one position is
    // treated like an absent one).
    for a in data.varying_axes() {
        let col = data.pos_mm[a].as_ref().expect("axes() lists present axes");
        let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        // Nodes from lo in steps, the last at or beyond hi (1 nm tolerance).
        // Counted in f64 first: a tiny step over a long travel would
        // saturate the usize conversion and overflow the `+ 1`, giving a
        // two-node grid that covers a sliver of the travel (issue 14).
        let nodes = ((hi - lo) / step_mm - 1e-9).ceil() + 1.0;
        if nodes.is_nan() || nodes > MAX_NODES as f64 {
            bail!(
                "grid:{step_mm}: {nodes:.3e} nodes along {} alone is more than {MAX_NODES}; choose a coarser step",
                AXES[a]
            );
        }
        axes.push(a);
        origin.push(lo);
        counts.push((nodes as usize).max(2));
    }
    if axes.is_empty() {
        bail!("grid:{step_mm}: every measured point lies at one position; a table needs travel on some axis");
    }
    let total = counts
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= MAX_NODES);
    if total.is_none() {
        bail!(
            "grid:{step_mm}: {} nodes is more than {MAX_NODES}; choose a coarser step",
            counts
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" × ")
        );
    }
    Ok((axes, origin, counts))
}

/// Node values for one target from the rows `rows` (values `e`, weights `w`).
fn solve_nodes(stencils: &[Stencil], e: &[f64], w: &[f64], counts: &[usize]) -> (Vec<f64>, usize) {
    let n_nodes: usize = counts.iter().product();
    // Diagonal of AᵀWA and right-hand side AᵀWe.
    let mut diag = vec![0.0; n_nodes];
    let mut rhs = vec![0.0; n_nodes];
    for (i, s) in stencils.iter().enumerate() {
        for k in 0..s.n {
            diag[s.idx[k]] += w[i] * s.w[k] * s.w[k];
            rhs[s.idx[k]] += w[i] * s.w[k] * e[i];
        }
    }
    let touched = diag.iter().filter(|&&d| d > 0.0).count();
    let mean_diag = diag.iter().sum::<f64>() / touched.max(1) as f64;
    let lambda = LAMBDA_REL * mean_diag.max(f64::MIN_POSITIVE);
    // A tiny ridge keeps the system definite when a 2-node axis has no
    // bending stencil and some node has no data.
    let ridge = 1e-9 * lambda;
    let strides: Vec<usize> = (0..counts.len())
        .map(|k| counts[..k].iter().product())
        .collect();
    let apply = |v: &[f64], y: &mut [f64]| {
        y.iter_mut().zip(v).for_each(|(y, v)| *y = ridge * v);
        for (i, s) in stencils.iter().enumerate() {
            let mut p = 0.0;
            for k in 0..s.n {
                p += s.w[k] * v[s.idx[k]];
            }
            p *= w[i];
            for k in 0..s.n {
                y[s.idx[k]] += s.w[k] * p;
            }
        }
        // Bending: for every interior node along each axis, d = v₋ − 2v + v₊;
        // y += λ Dᵀ D v.
        for (ax, &n_ax) in counts.iter().enumerate() {
            if n_ax < 3 {
                continue;
            }
            let st = strides[ax];
            for node in 0..v.len() {
                let i_ax = (node / st) % n_ax;
                if i_ax == 0 || i_ax + 1 == n_ax {
                    continue;
                }
                let d = v[node - st] - 2.0 * v[node] + v[node + st];
                y[node - st] += lambda * d;
                y[node] -= 2.0 * lambda * d;
                y[node + st] += lambda * d;
            }
        }
    };
    // Jacobi preconditioner: data diagonal + bending diagonal (≤ 6λ per axis).
    let mut pre = vec![0.0; n_nodes];
    for node in 0..n_nodes {
        let mut b = ridge;
        for (ax, &n_ax) in counts.iter().enumerate() {
            if n_ax < 3 {
                continue;
            }
            let i_ax = (node / strides[ax]) % n_ax;
            // Node appears as centre (weight 4) and as neighbour (weight 1).
            if i_ax > 0 && i_ax + 1 < n_ax {
                b += 4.0 * lambda;
            }
            if i_ax >= 2 {
                b += lambda;
            }
            if i_ax + 2 < n_ax {
                b += lambda;
            }
        }
        pre[node] = 1.0 / (diag[node] + b);
    }
    // Preconditioned conjugate gradients from v = 0.
    let mut v = vec![0.0; n_nodes];
    let mut r = rhs.clone();
    let mut z: Vec<f64> = r.iter().zip(&pre).map(|(r, p)| r * p).collect();
    let mut p = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let rhs_norm = rhs.iter().map(|x| x * x).sum::<f64>().sqrt();
    let mut ap = vec![0.0; n_nodes];
    let max_iter = 20 * n_nodes + 100;
    for _ in 0..max_iter {
        let r_norm = r.iter().map(|x| x * x).sum::<f64>().sqrt();
        if r_norm <= 1e-14 * rhs_norm.max(f64::MIN_POSITIVE) {
            break;
        }
        apply(&p, &mut ap);
        let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n_nodes {
            v[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        for i in 0..n_nodes {
            z[i] = r[i] * pre[i];
        }
        let rz_new: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n_nodes {
            p[i] = z[i] + beta * p[i];
        }
    }
    (v, n_nodes - touched)
}

/// Fits `grid:<step_mm>` to every target present.
pub fn fit(data: &Dataset, step_mm: f64, blocks: usize) -> Result<(FittedModel, FitStats)> {
    let (axes, origin, counts) = geometry(data, step_mm)?;
    let n_nodes: usize = counts.iter().product();
    let stencils: Vec<Stencil> = (0..data.len())
        .map(|r| stencil(&origin, step_mm, &counts, &point(data, &axes, r)))
        .collect();
    let mut stats = FitStats {
        terms: n_nodes,
        ..Default::default()
    };
    let mut outputs = Vec::new();
    let node_fit = |rows: &[usize], t: usize| -> Result<(Vec<f64>, usize)> {
        let err = data.err_um[t].as_ref().expect("target present");
        let w = holdout::weights(data, rows)?;
        let st: Vec<Stencil> = rows.iter().map(|&r| stencils[r]).collect();
        let e: Vec<f64> = rows.iter().map(|&r| err[r].unwrap_or(0.0)).collect();
        let w: Vec<f64> = w.map_or(vec![1.0; rows.len()], |w| w.iter().copied().collect());
        Ok(solve_nodes(&st, &e, &w, &counts))
    };
    let eval = |values: &[f64], r: usize| -> f64 {
        let s = &stencils[r];
        (0..s.n).map(|k| s.w[k] * values[s.idx[k]]).sum()
    };
    for t in data.targets() {
        let name = TARGETS[t].to_string();
        let rows: Vec<usize> = data.measured(t).map(|(r, _)| r).collect();
        let (values, untouched) = node_fit(&rows, t)?;
        let resid: Vec<f64> = data
            .measured(t)
            .map(|(r, e)| e - eval(&values, r))
            .collect();
        stats.terms_per_target.insert(name.clone(), n_nodes);
        stats.rows.insert(name.clone(), rows.len());
        stats
            .rms_um
            .insert(name.clone(), holdout::rms(resid.iter().copied()));
        stats.max_abs_um.insert(
            name.clone(),
            resid.iter().fold(0.0, |m, e| f64::max(m, e.abs())),
        );
        if untouched > 0 {
            stats.warnings.push(Warning::new("unmeasured_nodes", format!(
                "{name}: {untouched} of {n_nodes} grid nodes have no measurement in their cells; their values continue the neighbours linearly (a step finer than the measurement spacing adds nodes, not information)"
            )));
        }
        // Block hold-out: same grid, refitted without each block.
        let bl = holdout::blocks(data, &rows, blocks);
        if bl.len() >= 2 {
            let err = data.err_um[t].as_ref().expect("target present");
            let mut ss = 0.0;
            let mut n = 0usize;
            for block in &bl {
                let held: std::collections::HashSet<usize> = block.iter().copied().collect();
                let train: Vec<usize> =
                    rows.iter().copied().filter(|r| !held.contains(r)).collect();
                let (v, _) = node_fit(&train, t)?;
                for &r in block {
                    let e = err[r].unwrap_or(0.0) - eval(&v, r);
                    ss += e * e;
                    n += 1;
                }
            }
            stats
                .held_out_rms_um
                .insert(name.clone(), (ss / n.max(1) as f64).sqrt());
        } else {
            stats.warnings.push(Warning::new(
                "no_held_out",
                format!("{name}: no held-out RMS: a single position or pass"),
            ));
        }
        if stats.holdout.is_empty() {
            stats.holdout = holdout::describe(data, &rows, blocks);
        }
        outputs.push(GridOutput {
            target: t,
            values_um: values,
        });
    }
    Ok((
        FittedModel::Grid(GridModel {
            axes,
            origin_mm: origin,
            step_mm,
            counts,
            outputs,
        }),
        stats,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(nx: usize, ny: usize, sx: f64, sy: f64, f: impl Fn(f64, f64) -> f64) -> Dataset {
        let (mut x, mut y, mut e) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..nx {
            for j in 0..ny {
                let (px, py) = (i as f64 * sx, j as f64 * sy);
                x.push(px);
                y.push(py);
                e.push(Some(f(px, py)));
            }
        }
        Dataset {
            source: "plane".into(),
            pos_mm: [Some(x), Some(y), None],
            err_um: [Some(e), None, None],
            ..Default::default()
        }
    }

    #[test]
    fn bilinear_function_is_reproduced_exactly_between_nodes() {
        let f = |x: f64, y: f64| 1.0 + 0.02 * x - 0.03 * y + 1e-4 * x * y;
        // Measurements every 7 mm, table every 20 mm: nodes are fitted, not sampled.
        let d = plane(15, 12, 7.0, 7.0, f);
        let (m, s) = fit(&d, 20.0, 5).unwrap();
        let FittedModel::Grid(g) = &m else { panic!() };
        assert_eq!(g.counts, vec![6, 5]);
        assert!(s.rms_um["ex"] < 1e-9, "{}", s.rms_um["ex"]);
        // Off-grid points, inside the table.
        let probe = plane(9, 7, 10.3, 10.9, f);
        let p = m.predict(&probe).unwrap();
        for (r, v) in p[0].as_ref().unwrap().iter().enumerate() {
            let want = f(probe.pos(0, r), probe.pos(1, r));
            assert!((v - want).abs() < 1e-8, "{r}: {v} vs {want}");
        }
        // Held-out is exact too: the bilinear continuation fills held-out planes.
        assert!(
            s.held_out_rms_um["ex"] < 1e-7,
            "{}",
            s.held_out_rms_um["ex"]
        );
    }

    #[test]
    fn nodes_without_data_are_reported_and_continued() {
        // Data every 50 mm on a line, table every 10 mm.
        let d = Dataset {
            source: "line".into(),
            pos_mm: [Some((0..5).map(|i| i as f64 * 50.0).collect()), None, None],
            err_um: [
                Some((0..5).map(|i| Some(i as f64 * 2.0)).collect()),
                None,
                None,
            ],
            ..Default::default()
        };
        let (m, s) = fit(&d, 10.0, 5).unwrap();
        assert!(
            s.warnings
                .iter()
                .any(|w| w.code == "unmeasured_nodes" && w.detail.contains("have no measurement")),
            "{:?}",
            s.warnings
        );
        let FittedModel::Grid(g) = &m else { panic!() };
        assert_eq!(g.counts, vec![21]);
        // Linear data stays linear at the unmeasured nodes.
        for (i, v) in g.outputs[0].values_um.iter().enumerate() {
            assert!((v - i as f64 * 0.4).abs() < 1e-6, "{i}: {v}");
        }
    }

    #[test]
    fn outside_the_table_holds_the_edge() {
        let d = plane(3, 3, 10.0, 10.0, |x, _| x);
        let (m, _) = fit(&d, 10.0, 5).unwrap();
        let probe = plane(1, 1, 0.0, 0.0, |_, _| 0.0);
        let mut probe = probe;
        probe.pos_mm[0] = Some(vec![-100.0]);
        let p = m.predict(&probe).unwrap();
        assert!(p[0].as_ref().unwrap()[0].abs() < 1e-9);
    }

    #[test]
    fn too_fine_a_grid_is_refused() {
        let d = plane(3, 3, 100.0, 100.0, |x, _| x);
        let e = fit(&d, 0.01, 5).unwrap_err().to_string();
        assert!(e.contains("coarser"), "{e}");
        // A step so small that the node count leaves usize (it used to
        // overflow, or wrap to a two-node grid over a sliver of the travel).
        for step in [1e-300, f64::MIN_POSITIVE] {
            let e = fit(&d, step, 5).unwrap_err().to_string();
            assert!(e.contains("coarser") && e.contains("along x"), "{e}");
        }
    }
}
