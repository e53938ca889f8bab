//! The trueaxis core shared by the host tool and the firmware: everything the
//! two sides must agree on bit for bit — model evaluation (f32 and fixed
//! point, plus the f64 reference on the host) and the binary table format.
//! The link protocol is its own crate, `trueaxis-protocol` (`protocol/`).
//! `no_std`, no allocation, no `unsafe`.
//!
//! - [`table`]: format v1, [`table::parse`] (zero-copy, fully validated).
//! - [`eval`]: the prepared [`Model`] with `eval_f32` / `eval_fixed`,
//!   [`Inputs`], [`Outputs`], [`Flags`], [`DirTracker`].
//! - [`limits`]: the table format's and the firmware's capacity limits
//!   (`MAX_TEMPS`, `MAX_TERMS`, the MLP shape, …).
//! - [`monomials`]: the named polynomial sets (`cubic19`, `kinematic`).
//! - [`board`]: the compensation board's limits (staging buffer, model
//!   capacity) as constants the firmware uses and the host checks.
//! - [`cost`]: a static estimate of a table's evaluation cost in
//!   instructions, for the board's admission of a table at commit.
//! - [`definition`]: a table's own f64 definition read from its bytes, and
//!   the check that the fixed-point and f32 evaluations stay within a
//!   bound of it (the board's admission too).
//! - `spec` (feature `std`): [`TableSpec`] — the host's owned description,
//!   `encode` and the f64 reference `eval_f64`.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod board;
pub mod cost;
pub mod definition;
pub mod eval;
pub mod limits;
pub mod math;
pub mod monomials;
#[cfg(feature = "std")]
pub mod spec;
pub mod table;

pub use eval::{
    DirTracker, Flags, Inputs, LargeModel, LoadError, Model, ModelCap, Outputs, Transition,
    MAX_TEMPS,
};
#[cfg(feature = "std")]
pub use spec::{
    EncodeError, GridAxisSpec, GridSpec, InputsF64, LayerSpec, MlpInputSpec, MlpSource, MlpSpec,
    TableSpec, TermSpec,
};
pub use table::{parse, Envelope, InputScaling, Table, TableError, FORMAT_VERSION};
