//! Piecewise local polynomials (`--local`): the seed's polynomial fitted
//! per patch of the travel along one stacking axis — the saved form, its
//! evaluation and the checks of its fields.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::check::{check_finite, check_index, check_len, need, Check};
use super::linear::{check_linear_outputs, check_norm, LinearOutput};
use crate::data::{Dataset, AXES};
use crate::features::Norm;

/// Local polynomials (SEEDS.md: "for a point, fit locally on the cuboid
/// between two measured planes, or on the plane, or on the line"). With a
/// stacking axis, `patches[i]` covers planes i and i+1 of `planes_mm` along
/// it, and a point uses the patch whose bracket contains it (clamped to the
/// first / last patch outside). Without one (plane or line data), a single
/// patch covers everything.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalModel {
    /// `cuboid`, `plane` or `line`.
    pub shape: String,
    /// Position normalisation the monomials use.
    pub norm: Norm,
    /// The axis the measured planes are stacked along (cuboid only).
    pub stack_axis: Option<usize>,
    /// Positions of the measured planes along `stack_axis`, ascending, mm.
    pub planes_mm: Vec<f64>,
    /// One local fit per pair of neighbouring planes (or one in total).
    pub patches: Vec<LocalPatch>,
}

/// One local fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalPatch {
    /// Lower bracketing plane, mm (0 when there is no stacking axis).
    pub lo_mm: f64,
    /// Upper bracketing plane, mm.
    pub hi_mm: f64,
    /// The patch's polynomial per target.
    pub outputs: Vec<LinearOutput>,
}

impl LocalModel {
    /// Targets some patch predicts, sorted.
    pub fn targets(&self) -> Vec<usize> {
        let mut t: Vec<usize> = self
            .patches
            .iter()
            .flat_map(|p| p.outputs.iter().map(|o| o.target))
            .collect();
        t.sort_unstable();
        t.dedup();
        t
    }

    /// The model's value (µm) at every row of `data`, per target: each row
    /// takes the polynomial of the patch its stacking-axis position is in.
    pub fn predict(&self, data: &Dataset) -> Result<[Option<Vec<f64>>; 3]> {
        let m = self;
        let mut out: [Option<Vec<f64>>; 3] = [None, None, None];
        let n = data.len();
        let patch_of: Vec<usize> = match m.stack_axis {
            Some(a) => {
                let col = data.pos_mm[a]
                    .as_ref()
                    .with_context(|| format!("the local model needs {}_mm", AXES[a]))?;
                col.iter().map(|&p| m.patch_index(p)).collect()
            }
            None => vec![0; n],
        };
        for t in self.targets() {
            let mut v = vec![0.0; n];
            for (pi, patch) in m.patches.iter().enumerate() {
                let Some(o) = patch.outputs.iter().find(|o| o.target == t) else {
                    continue;
                };
                let rows: Vec<usize> = (0..n).filter(|&r| patch_of[r] == pi).collect();
                if rows.is_empty() {
                    continue;
                }
                // Evaluate only the rows of this patch.
                let sub = crate::data::subset(data, &rows);
                let pv = o.predict(&sub, &m.norm)?;
                for (r, p) in rows.iter().zip(pv) {
                    v[*r] = p;
                }
            }
            out[t] = Some(v);
        }
        Ok(out)
    }

    /// Index of the patch used for a position `p_mm` on the stacking axis.
    pub fn patch_index(&self, p_mm: f64) -> usize {
        if self.patches.len() <= 1 || self.planes_mm.len() < 2 {
            return 0;
        }
        // Planes are ascending; patch i spans planes i..i+1.
        let i = self.planes_mm.partition_point(|&c| c <= p_mm);
        i.saturating_sub(1).min(self.patches.len() - 1)
    }
}

pub(crate) fn check_local(m: &LocalModel) -> Check {
    check_norm(&m.norm, "model.norm")?;
    let n_patches = m.patches.len();
    match m.shape.as_str() {
        "cuboid" => {
            let s = m.stack_axis.ok_or_else(|| {
                "model.stack_axis: null, expected the axis the planes are stacked along (cuboid)"
                    .to_string()
            })?;
            check_index(s, &AXES, || "model.stack_axis".into())?;
            check_finite(&m.planes_mm, "model.planes_mm")?;
            need(
                m.planes_mm.len() >= 2 && m.planes_mm.windows(2).all(|w| w[0] < w[1]),
                || "model.planes_mm".into(),
                || format!("{:?}, expected at least 2 ascending positions", m.planes_mm),
            )?;
            check_len(
                n_patches,
                m.planes_mm.len() - 1,
                "model.patches",
                "one per pair of neighbouring planes",
            )?;
        }
        "plane" | "line" => {
            need(
                m.stack_axis.is_none(),
                || "model.stack_axis".into(),
                || format!("{:?}, expected null for shape `{}`", m.stack_axis, m.shape),
            )?;
            check_len(
                n_patches,
                1,
                "model.patches",
                "one patch for a plane or line",
            )?;
        }
        other => {
            return Err(format!(
                "model.shape: `{other}`, expected cuboid, plane or line"
            ))
        }
    }
    let mut first: Option<Vec<usize>> = None;
    for (i, p) in m.patches.iter().enumerate() {
        let at = format!("model.patches[{i}]");
        need(
            p.lo_mm.is_finite(),
            || format!("{at}.lo_mm"),
            || format!("{}, expected a finite number", p.lo_mm),
        )?;
        need(
            p.hi_mm.is_finite(),
            || format!("{at}.hi_mm"),
            || format!("{}, expected a finite number", p.hi_mm),
        )?;
        check_linear_outputs(&p.outputs, &format!("{at}.outputs"))?;
        let mut t: Vec<usize> = p.outputs.iter().map(|o| o.target).collect();
        t.sort_unstable();
        match &first {
            None => first = Some(t),
            Some(f) => need(
                *f == t,
                || format!("{at}.outputs"),
                || {
                    "targets differ from patch 0's, expected every patch to model the same targets"
                        .into()
                },
            )?,
        }
    }
    Ok(())
}
