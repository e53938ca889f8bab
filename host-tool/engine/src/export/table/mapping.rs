//! Model → table terms (the **Mapping** and **Units and sign** of the
//! module docs): a linear model's features grouped into model-core
//! `Poly`, `Periodic`, `Thermal`, `Reversal` and `Abbe` terms, a network
//! into an `Mlp` term, a grid into `Grid` terms, all as corrections in nm;
//! and what the rest of the export asks of the model (its kinds of terms,
//! its shortest period, its steady state).

use anyhow::{bail, Context, Result};

use model_core::spec::{
    GridAxisSpec, GridSpec, LayerSpec, MlpInputSpec, MlpSource, MlpSpec, PolyCoef, TermSpec,
};
use model_core::table::MAX_DEGREE;
use model_core::MAX_TEMPS;

use super::{mc, nm, TableError, Warning};
use crate::data::{AXES, TARGETS};
use crate::features::{Feature, Phase};
use crate::model::{FittedModel, LinearModel, LinearOutput};

/// The model as model-core terms, its channels, and warnings. Thermal lags
/// are refused unless `drop_lag`, local models always — as a
/// [`TableError`] inside the `anyhow` error, which `export` gets back
/// typed.
pub(super) fn terms_of(
    model: &FittedModel,
    drop_lag: bool,
    transition_nm: i32,
) -> Result<(Vec<TermSpec>, Vec<String>, Vec<Warning>)> {
    let mut warnings = Vec::new();
    let mut terms = Vec::new();
    let mut channels: Vec<String> = Vec::new();
    match model {
        FittedModel::Rigid21(m) => {
            terms.extend(rigid21_terms(m)?);
            // The named effects on top (docs/volumetric.md § Effects on
            // top): the linear models' terms, in the same scaled u.
            if let Some(fx) = &m.effects {
                terms.extend(linear_terms(
                    &fx.outputs,
                    drop_lag,
                    transition_nm,
                    &mut channels,
                    &mut warnings,
                )?);
            }
        }
        FittedModel::Linear(m) => terms.extend(linear_terms(
            &m.outputs,
            drop_lag,
            transition_nm,
            &mut channels,
            &mut warnings,
        )?),
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
        FittedModel::Local(_) => return Err(TableError::LocalModel.into()),
    }
    if channels.len() > MAX_TEMPS {
        bail!(
            "the model reads {} temperature channels ({}); a table holds at most {MAX_TEMPS}",
            channels.len(),
            channels.join(", ")
        );
    }
    // model-core stores each channel's name in 16 bytes; say which column
    // is too long here rather than "bad temperature channel name #0" from
    // the encoder.
    if let Some(c) = channels
        .iter()
        .find(|c| c.len() > model_core::table::CHANNEL_NAME_LEN)
    {
        bail!(
            "the model reads T_{c}_C: a table holds a channel name of at most {} bytes and `{c}` has {}; rename the column in the data (e.g. T_{}_C) and refit",
            model_core::table::CHANNEL_NAME_LEN,
            c.len(),
            c.chars().take(model_core::table::CHANNEL_NAME_LEN).collect::<String>()
        );
    }
    Ok((terms, channels, warnings))
}

/// A linear model's outputs (a linear model's, or a rigid21 model's
/// effects) as table terms: per target its monomials as a `Poly` term, its
/// periodic, thermal and reversal columns grouped into their terms, its
/// Abbe columns as an `Abbe` term; the channels the thermal terms read are
/// added to `channels`. Drift is left out with a warning.
fn linear_terms(
    outputs: &[LinearOutput],
    drop_lag: bool,
    transition_nm: i32,
    channels: &mut Vec<String>,
    warnings: &mut Vec<Warning>,
) -> Result<Vec<TermSpec>> {
    let mut terms = Vec::new();
    for o in outputs {
        let out = o.target as u8;
        let mut poly: Vec<PolyCoef> = Vec::new();
        let mut abbe: Vec<PolyCoef> = Vec::new();
        // (axis, period_mm) → (sin, cos) by harmonic.
        let mut periodic: Vec<(usize, f64, Vec<f64>, Vec<f64>)> = Vec::new();
        // (channel, t_ref_c) → coefficients nm/K.
        let mut thermal: Vec<(String, f64, Vec<PolyCoef>)> = Vec::new();
        let mut reversal: Vec<(usize, f64)> = Vec::new();
        let add = |v: &mut Vec<PolyCoef>, exp: [u8; 3], c: f64| match v
            .iter_mut()
            .find(|(e, _)| *e == exp)
        {
            Some((_, acc)) => *acc += c,
            None => v.push((exp, c)),
        };
        let degree_ok =
            |exp: [u8; 3]| exp.iter().map(|&e| u32::from(e)).sum::<u32>() <= u32::from(MAX_DEGREE);
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
                        bail!(
                            "{}: Abbe term {f} has degree above {MAX_DEGREE}",
                            TARGETS[o.target]
                        );
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
                        bail!(
                            "{f}: harmonic {k} outside 1..={}",
                            model_core::table::MAX_HARMONICS
                        );
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
                            return Err(TableError::Lag {
                                target: o.target,
                                term: f.to_string(),
                                lag_s: *lag_s,
                            }
                            .into());
                        }
                        warnings.push(Warning::new(
                            "lag_dropped",
                            format!("{}: {f} exported without its {lag_s} s lag: right in steady state, wrong while the temperature changes", TARGETS[o.target]),
                        ));
                    }
                    if !degree_ok(*exp) {
                        bail!(
                            "{}: thermal term {f} has degree above {MAX_DEGREE}",
                            TARGETS[o.target]
                        );
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
                Feature::Reversal { axis } => match reversal.iter_mut().find(|r| r.0 == *axis) {
                    Some(r) => r.1 += c_nm,
                    None => reversal.push((*axis, c_nm)),
                },
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
            terms.push(TermSpec::Poly {
                output: out,
                coefs: poly,
            });
        }
        for (axis, period_mm, sin_nm, cos_nm) in periodic {
            let period_nm = nm(period_mm).context("periodic period")?;
            if period_nm <= 0 {
                bail!(
                    "periodic term on {}: period {period_mm} mm rounds to 0 nm",
                    AXES[axis]
                );
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
            terms.push(TermSpec::Abbe {
                output: out,
                coefs: abbe,
            });
        }
    }
    Ok(terms)
}

/// A rigid21 model on the spindle axis (no lateral offset) at tool length
/// L is e = P0(x, y, z) + L·P1(x, y, z) with P0 of degree D + 1 and P1 of
/// degree D (docs/volumetric.md § On the board): per target a `Poly` term
/// (−P0) and an `Abbe` term (−P1), in the table's scaled coordinates u.
/// The monomial coefficients are solved from the model's own values on a
/// tensor grid of D + 2 Chebyshev nodes per axis, which determines every
/// polynomial of degree ≤ D + 1 exactly (up to rounding). Refused when the
/// monomials of degree D + 1 are more than a block holds.
fn rigid21_terms(m: &crate::model::Rigid21Model) -> Result<Vec<TermSpec>> {
    use crate::model::rigid21::ToolPoint;
    let top = m.degree + 1;
    let axes = m.chain.axes();
    if top > usize::from(MAX_DEGREE) {
        bail!(
            "a rigid21:{} model is a polynomial of degree {top} on the board (degree {} error functions times the arms); a table holds degree {MAX_DEGREE}: refit with rigid21:{} or lower",
            m.degree,
            m.degree,
            usize::from(MAX_DEGREE) - 1
        );
    }
    let mut exps: Vec<[u8; 3]> = Vec::new();
    let mut push_exps = |e: [u8; 3]| {
        let used_ok = (0..3).all(|a| e[a] == 0 || axes.contains(&a));
        if used_ok && e.iter().map(|&v| usize::from(v)).sum::<usize>() <= top {
            exps.push(e);
        }
    };
    for i in 0..=top as u8 {
        for j in 0..=top as u8 {
            for k in 0..=top as u8 {
                push_exps([i, j, k]);
            }
        }
    }
    if exps.len() > model_core::limits::MAX_MONOMIALS {
        bail!(
            "a rigid21:{} model needs {} monomials per target on the board; a table block holds {}: refit with a lower degree",
            m.degree,
            exps.len(),
            model_core::limits::MAX_MONOMIALS
        );
    }
    let (_, scaling) = super::envelope::travel_and_scaling(&FittedModel::Rigid21(m.clone()))?;
    let n = top + 1;
    let nodes: Vec<f64> = (0..n)
        .map(|i| (std::f64::consts::PI * (i as f64 + 0.5) / n as f64).cos())
        .collect();
    let grid = |a: usize| -> Vec<f64> {
        if axes.contains(&a) {
            nodes.clone()
        } else {
            vec![0.0]
        }
    };
    let mut us: Vec<[f64; 3]> = Vec::new();
    for &x in &grid(0) {
        for &y in &grid(1) {
            for &z in &grid(2) {
                us.push([x, y, z]);
            }
        }
    }
    let to_mm = |a: usize, u: f64| {
        if axes.contains(&a) {
            (f64::from(scaling.centre_nm[a]) + u * f64::from(scaling.half_span_nm[a])) * 1e-6
        } else {
            0.0
        }
    };
    // The arm used to separate P1: any length works (e is linear in L).
    const ARM_MM: f64 = 100.0;
    let cols: Vec<Vec<f64>> = exps
        .iter()
        .map(|e| {
            us.iter()
                .map(|u| (0..3).map(|a| u[a].powi(i32::from(e[a]))).product())
                .collect()
        })
        .collect();
    let mut y0: [Vec<f64>; 3] = Default::default();
    let mut y1: [Vec<f64>; 3] = Default::default();
    for u in &us {
        let pos_mm = [0, 1, 2].map(|a| to_mm(a, u[a]));
        let at = |tool_mm| {
            m.predict(&ToolPoint {
                pos_mm,
                tool_mm,
                tool_lat_mm: [0.0; 2],
            })
            .e_um
        };
        let (e0, e1) = (at(0.0), at(ARM_MM));
        for t in 0..3 {
            // Correction = −error: nm, and nm per nm of arm.
            y0[t].push(-1000.0 * e0[t]);
            y1[t].push(-1e-3 * (e1[t] - e0[t]) / ARM_MM);
        }
    }
    // A monomial the chain's structure does not produce (the angles of one
    // carriage times its arms: on the default chain 25 monomials in P0 and
    // 13 in P1 of the 56 of degree ≤ 5) comes out of the solve as rounding
    // noise, ~10⁻¹⁰ of the largest coefficient. One whose whole
    // contribution stays below 0.001 nm (|u| ≤ 1; the Abbe block at the
    // longest arm a table holds, 2^31 nm) is left out: the board then sums
    // only the monomials the model has (fewer instructions per tick), and
    // the accuracy gate still compares the table with the model.
    const NEGLIGIBLE_NM: f64 = 1e-3;
    let abbe_negligible = NEGLIGIBLE_NM / f64::from(i32::MAX);
    let mut terms = Vec::new();
    for t in 0..3 {
        let keep = |beta: Vec<f64>, negligible: f64| -> Vec<PolyCoef> {
            exps.iter()
                .zip(beta)
                .filter(|(_, c)| c.abs() >= negligible)
                .map(|(e, c)| (*e, c))
                .collect()
        };
        let fit = |y: &[f64]| crate::linalg::basis::small_fit(&cols, y).beta;
        let poly = keep(fit(&y0[t]), NEGLIGIBLE_NM);
        let abbe = keep(fit(&y1[t]), abbe_negligible);
        if !poly.is_empty() {
            terms.push(TermSpec::Poly {
                output: t as u8,
                coefs: poly,
            });
        }
        if !abbe.is_empty() {
            terms.push(TermSpec::Abbe {
                output: t as u8,
                coefs: abbe,
            });
        }
    }
    Ok(terms)
}

/// The model's part that is linear in features: a linear model, or a
/// rigid21 model's effects on top; `None` for the others.
pub(super) fn linear_part(model: &FittedModel) -> Option<&LinearModel> {
    match model {
        FittedModel::Linear(m) => Some(m),
        FittedModel::Rigid21(m) => m.effects.as_ref(),
        _ => None,
    }
}

/// True when the model has a term of this kind (for the sweep's states).
pub(super) fn has(model: &FittedModel, pred: impl Fn(&Feature) -> bool) -> bool {
    linear_part(model).is_some_and(|m| m.outputs.iter().flat_map(|o| &o.features).any(pred))
}

/// Shortest period on `axis` among the model's periodic terms, mm.
pub(in crate::export) fn shortest_period_mm(model: &FittedModel, axis: usize) -> Option<f64> {
    linear_part(model)?
        .outputs
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
pub(super) fn without_lag(model: &FittedModel) -> FittedModel {
    let mut m = model.clone();
    let part = match &mut m {
        FittedModel::Linear(l) => Some(l),
        FittedModel::Rigid21(r) => r.effects.as_mut(),
        _ => None,
    };
    if let Some(l) = part {
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
