//! The checks every export makes before anything is written, and their
//! typed refusals: a table of tiny corrections ([`refuse_tiny`]), the max
//! |correction| limit ([`max_corr_limit_nm`]) and, for the files that
//! cannot clamp (controller tables, bed meshes), corrections above that
//! limit ([`check_unclampable`]).
//!
//! The messages say what is wrong in the engine's terms — the options of
//! `TableOptions`, `ControllerOptions` and `MeshOptions` — and carry the
//! numbers; a command line that calls the options by its own names (the
//! `trueaxis` CLI's flags) words the refusal itself from the variant's
//! fields.

use crate::data::{AXES, TARGETS};

/// The largest |correction| any export may hold, µm: the firmware table's
/// limit (`model_core::table::MAX_CORR_LIMIT_NM`), applied to the
/// controller files and bed meshes as well.
pub const MAX_CORR_LIMIT_UM: f64 = model_core::table::MAX_CORR_LIMIT_NM as f64 / 1000.0;

/// Refused: every output's largest |correction| is below
/// [`crate::units::TINY_CORRECTION_UM`] (see [`refuse_tiny`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}; accept tiny corrections to export it anyway", self.finding())]
pub struct TinyCorrections {
    /// Per output the export holds: the target (0 = ex) and its largest
    /// |correction|, nm.
    pub largest_nm: Vec<(usize, f64)>,
}

impl TinyCorrections {
    /// What was found and its usual cause, without the way out (which a
    /// caller names in its own terms).
    pub fn finding(&self) -> String {
        let list: Vec<String> = self
            .largest_nm
            .iter()
            .map(|(t, m)| format!("{} {:.1} nm", TARGETS[*t], m))
            .collect();
        format!(
            "the largest correction is tiny ({}, below {} µm on every output): nothing a machine would notice, or errors in mm written into µm columns (a table 1000× too small) — check the data's units",
            list.join(", "),
            crate::units::TINY_CORRECTION_UM
        )
    }
}

/// Refused: the max |correction| limit (see [`max_corr_limit_nm`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MaxCorrError {
    /// The limit given is zero, negative or not a number.
    #[error("the max |correction| limit must be positive, got {given_um} µm")]
    NotPositive {
        /// The limit given, µm.
        given_um: f64,
    },
    /// The limit given is above what a table holds ([`MAX_CORR_LIMIT_UM`]).
    #[error(
        "{}: the max |correction| limit {given_um} µm exceeds the table's limit of {MAX_CORR_LIMIT_UM} µm",
        TARGETS[*target]
    )]
    AboveTableLimit {
        /// Output (0 = ex).
        target: usize,
        /// The limit given, µm.
        given_um: f64,
    },
    /// No limit was given and the default, 1.5 × the model's largest
    /// |correction|, is above what a table holds.
    #[error("{}; {}{}", self.finding(), self.suspect(), if self.model_above_table_limit() {
        format!("a limit given (at most {MAX_CORR_LIMIT_UM} µm) would clamp it")
    } else {
        format!("give the limit yourself (at most {MAX_CORR_LIMIT_UM} µm; at or above the model's {} µm nothing is clamped)", self.model_max_um())
    })]
    DefaultAboveTableLimit {
        /// Output (0 = ex).
        target: usize,
        /// The default limit, nm.
        default_nm: f64,
        /// The largest |correction| of the model, nm.
        model_max_nm: f64,
    },
}

/// A number of µm for a message: one decimal, or the exponent form above
/// 10⁶ µm (a wildly wrong model's 1e300 µm reads as 1.00e300, not as 300
/// digits).
fn fmt_um(x: f64) -> String {
    if x < 1e6 {
        format!("{x:.1}")
    } else {
        format!("{x:.2e}")
    }
}

// The parts of `DefaultAboveTableLimit`'s message, for a caller that names
// the way out (the limit it takes) in its own terms.
impl MaxCorrError {
    /// What was found: for `DefaultAboveTableLimit` the default, the
    /// model's largest and the table's limit; the whole message otherwise.
    pub fn finding(&self) -> String {
        match self {
            MaxCorrError::DefaultAboveTableLimit {
                target, default_nm, ..
            } => format!(
                "{}: the default max |correction| {} µm (1.5 × the model's largest correction, {} µm) exceeds the table's limit of {MAX_CORR_LIMIT_UM} µm",
                TARGETS[*target],
                fmt_um(default_nm / 1000.0),
                self.model_max_um()
            ),
            other => other.to_string(),
        }
    }

    /// The model's largest |correction| as the message writes it, µm
    /// (empty for the variants without it).
    pub fn model_max_um(&self) -> String {
        match self {
            MaxCorrError::DefaultAboveTableLimit { model_max_nm, .. } => {
                fmt_um(model_max_nm / 1000.0)
            }
            _ => String::new(),
        }
    }

    /// Whether the model's own largest |correction| is above
    /// [`MAX_CORR_LIMIT_UM`]: then the model or the data's units are the
    /// first suspects, not the limit.
    pub fn model_above_table_limit(&self) -> bool {
        matches!(self, MaxCorrError::DefaultAboveTableLimit { model_max_nm, .. } if model_max_nm / 1000.0 > MAX_CORR_LIMIT_UM)
    }

    /// When [`MaxCorrError::model_above_table_limit`], the first suspects
    /// ("the model's own largest correction (…) is above it — check the
    /// model and the data's units … before anything else; "), else empty.
    pub fn suspect(&self) -> String {
        if self.model_above_table_limit() {
            format!(
                "the model's own largest correction ({} µm) is above it — check the model and the data's units (an error column in nm, a temperature in K) before anything else; ",
                self.model_max_um()
            )
        } else {
            String::new()
        }
    }
}

/// Why a controller file or a bed mesh was not made. Each refusal names the
/// check and carries its numbers; [`FileError::Other`] is any other
/// failure (a model that cannot be evaluated, a value a writer cannot
/// hold).
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// No axis was chosen and the model uses more than one (or none).
    #[error(
        "the model uses the axes {}: a one-axis file needs one of them chosen",
        axis_list(used)
    )]
    AxisAmbiguous {
        /// The axes the model uses (0 = x).
        used: Vec<usize>,
    },
    /// The axis chosen is not one the model depends on.
    #[error("the model does not depend on {} (fitted axes: {}); choose one of them", AXES[*axis], axis_list(fitted))]
    AxisNotUsed {
        /// The axis chosen.
        axis: usize,
        /// The axes the model uses.
        fitted: Vec<usize>,
    },
    /// More points than the controller reads.
    #[error("{points} points: {controller} reads at most {max} entries")]
    TooManyPoints {
        /// The controller's name (`LinuxCNC`).
        controller: &'static str,
        /// Points asked for.
        points: usize,
        /// The most the controller reads.
        max: usize,
    },
    /// Every correction is tiny.
    #[error(transparent)]
    Tiny(#[from] TinyCorrections),
    /// The max |correction| limit is refused.
    #[error(transparent)]
    MaxCorr(#[from] MaxCorrError),
    /// The file would hold corrections above the limit given, and it cannot
    /// clamp (a controller's table, a firmware's bed mesh apply what they
    /// hold).
    #[error(
        "{}: the {format} file would hold corrections up to {:.3} µm, above the max |correction| limit of {} µm: {holder} cannot clamp",
        TARGETS[*target],
        largest_nm / 1000.0,
        limit_nm / 1000.0
    )]
    AboveLimit {
        /// Output (0 = ex).
        target: usize,
        /// The format's name (`linuxcnc`).
        format: &'static str,
        /// What holds the corrections (`a controller's compensation table`).
        holder: &'static str,
        /// The largest |correction| the file would hold, nm.
        largest_nm: f64,
        /// The limit, nm.
        limit_nm: f64,
    },
    /// A bed mesh departs from a probed reading by more than the limit.
    #[error(
        "the {format} mesh departs from the reading at x {:.2}, y {:.2} mm (line {}) by {:.3} µm, above the limit of {} µm (the model itself misses it by {:.3} µm, the interpolation between nodes the rest)",
        check.at_mm[0],
        check.at_mm[1],
        check.line,
        check.max_departure_um,
        check.limit_um,
        check.model_miss_um
    )]
    Departs {
        /// The format's name (`klipper-mesh`).
        format: &'static str,
        /// The check at the probed points.
        check: Box<super::mesh::ProbedCheck>,
    },
    /// The file needs errors of a rigid21 model that the data cannot
    /// determine (`cannot_know`): no value is written for them.
    #[error(
        "the {format} file needs {}, which these data cannot determine (cannot_know): no value is written for what cannot be known — measure {measure}",
        names.join(", ")
    )]
    CannotKnow {
        /// The format's name (`klipper-skew`).
        format: &'static str,
        /// The ISO 230-1 names of the errors.
        names: Vec<String>,
        /// What would determine them, in words.
        measure: String,
    },
    /// Any other failure, as the step that failed says it.
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

/// `x, y` for axis indices.
pub fn axis_list(axes: &[usize]) -> String {
    axes.iter().map(|&a| AXES[a]).collect::<Vec<_>>().join(", ")
}

/// Refuses an export whose largest |correction| on every output is below
/// [`crate::units::TINY_CORRECTION_UM`] unless `accept`: such a file
/// compensates nothing a machine notices, and the usual cause is errors in
/// mm written into µm columns (a table 1000× too small). `host` holds each
/// output's corrections, nm.
pub fn refuse_tiny(host: &[Option<Vec<f64>>; 3], accept: bool) -> Result<(), TinyCorrections> {
    let largest: Vec<(usize, f64)> = host
        .iter()
        .enumerate()
        .filter_map(|(t, h)| {
            h.as_ref()
                .map(|h| (t, h.iter().fold(0.0f64, |m, v| m.max(v.abs()))))
        })
        .collect();
    let tiny_nm = crate::units::TINY_CORRECTION_UM * 1000.0;
    if accept || largest.is_empty() || largest.iter().any(|&(_, m)| m >= tiny_nm) {
        return Ok(());
    }
    Err(TinyCorrections {
        largest_nm: largest,
    })
}

/// The max |correction| limit of output `target`, nm, shared by every
/// format: `given_um` when set, else 1.5 × `model_max_nm` (the largest
/// |correction| the export holds), at least 1 µm. Refused when not
/// positive and finite, or above [`MAX_CORR_LIMIT_UM`]. Whether a
/// `given_um` below the model's largest is a warning (the firmware table
/// clamps) or a refusal (a controller file cannot) is the caller's.
pub fn max_corr_limit_nm(
    target: usize,
    model_max_nm: f64,
    given_um: Option<f64>,
) -> Result<f64, MaxCorrError> {
    match given_um {
        Some(u) => {
            if !(u.is_finite() && u > 0.0) {
                return Err(MaxCorrError::NotPositive { given_um: u });
            }
            if u > MAX_CORR_LIMIT_UM {
                return Err(MaxCorrError::AboveTableLimit {
                    target,
                    given_um: u,
                });
            }
            Ok(u * 1000.0)
        }
        None => {
            let limit_nm = (1.5 * model_max_nm).max(1000.0);
            if limit_nm > MAX_CORR_LIMIT_UM * 1000.0 {
                return Err(MaxCorrError::DefaultAboveTableLimit {
                    target,
                    default_nm: limit_nm,
                    model_max_nm,
                });
            }
            Ok(limit_nm)
        }
    }
}

/// What a file that cannot clamp may hold: `corr_nm` are the corrections
/// of output `target` it would hold (nm). Refuses a file of tiny
/// corrections (unless `accept_tiny`), a refused limit, and corrections
/// above the limit given (`max_corr_um`; the default, 1.5 × the largest,
/// never bites): the controller interpolates between the values, so they
/// bound what it applies, and it cannot clamp. `format` and `holder` name
/// the file and what applies it in the refusal. Returns the limit and the largest |correction|, nm.
pub(crate) fn check_unclampable(
    target: usize,
    corr_nm: Vec<f64>,
    max_corr_um: Option<f64>,
    accept_tiny: bool,
    format: &'static str,
    holder: &'static str,
) -> Result<(f64, f64), FileError> {
    let largest_nm = corr_nm.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut host: [Option<Vec<f64>>; 3] = [None, None, None];
    host[target] = Some(corr_nm);
    refuse_tiny(&host, accept_tiny)?;
    let limit_nm = max_corr_limit_nm(target, largest_nm, max_corr_um)?;
    if largest_nm > limit_nm {
        return Err(FileError::AboveLimit {
            target,
            format,
            holder,
            largest_nm,
            limit_nm,
        });
    }
    Ok((limit_nm, largest_nm))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wildly_wrong_model_is_named_in_exponent_form() {
        // 1e300 µm, as a damaged or mis-scaled model file gives: the
        // message stays a line, not 300 digits.
        let e = max_corr_limit_nm(0, 1e303, None).unwrap_err().to_string();
        assert!(
            e.contains("default max |correction| 1.50e300 µm") && e.contains("(1.00e300 µm)"),
            "{e}"
        );
        assert!(e.len() < 400, "{e}");
        // Ordinary sizes keep one decimal.
        let e = max_corr_limit_nm(1, 3_068_000.0, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("ey: the default max |correction| 4602.0 µm")
                && e.contains("largest correction, 3068.0 µm"),
            "{e}"
        );
    }
}
