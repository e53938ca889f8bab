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
use trueaxis_engine::history::{History, Step};

use crate::report::plot::{format_value, Series, Style, Ticks, XyPlot};
use crate::report::{Page, Tone, Verdict};

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
    // In-sample series first, so target i has palette colour i and its
    // noise floor the same colour; held-out after them.
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
                Style::LinePoints,
            ));
        }
    }
    for (i, t) in targets.iter().enumerate() {
        if let Some(nf) = noise_um.get(*t).filter(|v| v.is_finite()) {
            p = p.with_dashed(*nf, format!("{t} noise floor {} µm", format_value(*nf)), i);
        }
    }
    let top = h
        .steps
        .iter()
        .flat_map(|s| s.rms_um.values().chain(s.held_out_rms_um.values()))
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    for (k, s) in h.steps.iter().enumerate() {
        // Alternate two heights so neighbouring labels do not overlap.
        let y = top * if k % 2 == 0 { 1.14 } else { 1.06 };
        p = p.with_note(s.step as f64, y, step_label(s));
    }
    p
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
    add_to_page(&mut page, h, noise_um)?;
    page.write(dir)
}

/// The history page's verdict: how far the error fell over the fits, what
/// each step bought, whether the last fit is at the noise floor (when it is
/// known), and the next command (`data`: the data file the model was
/// fitted to, for it).
pub fn verdict(h: &History, model: &str, data: &str, noise_um: &BTreeMap<String, f64>) -> Verdict {
    let um = |v: f64| format!("{} µm", format_value(v));
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
        let (a, b) = (&w[0], &w[1]);
        let changes: Vec<String> = b
            .rms_um
            .iter()
            .filter_map(|(t, r)| a.rms_um.get(t).map(|p| (t, *p, *r)))
            .filter(|(_, p, r)| (p - r).abs() > 0.005 * p.abs().max(1e-9))
            .map(|(t, p, r)| format!("{t} {} → {}", um(p), um(r)))
            .collect();
        details.push(format!(
            "Step {}: {} — {}.",
            b.step,
            step_label(b),
            if changes.is_empty() {
                "no target changed".to_string()
            } else {
                changes.join(", ")
            }
        ));
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
    page.figure(
        "history",
        "Residual RMS (in-sample) and block-held-out RMS per target after each fit; each step is labelled with the effect it added; dashed: the noise floor of the measurement, where known.",
        plot(h, noise_um).to_svg()?,
    );
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
