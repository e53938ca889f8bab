//! Fitting a compensation model to measurements: the one entry point
//! [`fit`] that `trueaxis fit`, `diagnose`, `improve` and `demo` call, and
//! the model kinds behind it —
//!
//! - `linear`: weighted least squares of a term set (`cubic19`, `kinematic`,
//!   plus `--add` effects), one fit per target;
//! - `local`: the seed's local polynomials on the cuboid between two
//!   measured planes / the plane / the line (`--local`);
//! - `grid`: a table with (bi/tri)linear interpolation (`grid:<step_mm>`);
//! - `nn`: a tanh MLP trained by Levenberg–Marquardt (`nn:<hidden>`).

pub mod bench_data;
pub mod grid;
pub mod linear;
pub mod local;
pub mod nn;
pub mod rigid21;
pub mod volumetric_check;

use anyhow::{bail, Result};

use crate::data::{Dataset, AXES, TARGETS};
use crate::effect::Effect;
use crate::holdout;
use crate::model::{DataRef, FitStats, FittedModel, ModelFile, ModelSeed, Seed, MODEL_FORMAT};
use crate::progress::Sink;
use crate::warning::Warning;

/// Options of a fit beyond the model spec.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Hold-out blocks (≥ 2) for the held-out RMS.
    pub blocks: usize,
    /// Fit the seed's local polynomials instead of one global polynomial.
    pub local: bool,
    /// Neural-network training options.
    pub nn: nn::NnOptions,
    /// Where progress events of long computations (network training) go.
    pub progress: Sink,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            blocks: holdout::DEFAULT_BLOCKS,
            local: false,
            nn: nn::NnOptions::default(),
            progress: Sink::none(),
        }
    }
}

/// What a fit refuses to do, in the engine's words; a caller names its
/// own way of asking (the CLI: `--add`, `--local`, cmd/flags.rs).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Effects added to a local fit.
    #[error("a local fit takes no added effects (the local patches use the seed's own terms)")]
    LocalWithEffects,
    /// A local fit or added effects asked of a seed that is no polynomial
    /// (added effects: nor rigid21).
    #[error("local fits and added effects apply to the polynomial seeds (cubic19, kinematic; added effects also to rigid21), not to {seed}")]
    NotPolynomial {
        /// The seed as given (`nn:8`, `grid:10`).
        seed: String,
    },
    /// Data a local fit cannot be made of.
    #[error("local fit: {0}")]
    Local(LocalRefusal),
}

/// Why data cannot have a local fit.
#[derive(Clone, Debug, PartialEq)]
pub enum LocalRefusal {
    /// The points are not on whole planes (the cuboid fit's stack).
    NotOnPlanes {
        /// Distinct positions along the stacking axis.
        planes: usize,
        /// The stacking axis (0 = x).
        axis: usize,
        /// Points in all.
        points: usize,
    },
    /// Every point at one position: nothing to fit a polynomial along.
    NoTravel,
}

impl std::fmt::Display for LocalRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LocalRefusal::NotOnPlanes {
                planes,
                axis,
                points,
            } => write!(
                f,
                "the data is not on measured planes ({planes} distinct {} positions for {points} points); the cuboid fit needs whole planes of points",
                AXES[*axis]
            ),
            LocalRefusal::NoTravel => f.write_str(
                "every measured point lies at one position; a local fit needs travel on some axis",
            ),
        }
    }
}

/// Fits the model `seed` (+ `adds`) to `data` and returns the complete
/// MODEL.json content, statistics included. Bad input (unknown seed, an
/// effect on a target or channel the data lacks, fewer distinct points than
/// terms, collinear columns, u_um ≤ 0) is an error with a message for the user.
pub fn fit(data: &Dataset, seed: &str, adds: &[Effect], opts: &FitOptions) -> Result<ModelFile> {
    fit_recorded(data, seed, adds, opts, || crate::import::content_hash(data))
}

/// [`fit`] of `data` recorded as fitted to the file whose content hash
/// `sha256` gives: `fit` and `improve` fit the file less its outliers and
/// record the file (`history` follows the file), so the hash of the
/// cleaned copy — a canonical CSV of every row, as long to make as the
/// fit's own solve at a million rows — is never computed, and `improve`
/// computes the file's once for all its steps.
pub fn fit_recorded(
    data: &Dataset,
    seed: &str,
    adds: &[Effect],
    opts: &FitOptions,
    sha256: impl FnOnce() -> String,
) -> Result<ModelFile> {
    let parsed = Seed::parse(seed)?;
    if data.is_empty() {
        bail!("{}: no data rows", data.source);
    }
    if data.targets().is_empty() && !matches!(parsed, Seed::Rigid21 { .. }) {
        bail!(
            "no ex_um, ey_um or ez_um column — the data hold only angle or beam readings (ea_urad, eb_urad, ec_urad, e_beam_um), which only the volumetric model reads (docs/volumetric.md)"
        );
    }
    for e in adds {
        if data.err_um[e.target()].is_none() {
            bail!(
                "effect `{}` is for {} but the data has no {}_um column",
                e.spec,
                e.spec.target(),
                e.spec.target()
            );
        }
    }
    let polynomial = matches!(parsed, Seed::Cubic19 | Seed::Kinematic);
    // rigid21 takes added effects on top (docs/volumetric.md), no local fit.
    let takes_adds = polynomial || matches!(parsed, Seed::Rigid21 { .. });
    if (!polynomial && opts.local) || (!takes_adds && !adds.is_empty()) {
        return Err(FitError::NotPolynomial {
            seed: seed.to_string(),
        }
        .into());
    }
    let blocks = opts.blocks.max(2);
    let (model, mut stats, seed_name) = match parsed {
        Seed::Cubic19 | Seed::Kinematic if opts.local => {
            if !adds.is_empty() {
                return Err(FitError::LocalWithEffects.into());
            }
            let (m, s) = local::fit(data, blocks)?;
            let name = ModelSeed {
                seed: parsed,
                local: true,
            };
            (m, s, name.to_string())
        }
        Seed::Cubic19 | Seed::Kinematic => {
            let (m, s) = linear::fit(data, parsed, adds, blocks)?;
            (m, s, parsed.to_string())
        }
        Seed::Nn { hidden } => {
            let (m, s) = nn::fit(data, hidden, &opts.nn, &opts.progress, blocks)?;
            (m, s, seed.to_string())
        }
        Seed::Grid { step_mm } => {
            let (m, s) = grid::fit(data, step_mm, blocks)?;
            (m, s, seed.to_string())
        }
        Seed::Rigid21 { degree } => {
            let (m, id, kinds) = rigid21::fit_with(data, degree, adds)?;
            let mut stats = FitStats {
                terms: m.errors.iter().map(|e| e.degrees.len()).sum::<usize>()
                    + adds.iter().map(|e| e.features.len()).sum::<usize>(),
                holdout: "none (rigid21: hold-out by set-up is not built yet)".into(),
                ..FitStats::default()
            };
            for (key, rms, n) in kinds {
                stats.rows.insert(key.clone(), n);
                stats.rms_um.insert(key, rms);
            }
            if let Some(text) = rigid21::cannot_know_text(&id) {
                stats.warnings.push(Warning::new("cannot_know", text));
            }
            stats.volumetric = Some(id);
            (FittedModel::Rigid21(m), stats, parsed.to_string())
        }
    };
    // Every model kind leaves out an axis held at one position (no terms,
    // grid nodes or network input along it): say so, with the position.
    for a in data.axes() {
        if let Some(p) = data.constant_position(a) {
            stats.warnings.push(Warning::new("axis_not_modelled", format!(
                "{ax}: every measured point is at {ax} = {p} mm; {ax} is not modelled (the correction does not depend on {ax}, as for an axis absent from the data)",
                ax = AXES[a]
            )));
        }
    }
    Ok(ModelFile {
        format: MODEL_FORMAT.to_string(),
        seed: seed_name,
        adds: adds.iter().map(|e| e.spec.to_string()).collect(),
        data: DataRef {
            source: data.source.clone(),
            sha256: sha256(),
            rows: data.len(),
            temp_range_c: Some(
                data.temps
                    .iter()
                    .map(|c| {
                        let lo = c.temp_c.iter().copied().fold(f64::INFINITY, f64::min);
                        let hi = c.temp_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                        (c.name.clone(), [lo, hi])
                    })
                    .collect(),
            ),
            outside_travel: Vec::new(),
        },
        model,
        stats,
    })
}

/// Records in `model` (fitted to `screen.inside(data)`) the rows of `data`
/// outside the travel (`crate::travel`), each with the model's miss there:
/// measured − model per target measured on the row, µm — the row held out
/// from the fit, evaluated outside the fitted travel. A model that cannot
/// be evaluated there records the rows without their misses.
pub fn record_outside(model: &mut ModelFile, data: &Dataset, screen: &crate::travel::Screen) {
    let mut outside = screen.outside.clone();
    let rows = screen.outside_rows();
    if !rows.is_empty() {
        if let Ok(pred) = model.model.predict(&crate::data::subset(data, &rows)) {
            for o in &mut outside {
                let k = rows.partition_point(|&r| r < o.row);
                for (t, p) in pred.iter().enumerate() {
                    let measured = data.err_um[t].as_ref().and_then(|c| c[o.row]);
                    if let (Some(p), Some(m)) = (p, measured) {
                        o.resid_um.insert(TARGETS[t].to_string(), m - p[k]);
                    }
                }
            }
        }
    }
    model.data.outside_travel = outside;
}
