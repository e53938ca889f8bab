//! The `compare --report DIR` page: the statistics of
//! [`trueaxis_engine::compare`] drawn as an HTML page with SVG plots — the
//! summary table, residual maps per plane (before and after), the residual
//! along each dense line, against every position axis and channel, and the
//! worst regions.

use std::path::{Path, PathBuf};

use anyhow::Result;

use trueaxis_engine::compare::{
    channels, dense_lines, planes, plot_num, residuals, Comparison, Line, Plane, REGION_BINS,
    REGION_RATIO, SNAP_MM,
};
use trueaxis_engine::data::{Dataset, AXES, TARGETS};

use crate::report::plot::{
    axis_title, before_after, format_value, ticks_for, Drawing as _, HeatMap, MapPair, Series,
    Style, XyPlot,
};
use crate::report::{Figure, Page, Tone, Verdict};

/// Where the data and the model came from, for the command the verdict
/// card proposes (`trueaxis diagnose DATA --model MODEL.json`).
#[derive(Clone, Copy, Debug)]
pub struct Sources<'a> {
    /// The data file as the user named it.
    pub data: &'a Path,
    /// The model file.
    pub model: &'a Path,
}

/// |r| from which the verdict card names a channel the residual follows.
pub const TREND_CORR: f64 = 0.2;
/// A worst region this many times the target's RMS turns the card orange:
/// at the noise, a 4 × 4 × 4 cell of ~80 points often reaches 1.3× by
/// chance (the demo's final model: 1.35× with every target at its noise).
pub const REGION_ACTION: f64 = 1.5;
/// Size of one map in the grid of planes (small multiples).
const SMALL_MAP: (u32, u32) = (460, 380);

/// Minimum distinct positions for a line to count as dense.
pub const DENSE_LINE_POINTS: usize = 25;
/// Plots of dense lines at most.
const MAX_LINE_PLOTS: usize = 6;
/// Residual maps per plane orientation at most: a 50 mm grid of the seed's
/// mill has 17 planes normal to x; five evenly spaced ones (both ends and
/// the middle among them) show how the residual changes through the
/// volume without burying the page in near-identical maps.
pub const MAX_PLANES_PER_NORMAL: usize = 5;

/// Indices of at most `max` of `n` items, evenly spaced, the first and the
/// last included (all of them when `n <= max`).
pub fn pick_evenly(n: usize, max: usize) -> Vec<usize> {
    if n <= max {
        return (0..n).collect();
    }
    if max <= 1 {
        return vec![0; max.min(n)];
    }
    let mut v: Vec<usize> = (0..max)
        .map(|i| ((i * (n - 1)) as f64 / (max - 1) as f64).round() as usize)
        .collect();
    v.dedup();
    v
}

/// The dense lines with the passes along the same line (same axis, same
/// fixed coordinates) joined, rows in position order, each with its number
/// of passes; in the order each line first appears.
fn merge_passes(lines: Vec<Line>, data: &Dataset) -> Vec<(Line, usize)> {
    let mut out: Vec<(Line, usize)> = Vec::new();
    for l in lines {
        match out
            .iter_mut()
            .find(|(m, _)| m.axis == l.axis && m.label == l.label)
        {
            Some((m, n)) => {
                m.rows.extend(l.rows);
                *n += 1;
            }
            None => out.push((l, 1)),
        }
    }
    for (l, _) in &mut out {
        let a = l.axis;
        l.rows
            .sort_by(|&r, &s| data.pos(a, r).total_cmp(&data.pos(a, s)));
    }
    out
}

/// Heat map of `vals` (µm per row, `None` where there is none) on the rows
/// of `plane`, against its two in-plane axes.
fn plane_map(
    data: &Dataset,
    plane: &Plane,
    title: String,
    vals: impl Fn(usize) -> Option<f64>,
) -> HeatMap {
    let others: Vec<usize> = (0..3).filter(|&a| a != plane.normal).collect();
    let pts: Vec<(f64, f64, f64)> = plane
        .rows
        .iter()
        .filter_map(|&r| vals(r).map(|v| (data.pos(others[0], r), data.pos(others[1], r), v)))
        .collect();
    HeatMap::from_points(
        title,
        format!("{} (mm)", AXES[others[0]]),
        format!("{} (mm)", AXES[others[1]]),
        "µm",
        &pts,
        SNAP_MM,
    )
}

/// Writes the HTML report of a comparison to `dir` (index.html + SVGs) and
/// returns the path of index.html.
pub fn write_report(
    dir: &Path,
    data: &Dataset,
    predicted: &[Option<Vec<f64>>; 3],
    c: &Comparison,
) -> Result<PathBuf> {
    write_report_from(dir, data, predicted, c, None)
}

/// [`write_report`], with the files named so the verdict card can give the
/// next command verbatim.
pub fn write_report_from(
    dir: &Path,
    data: &Dataset,
    predicted: &[Option<Vec<f64>>; 3],
    c: &Comparison,
    sources: Option<Sources>,
) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis compare — {} vs {}", c.data, c.model));
    page.verdict(verdict_for(c, sources, dir, data.is_probed_surface()));
    build_report(&mut page, data, predicted, c)?;
    page.write(dir)
}

/// [`write_report_from`] for a `rigid21` model: the card speaks in errors
/// (volumetric error before and after, what cannot be known and what would
/// tell) and the model's error functions come before the compare sections
/// (docs/volumetric.md § The page).
pub fn write_report_rigid21(
    dir: &Path,
    data: &Dataset,
    predicted: &[Option<Vec<f64>>; 3],
    c: &Comparison,
    sources: Option<Sources>,
    model: &trueaxis_engine::model::rigid21::Rigid21Model,
    id: Option<&trueaxis_engine::model::rigid21::Identifiability>,
) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis compare — {} vs {}", c.data, c.model));
    let next = verdict_for(c, sources, dir, false).next;
    page.verdict(crate::report::volumetric::verdict(c, id, next));
    crate::report::volumetric::build_section(&mut page, model, id)?;
    build_report(&mut page, data, predicted, c)?;
    page.write(dir)
}

/// The compare page's verdict: what is left after compensation, where, and
/// what it follows — and that `diagnose` names what is missing.
pub fn verdict(c: &Comparison, sources: Option<Sources>, dir: &Path) -> Verdict {
    verdict_for(c, sources, dir, false)
}

/// [`verdict`] for data that may be a probed surface (`bed`: the next
/// command exports a bed mesh when the model is no linear seed).
pub fn verdict_for(c: &Comparison, sources: Option<Sources>, dir: &Path, bed: bool) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    let worst = c
        .targets
        .iter()
        .max_by(|a, b| a.1.after.rms_um.total_cmp(&b.1.after.rms_um));
    let Some((wt, wr)) = worst else {
        return Verdict {
            headline: "No target of the data is predicted by the model: nothing to compare.".into(),
            details: Vec::new(),
            warnings: c.warnings.iter().map(|w| w.detail.clone()).collect(),
            next: None,
            tone: Tone::Unknown,
        };
    };
    let others: Vec<String> = c
        .targets
        .iter()
        .filter(|(t, _)| *t != wt)
        .map(|(t, r)| format!("{t} {}", um(r.after.rms_um)))
        .collect();
    let headline = format!(
        "After compensation {wt} is left at {} RMS (max {}), {:.0}× less than uncompensated{}.",
        um(wr.after.rms_um),
        um(wr.after.max_abs_um),
        wr.improvement,
        if others.is_empty() {
            String::new()
        } else {
            format!("; {}", others.join(", "))
        }
    );
    let mut details = Vec::new();
    let mut action = false;
    if let Some(r) = c.worst_regions.iter().find(|r| &r.target == wt) {
        let ratio = r.ratio.unwrap_or(f64::NAN);
        action |= ratio >= REGION_ACTION;
        details.push(format!(
            "Where: {wt} is worst in {} mm — {} RMS, {:.1}× its average, {:.0} % of its squared error{}.",
            trueaxis_engine::regions::bbox_text(&r.bbox_mm),
            um(r.rms_um),
            ratio,
            100.0 * r.share.unwrap_or(f64::NAN),
            if ratio < REGION_RATIO {
                " (no region stands out: the residual is spread evenly)"
            } else {
                ""
            }
        ));
    }
    // Ranked by the share of the residual each channel explains once
    // position is accounted for (compare::ranked_channels): a channel that
    // only follows the travel explains nothing position does not.
    let trends =
        trueaxis_engine::compare::ranked_channels(c, wt, trueaxis_engine::compare::RANK_MIN_SHARE);
    if trends.is_empty() {
        details.push(format!(
            "What it follows: no temperature, time, direction or other channel explains {:.0} % of the residual beyond position.",
            100.0 * trueaxis_engine::compare::RANK_MIN_SHARE
        ));
    }
    for p in trends.iter().take(3) {
        action = true;
        let slope = p.partial_slope.unwrap_or(f64::NAN);
        // The slope in the channel's own terms (a direction's is already
        // the step from −1 to +1).
        let size = if p.channel.starts_with("dir_") {
            format!("a step of {} from −1 to +1", um(slope))
        } else if p.channel == "t_s" {
            format!("{} µm per hour", format_value(3600.0 * slope))
        } else if p.channel.starts_with("T_") {
            format!("{} µm per K", format_value(slope))
        } else {
            format!("{} {}", format_value(slope), p.slope_unit)
        };
        details.push(format!(
            "What it follows: {wt}'s residual follows {} ({size}; {:.0} % of the residual beyond position, r = {:+.2}) — a trend the model does not hold.",
            axis_title(&p.channel),
            100.0 * p.explains_share.unwrap_or(0.0),
            p.partial_corr.unwrap_or(0.0),
        ));
    }
    if let Some(h) = wr.held_out_rms_um {
        let ratio = h / wr.after.rms_um.max(1e-12);
        details.push(if ratio > 1.2 {
            format!(
                "Held out: {} on blocks the fit did not see, {ratio:.1}× the in-sample — the model follows the data more closely than it predicts it (too many terms for the data)",
                um(h)
            )
        } else {
            format!(
                "Held out: {} on blocks the fit did not see ({ratio:.2}× the in-sample): the model predicts as well as it fits.",
                um(h)
            )
        });
    }
    details.push(
        "Whether this is the noise of the measurement or a missing effect is diagnose's answer: the command below."
            .into(),
    );
    let next = Some(match sources {
        Some(s) => next_command(&c.model, s.data, s.model, Some(dir), bed),
        None => format!(
            "trueaxis diagnose {} --model MODEL.json --report {}",
            c.data,
            dir.join("diagnose").display()
        ),
    });
    Verdict {
        headline,
        details,
        warnings: c
            .warnings
            .iter()
            .map(|w| format!("{} ({})", w.detail, w.code))
            .collect(),
        next,
        tone: if action { Tone::Action } else { Tone::Unknown },
    }
}

/// What to run after a comparison, each path one shell word as typed (the
/// command runs where compare ran): `trueaxis diagnose DATA --model MODEL
/// [--report DIR/diagnose]` for a linear seed (`model_spec`: what diagnose
/// works on); for a grid, local or network model, which diagnose refuses,
/// the export — a bed mesh for a probed surface, else the firmware table.
pub fn next_command(
    model_spec: &str,
    data: &Path,
    model: &Path,
    report: Option<&Path>,
    bed: bool,
) -> String {
    use crate::report::diagnose::shell_word;
    let word = |p: &Path| shell_word(&p.display().to_string());
    let seed = model_spec.split([' ', '+']).next().unwrap_or("");
    // A rigid21 model: diagnose names the error function it misses (no
    // page of its own yet).
    if seed.starts_with("rigid21") && !bed {
        return format!("trueaxis diagnose {} --model {}", word(data), word(model));
    }
    if !matches!(seed, "cubic19" | "kinematic") {
        return if bed {
            format!(
                "trueaxis export {} --format klipper-mesh -o mesh.cfg",
                word(model)
            )
        } else {
            format!("trueaxis export {} -o table.bin", word(model))
        };
    }
    let mut cmd = format!("trueaxis diagnose {} --model {}", word(data), word(model));
    if let Some(dir) = report {
        cmd.push_str(&format!(" --report {}", word(&dir.join("diagnose"))));
    }
    cmd
}

/// Adds the comparison's sections to `page` (so `demo` and `diagnose` can
/// put them on a page of their own).
pub fn build_report(
    page: &mut Page,
    data: &Dataset,
    predicted: &[Option<Vec<f64>>; 3],
    c: &Comparison,
) -> Result<()> {
    if !data.metadata.is_empty() {
        page.paragraph(
            data.metadata
                .iter()
                .map(|(k, v)| format!("{k}: {v}"))
                .collect::<Vec<_>>()
                .join(" · "),
        );
    }
    for w in &c.warnings {
        page.paragraph(format!("Warning ({}): {}", w.code, w.detail));
    }
    page.heading("Summary");
    page.colour_key();
    let f = |v: f64| format!("{v:.3}");
    let rows = c
        .targets
        .iter()
        .map(|(name, r)| {
            vec![
                name.clone(),
                r.after.points.to_string(),
                f(r.before.rms_um),
                f(r.after.rms_um),
                r.held_out_rms_um.map_or("—".into(), f),
                f(r.after.max_abs_um),
                f(r.after.pv_um),
                f(r.after.p50_abs_um),
                f(r.after.p95_abs_um),
                f(r.after.p99_abs_um),
                format!("{:.1}×", r.improvement),
            ]
        })
        .collect();
    page.table(
        &[
            "target",
            "points",
            "RMS before (µm)",
            "RMS after (µm)",
            "held-out RMS (µm)",
            "max |e| (µm)",
            "PV (µm)",
            "p50 |e| (µm)",
            "p95 |e| (µm)",
            "p99 |e| (µm)",
            "improvement",
        ],
        rows,
    );
    let names: Vec<String> = c.targets.keys().cloned().collect();
    let before: Vec<f64> = c.targets.values().map(|r| r.before.rms_um).collect();
    let after: Vec<f64> = c.targets.values().map(|r| r.after.rms_um).collect();
    let rms_fig = Figure::plot(
        "before_after_rms",
        "RMS error per target before compensation (the raw measured error) and after (the residual the model leaves).",
        &before_after("Before vs after: RMS", "RMS (µm)", &names, &before, &after),
    )?;
    let before: Vec<f64> = c.targets.values().map(|r| r.before.max_abs_um).collect();
    let after: Vec<f64> = c.targets.values().map(|r| r.after.max_abs_um).collect();
    let max_fig = Figure::plot(
        "before_after_max",
        "Largest |error| per target before and after compensation.",
        &before_after(
            "Before vs after: max |e|",
            "max |e| (µm)",
            &names,
            &before,
            &after,
        ),
    )?;
    page.grid_wide(vec![rms_fig, max_fig]);

    page.heading("Worst regions");
    page.paragraph(format!(
        "The travel is cut into {REGION_BINS} slices per axis; cells whose residual RMS is at least {REGION_RATIO}× the target's overall RMS are merged into regions. A ratio near 1 means the residual is spread evenly."
    ));
    let rows = c
        .worst_regions
        .iter()
        .map(|r| {
            vec![
                r.target.clone(),
                r.bbox_mm
                    .iter()
                    .map(|(a, b)| format!("{a} {}…{}", plot_num(b[0]), plot_num(b[1])))
                    .collect::<Vec<_>>()
                    .join(", "),
                f(r.rms_um),
                format!("{:.2}", r.ratio.unwrap_or(f64::NAN)),
                r.points.to_string(),
                format!("{:.0} %", 100.0 * r.share.unwrap_or(f64::NAN)),
            ]
        })
        .collect();
    page.table(
        &[
            "target",
            "box (mm)",
            "RMS (µm)",
            "ratio",
            "points",
            "share of SS",
        ],
        rows,
    );

    // Heat maps: residual on every measured plane, in every orientation
    // (at most MAX_PLANES_PER_NORMAL per orientation, evenly spaced, and the
    // page says so when planes are left out); before vs after on the middle
    // plane of the first orientation.
    let planes = planes(data);
    // `planes` lists the planes of each orientation together.
    let groups: Vec<&[Plane]> = planes.chunk_by(|a, b| a.normal == b.normal).collect();
    if let Some(first) = groups.first() {
        // A probed bed is drawn as a bed mesh is (Klipper, Mainsail): its
        // height, up warm — ez is the tool's error, −height (issue 28: a
        // high bed showed blue).
        let bed = data.is_probed_surface();
        let sign = if bed { -1.0 } else { 1.0 };
        let what = |t: usize| {
            if bed {
                "bed height".to_string()
            } else {
                format!("{} residual", TARGETS[t])
            }
        };
        // Where a map lies: a plane of the volume, or the bed (a file with
        // no z has no plane z = 0 to speak of).
        let on = |plane: &Plane| {
            if data.pos_mm[plane.normal].is_none() {
                format!(
                    "over {}–{}",
                    AXES[(plane.normal + 1) % 3],
                    AXES[(plane.normal + 2) % 3]
                )
            } else {
                format!(
                    "on the plane {} = {} mm",
                    AXES[plane.normal],
                    plot_num(plane.at_mm)
                )
            }
        };
        page.heading("Residual maps on measured planes");
        page.paragraph(if bed {
            "The bed height the model leaves (−ez: the residual of the tool's error, turned into the bed's height) per probe point. Red: the bed stands higher than the model says, as Klipper and Mainsail colour a mesh."
        } else {
            "Mean residual per grid position (both directions and repeats averaged); grey cells were not measured. Red: the machine is further along the error's axis than the model says."
        });
        if data.axes().len() == 3 {
            for same in &groups {
                let normal = AXES[same[0].normal];
                let shown = pick_evenly(same.len(), MAX_PLANES_PER_NORMAL);
                page.paragraph(if shown.len() < same.len() {
                    format!(
                        "Planes {normal} = const: {} measured, {} shown (at most {MAX_PLANES_PER_NORMAL} per orientation, evenly spaced, first and last included): {} mm.",
                        same.len(),
                        shown.len(),
                        shown
                            .iter()
                            .map(|&i| plot_num(same[i].at_mm))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                } else {
                    format!(
                        "Planes {normal} = const: {} measured, all shown.",
                        same.len()
                    )
                });
            }
        }
        for t in data.targets() {
            let res = residuals(data, predicted, t);
            // Small multiples: every plane shown of this target, side by
            // side, on one colour scale — planes are compared by colour,
            // so a scale per map would make a 3 µm plane look as hot as a
            // 6 µm one.
            let mut maps = Vec::new();
            for same in &groups {
                for i in pick_evenly(same.len(), MAX_PLANES_PER_NORMAL) {
                    let plane = &same[i];
                    let title = if data.axes().len() == 3 {
                        format!(
                            "{} at {} = {} mm",
                            what(t),
                            AXES[plane.normal],
                            plot_num(plane.at_mm)
                        )
                    } else {
                        what(t)
                    };
                    let mut m = plane_map(data, plane, title, |r| res[r].map(|v| sign * v));
                    m.size = SMALL_MAP;
                    maps.push((
                        format!("map_{}_{}{}", TARGETS[t], AXES[plane.normal], i),
                        plane,
                        m,
                    ));
                }
            }
            let limit = maps.iter().fold(0.0f64, |l, m| l.max(m.2.max_abs()));
            page.subheading(format!(
                "{} on the measured planes — one colour scale, ±{} µm",
                what(t),
                format_value(limit)
            ));
            let mut figs = Vec::with_capacity(maps.len());
            for (name, plane, mut m) in maps {
                m.limit = Some(limit);
                figs.push(Figure {
                    name,
                    caption: if bed {
                        format!("The bed height the model leaves, {}.", on(plane))
                    } else {
                        format!("Residual of {} {}.", TARGETS[t], on(plane))
                    },
                    svg: m.svg()?,
                    narrow: m.phone_svg()?,
                });
            }
            page.grid(figs);
            // Before vs after on the middle plane, one colour scale.
            let plane = &first[first.len() / 2];
            let raw = data.err_um[t].as_ref();
            let (b_title, a_title) = if bed {
                (
                    "bed height before (as probed)".to_string(),
                    "bed height after (residual)".to_string(),
                )
            } else {
                (
                    format!("{} before (raw error)", TARGETS[t]),
                    format!("{} after (residual)", TARGETS[t]),
                )
            };
            let before = plane_map(data, plane, b_title, |r| {
                raw.and_then(|c| c[r]).map(|v| sign * v)
            });
            let after = plane_map(data, plane, a_title, |r| res[r].map(|v| sign * v));
            page.plot(
                format!("map_before_after_{}", TARGETS[t]),
                format!(
                    "{} before and after compensation {}, on one colour scale.",
                    if bed { "The bed height" } else { TARGETS[t] },
                    on(plane)
                ),
                &MapPair {
                    before: &before,
                    after: &after,
                },
            )?;
        }
    }

    // Dense lines: residual along the line, measured vs model. The passes
    // of one line (forward and backward, repeated runs) are one plot: six
    // runs of the same line made six near-identical plots (and 2 MB).
    let lines = merge_passes(dense_lines(data, DENSE_LINE_POINTS), data);
    if !lines.is_empty() {
        page.heading("Dense lines");
        page.paragraph(format!(
            "Lines with at least {DENSE_LINE_POINTS} positions along one axis: the measured error with the model's prediction, and the residual. Short-period errors (a lead screw's pitch) show here and not on a coarse grid."
        ));
    }
    for (k, (line, passes)) in lines.iter().take(MAX_LINE_PLOTS).enumerate() {
        let ax = AXES[line.axis];
        let passes = if *passes > 1 {
            format!(", {passes} passes overlaid")
        } else {
            String::new()
        };
        let mut meas = XyPlot::new(
            format!("measured vs model along {ax} ({})", line.label),
            format!("{ax} (mm)"),
            "error (µm)",
        );
        let mut resid = XyPlot::new(
            format!("residual along {ax} ({})", line.label),
            format!("{ax} (mm)"),
            "residual (µm)",
        )
        .with_hline(0.0, "");
        for t in data.targets() {
            let res = residuals(data, predicted, t);
            let m: Vec<(f64, f64)> = line
                .rows
                .iter()
                .filter_map(|&r| {
                    data.err_um[t]
                        .as_ref()
                        .and_then(|c| c[r])
                        .map(|v| (data.pos(line.axis, r), v))
                })
                .collect();
            let p: Vec<(f64, f64)> = line
                .rows
                .iter()
                .filter_map(|&r| {
                    predicted[t]
                        .as_ref()
                        .and_then(|c| c.get(r).copied())
                        .map(|v| (data.pos(line.axis, r), v))
                })
                .collect();
            let rr: Vec<(f64, f64)> = line
                .rows
                .iter()
                .filter_map(|&r| res[r].map(|v| (data.pos(line.axis, r), v)))
                .collect();
            if m.is_empty() {
                continue;
            }
            meas = meas
                .with(Series::points(format!("{} measured", TARGETS[t]), m))
                .with(Series::line(format!("{} model", TARGETS[t]), p));
            // A polyline of every point: compact, and the zoom below needs
            // the full resolution.
            resid = resid.with(Series::line(TARGETS[t], rr));
        }
        let mut figs = vec![Figure {
            name: format!("line{k}_measured"),
            caption: format!(
                "Measured error and model along {ax} at {}{passes}.",
                line.label
            ),
            svg: meas.svg()?,
            narrow: meas.phone_svg()?,
        }];
        // Zoom on the first 60 mm of a long line: short periods (a lead
        // screw's pitch) are unreadable over the whole travel.
        let lo = data.pos(line.axis, line.rows[0]);
        let hi = data.pos(line.axis, line.rows[line.rows.len() - 1]);
        let zoom = (hi - lo > 200.0).then(|| {
            let mut z = resid.clone();
            z.title = format!("residual along {ax}, first 60 mm ({})", line.label);
            for s in &mut z.series {
                s.points.retain(|p| p.0 <= lo + 60.0);
            }
            z
        });
        figs.push(Figure {
            name: format!("line{k}_residual"),
            caption: format!("Residual along {ax} at {}{passes}.", line.label),
            svg: resid.svg()?,
            narrow: resid.phone_svg()?,
        });
        if let Some(z) = zoom {
            figs.push(Figure {
                name: format!("line{k}_residual_zoom"),
                caption: format!(
                    "Residual along {ax} at {}, the first 60 mm{passes}.",
                    line.label
                ),
                svg: z.svg()?,
                narrow: z.phone_svg()?,
            });
        }
        page.grid_wide(figs);
    }

    // Measured vs model over all points.
    page.heading("Measured vs model");
    let mut mv = XyPlot::new(
        "measured vs model, all points",
        "model (µm)",
        "measured (µm)",
    );
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for t in data.targets() {
        let Some(pred) = &predicted[t] else { continue };
        let pts: Vec<(f64, f64)> = data
            .measured(t)
            .filter_map(|(r, v)| pred.get(r).map(|p| (*p, v)))
            .collect();
        for p in &pts {
            lo = lo.min(p.0.min(p.1));
            hi = hi.max(p.0.max(p.1));
        }
        mv = mv.with(Series::points(TARGETS[t], pts));
    }
    if lo.is_finite() {
        mv = mv.with(Series::line("y = x", vec![(lo, lo), (hi, hi)]));
    }
    page.plot(
        "measured_vs_model",
        "Each point is one measurement; on the line y = x the model is exact.",
        &mv,
    )?;

    // Residual against every axis and channel.
    page.heading("Residual against positions and channels");
    page.paragraph("A trend here is an effect the model lacks: a slope against a temperature is thermal growth, a step between dir = −1 and +1 is reversal (backlash), a drift with t_s is drift.");
    let mut figs = Vec::new();
    for (k, (channel, values)) in channels(data).iter().enumerate() {
        let mut plot = XyPlot::new(
            format!("residual against {}", axis_title(channel)),
            axis_title(channel),
            "residual (µm)",
        )
        .with_x_ticks(ticks_for(channel))
        .with_hline(0.0, "");
        for t in data.targets() {
            let res = residuals(data, predicted, t);
            let pts: Vec<(f64, f64)> = res
                .iter()
                .zip(values)
                .filter_map(|(r, x)| r.map(|r| (*x, r)))
                .collect();
            plot = plot.with(Series::points(TARGETS[t], pts));
            if let Some(p) = c
                .channels
                .iter()
                .find(|p| &p.channel == channel && p.target == TARGETS[t])
            {
                let means: Vec<(f64, f64)> = p
                    .bins
                    .iter()
                    .map(|b| (0.5 * (b.lo + b.hi), b.mean_um))
                    .collect();
                plot = plot.with(Series::styled(
                    format!("{} binned mean", TARGETS[t]),
                    means,
                    Style::LinePoints,
                ));
            }
        }
        figs.push(Figure {
            name: format!("channel{k}"),
            caption: format!(
                "Residual against {} (column {channel}), with the mean per bin.",
                axis_title(channel)
            ),
            svg: plot.svg()?,
            narrow: plot.phone_svg()?,
        });
    }
    page.grid_wide(figs);
    let rows = c
        .channels
        .iter()
        .map(|p| {
            vec![
                p.channel.clone(),
                p.target.clone(),
                p.corr.map_or("—".into(), |v| format!("{v:+.3}")),
                p.slope_um_per_unit
                    .map_or("—".into(), |v| format!("{v:+.4}")),
            ]
        })
        .collect();
    page.table(
        &["channel", "target", "correlation", "slope (µm/unit)"],
        rows,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_engine::compare::compare;

    #[test]
    fn pick_evenly_keeps_both_ends() {
        assert_eq!(pick_evenly(3, 5), vec![0, 1, 2]);
        assert_eq!(pick_evenly(9, 5), vec![0, 2, 4, 6, 8]);
        assert_eq!(pick_evenly(17, 5), vec![0, 4, 8, 12, 16]);
        assert_eq!(pick_evenly(6, 5), vec![0, 1, 3, 4, 5]);
        assert_eq!(pick_evenly(0, 5), Vec::<usize>::new());
    }
    #[test]
    fn the_card_turns_orange_for_a_trend_or_a_clear_region_only() {
        let mut d = Dataset {
            source: "d.csv".into(),
            ..Dataset::default()
        };
        let n = 40;
        d.pos_mm = [Some((0..n).map(|i| i as f64 * 10.0).collect()), None, None];
        d.err_um = [
            Some(
                (0..n)
                    .map(|i| Some(if i % 2 == 0 { 0.2 } else { -0.2 }))
                    .collect(),
            ),
            None,
            None,
        ];
        let pred = [Some(vec![0.0; n as usize]), None, None];
        let mut c = compare(&d, "cubic19", &pred, [None; 3]);
        let region = |ratio: f64| trueaxis_engine::regions::Region {
            target: "ex".into(),
            bbox_mm: [("x".to_string(), [0.0, 100.0])].into(),
            rms_um: 0.2 * ratio,
            ratio: Some(ratio),
            points: 10,
            share: Some(0.3),
            time_s: None,
        };
        c.worst_regions = vec![region(1.35)];
        c.channels.clear();
        let dir = Path::new("rep");
        let v = verdict(&c, None, dir);
        assert_eq!(v.tone, Tone::Unknown, "1.35× is within chance at the noise");
        assert!(
            v.headline
                .starts_with("After compensation ex is left at 0.200 µm RMS"),
            "{}",
            v.headline
        );
        assert_eq!(
            v.next.as_deref(),
            Some("trueaxis diagnose d.csv --model MODEL.json --report rep/diagnose")
        );
        c.worst_regions = vec![region(1.6)];
        assert_eq!(verdict(&c, None, dir).tone, Tone::Action);
        c.worst_regions = vec![region(1.1)];
        c.channels = vec![trueaxis_engine::compare::ChannelProfile {
            channel: "dir_x".into(),
            target: "ex".into(),
            corr: Some(-0.4),
            slope_um_per_unit: Some(-0.5),
            slope_unit: "µm per direction change".into(),
            partial_corr: Some(-0.4),
            partial_slope: Some(-1.0),
            explains_share: Some(0.16),
            bins: Vec::new(),
        }];
        let v = verdict(&c, None, dir);
        assert_eq!(v.tone, Tone::Action);
        assert!(
            v.details.iter().any(|l| l.contains(
                "approach direction along x (a step of -1.00 µm from −1 to +1; 16 % of the residual beyond position, r = -0.40)"
            )),
            "{:?}",
            v.details
        );
    }

    #[test]
    fn planes_and_lines_of_a_plan() {
        // Grid 5 × 4 × 3 plus a dense line along x at y = 0, z = 0.
        let mut d = Dataset {
            source: "t".into(),
            ..Dataset::default()
        };
        let (mut x, mut y, mut z, mut e) = (vec![], vec![], vec![], vec![]);
        for iz in 0..3 {
            for iy in 0..4 {
                for ix in 0..5 {
                    x.push(f64::from(ix) * 50.0);
                    y.push(f64::from(iy) * 50.0);
                    z.push(f64::from(iz) * 50.0);
                    e.push(Some(0.0));
                }
            }
        }
        for i in 0..40 {
            x.push(f64::from(i) * 5.0);
            y.push(0.0);
            z.push(0.0);
            e.push(Some(1.0));
        }
        d.pos_mm = [Some(x), Some(y), Some(z)];
        d.err_um = [Some(e), None, None];
        let p = planes(&d);
        assert_eq!(p.iter().filter(|p| p.normal == 2).count(), 3);
        let lines = dense_lines(&d, 25);
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].axis, 0);
        assert_eq!(lines[0].label, "y=0, z=0");
        let pred = [Some(vec![0.0; d.len()]), None, None];
        let c = compare(&d, "m", &pred, [None; 3]);
        let mut page = Page::new("t");
        build_report(&mut page, &d, &pred, &c).unwrap();
        let html = page.to_html();
        assert!(html.contains("ex residual at z = 0 mm"));
        assert!(html.contains("residual along x"));
        assert!(page.figure_count() > 8);
    }
}
