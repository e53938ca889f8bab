//! The named effects on top of a rigid21 fit (docs/volumetric.md § Effects
//! on top): each `--add` effect's columns (the linear models' own
//! [`Feature`]s, `features.rs`) join the joint design as columns of the
//! error vector's component the effect is for, so an ex effect reads +1 on
//! an ex reading, n_x on a beam reading along n and nothing on an angle
//! reading (a translation turns no carriage). They are fitted with the error
//! functions and the set-up unknowns, and take part in the
//! identifiability answer: an effect a near-null direction reaches (a
//! period longer than the travel looks like the positioning polynomial) is
//! refused, never fitted into an error function's place.

use anyhow::{bail, Context, Result};
use nalgebra::DMatrix;

use super::{Param, REACH, SIZE_TRANSLATION_UM};
use crate::effect::{Effect, Family, Reading as PhysicalReading, Scale};
use crate::features::{Feature, Norm};
use crate::model::rigid21::{EffectAnswer, Prediction, Rigid21Model, ToolPoint};
use crate::model::{LinearModel, LinearOutput};

/// One column of an effect on the data, scaled to its realistic size: its
/// largest |value| over the rows is [`SIZE_TRANSLATION_UM`] µm, as a
/// translation error's coefficient is (the identifiability answer's unit).
pub(crate) struct EffectColumn {
    /// Index into the fit's effects.
    effect: usize,
    /// ex, ey, ez (0, 1, 2).
    target: usize,
    feature: Feature,
    /// µm of the feature per unit of the scaled coefficient.
    scale: f64,
    /// The feature's value per row times `scale`.
    values: Vec<f64>,
}

impl EffectColumn {
    /// Its effect at row `r`: the component of the error vector.
    pub(crate) fn at(&self, r: usize, _pt: &ToolPoint) -> Prediction {
        let mut p = Prediction::default();
        p.e_um[self.target] = self.values[r];
        p
    }
}

/// A column of the joint design beyond the error functions' (an
/// [`super::ExtraColumn`] boxed with the data it reads).
pub(crate) type Column<'a> = Box<dyn Fn(usize, &ToolPoint) -> Prediction + 'a>;

/// The effect columns as design columns.
pub(crate) fn as_columns(cols: &[EffectColumn]) -> Vec<Column<'_>> {
    cols.iter()
        .map(|c| Box::new(move |r, pt: &ToolPoint| c.at(r, pt)) as Column)
        .collect()
}

/// The columns of `adds` on `data`, in order (effect by effect, feature by
/// feature); `norm` the monomials' normalisation. Err when the data lack a
/// column an effect reads or a column is zero on every row.
pub(crate) fn columns(
    data: &crate::data::Dataset,
    adds: &[Effect],
    norm: &Norm,
) -> Result<Vec<EffectColumn>> {
    let mut out = Vec::new();
    for (i, e) in adds.iter().enumerate() {
        // Families that are geometry — an angle times the tool arm, a
        // squareness, a higher polynomial degree — are what the 21 errors
        // themselves are: a second copy would only trade with them.
        if matches!(
            e.spec.family(),
            Family::Abbe | Family::Squareness | Family::HigherOrder
        ) {
            bail!(
                "effect `{}`: a rigid21 model holds {} in its own error functions (the angles through their arms, the squarenesses, the degree); on top of it go periodic, reversal, thermal and drift",
                e.spec,
                e.spec.family()
            );
        }
        for f in &e.features {
            let raw = f
                .column(data, norm)
                .with_context(|| format!("effect `{}`", e.spec))?;
            let top = raw.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if !(top.is_finite() && top > 0.0) {
                bail!(
                    "effect `{}`: its column {f} is zero on every row (nothing for it to fit)",
                    e.spec
                );
            }
            let scale = SIZE_TRANSLATION_UM / top;
            out.push(EffectColumn {
                effect: i,
                target: e.target(),
                feature: f.clone(),
                scale,
                values: raw.iter().map(|v| v * scale).collect(),
            });
        }
    }
    Ok(out)
}

/// Refuses an effect a near-null direction of the design reaches
/// (`nulls`: rows the model's parameters, then the effect columns), naming
/// the errors it cannot be told from.
pub(crate) fn refuse_unseen(
    model: &Rigid21Model,
    params: &[Param],
    adds: &[Effect],
    cols: &[EffectColumn],
    nulls: &DMatrix<f64>,
) -> Result<()> {
    let np = params.len();
    for (i, c) in cols.iter().enumerate() {
        let j = np + i;
        let reach: f64 = (0..nulls.ncols()).map(|k| nulls[(j, k)].powi(2)).sum();
        if reach <= REACH {
            continue;
        }
        // The errors sharing those directions, by weight.
        let mut share: Vec<(f64, usize)> = Vec::new();
        for k in 0..nulls.ncols() {
            let w = nulls[(j, k)].powi(2);
            for (jp, p) in params.iter().enumerate() {
                let v = w * nulls[(jp, k)].powi(2);
                match share.iter_mut().find(|(_, t)| *t == p.term) {
                    Some(s) => s.0 += v,
                    None => share.push((v, p.term)),
                }
            }
        }
        share.sort_by(|a, b| b.0.total_cmp(&a.0));
        let names: Vec<&str> = share
            .iter()
            .take(3)
            .filter(|(s, _)| *s > 1e-3 * reach)
            .map(|(_, t)| model.errors[*t].name.as_str())
            .collect();
        let with = if names.is_empty() {
            "the set-ups' own zeros and alignments".to_string()
        } else {
            names.join(", ")
        };
        let spec = &adds[c.effect].spec;
        let why = if spec.period_mm().is_some() {
            "a period not well inside the travel is a smooth shape the error functions already hold"
        } else {
            "on these rows its shape is one the error functions and each set-up's own zero and alignment already hold"
        };
        bail!(
            "effect `{spec}`: these data cannot tell its {} column from {with} ({why}); leave it out or measure where it differs",
            c.feature
        );
    }
    Ok(())
}

/// The fitted effects as the model stores them, and their answers: `x`
/// the scaled coefficients and `var` their variances, column by column.
pub(crate) fn saved(
    adds: &[Effect],
    cols: &[EffectColumn],
    x: &[f64],
    var: &[f64],
    norm: Norm,
) -> (LinearModel, Vec<EffectAnswer>) {
    let mut outputs: Vec<LinearOutput> = Vec::new();
    let mut answers = Vec::new();
    for (i, e) in adds.iter().enumerate() {
        let mine: Vec<usize> = (0..cols.len()).filter(|&k| cols[k].effect == i).collect();
        let coef: Vec<f64> = mine.iter().map(|&k| x[k] * cols[k].scale).collect();
        let sd: Vec<f64> = mine
            .iter()
            .map(|&k| var[k].max(0.0).sqrt() * cols[k].scale)
            .collect();
        let k = match outputs.iter().position(|o| o.target == e.target()) {
            Some(k) => k,
            None => {
                outputs.push(LinearOutput {
                    target: e.target(),
                    features: Vec::new(),
                    coef_um: Vec::new(),
                    coef_sd_um: Vec::new(),
                });
                outputs.len() - 1
            }
        };
        outputs[k]
            .features
            .extend(mine.iter().map(|&k| cols[k].feature.clone()));
        outputs[k].coef_um.extend(&coef);
        outputs[k].coef_sd_um.extend(&sd);
        let physical = e.spec.physical().and_then(|p| {
            let value = match p.reading {
                PhysicalReading::Amplitude { .. } => coef.first()?.hypot(*coef.get(1)?),
                PhysicalReading::Linear {
                    scale: Scale::Fixed(f),
                    ..
                } => coef.first()? * f,
                PhysicalReading::Linear {
                    scale: Scale::PerMetreAlong(a),
                    ..
                } => coef.first()? * 1000.0 / norm.half_span_mm[a.index()],
                _ => return None,
            };
            Some((p.name.to_string(), value, p.unit.to_string()))
        });
        answers.push(EffectAnswer {
            effect: e.spec.to_string(),
            features: mine.iter().map(|&k| cols[k].feature.to_string()).collect(),
            coef_um: coef,
            coef_sd_um: sd,
            physical: physical.as_ref().map(|p| p.0.clone()),
            value: physical.as_ref().map(|p| p.1),
            unit: physical.map(|p| p.2),
        });
    }
    (LinearModel { norm, outputs }, answers)
}

/// `mill800-21` (cubic translations, quadratic angles: all a `rigid21`
/// model of degree 4 holds) with a lead error of `amp_um` with period
/// `period_mm` on X's positioning; its laser lines at tool lengths 0 and
/// 150 mm, X's dense enough (5 mm steps) to see the lead. Seeded noise.
#[cfg(test)]
pub(crate) fn lead_lines(amp_um: f64, period_mm: f64, seed: u64) -> crate::data::Dataset {
    use crate::simulate::instruments::{laser_lines_along, measure};
    let m = crate::simulate::Machine::preset("mill800-21")
        .expect("a preset")
        .with_lead(0, amp_um, period_mm, 0.3);
    measure(
        &m,
        &laser_lines_along(m.travel_mm, &[0.0, 150.0], 0, 161),
        seed,
        true,
    )
}

/// Adds the simulator's form of `spec` (`simulate --effect`) to the
/// ex/ey/ez readings of `data`, which is read as one run in row order,
/// 10 s apart, X approached from alternating sides (a bidirectional
/// run); the form's sensor, if any, is recorded as its `T_*_C` column.
#[cfg(test)]
pub(crate) fn add_simulated(data: &mut crate::data::Dataset, spec: &str) {
    use crate::effect::{Pairs, SimRows};
    let (family, kv) = Pairs::of_effect(spec, "").unwrap();
    let family: Family = family.parse().unwrap();
    let sim = (family.info().simulate.unwrap())(&kv).unwrap();
    let n = data.len();
    let t_s: Vec<f64> = (0..n).map(|r| 10.0 * r as f64).collect();
    let dir: Vec<i8> = (0..n).map(|r| if r % 2 == 0 { 1 } else { -1 }).collect();
    if let Some(sensor) = sim.sensor() {
        data.temps.push(crate::data::TempChannel {
            name: sensor.name().to_string(),
            temp_c: t_s.iter().map(|&t| sensor.temp_c(t)).collect(),
        });
    }
    data.t_s = Some(t_s.clone());
    data.dir[0] = Some(dir.clone());
    let pos = [0, 1, 2].map(|a| (0..n).map(|r| data.pos(a, r)).collect::<Vec<_>>());
    let mut truth = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    sim.add_error(
        &SimRows {
            pos_mm: &pos,
            dir: &[dir, vec![0; n], vec![0; n]],
            t_s: &t_s,
            session: &vec![0; n],
            tool_mm: &vec![0.0; n],
            temps: &data.temps,
        },
        &mut truth,
    );
    for (col, t) in data.err_um.iter_mut().zip(&truth) {
        for (v, t) in col.iter_mut().flatten().zip(t) {
            if let Some(v) = v {
                *v += t;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{fit, fit_with};
    use super::*;
    use crate::data::Dataset;

    fn rms(kinds: &[(String, f64, usize)], key: &str) -> f64 {
        kinds.iter().find(|k| k.0 == key).expect("a kind").1
    }

    fn add(s: &str) -> Effect {
        Effect::parse(s).unwrap()
    }

    #[test]
    fn a_lead_on_top_is_fitted_jointly_with_its_amplitude() {
        let data = lead_lines(3.0, 100.0, 11);
        let (_, _, before) = fit(&data, 4).unwrap();
        let lead = add("periodic:target=ex,axis=x,period_mm=100");
        let (model, id, after) = fit_with(&data, 4, std::slice::from_ref(&lead)).unwrap();
        let a = &id.effects[0];
        assert_eq!(a.effect, "periodic:target=ex,axis=x,period_mm=100");
        assert_eq!(a.physical.as_deref(), Some("amplitude"));
        let amp = a.value.unwrap();
        let sd = a.coef_sd_um[0].hypot(a.coef_sd_um[1]);
        assert!(sd < 0.1, "{a:?}");
        assert!((amp - 3.0).abs() < 4.0 * sd + 0.02, "{amp} ± {sd}");
        // The phase too: 3 sin(2πx/P + 0.3) = 3 cos 0.3 sin + 3 sin 0.3 cos.
        let (s, c) = (a.coef_um[0], a.coef_um[1]);
        assert!((s - 3.0 * 0.3f64.cos()).abs() < 0.1, "{s}");
        assert!((c - 3.0 * 0.3f64.sin()).abs() < 0.1, "{c}");
        // The ex residual falls to the laser's noise (0.2 µm).
        let (b, f) = (rms(&before, "ex"), rms(&after, "ex"));
        assert!(b > 1.0 && f < 0.3, "ex RMS {b} → {f}");
        // The model carries the effect: its prediction at the rows is the
        // geometric one plus the lead.
        let fx = model.effects.as_ref().expect("effects saved");
        assert_eq!(fx.outputs.len(), 1);
        assert_eq!(fx.outputs[0].features, lead.features);
        let rows = model.predict_rows(&data).unwrap();
        let r = 7;
        let geo = model.predict(&ToolPoint::of_row(&data, r)).e_um[0];
        let q = data.pos(0, r) * std::f64::consts::TAU / 100.0;
        assert!((rows[0][r] - geo - (s * q.sin() + c * q.cos())).abs() < 1e-9);
        model.check().unwrap();
    }

    #[test]
    fn without_a_lead_the_effect_fits_nothing() {
        let data = lead_lines(0.0, 100.0, 11);
        let (_, id, _) =
            fit_with(&data, 4, &[add("periodic:target=ex,axis=x,period_mm=100")]).unwrap();
        let a = &id.effects[0];
        let sd = a.coef_sd_um[0].hypot(a.coef_sd_um[1]);
        assert!(a.value.unwrap() < 4.0 * sd, "{a:?}");
    }

    #[test]
    fn a_period_longer_than_the_travel_is_refused_not_absorbed() {
        // 1.6 m on 800 mm of X: a smooth shape EXX's polynomial holds.
        let data = lead_lines(3.0, 100.0, 11);
        let e = fit_with(&data, 4, &[add("periodic:target=ex,axis=x,period_mm=1600")])
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot tell") && e.contains("EXX"), "{e}");
    }

    /// Fits `add` on top of `rigid21` to the lines plus the simulated
    /// `sim`: the effect's physical parameter and its σ (from coefficient
    /// `k`, times `per`), and the ex RMS without and with it.
    fn read_back(sim: &str, add_spec: &str, k: usize, per: f64) -> (f64, f64, f64, f64) {
        let mut data: Dataset = lead_lines(0.0, 100.0, 5);
        add_simulated(&mut data, sim);
        let (_, _, before) = fit(&data, 4).unwrap();
        let (_, id, after) = fit_with(&data, 4, &[add(add_spec)]).unwrap();
        let a = &id.effects[0];
        (
            a.value.unwrap(),
            per * a.coef_sd_um[k],
            rms(&before, "ex"),
            rms(&after, "ex"),
        )
    }

    #[test]
    fn a_reversal_on_top_reads_the_backlash() {
        let (b, sd, before, after) = read_back(
            "reversal:axis=x,backlash_um=8",
            "reversal:target=ex,axis=x",
            0,
            2.0,
        );
        assert!((b - 8.0).abs() < 4.0 * sd + 0.02, "{b} ± {sd}");
        assert!(before > 2.0 && after < 0.3, "ex RMS {before} → {after}");
    }

    /// A bed warming by 3 K (τ 1 h) over the ≈ 2.3 h run; X's scale grows
    /// 11.5 µm/m/K about the travel's centre (400 mm: −4.6 µm/K at X = 0).
    const WARMING: &str =
        "thermal:channel=bed,target=ex,times=x,cte_um_per_m_k=11.5,offset_um_per_k=-4.6";

    #[test]
    fn a_thermal_growth_on_top_reads_its_cte() {
        let (cte, sd, before, after) = read_back(
            WARMING,
            "thermal:target=ex,channel=bed,times=x",
            0,
            1000.0 / 400.0,
        );
        assert!((cte - 11.5).abs() < 4.0 * sd + 0.05, "{cte} ± {sd}");
        assert!(after < before, "ex RMS {before} → {after}");
    }

    #[test]
    fn a_growth_the_lines_zeros_take_is_refused() {
        // The plain ΔT on ex: within each laser line the temperature is a
        // smooth function of X (the line moves X as time passes), so the
        // line's zero and EXX hold it: refused, not fitted.
        let mut data: Dataset = lead_lines(0.0, 100.0, 5);
        add_simulated(&mut data, WARMING);
        let e = fit_with(
            &data,
            4,
            &[add("thermal:target=ex,channel=bed,times=x,offset=1")],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("cannot tell") && e.contains("ΔT_bed"), "{e}");
    }

    #[test]
    fn a_geometric_family_is_refused_on_top_of_the_errors() {
        let data = lead_lines(0.0, 100.0, 5);
        let e = fit_with(&data, 4, &[add("abbe:target=ex,times=y")])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("abbe") && e.contains("periodic, reversal"),
            "{e}"
        );
    }

    #[test]
    fn an_effect_on_a_missing_column_is_refused_with_its_name() {
        let data = lead_lines(0.0, 100.0, 5);
        let e = fit_with(&data, 4, &[add("reversal:target=ex,axis=x")]).unwrap_err();
        let text = format!("{e:#}");
        assert!(
            text.contains("reversal:target=ex,axis=x") && text.contains("dir_x"),
            "{text}"
        );
    }
}
