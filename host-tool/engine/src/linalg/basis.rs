//! The least-squares building blocks of the diagnosis: an orthonormal basis
//! of the current model's columns (to measure how much of a candidate lies
//! outside it, and to partial the model out — Frisch–Waugh–Lovell), small
//! dense solves for the candidate's own coefficients, and block hold-out
//! refits done with per-fold Gram sums so that scoring dozens of candidates
//! costs one pass over the rows each instead of one SVD per fold.
//!
//! Columns are scaled to unit RMS before any matrix is formed: a thermal
//! column in K, an Abbe column in mm and a monomial in [−1, 1] would
//! otherwise differ by 10⁴ in scale and the rank tolerance would mean
//! nothing.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// Relative singular-value tolerance below which a direction counts as
/// absent (the span of a rank-deficient model).
const RANK_TOL: f64 = 1e-9;

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (dot(v, v) / v.len() as f64).sqrt()
}

/// Dot product, over the shorter of the two. Eight running sums: one sum
/// is a chain of dependent additions the CPU cannot overlap (4 cycles
/// each); eight independent ones vectorise and run at the speed of the
/// loads. Differs from the sequential sum at round-off.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0f64; 8];
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// Rows per block of [`Basis::residuals`]: a block of each input and output
/// column stays in the first-level cache while every basis vector passes.
const BLOCK: usize = 512;

/// An orthonormal basis (n × r) of the span of a set of columns, its vectors
/// kept as plain slices (projections are the inner loop of every candidate
/// search, and plain slices keep them fast in unoptimised test builds too).
#[derive(Clone, Debug)]
pub struct Basis {
    u: Vec<Vec<f64>>,
}

/// The Gram matrix Σ_rows a_i·a_j of `cols` (all of one length), summed in
/// blocks of rows that stay in cache: each column is read once, not once per
/// pair.
fn gram(cols: &[&[f64]]) -> DMatrix<f64> {
    let p = cols.len();
    let n = cols.first().map_or(0, |c| c.len());
    let mut g = DMatrix::zeros(p, p);
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        for i in 0..p {
            for j in 0..=i {
                g[(i, j)] += dot(&cols[i][start..end], &cols[j][start..end]);
            }
        }
        start = end;
    }
    for i in 0..p {
        for j in 0..i {
            g[(j, i)] = g[(i, j)];
        }
    }
    g
}

/// The columns Σ_j w[(j, k)]·cols[j] for each column k of `w`, in blocks of
/// rows.
fn mix(cols: &[&[f64]], w: &DMatrix<f64>) -> Vec<Vec<f64>> {
    let n = cols.first().map_or(0, |c| c.len());
    let mut out = vec![vec![0.0; n]; w.ncols()];
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        for (k, o) in out.iter_mut().enumerate() {
            let ob = &mut o[start..end];
            for (j, c) in cols.iter().enumerate() {
                let wj = w[(j, k)];
                for (oi, ci) in ob.iter_mut().zip(&c[start..end]) {
                    *oi += wj * ci;
                }
            }
        }
        start = end;
    }
    out
}

/// W = V·Λ^{-1/2} of the Gram matrix `g` = VΛVᵀ, with each row j divided by
/// `scale[j]`, so that `mix(cols, W)` is orthonormal in exact arithmetic; None
/// when the smallest eigenvalue is below 10⁻¹² of the largest (a condition
/// number of the columns above 10⁶: squaring it in the Gram matrix would
/// lose the directions' accuracy, and whether a direction is absent can
/// only be told by an SVD of the columns themselves).
fn whitening(g: DMatrix<f64>, scale: &[f64]) -> Option<DMatrix<f64>> {
    let p = scale.len();
    let eig = SymmetricEigen::new(DMatrix::from_fn(p, p, |j, k| {
        g[(j, k)] / (scale[j] * scale[k])
    }));
    let lmax = eig.eigenvalues.iter().copied().fold(0.0f64, f64::max);
    let lmin = eig
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    if !(lmax.is_finite() && lmin > 1e-12 * lmax) {
        return None;
    }
    Some(DMatrix::from_fn(p, p, |j, k| {
        eig.eigenvectors[(j, k)] / eig.eigenvalues[k].sqrt() / scale[j]
    }))
}

impl Basis {
    /// The basis of the span of `cols` (each of length `n`); zero columns and
    /// exactly dependent ones add nothing.
    ///
    /// Well-conditioned columns (the usual model: scaled monomials and
    /// effect columns) take a Cholesky-QR done twice (CholeskyQR2: the
    /// columns whitened by their Gram matrix, then the result by its own,
    /// which restores orthonormality to round-off when the condition number
    /// is below ~10⁸; here at most 10⁶) — three passes over the rows and one
    /// n × r matrix, where an SVD of the n × r matrix needs a copy of it,
    /// U, and about three times the arithmetic. Columns closer to dependent
    /// take the SVD, which drops directions below 10⁻⁹ of the largest
    /// singular value (the same directions: the fast path runs only when
    /// none is below 10⁻⁶).
    pub fn new(cols: &[Vec<f64>], n: usize) -> Basis {
        let keep: Vec<(usize, f64)> = cols
            .iter()
            .enumerate()
            .map(|(j, c)| (j, rms(c)))
            .filter(|(_, s)| *s > 0.0 && s.is_finite())
            .collect();
        if keep.is_empty() || n == 0 {
            return Basis { u: Vec::new() };
        }
        let refs: Vec<&[f64]> = keep.iter().map(|&(j, _)| cols[j].as_slice()).collect();
        let scale: Vec<f64> = keep.iter().map(|&(_, s)| s * (n as f64).sqrt()).collect();
        if let Some(w1) = whitening(gram(&refs), &scale) {
            let q1 = mix(&refs, &w1);
            let q1r: Vec<&[f64]> = q1.iter().map(Vec::as_slice).collect();
            let ones = vec![1.0; q1.len()];
            if let Some(w2) = whitening(gram(&q1r), &ones) {
                return Basis { u: mix(&q1r, &w2) };
            }
        }
        Basis::by_svd(&refs, n)
    }

    /// The basis by an SVD of the columns scaled to unit RMS.
    fn by_svd(cols: &[&[f64]], n: usize) -> Basis {
        let scale: Vec<f64> = cols.iter().map(|c| rms(c)).collect();
        let m = DMatrix::from_fn(n, cols.len(), |i, j| cols[j][i] / scale[j]);
        let svd = m.svd(true, false);
        let smax = svd.singular_values.max();
        let u = svd.u.expect("SVD asked for U");
        Basis {
            u: (0..svd.singular_values.len())
                .filter(|&k| svd.singular_values[k] > RANK_TOL * smax)
                .map(|k| u.column(k).iter().copied().collect())
                .collect(),
        }
    }

    /// The basis vectors.
    fn vectors(&self) -> impl Iterator<Item = &[f64]> {
        self.u.iter().map(Vec::as_slice)
    }

    /// The basis vectors (orthonormal over all rows), one per dimension.
    pub fn columns(&self) -> &[Vec<f64>] {
        &self.u
    }

    /// Dimension of the span.
    pub fn rank(&self) -> usize {
        self.u.len()
    }

    /// How much two spans share: the mean squared cosine of their principal
    /// angles over the smaller one, ‖U_aᵀ U_b‖²_F / min(r_a, r_b) ∈ [0, 1].
    /// 1 when one span lies inside the other, 0 when they are orthogonal;
    /// two columns of which only one lies in the other span give ½, not 1
    /// (a per-column maximum would call them the same effect).
    pub fn overlap(&self, other: &Basis) -> f64 {
        let r = self.rank().min(other.rank());
        if r == 0 {
            return 0.0;
        }
        let ss: f64 = self
            .vectors()
            .flat_map(|a| other.vectors().map(move |b| dot(a, b).powi(2)))
            .sum();
        (ss / r as f64).clamp(0.0, 1.0)
    }

    /// v − P v: the part of `v` orthogonal to the span.
    pub fn residual(&self, v: &[f64]) -> Vec<f64> {
        self.residuals(&[v]).pop().unwrap_or_default()
    }

    /// Uᵀv for each of `vs` (all of the basis' length): one pass over the
    /// basis in blocks of rows.
    pub fn coefficients(&self, vs: &[&[f64]]) -> Vec<Vec<f64>> {
        let n = self.u.first().map_or(0, Vec::len);
        let mut coef = vec![vec![0.0; self.rank()]; vs.len()];
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            for (k, u) in self.vectors().enumerate() {
                let ub = &u[start..end];
                for (c, v) in coef.iter_mut().zip(vs) {
                    c[k] += dot(ub, &v[start..end]);
                }
            }
            start = end;
        }
        coef
    }

    /// The residual sum of squares after adding the columns `cs` to the
    /// model whose residual is `resid` (orthogonal to this basis; its sum of
    /// squares `rss`), the model partialled out — [`small_fit`]'s `rss` on
    /// the partialled columns, from sums alone: rss − bᵀS⁺b with b = Cᵀr
    /// (= (C − UUᵀC)ᵀr, r being orthogonal to U) and S = CᵀC − (UᵀC)ᵀ(UᵀC),
    /// the partialled columns' Gram matrix. One pass over the basis instead
    /// of two, and no partialled copy; `coef` is each column's Uᵀc
    /// ([`Basis::coefficients`]). A column with less than 10⁻¹² of its sum
    /// of squares outside the span adds nothing (its S would be round-off).
    pub fn rss_added(cs: &[&[f64]], coef: &[Vec<f64>], resid: &[f64], rss: f64) -> f64 {
        let keep: Vec<usize> = (0..cs.len())
            .filter(|&i| {
                let cc = dot(cs[i], cs[i]);
                cc > 0.0 && cc - dot(&coef[i], &coef[i]) > 1e-12 * cc
            })
            .collect();
        let k = keep.len();
        if k == 0 {
            return rss;
        }
        let s = DMatrix::from_fn(k, k, |a, b| {
            let (i, j) = (keep[a], keep[b]);
            dot(cs[i], cs[j]) - dot(&coef[i], &coef[j])
        });
        let scale: Vec<f64> = (0..k).map(|a| s[(a, a)].sqrt()).collect();
        let g = DMatrix::from_fn(k, k, |a, b| s[(a, b)] / (scale[a] * scale[b]));
        let b = DVector::from_fn(k, |a, _| dot(cs[keep[a]], resid) / scale[a]);
        let (inv, _) = pinv_sym(&g);
        (rss - b.dot(&(&inv * &b))).max(0.0)
    }

    /// v − P v for each of `vs` (all of the basis' length): the basis is read
    /// twice in all — once for the coefficients Uᵀv of every column, once to
    /// subtract U·(Uᵀv) — in blocks of rows that stay in cache, instead of
    /// twice per basis vector and column (the projection is the inner loop
    /// of every candidate search: at a million rows U is 8 MB per vector).
    pub fn residuals(&self, vs: &[&[f64]]) -> Vec<Vec<f64>> {
        let n = self.u.first().map_or(0, Vec::len);
        let basis: Vec<&[f64]> = self.vectors().collect();
        let r = basis.len();
        let coef = self.coefficients(vs).concat();
        let mut out: Vec<Vec<f64>> = vs.iter().map(|v| v.to_vec()).collect();
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            for (k, u) in basis.iter().enumerate() {
                let ub = &u[start..end];
                for (j, o) in out.iter_mut().enumerate() {
                    let c = coef[j * r + k];
                    for (oi, ui) in o[start..end].iter_mut().zip(ub) {
                        *oi -= c * ui;
                    }
                }
            }
            start = end;
        }
        out
    }
}

/// Least squares of `y` on a few columns: coefficients, residual sum of
/// squares and (XᵀX)⁻¹ (the coefficient covariance up to σ²).
#[derive(Clone, Debug)]
pub struct SmallFit {
    /// Coefficients in the columns' own units.
    pub beta: Vec<f64>,
    /// Residual sum of squares.
    pub rss: f64,
    /// (XᵀX)⁺ in the columns' own units.
    pub xtx_inv: DMatrix<f64>,
    /// Numerical rank of the columns.
    pub rank: usize,
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix, with its rank.
fn pinv_sym(g: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let k = g.nrows();
    if k == 0 {
        return (DMatrix::zeros(0, 0), 0);
    }
    let eig = SymmetricEigen::new(g.clone());
    let emax = eig.eigenvalues.iter().copied().fold(0.0f64, f64::max);
    let mut inv = DMatrix::zeros(k, k);
    let mut rank = 0;
    for (i, &e) in eig.eigenvalues.iter().enumerate() {
        // Eigenvalues of a Gram matrix are squared singular values.
        if e > RANK_TOL * RANK_TOL * 1e2 * emax && e > 0.0 {
            rank += 1;
            let v = eig.eigenvectors.column(i);
            inv += (v * v.transpose()) / e;
        }
    }
    (inv, rank)
}

/// A column scale that is never zero: a column with no sum keeps 1.
fn nonzero(s: f64) -> f64 {
    if s > 0.0 {
        s
    } else {
        1.0
    }
}

/// The solve [`small_fit`] and [`pinv_solve`] share: the Gram matrix Σccᵀ
/// and Σcy divided by a per-column `scale` (unit scale for every column,
/// so the rank tolerance means the same for a column in K and one in mm),
/// the pseudo-inverse of the scaled matrix with its rank, and the
/// coefficients back in the columns' own units. Returns (β, (G_s)⁺, rank).
fn scaled_pinv_solve(
    g: &DMatrix<f64>,
    cy: &DVector<f64>,
    scale: &[f64],
) -> (Vec<f64>, DMatrix<f64>, usize) {
    let k = g.nrows();
    let gs = DMatrix::from_fn(k, k, |i, j| g[(i, j)] / (scale[i] * scale[j]));
    let b = DVector::from_fn(k, |i, _| cy[i] / scale[i]);
    let (inv, rank) = pinv_sym(&gs);
    let beta_s = &inv * b;
    let beta = (0..k).map(|i| beta_s[i] / scale[i]).collect();
    (beta, inv, rank)
}

/// The least-squares coefficients from a Gram matrix Σccᵀ and Σcy, as
/// [`small_fit`] solves them: columns scaled to unit diagonal, the
/// pseudo-inverse with its rank tolerance (zero for a column with no sum).
/// Never refuses: a candidate's few columns are judged by their rank, not
/// by a condition number (unlike `fit`'s [`super::lsq::solve_gram`], which
/// refuses ill-conditioned sums and falls back to a QR of the rows).
pub fn pinv_solve(g: &DMatrix<f64>, cy: &DVector<f64>) -> DVector<f64> {
    let scale: Vec<f64> = (0..g.nrows()).map(|i| nonzero(g[(i, i)].sqrt())).collect();
    DVector::from_vec(scaled_pinv_solve(g, cy, &scale).0)
}

/// Least squares of `y` on `cols` (all of length `y.len()`), each column
/// scaled to unit RMS.
pub fn small_fit(cols: &[Vec<f64>], y: &[f64]) -> SmallFit {
    let k = cols.len();
    let scale: Vec<f64> = cols.iter().map(|c| nonzero(rms(c))).collect();
    let g = DMatrix::from_fn(k, k, |i, j| dot(&cols[i], &cols[j]));
    let cy = DVector::from_fn(k, |i, _| dot(&cols[i], y));
    let (beta, inv, rank) = scaled_pinv_solve(&g, &cy, &scale);
    let mut rss = 0.0;
    for (r, yv) in y.iter().enumerate() {
        let f: f64 = (0..k).map(|i| beta[i] * cols[i][r]).sum();
        rss += (yv - f).powi(2);
    }
    let xtx_inv = DMatrix::from_fn(k, k, |i, j| inv[(i, j)] / (scale[i] * scale[j]));
    SmallFit {
        beta,
        rss,
        xtx_inv,
        rank,
    }
}

/// Block hold-out refits of a fixed model plus a few extra columns. The
/// model's per-fold Gram sums are computed once; each candidate adds only
/// its own cross products.
#[derive(Clone, Debug)]
pub struct HoldOut {
    fold: Vec<usize>,
    nfolds: usize,
    /// The model's columns (shared with the model state, not copied: at a
    /// million rows each copy is ~8 MB per column), the nonzero ones used
    /// scaled to unit RMS: `cols[j][r] / scale[j]` for `(j, scale)` in `used`.
    cols: Arc<Vec<Vec<f64>>>,
    used: Vec<(usize, f64)>,
    y: Vec<f64>,
    /// Per-fold Σ x xᵀ over the fold's rows (model columns).
    gram: Vec<DMatrix<f64>>,
    /// Per-fold Σ x y.
    xy: Vec<DVector<f64>>,
}

impl HoldOut {
    /// Prepares the model `cols` for hold-out refits with `fold[row]` ∈
    /// 0..nfolds giving each row's block.
    pub fn new(cols: Arc<Vec<Vec<f64>>>, y: &[f64], fold: &[usize], nfolds: usize) -> HoldOut {
        let used: Vec<(usize, f64)> = cols
            .iter()
            .enumerate()
            .filter_map(|(j, c)| {
                let s = rms(c);
                (s > 0.0).then_some((j, s))
            })
            .collect();
        let p = used.len();
        let mut g_raw = vec![0.0; nfolds * p * p];
        let mut xy_raw = vec![0.0; nfolds * p];
        let mut x = vec![0.0; p];
        for (r, &f) in fold.iter().enumerate() {
            for (xj, &(j, s)) in x.iter_mut().zip(&used) {
                *xj = cols[j][r] / s;
            }
            let g = &mut g_raw[f * p * p..(f + 1) * p * p];
            for i in 0..p {
                for j in 0..p {
                    g[i * p + j] += x[i] * x[j];
                }
                xy_raw[f * p + i] += x[i] * y[r];
            }
        }
        let gram = (0..nfolds)
            .map(|f| DMatrix::from_row_slice(p, p, &g_raw[f * p * p..(f + 1) * p * p]))
            .collect();
        let xy = (0..nfolds)
            .map(|f| DVector::from_column_slice(&xy_raw[f * p..(f + 1) * p]))
            .collect();
        HoldOut {
            fold: fold.to_vec(),
            nfolds,
            cols,
            used,
            y: y.to_vec(),
            gram,
            xy,
        }
    }

    /// RMS of the held-out residuals (each block predicted by a fit to the
    /// others) of the model plus `extra` columns. `None` when a block cannot
    /// be predicted (no rows left to fit).
    pub fn rms(&self, extra: &[Vec<f64>]) -> Option<f64> {
        let p = self.used.len();
        let extra: Vec<Vec<f64>> = extra
            .iter()
            .filter_map(|c| {
                let s = rms(c);
                (s > 0.0).then(|| c.iter().map(|v| v / s).collect())
            })
            .collect();
        let k = extra.len();
        let q = p + k;
        let nf = self.nfolds;
        // Per-fold cross products of the extra columns, accumulated in plain
        // arrays (row-major p×k, k×k, k per fold) and converted once.
        let mut mc_raw = vec![0.0; nf * p * k];
        let mut cc_raw = vec![0.0; nf * k * k];
        let mut cy_raw = vec![0.0; nf * k];
        for (r, &f) in self.fold.iter().enumerate() {
            for a in 0..k {
                let ca = extra[a][r];
                if ca == 0.0 {
                    continue;
                }
                let mc = &mut mc_raw[f * p * k..(f + 1) * p * k];
                for (j, &(c, s)) in self.used.iter().enumerate() {
                    mc[j * k + a] += self.cols[c][r] / s * ca;
                }
                for b in 0..k {
                    cc_raw[f * k * k + a * k + b] += ca * extra[b][r];
                }
                cy_raw[f * k + a] += ca * self.y[r];
            }
        }
        let g_mc: Vec<DMatrix<f64>> = (0..nf)
            .map(|f| DMatrix::from_row_slice(p, k, &mc_raw[f * p * k..(f + 1) * p * k]))
            .collect();
        let g_cc: Vec<DMatrix<f64>> = (0..nf)
            .map(|f| DMatrix::from_row_slice(k, k, &cc_raw[f * k * k..(f + 1) * k * k]))
            .collect();
        let cy: Vec<DVector<f64>> = (0..nf)
            .map(|f| DVector::from_column_slice(&cy_raw[f * k..(f + 1) * k]))
            .collect();
        let sum_m = |v: &Vec<DMatrix<f64>>| {
            v.iter()
                .fold(DMatrix::zeros(v[0].nrows(), v[0].ncols()), |acc, m| acc + m)
        };
        let tot_mm = sum_m(&self.gram);
        let tot_mc = sum_m(&g_mc);
        let tot_cc = sum_m(&g_cc);
        let tot_my = self.xy.iter().fold(DVector::zeros(p), |a, v| a + v);
        let tot_cy = cy.iter().fold(DVector::zeros(k), |a, v| a + v);
        let mut betas = Vec::with_capacity(nf);
        for f in 0..nf {
            let mut g = DMatrix::zeros(q, q);
            let mut b = DVector::zeros(q);
            g.view_mut((0, 0), (p, p))
                .copy_from(&(&tot_mm - &self.gram[f]));
            let mc = &tot_mc - &g_mc[f];
            g.view_mut((0, p), (p, k)).copy_from(&mc);
            g.view_mut((p, 0), (k, p)).copy_from(&mc.transpose());
            g.view_mut((p, p), (k, k)).copy_from(&(&tot_cc - &g_cc[f]));
            b.rows_mut(0, p).copy_from(&(&tot_my - &self.xy[f]));
            b.rows_mut(p, k).copy_from(&(&tot_cy - &cy[f]));
            if g.diagonal().iter().all(|d| *d == 0.0) {
                return None;
            }
            let (inv, _) = pinv_sym(&g);
            betas.push(inv * b);
        }
        let betas: Vec<Vec<f64>> = betas.iter().map(|b| b.iter().copied().collect()).collect();
        let mut ss = 0.0;
        let n = self.fold.len();
        for (r, &f) in self.fold.iter().enumerate() {
            let beta = &betas[f];
            let mut pred = 0.0;
            for (b, &(c, s)) in beta.iter().zip(&self.used) {
                pred += b * (self.cols[c][r] / s);
            }
            for (b, c) in beta[p..].iter().zip(&extra) {
                pred += b * c[r];
            }
            ss += (self.y[r] - pred).powi(2);
        }
        (n > 0).then(|| (ss / n as f64).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_removes_span_and_keeps_the_rest() {
        let n = 50;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let one = vec![1.0; n];
        let x2: Vec<f64> = x.iter().map(|v| v * v).collect();
        // A duplicated column must not raise the rank.
        let b = Basis::new(&[one.clone(), x.clone(), x.clone()], n);
        assert_eq!(b.rank(), 2);
        let r = b.residual(&x.iter().map(|v| 3.0 * v + 1.0).collect::<Vec<_>>());
        assert!(r.iter().all(|v| v.abs() < 1e-9));
        let r2 = b.residual(&x2);
        assert!(dot(&r2, &r2) > 1e-3);
    }

    #[test]
    fn cholesky_qr2_is_orthonormal_and_projects_as_the_svd_does() {
        // A cubic in three normalised coordinates plus a lagged-temperature
        // like column: the model columns of a diagnosis.
        let n = 3000;
        let mut rng = trueaxis_test_support::SplitMix64::new(15);
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                [
                    rng.unit() * 2.0 - 1.0,
                    rng.unit() * 2.0 - 1.0,
                    rng.unit() * 2.0 - 1.0,
                ]
            })
            .collect();
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for e in [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [2, 0, 0],
            [1, 1, 0],
            [3, 0, 0],
            [1, 1, 1],
        ] {
            cols.push(
                pts.iter()
                    .map(|p| (0..3).map(|a| p[a].powi(e[a])).product())
                    .collect(),
            );
        }
        cols.push(
            (0..n)
                .map(|i| 3.0 + 0.2 * (i as f64 / 400.0).tanh())
                .collect(),
        );
        let fast = Basis::new(&cols, n);
        let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
        let svd = Basis::by_svd(&refs, n);
        assert_eq!(fast.rank(), cols.len());
        assert_eq!(svd.rank(), cols.len());
        for (i, a) in fast.vectors().enumerate() {
            for (j, b) in fast.vectors().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot(a, b) - want).abs() < 1e-12, "{i} {j} {}", dot(a, b));
            }
        }
        let v: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let (rf, rs) = (fast.residual(&v), svd.residual(&v));
        let d: f64 = rf
            .iter()
            .zip(&rs)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(d < 1e-12, "{d}");
    }

    #[test]
    fn rss_from_sums_is_the_partialled_fits_rss() {
        let n = 2000;
        let mut rng = trueaxis_test_support::SplitMix64::new(9);
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64 - 0.5).collect();
        let model = vec![vec![1.0; n], x.clone(), x.iter().map(|v| v * v).collect()];
        let b = Basis::new(&model, n);
        let y: Vec<f64> = x
            .iter()
            .map(|v| 2.0 + v + 0.3 * (40.0 * v).sin() + 0.01 * rng.normal())
            .collect();
        let resid = b.residual(&y);
        let rss = dot(&resid, &resid);
        // Two informative columns, one nearly in the span, one exactly in it
        // (a multiple of x: adds nothing, as the partialled fit says).
        let cands: Vec<Vec<f64>> = vec![
            x.iter().map(|v| (40.0 * v).sin()).collect(),
            x.iter().map(|v| (40.0 * v).cos()).collect(),
            x.iter()
                .map(|v| v * v * v + 1e-4 * (7.0 * v).sin())
                .collect(),
            x.iter().map(|v| 3.0 * v).collect(),
        ];
        let refs: Vec<&[f64]> = cands.iter().map(Vec::as_slice).collect();
        let coef = b.coefficients(&refs);
        // The partialled fit is given the set without the in-span column:
        // partialled, that column is round-off, which `small_fit` scales up
        // to unit RMS and fits (a spurious 10⁻⁵ of the rss here); the sums
        // see that nothing of it lies outside the span.
        for set in [&[0usize][..], &[0, 1], &[2], &[3], &[0, 3], &[0, 1, 2]] {
            let cs: Vec<&[f64]> = set.iter().map(|&i| refs[i]).collect();
            let co: Vec<Vec<f64>> = set.iter().map(|&i| coef[i].clone()).collect();
            let fast = Basis::rss_added(&cs, &co, &resid, rss);
            let outside: Vec<&[f64]> = set.iter().filter(|&&i| i != 3).map(|&i| refs[i]).collect();
            let parts = b.residuals(&outside);
            let slow = small_fit(&parts, &resid).rss;
            assert!(
                (fast - slow).abs() <= 1e-9 * rss,
                "{set:?}: {fast} vs {slow} (rss {rss})"
            );
        }
        // The sine explains most of the residual: the sums see it.
        let cs = [refs[0], refs[1]];
        assert!(Basis::rss_added(&cs, &coef[..2], &resid, rss) < 0.01 * rss);
    }

    #[test]
    fn nearly_dependent_columns_take_the_svd_and_keep_its_rank() {
        // x and x + 1e-8·noise: condition number ~10⁸, past the fast path's
        // 10⁶ (its Gram matrix could not tell the second direction), but
        // above the SVD's 10⁻⁹ rank tolerance: two directions, as the SVD says.
        let n = 500;
        let mut rng = trueaxis_test_support::SplitMix64::new(3);
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64 - 0.5).collect();
        let y: Vec<f64> = x.iter().map(|v| v + 1e-8 * rng.normal()).collect();
        let b = Basis::new(&[x.clone(), y.clone()], n);
        assert_eq!(b.rank(), 2);
        assert!(whitening(gram(&[&x, &y]), &[1.0, 1.0]).is_none());
    }

    #[test]
    fn overlap_is_the_mean_share_over_the_smaller_span() {
        let n = 200;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64 - 0.5).collect();
        let x2: Vec<f64> = x.iter().map(|v| v * v - 1.0 / 12.0).collect();
        let s: Vec<f64> = x.iter().map(|v| (40.0 * v).sin()).collect();
        let a = Basis::new(&[x.clone(), x2.clone()], n);
        // Nested: x alone lies inside span(x, x²).
        assert!((a.overlap(&Basis::new(std::slice::from_ref(&x), n)) - 1.0).abs() < 1e-9);
        // Only one of two directions shared: about ½, where the largest
        // per-column share would say 100 %.
        let b = Basis::new(&[x.clone(), s.clone()], n);
        let ov = a.overlap(&b);
        assert!(ov > 0.45 && ov < 0.6, "{ov}");
        assert!((ov - b.overlap(&a)).abs() < 1e-12);
        // Unrelated.
        let c = Basis::new(
            &[(0..n)
                .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
                .collect()],
            n,
        );
        assert!(a.overlap(&c) < 0.01);
    }

    #[test]
    fn small_fit_recovers_coefficients() {
        let n = 40;
        let a: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
        let c: Vec<f64> = (0..n).map(|i| 1000.0 * (i as f64 * 0.17).cos()).collect();
        let y: Vec<f64> = (0..n).map(|i| 2.0 * a[i] - 0.004 * c[i]).collect();
        let f = small_fit(&[a, c], &y);
        assert!((f.beta[0] - 2.0).abs() < 1e-9 && (f.beta[1] + 0.004).abs() < 1e-12);
        assert!(f.rss < 1e-18);
    }

    #[test]
    fn hold_out_of_exact_model_is_zero_and_detects_missing_column() {
        let n = 60;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / 10.0).collect();
        let one = vec![1.0; n];
        let s: Vec<f64> = x.iter().map(|v| (3.0 * v).sin()).collect();
        let y: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * x[i] + s[i]).collect();
        let fold: Vec<usize> = (0..n).map(|i| (i / 6) % 5).collect();
        let h = HoldOut::new(Arc::new(vec![one, x]), &y, &fold, 5);
        let without = h.rms(&[]).unwrap();
        let with = h.rms(&[s]).unwrap();
        assert!(without > 0.3, "{without}");
        assert!(with < 1e-9, "{with}");
    }
}
