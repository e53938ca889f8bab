//! MODEL.json → the firmware's binary table (model-core format v1), with the
//! accuracy check of docs/cli.md.
//!
//! **Mapping.** A linear model's features become model-core terms, per
//! target: all monomials (any degree ≤ 5) → one `Poly` term; the sin/cos
//! pairs of one axis and period → one `Periodic` term (harmonic k at index
//! k−1); thermal features of one channel and reference → one `Thermal` term
//! (alone = the `[0,0,0]` coefficient, "times x" = `[1,0,0]`); `dir_axis` →
//! `Reversal`; `tool·monomial` → one `Abbe` term. Drift (t/1 h)^p describes
//! the measurement session, not the machine, and is left out with a warning.
//! A thermal lag cannot be represented (the firmware applies a coefficient
//! to the sensor's reading as it is): export refuses such a model unless
//! `drop_lag` is set, which exports the steady state (lag 0) and warns. A
//! tanh network becomes an `Mlp` term, a grid model one `Grid` term per
//! target; local (piecewise) models are refused.
//!
//! **Units and sign.** The table holds the *correction* in nm, −e where e
//! (µm) is the model's error (see the module docs of `export`): monomial
//! coefficients ×(−1000) nm; thermal ×(−1000) nm/K; Abbe coefficients are
//! µm per mm of arm, so ×(−1e-3) nm per nm; positions mm ×1e6 → nm, with
//! the model's normalisation centre and half-span rounded to whole nm.
//!
//! **Envelope** (docs/export-formats.md): travel = the fitted data's span on
//! every axis the model uses, no margin (outside it the firmware holds the
//! edge value and flags it; extrapolating a cubic is how machines crash);
//! axes the model does not use are unbounded. Max |correction| per output =
//! 1.5 × the largest |correction| found on the accuracy sweep (or
//! `max_corr_um`). Max slew = 1.5 × the largest gradient found on the sweep
//! (including a reversal's ramp over `reversal_transition_um`) × the
//! maximum feed (or `max_slew_nm_per_ms`). Temperatures: per channel the
//! range measured in the fitted data (MODEL.json `data.temp_range_c`), no
//! margin, like the travel — outside it the firmware holds the edge value
//! and flags it instead of extrapolating the thermal terms; `temp_range_c`
//! sets one range for every channel instead; a model file that does not
//! record the measured range falls back to 10…40 °C with the warning
//! `temp_range_unknown`. Tool arm: `tool_range_mm` (default 0…300 mm when
//! the model has an Abbe term, else 0…0).
//!
//! **Accuracy check.** The encoded bytes are parsed and loaded into
//! model-core's `Model` exactly as the firmware does, and its f32 and
//! fixed-point corrections are compared with the host's own f64 model
//! (`FittedModel::predict`, not the table's f64 reference, so the mapping
//! above is checked too) over a dense sweep of the envelope: an 11-point
//! grid on the used axes at every state (both approach directions, low and
//! high temperature, low and high tool arm — where the model has such
//! terms), plus dense lines along each axis (steps of 1/16 of the shortest
//! period or 1/2000 of the travel, at most 4000 points per line) with the
//! other axes at their low, middle and high positions, at the first and the
//! last state. Positions and temperatures are whole nm and m°C, so both
//! sides see the same inputs. The host value is clamped to the table's max
//! |correction| as the firmware clamps it: by default that limit is 1.5 ×
//! the sweep's maximum and never bites; a smaller `max_corr_um` is warned
//! (`max_corr_below_model`) and then does not fail the check.
//!
//! **Accuracy gate.** When the larger of the two errors is above
//! `allow_error_nm` (default 1 nm) or NaN, the export is refused
//! ([`TableError::Accuracy`]): nothing is to be written.
//!
//! The steps live in submodules: `mapping` (model → terms), `envelope`
//! (travel, scaling, ranges, max |correction| and slew), `sweep` (the
//! check's points) and `verify` (host against firmware); [`export`] runs
//! them in order. Every refusal a caller may word in its own terms is a
//! [`TableError`] variant with its numbers.

mod envelope;
mod error;
mod mapping;
mod sweep;
mod verify;

use anyhow::{anyhow, bail, Result};
use serde::Serialize;

use model_core::spec::TableSpec;
use model_core::Model;

pub use envelope::EnvelopeJson;
pub use error::{Clamped, TableError};
pub(in crate::export) use mapping::shortest_period_mm;

use super::checks::refuse_tiny;
use super::Warning;
use crate::features::Feature;
use crate::model::{FittedModel, ModelFile};

/// Options of the table export (the flags of `trueaxis export`).
#[derive(Clone, Debug, PartialEq)]
pub struct TableOptions {
    /// Max |correction| per output, µm; `None` = 1.5 × the sweep's maximum.
    pub max_corr_um: Option<f64>,
    /// Max correction slew, nm/ms; `None` = 1.5 × gradient × max feed.
    pub max_slew_nm_per_ms: Option<f64>,
    /// Fastest feed of the machine, mm/min (for the default slew).
    pub max_feed_mm_per_min: f64,
    /// Travel over which a reversal term ramps from one side to the other, µm.
    pub reversal_transition_um: f64,
    /// Valid temperature range for every channel, °C; `None` = per
    /// channel the range measured in the fitted data.
    pub temp_range_c: Option<(f64, f64)>,
    /// Valid tool-arm range, mm; `None` = 0…300 with an Abbe term, else 0…0.
    pub tool_range_mm: Option<(f64, f64)>,
    /// Export a thermal model with a lag as its steady state (lag 0).
    pub drop_lag: bool,
    /// Creation time written into the table, s since the Unix epoch.
    pub created_unix_s: i64,
    /// Export a table whose largest |correction| is below
    /// `units::TINY_CORRECTION_UM` (refused otherwise: nothing worth
    /// compensating, or errors in mm written as µm).
    pub accept_tiny: bool,
    /// Largest accepted difference between the firmware's evaluation (f32
    /// and fixed point) and the host model, nm: above it the export is
    /// refused ([`TableError::Accuracy`]).
    pub allow_error_nm: f64,
}

impl Default for TableOptions {
    fn default() -> Self {
        TableOptions {
            max_corr_um: None,
            max_slew_nm_per_ms: None,
            max_feed_mm_per_min: 10_000.0,
            reversal_transition_um: 20.0,
            temp_range_c: None,
            tool_range_mm: None,
            drop_lag: false,
            created_unix_s: 0,
            accept_tiny: false,
            allow_error_nm: 1.0,
        }
    }
}

/// The result of a table export: the bytes and the accuracy check.
#[derive(Clone, Debug, Serialize)]
pub struct TableExport {
    /// Size of the table, bytes.
    pub bytes: usize,
    /// CRC-32 of the table (the one stored in its last 4 bytes), `0x…`.
    pub crc32: String,
    /// Largest |f32 evaluation − host f64 model| over the sweep, nm (the
    /// host value clamped to the envelope's max |correction|, as the
    /// firmware applies it).
    pub max_f32_error_nm: f64,
    /// Largest |fixed-point evaluation − host f64 model| over the sweep, nm
    /// (clamped likewise).
    pub max_fixed_error_nm: f64,
    /// Points in the sweep (positions × states).
    pub sweep_points: usize,
    /// Terms in the table.
    pub terms: usize,
    /// The envelope written.
    pub envelope: EnvelopeJson,
    /// Whether the compensation board takes the table (`model_core::board`:
    /// size, model capacity, loop budget), with the cost estimate it admits
    /// tables by.
    pub board: BoardFit,
    /// What was left out or changed, and why.
    pub warnings: Vec<Warning>,
    /// The outputs the firmware clamps below the model's largest
    /// correction, in the order of their `max_corr_below_model` warnings.
    #[serde(skip)]
    pub clamped: Vec<Clamped>,
    /// The encoded table.
    #[serde(skip)]
    pub table: Vec<u8>,
    /// The spec it was encoded from.
    #[serde(skip)]
    pub spec: Option<TableSpec>,
}

/// The table against the compensation board's limits (JSON `board`).
#[derive(Clone, Debug, Serialize)]
pub struct BoardFit {
    /// The board takes it: `trueaxis upload` and `flash` would not refuse it.
    pub fits: bool,
    /// Estimated instructions of one fixed-point evaluation (what the
    /// board's correction loop runs; `model_core::cost`).
    pub estimate_fixed_instr: u32,
    /// Estimated instructions of one f32 evaluation.
    pub estimate_f32_instr: u32,
    /// The most the board accepts for the fixed-point estimate.
    pub model_budget_instr: u32,
    /// Why the board would refuse it (`null` when it fits).
    pub refusal: Option<String>,
}

impl BoardFit {
    /// `table` against the board's limits.
    pub fn of(table: &model_core::Table<'_>) -> BoardFit {
        let est = model_core::cost::estimate(table);
        let refusal = model_core::board::check(table).err().map(|e| e.to_string());
        BoardFit {
            fits: refusal.is_none(),
            estimate_fixed_instr: est.fixed_instr,
            estimate_f32_instr: est.f32_instr,
            model_budget_instr: model_core::board::MODEL_BUDGET_INSTR,
            refusal,
        }
    }
}

/// Largest |position| a table can hold (i32 nm), mm.
const MAX_POS_MM: f64 = 2000.0;
/// Unbounded travel for an axis the model does not use.
const UNBOUNDED_NM: i32 = i32::MAX;

fn nm(mm: f64) -> Result<i32> {
    if !mm.is_finite() || mm.abs() > MAX_POS_MM {
        bail!("position {mm} mm is outside what a table holds (±{MAX_POS_MM} mm)");
    }
    Ok((mm * 1e6).round() as i32)
}

fn mc(c: f64) -> Result<i32> {
    if !c.is_finite() || c.abs() > 200.0 {
        bail!("temperature {c} °C is outside what a table holds (±200 °C)");
    }
    Ok((c * 1000.0).round() as i32)
}

/// What to fit instead of a model too large for the firmware or the board,
/// as the end of a message: for a grid, the finest whole-mm step whose
/// nodes over the same travel fit the board's grid store
/// (`model_core::board::MODEL_GRID` values over all outputs).
fn smaller_model_hint(model: &FittedModel) -> String {
    match model {
        FittedModel::Grid(g) => {
            let outputs = g.outputs.len().max(1);
            let spans: Vec<f64> = g
                .counts
                .iter()
                .map(|&n| g.step_mm * (n.max(1) - 1) as f64)
                .collect();
            let values = |step: f64| -> usize {
                outputs
                    * spans
                        .iter()
                        .map(|&sp| (((sp / step) - 1e-9).ceil() as usize + 1).max(2))
                        .product::<usize>()
            };
            let cap = model_core::board::MODEL_GRID;
            let mut step = g.step_mm.floor() + 1.0;
            while values(step) > cap && step < 1e4 {
                step += 1.0;
            }
            format!(
                " — fit a coarser grid: grid:{} holds {} values over {} output(s); grid:{step} or coarser ({} values) fits the board's {cap}",
                g.step_mm,
                values(g.step_mm),
                outputs,
                values(step)
            )
        }
        FittedModel::Nn(_) => " — fit a smaller network (fewer hidden neurons)".into(),
        _ => " — fit a smaller model".into(),
    }
}

/// Exports `file` as a table and runs the accuracy check; refused when
/// the check finds more than `opts.allow_error_nm`. Nothing is written:
/// the caller writes [`TableExport::table`].
pub fn export(file: &ModelFile, opts: &TableOptions) -> Result<TableExport, TableError> {
    if !(opts.allow_error_nm.is_finite() && opts.allow_error_nm >= 0.0) {
        return Err(TableError::BadAllowance {
            allowed_nm: opts.allow_error_nm,
        });
    }
    let model = if opts.drop_lag {
        mapping::without_lag(&file.model)
    } else {
        file.model.clone()
    };
    if !(opts.reversal_transition_um.is_finite() && opts.reversal_transition_um >= 0.0) {
        return Err(TableError::BadReversalTransition {
            transition_um: opts.reversal_transition_um,
        });
    }
    let transition_nm = (opts.reversal_transition_um * 1000.0).round() as i32;
    let (terms, channels, mut warnings) =
        mapping::terms_of(&file.model, opts.drop_lag, transition_nm)?;
    if terms.is_empty() {
        return Err(anyhow!("the model has no term the table can hold").into());
    }

    // The envelope's ranges, the sweep inside them and the host's
    // corrections there, then the envelope's limits from the sweep.
    let (travel, scaling) = envelope::travel_and_scaling(&model)?;
    // A time series at one point (a thermal test): no term depends on
    // position, so model-core's table has no travel axis — the correction
    // is the same everywhere. That is what the table can express; it was
    // only measured at one point, so say where.
    if let FittedModel::Linear(m) = &model {
        if (0..3).all(|a| crate::export::axis_travel_mm(&model, a).is_none())
            && m.norm.half_span_mm.iter().any(|&h| h <= 1e-3)
        {
            let at: Vec<String> = (0..3)
                .filter(|&a| m.norm.half_span_mm[a] <= 1e-3)
                .map(|a| format!("{} = {} mm", crate::data::AXES[a], m.norm.centre_mm[a]))
                .collect();
            warnings.push(Warning::new(
                "measured_at_one_point",
                format!(
                    "no term depends on position: the data were measured at one point ({}), so the table's correction is the same over the whole travel (no travel axis, unbounded) — it is valid at that point; measure elsewhere before relying on it there",
                    at.join(", ")
                ),
            ));
        }
    }
    let temps_c = envelope::temp_ranges(file, &channels, opts.temp_range_c, &mut warnings)?;
    // A rigid21 model's error depends on the tool length (its Abbe terms).
    let has_abbe = matches!(model, FittedModel::Rigid21(_))
        || mapping::has(&model, |f| matches!(f, Feature::Abbe { .. }));
    let tool_mm = envelope::tool_range(opts.tool_range_mm, has_abbe)?;
    let has_rev = mapping::has(&model, |f| matches!(f, Feature::Reversal { .. }));
    let ranges = envelope::Ranges {
        travel,
        temps_c,
        tool_mm,
    };
    let points = sweep::points(&model, &ranges, has_abbe, has_rev);
    let host = verify::host_corrections(&model, &channels, &points)?;
    refuse_tiny(&host, opts.accept_tiny)?;
    let (max_corr_nm, clamped) = envelope::max_corr_nm(&host, opts.max_corr_um, &mut warnings)?;
    let max_slew_nm_per_ms =
        envelope::max_slew_nm_per_ms(&model, &points, &host, has_rev, transition_nm, opts)?;

    // Encode, parse and load the table as the firmware does.
    let spec = TableSpec {
        created_unix_s: opts.created_unix_s,
        source_hash: source_hash(file),
        channels: channels.clone(),
        envelope: envelope::envelope(&ranges, max_corr_nm, max_slew_nm_per_ms)?,
        scaling,
        outputs: host.each_ref().map(Option::is_some),
        terms,
    };
    let bytes = spec
        .encode()
        .map_err(|e| anyhow!("encoding the table: {e}"))?;
    let table =
        model_core::parse(&bytes).map_err(|e| anyhow!("the encoded table does not parse: {e}"))?;
    let crc = table.crc32();
    // A table the firmware's model cannot even hold is refused (nothing is
    // written): no controller could run it, and the check below needs it.
    let fw = Model::load(&table).map_err(|e| {
        anyhow!(
            "the firmware cannot load the table: {e}; nothing was written{}",
            smaller_model_hint(&model)
        )
    })?;
    // The board's own limits: the table is written anyway (it is valid),
    // but upload and flash will refuse it, so say so now.
    let board = BoardFit::of(&table);
    if let Some(why) = &board.refusal {
        warnings.push(Warning::new(
            "board_refuses",
            format!(
                "the compensation board would refuse this table ({why}); `trueaxis upload` and `flash` refuse it too{}",
                smaller_model_hint(&model)
            ),
        ));
    }

    let (max_f32, max_fixed) = verify::max_errors_nm(&fw, &points, &host, &max_corr_nm)?;
    let worst = max_f32.max(max_fixed);
    if worst.is_nan() || worst > opts.allow_error_nm {
        return Err(TableError::Accuracy {
            worst_nm: worst,
            f32_nm: max_f32,
            fixed_nm: max_fixed,
            sweep_points: points.len(),
            allowed_nm: opts.allow_error_nm,
        });
    }
    Ok(TableExport {
        bytes: bytes.len(),
        crc32: format!("0x{crc:08x}"),
        max_f32_error_nm: max_f32,
        max_fixed_error_nm: max_fixed,
        sweep_points: points.len(),
        terms: spec.terms.len(),
        envelope: envelope::json(
            &ranges,
            &channels,
            opts.temp_range_c,
            max_corr_nm,
            max_slew_nm_per_ms,
        ),
        board,
        warnings,
        clamped,
        table: bytes,
        spec: Some(spec),
    })
}

/// The fitted data's SHA-256 (hex in the model file) as the table's
/// source hash; bytes that do not parse are 0.
fn source_hash(file: &ModelFile) -> [u8; 32] {
    let mut source_hash = [0u8; 32];
    for (i, b) in source_hash.iter_mut().enumerate() {
        *b = file
            .data
            .sha256
            .get(2 * i..2 * i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0);
    }
    source_hash
}

/// How far a rigid21 table's f64 definition is from its model at
/// `pos_nm` with the tool at `tool_mm` on the spindle axis: per target the
/// table's correction plus the model's error (nm; the table holds the
/// negated error), and the model's error there (µm).
pub fn rigid21_gap_nm(
    table: &model_core::Table<'_>,
    model: &crate::model::Rigid21Model,
    pos_nm: [i32; 3],
    tool_mm: f64,
) -> ([f64; 3], [f64; 3]) {
    let inp = model_core::Inputs {
        pos_nm,
        tool_nm: (tool_mm * 1e6) as i32,
        ..model_core::Inputs::default()
    };
    let got = model_core::definition::eval_f64(table, &inp);
    let want = model
        .predict(&crate::model::rigid21::ToolPoint {
            pos_mm: pos_nm.map(|p| f64::from(p) * 1e-6),
            tool_mm,
            tool_lat_mm: [0.0; 2],
        })
        .e_um;
    ([0, 1, 2].map(|k| got[k] + 1000.0 * want[k]), want)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{Norm, Phase, CUBIC19};
    use model_core::Inputs;

    use crate::export::fixtures::file;
    use crate::model::{GridModel, GridOutput, LinearModel, LinearOutput, NnModel, NnTraining};

    /// A network's training record (export does not read it).
    fn training() -> NnTraining {
        NnTraining {
            epochs: 1,
            best_epoch: 1,
            stop: "test".into(),
            seed: 1,
            split_rows: [1, 1, 1],
        }
    }

    fn norm() -> Norm {
        Norm {
            centre_mm: [400.0, 250.0, 250.0],
            half_span_mm: [400.0, 250.0, 250.0],
        }
    }

    /// cubic19 with fixed pseudo-random coefficients of a few µm, plus
    /// every effect family on ex.
    fn full_model(lag_s: f64) -> FittedModel {
        let mut outputs = Vec::new();
        for t in 0..3 {
            let mut features: Vec<Feature> = CUBIC19
                .iter()
                .map(|&exp| Feature::Monomial { exp })
                .collect();
            let mut coef_um: Vec<f64> = (0..19)
                .map(|i| 3.0 * ((i as f64 + 1.0) * (t as f64 + 1.7)).sin())
                .collect();
            if t == 0 {
                let extra = vec![
                    (Feature::Monomial { exp: [4, 0, 0] }, 0.8),
                    (Feature::Monomial { exp: [5, 0, 0] }, -0.4),
                    (
                        Feature::Periodic {
                            axis: 0,
                            period_mm: 5.08,
                            harmonic: 1,
                            phase: Phase::Sin,
                        },
                        2.5,
                    ),
                    (
                        Feature::Periodic {
                            axis: 0,
                            period_mm: 5.08,
                            harmonic: 1,
                            phase: Phase::Cos,
                        },
                        -1.0,
                    ),
                    (
                        Feature::Periodic {
                            axis: 0,
                            period_mm: 5.08,
                            harmonic: 2,
                            phase: Phase::Sin,
                        },
                        0.5,
                    ),
                    (
                        Feature::Thermal {
                            channel: "bed".into(),
                            t_ref_c: 20.0,
                            lag_s,
                            exp: [1, 0, 0],
                        },
                        4.6,
                    ),
                    (
                        Feature::Thermal {
                            channel: "bed".into(),
                            t_ref_c: 20.0,
                            lag_s: 0.0,
                            exp: [0, 0, 0],
                        },
                        0.7,
                    ),
                    (Feature::Reversal { axis: 0 }, 2.0),
                    (Feature::Abbe { exp: [0, 1, 0] }, 0.01),
                    (Feature::Drift { power: 1 }, 0.3),
                ];
                for (f, c) in extra {
                    features.push(f);
                    coef_um.push(c);
                }
            }
            let n = features.len();
            outputs.push(LinearOutput {
                target: t,
                features,
                coef_um,
                coef_sd_um: vec![0.0; n],
            });
        }
        FittedModel::Linear(LinearModel {
            norm: norm(),
            outputs,
        })
    }

    #[test]
    fn every_linear_feature_maps_within_a_nanometre() {
        let e = export(&file(full_model(0.0)), &TableOptions::default()).unwrap();
        assert!(e.max_f32_error_nm <= 1.0, "{e:?}");
        assert!(e.max_fixed_error_nm <= 1.0, "{e:?}");
        assert!(e.sweep_points > 10_000);
        assert!(e.warnings.iter().any(|w| w.code == "drift_left_out"));
        // Poly ×3, periodic, thermal, reversal, abbe.
        assert_eq!(e.terms, 7);
        let t = model_core::parse(&e.table).unwrap();
        assert_eq!(format!("0x{:08x}", t.crc32()), e.crc32);
        assert_eq!(t.channel_name(0), Some("bed"));
        let env = t.envelope();
        assert_eq!(env.travel_nm(0), (0, 800_000_000));
        assert!(env.max_slew_nm_per_ms > 0);
    }

    #[test]
    fn correction_has_the_opposite_sign_of_the_error() {
        let m = FittedModel::Linear(LinearModel {
            norm: norm(),
            outputs: vec![LinearOutput {
                target: 0,
                features: vec![
                    Feature::Monomial { exp: [0, 0, 0] },
                    Feature::Monomial { exp: [1, 0, 0] },
                ],
                coef_um: vec![3.0, 1.0],
                coef_sd_um: vec![0.0; 2],
            }],
        });
        let e = export(&file(m), &TableOptions::default()).unwrap();
        let t = model_core::parse(&e.table).unwrap();
        let fw = Model::load(&t).unwrap();
        // At x = 800 mm (u = 1) the error is 3 + 1 = 4 µm → correction −4000 nm.
        let inp = Inputs {
            pos_nm: [800_000_000, 0, 0],
            ..Inputs::default()
        };
        assert_eq!(fw.eval_fixed(&inp).corr_nm[0], -4000);
        assert_eq!(e.envelope.max_corr_um[0], 6.0);
    }

    #[test]
    fn lag_is_refused_unless_dropped() {
        let err = export(&file(full_model(600.0)), &TableOptions::default()).unwrap_err();
        assert!(
            matches!(&err, TableError::Lag { target: 0, lag_s, .. } if *lag_s == 600.0),
            "{err:#}"
        );
        assert!(!err.to_string().contains("--"), "{err}");
        let e = export(
            &file(full_model(600.0)),
            &TableOptions {
                drop_lag: true,
                ..TableOptions::default()
            },
        )
        .unwrap();
        assert!(e.warnings.iter().any(|w| w.code == "lag_dropped"));
        assert!(e.max_fixed_error_nm <= 1.0);
    }

    #[test]
    fn the_boards_limits_are_reported_and_a_too_slow_table_warned() {
        let net = |hidden: usize| {
            let mut rng = 0x2545_f491_u32;
            let mut r = move || {
                rng ^= rng << 13;
                rng ^= rng >> 17;
                rng ^= rng << 5;
                f64::from(rng % 2000) / 1000.0 - 1.0
            };
            FittedModel::Nn(NnModel {
                inputs: vec![0, 1, 2],
                outputs: vec![0, 1, 2],
                in_min_mm: vec![0.0; 3],
                in_max_mm: vec![100.0; 3],
                out_min_um: vec![-2.0; 3],
                out_max_um: vec![2.0; 3],
                hidden,
                w1: (0..3 * hidden).map(|_| r()).collect(),
                b1: (0..hidden).map(|_| 0.5 * r()).collect(),
                w2: (0..3 * hidden).map(|_| 0.3 * r()).collect(),
                b2: vec![0.01, -0.02, 0.03],
                training: training(),
            })
        };
        // 3-16-3: within the board's budget.
        let e = export(&file(net(16)), &TableOptions::default()).unwrap();
        assert!(e.board.fits, "{:?}", e.board);
        assert!(e.board.estimate_fixed_instr <= e.board.model_budget_instr);
        assert!(e.warnings.iter().all(|w| w.code != "board_refuses"));
        // 3-32-3: its fixed-point evaluation is estimated over the budget —
        // written (it is valid), but warned, and the JSON says why.
        let e = export(&file(net(32)), &TableOptions::default()).unwrap();
        assert!(!e.board.fits);
        assert!(e.board.estimate_fixed_instr > e.board.model_budget_instr);
        let why = e.board.refusal.as_deref().unwrap();
        assert!(why.contains("estimated at"), "{why}");
        assert!(e.warnings.iter().any(|w| w.code == "board_refuses"));
        let json = serde_json::to_value(&e).unwrap();
        assert_eq!(json["board"]["fits"], false);
        assert_eq!(
            json["board"]["model_budget_instr"],
            model_core::board::MODEL_BUDGET_INSTR
        );
    }

    #[test]
    fn network_and_grid_export() {
        let nn = FittedModel::Nn(NnModel {
            inputs: vec![0, 1],
            outputs: vec![0, 1],
            in_min_mm: vec![0.0, 0.0],
            in_max_mm: vec![100.0, 100.0],
            out_min_um: vec![-2.0, -1.0],
            out_max_um: vec![3.0, 1.5],
            hidden: 3,
            w1: vec![0.5, -0.3, 1.2, 0.1, -0.8, 0.4],
            b1: vec![0.1, -0.2, 0.05],
            w2: vec![0.7, -0.4, 0.2, -0.3, 0.9, 0.1],
            b2: vec![0.05, -0.1],
            training: training(),
        });
        let e = export(&file(nn), &TableOptions::default()).unwrap();
        assert!(
            e.max_f32_error_nm <= 1.0 && e.max_fixed_error_nm <= 1.0,
            "{e:?}"
        );
        let grid = FittedModel::Grid(GridModel {
            axes: vec![0, 2],
            origin_mm: vec![0.0, 0.0],
            step_mm: 50.0,
            counts: vec![3, 2],
            outputs: vec![GridOutput {
                target: 2,
                values_um: vec![1.0, -2.0, 0.5, 3.0, 0.0, -1.5],
            }],
        });
        let e = export(&file(grid), &TableOptions::default()).unwrap();
        assert!(
            e.max_f32_error_nm <= 1.0 && e.max_fixed_error_nm <= 1.0,
            "{e:?}"
        );
        assert_eq!(e.envelope.travel_mm[1], None);
        assert_eq!(e.envelope.travel_mm[2], Some([0.0, 50.0]));
    }

    fn rigid21_model(degree: usize) -> crate::model::Rigid21Model {
        crate::export::fixtures::rigid21(degree)
    }

    #[test]
    fn a_rigid21_model_exports_as_poly_and_abbe_terms() {
        let m = rigid21_model(4);
        let e = export(
            &file(FittedModel::Rigid21(m.clone())),
            &TableOptions::default(),
        )
        .unwrap();
        // The accuracy gate (default 1 nm allowance) passed; per target a
        // polynomial block, an Abbe block for ex and ey (a rotation moves
        // the tool tip along z by ω × arm, whose z part has no arm_z: ez
        // does not depend on the tool length).
        assert!(e.max_f32_error_nm <= 1.0, "{e:?}");
        assert!(e.max_fixed_error_nm <= 1.0, "{e:?}");
        assert_eq!(e.terms, 5);
        assert_eq!(e.envelope.tool_range_mm, [0.0, 300.0]);
        let t = model_core::parse(&e.table).unwrap();
        // The table's f64 reference equals the model at random points at
        // two tool lengths.
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0.0f64;
        let mut largest = 0.0f64;
        for _ in 0..200 {
            let pos_nm = [800.0, 500.0, 400.0].map(|h| (next() * h * 1e6).round() as i32);
            for tool_mm in [0.0, 250.0] {
                let (gap, want) = rigid21_gap_nm(&t, &m, pos_nm, tool_mm);
                for k in 0..3 {
                    worst = worst.max(gap[k].abs());
                    largest = largest.max(want[k].abs());
                }
            }
        }
        assert!(largest > 1.0, "the model is not trivial: {largest} µm");
        assert!(worst <= 0.5, "table f64 vs model: {worst} nm");
    }

    #[test]
    fn a_rigid21_model_above_degree_4_is_refused() {
        let err = export(
            &file(FittedModel::Rigid21(rigid21_model(5))),
            &TableOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("rigid21:4 or lower"), "{err}");
    }

    #[test]
    fn a_limit_below_the_model_is_warned_and_recorded_for_the_clamp() {
        use super::error::tests::cubic_x;
        let opts = TableOptions {
            max_corr_um: Some(2.0),
            ..TableOptions::default()
        };
        let e = export(&cubic_x(), &opts).unwrap();
        assert_eq!(e.clamped.len(), 1);
        let c = e.clamped[0];
        assert_eq!((c.target, c.limit_nm), (0, 2000.0));
        assert!((c.model_max_nm - 4700.0).abs() < 1.0, "{c:?}");
        assert_eq!(e.envelope.max_corr_um[0], 2.0);
        let w: Vec<&Warning> = e
            .warnings
            .iter()
            .filter(|w| w.code == "max_corr_below_model")
            .collect();
        assert_eq!(w.len(), 1);
        assert!(
            w[0].detail
                .starts_with("ex: the max |correction| limit 2 µm"),
            "{w:?}"
        );
        // Without a limit nothing is clamped.
        assert!(export(&cubic_x(), &TableOptions::default())
            .unwrap()
            .clamped
            .is_empty());
    }
}
