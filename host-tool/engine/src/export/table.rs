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

use anyhow::{bail, Context, Result};
use serde::Serialize;

use model_core::spec::{
    GridAxisSpec, GridSpec, LayerSpec, MlpInputSpec, MlpSource, MlpSpec, PolyCoef, TableSpec,
    TermSpec,
};
use model_core::table::{Envelope, InputScaling, MAX_DEGREE};
use model_core::{Inputs, Model, MAX_TEMPS};

use super::{axis_travel_mm, predict_points, Point, Warning};
use crate::data::{AXES, TARGETS};
use crate::features::{Feature, Phase};
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

/// The envelope in readable units for JSON.
#[derive(Clone, Debug, Serialize)]
pub struct EnvelopeJson {
    /// Per axis `[min, max]`, mm (`null` = unbounded).
    pub travel_mm: [Option<[f64; 2]>; 3],
    /// Per output, µm.
    pub max_corr_um: [f64; 3],
    /// nm/ms.
    pub max_slew_nm_per_ms: i32,
    /// °C: the lowest and highest end over the channels the table reads
    /// (`null` when it reads none and no range was given).
    pub temp_range_c: Option<[f64; 2]>,
    /// °C, per channel the table reads.
    pub temp_range_c_by_channel: std::collections::BTreeMap<String, [f64; 2]>,
    /// mm.
    pub tool_range_mm: [f64; 2],
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

/// The model as model-core terms, its channels, and warnings. Thermal lags
/// are refused unless `drop_lag`.
fn terms_of(
    model: &FittedModel,
    drop_lag: bool,
    transition_nm: i32,
) -> Result<(Vec<TermSpec>, Vec<String>, Vec<Warning>)> {
    let mut warnings = Vec::new();
    let mut terms = Vec::new();
    let mut channels: Vec<String> = Vec::new();
    match model {
        FittedModel::Linear(m) => {
            for o in &m.outputs {
                let out = o.target as u8;
                let mut poly: Vec<PolyCoef> = Vec::new();
                let mut abbe: Vec<PolyCoef> = Vec::new();
                // (axis, period_mm) → (sin, cos) by harmonic.
                let mut periodic: Vec<(usize, f64, Vec<f64>, Vec<f64>)> = Vec::new();
                // (channel, t_ref_c) → coefficients nm/K.
                let mut thermal: Vec<(String, f64, Vec<PolyCoef>)> = Vec::new();
                let mut reversal: Vec<(usize, f64)> = Vec::new();
                let add = |v: &mut Vec<PolyCoef>, exp: [u8; 3], c: f64| {
                    match v.iter_mut().find(|(e, _)| *e == exp) {
                        Some((_, acc)) => *acc += c,
                        None => v.push((exp, c)),
                    }
                };
                let degree_ok = |exp: [u8; 3]| exp.iter().map(|&e| u32::from(e)).sum::<u32>() <= u32::from(MAX_DEGREE);
                for (f, &c_um) in o.features.iter().zip(&o.coef_um) {
                    let c_nm = -1000.0 * c_um; // correction = −error
                    match f {
                        Feature::Monomial { exp } => {
                            if !degree_ok(*exp) {
                                bail!("{}: monomial {f} has degree above {MAX_DEGREE}, which the table cannot hold", TARGETS[o.target]);
                            }
                            add(&mut poly, *exp, c_nm);
                        }
                        Feature::Abbe { exp } => {
                            if !degree_ok(*exp) {
                                bail!("{}: Abbe term {f} has degree above {MAX_DEGREE}", TARGETS[o.target]);
                            }
                            // µm per mm of arm → nm per nm: ×1e-3 (and the sign).
                            add(&mut abbe, *exp, -1e-3 * c_um);
                        }
                        Feature::Periodic {
                            axis,
                            period_mm,
                            harmonic,
                            phase,
                        } => {
                            let k = usize::from(*harmonic);
                            if k == 0 || k > model_core::table::MAX_HARMONICS {
                                bail!("{f}: harmonic {k} outside 1..={}", model_core::table::MAX_HARMONICS);
                            }
                            let idx = match periodic
                                .iter()
                                .position(|p| p.0 == *axis && p.1 == *period_mm)
                            {
                                Some(i) => i,
                                None => {
                                    periodic.push((*axis, *period_mm, Vec::new(), Vec::new()));
                                    periodic.len() - 1
                                }
                            };
                            let p = &mut periodic[idx];
                            if p.2.len() < k {
                                p.2.resize(k, 0.0);
                                p.3.resize(k, 0.0);
                            }
                            match phase {
                                Phase::Sin => p.2[k - 1] += c_nm,
                                Phase::Cos => p.3[k - 1] += c_nm,
                            }
                        }
                        Feature::Thermal {
                            channel,
                            t_ref_c,
                            lag_s,
                            exp,
                        } => {
                            if *lag_s > 0.0 {
                                if !drop_lag {
                                    bail!(
                                        "{}: the thermal term {f} has a lag of {lag_s} s, which the firmware table cannot represent (it applies the coefficient to the sensor reading at once); refit without lag_s, or export with --drop-lag to use its steady state",
                                        TARGETS[o.target]
                                    );
                                }
                                warnings.push(Warning::new(
                                    "lag_dropped",
                                    format!("{}: {f} exported without its {lag_s} s lag: right in steady state, wrong while the temperature changes", TARGETS[o.target]),
                                ));
                            }
                            if !degree_ok(*exp) {
                                bail!("{}: thermal term {f} has degree above {MAX_DEGREE}", TARGETS[o.target]);
                            }
                            if !channels.contains(channel) {
                                channels.push(channel.clone());
                            }
                            let idx = match thermal
                                .iter()
                                .position(|t| &t.0 == channel && t.1 == *t_ref_c)
                            {
                                Some(i) => i,
                                None => {
                                    thermal.push((channel.clone(), *t_ref_c, Vec::new()));
                                    thermal.len() - 1
                                }
                            };
                            add(&mut thermal[idx].2, *exp, c_nm);
                        }
                        Feature::Reversal { axis } => {
                            match reversal.iter_mut().find(|r| r.0 == *axis) {
                                Some(r) => r.1 += c_nm,
                                None => reversal.push((*axis, c_nm)),
                            }
                        }
                        Feature::Drift { .. } => {
                            warnings.push(Warning::new(
                                "drift_left_out",
                                format!(
                                    "{}: {f} ({c_um:+.4} µm per h^p) left out: drift describes the measurement session, not the machine",
                                    TARGETS[o.target]
                                ),
                            ));
                        }
                    }
                }
                if !poly.is_empty() {
                    terms.push(TermSpec::Poly { output: out, coefs: poly });
                }
                for (axis, period_mm, sin_nm, cos_nm) in periodic {
                    let period_nm = nm(period_mm).context("periodic period")?;
                    if period_nm <= 0 {
                        bail!("periodic term on {}: period {period_mm} mm rounds to 0 nm", AXES[axis]);
                    }
                    if ((period_nm as f64) * 1e-6 - period_mm).abs() > 1e-9 {
                        warnings.push(Warning::new(
                            "period_rounded",
                            format!("period {period_mm} mm stored as {period_nm} nm"),
                        ));
                    }
                    terms.push(TermSpec::Periodic {
                        output: out,
                        axis: axis as u8,
                        period_nm,
                        sin_nm,
                        cos_nm,
                    });
                }
                for (channel, t_ref_c, coefs) in thermal {
                    let ch = channels.iter().position(|c| *c == channel).unwrap_or(0);
                    terms.push(TermSpec::Thermal {
                        output: out,
                        channel: ch as u8,
                        t_ref_mc: mc(t_ref_c)?,
                        coefs_nm_per_k: coefs,
                    });
                }
                for (axis, amplitude_nm) in reversal {
                    terms.push(TermSpec::Reversal {
                        output: out,
                        axis: axis as u8,
                        transition_nm,
                        amplitude_nm,
                    });
                }
                if !abbe.is_empty() {
                    terms.push(TermSpec::Abbe { output: out, coefs: abbe });
                }
            }
        }
        FittedModel::Nn(m) => {
            let n_in = m.inputs.len();
            let inputs = (0..n_in)
                .map(|i| {
                    Ok(MlpInputSpec {
                        source: MlpSource::Pos(m.inputs[i] as u8),
                        min: f64::from(nm(m.in_min_mm[i])?),
                        max: f64::from(nm(m.in_max_mm[i])?),
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            for i in &inputs {
                if i.max <= i.min {
                    bail!("network input scaling is empty ({}…{} nm)", i.min, i.max);
                }
            }
            // Output scaling −1 ↦ min, +1 ↦ max in nm of *correction*:
            // negating swaps the ends, so min_corr = −max_err.
            terms.push(TermSpec::Mlp(MlpSpec {
                outputs: m.outputs.iter().map(|&t| t as u8).collect(),
                inputs,
                hidden: vec![LayerSpec {
                    weights: m.w1.clone(),
                    bias: m.b1.clone(),
                }],
                output: LayerSpec {
                    // y_corr = −y_err: flip the output layer so the scaled
                    // output of the correction uses swapped ends.
                    weights: m.w2.iter().map(|w| -w).collect(),
                    bias: m.b2.iter().map(|b| -b).collect(),
                },
                out_min_nm: m.out_max_um.iter().map(|v| -1000.0 * v).collect(),
                out_max_nm: m.out_min_um.iter().map(|v| -1000.0 * v).collect(),
            }));
        }
        FittedModel::Grid(g) => {
            let step_nm = nm(g.step_mm)?;
            if step_nm <= 0 {
                bail!("grid step {} mm is not positive", g.step_mm);
            }
            let mut axes = [GridAxisSpec {
                nodes: 1,
                origin_nm: 0,
                step_nm: 1_000_000,
            }; 3];
            // The model stores its first listed axis fastest; the table
            // stores x fastest. They agree when the axes are ascending.
            if g.axes.windows(2).any(|w| w[0] >= w[1]) {
                bail!("grid model axes {:?} are not in x, y, z order", g.axes);
            }
            for (i, &a) in g.axes.iter().enumerate() {
                axes[a] = GridAxisSpec {
                    nodes: u16::try_from(g.counts[i]).context("grid node count")?,
                    origin_nm: nm(g.origin_mm[i])?,
                    step_nm,
                };
            }
            for o in &g.outputs {
                terms.push(TermSpec::Grid(GridSpec {
                    output: o.target as u8,
                    axes,
                    values_nm: o.values_um.iter().map(|v| -1000.0 * v).collect(),
                }));
            }
        }
        FittedModel::Local(_) => bail!(
            "local (piecewise) models cannot be exported as a table: the firmware evaluates one global model; fit a global seed (cubic19 with --add …) or grid:<step_mm>"
        ),
    }
    if channels.len() > MAX_TEMPS {
        bail!(
            "the model reads {} temperature channels ({}); a table holds at most {MAX_TEMPS}",
            channels.len(),
            channels.join(", ")
        );
    }
    Ok((terms, channels, warnings))
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

/// The fallback temperature range of a model file that does not record the
/// measured one (written before it was recorded), °C.
const FALLBACK_TEMP_RANGE_C: (f64, f64) = (10.0, 40.0);

/// The temperature range of each of `channels`, °C: `given` for every
/// channel, else the range measured in the fitted data (rounded outwards to
/// the table's 1 m°C), else 10…40 °C with the warning `temp_range_unknown`.
fn temp_ranges(
    file: &ModelFile,
    channels: &[String],
    given: Option<(f64, f64)>,
    warnings: &mut Vec<Warning>,
) -> Result<Vec<(f64, f64)>> {
    if let Some((lo, hi)) = given {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            bail!("temperature range {lo}…{hi} °C is empty");
        }
        return Ok(vec![(lo, hi); channels.len()]);
    }
    let mut out = Vec::with_capacity(channels.len());
    let mut unknown = Vec::new();
    for c in channels {
        match file.data.temp_range_c.as_ref().and_then(|m| m.get(c)) {
            Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && lo <= hi => {
                out.push((
                    (lo * 1000.0).floor() / 1000.0,
                    (hi * 1000.0).ceil() / 1000.0,
                ));
            }
            _ => {
                unknown.push(format!("T_{c}_C"));
                out.push(FALLBACK_TEMP_RANGE_C);
            }
        }
    }
    if !unknown.is_empty() {
        let (lo, hi) = FALLBACK_TEMP_RANGE_C;
        warnings.push(Warning::new(
            "temp_range_unknown",
            format!(
                "the model file does not record the temperatures measured on {} (written by an older trueaxis): the table accepts {lo}…{hi} °C there, which may extrapolate the thermal terms beyond the data — refit the model, or give the measured range with --temp-range-c",
                unknown.join(", ")
            ),
        ));
    }
    Ok(out)
}

/// True when the model has a term of this kind (for the sweep's states).
fn has(model: &FittedModel, pred: impl Fn(&Feature) -> bool) -> bool {
    match model {
        FittedModel::Linear(m) => m.outputs.iter().flat_map(|o| &o.features).any(pred),
        _ => false,
    }
}

/// Shortest period on `axis` among the model's periodic terms, mm.
pub(super) fn shortest_period_mm(model: &FittedModel, axis: usize) -> Option<f64> {
    let FittedModel::Linear(m) = model else {
        return None;
    };
    m.outputs
        .iter()
        .flat_map(|o| &o.features)
        .filter_map(|f| match f {
            Feature::Periodic {
                axis: a,
                period_mm,
                harmonic,
                ..
            } if *a == axis => Some(period_mm / f64::from(*harmonic)),
            _ => None,
        })
        .reduce(f64::min)
}

/// The model with every thermal lag set to 0 (the steady state the table
/// holds when `drop_lag` is used).
fn without_lag(model: &FittedModel) -> FittedModel {
    let mut m = model.clone();
    if let FittedModel::Linear(l) = &mut m {
        for o in &mut l.outputs {
            for f in &mut o.features {
                if let Feature::Thermal { lag_s, .. } = f {
                    *lag_s = 0.0;
                }
            }
        }
    }
    m
}

/// The larger of `a` and `b`, NaN when either is.
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Exports `file` as a table and runs the accuracy check.
// Per-axis and per-output arrays are indexed together; index loops read clearer.
#[allow(clippy::needless_range_loop)]
pub fn export(file: &ModelFile, opts: &TableOptions) -> Result<TableExport> {
    let model = if opts.drop_lag {
        without_lag(&file.model)
    } else {
        file.model.clone()
    };
    if !(opts.reversal_transition_um.is_finite() && opts.reversal_transition_um >= 0.0) {
        bail!("--reversal-transition-um must be ≥ 0");
    }
    let transition_nm = (opts.reversal_transition_um * 1000.0).round() as i32;
    let (terms, channels, mut warnings) = terms_of(&file.model, opts.drop_lag, transition_nm)?;
    if terms.is_empty() {
        bail!("the model has no term the table can hold");
    }

    // Travel and scaling.
    let mut travel: [Option<(i32, i32)>; 3] = [None; 3];
    let mut scaling = InputScaling {
        centre_nm: [0; 3],
        half_span_nm: [UNBOUNDED_NM; 3],
    };
    for a in 0..3 {
        if let Some((lo, hi)) = axis_travel_mm(&model, a) {
            let (lo_nm, hi_nm) = (nm(lo)?, nm(hi)?);
            if hi_nm < lo_nm {
                bail!("empty travel on {}", AXES[a]);
            }
            travel[a] = Some((lo_nm, hi_nm));
            // Centre and half-span from the model's own normalisation when
            // it has one (so u is the same number on both sides).
            let (c, h) = match &model {
                FittedModel::Linear(m) => (m.norm.centre_mm[a], m.norm.half_span_mm[a]),
                _ => (0.5 * (lo + hi), 0.5 * (hi - lo)),
            };
            let (c_nm, h_nm) = (nm(c)?, ((h * 1e6).round() as i64).max(1));
            // The travel must lie inside centre ± half-span after rounding.
            let h_nm = h_nm
                .max(c_nm as i64 - lo_nm as i64)
                .max(hi_nm as i64 - c_nm as i64);
            scaling.centre_nm[a] = c_nm;
            scaling.half_span_nm[a] = i32::try_from(h_nm).context("half-span")?;
        }
    }

    let temp_ranges = temp_ranges(file, &channels, opts.temp_range_c, &mut warnings)?;
    let has_abbe = has(&model, |f| matches!(f, Feature::Abbe { .. }));
    let (tool_lo, tool_hi) =
        opts.tool_range_mm
            .unwrap_or(if has_abbe { (0.0, 300.0) } else { (0.0, 0.0) });
    if tool_lo.is_nan() || tool_hi.is_nan() || tool_lo > tool_hi {
        bail!("tool range {tool_lo}…{tool_hi} mm is empty");
    }
    let has_rev = has(&model, |f| matches!(f, Feature::Reversal { .. }));

    // The sweep: an 11-point grid on the used axes at every state, and
    // dense lines at the first and last state (both directions, low and
    // high temperature and tool arm together).
    let used: Vec<usize> = (0..3).filter(|&a| travel[a].is_some()).collect();
    let at = |a: usize, k: usize, n: usize| -> f64 {
        let (lo, hi) = travel[a].unwrap_or((0, 0));
        let v = lo as f64 + (hi as f64 - lo as f64) * k as f64 / (n - 1).max(1) as f64;
        v.round() * 1e-6
    };
    let n_grid: usize = 11;
    let mut grid_pos: Vec<[f64; 3]> = Vec::new();
    for k in 0..n_grid.pow(used.len() as u32) {
        let mut p = [0.0; 3];
        let mut r = k;
        for &a in &used {
            p[a] = at(a, r % n_grid, n_grid);
            r /= n_grid;
        }
        grid_pos.push(p);
    }
    let mut line_pos: Vec<[f64; 3]> = Vec::new();
    for &a in &used {
        let (lo, hi) = travel[a].unwrap_or((0, 0));
        let span_mm = (hi as f64 - lo as f64) * 1e-6;
        let step = match shortest_period_mm(&model, a) {
            Some(p) => (p / 16.0).min(span_mm / 2000.0),
            None => span_mm / 2000.0,
        };
        let n_line = ((span_mm / step.max(1e-6)).ceil() as usize + 1).clamp(2, 4000);
        // The other axes at their low, middle and high position together.
        for k in 0..3 {
            let mut base = [0.0; 3];
            for &b in used.iter().filter(|&&b| b != a) {
                base[b] = at(b, k, 3);
            }
            for i in 0..n_line {
                let mut p = base;
                p[a] = at(a, i, n_line);
                line_pos.push(p);
            }
        }
    }
    let dirs: Vec<i8> = if has_rev { vec![1, -1] } else { vec![1] };
    // 0 = every channel at its low end, 1 = at its high end.
    let temps: Vec<usize> = if channels.is_empty() {
        vec![0]
    } else {
        vec![0, 1]
    };
    let tools: Vec<f64> = if has_abbe {
        vec![tool_lo, tool_hi]
    } else {
        vec![tool_lo]
    };
    let mut states: Vec<(i8, usize, f64)> = Vec::new();
    for &d in &dirs {
        for &t in &temps {
            for &tool in &tools {
                states.push((d, t, tool));
            }
        }
    }
    let first_last = [states[0], states[states.len() - 1]];
    let mut points = Vec::with_capacity(grid_pos.len() * states.len() + 2 * line_pos.len());
    let mut push = |p: &[f64; 3], (d, t, tool): (i8, usize, f64)| {
        points.push(Point {
            pos_mm: *p,
            dir: [d; 3],
            temp_c: temp_ranges
                .iter()
                .map(|r| ((if t == 0 { r.0 } else { r.1 }) * 1000.0).round() / 1000.0)
                .collect(),
            tool_mm: (tool * 1e6).round() * 1e-6,
        });
    };
    for &st in &states {
        for p in &grid_pos {
            push(p, st);
        }
    }
    for (k, &st) in first_last.iter().enumerate() {
        if k == 1 && states.len() == 1 {
            break;
        }
        for p in &line_pos {
            push(p, st);
        }
    }
    let pred = predict_points(&model, &channels, &points)?;
    let outputs = [0, 1, 2].map(|t| pred[t].is_some());
    // Host corrections, nm.
    let host: [Option<Vec<f64>>; 3] =
        pred.map(|p| p.map(|v| v.iter().map(|e| -1000.0 * e).collect()));

    // Envelope from the sweep.
    let mut max_corr_nm = [0i32; 3];
    for t in 0..3 {
        let Some(h) = &host[t] else { continue };
        let m = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let limit = super::max_corr_limit_nm(t, m, opts.max_corr_um)?;
        if limit < m {
            warnings.push(Warning::new(
                "max_corr_below_model",
                format!(
                    "{}: --max-corr-um {} is below the model's {:.3} µm: the firmware will clamp",
                    TARGETS[t],
                    limit / 1000.0,
                    m / 1000.0
                ),
            ));
        }
        max_corr_nm[t] = limit.ceil() as i32;
    }
    // Gradient along each axis from neighbouring points on the dense lines
    // (consecutive points that differ on one axis only).
    let mut grad_nm_per_mm = 0.0f64;
    for h in host.iter().flatten() {
        for i in 1..points.len() {
            let (p, q) = (&points[i - 1], &points[i]);
            if p.dir != q.dir || p.temp_c != q.temp_c || p.tool_mm != q.tool_mm {
                continue;
            }
            let d: Vec<f64> = (0..3).map(|a| q.pos_mm[a] - p.pos_mm[a]).collect();
            let moved = d.iter().filter(|v| v.abs() > 0.0).count();
            let dist = d.iter().map(|v| v.abs()).sum::<f64>();
            if moved == 1 && dist > 0.0 {
                grad_nm_per_mm = grad_nm_per_mm.max((h[i] - h[i - 1]).abs() / dist);
            }
        }
    }
    if has_rev && transition_nm > 0 {
        if let FittedModel::Linear(m) = &model {
            for o in &m.outputs {
                for (f, c) in o.features.iter().zip(&o.coef_um) {
                    if matches!(f, Feature::Reversal { .. }) {
                        // A swing of 2·|amp| over the transition length.
                        let g = 2.0 * c.abs() * 1000.0 / (f64::from(transition_nm) * 1e-6);
                        grad_nm_per_mm = grad_nm_per_mm.max(g);
                    }
                }
            }
        }
    }
    let feed_mm_per_ms = opts.max_feed_mm_per_min / 60_000.0;
    let slew = match opts.max_slew_nm_per_ms {
        Some(s) => {
            if !(s.is_finite() && s >= 1.0) {
                bail!("--max-slew-nm-per-ms must be ≥ 1");
            }
            s
        }
        None => {
            if !(opts.max_feed_mm_per_min.is_finite() && opts.max_feed_mm_per_min > 0.0) {
                bail!("--max-feed-mm-per-min must be positive");
            }
            (1.5 * grad_nm_per_mm * feed_mm_per_ms).max(1.0)
        }
    };
    let max_slew_nm_per_ms = slew.ceil().min(f64::from(i32::MAX)) as i32;

    let mut env = Envelope {
        travel_min_nm: [0; 3],
        travel_max_nm: [0; 3],
        max_corr_nm,
        max_slew_nm_per_ms,
        temp_min_mc: [0; MAX_TEMPS],
        temp_max_mc: [0; MAX_TEMPS],
        tool_min_nm: nm(tool_lo)?,
        tool_max_nm: nm(tool_hi)?,
    };
    for a in 0..3 {
        let (lo, hi) = travel[a].unwrap_or((-UNBOUNDED_NM, UNBOUNDED_NM));
        env.travel_min_nm[a] = lo;
        env.travel_max_nm[a] = hi;
    }
    for (ch, &(lo, hi)) in temp_ranges.iter().enumerate() {
        env.temp_min_mc[ch] = mc(lo)?;
        env.temp_max_mc[ch] = mc(hi)?;
    }
    let mut source_hash = [0u8; 32];
    for (i, b) in source_hash.iter_mut().enumerate() {
        *b = file
            .data
            .sha256
            .get(2 * i..2 * i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0);
    }
    let spec = TableSpec {
        created_unix_s: opts.created_unix_s,
        source_hash,
        channels: channels.clone(),
        envelope: env,
        scaling,
        outputs,
        terms,
    };
    let bytes = spec
        .encode()
        .map_err(|e| anyhow::anyhow!("encoding the table: {e}"))?;
    let table = model_core::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("the encoded table does not parse: {e}"))?;
    let crc = table.crc32();
    // A table the firmware's model cannot even hold is refused (nothing is
    // written): no controller could run it, and the check below needs it.
    let fw = Model::load(&table).map_err(|e| {
        anyhow::anyhow!(
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

    // The check.
    let mut max_f32 = 0.0f64;
    let mut max_fixed = 0.0f64;
    for (i, p) in points.iter().enumerate() {
        let mut inp = Inputs {
            pos_nm: [0; 3],
            rev_q30: p.dir.map(|d| i32::from(d) * (1 << 30)),
            temp_mc: [0; MAX_TEMPS],
            tool_nm: nm(p.tool_mm)?,
        };
        for a in 0..3 {
            inp.pos_nm[a] = nm(p.pos_mm[a])?;
        }
        for (ch, t) in p.temp_c.iter().enumerate() {
            inp.temp_mc[ch] = mc(*t)?;
        }
        let f32_out = fw.eval_f32(&inp);
        let fixed_out = fw.eval_fixed(&inp);
        for t in 0..3 {
            let Some(h) = &host[t] else { continue };
            // The firmware clamps to the envelope's max |correction| by
            // design; with a `--max-corr-um` below the model's (warned
            // above) the check must compare like with like, or every such
            // export would fail on the clamp rather than on the arithmetic.
            let lim = f64::from(max_corr_nm[t]);
            let want = h[i].clamp(-lim, lim);
            // NaN-sticky (f64::max would drop it): a non-finite
            // difference fails the check instead of reading as 0 nm.
            max_f32 = nan_max(max_f32, (f64::from(f32_out.corr_nm[t]) - want).abs());
            max_fixed = nan_max(max_fixed, (f64::from(fixed_out.corr_nm[t]) - want).abs());
        }
    }
    let travel_mm = travel.map(|t| t.map(|(lo, hi)| [f64::from(lo) * 1e-6, f64::from(hi) * 1e-6]));
    Ok(TableExport {
        bytes: bytes.len(),
        crc32: format!("0x{crc:08x}"),
        max_f32_error_nm: max_f32,
        max_fixed_error_nm: max_fixed,
        sweep_points: points.len(),
        terms: spec.terms.len(),
        envelope: EnvelopeJson {
            travel_mm,
            max_corr_um: max_corr_nm.map(|v| f64::from(v) / 1000.0),
            max_slew_nm_per_ms,
            temp_range_c: match opts.temp_range_c {
                Some((lo, hi)) => Some([lo, hi]),
                None => temp_ranges
                    .iter()
                    .copied()
                    .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
                    .map(|(lo, hi)| [lo, hi]),
            },
            temp_range_c_by_channel: channels
                .iter()
                .zip(&temp_ranges)
                .map(|(c, &(lo, hi))| (c.clone(), [lo, hi]))
                .collect(),
            tool_range_mm: [tool_lo, tool_hi],
        },
        board,
        warnings,
        table: bytes,
        spec: Some(spec),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{Norm, CUBIC19};
    use crate::model::{
        DataRef, FitStats, GridModel, GridOutput, LinearModel, LinearOutput, NnModel, NnTraining,
        MODEL_FORMAT,
    };

    fn file(model: FittedModel) -> ModelFile {
        ModelFile {
            format: MODEL_FORMAT.into(),
            seed: "test".into(),
            adds: vec![],
            data: DataRef {
                source: "test".into(),
                sha256: "ab".repeat(32),
                rows: 0,
                temp_range_c: Some(Default::default()),
            },
            model,
            stats: FitStats::default(),
        }
    }

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
        assert!(format!("{err:#}").contains("--drop-lag"), "{err:#}");
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
}
