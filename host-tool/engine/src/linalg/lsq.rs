//! Weighted linear least squares for compensation models: the design matrix
//! of a term set over chosen rows, and a solver that tells the truth about
//! the problem — condition number, rank, the columns that are collinear, and
//! the standard deviation of every coefficient.
//!
//! Method: rows are multiplied by √w (w = 1/u², so a row with a huge
//! uncertainty has no say), every column is scaled to unit 2-norm (the
//! condition number then measures real collinearity, not units), a
//! Householder QR reduces the tall m×n problem to n×n, and an SVD of R gives
//! the solution, the singular values and — for a rank-deficient problem —
//! the right singular vectors that name the collinear columns. QR first keeps
//! the cost at O(m·n²) with a tiny SVD: cubic19 on the 2057-point grid is a
//! few hundred microseconds (BENCHMARKS.md).

// Numerical code indexes several parallel arrays by the same index;
// index loops read closer to the formulas than zipped iterators.
#![allow(clippy::needless_range_loop)]

use std::collections::HashSet;

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use crate::data::Dataset;
use crate::features::{Feature, Norm};

/// A column-scaled condition number above this is reported as ill-conditioned
/// (coefficients then trade off against each other; predictions at the
/// measured points stay good, extrapolation and coefficient values do not).
pub const ILL_CONDITIONED: f64 = 1e6;

/// Singular values below `RANK_TOL × σ_max` (of the column-scaled matrix)
/// count as zero: such a combination of columns is zero to ten digits on the
/// measured rows, and its coefficients would be noise amplified by 10¹⁰.
pub const RANK_TOL: f64 = 1e-10;

/// Why a least-squares problem cannot be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LsqError {
    /// Fewer rows than unknowns.
    #[error("{rows} rows for {cols} unknowns")]
    TooFewRows {
        /// Rows (after weighting).
        rows: usize,
        /// Columns (unknowns).
        cols: usize,
    },
    /// The columns are linearly dependent on these rows.
    #[error("rank {rank} < {cols} columns; collinear column groups (indices): {groups:?}")]
    RankDeficient {
        /// Numerical rank.
        rank: usize,
        /// Number of columns.
        cols: usize,
        /// For each (numerically) zero singular value, the columns that take
        /// part in the vanishing combination (|v_j| ≥ 0.1 % of the largest, in column-scaled units).
        groups: Vec<Vec<usize>>,
    },
    /// A weight is zero, negative or not finite, or a value is not finite.
    #[error("{0}")]
    BadInput(String),
}

/// The solution of a weighted least-squares problem, in the units of `b`.
#[derive(Debug, Clone, PartialEq)]
pub struct LsqSolution {
    /// Coefficients, one per column.
    pub coef: DVector<f64>,
    /// Standard deviation of each coefficient, √(σ̂²·[(AᵀWA)⁻¹]_jj) with
    /// σ̂² = rss/dof; NaN when dof = 0 (an exact fit says nothing about noise).
    pub coef_sd: DVector<f64>,
    /// Weighted residual sum of squares Σ w·r².
    pub rss: f64,
    /// Residual degrees of freedom, rows − columns.
    pub dof: usize,
    /// Numerical rank (= columns for a returned solution unless it came from
    /// [`solve_min_norm`]).
    pub rank: usize,
    /// σ_max/σ_min of the weighted, column-scaled matrix (∞ when rank-deficient).
    pub condition_number: f64,
}

/// The design matrix: one row per entry of `rows`, one column per feature,
/// in the units [`Feature::column`] gives (coefficients in µm).
pub fn design_matrix(
    data: &Dataset,
    norm: &Norm,
    features: &[Feature],
    rows: &[usize],
) -> Result<DMatrix<f64>> {
    let mut a = DMatrix::zeros(rows.len(), features.len());
    // Monomials (most columns of every seed) come from a table of the
    // powers u_a^k of the selected rows, built once: ten times faster than
    // evaluating each feature over the whole data set, and bit-identical to
    // `Feature::column` (same powi, same product order x·y·z).
    let max_exp = features
        .iter()
        .filter_map(|f| match f {
            Feature::Monomial { exp } => exp.iter().copied().max(),
            _ => None,
        })
        .max()
        .unwrap_or(0) as usize;
    let mut pow: [Vec<f64>; 3] = Default::default();
    if features
        .iter()
        .any(|f| matches!(f, Feature::Monomial { .. }))
    {
        for axis in 0..3 {
            let mut p = vec![1.0; rows.len() * (max_exp + 1)];
            if let Some(col) = &data.pos_mm[axis] {
                for (i, &r) in rows.iter().enumerate() {
                    let u = norm.u(axis, col[r]);
                    for k in 1..=max_exp {
                        p[k * rows.len() + i] = u.powi(k as i32);
                    }
                }
            } else {
                // An absent axis sits at u = 0: u^0 = 1, higher powers 0.
                for v in &mut p[rows.len()..] {
                    *v = 0.0;
                }
            }
            pow[axis] = p;
        }
    }
    let m = rows.len();
    for (j, f) in features.iter().enumerate() {
        if let Feature::Monomial { exp } = f {
            let [ex, ey, ez] = exp.map(usize::from);
            let (px, py, pz) = (
                &pow[0][ex * m..(ex + 1) * m],
                &pow[1][ey * m..(ey + 1) * m],
                &pow[2][ez * m..(ez + 1) * m],
            );
            let mut col = a.column_mut(j);
            for i in 0..m {
                col[i] = px[i] * py[i] * pz[i];
            }
            continue;
        }
        let col = f.column(data, norm)?;
        for (i, &r) in rows.iter().enumerate() {
            a[(i, j)] = col[r];
        }
    }
    Ok(a)
}

/// Number of distinct rows of `a` (bit-exact): the number of distinct points
/// in the model's own coordinates. Fewer than the column count means the
/// model cannot be determined whatever the solver does (docs/cli.md § Measurement CSV).
pub fn distinct_rows(a: &DMatrix<f64>) -> usize {
    distinct_rows_up_to(a, usize::MAX)
}

/// [`distinct_rows`], counting no further than `cap`: whether a model of
/// `cap` terms has enough points is known once `cap` distinct rows are
/// seen (a few dozen rows of a million-row capture), and a count below
/// `cap` is exact.
pub fn distinct_rows_up_to(a: &DMatrix<f64>, cap: usize) -> usize {
    let mut seen: HashSet<Vec<u64>> = HashSet::new();
    let mut row = Vec::with_capacity(a.ncols());
    for i in 0..a.nrows() {
        if seen.len() >= cap {
            break;
        }
        // +0.0 so that −0.0 and 0.0 count as the same point.
        row.clear();
        row.extend(a.row(i).iter().map(|v| (v + 0.0).to_bits()));
        if !seen.contains(row.as_slice()) {
            seen.insert(row.clone());
        }
    }
    seen.len()
}

/// Weighted least squares min Σ wᵢ(bᵢ − aᵢ·x)²; `weights` = None means all 1.
///
/// Fails with [`LsqError`] (inside the `anyhow::Error`, so callers can
/// `downcast_ref` and name the columns) when there are fewer rows than
/// columns or the columns are collinear.
pub fn solve(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    weights: Option<&DVector<f64>>,
) -> Result<LsqSolution> {
    let b = DMatrix::from_column_slice(b.len(), 1, b.as_slice());
    Ok(solve_inner(a, &b, weights, false)?.remove(0))
}

/// [`solve`] for several right-hand sides (the columns of `b`) on the same
/// design and weights — the three error targets of a seed model measured on
/// the same rows — with one QR and one SVD: one solution per column, each
/// equal to what [`solve`] gives for that column alone.
pub fn solve_multi(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    weights: Option<&DVector<f64>>,
) -> Result<Vec<LsqSolution>> {
    solve_inner(a, b, weights, false)
}

/// Like [`solve`], but a rank-deficient problem gets the minimum-norm
/// solution (truncated SVD) instead of an error. Used by block hold-out,
/// where leaving a block out can make a well-posed model briefly
/// undetermined; the held-out error then shows the price honestly.
pub fn solve_min_norm(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    weights: Option<&DVector<f64>>,
) -> Result<LsqSolution> {
    let b = DMatrix::from_column_slice(b.len(), 1, b.as_slice());
    Ok(solve_inner(a, &b, weights, true)?.remove(0))
}

fn solve_inner(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    weights: Option<&DVector<f64>>,
    allow_deficient: bool,
) -> Result<Vec<LsqSolution>> {
    let (m, n) = a.shape();
    let nrhs = b.ncols();
    if b.nrows() != m || nrhs == 0 {
        bail!(LsqError::BadInput(format!(
            "{m} rows but {} right-hand sides",
            b.nrows()
        )));
    }
    if n == 0 {
        bail!(LsqError::BadInput("no columns to fit".into()));
    }
    if m < n && !allow_deficient {
        bail!(LsqError::TooFewRows { rows: m, cols: n });
    }
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        bail!(LsqError::BadInput(
            "non-finite value in the least-squares problem".into()
        ));
    }
    // Row weighting by √w.
    let mut aw = a.clone();
    let mut bw = b.clone();
    if let Some(w) = weights {
        if w.len() != m {
            bail!(LsqError::BadInput(format!(
                "{m} rows but {} weights",
                w.len()
            )));
        }
        if let Some(bad) = w.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
            bail!(LsqError::BadInput(format!(
                "weight {bad} is not a positive finite number (u_um must be > 0)"
            )));
        }
        for i in 0..m {
            let s = w[i].sqrt();
            aw.row_mut(i).scale_mut(s);
            bw.row_mut(i).scale_mut(s);
        }
    }
    // Column scaling to unit norm; an all-zero column is its own collinear
    // group. "Zero" is relative to the largest column: sin(2π·p/period)
    // sampled at multiples of half the period is 1e-15, not 0, and scaling
    // it to unit norm would fit rounding noise.
    let mut scale = DVector::zeros(n);
    let mut zero_cols = Vec::new();
    let norms: Vec<f64> = (0..n).map(|j| aw.column(j).norm()).collect();
    let largest = norms.iter().copied().fold(0.0, f64::max);
    for j in 0..n {
        let c = norms[j];
        if c > 1e-12 * largest {
            scale[j] = c;
            aw.column_mut(j).unscale_mut(c);
        } else {
            scale[j] = 1.0;
            zero_cols.push(j);
        }
    }
    // Reduce to a square problem: R x = Qᵀb (QR of the scaled m×n matrix).
    let (r, qtb) = if m > n {
        let qr = aw.qr();
        let mut qtb_full = bw.clone();
        qr.q_tr_mul(&mut qtb_full);
        (qr.r(), qtb_full.rows(0, n).into_owned())
    } else {
        (aw, bw.clone())
    };
    let svd = nalgebra::linalg::SVD::new(r, true, true);
    let (Some(u), Some(v_t)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        bail!(LsqError::BadInput("SVD did not converge".into()));
    };
    let s = &svd.singular_values;
    let s_max = s.iter().copied().fold(0.0, f64::max);
    let tol = RANK_TOL * s_max;
    let rank = s.iter().filter(|&&v| v > tol).count();
    let k_cols = s.len();
    if (rank < n || !zero_cols.is_empty()) && !allow_deficient {
        let mut groups: Vec<Vec<usize>> = zero_cols.iter().map(|&j| vec![j]).collect();
        for k in 0..k_cols {
            if s[k] > tol {
                continue;
            }
            let v = v_t.row(k);
            let vmax = v.iter().fold(0.0f64, |acc, x| acc.max(x.abs()));
            let g: Vec<usize> = (0..n)
                .filter(|&j| v[j].abs() >= 1e-3 * vmax && !zero_cols.contains(&j))
                .collect();
            if g.len() > 1 && !groups.contains(&g) {
                groups.push(g);
            }
        }
        bail!(LsqError::RankDeficient {
            rank: rank.min(n - zero_cols.len()),
            cols: n,
            groups,
        });
    }
    // x_scaled = V S⁺ Uᵀ (Qᵀb); the truncated pseudo-inverse keeps the
    // minimum-norm solution when rank-deficient (only reached with allow_deficient).
    let utb = u.tr_mul(&qtb);
    let mut var_scaled: DVector<f64> = DVector::zeros(n);
    let mut x: DMatrix<f64> = DMatrix::zeros(n, nrhs);
    for k in 0..k_cols {
        if s[k] <= tol {
            continue;
        }
        for j in 0..n {
            var_scaled[j] += (v_t[(k, j)] / s[k]).powi(2);
        }
        for c in 0..nrhs {
            let coef_k = utb[(k, c)] / s[k];
            for j in 0..n {
                x[(j, c)] += v_t[(k, j)] * coef_k;
            }
        }
    }
    let s_min = s.iter().copied().fold(f64::INFINITY, f64::min);
    let condition_number = if rank < n || s_min <= 0.0 {
        f64::INFINITY
    } else {
        s_max / s_min
    };
    let dof = m.saturating_sub(rank);
    Ok((0..nrhs)
        .map(|c| {
            let coef = x.column(c).component_div(&scale);
            // Residuals from the weighted original problem (not Qᵀb
            // bookkeeping), so rss is exact even when the fit is nearly perfect.
            let resid = bw.column(c) - a_weighted_times(a, weights, &coef);
            let rss = resid.norm_squared();
            let sigma2 = if dof > 0 { rss / dof as f64 } else { f64::NAN };
            let coef_sd = DVector::from_fn(n, |j, _| (sigma2 * var_scaled[j]).sqrt() / scale[j]);
            LsqSolution {
                coef,
                coef_sd,
                rss,
                dof,
                rank,
                condition_number,
            }
        })
        .collect())
}

/// The condition number of a column-scaled Gram matrix (= the square of
/// the design's) below which the normal equations are solved instead of a
/// QR of the rows: up to it they lose at most ~ε·10⁸ ≈ 10⁻⁸ relative
/// accuracy before refinement (far below any coefficient's standard
/// deviation); above it, or with a zero column, the caller takes the QR
/// path, whose SVD also makes the rank decision and names collinear
/// columns. Shared by the fit, its block hold-out and the outlier screen.
pub const GRAM_MAX_CONDITION: f64 = 1e8;

/// Rows gathered per chunk of the Gram sums: a chunk of a 25-column design
/// (1024 × 25 × 8 B = 200 kB) stays in cache while its column products
/// are formed.
const GRAM_CHUNK: usize = 1024;

/// Weighted Gram sums of a least-squares problem over some of its rows:
/// `g` = AᵀWA (p × p, symmetric) and `r` = AᵀWB (p × right-hand sides),
/// for chosen columns of A and B. Sums over disjoint row sets add, so a
/// fit's Gram is the sum of its hold-out blocks' and a block's training
/// system is the total minus the block.
#[derive(Clone, Debug, PartialEq)]
pub struct Gram {
    /// AᵀWA.
    pub g: DMatrix<f64>,
    /// AᵀWB.
    pub r: DMatrix<f64>,
}

impl Gram {
    /// The sums over `rows` (indices into the rows of `a`, `b` and `w`) of
    /// the columns `cols` of `a` and `bcols` of `b`, each row weighted by
    /// `w` (None: 1).
    pub fn over(
        a: &DMatrix<f64>,
        cols: &[usize],
        b: &DMatrix<f64>,
        bcols: &[usize],
        w: Option<&DVector<f64>>,
        rows: &[usize],
    ) -> Gram {
        let mut s = Gram {
            g: DMatrix::zeros(cols.len(), cols.len()),
            r: DMatrix::zeros(cols.len(), bcols.len()),
        };
        s.add_rows(a, cols, b, bcols, w, rows, 1.0);
        s
    }

    /// The sums of disjoint row sets added up: the Gram of their union
    /// (None for none).
    pub fn total(parts: &[Gram]) -> Option<Gram> {
        let mut t = parts.first()?.clone();
        for part in &parts[1..] {
            t.g += &part.g;
            t.r += &part.r;
        }
        Some(t)
    }

    /// Adds `sign` × the sums over `rows` (see [`Gram::over`]): −1 takes
    /// rows out (the outlier screen's flagged readings).
    #[allow(clippy::too_many_arguments)]
    pub fn add_rows(
        &mut self,
        a: &DMatrix<f64>,
        cols: &[usize],
        b: &DMatrix<f64>,
        bcols: &[usize],
        w: Option<&DVector<f64>>,
        rows: &[usize],
        sign: f64,
    ) {
        self.accumulate(a, cols, b, bcols, w, rows, sign, true);
    }

    /// AᵀWB alone over `rows` (the `r` of [`Gram::over`] without the p²
    /// products of `g`): a refinement step's AᵀW·residual.
    pub fn rhs_over(
        a: &DMatrix<f64>,
        cols: &[usize],
        b: &DMatrix<f64>,
        bcols: &[usize],
        w: Option<&DVector<f64>>,
        rows: &[usize],
    ) -> DMatrix<f64> {
        let mut s = Gram {
            g: DMatrix::zeros(cols.len(), cols.len()),
            r: DMatrix::zeros(cols.len(), bcols.len()),
        };
        s.accumulate(a, cols, b, bcols, w, rows, 1.0, false);
        s.r
    }

    #[allow(clippy::too_many_arguments)]
    fn accumulate(
        &mut self,
        a: &DMatrix<f64>,
        cols: &[usize],
        b: &DMatrix<f64>,
        bcols: &[usize],
        w: Option<&DVector<f64>>,
        rows: &[usize],
        sign: f64,
        with_g: bool,
    ) {
        let (p, q) = (cols.len(), bcols.len());
        let width = p + q;
        // The products computed: [A B] with g, B alone without.
        let start = if with_g { 0 } else { p };
        let mut acc = DMatrix::zeros(p, width - start);
        // The chunk twice: `c` (rows × columns) and its transpose `ct`, the
        // p design columns then the q values, each row scaled by √w (as
        // the QR path weights rows). Two plain column-major matrices, so
        // that nalgebra hands their product to matrixmultiply's dgemm (SIMD
        // kernels chosen at run time).
        let mut c = DMatrix::<f64>::zeros(GRAM_CHUNK, width);
        let mut ct = DMatrix::<f64>::zeros(width, GRAM_CHUNK);
        let w = w.map(|w| w.as_slice());
        for chunk in rows.chunks(GRAM_CHUNK) {
            let m = chunk.len();
            let sources = (cols.iter().map(|&k| (a, k))).chain(bcols.iter().map(|&k| (b, k)));
            // Consecutive rows (the usual case: a target measured on
            // every row but a few outliers) are copied as slices.
            let first = chunk[0];
            let consecutive = consecutive(chunk);
            let cs = c.as_mut_slice();
            for (j, (mat, k)) in sources.enumerate() {
                let n = mat.nrows();
                let src = &mat.as_slice()[k * n..(k + 1) * n];
                let dst = &mut cs[j * GRAM_CHUNK..j * GRAM_CHUNK + m];
                if consecutive {
                    dst.copy_from_slice(&src[first..first + m]);
                } else {
                    for (d, &i) in dst.iter_mut().zip(chunk) {
                        *d = src[i];
                    }
                }
                if let Some(w) = w {
                    for (d, &i) in dst.iter_mut().zip(chunk) {
                        *d *= w[i].sqrt();
                    }
                }
            }
            // The transpose written row by row (contiguous stores; the
            // `width` columns are read as that many sequential streams).
            let cs = c.as_slice();
            for (l, out) in ct
                .as_mut_slice()
                .chunks_exact_mut(width)
                .take(m)
                .enumerate()
            {
                for (o, col) in out.iter_mut().zip(cs.chunks_exact(GRAM_CHUNK)) {
                    *o = col[l];
                }
            }
            acc.gemm(
                sign,
                &ct.view((0, 0), (p, m)),
                &c.view((0, start), (m, width - start)),
                1.0,
            );
        }
        // g from the upper triangle (the product's two halves may differ
        // in the last bit), r from the value columns.
        if with_g {
            for j in 0..p {
                for k in j..p {
                    self.g[(j, k)] += acc[(j, k)];
                    self.g[(k, j)] = self.g[(j, k)];
                }
            }
        }
        for j in 0..p {
            for k in 0..q {
                self.r[(j, k)] += acc[(j, p - start + k)];
            }
        }
    }
}

/// Whether `rows` are consecutive ascending indices (k, k+1, k+2, …): then
/// a slice of a column is read in place of a gather.
pub fn consecutive(rows: &[usize]) -> bool {
    rows.windows(2).all(|w| w[1] == w[0] + 1)
}

/// The solution of the normal equations (AᵀWA) x = AᵀWB from a [`Gram`]:
/// the column-scaled Gram's eigen-decomposition, kept so that a
/// refinement step ([`GramSolution::apply`]) costs no second one.
#[derive(Clone, Debug)]
pub struct GramSolution {
    /// Coefficients, p × right-hand sides.
    pub coef: DMatrix<f64>,
    /// [(AᵀWA)⁻¹]ⱼⱼ: times σ̂², the variance of coefficient j.
    pub inv_diag: DVector<f64>,
    /// σ_max/σ_min of the weighted, column-scaled design (the square root
    /// of the scaled Gram's eigenvalue ratio): what the QR path reports.
    pub condition_number: f64,
    /// Column scales √Gⱼⱼ.
    d: DVector<f64>,
    eig: nalgebra::SymmetricEigen<f64, nalgebra::Dyn>,
}

impl GramSolution {
    /// (AᵀWA)⁻¹ `rhs` (p × any) with the decomposition already made.
    pub fn apply(&self, rhs: &DMatrix<f64>) -> DMatrix<f64> {
        let v = &self.eig.eigenvectors;
        let mut z = rhs.clone();
        for (j, mut row) in z.row_iter_mut().enumerate() {
            row /= self.d[j];
        }
        let mut z = v.tr_mul(&z);
        for (k, mut row) in z.row_iter_mut().enumerate() {
            row /= self.eig.eigenvalues[k];
        }
        let mut x = v * z;
        for (j, mut row) in x.row_iter_mut().enumerate() {
            row /= self.d[j];
        }
        x
    }
}

/// Solves the normal equations of `gram`; None when they are not to be
/// trusted — a zero column (relative to the largest, as the QR path
/// decides), a non-finite sum, or a column-scaled condition number of
/// [`GRAM_MAX_CONDITION`] or more — and the caller takes the QR path.
pub fn solve_gram(gram: &Gram) -> Option<GramSolution> {
    let g = &gram.g;
    let p = g.nrows();
    if p == 0 || g.iter().chain(gram.r.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    let d = DVector::from_fn(p, |j, _| g[(j, j)].max(0.0).sqrt());
    let largest = d.max();
    if d.iter().any(|&v| v <= 1e-12 * largest) {
        return None;
    }
    let scaled = DMatrix::from_fn(p, p, |i, j| g[(i, j)] / (d[i] * d[j]));
    let eig = nalgebra::SymmetricEigen::new(scaled);
    let lmax = eig.eigenvalues.max();
    let lmin = eig.eigenvalues.min();
    if !(lmin > 0.0 && lmax / lmin < GRAM_MAX_CONDITION) {
        return None;
    }
    let inv_diag = DVector::from_fn(p, |j, _| {
        (0..p)
            .map(|k| eig.eigenvectors[(j, k)].powi(2) / eig.eigenvalues[k])
            .sum::<f64>()
            / (d[j] * d[j])
    });
    let mut sol = GramSolution {
        coef: DMatrix::zeros(p, gram.r.ncols()),
        inv_diag,
        condition_number: (lmax / lmin).sqrt(),
        d,
        eig,
    };
    sol.coef = sol.apply(&gram.r);
    Some(sol)
}

/// √W·A·x without forming √W·A again.
fn a_weighted_times(
    a: &DMatrix<f64>,
    weights: Option<&DVector<f64>>,
    x: &DVector<f64>,
) -> DVector<f64> {
    let mut y = a * x;
    if let Some(w) = weights {
        for i in 0..y.len() {
            y[i] *= w[i].sqrt();
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poly_problem(n_rows: usize) -> (DMatrix<f64>, DVector<f64>, [f64; 4]) {
        let coef = [1.5, -2.0, 0.25, 3.0];
        let a = DMatrix::from_fn(n_rows, 4, |i, j| {
            let u = -1.0 + 2.0 * i as f64 / (n_rows - 1) as f64;
            u.powi(j as i32)
        });
        let b = DVector::from_fn(n_rows, |i, _| (0..4).map(|j| a[(i, j)] * coef[j]).sum());
        (a, b, coef)
    }

    #[test]
    fn several_right_hand_sides_equal_separate_solves() {
        let (a, b, _) = poly_problem(40);
        let b2 = b.map(|v| (v * 1.7).sin());
        let b3 = DVector::from_fn(b.len(), |i, _| (i as f64 * 0.37).cos());
        let w = DVector::from_fn(b.len(), |i, _| 1.0 + (i % 5) as f64);
        let bm = DMatrix::from_columns(&[b.clone(), b2.clone(), b3.clone()]);
        let multi = solve_multi(&a, &bm, Some(&w)).unwrap();
        assert_eq!(multi.len(), 3);
        for (sol, rhs) in multi.iter().zip([&b, &b2, &b3]) {
            let one = solve(&a, rhs, Some(&w)).unwrap();
            assert!((&sol.coef - &one.coef).amax() < 1e-12 * one.coef.amax().max(1.0));
            assert!((&sol.coef_sd - &one.coef_sd).amax() < 1e-12 * one.coef_sd.amax().max(1.0));
            assert!((sol.rss - one.rss).abs() <= 1e-12 * rhs.norm_squared());
            assert_eq!((sol.dof, sol.rank), (one.dof, one.rank));
            assert_eq!(sol.condition_number, one.condition_number);
        }
        assert!(multi[1].rss > 0.0 && multi[0].coef != multi[1].coef);
    }

    #[test]
    fn exact_recovery_and_zero_residual() {
        let (a, b, coef) = poly_problem(30);
        let s = solve(&a, &b, None).unwrap();
        for j in 0..4 {
            assert!((s.coef[j] - coef[j]).abs() < 1e-12, "{j}: {}", s.coef[j]);
        }
        assert!(s.rss < 1e-20);
        assert_eq!(s.dof, 26);
        assert_eq!(s.rank, 4);
        assert!(s.condition_number > 1.0 && s.condition_number < 100.0);
    }

    #[test]
    fn square_problem_is_exact_and_has_no_sd() {
        let (a, b, coef) = poly_problem(4);
        let s = solve(&a, &b, None).unwrap();
        for j in 0..4 {
            assert!((s.coef[j] - coef[j]).abs() < 1e-12);
        }
        assert_eq!(s.dof, 0);
        assert!(s.coef_sd[0].is_nan());
    }

    #[test]
    fn coefficient_sd_matches_textbook_line_fit() {
        // y = a + b·x with residuals ±1 alternating: σ̂² = rss/(n−2),
        // sd(b) = σ̂ / √Σ(x − x̄)².
        let n = 10;
        let a = DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { i as f64 });
        let b = DVector::from_fn(n, |i, _| {
            2.0 + 0.5 * i as f64 + if i % 2 == 0 { 1.0 } else { -1.0 }
        });
        let s = solve(&a, &b, None).unwrap();
        let xbar = 4.5;
        let sxx: f64 = (0..n).map(|i| (i as f64 - xbar).powi(2)).sum();
        let sigma = (s.rss / (n - 2) as f64).sqrt();
        assert!((s.coef_sd[1] - sigma / sxx.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_row_with_huge_uncertainty_has_no_influence() {
        let (a, mut b, coef) = poly_problem(20);
        b[7] += 1000.0; // a gross outlier …
        let mut w = DVector::from_element(20, 1.0);
        w[7] = 1.0 / (1e9f64).powi(2); // … measured with u = 10⁹ µm
        let s = solve(&a, &b, Some(&w)).unwrap();
        for j in 0..4 {
            assert!((s.coef[j] - coef[j]).abs() < 1e-9, "{j}: {}", s.coef[j]);
        }
        // Without the weights the outlier moves the fit.
        let s = solve(&a, &b, None).unwrap();
        assert!((s.coef[0] - coef[0]).abs() > 1.0);
    }

    #[test]
    fn bad_weights_are_rejected() {
        let (a, b, _) = poly_problem(10);
        let mut w = DVector::from_element(10, 1.0);
        w[3] = 0.0;
        let e = solve(&a, &b, Some(&w)).unwrap_err();
        assert!(matches!(
            e.downcast_ref::<LsqError>(),
            Some(LsqError::BadInput(_))
        ));
    }

    #[test]
    fn rank_deficiency_names_the_collinear_columns() {
        // Column 3 = 2·column 1 − column 0; column 2 independent.
        let n = 12;
        let a = DMatrix::from_fn(n, 4, |i, j| {
            let x = i as f64;
            match j {
                0 => 1.0,
                1 => x,
                2 => x * x,
                _ => 2.0 * x - 1.0,
            }
        });
        let b = DVector::from_fn(n, |i, _| i as f64);
        let e = solve(&a, &b, None).unwrap_err();
        match e.downcast_ref::<LsqError>() {
            Some(LsqError::RankDeficient { rank, cols, groups }) => {
                assert_eq!((*rank, *cols), (3, 4));
                assert_eq!(groups, &vec![vec![0, 1, 3]]);
            }
            other => panic!("{other:?}"),
        }
        // The min-norm variant still answers, and fits the data.
        let s = solve_min_norm(&a, &b, None).unwrap();
        assert_eq!(s.rank, 3);
        assert!(s.rss < 1e-18);
    }

    #[test]
    fn zero_column_and_too_few_rows() {
        let a = DMatrix::from_fn(5, 2, |i, j| if j == 0 { i as f64 } else { 0.0 });
        let b = DVector::from_element(5, 1.0);
        match solve(&a, &b, None).unwrap_err().downcast_ref::<LsqError>() {
            Some(LsqError::RankDeficient { groups, .. }) => assert_eq!(groups, &vec![vec![1]]),
            other => panic!("{other:?}"),
        }
        let a = DMatrix::from_element(2, 3, 1.0);
        let b = DVector::from_element(2, 1.0);
        assert!(matches!(
            solve(&a, &b, None).unwrap_err().downcast_ref::<LsqError>(),
            Some(LsqError::TooFewRows { rows: 2, cols: 3 })
        ));
    }

    #[test]
    fn design_matrix_fast_path_matches_feature_columns() {
        let data = Dataset {
            pos_mm: [
                Some(vec![0.0, 3.0, 7.5, 10.0]),
                None,
                Some(vec![1.0, -2.0, 4.0, 0.5]),
            ],
            err_um: [Some(vec![Some(0.0); 4]), None, None],
            dir: [Some(vec![1, -1, 1, -1]), None, None],
            ..Default::default()
        };
        let norm = Norm::from_data(&data);
        let features: Vec<Feature> = crate::features::CUBIC19
            .iter()
            .map(|&exp| Feature::Monomial { exp })
            .chain([Feature::Reversal { axis: 0 }])
            .collect();
        let rows = [3, 1, 2];
        let a = design_matrix(&data, &norm, &features, &rows).unwrap();
        for (j, f) in features.iter().enumerate() {
            let col = f.column(&data, &norm).unwrap();
            for (i, &r) in rows.iter().enumerate() {
                assert_eq!(a[(i, j)].to_bits(), col[r].to_bits(), "{f} row {r}");
            }
        }
    }

    /// Issue 15: the chunked Gram sums equal the explicit products AᵀWA
    /// and AᵀWB over a row subset — more rows than a chunk, scattered and
    /// consecutive rows, wide (the dgemm path) and narrow (nalgebra's own
    /// loop) — taking rows out equals summing the rest, and the normal
    /// equations give [`solve`]'s coefficients and standard deviations.
    #[test]
    fn gram_sums_equal_the_explicit_products() {
        let mut rng = trueaxis_test_support::SplitMix64::new(3);
        let n = 2 * GRAM_CHUNK + 77;
        for p in [3, 9] {
            let a = DMatrix::from_fn(n, p, |_, _| rng.signed_unit());
            let b = DMatrix::from_fn(n, 2, |_, _| rng.signed_unit());
            let w = DVector::from_fn(n, |_, _| 0.5 + rng.unit());
            // Scattered rows, a consecutive run, a shuffled run that spans
            // as many indices as it has rows, and one row twice.
            let rows: Vec<usize> = (0..GRAM_CHUNK)
                .filter(|i| i % 3 != 1)
                .chain(GRAM_CHUNK..2 * GRAM_CHUNK)
                .chain([
                    2 * GRAM_CHUNK + 1,
                    2 * GRAM_CHUNK,
                    2 * GRAM_CHUNK + 3,
                    2 * GRAM_CHUNK + 3,
                ])
                .collect();
            let cols: Vec<usize> = (0..p).rev().collect();
            let got = Gram::over(&a, &cols, &b, &[1, 0], Some(&w), &rows);
            let sub = DMatrix::from_fn(rows.len(), p, |i, j| {
                a[(rows[i], cols[j])] * w[rows[i]].sqrt()
            });
            let bs = DMatrix::from_fn(rows.len(), 2, |i, k| {
                b[(rows[i], 1 - k)] * w[rows[i]].sqrt()
            });
            let (g, r) = (sub.tr_mul(&sub), sub.tr_mul(&bs));
            assert!((&got.g - &g).amax() < 1e-12 * g.amax(), "p {p}");
            assert!((&got.r - &r).amax() < 1e-12 * r.amax(), "p {p}");
            assert_eq!(got.g, got.g.transpose());
            let rhs = Gram::rhs_over(&a, &cols, &b, &[1, 0], Some(&w), &rows);
            assert!((&rhs - &r).amax() < 1e-12 * r.amax());
            // Short lists that span as many indices as they hold rows but
            // are not consecutive (a row twice; descending).
            for odd in [[5, 5, 7], [7, 5, 6]] {
                let got = Gram::over(&a, &cols, &b, &[0], None, &odd);
                let sub = DMatrix::from_fn(3, p, |i, j| a[(odd[i], cols[j])]);
                assert!((got.g - sub.tr_mul(&sub)).amax() < 1e-12, "{odd:?}");
            }
            // Take the first 100 rows out again: the sums of the others.
            let mut down = got.clone();
            down.add_rows(&a, &cols, &b, &[1, 0], Some(&w), &rows[..100], -1.0);
            let rest = Gram::over(&a, &cols, &b, &[1, 0], Some(&w), &rows[100..]);
            assert!((&down.g - &rest.g).amax() < 1e-12 * g.amax());
            // The normal equations against the QR path.
            let sol = solve_gram(&got).unwrap();
            let qr = solve(&sub.map(|v| v), &bs.column(0).into_owned(), None).unwrap();
            assert!((sol.coef.column(0) - &qr.coef).amax() < 1e-12 * qr.coef.amax());
            let sd = sol.inv_diag.map(|v| (qr.rss / qr.dof as f64 * v).sqrt());
            assert!((sd - &qr.coef_sd).amax() < 1e-12 * qr.coef_sd.amax());
            assert!((sol.condition_number / qr.condition_number - 1.0).abs() < 1e-12);
        }
        // A zero column or a rank-deficient pair: no Gram solution.
        let a = DMatrix::from_fn(20, 3, |i, j| [1.0, i as f64, 0.0][j]);
        let b = DMatrix::from_element(20, 1, 1.0);
        let all: Vec<usize> = (0..20).collect();
        assert!(solve_gram(&Gram::over(&a, &[0, 1, 2], &b, &[0], None, &all)).is_none());
        let a = DMatrix::from_fn(20, 2, |i, _| i as f64);
        assert!(solve_gram(&Gram::over(&a, &[0, 1], &b, &[0], None, &all)).is_none());
    }

    #[test]
    fn distinct_rows_counts_points() {
        let a = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 1.0, -0.0, 1.0, 2.0, 1.0, 2.0]);
        assert_eq!(distinct_rows(&a), 2);
    }
}
