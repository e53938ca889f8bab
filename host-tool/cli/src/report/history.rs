//! The `history --report DIR` page: a verdict card (how far the error fell
//! and whether anything is left), the table of steps and the plot of the
//! error falling — RMS and held-out RMS per target against the fit step,
//! each step labelled with the effect it added, the noise floor per target
//! as a dashed line when known; also drawn on `diagnose --report` for a
//! model that has a history.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Result;

use trueaxis_engine::diagnose::ABOVE_NOISE_RATIO;
use trueaxis_engine::effect::EffectSpec;
use trueaxis_engine::history::{History, Step};

use crate::report::plot::{self, format_value, Series, Style, Ticks, XyPlot};
use crate::report::{Page, Tone, Verdict};
use plotters::style::RGBColor;

/// A step's label on the plot: the seed for the first fit, else what it
/// added, short (`+ periodic ex x 5.00011`), several joined by `, `.
pub fn step_label(s: &Step) -> String {
    if s.added.is_empty() {
        return s.seed.clone();
    }
    let short: Vec<String> = s
        .added
        .iter()
        .map(|a| {
            let (family, rest) = a.split_once(':').unwrap_or((a.as_str(), ""));
            let mut parts = vec![family.replace('_', " ")];
            for kv in rest.split(',') {
                if let Some((k, v)) = kv.split_once('=') {
                    if matches!(k, "target" | "axis" | "channel" | "times") {
                        parts.push(v.to_string());
                    }
                }
            }
            parts.join(" ")
        })
        .collect();
    format!("+ {}", short.join(", "))
}

/// The value of `key` in an effect spec (`periodic:target=ex,axis=x,…`).
fn spec_value<'a>(add: &'a str, key: &str) -> Option<&'a str> {
    add.split_once(':')?
        .1
        .split(',')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

/// An added effect in words, from its spec: "a periodic error of ex along
/// x (lead screw or scale pitch), period 5 mm", "thermal growth of ex with
/// the bed temperature, growing along x, lag 600 s".
pub fn effect_words(add: &str) -> String {
    let Ok(spec) = add.parse::<EffectSpec>() else {
        return add.to_string();
    };
    let mut w = spec.describe();
    if let Some(p) = spec.period_mm() {
        w.push_str(&format!(", period {} mm", format_value(p)));
    }
    if let Some(l) = spec
        .param("lag_s")
        .filter(|l| l.parse::<f64>().is_ok_and(|v| v > 0.0))
    {
        w.push_str(&format!(", lag {l} s"));
    }
    w
}

/// What step `b` did after step `a`, one line per effect it added (a step
/// of `improve` may add one per target): the effect in words and how its
/// target's RMS changed — "Step 3 (2 of 2): + thermal growth of ey … — ey
/// 3.20 µm → 0.200 µm."; a step that added nothing (a refit) says so.
pub fn step_explained(a: &Step, b: &Step) -> Vec<String> {
    let um = |v: f64| format!("{} µm", format_value(v));
    let change = |t: &str| match (a.rms_um.get(t), b.rms_um.get(t)) {
        (Some(p), Some(r)) if (p - r).abs() > 0.005 * p.abs().max(1e-9) => {
            format!("{t} {} → {}", um(*p), um(*r))
        }
        (Some(_), Some(r)) => format!("{t} unchanged at {}", um(*r)),
        _ => format!("{t} not in both fits"),
    };
    if b.added.is_empty() {
        let changes: Vec<String> = b.rms_um.keys().map(|t| change(t)).collect();
        return vec![format!(
            "Step {}: {} refitted, nothing added — {}.",
            b.step,
            b.seed,
            changes.join(", ")
        )];
    }
    let n = b.added.len();
    b.added
        .iter()
        .enumerate()
        .map(|(j, add)| {
            let of = if n > 1 {
                format!(" ({} of {n})", j + 1)
            } else {
                String::new()
            };
            let target = spec_value(add, "target");
            let shared = n > 1
                && b.added
                    .iter()
                    .filter(|o| spec_value(o, "target") == target)
                    .count()
                    > 1;
            format!(
                "Step {}{of}: + {} — {}{}.",
                b.step,
                effect_words(add),
                target.map_or("its target".into(), change),
                if shared {
                    " (together with the other effect(s) of this step on it)"
                } else {
                    ""
                }
            )
        })
        .collect()
}

/// The plot of RMS and held-out RMS per target against the step: whole
/// steps, a marker per fit (one fit is a point), each step labelled with
/// what it added, and `noise_um` per target as a dashed line in the
/// target's colour.
pub fn plot(h: &History, noise_um: &BTreeMap<String, f64>) -> XyPlot {
    let mut p = XyPlot::new(
        "The error falling, fit by fit",
        "fit step",
        "residual RMS (µm)",
    )
    .with_x_ticks(Ticks::Integer);
    let targets: Vec<&String> = h
        .steps
        .iter()
        .flat_map(|s| s.rms_um.keys())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    // Each target in its colour on every page (plot::target_of by the
    // series' name): in-sample solid, held-out dashed with hollow dots, the
    // noise floor a paler dashed line.
    for t in &targets {
        let rms: Vec<(f64, f64)> = h
            .steps
            .iter()
            .filter_map(|s| s.rms_um.get(*t).map(|v| (s.step as f64, *v)))
            .collect();
        p = p.with(Series::styled(format!("{t} RMS"), rms, Style::LinePoints));
    }
    for t in &targets {
        let held: Vec<(f64, f64)> = h
            .steps
            .iter()
            .filter_map(|s| s.held_out_rms_um.get(*t).map(|v| (s.step as f64, *v)))
            .collect();
        if !held.is_empty() {
            p = p.with(Series::styled(
                format!("{t} held-out RMS"),
                held,
                Style::DashedPoints,
            ));
        }
    }
    for t in &targets {
        if let Some(nf) = noise_um.get(*t).filter(|v| v.is_finite()) {
            let colour = plot::target_of(t).map_or(RGBColor(120, 120, 120), |i| {
                plot::lighter(plot::target_colour(i), 0.45)
            });
            p = p.with_dashed(
                *nf,
                format!("{t} noise floor {} µm", format_value(*nf)),
                colour,
            );
        }
    }
    let values: Vec<f64> = h
        .steps
        .iter()
        .flat_map(|s| s.rms_um.values().chain(s.held_out_rms_um.values()))
        .chain(noise_um.values())
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let top = values.iter().copied().fold(0.0f64, f64::max);
    let log = log_scale_fits(&values);
    if log {
        p = p.with_log_y();
    }
    for (k, s) in h.steps.iter().enumerate() {
        // Alternate two heights so neighbouring labels do not overlap (on
        // a log axis a height is a factor: the same gaps on the page).
        let y = match (log, k % 2 == 0) {
            (false, true) => top * 1.14,
            (false, false) => top * 1.06,
            (true, true) => top * 1.9,
            (true, false) => top * 1.4,
        };
        p = p.with_note(s.step as f64, y, step_label(s));
    }
    p
}

/// Whether the history plot's µm axis is logarithmic: when the values span
/// more than a decade (an error falling from 20 µm to the 0.2 µm noise
/// would leave every step after the first flat on the floor of a linear
/// axis); a linear axis otherwise, where differences read directly.
pub fn log_scale_fits(values: &[f64]) -> bool {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0f64, f64::max);
    lo > 0.0 && hi / lo > 10.0
}

/// Writes `DIR/index.html` with the verdict, the table and the plot;
/// `noise_um` is the noise floor per target when it is known (the demo's
/// loop measures it; a history file alone does not hold it).
pub fn write_report(
    h: &History,
    name: &str,
    data: &str,
    dir: &std::path::Path,
    noise_um: &BTreeMap<String, f64>,
) -> Result<PathBuf> {
    let mut page = Page::new(format!("trueaxis history — {name}"));
    page.verdict(verdict(h, name, data, noise_um));
    page.heading("History");
    page.colour_key();
    add_to_page(&mut page, h, noise_um)?;
    page.write(dir)
}

/// The history page's verdict: how far the error fell over the fits, what
/// each step bought, whether the last fit is at the noise floor (when it is
/// known), and the next command (`data`: the data file the model was
/// fitted to, for it).
pub fn verdict(h: &History, model: &str, data: &str, noise_um: &BTreeMap<String, f64>) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
    // One shell word each: the command runs as pasted.
    let (model, data) = (
        &crate::report::diagnose::shell_word(model),
        &crate::report::diagnose::shell_word(data),
    );
    let (Some(first), Some(last)) = (h.steps.first(), h.steps.last()) else {
        return Verdict {
            headline: "The history is empty: no fit was recorded.".into(),
            details: Vec::new(),
            warnings: Vec::new(),
            next: Some(format!("trueaxis fit {data} --model cubic19 -o {model}")),
            tone: Tone::Unknown,
        };
    };
    // The target that started worst tells the story.
    let worst = first
        .rms_um
        .iter()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(t, _)| t.clone())
        .unwrap_or_default();
    let headline = if h.steps.len() == 1 {
        format!(
            "One fit so far ({}): {}.",
            first.seed,
            first
                .rms_um
                .iter()
                .map(|(t, r)| format!("{t} {} RMS", um(*r)))
                .collect::<Vec<_>>()
                .join(", ")
        )
    } else {
        format!(
            "Over {} fits the residual of {} fell from {} to {} RMS{}.",
            h.steps.len(),
            worst,
            um(first.rms_um.get(&worst).copied().unwrap_or(f64::NAN)),
            um(last.rms_um.get(&worst).copied().unwrap_or(f64::NAN)),
            last.held_out_rms_um
                .get(&worst)
                .map_or(String::new(), |v| format!(" (held out: {})", um(*v)))
        )
    };
    let mut details = Vec::new();
    for w in h.steps.windows(2) {
        details.extend(step_explained(&w[0], &w[1]));
    }
    let mut left = Vec::new();
    let mut known = 0;
    for (t, r) in &last.rms_um {
        if let Some(nf) = noise_um.get(t).filter(|v| **v > 0.0) {
            known += 1;
            if *r > ABOVE_NOISE_RATIO * nf {
                left.push(format!(
                    "{t} at {:.1}× its noise floor ({} against {})",
                    r / nf,
                    um(*r),
                    um(*nf)
                ));
            }
        }
    }
    let (tone, next) = if known == 0 {
        details.push(
            "The history does not hold the noise floor: diagnose says whether anything is left above it."
                .into(),
        );
        (
            Tone::Unknown,
            format!("trueaxis diagnose {data} --model {model} --report report/diagnose"),
        )
    } else if left.is_empty() {
        details.push(format!(
            "The last fit is at the noise floor: {}.",
            last.rms_um
                .iter()
                .map(|(t, r)| format!(
                    "{t} {} (noise {})",
                    um(*r),
                    noise_um.get(t).map_or("unknown".into(), |v| um(*v))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        (Tone::Good, format!("trueaxis export {model} -o table.bin"))
    } else {
        details.push(format!("Left above the noise: {}.", left.join("; ")));
        (
            Tone::Action,
            format!("trueaxis diagnose {data} --model {model} --report report/diagnose"),
        )
    };
    Verdict {
        headline,
        details,
        warnings: Vec::new(),
        next: Some(next),
        tone,
    }
}

/// The history's table (one row per step and target) and the plot of the
/// error falling (`history.svg`) on `page`: this command's report, and
/// `diagnose --report` on a model that has a history.
pub fn add_to_page(page: &mut Page, h: &History, noise_um: &BTreeMap<String, f64>) -> Result<()> {
    let plot = plot(h, noise_um);
    page.plot(
        "history",
        format!(
            "Residual RMS (in-sample) and block-held-out RMS per target after each fit; each step is labelled with the effect it added; dashed: the noise floor of the measurement, where known.{}",
            if plot.log_y {
                " The µm axis is logarithmic (the values span more than a decade): equal heights are equal factors."
            } else {
                ""
            }
        ),
        &plot,
    )?;
    let rows = h
        .steps
        .iter()
        .flat_map(|s| {
            s.rms_um.iter().map(move |(t, r)| {
                vec![
                    s.step.to_string(),
                    t.clone(),
                    format!("{r:.4}"),
                    s.held_out_rms_um
                        .get(t)
                        .map_or("—".into(), |v| format!("{v:.4}")),
                    if s.added.is_empty() {
                        s.spec()
                    } else {
                        format!("+ {}", s.added.join(" + "))
                    },
                ]
            })
        })
        .collect();
    page.table(
        &["step", "target", "rms µm", "held-out rms µm", "added"],
        rows,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use trueaxis_engine::history::HISTORY_FORMAT;

    fn step(k: usize, added: &[&str], ex: f64, held: f64) -> Step {
        Step {
            step: k,
            seed: "cubic19".into(),
            adds: added.iter().map(|s| s.to_string()).collect(),
            added: added.iter().map(|s| s.to_string()).collect(),
            terms: 19,
            rms_um: [("ex".to_string(), ex), ("ey".to_string(), 0.2)].into(),
            held_out_rms_um: [("ex".to_string(), held), ("ey".to_string(), 0.21)].into(),
            data_sha256: "h".into(),
        }
    }

    fn history(steps: Vec<Step>) -> History {
        History {
            format: HISTORY_FORMAT.into(),
            steps,
        }
    }

    #[test]
    fn each_step_is_labelled_and_the_noise_floor_is_drawn() {
        let h = history(vec![
            step(1, &[], 2.0, 2.05),
            step(2, &["periodic:target=ex,axis=x,period_mm=5"], 1.0, 1.05),
            step(
                3,
                &["thermal:target=ex,channel=bed,times=x,offset=1"],
                0.2,
                0.21,
            ),
        ]);
        let noise: BTreeMap<String, f64> = [("ex".to_string(), 0.2)].into();
        let svg = plot(&h, &noise).to_svg().unwrap();
        for label in [
            "cubic19",
            "+ periodic ex x",
            "+ thermal ex bed x",
            "ex noise floor 0.200 µm",
            "ex held-out RMS",
        ] {
            assert!(svg.contains(label), "{label}");
        }
        // A marker per fit and target (in-sample and held-out).
        assert!(svg.matches("<circle").count() >= 12);
        let v = verdict(&h, "m.json", "d.csv", &noise);
        assert_eq!(v.tone, Tone::Good);
        assert!(
            v.headline.contains("fell from 2.00 µm to 0.200 µm"),
            "{}",
            v.headline
        );
        assert_eq!(
            v.next.as_deref(),
            Some("trueaxis export m.json -o table.bin")
        );
        // Without the noise floor the card does not claim it.
        let v = verdict(&h, "m.json", "d.csv", &BTreeMap::new());
        assert_eq!(v.tone, Tone::Unknown);
        assert!(v
            .next
            .unwrap()
            .starts_with("trueaxis diagnose d.csv --model m.json"));
    }

    /// Issue 13: a step of `improve` that adds several effects explains
    /// every one of them on the history page, each with its target's fall.
    #[test]
    fn every_effect_a_step_adds_is_explained() {
        let mut two = step(
            2,
            &[
                "periodic:target=ex,axis=x,period_mm=5",
                "thermal:target=ey,channel=bed,times=y,offset=1,lag_s=600",
            ],
            1.0,
            1.05,
        );
        two.rms_um.insert("ey".into(), 0.05);
        let h = history(vec![step(1, &[], 2.0, 2.05), two, step(3, &[], 1.0, 1.0)]);
        let v = verdict(&h, "m.json", "d.csv", &BTreeMap::new());
        assert_eq!(
            v.details[..3],
            [
                "Step 2 (1 of 2): + a periodic error of ex along x (lead screw or scale pitch), period 5.00 mm — ex 2.00 µm → 1.00 µm.".to_string(),
                "Step 2 (2 of 2): + thermal growth of ey with the bed temperature, growing along y, lag 600 s — ey 0.200 µm → 0.0500 µm.".to_string(),
                "Step 3: cubic19 refitted, nothing added — ex unchanged at 1.00 µm, ey 0.0500 µm → 0.200 µm.".to_string(),
            ]
        );
    }

    /// Issue 13: "log or linear µm axis". An error falling over two
    /// decades is drawn on a log axis ticked at 1, 2, 5 × 10ᵏ µm (on a
    /// linear one every step after the first lay flat on the floor); one
    /// falling by less than a decade keeps the linear axis.
    #[test]
    fn an_error_falling_over_decades_gets_a_log_axis() {
        let h = history(vec![
            step(1, &[], 20.0, 21.0),
            step(2, &["periodic:target=ex,axis=x,period_mm=5"], 2.0, 2.1),
            step(3, &["reversal:target=ex,axis=x"], 0.2, 0.21),
        ]);
        let noise: BTreeMap<String, f64> = [("ex".to_string(), 0.2)].into();
        let p = plot(&h, &noise);
        assert!(p.log_y);
        let labels = crate::report::plot::svg_texts(&p.to_svg().unwrap());
        for tick in ["0.2", "0.5", "1", "2", "5", "10", "20"] {
            assert!(labels.iter().any(|l| l == tick), "log tick {tick}");
        }
        for linear in ["15", "0.4", "7"] {
            assert!(
                !labels.iter().any(|l| l == linear),
                "no linear tick {linear}"
            );
        }
        let mut page = Page::new("t");
        add_to_page(&mut page, &h, &noise).unwrap();
        assert!(page.to_html().contains("logarithmic"));
        let small = history(vec![step(1, &[], 1.5, 1.55), step(2, &[], 1.0, 1.05)]);
        assert!(!plot(&small, &BTreeMap::new()).log_y);
        assert!(!log_scale_fits(&[0.3, 2.9]));
        assert!(log_scale_fits(&[0.2, 2.1]));
    }

    #[test]
    fn one_fit_is_a_point_not_an_empty_plot() {
        let h = history(vec![step(1, &[], 2.0, 2.05)]);
        let svg = plot(&h, &BTreeMap::new()).to_svg().unwrap();
        assert!(
            svg.matches("<circle").count() >= 4,
            "ex, ey: RMS and held-out"
        );
        let v = verdict(&h, "m.json", "d.csv", &BTreeMap::new());
        assert!(v.headline.starts_with("One fit so far"), "{}", v.headline);
    }
}
