//! The `iso230 --report DIR` page and plot: a verdict card (accuracy A,
//! what compensation can remove — the systematic E, the reversal B — and
//! what it cannot, the repeatability R; the next command), then x̄↑ and x̄↓
//! against the target position with their ±2s bands, as SVG, and the
//! per-target table.

use std::path::{Path, PathBuf};

use anyhow::Result;

use trueaxis_engine::data::{Dataset, AXES};
use trueaxis_engine::iso230::{max, min, Iso230, TargetStats};

use crate::report::plot::format_value;
use crate::report::{Page, Tone, Verdict};

/// ISO 230-2's runs per direction (5); fewer gives a wide ±2s.
const ISO_RUNS: usize = 5;

/// The page's verdict: A, and how it splits into what a model removes (E,
/// with B) and what it cannot (R); the `fit` command to run next.
pub fn verdict(res: &Iso230, data_path: &str) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    let ax = &res.axis;
    // The unidirectional repeatability is the floor: the bidirectional R
    // includes the reversal, which compensation does remove.
    let r_uni = res.r_up_um.max(res.r_down_um);
    let big_reversal = res.b_um.abs() >= 0.3 * res.e_um && res.b_um.abs() > 0.5 * r_uni;
    let mut details = vec![
        format!(
            "Systematic deviation E = {} (the mean paths of both directions): a fitted model removes it.",
            um(res.e_um)
        ),
        format!(
            "Reversal B = {} (mean {}): {}",
            um(res.b_um),
            um(res.b_mean_um),
            if big_reversal {
                "a large share of E — the model needs a reversal (backlash) term."
            } else {
                "small against E."
            }
        ),
        format!(
            "Repeatability in one direction R↑ = {}, R↓ = {}: the scatter from run to run; no compensation lowers it — after compensation A cannot fall much below it. (The bidirectional R = {} includes the reversal.)",
            um(res.r_up_um),
            um(res.r_down_um),
            um(res.r_um)
        ),
    ];
    details.push(format!(
        "{} targets, {} run(s) per direction.",
        res.targets, res.runs
    ));
    let mut warnings = if res.runs < ISO_RUNS {
        vec![format!(
            "{} run(s) per direction, ISO 230-2 asks for {ISO_RUNS}: s and the ±2s bands are uncertain",
            res.runs
        )]
    } else {
        Vec::new()
    };
    // A reading far outside the others (a beam break, a misread) sets A
    // and R by itself: the figures keep it, as the standard says, but the
    // card says so and is not green (issue 24).
    for f in &res.flags {
        warnings.push(format!(
            "flagged reading: {} — check it (a broken beam, a misread) and re-measure that run",
            f.text(res)
        ));
    }
    let removable = res.e_um > 1.5 * r_uni;
    let next = fit_command(res, data_path, big_reversal);
    Verdict {
        headline: format!(
            "Axis {ax}: accuracy A = {}; compensation can remove most of the systematic E = {}{}, not the repeatability (one direction, up to {}).",
            um(res.a_um),
            um(res.e_um),
            if big_reversal {
                format!(" (reversal B = {})", um(res.b_um))
            } else {
                String::new()
            },
            um(r_uni)
        ),
        details: std::mem::take(&mut details),
        warnings,
        next: Some(next),
        tone: if !res.flags.is_empty() {
            Tone::Unknown
        } else if removable {
            Tone::Action
        } else {
            Tone::Good
        },
    }
}

/// The command that fits a model to the run, as it runs when pasted where
/// `iso230` ran: an ecmc `.dat` (which does not name its axis) imported
/// first with `--axis`; the cubic seed when the run has the 4 targets a
/// cubic along one axis needs, else a grid model on the targets' spacing
/// (a 3-target run cannot fit 4 terms); a reversal term when B is large.
pub fn fit_command(res: &Iso230, data_path: &str, reversal: bool) -> String {
    let ax = &res.axis;
    let data = crate::report::diagnose::shell_word(data_path);
    let (mut cmd, input) = if data_path.to_ascii_lowercase().ends_with(".dat") {
        (
            format!("trueaxis import {data} --axis {ax} -o run.csv && "),
            "run.csv".to_string(),
        )
    } else {
        (String::new(), data)
    };
    let mut pos: Vec<f64> = res.per_target.iter().map(|t| t.pos_mm).collect();
    pos.sort_by(f64::total_cmp);
    let step = pos
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 1e-9)
        .fold(f64::INFINITY, f64::min);
    let model = if pos.len() >= 4 || !step.is_finite() {
        "cubic19".to_string()
    } else {
        format!("grid:{}", trueaxis_engine::lines::plot_num(step))
    };
    cmd.push_str(&format!("trueaxis fit {input} --model {model}"));
    if reversal {
        cmd.push_str(&format!(" --add 'reversal:target=e{ax},axis={ax}'"));
    }
    cmd.push_str(" -o model.json");
    cmd
}

/// One reading of the run: where, what, from which side, in which run, and
/// why it is flagged (None: not flagged — the hook for the engine's
/// reading checks: a flagged reading is ringed in red and named).
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    pub pos_mm: f64,
    pub err_um: f64,
    /// +1 approached from below, −1 from above.
    pub dir: i8,
    /// The run (`pass_id`), when the file tells.
    pub run: Option<i64>,
    pub flag: Option<String>,
}

/// [`readings`] with the engine's flags (`Iso230::flags`) set: a flagged
/// reading is ringed and named on the page.
pub fn flagged_readings(data: &Dataset, axis: usize, res: &Iso230) -> Vec<Reading> {
    let rows: Vec<usize> = match data.err_um[axis].as_ref() {
        Some(err) => (0..data.len()).filter(|&r| err[r].is_some()).collect(),
        None => Vec::new(),
    };
    let mut reads = readings(data, axis);
    for (read, r) in reads.iter_mut().zip(rows) {
        read.flag = res.flags.iter().find(|f| f.row == r).map(|f| {
            format!(
                "far outside the other readings there (their mean {:+.3} µm); without it A = {:.3} µm, R = {:.3} µm",
                f.others_mean_um, f.a_without_um, f.r_without_um
            )
        });
    }
    reads
}

/// Every reading of `axis`'s error along `axis` with its direction and run.
pub fn readings(data: &Dataset, axis: usize) -> Vec<Reading> {
    let Some((pos, err, dir)) = trueaxis_engine::iso230::readings_of(data, axis) else {
        return Vec::new();
    };
    (0..data.len())
        .filter_map(|r| {
            Some(Reading {
                pos_mm: pos[r],
                err_um: err[r]?,
                dir: dir[r],
                run: data.pass_id.as_ref().map(|p| p[r]),
                flag: None,
            })
        })
        .collect()
}

/// The test conditions a file's metadata gives (an `.rtl`'s machine,
/// serial number, date, operator, air and material temperature, laser;
/// an ecmc file's header), as (what, value) rows; the file format line
/// is left out (the title says the file).
pub fn conditions(data: &Dataset) -> Vec<Vec<String>> {
    data.metadata
        .iter()
        .filter(|(k, _)| !matches!(k.as_str(), "format" | "axis" | "Software"))
        .map(|(k, v)| {
            let what = match k.as_str() {
                "By" => "operator (By)".to_string(),
                k => k
                    .strip_prefix("environment ")
                    .or_else(|| k.strip_prefix("equipment "))
                    .unwrap_or(k)
                    .to_string(),
            };
            vec![what, v.clone()]
        })
        .collect()
}

/// Writes `DIR/index.html` (verdict, the file's test conditions, the plot
/// of every run's readings beside the means, the per-target table) and
/// `DIR/iso230_<axis>.svg`; returns the page's path.
pub fn write_page(res: &Iso230, data: &Dataset, data_path: &str, dir: &Path) -> Result<PathBuf> {
    let mut page = Page::new(format!(
        "trueaxis iso230 — axis {} of {data_path}",
        res.axis
    ));
    page.verdict(verdict(res, data_path));
    let axis = AXES.iter().position(|a| *a == res.axis).unwrap_or(0);
    let conds = conditions(data);
    if !conds.is_empty() {
        page.heading("Test conditions (from the file)");
        page.table(&["what", "value"], conds);
    }
    let reads = flagged_readings(data, axis, res);
    page.heading("Every run beside the means");
    page.plot(
        format!("iso230_{}", res.axis),
        format!(
            "Each run's readings (thin lines and open dots: {} readings in {} run(s) per direction) beside x̄↑ and x̄↓ (the mean deviation approaching from below and from above) with their ±2s bands: a reading far from its run's neighbours stands out.",
            reads.len(),
            res.runs
        ),
        &IsoPlot {
            res,
            readings: &reads,
        },
    )?;
    let flagged: Vec<Vec<String>> = reads
        .iter()
        .filter_map(|r| {
            r.flag.as_ref().map(|f| {
                vec![
                    format!("{:.3}", r.pos_mm),
                    if r.dir > 0 { "↑" } else { "↓" }.to_string(),
                    r.run.map_or("—".into(), |k| k.to_string()),
                    format!("{:.3}", r.err_um),
                    f.clone(),
                ]
            })
        })
        .collect();
    if !flagged.is_empty() {
        page.heading("Flagged readings");
        page.table(
            &["target (mm)", "dir", "run", "deviation (µm)", "why"],
            flagged,
        );
    }
    let f = |v: f64| format!("{v:.3}");
    let rows = res
        .per_target
        .iter()
        .map(|t| {
            vec![
                f(t.pos_mm),
                t.n_up.to_string(),
                t.n_down.to_string(),
                f(t.mean_up_um),
                f(t.mean_down_um),
                f(t.s_up_um),
                f(t.s_down_um),
                f(t.b_um),
                f(t.r_um),
            ]
        })
        .collect();
    page.table(
        &[
            "target (mm)",
            "n↑",
            "n↓",
            "x̄↑ (µm)",
            "x̄↓ (µm)",
            "s↑ (µm)",
            "s↓ (µm)",
            "B (µm)",
            "R (µm)",
        ],
        rows,
    );
    page.write(dir)
}

/// Writes an SVG plot of x̄↑ and x̄↓ against position with the ±2s
/// bands to `path`. Text is plain SVG `<text>` (plotters without a font
/// library), so the file renders in any browser with no network.
pub fn plot_svg(res: &Iso230, path: &Path) -> Result<()> {
    trueaxis_engine::files::write(path, svg(res)?.as_bytes())
}

/// The plot of [`plot_svg`] as an SVG document (the means and bands only).
pub fn svg(res: &Iso230) -> Result<String> {
    svg_with(res, &[])
}

/// The means with their ±2s bands and every run's readings: each run a
/// thin line with open dots in its direction's colour (the readings
/// approached from below a little left of the target, from above a little
/// right, so they do not hide each other), a flagged reading ringed red;
/// the legend in a strip of its own right of the plot, never on the data.
pub fn svg_with(res: &Iso230, readings: &[Reading]) -> Result<String> {
    svg_sized(res, readings, (900, 520))
}

/// The ISO plot as a [`Drawing`](crate::report::plot::Drawing): 900 px
/// wide, and for a phone [`PHONE_WIDTH`](crate::report::plot::PHONE_WIDTH)
/// wide with the legend under it.
#[derive(Debug)]
pub struct IsoPlot<'a> {
    /// The figures.
    pub res: &'a Iso230,
    /// Every run's readings.
    pub readings: &'a [Reading],
}

impl crate::report::plot::Drawing for IsoPlot<'_> {
    fn svg(&self) -> Result<String> {
        svg_with(self.res, self.readings)
    }
    fn phone_svg(&self) -> Result<Option<String>> {
        svg_sized(
            self.res,
            self.readings,
            (crate::report::plot::PHONE_WIDTH, 420),
        )
        .map(Some)
    }
}

/// [`svg_with`] at `size` (the plot; a legend under a narrow plot adds to
/// its height).
fn svg_sized(res: &Iso230, readings: &[Reading], size: (u32, u32)) -> Result<String> {
    use crate::report::plot::{
        darker, legend_below_height, legend_strip, LegendMark, DIRECTION_COLOURS, LEGEND_BELOW,
    };
    use plotters::prelude::*;
    let t = &res.per_target;
    let lo = min(t
        .iter()
        .map(|s| (s.mean_up_um - 2.0 * s.s_up_um).min(s.mean_down_um - 2.0 * s.s_down_um))
        .chain(readings.iter().map(|r| r.err_um)));
    let hi = max(t
        .iter()
        .map(|s| (s.mean_up_um + 2.0 * s.s_up_um).max(s.mean_down_um + 2.0 * s.s_down_um))
        .chain(readings.iter().map(|r| r.err_um)));
    let pad = ((hi - lo) * 0.1).max(0.05);
    let (x0, x1) = (t[0].pos_mm, t[t.len() - 1].pos_mm);
    let xpad = ((x1 - x0) * 0.03).max(1.0);
    let up = darker(DIRECTION_COLOURS[0], 0.2);
    let down = darker(DIRECTION_COLOURS[1], 0.3);
    let mut entries = vec![
        ("x̄↑ ± 2s (from below)".to_string(), up, LegendMark::LineDot),
        (
            "x̄↓ ± 2s (from above)".to_string(),
            down,
            LegendMark::LineDot,
        ),
    ];
    if !readings.is_empty() {
        entries.push((
            "runs ↑ (readings)".into(),
            DIRECTION_COLOURS[0],
            LegendMark::Dot,
        ));
        entries.push((
            "runs ↓ (readings)".into(),
            DIRECTION_COLOURS[1],
            LegendMark::Dot,
        ));
    }
    if readings.iter().any(|r| r.flag.is_some()) {
        entries.push((
            "flagged reading".into(),
            RGBColor(200, 0, 0),
            LegendMark::Dot,
        ));
    }
    let mut buf = String::new();
    let below = legend_below_height(&entries, size.0);
    let narrow = size.0 < LEGEND_BELOW;
    let whole = SVGBackend::with_string(&mut buf, (size.0, size.1 + below)).into_drawing_area();
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        whole.fill(&WHITE)?;
        let root = legend_strip(&whole, &entries, size).map_err(|e| e.to_string())?;
        // Left and right of the target by 0.6 % of the travel.
        let dx = 0.006 * (x1 - x0).abs().max(1.0);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                if narrow {
                    format!(
                        "axis {}: A {:.2}, E {:.2}, R {:.2}, B {:.2} µm",
                        res.axis, res.a_um, res.e_um, res.r_um, res.b_um
                    )
                } else {
                    format!(
                        "ISO 230-2 axis {}: A = {:.2} µm, E = {:.2} µm, R = {:.2} µm, B = {:.2} µm",
                        res.axis, res.a_um, res.e_um, res.r_um, res.b_um
                    )
                },
                ("sans-serif", if narrow { 14 } else { 18 }),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((x0 - xpad)..(x1 + xpad), (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc(format!("target position along {} (mm)", res.axis))
            .y_desc("deviation (µm)")
            .draw()?;
        // Every run: its readings in order of position, per direction.
        let mut runs: Vec<(i8, Option<i64>)> = readings.iter().map(|r| (r.dir, r.run)).collect();
        runs.sort_unstable();
        runs.dedup();
        for (d, run) in runs {
            let colour = if d > 0 {
                DIRECTION_COLOURS[0]
            } else {
                DIRECTION_COLOURS[1]
            };
            let shift = if d > 0 { -dx } else { dx };
            let mut pts: Vec<(f64, f64)> = readings
                .iter()
                .filter(|r| r.dir == d && r.run == run)
                .map(|r| (r.pos_mm + shift, r.err_um))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            if run.is_some() {
                chart.draw_series(LineSeries::new(
                    pts.clone(),
                    colour.mix(0.45).stroke_width(1),
                ))?;
            }
            chart.draw_series(
                pts.iter()
                    .map(|p| Circle::new(*p, 3, colour.stroke_width(1))),
            )?;
        }
        for (color, f) in [
            (
                up,
                (|s: &TargetStats| (s.mean_up_um, s.s_up_um)) as fn(&TargetStats) -> (f64, f64),
            ),
            (down, |s: &TargetStats| (s.mean_down_um, s.s_down_um)),
        ] {
            let band: Vec<(f64, f64)> = t
                .iter()
                .map(|s| (s.pos_mm, f(s).0 + 2.0 * f(s).1))
                .chain(t.iter().rev().map(|s| (s.pos_mm, f(s).0 - 2.0 * f(s).1)))
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(
                band,
                color.mix(0.15).filled(),
            )))?;
            chart.draw_series(LineSeries::new(
                t.iter().map(|s| (s.pos_mm, f(s).0)),
                color.stroke_width(2),
            ))?;
            chart.draw_series(
                t.iter()
                    .map(|s| Circle::new((s.pos_mm, f(s).0), 3, color.filled())),
            )?;
        }
        let red = RGBColor(200, 0, 0);
        chart.draw_series(readings.iter().filter(|r| r.flag.is_some()).map(|r| {
            let shift = if r.dir > 0 { -dx } else { dx };
            Circle::new((r.pos_mm + shift, r.err_um), 7, red.stroke_width(2))
        }))?;
        whole.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing the ISO 230-2 plot: {e}"))?;
    drop(whole);
    // Scales to the window like every report figure (viewBox, no width).
    Ok(crate::report::plot::responsive(buf))
}
