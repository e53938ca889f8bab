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
use trueaxis_engine::effect::{EffectSpec, Family};
use trueaxis_engine::features;

use trueaxis_engine::diagnose::{Verdict as DVerdict, ABOVE_NOISE_RATIO};

use crate::report::plot::{
    self, axis_title, darker, format_value, target_colour, Drawing as _, HeatMap, MapPair, Series,
    Style, Ticks, XyPlot, DIRECTION_COLOURS,
};
use crate::report::{Figure, Page, Tone, Verdict};

/// Warning codes that undermine a verdict (shown on the card); the rest
/// (`in_model_span`, `aux_columns`, …) stay in the Warnings section.
pub const UNDERMINING: [&str; 10] = [
    "aliasing",
    "one_direction",
    "constant_temperature",
    "no_temperature",
    "confounded",
    "implausible_parameter",
    "aux_misspelled",
    "noise_floor_upper_bound",
    "noise_floor_unknown",
    "duplicate_rows",
];

/// The `fit` command that adds every effect the path found (one that
/// replaces an effect of the model takes its place); None without a path.
/// The text output's `next:` line and the verdict card's.
pub fn fit_command(d: &Diagnosis, data_path: &str, model_out: &str) -> Option<String> {
    if d.path.is_empty() {
        return None;
    }
    let mut cmd = format!(
        "trueaxis fit {} --model {}",
        shell_word(data_path),
        d.model.split(" + ").next().unwrap_or("cubic19")
    );
    let mut adds: Vec<String> = d.model.split(" + ").skip(1).map(String::from).collect();
    for p in &d.path {
        trueaxis_engine::diagnose::swap_in(&mut adds, &p.add, p.replaces.as_deref());
    }
    for a in adds {
        cmd.push_str(&format!(" --add '{a}'"));
    }
    // Written over the diagnosed model (or `model.json` for a seed name),
    // so the command runs as printed and the history continues.
    cmd.push_str(&format!(" -o {}", shell_word(model_out)));
    Some(cmd)
}

/// The diagnosed model fitted again as it is (its seed and every `--add`),
/// written to `model_out`: the first half of the command at the noise
/// floor ("fit, then export").
pub fn refit_command(d: &Diagnosis, data_path: &str, model_out: &str) -> String {
    let mut parts = d.model.split(" + ");
    let mut cmd = format!(
        "trueaxis fit {} --model {}",
        shell_word(data_path),
        parts.next().unwrap_or("cubic19")
    );
    for a in parts {
        cmd.push_str(&format!(" --add {}", shell_word(a)));
    }
    cmd.push_str(&format!(" -o {}", shell_word(model_out)));
    cmd
}

/// What to run for a probed bed (issue 28: beds were told to measure
/// ball-screw leads): fit a grid on the probe spacing and export it as a
/// Klipper mesh, as it runs when pasted where diagnose ran.
pub fn bed_next(data: &Dataset, data_path: &str) -> String {
    format!(
        "{} && trueaxis export bed.json --format klipper-mesh -o mesh.cfg",
        crate::workflow::next_for_data(data, std::path::Path::new(data_path))
    )
}

/// A path as one shell word: as it is when it has only characters no
/// shell treats specially, else in single quotes.
pub fn shell_word(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+,:=@%".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// An effect in words: "a periodic error of ex along x" (its family's
/// words, `EffectSpec::describe`).
pub fn effect_words(c: &Candidate) -> String {
    c.add
        .parse::<EffectSpec>()
        .map_or_else(|_| c.add.clone(), |s| s.describe())
}

/// The physical value in words: "amplitude 3.08 µm (95 %: 3.03 … 3.13)",
/// with the searched parameter (period, lag) first.
fn physical_words(c: &Candidate) -> String {
    let mut parts = Vec::new();
    if let Some(p) = c.params.get("period_mm") {
        parts.push(format!("period {} mm", format_value(*p)));
    }
    if let Some(l) = c.params.get("lag_s").filter(|l| **l > 0.0) {
        parts.push(format!("lag {} s", format_value(*l)));
    }
    if let Some(ph) = &c.physical {
        parts.push(format!(
            "{} {} {} (95 %: {} … {})",
            ph.name.replace('_', " "),
            format_value(ph.value),
            ph.unit,
            format_value(ph.ci95[0]),
            format_value(ph.ci95[1])
        ));
    }
    parts.join(", ")
}

/// How sure, in plain words: ΔBIC and the held-out gain.
fn sureness(c: &Candidate) -> String {
    let bic = c.delta_bic.map_or("no ΔBIC".into(), |b| {
        let word = if b < -100.0 {
            "overwhelming"
        } else if b < -30.0 {
            "very strong"
        } else {
            "strong"
        };
        format!("ΔBIC {b:.0} — {word} evidence (the rule asks for < −10)")
    });
    let held = match (c.gain, c.held_out_rms_um_after) {
        (Some(g), Some(after)) if g < 1.0 => format!(
            "on blocks the fit never saw, the {} error falls from {} to {} µm ({:.0} % lower; the rule asks for 10 %)",
            c.target,
            format_value(after / (1.0 - g)),
            format_value(after),
            100.0 * g
        ),
        _ => "no held-out figure".into(),
    };
    format!("{bic}; {held}")
}

/// The diagnose page's verdict: what is missing (effect, target, value
/// ± 95 %, how sure) or that nothing named is, what is left above the
/// noise and where, the warnings that undermine it, and the next command.
pub fn verdict(d: &Diagnosis, data_path: &str, model_out: &str) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    let path_cands: Vec<&Candidate> = d
        .path
        .iter()
        .filter_map(|p| d.candidates.iter().find(|c| c.on_path() && c.add == p.add))
        .collect();
    let mut details = Vec::new();
    let mut warnings: Vec<String> = d
        .warnings
        .iter()
        .filter(|w| UNDERMINING.contains(&w.code.as_str()))
        .map(|w| format!("{} ({})", w.detail, w.code))
        .collect();
    // What is left after the path, per target, against its noise floor.
    let final_rms = |t: &str| {
        d.path
            .iter()
            .rev()
            .find(|p| p.target == t)
            .map_or(d.rms_um.get(t).copied().unwrap_or(f64::NAN), |p| p.rms_um)
    };
    let mut left = Vec::new();
    let mut unknown_noise = Vec::new();
    for t in d.rms_um.keys() {
        match d.noise_floor_um.get(t).copied().flatten() {
            Some(nf) if nf > 0.0 => {
                let r = final_rms(t);
                if r > ABOVE_NOISE_RATIO * nf {
                    left.push((t.clone(), r, nf));
                }
            }
            _ => unknown_noise.push(t.clone()),
        }
    }
    let region = |t: &str| {
        d.worst_regions
            .iter()
            .filter(|r| r.target == t)
            .max_by(|a, b| a.rms_um.total_cmp(&b.rms_um))
            .map(|r| r.place())
    };
    let mut left_words: Vec<String> = left
        .iter()
        .map(|(t, r, nf)| {
            format!(
                "{t} at {:.1}× the noise ({} against {}{})",
                r / nf,
                um(*r),
                um(*nf),
                region(t).map_or(String::new(), |b| format!(", worst in {b} mm"))
            )
        })
        .collect();
    // A target within 1.3× overall but far above its floor in a region of
    // the working volume (`region_ratio`): left above the noise there.
    for u in &d.unexplained {
        if let (Some(_), Some(_)) = (u.region_ratio, &u.region) {
            if !left.iter().any(|(t, _, _)| *t == u.target) {
                left.push((u.target.clone(), u.rms_um, u.noise_floor_um));
                left_words.push(u.text());
            }
        }
    }
    let noise_words: Vec<String> = d
        .rms_um
        .keys()
        .map(|t| {
            let nf = d.noise_floor_um.get(t).copied().flatten();
            format!(
                "{t} {} (noise {})",
                um(final_rms(t)),
                nf.map_or("unknown".into(), um)
            )
        })
        .collect();
    // Candidates held back as aliasing-suspect: beside the verdict, each
    // with why and the line to measure.
    let held: Vec<String> = d
        .held_back()
        .map(|(c, a)| format!("Not added: {} ({}) — {}.", effect_words(c), c.add, a.text))
        .collect();
    let measure_first = d
        .held_back()
        .next()
        .map(|(_, a)| format!("measure first: a dense line: {}", a.measure));
    // Targets whose floor is only an upper bound (`sparse_differences`).
    let upper_bound: Vec<&str> = d
        .noise_method
        .iter()
        .filter(|(_, m)| {
            **m == Some(trueaxis_engine::diagnose::noise::NoiseMethod::SparseDifferences)
        })
        .map(|(t, _)| t.as_str())
        .collect();
    let (headline, tone, next) = match d.verdict {
        DVerdict::MissingEffect if !path_cands.is_empty() => {
            let names: Vec<String> = path_cands.iter().map(|c| effect_words(c)).collect();
            for (k, c) in path_cands.iter().enumerate() {
                details.push(format!(
                    "{}. {}: {}. How sure: {}.",
                    k + 1,
                    effect_words(c),
                    physical_words(c),
                    sureness(c)
                ));
                if let Some(ph) = c.physical.as_ref().filter(|p| !p.plausible) {
                    warnings.push(format!(
                        "{} {} {} is outside the plausible range ({}): check the sensor and the unit before trusting the value",
                        ph.name, format_value(ph.value), ph.unit, ph.expected
                    ));
                }
            }
            details.push(if left.is_empty() {
                format!(
                    "With {}: {} — nothing else is left above the noise.",
                    if names.len() == 1 { "it" } else { "them" },
                    noise_words.join(", ")
                )
            } else {
                format!(
                    "Even with {}, {} is left above the noise: another effect, or one outside the library.",
                    if names.len() == 1 { "it" } else { "them" },
                    left_words.join("; ")
                )
            });
            details.extend(held);
            (
                format!("Missing: {}.", names.join("; and ")),
                Tone::Action,
                fit_command(d, data_path, model_out),
            )
        }
        _ if !held.is_empty() => {
            let (c, a) = d.held_back().next().expect("held is not empty");
            let seen = match c.effect {
                Family::Periodic => {
                    format!("with a period of {} mm", format_value(a.seen_period_mm))
                }
                _ => format!("like a {} mm wave", format_value(a.seen_period_mm)),
            };
            details.extend(held);
            if !left.is_empty() {
                details.push(format!("Left above the noise: {}.", left_words.join("; ")));
            }
            (
                format!(
                    "Not claimed: {} varies along {} {seen}, but {} is sampled every {} mm — a lead's alias would look the same. Measure a dense line first.",
                    c.target,
                    a.axis,
                    a.axis,
                    trueaxis_engine::lines::plot_num(a.sampling_mm)
                ),
                Tone::Action,
                measure_first,
            )
        }
        _ if left.is_empty() && unknown_noise.is_empty() && !upper_bound.is_empty() => {
            details.push(format!("Residual: {}.", noise_words.join(", ")));
            (
                format!(
                    "Nothing named is missing, but the noise floor of {} is an upper bound: re-probe points (repeat the map / these points) to measure repeatability.",
                    upper_bound.join(", ")
                ),
                Tone::Unknown,
                Some("re-probe the points the warning names (or repeat the whole measurement) within 15 min, then run diagnose again on both together".into()),
            )
        }
        _ if left.is_empty() && unknown_noise.is_empty() => {
            details.push(format!("Residual: {}.", noise_words.join(", ")));
            details.push(
                "No candidate effect passes the rules (ΔBIC < −10 and 10 % lower held-out error)."
                    .into(),
            );
            (
                "Nothing is missing: every target is at the noise floor of the measurement.".into(),
                if warnings.is_empty() {
                    Tone::Good
                } else {
                    Tone::Unknown
                },
                Some(format!(
                    "{} && trueaxis export {} -o table.bin",
                    refit_command(d, data_path, model_out),
                    shell_word(model_out)
                )),
            )
        }
        _ if left.is_empty() => {
            details.push(format!("Residual: {}.", noise_words.join(", ")));
            (
                format!(
                    "Nothing named is missing, but the noise floor of {} cannot be estimated (no repeated points or dense lines): whether anything is left is unknown.",
                    unknown_noise.join(", ")
                ),
                Tone::Unknown,
                Some("measure a few points repeatedly (or a dense line), then run diagnose again".into()),
            )
        }
        _ => {
            details.push(
                "No candidate effect of the library passes the rules (ΔBIC < −10 and 10 % lower held-out error): what is left is a smooth shape the seed cannot follow, an effect outside the library, or one the measurement cannot show (see below)."
                    .into(),
            );
            let next = d
                .warnings
                .iter()
                .find(|w| {
                    [
                        "aliasing",
                        "one_direction",
                        "constant_temperature",
                        "no_temperature",
                    ]
                    .contains(&w.code.as_str())
                })
                .map(|w| format!("measure first: {}", w.detail))
                .or_else(|| {
                    Some(format!(
                        "{} && trueaxis compare {} --model {} --report report",
                        refit_command(d, data_path, model_out),
                        shell_word(data_path),
                        shell_word(model_out)
                    ))
                });
            (
                format!(
                    "Nothing named is missing, but {} is left above the noise: {}.",
                    left.iter()
                        .map(|l| l.0.clone())
                        .collect::<Vec<_>>()
                        .join(", "),
                    left_words.join("; ")
                ),
                Tone::Action,
                next,
            )
        }
    };
    Verdict {
        headline,
        details,
        warnings,
        next,
        tone,
    }
}

/// False-alarm probability of the periodogram's significance line.
pub const FALSE_ALARM: f64 = 0.01;
/// Multiples of the grid's frequency marked as its sampling comb.
const COMB_MARKS: usize = 6;

/// What a periodogram was computed from: the readings on the densest lines
/// along the axis (as the periodic search takes them) and the spacing of
/// the coarser grid the plan also has along it (its sampling comb), if any.
struct Sampling {
    points: usize,
    grid_mm: Option<f64>,
}

fn periodogram_sampling(data: &Dataset, axis: usize, rows: &[usize]) -> Option<Sampling> {
    let dl = trueaxis_engine::lines::densest_lines(data, axis, rows)?;
    let pos = data.pos_mm[axis].as_ref()?;
    let grid_mm = if dl.from_lines {
        let on: std::collections::HashSet<usize> = dl.rows.iter().copied().collect();
        let mut p: Vec<i64> = rows
            .iter()
            .filter(|r| !on.contains(r))
            .map(|&r| (pos[r] * 1000.0).round() as i64)
            .collect();
        p.sort_unstable();
        p.dedup();
        let mut gaps: Vec<i64> = p.windows(2).map(|w| w[1] - w[0]).collect();
        gaps.sort_unstable();
        gaps.get(gaps.len() / 2)
            .map(|g| *g as f64 / 1000.0)
            .filter(|g| *g > dl.spacing_mm * 1.5)
    } else {
        Some(dl.spacing_mm)
    };
    Some(Sampling {
        points: dl.rows.len(),
        grid_mm,
    })
}

/// Independent frequencies among `n_freq` computed: the periodic search
/// oversamples the natural resolution 1/span five times.
fn independent_frequencies(n_freq: usize) -> usize {
    n_freq.div_ceil(5).max(1)
}

/// The power that noise alone exceeds at some frequency of the band with
/// probability `fap`: for Gaussian noise N·p/2 is about exponential at each
/// independent frequency (the scale the periodic search's harmonic rule
/// uses), so over M of them the level is 2·ln(M/fap)/N. None with too few
/// readings to say.
pub fn false_alarm_level(n_points: usize, n_freq: usize, fap: f64) -> Option<f64> {
    if n_points < 8 || n_freq == 0 || !(fap > 0.0 && fap < 1.0) {
        return None;
    }
    let m = independent_frequencies(n_freq) as f64;
    Some((2.0 * (m / fap).ln() / n_points as f64).min(1.0))
}

/// Bins along the travel of a forward/backward profile.
const PROFILE_BINS: usize = 40;

/// The mean y per x bin (`bins` even bins over the x range), at the bin's
/// mean x, for the bins that hold points: a profile through a scatter.
fn binned_mean(pts: &[(f64, f64)], bins: usize) -> Vec<(f64, f64)> {
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
            (l.min(p.0), h.max(p.0))
        });
    if pts.is_empty() || bins == 0 {
        return Vec::new();
    }
    let mut acc = vec![(0.0, 0.0, 0usize); bins];
    for &(x, y) in pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        let k = if hi > lo {
            (((x - lo) / (hi - lo) * bins as f64) as usize).min(bins - 1)
        } else {
            0
        };
        acc[k].0 += x;
        acc[k].1 += y;
        acc[k].2 += 1;
    }
    acc.into_iter()
        .filter(|a| a.2 > 0)
        .map(|(sx, sy, n)| (sx / n as f64, sy / n as f64))
        .collect()
}

/// Bins per axis of the working-volume overview at most.
const OVERVIEW_BINS: usize = 12;

/// The cell centres of an overview axis over the sorted distinct measured
/// positions: the positions themselves when there are at most `max`, else
/// the centres of the most even bins (at most `max`) of which none is
/// empty — a complete grid never shows a hole.
fn overview_centres(distinct: &[f64], max: usize) -> Vec<f64> {
    if distinct.len() <= max {
        return distinct.to_vec();
    }
    let (lo, hi) = (distinct[0], distinct[distinct.len() - 1]);
    for n in (1..=max).rev() {
        let w = (hi - lo) / n as f64;
        let mut filled = vec![false; n];
        for &p in distinct {
            filled[(((p - lo) / w) as usize).min(n - 1)] = true;
        }
        if filled.iter().all(|&f| f) {
            return (0..n).map(|k| lo + w * (k as f64 + 0.5)).collect();
        }
    }
    vec![0.5 * (lo + hi)]
}

/// The index of the centre nearest `v` (centres ascending, not empty).
fn nearest_index(centres: &[f64], v: f64) -> usize {
    let i = centres.partition_point(|&c| c < v);
    if i == 0 {
        0
    } else if i == centres.len() || v - centres[i - 1] <= centres[i] - v {
        i - 1
    } else {
        i
    }
}

/// Where in the working volume the final residual is large, on the first
/// screen (issue 13): per target, the RMS of the residual after the path in
/// even bins (≤ 12 per axis) projected on each pair of moving axes — small
/// maps side by side on one colour scale per target (0 white … the largest
/// cell red), the worst reading ringed. Nothing for fewer than two moving
/// axes.
fn volume_overview(page: &mut Page, d: &Diagnosis, data: &Dataset) -> Result<()> {
    let axes = data.varying_axes();
    if axes.len() < 2 {
        return Ok(());
    }
    let pairs: Vec<(usize, usize)> = (0..axes.len())
        .flat_map(|i| (i + 1..axes.len()).map(move |j| (i, j)))
        .map(|(i, j)| (axes[i], axes[j]))
        .collect();
    let mut figs = Vec::new();
    let mut scales = Vec::new();
    for (t, rows, after) in &d.evidence.resid_after {
        let tn = TARGETS[*t];
        let mut maps = Vec::new();
        for &(a, b) in &pairs {
            let (Some(pa), Some(pb)) = (data.pos_mm[a].as_ref(), data.pos_mm[b].as_ref()) else {
                continue;
            };
            // Cells on the measured positions (issue 28: 11 grid lines cut
            // into 12 even bins left a grey "not measured" band on a
            // complete grid): each distinct position its own cell while
            // they are few, else even bins, as many as leave none empty.
            let bins = |p: &[f64]| {
                let mut distinct: Vec<f64> = rows.iter().map(|&r| p[r]).collect();
                distinct.sort_by(f64::total_cmp);
                distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-3);
                overview_centres(&distinct, OVERVIEW_BINS)
            };
            let (ca, cb) = (bins(pa), bins(pb));
            let (na, nb) = (ca.len(), cb.len());
            let mut ss = vec![0.0; na * nb];
            let mut count = vec![0usize; na * nb];
            let mut worst: Option<(f64, f64, f64)> = None;
            for (i, &r) in rows.iter().enumerate() {
                let v = after[i];
                if !v.is_finite() {
                    continue;
                }
                let k = nearest_index(&cb, pb[r]) * na + nearest_index(&ca, pa[r]);
                ss[k] += v * v;
                count[k] += 1;
                if worst.is_none_or(|w| v.abs() > w.2.abs()) {
                    worst = Some((pa[r], pb[r], v));
                }
            }
            let values = ss
                .iter()
                .zip(&count)
                .map(|(s, &c)| (c > 0).then(|| (s / c as f64).sqrt()))
                .collect();
            let mut m = HeatMap::from_cells(
                format!("{tn} RMS over {}–{}", AXES[a], AXES[b]),
                format!("{} (mm)", AXES[a]),
                format!("{} (mm)", AXES[b]),
                "µm",
                ca,
                cb,
                values,
                worst,
                rows.len(),
            );
            m.size = (460, 380);
            maps.push((format!("overview_{tn}_{}{}", AXES[a], AXES[b]), m));
        }
        // At the noise a map must look pale, not red: the scale reaches at
        // least 3× the noise floor.
        let noise = d.noise_floor_um.get(tn).copied().flatten();
        let limit = maps
            .iter()
            .fold(noise.map_or(0.0, |n| 3.0 * n), |l, m| l.max(m.1.max_abs()));
        scales.push(format!(
            "{tn} 0…{} µm{}",
            format_value(limit),
            noise.map_or(String::new(), |n| format!(", noise {}", format_value(n)))
        ));
        for (name, mut m) in maps {
            m.limit = Some(limit);
            figs.push(Figure {
                name,
                caption: format!(
                    "RMS of the {tn} residual after the path per cell, projected on {}–{} (red: where the model fails most).",
                    m.x_label, m.y_label
                ),
                svg: m.svg()?,
            narrow: m.phone_svg()?,
            });
        }
    }
    if figs.is_empty() {
        return Ok(());
    }
    page.heading("Where the model fails");
    page.paragraph(format!(
        "RMS of the residual after the path, in bins of the working volume projected on each pair of axes; one colour scale per target, reaching at least 3× its noise floor so that a map at the noise stays pale ({}); the worst reading ringed.",
        scales.join(", ")
    ));
    page.grid(figs);
    Ok(())
}

/// Least-squares slope and intercept of y on x; None for fewer than 3
/// points or no spread in x.
fn line_fit(pts: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = pts.len() as f64;
    if pts.len() < 3 {
        return None;
    }
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 1e-12 * n).then(|| (sxy / sxx, my - sxy / sxx * mx))
}

/// The thermal evidence as the slope a user wants (issue 13): a one-sensor
/// thermal effect's component plus the final residual against the sensor's
/// temperature — per metre of travel when the growth scales with an axis
/// (rows within 20 % of the axis' largest |position| left out: dividing by
/// a short arm blows the noise up) — with the least-squares line and its
/// slope (µm/m/K: the CTE; µm/K without an axis), the fit's value ± 95 %
/// and the lag beside it. None for other effects or without the sensor.
fn thermal_slope(
    data: &Dataset,
    c: &Candidate,
    step: usize,
    rows: &[usize],
    component: &[f64],
    after: &[f64],
) -> Result<Option<Figure>> {
    if c.effect != Family::Thermal {
        return Ok(None);
    }
    let Some(column) = c.channel.as_deref().filter(|ch| !ch.contains('+')) else {
        return Ok(None);
    };
    let name = column
        .strip_prefix("T_")
        .and_then(|n| n.strip_suffix("_C"))
        .unwrap_or(column);
    let Some(raw) = data.temp(name).map(|t| &t.temp_c) else {
        return Ok(None);
    };
    // With a lag the structure follows the sensor's first-order lag, not
    // its reading: against the raw reading warm-up and cool-down lie on
    // two branches and the eye cannot find the slope. The points are drawn
    // against the lagged temperature the model uses (the caption says so).
    let lag_s = c.params.get("lag_s").copied().filter(|l| *l > 0.0);
    let lagged = match (lag_s, data.t_s.as_deref()) {
        (Some(tau), Some(t_s)) => Some(features::lagged(raw, t_s, data.session_id.as_deref(), tau)),
        _ => None,
    };
    let temp = lagged.as_deref().unwrap_or(raw);
    let column = format!("T_{name}_C");
    let axis = c
        .axis
        .as_deref()
        .and_then(|a| AXES.iter().position(|x| *x == a));
    let arm = axis.and_then(|a| data.pos_mm[a].as_ref());
    let reach = arm.map_or(0.0, |p| {
        rows.iter().map(|&r| p[r].abs()).fold(0.0, f64::max)
    });
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, &r)| {
            let y = component[i] + after[i];
            match arm {
                Some(p) if p[r].abs() >= 0.2 * reach && reach > 0.0 => {
                    Some((temp[r], y / (p[r] / 1000.0)))
                }
                Some(_) => None,
                None => Some((temp[r], y)),
            }
        })
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let Some((slope, icpt)) = line_fit(&pts) else {
        return Ok(None);
    };
    let (unit, y_label) = match axis {
        Some(a) => (
            "µm/m/K",
            format!("{} per metre of {} travel (µm/m)", c.target, AXES[a]),
        ),
        None => ("µm/K", format!("{} (µm)", c.target)),
    };
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
            (l.min(p.0), h.max(p.0))
        });
    let t_title = match (&lagged, lag_s) {
        (Some(_), Some(l)) => format!(
            "{} lagged by {} s (°C)",
            axis_title(&column).trim_end_matches(" (°C)"),
            format_value(l)
        ),
        _ => axis_title(&column),
    };
    let colour =
        plot::target_of(&c.target.to_string()).map_or(plot::OTHER_COLOURS[0], target_colour);
    let plot = XyPlot::new(
        format!(
            "Thermal growth of {}{}: the slope",
            c.target,
            axis.map_or(String::new(), |a| format!(" along {}", AXES[a]))
        ),
        t_title.clone(),
        y_label,
    )
    .with(Series::points("component + residual", pts.clone()).coloured(colour))
    .with(
        Series::line(
            format!("least squares: {} {unit}", format_value(slope)),
            vec![(lo, icpt + slope * lo), (hi, icpt + slope * hi)],
        )
        .coloured(darker(colour, 0.45)),
    );
    let fitted = c.physical.as_ref().map_or(String::new(), |ph| {
        format!(
            "; the model's {} is {} {} (95 %: {} … {})",
            ph.name.replace('_', " "),
            format_value(ph.value),
            ph.unit,
            format_value(ph.ci95[0]),
            format_value(ph.ci95[1])
        )
    });
    let lag = match (lag_s, &lagged) {
        (Some(l), Some(_)) => format!(
            ". The structure follows the sensor with a lag of {} s (a first-order lag, as the model has it): the points are drawn against that lagged temperature, where warm-up and cool-down fall on one line; against the raw reading they would lie on two branches",
            format_value(l)
        ),
        (Some(l), None) => format!(
            ". The model lags the sensor by {} s, but the data have no time column to lag it with here, so warm-up and cool-down lie on two branches around the line",
            format_value(l)
        ),
        _ => String::new(),
    };
    Ok(Some(Figure {
        name: format!("thermal_slope_{}_{step}", c.target),
        caption: format!(
            "Path step {step} of {}: component + final residual{} against the {t_title}; the slope of the least-squares line, {} {unit}, is the {}{fitted}{lag}.",
            c.target,
            axis.map_or(String::new(), |a| format!(
                " per metre of {} travel (rows within 20 % of the largest |{}| left out)",
                AXES[a], AXES[a]
            )),
            format_value(slope),
            if axis.is_some() {
                "thermal expansion coefficient (CTE)"
            } else {
                "growth per kelvin"
            },
        ),
        svg: plot.svg()?,
            narrow: plot.phone_svg()?,
    }))
}

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
            Some((
                axis_title(&format!("T_{name}_C")),
                data.temp(name)?.temp_c.clone(),
            ))
        }
        Family::Drift => Some((axis_title("t_s"), data.t_s.clone()?)),
        Family::Abbe => Some((axis_title("tool_mm"), data.tool_mm.clone()?)),
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
    write_for(d, data, &data.source, "model.json", dir, history)
}

/// [`write_with_history`], with the data file named as the user would
/// type it in the verdict card's next command (`data.source` may be a
/// generator's name, `simulate:mill800`).
pub fn write_for(
    d: &Diagnosis,
    data: &Dataset,
    data_path: &str,
    model_out: &str,
    dir: &Path,
    history: Option<&trueaxis_engine::history::History>,
) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis diagnose — {}", data.source));
    let mut v = verdict(d, data_path, model_out);
    if data.is_probed_surface() {
        v.details.insert(
            0,
            "A probed bed (ez over x and y only): its model is a grid over the probe points or a smoother mesh, exported as the firmware's bed mesh.".into(),
        );
        v.next = Some(bed_next(data, data_path));
    }
    page.verdict(v);
    volume_overview(&mut page, d, data)?;
    page.heading("Diagnosis");
    page.paragraph(format!(
        "Model {}; verdict {}; hold-out: {}.",
        d.model,
        d.verdict.as_str(),
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
                    None if c.held_back => "no (held back: aliasing-suspect)".into(),
                    None => "no".into(),
                },
                match &c.aliasing {
                    Some(a) => format!("{}; aliasing: {}", c.evidence, a.text),
                    None => c.evidence.clone(),
                },
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
        let noise: std::collections::BTreeMap<String, f64> = d
            .noise_floor_um
            .iter()
            .filter_map(|(t, v)| v.map(|v| (t.clone(), v)))
            .collect();
        crate::report::history::add_to_page(&mut page, h, &noise)?;
    }
    page.heading("Evidence");
    page.colour_key();
    // The x–y evidence side by side, two per row; the maps below full width.
    let mut figs: Vec<Figure> = Vec::new();
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
            "period (mm), on a frequency scale",
            "share of variance",
        )
        .with_x_ticks(Ticks::Period)
        .with(Series::line("Lomb–Scargle power", pts).coloured(plot::target_colour(e.target)));
        let rows = d
            .evidence
            .resid_before
            .iter()
            .find(|r| r.0 == e.target)
            .map(|r| r.1.as_slice())
            .unwrap_or(&[]);
        let sampling = periodogram_sampling(data, e.axis, rows);
        let mut caption =
            format!("Lomb–Scargle periodogram of the {tn} residual along {ax}{at} (dense lines)");
        let level = sampling
            .as_ref()
            .and_then(|s| false_alarm_level(s.points, e.pg.power.len(), FALSE_ALARM));
        // The peak is marked red only when it is a finding (above the 1 %
        // level, or no level known); a peak below it is marked grey.
        if let Some(k) = e.pg.peak() {
            let label = format!("{} mm", format_value(1.0 / e.pg.freq_per_mm[k]));
            plot = if level.is_some_and(|l| e.pg.power[k] < l) {
                plot.with_vline_coloured(e.pg.freq_per_mm[k], label, plot::NO_FINDING)
            } else {
                plot.with_vline(e.pg.freq_per_mm[k], label)
            };
        }
        if let Some(level) = level {
            plot = plot.with_dashed(level, "1 % false-alarm level", plot::NO_FINDING);
            caption.push_str(&format!(
                "; dashed: the power noise alone passes somewhere in the band with 1 % probability ({} points, {} independent frequencies) — a peak below it is no finding",
                sampling.as_ref().map_or(0, |s| s.points),
                independent_frequencies(e.pg.power.len())
            ));
        }
        if let Some(grid) = sampling.as_ref().and_then(|s| s.grid_mm) {
            let (lo, hi) = (
                e.pg.freq_per_mm.first().copied().unwrap_or(0.0),
                e.pg.freq_per_mm.last().copied().unwrap_or(0.0),
            );
            let comb: Vec<f64> = (1..=COMB_MARKS)
                .map(|k| k as f64 / grid)
                .filter(|f| *f >= lo && *f <= hi)
                .collect();
            for (k, f) in comb.iter().enumerate() {
                let label = if k == 0 {
                    format!("{} mm grid comb", format_value(grid))
                } else {
                    String::new()
                };
                plot = plot.with_vmark(*f, label);
            }
            if !comb.is_empty() {
                caption.push_str(&format!(
                    "; dotted: the sampling comb of the {} mm grid along {ax} (periods {} mm …), where a coarse grid puts power of its own",
                    format_value(grid),
                    comb.iter()
                        .take(3)
                        .map(|f| format_value(1.0 / f))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
        }
        figs.push(Figure {
            name: if e.step > 1 {
                format!("periodogram_{tn}_{ax}_step{}", e.step)
            } else {
                format!("periodogram_{tn}_{ax}")
            },
            caption,
            svg: plot.svg()?,
            narrow: plot.phone_svg()?,
        });
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
        .with(Series::points(format!("dir_{} = +1", AXES[*a]), up.clone()))
        .with(Series::points(
            format!("dir_{} = −1", AXES[*a]),
            down.clone(),
        ))
        .with(
            Series::styled(
                "forward profile (mean per bin)",
                binned_mean(&up, PROFILE_BINS),
                Style::LinePoints,
            )
            .coloured(darker(DIRECTION_COLOURS[0], 0.35)),
        )
        .with(
            Series::styled(
                "backward profile (mean per bin)",
                binned_mean(&down, PROFILE_BINS),
                Style::LinePoints,
            )
            .coloured(darker(DIRECTION_COLOURS[1], 0.35)),
        );
        figs.push(Figure {
            name: format!("reversal_{}_{}", TARGETS[*t], AXES[*a]),
            caption: format!(
                "{caption}; lines: the forward and the backward profile, the mean per {PROFILE_BINS}th of the travel — the gap between them is the reversal"
            ),
            svg: plot.svg()?,
            narrow: plot.phone_svg()?,
        });
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
        .with(Series::points("component + residual", partial).coloured(target_colour(t)))
        .with(Series::points("fitted component", fitted).coloured(darker(target_colour(t), 0.5)));
        figs.push(Figure {
            name: format!("component_{}_{}", TARGETS[t], comp.step),
            caption: format!(
                "Path step {} of {}: the fitted {} component with the final residual added back",
                comp.step, TARGETS[t], c.effect
            ),
            svg: plot.svg()?,
            narrow: plot.phone_svg()?,
        });
        if let Some(fig) = thermal_slope(data, c, comp.step, rows, &comp.values, after)? {
            figs.push(fig);
        }
    }
    page.grid_wide(figs);
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
            // The cells are the measured grid's lines; a dense line's
            // readings are averaged into them (one cell per reading made
            // 3 MB maps of grey columns).
            let snap = 1e-3;
            let mk = |title: &str, v: &[f64]| {
                HeatMap::from_grid_points(
                    title,
                    format!("{} (mm)", AXES[a]),
                    format!("{} (mm)", AXES[b]),
                    "µm",
                    &pts(v),
                    snap,
                )
            };
            let hb = mk(&format!("{tn} residual, {}", d.model), before);
            let ha = mk(&format!("{tn} residual after the path"), after);
            page.plot(
                format!("residual_map_{tn}"),
                format!(
                    "{tn}: mean residual per ({}, {}) cell, before and after",
                    AXES[a], AXES[b]
                ),
                &MapPair {
                    before: &hb,
                    after: &ha,
                },
            )?;
        }
    }
    page.write(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_engine::diagnose::{Evidence, PathStep, Physical, Region, Warning};

    fn diagnosis(rms_ex: f64, noise_ex: Option<f64>) -> Diagnosis {
        let m = |ex: f64| -> BTreeMap<String, f64> {
            [("ex".to_string(), ex), ("ey".to_string(), 0.2)].into()
        };
        Diagnosis {
            model: "cubic19".into(),
            rms_um: m(rms_ex),
            held_out_rms_um: m(rms_ex * 1.01),
            noise_floor_um: [("ex".to_string(), noise_ex), ("ey".to_string(), Some(0.2))].into(),
            noise_method: BTreeMap::new(),
            verdict: DVerdict::AtNoiseFloor,
            candidates: Vec::new(),
            path: Vec::new(),
            worst_regions: vec![Region {
                target: "ex".into(),
                bbox_mm: [("x".to_string(), [600.0, 800.0])].into(),
                rms_um: 3.9,
                ratio: None,
                points: 40,
                share: None,
                time_s: None,
            }],
            warnings: Vec::new(),
            hold_out: "spatial cells".into(),
            n_eff: Default::default(),
            lag1_autocorrelation: Default::default(),
            evidence: Evidence::default(),
            unexplained: Vec::new(),
            held_back: Vec::new(),
            unresolved: Vec::new(),
            outliers: Vec::new(),
        }
    }
    use std::collections::BTreeMap;

    #[test]
    fn at_the_noise_floor_the_card_says_nothing_is_missing_and_proposes_export() {
        let v = verdict(&diagnosis(0.2, Some(0.2)), "d.csv", "m.json");
        assert_eq!(v.tone, Tone::Good);
        assert!(
            v.headline.starts_with("Nothing is missing"),
            "{}",
            v.headline
        );
        // The model it diagnosed, refitted and exported: the same path in
        // both halves (it wrote model.json and exported that).
        assert_eq!(
            v.next.unwrap(),
            "trueaxis fit d.csv --model cubic19 -o m.json && trueaxis export m.json -o table.bin"
        );
        let spaced = verdict(&diagnosis(0.2, Some(0.2)), "my data.csv", "a b/m.json");
        assert_eq!(
            spaced.next.unwrap(),
            "trueaxis fit 'my data.csv' --model cubic19 -o 'a b/m.json' && trueaxis export 'a b/m.json' -o table.bin"
        );
    }

    #[test]
    fn a_residual_above_the_noise_is_named_with_its_region_and_what_undermines_it() {
        let mut d = diagnosis(0.5, Some(0.2));
        d.warnings = vec![
            Warning {
                code: "aliasing".into(),
                detail: "add a dense line along y".into(),
            },
            Warning {
                code: "in_model_span".into(),
                detail: "squareness cannot be told".into(),
            },
        ];
        let v = verdict(&d, "d.csv", "m.json");
        assert_eq!(v.tone, Tone::Action);
        assert!(
            v.headline.starts_with(
                "Nothing named is missing, but ex is left above the noise: ex at 2.5× the noise"
            ),
            "{}",
            v.headline
        );
        assert!(
            v.headline.contains("worst in x 600…800 mm"),
            "{}",
            v.headline
        );
        assert_eq!(
            v.warnings,
            vec!["add a dense line along y (aliasing)".to_string()]
        );
        assert_eq!(
            v.next.as_deref(),
            Some("measure first: add a dense line along y")
        );
        // Without a noise floor the card does not claim either way.
        let v = verdict(&diagnosis(0.5, None), "d.csv", "m.json");
        assert_eq!(v.tone, Tone::Unknown);
        assert!(v.headline.contains("cannot be estimated"), "{}", v.headline);
    }

    /// Issue 12: a wave the grid cannot attribute is not "nothing is
    /// missing" although the residual is at the noise elsewhere: the card
    /// names the held-back candidate, why, and the line to measure next.
    #[test]
    fn a_held_back_alias_is_named_on_the_card_with_the_line_to_measure() {
        let mut d = diagnosis(0.2, Some(0.2));
        d.verdict = DVerdict::AboveNoiseFloor;
        let add = "higher_order:target=ey,axis=y,degree=5";
        let measure = "y from 0 to 480 mm every 0.5 mm at x=400, z=240, forward and backward";
        d.held_back = vec![add.into()];
        d.candidates = vec![Candidate {
            effect: Family::HigherOrder,
            target: "ey".into(),
            axis: Some("y".into()),
            channel: None,
            params: [("degree".to_string(), 5.0)].into(),
            add: add.into(),
            held_out_rms_um_after: Some(0.45),
            held_out_rms_um_before: Some(1.7),
            hold_out: trueaxis_engine::diagnose::HoldOutKind::Blocks,
            gain: Some(0.74),
            identifiable: true,
            evidence: String::new(),
            delta_bic: Some(-17041.0),
            rms_um_after: Some(0.44),
            out_of_span_share: 0.01,
            significant: false,
            physical: None,
            confounded_with: Vec::new(),
            replaces: None,
            step: None,
            aliasing: Some(trueaxis_engine::diagnose::aliasing::Aliasing {
                axis: "y".into(),
                sampling_mm: 40.0,
                seen_period_mm: 317.0,
                alias_periods_mm: vec![5.08],
                measure: measure.into(),
                text: "ey varies along y like a 317 mm wave, but y is sampled every 40 mm: …"
                    .into(),
            }),
            held_back: true,
        }];
        let v = verdict(&d, "d.csv", "m.json");
        assert_eq!(v.tone, Tone::Action);
        assert_eq!(
            v.headline,
            "Not claimed: ey varies along y like a 317 mm wave, but y is sampled every 40 mm — a lead's alias would look the same. Measure a dense line first."
        );
        assert!(
            v.details[0].starts_with("Not added: a smooth shape of ey along y")
                && v.details[0].contains(add)
                && v.details[0].contains("but y is sampled every 40 mm"),
            "{:?}",
            v.details
        );
        assert_eq!(
            v.next.as_deref(),
            Some(format!("measure first: a dense line: {measure}").as_str())
        );
    }

    #[test]
    fn a_missing_effect_is_named_with_its_value_and_how_sure() {
        let mut d = diagnosis(2.0, Some(0.2));
        d.verdict = DVerdict::MissingEffect;
        let add = "periodic:target=ex,axis=x,period_mm=5";
        d.path = vec![PathStep {
            target: "ex".into(),
            add: add.into(),
            delta_bic: -6751.0,
            rms_um: 0.21,
            held_out_rms_um: 0.22,
            replaces: None,
            effective_n: None,
            delta_bic_effective: None,
        }];
        d.candidates = vec![Candidate {
            effect: Family::Periodic,
            target: "ex".into(),
            axis: Some("x".into()),
            channel: None,
            params: [("period_mm".to_string(), 5.0)].into(),
            add: add.into(),
            held_out_rms_um_after: Some(1.0),
            held_out_rms_um_before: Some(2.0),
            hold_out: trueaxis_engine::diagnose::HoldOutKind::Blocks,
            gain: Some(0.5),
            identifiable: true,
            evidence: String::new(),
            delta_bic: Some(-6751.0),
            rms_um_after: Some(0.99),
            out_of_span_share: 1.0,
            significant: true,
            physical: Some(Physical {
                name: "amplitude".into(),
                unit: "µm".into(),
                value: 3.08,
                ci95: [3.03, 3.13],
                plausible: false,
                expected: "≤ 20 µm".into(),
            }),
            confounded_with: Vec::new(),
            replaces: None,
            step: Some(1),
            aliasing: None,
            held_back: false,
        }];
        let v = verdict(&d, "d.csv", "m.json");
        assert_eq!(v.tone, Tone::Action);
        assert_eq!(
            v.headline,
            "Missing: a periodic error of ex along x (lead screw or scale pitch)."
        );
        let one = &v.details[0];
        for part in [
            "period 5.00 mm",
            "amplitude 3.08 µm (95 %: 3.03 … 3.13)",
            "ΔBIC -6751 — overwhelming evidence",
            "falls from 2.00 to 1.00 µm (50 % lower",
        ] {
            assert!(one.contains(part), "{part} in {one}");
        }
        assert!(
            v.details[1].contains("nothing else is left above the noise"),
            "{:?}",
            v.details
        );
        assert!(
            v.warnings[0].contains("outside the plausible range"),
            "{:?}",
            v.warnings
        );
        assert_eq!(
            v.next.as_deref(),
            Some(
                "trueaxis fit d.csv --model cubic19 --add 'periodic:target=ex,axis=x,period_mm=5' -o m.json"
            )
        );
    }

    /// Issue 15: the page's size does not grow with the rows. 64 004
    /// readings on four dense x lines (0.05 mm, no grid) with a periodogram
    /// of 64 000 frequencies: under 2 MB, the map binned with its worst
    /// reading ringed, the periodogram reduced and saying so. Before: every
    /// x of the lines was a map column (4 × 16 001 cells, ~13 MB) and the
    /// periodogram a polyline of every frequency.
    #[test]
    fn a_large_capture_gives_a_page_of_bounded_size() {
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for k in 0..4 {
            for i in 0..16_001 {
                x.push(i as f64 * 0.05);
                y.push(100.0 * k as f64);
            }
        }
        let n = x.len();
        let data = Dataset {
            source: "big.csv".into(),
            pos_mm: [Some(x.clone()), Some(y), Some(vec![250.0; n])],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            ..Dataset::default()
        };
        let mut before: Vec<f64> = x.iter().map(|x| (x / 0.8).sin()).collect();
        before[40_000] = 25.0;
        let after: Vec<f64> = before.iter().map(|v| 0.1 * v).collect();
        let rows: Vec<usize> = (0..n).collect();
        let mut d = diagnosis(1.0, Some(0.2));
        d.evidence = Evidence {
            periodograms: vec![trueaxis_engine::diagnose::PeriodogramEvidence {
                target: 0,
                axis: 0,
                step: 1,
                pg: trueaxis_engine::diagnose::periodogram::Periodogram {
                    freq_per_mm: (1..=64_000).map(|k| k as f64 / 6400.0).collect(),
                    power: (1..=64_000).map(|k| ((k % 97) as f64) / 1e3).collect(),
                },
            }],
            resid_before: vec![(0, rows.clone(), before)],
            resid_after: vec![(0, rows, after)],
            components: Vec::new(),
        };
        let dir = std::env::temp_dir().join(format!("trueaxis-diag-big-{}", std::process::id()));
        let index = write(&d, &data, &dir).unwrap();
        let html = std::fs::read_to_string(&index).unwrap();
        assert!(html.len() < 2_000_000, "index.html is {} bytes", html.len());
        assert!(
            html.contains("64 004 readings on"),
            "the map says it is binned"
        );
        assert!(
            html.contains("ringed: the worst, 25.0 µm"),
            "the worst is ringed"
        );
        assert!(
            html.contains("64 000 points shown as"),
            "the periodogram is reduced"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The 1 % false-alarm level is one: on pure noise (fixed seed, 1 601
    /// readings every 0.5 mm) the highest power of the band stays under
    /// it, and a 5 mm wave of 0.15× the noise's σ rises above it.
    #[test]
    fn noise_stays_under_the_false_alarm_level_and_a_small_wave_passes_it() {
        use trueaxis_engine::diagnose::periodogram::periodogram;
        let pos: Vec<f64> = (0..1601).map(|i| i as f64 * 0.5).collect();
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut gauss = || {
            // Box–Muller on an xorshift stream: fixed, no crate.
            let mut u = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let (a, b) = (u().max(1e-300), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let noise: Vec<f64> = pos.iter().map(|_| gauss()).collect();
        let pg = periodogram(&pos, &noise, 1.0, 400.0);
        let level = false_alarm_level(pos.len(), pg.power.len(), FALSE_ALARM).unwrap();
        let top = pg.power.iter().copied().fold(0.0, f64::max);
        assert!(top < level, "noise peak {top} vs level {level}");
        let wave: Vec<f64> = pos
            .iter()
            .zip(&noise)
            .map(|(p, n)| {
                n + 0.15 * std::f64::consts::SQRT_2 * (std::f64::consts::TAU * p / 5.0).sin()
            })
            .collect();
        let pg = periodogram(&pos, &wave, 1.0, 400.0);
        let k = pg.peak().unwrap();
        assert!((1.0 / pg.freq_per_mm[k] - 5.0).abs() < 0.05);
        assert!(pg.power[k] > level, "{} vs {level}", pg.power[k]);
        assert_eq!(false_alarm_level(4, 100, FALSE_ALARM), None);
    }

    /// The periodogram figure draws the level and the grid's comb: a 50 mm
    /// grid along x plus a dense 2 mm line.
    #[test]
    fn the_periodogram_shows_its_false_alarm_level_and_the_grid_comb() {
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for iy in 0..3 {
            for ix in 0..17 {
                x.push(50.0 * ix as f64);
                y.push(100.0 * iy as f64);
            }
        }
        for i in 0..=400 {
            x.push(2.0 * i as f64);
            y.push(100.0);
        }
        let n = x.len();
        let data = Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x.clone()), Some(y), Some(vec![0.0; n])],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            ..Dataset::default()
        };
        let rows: Vec<usize> = (0..n).collect();
        let s = periodogram_sampling(&data, 0, &rows).unwrap();
        // The line's 401 readings and the grid's 17 on the same line.
        assert_eq!(s.points, 418);
        assert_eq!(s.grid_mm, Some(50.0));
        let mut d = diagnosis(1.0, Some(0.2));
        d.evidence.resid_before = vec![(0, rows.clone(), vec![0.0; n])];
        d.evidence.periodograms = vec![trueaxis_engine::diagnose::PeriodogramEvidence {
            target: 0,
            axis: 0,
            step: 1,
            pg: trueaxis_engine::diagnose::periodogram::periodogram(
                &x[51..],
                &x[51..].iter().map(|p| (p / 0.8).sin()).collect::<Vec<_>>(),
                4.0,
                400.0,
            ),
        }];
        let dir = std::env::temp_dir().join(format!("trueaxis-diag-pg-{}", std::process::id()));
        let html = std::fs::read_to_string(write(&d, &data, &dir).unwrap()).unwrap();
        assert!(html.contains("1 % false-alarm level"), "level drawn");
        assert!(html.contains("50.0 mm grid comb"), "comb marked");
        assert!(html.contains("periods 50.0, 25.0, 16.7 mm"), "comb named");
        assert!(html.contains("period (mm), on a frequency scale"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A significant one-sensor thermal candidate on ex along x (bed).
    fn thermal_candidate() -> Candidate {
        Candidate {
            effect: Family::Thermal,
            target: "ex".into(),
            axis: Some("x".into()),
            channel: Some("T_bed_C".into()),
            params: BTreeMap::new(),
            add: "thermal:target=ex,channel=bed,times=x".into(),
            held_out_rms_um_after: Some(0.2),
            held_out_rms_um_before: Some(5.0),
            hold_out: trueaxis_engine::diagnose::HoldOutKind::Blocks,
            gain: Some(0.9),
            identifiable: true,
            evidence: String::new(),
            delta_bic: Some(-900.0),
            rms_um_after: Some(0.2),
            out_of_span_share: 1.0,
            significant: true,
            physical: Some(Physical {
                name: "cte".into(),
                unit: "µm/m/K".into(),
                value: 11.49,
                ci95: [11.3, 11.7],
                plausible: true,
                expected: String::new(),
            }),
            confounded_with: Vec::new(),
            replaces: None,
            step: Some(1),
            aliasing: None,
            held_back: false,
        }
    }

    /// Issue 13: thermal evidence is the slope. Steel growing 11.5 µm/m/K
    /// along x with the bed temperature (20 → 23 °C over 400 readings, x
    /// 0…800 mm, a ±0.2 µm residual): the figure shows the error per metre
    /// of x against the temperature with a least-squares slope of 11.5
    /// µm/m/K and the model's value beside it.
    #[test]
    fn thermal_evidence_is_the_slope_against_temperature() {
        let n = 400;
        let x: Vec<f64> = (0..n).map(|i| ((i * 37) % 401) as f64 * 2.0).collect();
        let t: Vec<f64> = (0..n).map(|i| 20.0 + 3.0 * i as f64 / n as f64).collect();
        let data = Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x.clone()), Some(vec![0.0; n]), Some(vec![0.0; n])],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            temps: vec![trueaxis_engine::data::TempChannel {
                name: "bed".into(),
                temp_c: t.clone(),
            }],
            ..Dataset::default()
        };
        let comp: Vec<f64> = (0..n).map(|i| 11.5e-3 * x[i] * (t[i] - 20.0)).collect();
        let after: Vec<f64> = (0..n)
            .map(|i| if i % 2 == 0 { 0.2 } else { -0.2 })
            .collect();
        let mut d = diagnosis(0.2, Some(0.2));
        d.candidates = vec![thermal_candidate()];
        let rows: Vec<usize> = (0..n).collect();
        let fig = thermal_slope(&data, &d.candidates[0], 1, &rows, &comp, &after)
            .unwrap()
            .expect("a slope figure");
        assert_eq!(fig.name, "thermal_slope_ex_1");
        assert!(
            fig.svg.contains("least squares: 11.5 µm/m/K"),
            "slope in the legend"
        );
        assert!(fig.svg.contains("ex per metre of x travel (µm/m)"));
        assert!(fig.svg.contains("bed temperature (°C)"));
        assert!(
            fig.caption
                .contains("the model's cte is 11.5 µm/m/K (95 %: 11.3 … 11.7)"),
            "{}",
            fig.caption
        );
        // Not for another family.
        let mut other = d.candidates[0].clone();
        other.effect = Family::Drift;
        assert!(thermal_slope(&data, &other, 1, &rows, &comp, &after)
            .unwrap()
            .is_none());
    }

    /// Issue 13: with a lag the slope is read against the lagged
    /// temperature. The bed warms 20 → 23 °C over 2 h and cools back; the
    /// growth follows it with a 1200 s first-order lag at 11.5 µm/m/K.
    /// Against the lagged temperature the points lie on one line of slope
    /// 11.5; against the raw reading (what the figure drew before) warm-up
    /// and cool-down are two branches whose least-squares slope is not the
    /// CTE.
    #[test]
    fn a_lagged_thermal_slope_is_read_against_the_lagged_temperature() {
        let n = 480;
        let t_s: Vec<f64> = (0..n).map(|i| i as f64 * 30.0).collect();
        let x: Vec<f64> = (0..n)
            .map(|i| 400.0 + ((i * 37) % 201) as f64 * 2.0)
            .collect();
        let temp: Vec<f64> = t_s
            .iter()
            .map(|&t| 20.0 + 3.0 * (std::f64::consts::PI * t / (n as f64 * 30.0)).sin())
            .collect();
        let tau = 1200.0;
        let lag = features::lagged(&temp, &t_s, None, tau);
        let data = Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x.clone()), Some(vec![0.0; n]), Some(vec![0.0; n])],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            temps: vec![trueaxis_engine::data::TempChannel {
                name: "bed".into(),
                temp_c: temp.clone(),
            }],
            t_s: Some(t_s.clone()),
            ..Dataset::default()
        };
        let comp: Vec<f64> = (0..n).map(|i| 11.5e-3 * x[i] * (lag[i] - 20.0)).collect();
        let after = vec![0.0; n];
        let mut c = thermal_candidate();
        c.params.insert("lag_s".into(), tau);
        let rows: Vec<usize> = (0..n).collect();
        let fig = thermal_slope(&data, &c, 1, &rows, &comp, &after)
            .unwrap()
            .expect("a slope figure");
        assert!(
            fig.svg.contains("least squares: 11.5 µm/m/K"),
            "the CTE, read against the lagged temperature"
        );
        assert!(fig.svg.contains("bed temperature lagged by 1200 s (°C)"));
        assert!(fig
            .caption
            .contains("drawn against that lagged temperature"));
        // Against the raw reading the same points give another slope: the
        // figure would not show the CTE.
        let raw: Vec<(f64, f64)> = (0..n)
            .map(|i| (temp[i], comp[i] / (x[i] / 1000.0)))
            .collect();
        let (raw_slope, _) = line_fit(&raw).unwrap();
        assert!((raw_slope - 11.5).abs() > 0.5, "raw slope {raw_slope}");
    }

    /// Issue 13: the first thing after the verdict card is where in the
    /// working volume the residual is large. A 5 × 5 × 5 grid with the
    /// residual at the noise except near x = y = 400 mm: the overview's
    /// maps come before the tables, ring the worst reading there and keep
    /// the scale at ≥ 3× the noise floor.
    #[test]
    fn the_overview_shows_where_in_the_volume_the_model_fails() {
        let (mut x, mut y, mut z) = (Vec::new(), Vec::new(), Vec::new());
        for iz in 0..5 {
            for iy in 0..5 {
                for ix in 0..5 {
                    x.push(100.0 * ix as f64);
                    y.push(100.0 * iy as f64);
                    z.push(100.0 * iz as f64);
                }
            }
        }
        let n = x.len();
        let after: Vec<f64> = (0..n)
            .map(|r| {
                if x[r] == 400.0 && y[r] == 400.0 {
                    if z[r] == 200.0 {
                        5.0
                    } else {
                        3.0
                    }
                } else if r % 2 == 0 {
                    0.2
                } else {
                    -0.2
                }
            })
            .collect();
        let data = Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x), Some(y), Some(z)],
            err_um: [Some(vec![Some(0.0); n]), None, None],
            ..Dataset::default()
        };
        let mut d = diagnosis(0.2, Some(0.2));
        let rows: Vec<usize> = (0..n).collect();
        d.evidence.resid_after = vec![(0, rows, after)];
        let mut page = Page::new("t");
        volume_overview(&mut page, &d, &data).unwrap();
        let html = page.to_html();
        for name in ["overview_ex_xy", "overview_ex_xz", "overview_ex_yz"] {
            assert!(html.contains(name), "{name}");
        }
        assert!(html.contains("ringed: the worst, 5.00 µm at (400, 400)"));
        let at = html.find("one colour scale").unwrap();
        assert!(
            html.contains("ex 0…3.49 µm, noise 0.200"),
            "scale: the worst cell, √((4·3² + 5²)/5): {}",
            &html[at..at + 300]
        );
        let dir = std::env::temp_dir().join(format!("trueaxis-diag-ov-{}", std::process::id()));
        let html = std::fs::read_to_string(write(&d, &data, &dir).unwrap()).unwrap();
        let (ov, tables) = (
            html.find("Where the model fails").unwrap(),
            html.find("<h2>Diagnosis").unwrap(),
        );
        assert!(ov < tables, "the overview comes first");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Issue 13: reversal as forward vs backward profiles — the mean per
    /// bin of each direction, their gap the backlash.
    #[test]
    fn forward_and_backward_profiles_show_the_gap() {
        let up: Vec<(f64, f64)> = (0..800)
            .map(|i| (i as f64, 4.0 + (i % 3) as f64 - 1.0))
            .collect();
        let down: Vec<(f64, f64)> = (0..800)
            .map(|i| (i as f64, -4.0 + (i % 3) as f64 - 1.0))
            .collect();
        let (pu, pd) = (
            binned_mean(&up, PROFILE_BINS),
            binned_mean(&down, PROFILE_BINS),
        );
        assert_eq!(pu.len(), PROFILE_BINS);
        for (u, d) in pu.iter().zip(&pd) {
            assert!((u.1 - d.1 - 8.0).abs() < 0.1, "{u:?} {d:?}");
            assert_eq!(u.0, d.0);
        }
        assert!(binned_mean(&[], 10).is_empty());
    }

    #[test]
    fn a_complete_grid_overview_has_no_empty_cell() {
        // 11 grid lines 0…500 every 50 mm: 11 cells on the lines, none
        // empty (12 even bins left one empty).
        let lines: Vec<f64> = (0..=10).map(|k| 50.0 * f64::from(k)).collect();
        assert_eq!(overview_centres(&lines, OVERVIEW_BINS), lines);
        // 17 lines and a dense line every 0.5 mm: even bins, none empty.
        let mut many: Vec<f64> = (0..=16).map(|k| 50.0 * f64::from(k)).collect();
        many.extend((0..1600).map(|k| 0.5 * f64::from(k)));
        many.sort_by(f64::total_cmp);
        many.dedup();
        let c = overview_centres(&many, OVERVIEW_BINS);
        assert!(c.len() <= OVERVIEW_BINS && c.len() >= 6, "{c:?}");
        let mut hit = vec![false; c.len()];
        for p in &many {
            hit[nearest_index(&c, *p)] = true;
        }
        assert!(hit.iter().all(|&h| h));
        assert_eq!(nearest_index(&[0.0, 10.0, 20.0], 14.0), 1);
        assert_eq!(nearest_index(&[0.0, 10.0, 20.0], 16.0), 2);
    }
}
