//! The page of a `rigid21` model (docs/volumetric.md), on `compare
//! --report DIR`: the card speaks in errors — the volumetric error before
//! and after, what these data cannot know and the measurement that would
//! tell — then per axis its six error functions over the travel with their
//! ±2σ bands (a `cannot_know` function gets a label, never a curve), and
//! the squarenesses and tilts as a table. The compare page's own sections
//! follow.
//!
//! The values come from the saved model and the identifiability answer
//! `fit` stored beside it (`stats.volumetric`): the page never evaluates an
//! error the fit could not determine.

use trueaxis_engine::compare::Comparison;
use trueaxis_engine::model::rigid21::{
    self, legendre, ErrorAnswer, ErrorKind, Identifiability, Rigid21Model, Status,
};

use crate::report::plot::{format_value, Band, Series, XyPlot, OTHER_COLOURS, TARGET_COLOURS};
use crate::report::{Figure, Page, Tone, Verdict};

/// Points a function is drawn at over its travel.
const SAMPLES: usize = 81;
/// Size of one function's plot (six per axis, two per row).
const FUNCTION_PLOT: (u32, u32) = (560, 300);

/// RMS and largest |e| over the translation readings (ex, ey, ez pooled),
/// before and after compensation; `None` without any.
fn volumetric(c: &Comparison) -> Option<([f64; 2], [f64; 2])> {
    let (mut n, mut sb, mut sa, mut mb, mut ma) = (0.0, 0.0, 0.0, 0.0f64, 0.0f64);
    for r in c.targets.values() {
        let k = r.after.points as f64;
        n += k;
        sb += k * r.before.rms_um.powi(2);
        sa += k * r.after.rms_um.powi(2);
        mb = mb.max(r.before.max_abs_um);
        ma = ma.max(r.after.max_abs_um);
    }
    (n > 0.0).then(|| ([(sb / n).sqrt(), mb], [(sa / n).sqrt(), ma]))
}

/// The card of a rigid21 comparison: the volumetric error before and
/// after, which errors these data cannot know (and how much that hides),
/// and the measurement that would tell. `next` is the compare card's
/// command.
pub fn verdict(c: &Comparison, id: Option<&Identifiability>, next: Option<String>) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    let mut details = Vec::new();
    let headline_left = match volumetric(c) {
        Some((before, after)) => format!(
            "The volumetric error falls from {} RMS (max {}) to {} RMS (max {}) at the measured tool points",
            um(before[0]),
            um(before[1]),
            um(after[0]),
            um(after[1])
        ),
        None => "No translation reading to compare at the tool points".into(),
    };
    for r in c.readings.iter().flatten() {
        details.push(format!(
            "{}: {} readings, residual RMS {} {}, max {} {}",
            r.reading,
            r.count,
            format_value(r.rms),
            r.unit,
            format_value(r.max_abs),
            r.unit
        ));
    }
    let Some(id) = id else {
        details.push(
            "The model file has no identifiability answer (written by an older trueaxis): fit again to see what these data cannot know."
                .into(),
        );
        return Verdict {
            headline: format!("{headline_left}."),
            details,
            warnings: warning_texts(c),
            next,
            tone: Tone::Unknown,
        };
    };
    let unknown: Vec<&ErrorAnswer> = id
        .errors
        .iter()
        .filter(|e| e.status == Status::CannotKnow)
        .collect();
    let headline = if unknown.is_empty() {
        format!("{headline_left}; these data determine every error of the model.")
    } else {
        format!(
            "{headline_left}; {} of {} errors cannot be known from these data — up to {} at the tool point unseen.",
            unknown.len(),
            id.errors.len(),
            um(id.hidden_um)
        )
    };
    if !unknown.is_empty() {
        details.insert(
            0,
            format!(
                "Cannot know: {} (at realistic sizes, 30 µrad for an angle, squareness or tilt and 10 µm for a translation, up to {} unseen, at tool length {} mm{}).",
                unknown
                    .iter()
                    .map(|e| e.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                um(id.hidden_um),
                format_value(id.hidden_at_tool_mm),
                if id.hidden_from.is_empty() {
                    String::new()
                } else {
                    format!(", mostly {}", id.hidden_from.join(", "))
                }
            ),
        );
        if let Some(m) = &id.measure {
            details.insert(
                1,
                format!(
                    "The measurement that would tell the most: {} (what stays unseen then: {}).",
                    m.what,
                    um(m.hidden_um_after)
                ),
            );
        }
    }
    Verdict {
        headline,
        details,
        warnings: warning_texts(c),
        next,
        // Unseen error is something left to do; a model that sees all is
        // still only as good as compare's residual (the compare card's
        // questions), so it is never green here.
        tone: if unknown.is_empty() {
            Tone::Unknown
        } else {
            Tone::Action
        },
    }
}

fn warning_texts(c: &Comparison) -> Vec<String> {
    c.warnings
        .iter()
        .map(|w| format!("{} ({})", w.detail, w.code))
        .collect()
}

/// What an error is called in words (`X yaw`, `Y straightness along Z`).
pub fn words(model: &Rigid21Model, name: &str) -> String {
    model
        .error(name)
        .map_or_else(|| name.into(), rigid21::words)
}

/// One function's plot: its value over the travel with the ±2σ band, or a
/// "cannot know" label and no curve.
fn function_figure(
    model: &Rigid21Model,
    id: Option<&Identifiability>,
    name: &str,
) -> anyhow::Result<Figure> {
    let e = model.error(name).expect("the layout's own name");
    let a = e.axis.unwrap_or(0);
    let [lo, hi] = model.travel_mm[a].unwrap_or([0.0, 1.0]);
    let unit = e.kind.unit();
    let title = format!("{name} — {}", words(model, name));
    let x_label = format!("{} (mm)", ["x", "y", "z"][a]);
    let y_label = format!("{name} ({unit})");
    let colour = if e.kind.is_angular() {
        OTHER_COLOURS[0]
    } else {
        TARGET_COLOURS[e.component]
    };
    let mut plot = XyPlot::new(title, x_label, y_label);
    plot.size = FUNCTION_PLOT;
    let caption;
    match &e.coef {
        Some(coef) => {
            let cov = id
                .and_then(|i| i.errors.iter().find(|x| x.name == name))
                .and_then(|x| x.coef_cov.as_ref());
            let mut curve = Vec::with_capacity(SAMPLES);
            let mut band = Vec::with_capacity(SAMPLES);
            let mut peak = 0.0f64;
            for i in 0..SAMPLES {
                let q = lo + (hi - lo) * i as f64 / (SAMPLES - 1) as f64;
                let p = legendre(model.degree, model.normalised(a, q));
                let pd: Vec<f64> = e.degrees.iter().map(|&d| p[d]).collect();
                let v: f64 = pd.iter().zip(coef).map(|(p, c)| p * c).sum();
                peak = peak.max(v.abs());
                curve.push((q, v));
                if let Some(c) = cov {
                    let var: f64 = (0..pd.len())
                        .flat_map(|i| (0..pd.len()).map(move |j| (i, j)))
                        .map(|(i, j)| {
                            pd[i] * pd[j] * c.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
                        })
                        .sum();
                    let s = var.max(0.0).sqrt();
                    band.push((q, v - 2.0 * s, v + 2.0 * s));
                }
            }
            plot = plot.with(Series::line(format!("{name} fitted"), curve).coloured(colour));
            caption = if band.is_empty() {
                format!(
                    "{name}: up to {} {unit} over the travel; no band (the model file holds no covariance: fit again).",
                    format_value(peak)
                )
            } else {
                plot = plot.with_band(Band {
                    name: "±2σ".into(),
                    points: band,
                });
                format!(
                    "{name}: up to {} {unit} over the travel, shaded ±2σ.",
                    format_value(peak)
                )
            };
        }
        None => {
            plot = plot
                .with_y_range(-1.0, 1.0)
                .with_note(lo + 0.25 * (hi - lo), 0.0, "cannot know from these data")
                // Unlabelled notes at the travel's ends: the axis spans the
                // travel though nothing is drawn on it.
                .with_note(lo, 0.0, "")
                .with_note(hi, 0.0, "");
            let hidden = id
                .and_then(|i| i.errors.iter().find(|x| x.name == name))
                .and_then(|x| x.hidden_um);
            caption = match hidden {
                // Tool on the spindle axis: ECY and ECZ have no arm.
                Some(h) if h < 0.05 => format!(
                    "{name}: cannot know from these data (no value); it has no arm at the measured tool points (no lateral offset), so it moves none of them — a tool off the spindle axis would feel it."
                ),
                // Its own effect, not what stays unseen: part of it the data
                // see mixed with the other errors (the card's figure is the
                // unseen part of them all, which can be smaller).
                Some(h) => format!(
                    "{name}: cannot know from these data (no value); at a realistic size it alone would move the tool point by up to {} µm — the data see part of that only mixed with other errors (what stays unseen of all of them: the card).",
                    format_value(h)
                ),
                None => format!("{name}: cannot know from these data (no value)."),
            };
        }
    }
    Figure::plot(format!("fn_{}", name.to_lowercase()), caption, &plot)
}

/// Adds the model's errors to `page`: per axis its six functions, then the
/// squarenesses and tilts with ±.
pub fn build_section(
    page: &mut Page,
    model: &Rigid21Model,
    id: Option<&Identifiability>,
) -> anyhow::Result<()> {
    page.heading("The error functions of each axis (ISO 230-1)");
    page.paragraph(
        "Each axis' positioning, two straightnesses, roll, pitch and yaw over its measured travel, in the ISO 230-1 gauge (positioning and angles without a mean, straightness without its line: that slope is squareness). Translations in µm in their component's colour, angles in µrad in black; the shaded band is ±2σ of the fitted function. An error these data cannot determine is labelled and drawn without a curve.",
    );
    for a in model.chain.axes() {
        page.subheading(format!("{} axis", ["X", "Y", "Z"][a]));
        let figs = model
            .errors()
            .filter(|e| {
                e.axis == Some(a)
                    && matches!(
                        e.kind,
                        ErrorKind::Positioning | ErrorKind::Straightness | ErrorKind::Angle
                    )
            })
            .map(|e| function_figure(model, id, &e.name))
            .collect::<anyhow::Result<Vec<_>>>()?;
        page.grid_wide(figs);
    }
    let constants: Vec<Vec<String>> = model
        .errors()
        .filter(|e| matches!(e.kind, ErrorKind::Squareness | ErrorKind::Tilt))
        .map(|e| {
            let ans = id.and_then(|i| i.errors.iter().find(|x| x.name == e.name));
            let value = match (&e.coef, ans.and_then(|x| x.sigma)) {
                (Some(c), Some(s)) => format!(
                    "{} ± {}",
                    format_value(c.first().copied().unwrap_or(0.0)),
                    format_value(s)
                ),
                (Some(c), None) => format_value(c.first().copied().unwrap_or(0.0)),
                (None, _) => match ans.and_then(|x| x.hidden_um) {
                    Some(h) => format!(
                        "cannot know (alone up to {} µm at the tool point)",
                        format_value(h)
                    ),
                    None => "cannot know".into(),
                },
            };
            vec![e.name.clone(), words(model, &e.name), value]
        })
        .collect();
    if !constants.is_empty() {
        page.heading("Squarenesses and tilts");
        page.table(&["error", "what", "value (µrad, ± 1σ)"], constants);
    }
    Ok(())
}
