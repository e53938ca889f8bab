//! `diagnose --report DIR`: the evidence as an HTML page with SVG plots (on
//! the shared `crate::report` helpers) — the periodogram of the residual
//! along each axis with its peak, the forward/backward split of the best
//! reversal candidate, the top candidate's component plus residual against
//! its channel, and the spatial residual map before and after the path.

use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::data::{Dataset, AXES, TARGETS};
use crate::report::plot::{heat_map_pair, HeatMap, Series, XyPlot};
use crate::report::Page;

use super::{Candidate, Diagnosis};

/// The channel a candidate follows, as (label, value per data row).
fn channel(data: &Dataset, c: &Candidate) -> Option<(String, Vec<f64>)> {
    let axis = c
        .axis
        .as_deref()
        .and_then(|a| AXES.iter().position(|x| *x == a));
    match c.effect.as_str() {
        "thermal" => {
            let name = c
                .channel
                .as_deref()?
                .strip_prefix("T_")?
                .strip_suffix("_C")?;
            Some((format!("T_{name}_C (°C)"), data.temp(name)?.temp_c.clone()))
        }
        "drift" => Some(("t_s (s)".into(), data.t_s.clone()?)),
        "abbe" => Some(("tool_mm (mm)".into(), data.tool_mm.clone()?)),
        _ => {
            let a = axis?;
            Some((format!("{} (mm)", AXES[a]), data.pos_mm[a].clone()?))
        }
    }
}

/// The two axes with the longest travel, for the residual maps.
fn map_axes(data: &Dataset) -> Option<(usize, usize)> {
    let mut spans: Vec<(usize, f64)> = data
        .axes()
        .into_iter()
        .map(|a| {
            let v = data.pos_mm[a].as_deref().unwrap_or(&[]);
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (a, hi - lo)
        })
        .collect();
    spans.sort_by(|a, b| b.1.total_cmp(&a.1));
    (spans.len() >= 2).then(|| (spans[0].0.min(spans[1].0), spans[0].0.max(spans[1].0)))
}

/// Writes `DIR/index.html` and the SVGs; returns the page's path.
pub fn write(d: &Diagnosis, data: &Dataset, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis diagnose — {}", data.source));
    page.heading("Diagnosis");
    page.paragraph(format!(
        "Model {}; verdict {}; hold-out: {}.",
        d.model,
        match d.verdict {
            super::Verdict::MissingEffect => "missing_effect",
            super::Verdict::AtNoiseFloor => "at_noise_floor",
        },
        d.hold_out
    ));
    let rows: Vec<Vec<String>> = d
        .rms_um
        .iter()
        .map(|(t, r)| {
            vec![
                t.clone(),
                format!("{r:.4}"),
                d.held_out_rms_um
                    .get(t)
                    .map_or("—".into(), |v| format!("{v:.4}")),
                d.noise_floor_um
                    .get(t)
                    .copied()
                    .flatten()
                    .map_or("—".into(), |v| format!("{v:.4}")),
            ]
        })
        .collect();
    page.table(
        &["target", "rms µm", "held-out rms µm", "noise floor µm"],
        rows,
    );
    page.subheading("Candidates (best first)");
    let rows: Vec<Vec<String>> = d
        .candidates
        .iter()
        .filter(|c| c.identifiable)
        .take(10)
        .map(|c| {
            vec![
                c.add.clone(),
                c.delta_bic.map_or("—".into(), |v| format!("{v:.0}")),
                c.gain.map_or("—".into(), |g| format!("{:.0} %", 100.0 * g)),
                if c.significant {
                    "yes".into()
                } else {
                    "no".into()
                },
                c.evidence.clone(),
            ]
        })
        .collect();
    page.table(
        &["add", "ΔBIC", "held-out gain", "significant", "evidence"],
        rows,
    );
    if !d.path.is_empty() {
        page.subheading("Path");
        let rows = d
            .path
            .iter()
            .map(|p| {
                vec![
                    p.target.clone(),
                    p.add.clone(),
                    format!("{:.4}", p.rms_um),
                    format!("{:.4}", p.held_out_rms_um),
                ]
            })
            .collect();
        page.table(&["target", "added", "rms µm", "held-out rms µm"], rows);
    }
    if !d.warnings.is_empty() {
        page.subheading("Warnings");
        for w in &d.warnings {
            page.paragraph(format!("[{}] {}", w.code, w.detail));
        }
    }
    page.heading("Evidence");
    // Periodograms: the ones of targets whose best periodic candidate ranks
    // in the top five, else all (a handful).
    for (t, a, pg) in &d.evidence.periodograms {
        let tn = TARGETS[*t];
        let pts: Vec<(f64, f64)> = pg
            .freq_per_mm
            .iter()
            .zip(&pg.power)
            .map(|(f, p)| (*f, *p))
            .collect();
        let mut plot = XyPlot::new(
            format!("Periodogram of the {tn} residual along {}", AXES[*a]),
            "frequency (cycles/mm)",
            "share of variance",
        )
        .with(Series::line("Lomb–Scargle power", pts));
        if let Some(k) = pg.peak() {
            plot = plot.with_vline(
                pg.freq_per_mm[k],
                format!("{:.3} mm", 1.0 / pg.freq_per_mm[k]),
            );
        }
        page.figure(
            format!("periodogram_{tn}_{}", AXES[*a]),
            format!(
                "Lomb–Scargle periodogram of the {tn} residual along {} (dense lines)",
                AXES[*a]
            ),
            plot.to_svg()?,
        );
    }
    // Forward/backward split of the best reversal candidate.
    if let Some(c) = d
        .candidates
        .iter()
        .find(|c| c.effect == "reversal" && c.identifiable)
    {
        let t = TARGETS.iter().position(|x| *x == c.target);
        let a = c
            .axis
            .as_deref()
            .and_then(|x| AXES.iter().position(|y| *y == x));
        if let (Some(t), Some(a)) = (t, a) {
            if let (Some((_, rows, res)), Some(dir), Some(pos)) = (
                d.evidence.resid_before.iter().find(|e| e.0 == t),
                data.dir[a].as_ref(),
                data.pos_mm[a].as_ref(),
            ) {
                let mut up = Vec::new();
                let mut down = Vec::new();
                for (i, &r) in rows.iter().enumerate() {
                    if dir[r] > 0 {
                        up.push((pos[r], res[i]));
                    } else {
                        down.push((pos[r], res[i]));
                    }
                }
                let plot = XyPlot::new(
                    format!("Forward/backward split of the {} residual", c.target),
                    format!("{} (mm)", AXES[a]),
                    "residual (µm)",
                )
                .with(Series::points(format!("dir_{} = +1", AXES[a]), up))
                .with(Series::points(format!("dir_{} = −1", AXES[a]), down));
                page.figure(
                    format!("reversal_{}_{}", c.target, AXES[a]),
                    format!("{}: the residual by approach direction", c.add),
                    plot.to_svg()?,
                );
            }
        }
    }
    // Component + residual of each target's first path step.
    for (t, add, comp) in &d.evidence.components {
        let Some(c) = d.candidates.iter().find(|c| &c.add == add) else {
            continue;
        };
        let Some((label, ch)) = channel(data, c) else {
            continue;
        };
        let Some((_, rows, after)) = d.evidence.resid_after.iter().find(|e| e.0 == *t) else {
            continue;
        };
        let partial: Vec<(f64, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| (ch[r], comp[i] + after[i]))
            .collect();
        let mut fitted: Vec<(f64, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| (ch[r], comp[i]))
            .collect();
        fitted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let plot = XyPlot::new(
            format!("{}: component + residual", add),
            label,
            format!("{} (µm)", TARGETS[*t]),
        )
        .with(Series::points("component + residual", partial))
        .with(Series::points("fitted component", fitted));
        page.figure(
            format!("component_{}", TARGETS[*t]),
            format!(
                "The fitted {} component of {} with the final residual added back",
                c.effect, TARGETS[*t]
            ),
            plot.to_svg()?,
        );
    }
    // Spatial residual maps before and after the path.
    if let Some((a, b)) = map_axes(data) {
        for (t, rows, before) in &d.evidence.resid_before {
            let Some((_, _, after)) = d.evidence.resid_after.iter().find(|e| e.0 == *t) else {
                continue;
            };
            let (pa, pb) = (data.pos_mm[a].as_ref(), data.pos_mm[b].as_ref());
            let (Some(pa), Some(pb)) = (pa, pb) else {
                continue;
            };
            let pts = |v: &[f64]| -> Vec<(f64, f64, f64)> {
                rows.iter()
                    .enumerate()
                    .map(|(i, &r)| (pa[r], pb[r], v[i]))
                    .collect()
            };
            let tn = TARGETS[*t];
            let mk = |title: &str, v: &[f64]| {
                HeatMap::from_points(
                    title,
                    format!("{} (mm)", AXES[a]),
                    format!("{} (mm)", AXES[b]),
                    "µm",
                    &pts(v),
                    1e-3,
                )
            };
            let hb = mk(&format!("{tn} residual, {}", d.model), before);
            let ha = mk(&format!("{tn} residual after the path"), after);
            page.figure(
                format!("residual_map_{tn}"),
                format!(
                    "{tn}: mean residual per ({}, {}) cell, before and after",
                    AXES[a], AXES[b]
                ),
                heat_map_pair(&hb, &ha)?,
            );
        }
    }
    page.write(dir)
}
