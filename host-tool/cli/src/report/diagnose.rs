//! `diagnose --report DIR`: the evidence as an HTML page with SVG plots (on
//! the shared `crate::report` helpers) — the periodogram of the residual
//! along each axis with its peak (and the one that found each periodic
//! effect added later on the path), the forward/backward split of each
//! reversal on the path (else of the best reversal candidate), each path
//! effect's fitted component plus the final residual against its channel,
//! and the spatial residual map before and after the path.

use std::path::{Path, PathBuf};

use anyhow::Result;

use trueaxis_engine::data::{Dataset, AXES, TARGETS};
use trueaxis_engine::diagnose::{Candidate, Diagnosis};
use trueaxis_engine::effect::Family;

use crate::report::plot::{heat_map_pair, HeatMap, Series, XyPlot};
use crate::report::Page;

/// The channel a candidate follows, as (label, value per data row).
fn channel(data: &Dataset, c: &Candidate) -> Option<(String, Vec<f64>)> {
    let axis = c
        .axis
        .as_deref()
        .and_then(|a| AXES.iter().position(|x| *x == a));
    match c.effect {
        // Several sensors: no one temperature to plot against — the
        // component over time shows the warm-up and cool-down it follows.
        Family::Thermal if c.channel.as_deref().is_some_and(|ch| ch.contains('+')) => {
            Some(("t_s (s)".into(), data.t_s.clone()?))
        }
        Family::Thermal => {
            let name = c
                .channel
                .as_deref()?
                .strip_prefix("T_")?
                .strip_suffix("_C")?;
            Some((format!("T_{name}_C (°C)"), data.temp(name)?.temp_c.clone()))
        }
        Family::Drift => Some(("t_s (s)".into(), data.t_s.clone()?)),
        Family::Abbe => Some(("tool_mm (mm)".into(), data.tool_mm.clone()?)),
        _ => {
            let a = axis?;
            Some((format!("{} (mm)", AXES[a]), data.pos_mm[a].clone()?))
        }
    }
}

/// A forward/backward split to draw: the residual of `target` on `rows`,
/// split by the approach direction along `axis`.
struct ReversalPlot {
    target: usize,
    axis: usize,
    rows: Vec<usize>,
    resid: Vec<f64>,
    caption: String,
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
    write_with_history(d, data, dir, None)
}

/// [`write`], plus the model's history (the error falling fit by fit, as
/// `trueaxis history` draws it) when the diagnosed model has one.
pub fn write_with_history(
    d: &Diagnosis,
    data: &Dataset,
    dir: &Path,
    history: Option<&trueaxis_engine::history::History>,
) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis diagnose — {}", data.source));
    page.heading("Diagnosis");
    page.paragraph(format!(
        "Model {}; verdict {}; hold-out: {}.",
        d.model,
        match d.verdict {
            trueaxis_engine::diagnose::Verdict::MissingEffect => "missing_effect",
            trueaxis_engine::diagnose::Verdict::AtNoiseFloor => "at_noise_floor",
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
                match c.step {
                    Some(k) => format!("yes (path step {k})"),
                    None if c.significant => "yes".into(),
                    None => "no".into(),
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
    if let Some(h) = history.filter(|h| !h.steps.is_empty()) {
        page.subheading("History of the model");
        crate::report::history::add_to_page(&mut page, h)?;
    }
    page.heading("Evidence");
    // Periodograms: every target and axis with dense lines at the starting
    // model (at most 3 × 3), plus the one that found each periodic effect
    // added at a later path step.
    for e in &d.evidence.periodograms {
        let (tn, ax) = (TARGETS[e.target], AXES[e.axis]);
        let pts: Vec<(f64, f64)> =
            e.pg.freq_per_mm
                .iter()
                .zip(&e.pg.power)
                .map(|(f, p)| (*f, *p))
                .collect();
        let at = if e.step > 1 {
            format!(" at path step {}", e.step)
        } else {
            String::new()
        };
        let mut plot = XyPlot::new(
            format!("Periodogram of the {tn} residual along {ax}{at}"),
            "frequency (cycles/mm)",
            "share of variance",
        )
        .with(Series::line("Lomb–Scargle power", pts));
        if let Some(k) = e.pg.peak() {
            plot = plot.with_vline(
                e.pg.freq_per_mm[k],
                format!("{:.3} mm", 1.0 / e.pg.freq_per_mm[k]),
            );
        }
        page.figure(
            if e.step > 1 {
                format!("periodogram_{tn}_{ax}_step{}", e.step)
            } else {
                format!("periodogram_{tn}_{ax}")
            },
            format!("Lomb–Scargle periodogram of the {tn} residual along {ax}{at} (dense lines)"),
            plot.to_svg()?,
        );
    }
    // Forward/backward split of each reversal on the path: the partial
    // residual (final residual plus the fitted reversal component), so that
    // the other effects found do not blur the step. Without one on the path,
    // the best reversal candidate on the starting model's residual.
    let index = |names: &[&str], x: &str| names.iter().position(|y| *y == x);
    let mut reversals: Vec<ReversalPlot> = Vec::new();
    for comp in d.evidence.components.iter() {
        let Some(c) = d
            .candidates
            .iter()
            .find(|c| c.on_path() && c.add == comp.add)
        else {
            continue;
        };
        let Some(a) = c.axis.as_deref().and_then(|x| index(&AXES, x)) else {
            continue;
        };
        if c.effect != Family::Reversal {
            continue;
        }
        let Some((_, rows, after)) = d.evidence.resid_after.iter().find(|e| e.0 == comp.target)
        else {
            continue;
        };
        reversals.push(ReversalPlot {
            target: comp.target,
            axis: a,
            rows: rows.clone(),
            resid: after.iter().zip(&comp.values).map(|(r, v)| r + v).collect(),
            caption: format!(
                "{}: final residual plus the fitted reversal, by approach direction (path step {})",
                c.add, comp.step
            ),
        });
    }
    if reversals.is_empty() {
        if let Some(c) = d
            .candidates
            .iter()
            .find(|c| c.effect == Family::Reversal && c.identifiable)
        {
            let t = index(&TARGETS, &c.target);
            let a = c.axis.as_deref().and_then(|x| index(&AXES, x));
            if let (Some(t), Some(a)) = (t, a) {
                if let Some((_, rows, res)) = d.evidence.resid_before.iter().find(|e| e.0 == t) {
                    reversals.push(ReversalPlot {
                        target: t,
                        axis: a,
                        rows: rows.clone(),
                        resid: res.clone(),
                        caption: format!(
                            "{} (not added): the starting model's residual by approach direction",
                            c.add
                        ),
                    });
                }
            }
        }
    }
    for ReversalPlot {
        target: t,
        axis: a,
        rows,
        resid: res,
        caption,
    } in &reversals
    {
        let (Some(dir), Some(pos)) = (data.dir[*a].as_ref(), data.pos_mm[*a].as_ref()) else {
            continue;
        };
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
            format!("Forward/backward split of the {} residual", TARGETS[*t]),
            format!("{} (mm)", AXES[*a]),
            "residual (µm)",
        )
        .with(Series::points(format!("dir_{} = +1", AXES[*a]), up))
        .with(Series::points(format!("dir_{} = −1", AXES[*a]), down));
        page.figure(
            format!("reversal_{}_{}", TARGETS[*t], AXES[*a]),
            caption.clone(),
            plot.to_svg()?,
        );
    }
    // Component + residual of every effect on the path.
    for comp in &d.evidence.components {
        let t = comp.target;
        let Some(c) = d
            .candidates
            .iter()
            .find(|c| c.on_path() && c.add == comp.add)
        else {
            continue;
        };
        let Some((label, ch)) = channel(data, c) else {
            continue;
        };
        let Some((_, rows, after)) = d.evidence.resid_after.iter().find(|e| e.0 == t) else {
            continue;
        };
        let partial: Vec<(f64, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| (ch[r], comp.values[i] + after[i]))
            .collect();
        let mut fitted: Vec<(f64, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| (ch[r], comp.values[i]))
            .collect();
        fitted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let plot = XyPlot::new(
            format!("{}: component + residual", comp.add),
            label,
            format!("{} (µm)", TARGETS[t]),
        )
        .with(Series::points("component + residual", partial))
        .with(Series::points("fitted component", fitted));
        page.figure(
            format!("component_{}_{}", TARGETS[t], comp.step),
            format!(
                "Path step {} of {}: the fitted {} component with the final residual added back",
                comp.step, TARGETS[t], c.effect
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
