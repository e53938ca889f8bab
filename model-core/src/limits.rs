//! The table format's and the firmware's capacity limits, in one place: how
//! many temperature channels an input carries, how many terms a model holds,
//! the largest polynomial degree, periodic harmonics and MLP shape a table
//! may declare. [`crate::table`] validates against them, [`crate::eval`]
//! sizes its fixed arrays with them and [`crate::cost`] bounds its walk by
//! them, so none of those modules depends on another for a limit (the
//! format is documented in `docs/table-format.md`).

/// Temperature channels an input carries.
pub const MAX_TEMPS: usize = 4;
/// Most terms in a model.
pub const MAX_TERMS: usize = 24;
/// Most MLP inputs over all MLP terms of a model.
pub const MAX_MLP_INPUTS_TOTAL: usize = 16;
/// Highest total degree of a polynomial monomial.
pub const MAX_DEGREE: u8 = 5;
/// Number of monomials x^a y^b z^c with a+b+c ≤ 5.
pub const MAX_MONOMIALS: usize = 56;
/// Most harmonics in a periodic term.
pub const MAX_HARMONICS: usize = 4;
/// Most inputs of an MLP (3 positions + 4 temperatures).
pub const MAX_MLP_INPUTS: usize = 3 + MAX_TEMPS;
/// Most units in an MLP hidden layer.
pub const MAX_HIDDEN_UNITS: usize = 32;
/// Most hidden layers of an MLP.
pub const MAX_HIDDEN_LAYERS: usize = 2;
