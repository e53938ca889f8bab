//! The engine's linear algebra, in one place:
//!
//! - [`lsq`]: weighted least squares of a model's design matrix (QR + SVD
//!   with rank and conditioning checks, the collinear columns named) and
//!   per-block Gram sums for `fit`'s and the hold-out's refits;
//! - [`basis`]: the diagnosis' building blocks — an orthonormal basis of a
//!   model's columns (CholeskyQR2), small pseudo-inverse fits of a
//!   candidate's few columns, hold-out refits from per-fold Gram sums, and
//!   the fast dot product they share;
//! - [`brent`]: one-dimensional minimisation on a bracket (a thermal lag).
//!
//! Two Gram solves live here on purpose: [`lsq::solve_gram`] refuses a
//! badly conditioned sum (fit then falls back to a QR of the rows), while
//! [`basis::pinv_solve`] never refuses (a candidate's few columns are
//! judged by their rank). The layer is the one of `features`' users: `lsq`
//! builds design matrices from a data set and its features.

pub mod basis;
pub mod brent;
pub mod lsq;
