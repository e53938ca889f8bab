//! The table export's typed refusals ([`TableError`]: which check refused,
//! with its numbers) and the record of a clamped output ([`Clamped`]).
//! The messages say what is wrong in the options' terms (`TableOptions`);
//! the CLI words them with its flags.

use crate::data::TARGETS;
use crate::export::checks::{MaxCorrError, TinyCorrections};

/// Why a table export was refused. Each refusal names the check and
/// carries its numbers; [`TableError::Other`] is any other failure (a
/// model the table cannot hold, a value outside its ranges).
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// `allow_error_nm` is NaN, infinite or negative: it would switch the
    /// accuracy check off or fail every table.
    #[error("the allowed difference between firmware and model must be a finite number ≥ 0, got {allowed_nm} nm")]
    BadAllowance {
        /// The allowance given, nm.
        allowed_nm: f64,
    },
    /// `reversal_transition_um` is negative or not a number.
    #[error("the reversal transition must be ≥ 0 µm, got {transition_um}")]
    BadReversalTransition {
        /// The transition given, µm.
        transition_um: f64,
    },
    /// A thermal term has a lag, which the table cannot represent, and
    /// `drop_lag` is not set.
    #[error(
        "{}: the thermal term {term} has a lag of {lag_s} s, which the firmware table cannot represent (it applies the coefficient to the sensor reading at once); refit without lag_s, or export its steady state (drop the lag)",
        TARGETS[*target]
    )]
    Lag {
        /// Output (0 = ex).
        target: usize,
        /// The term, as the model file writes it.
        term: String,
        /// Its lag, s.
        lag_s: f64,
    },
    /// A local (piecewise) model: the firmware evaluates one global model.
    #[error("local (piecewise) models cannot be exported as a table: the firmware evaluates one global model; fit a global seed (cubic19 with effects added) or grid:<step_mm>")]
    LocalModel,
    /// Every correction is tiny.
    #[error(transparent)]
    Tiny(#[from] TinyCorrections),
    /// The max |correction| limit is refused.
    #[error(transparent)]
    MaxCorr(#[from] MaxCorrError),
    /// The max slew given is below 1 nm/ms or not a number.
    #[error("the max slew must be ≥ 1 nm/ms, got {given_nm_per_ms}")]
    SlewBelowOne {
        /// The slew given, nm/ms.
        given_nm_per_ms: f64,
    },
    /// The max slew given is above what a table holds.
    #[error("max slew {given_nm_per_ms} nm/ms: a table holds at most {} nm/ms (10 m/s; the format's and the board's limit) — check the unit (nm per ms)", model_core::table::MAX_SLEW_LIMIT_NM_PER_MS)]
    SlewAboveTableLimit {
        /// The slew given, nm/ms.
        given_nm_per_ms: f64,
    },
    /// The fastest feed (for the default slew) is not a positive number.
    #[error("the fastest feed must be positive, got {given_mm_per_min} mm/min")]
    BadFeed {
        /// The feed given, mm/min.
        given_mm_per_min: f64,
    },
    /// The firmware's evaluation differs from the model by more than
    /// allowed (or by NaN).
    #[error("accuracy check failed: the firmware's evaluation differs from the model by up to {worst_nm:.3} nm (f32 {f32_nm:.3}, fixed {fixed_nm:.3}) over {sweep_points} sweep points, above the {allowed_nm} nm allowed")]
    Accuracy {
        /// The larger of the two, nm.
        worst_nm: f64,
        /// Largest f32 difference, nm.
        f32_nm: f64,
        /// Largest fixed-point difference, nm.
        fixed_nm: f64,
        /// Points of the sweep.
        sweep_points: usize,
        /// The allowance, nm.
        allowed_nm: f64,
    },
    /// Any other failure, as the step that failed says it.
    #[error(transparent)]
    Other(anyhow::Error),
}

impl From<anyhow::Error> for TableError {
    /// A step that reports through `anyhow` (the mapping) raises its
    /// refusals as `TableError`s inside it: they come back typed; anything
    /// else is [`TableError::Other`], unchanged.
    fn from(e: anyhow::Error) -> Self {
        e.downcast::<TableError>().unwrap_or_else(TableError::Other)
    }
}

/// An output whose max |correction| limit was given below the model's own
/// largest correction: the firmware clamps there (the warning
/// `max_corr_below_model`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clamped {
    /// Output (0 = ex).
    pub target: usize,
    /// The limit, nm.
    pub limit_nm: f64,
    /// The model's largest |correction| on the sweep, nm.
    pub model_max_nm: f64,
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::export::fixtures::{file, linear, mono};
    use crate::export::table::{export, TableOptions};
    use crate::features::Norm;
    use crate::model::{FittedModel, LocalModel, ModelFile};

    /// ex = 3 + u + 0.7·u³ along x: largest 4.7 µm at x = 200 mm.
    pub(in crate::export) fn cubic_x() -> ModelFile {
        linear(
            0,
            &[
                (mono([0, 0, 0]), 3.0),
                (mono([1, 0, 0]), 1.0),
                (mono([3, 0, 0]), 0.7),
            ],
        )
    }

    #[test]
    fn the_accuracy_gate_refuses_with_its_numbers() {
        let m = cubic_x();
        let e = export(&m, &TableOptions::default()).unwrap();
        let worst = e.max_f32_error_nm.max(e.max_fixed_error_nm);
        assert!(worst > 0.0 && worst <= 1.0, "{worst}");
        let strict = TableOptions {
            allow_error_nm: worst / 2.0,
            ..TableOptions::default()
        };
        match export(&m, &strict).unwrap_err() {
            TableError::Accuracy {
                worst_nm,
                sweep_points,
                allowed_nm,
                ..
            } => {
                assert_eq!(worst_nm, worst);
                assert_eq!(sweep_points, e.sweep_points);
                assert_eq!(allowed_nm, worst / 2.0);
            }
            other => panic!("{other}"),
        }
        // NaN, inf or a negative allowance would switch the check off or
        // fail every table.
        for bad in [f64::NAN, f64::INFINITY, -1.0] {
            let opts = TableOptions {
                allow_error_nm: bad,
                ..TableOptions::default()
            };
            assert!(
                matches!(export(&m, &opts), Err(TableError::BadAllowance { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn limit_refusals_are_typed_and_name_no_command_line_flag() {
        let d = TableOptions::default;
        type Is = fn(&TableError) -> bool;
        let cases: Vec<(TableOptions, Is)> = vec![
            (
                TableOptions {
                    max_slew_nm_per_ms: Some(0.5),
                    ..d()
                },
                |e| matches!(e, TableError::SlewBelowOne { given_nm_per_ms } if *given_nm_per_ms == 0.5),
            ),
            (
                TableOptions {
                    max_slew_nm_per_ms: Some(4e8),
                    ..d()
                },
                |e| matches!(e, TableError::SlewAboveTableLimit { .. }),
            ),
            (
                TableOptions {
                    max_feed_mm_per_min: 0.0,
                    ..d()
                },
                |e| matches!(e, TableError::BadFeed { .. }),
            ),
            (
                TableOptions {
                    reversal_transition_um: -1.0,
                    ..d()
                },
                |e| matches!(e, TableError::BadReversalTransition { transition_um } if *transition_um == -1.0),
            ),
            (
                TableOptions {
                    max_corr_um: Some(5000.0),
                    ..d()
                },
                |e| {
                    matches!(
                        e,
                        TableError::MaxCorr(MaxCorrError::AboveTableLimit {
                            target: 0,
                            given_um
                        }) if *given_um == 5000.0
                    )
                },
            ),
        ];
        for (opts, is) in cases {
            let e = export(&cubic_x(), &opts).unwrap_err();
            assert!(is(&e), "{e:?}");
            assert!(!e.to_string().contains("--"), "{e}");
        }
        let local = FittedModel::Local(LocalModel {
            shape: "line".into(),
            norm: Norm {
                centre_mm: [100.0; 3],
                half_span_mm: [100.0; 3],
            },
            stack_axis: None,
            planes_mm: vec![],
            patches: vec![],
        });
        let e = export(&file(local), &d()).unwrap_err();
        assert!(matches!(e, TableError::LocalModel), "{e:?}");
    }
}
