//! Units a data set probably does not have: the mistakes that pass every
//! range check and give a confident, wrong answer — errors in mm written
//! into `*_um` columns (a model and a table 1000× too small, a "noise
//! floor" of 0.2 nm), errors in nm below the import's 10 mm limit,
//! positions in metres (a 0.8 "mm" travel with a 1 % scale error).
//! Warned (`units_suspect`) by fit, diagnose and improve; export refuses a
//! table whose largest correction is below [`TINY_CORRECTION_UM`] unless
//! told (docs/cli.md § Measurement CSV, Units).

use crate::data::{Dataset, AXES, TARGETS};
use crate::warning::Warning;

/// Below this largest |error| (µm) on every target the errors are more
/// likely mm than µm: no machine a table compensates is that good, and a
/// laser interferometer resolves no better.
pub const TINY_ERROR_UM: f64 = 0.05;

/// Below this largest |correction| (µm) export refuses a table unless
/// told: nothing worth compensating, or data in mm.
pub const TINY_CORRECTION_UM: f64 = 0.05;

/// Above this |error| (µm) an error is more likely nm than µm.
pub const HUGE_ERROR_UM: f64 = 1000.0;

/// A linear trend of the error along an axis steeper than this (µm per
/// mm, 0.5 %) is no scale error a machine has (a 3-D printer's tilted bed
/// reaches 0.2 %): the positions are not mm, or the errors not µm.
pub const STEEP_SLOPE_UM_PER_MM: f64 = 5.0;

/// Travel spans below this (mm) on every axis, with a steep slope, look
/// like metres.
const SHORT_TRAVEL_MM: f64 = 2.0;

/// The `units_suspect` warnings of a data set.
pub fn suspect(data: &Dataset) -> Vec<Warning> {
    let mut w = Vec::new();
    let targets = data.targets();
    let max_abs: Vec<(usize, f64)> = targets
        .iter()
        .map(|&t| (t, data.measured(t).fold(0.0f64, |m, (_, v)| m.max(v.abs()))))
        .collect();
    if !max_abs.is_empty() && max_abs.iter().all(|&(_, m)| m < TINY_ERROR_UM) {
        let list: Vec<String> = max_abs
            .iter()
            .map(|(t, m)| format!("max |{}| {m:.4} µm", TARGETS[*t]))
            .collect();
        w.push(Warning::new(
            "units_suspect",
            format!(
                "{}: the errors are tiny ({}): no machine is that good — if they are mm, multiply them by 1000 (the columns are µm: `ex_um` …)",
                data.source,
                list.join(", ")
            ),
        ));
    }
    if let Some(&(t, m)) = max_abs
        .iter()
        .filter(|&&(_, m)| m > HUGE_ERROR_UM)
        .max_by(|a, b| a.1.total_cmp(&b.1))
    {
        w.push(Warning::new(
            "units_suspect",
            format!(
                "{}: {} reaches {:.1} µm ({:.3} mm): if these are nm, divide them by 1000; if they are µm, check the reference (an offset left in) before compensating",
                data.source,
                TARGETS[t],
                m,
                m / 1000.0
            ),
        ));
    }
    let axes = data.varying_axes();
    let spans: Vec<(usize, f64)> = axes
        .iter()
        .map(|&a| {
            let p = data.pos_mm[a].as_ref().expect("varying axis");
            let (lo, hi) = p
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            (a, hi - lo)
        })
        .collect();
    if !spans.is_empty() && spans.iter().all(|&(_, s)| s < SHORT_TRAVEL_MM) {
        for &t in &targets {
            for &(a, span) in &spans {
                let Some(slope) = slope(data, t, a) else {
                    continue;
                };
                if slope.abs() > STEEP_SLOPE_UM_PER_MM {
                    w.push(Warning::new(
                        "units_suspect",
                        format!(
                            "{}: {} changes {slope:+.1} µm per mm of {} over a travel of only {span:.3} mm: if the positions are metres, multiply them by 1000 (the columns are mm: `{}_mm`)",
                            data.source,
                            TARGETS[t],
                            AXES[a],
                            AXES[a]
                        ),
                    ));
                    return w;
                }
            }
        }
    }
    w
}

/// Least-squares slope of target `t` against axis `a`, µm per mm.
fn slope(data: &Dataset, t: usize, a: usize) -> Option<f64> {
    let p = data.pos_mm[a].as_ref()?;
    let pairs: Vec<(f64, f64)> = data.measured(t).map(|(r, v)| (p[r], v)).collect();
    let n = pairs.len() as f64;
    if pairs.len() < 3 {
        return None;
    }
    let mx = pairs.iter().map(|q| q.0).sum::<f64>() / n;
    let my = pairs.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = pairs.iter().map(|q| (q.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(x: Vec<f64>, e: Vec<f64>) -> Dataset {
        Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x), None, None],
            err_um: [Some(e.into_iter().map(Some).collect()), None, None],
            ..Dataset::default()
        }
    }

    #[test]
    fn mm_in_a_um_column_is_suspected_and_um_is_not() {
        let x: Vec<f64> = (0..=50).map(|i| 10.0 * i as f64).collect();
        let um: Vec<f64> = x
            .iter()
            .map(|v| 12.0 * v / 500.0 - 3.0 * (v / 80.0).sin())
            .collect();
        assert!(suspect(&line(x.clone(), um.clone())).is_empty());
        let mm: Vec<f64> = um.iter().map(|v| v / 1000.0).collect();
        let w = suspect(&line(x.clone(), mm));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].detail.contains("multiply them by 1000"), "{w:?}");
        let nm: Vec<f64> = um.iter().map(|v| v * 1000.0).collect();
        let w = suspect(&line(x, nm));
        assert!(
            w.iter().any(|w| w.detail.contains("divide them by 1000")),
            "{w:?}"
        );
    }

    #[test]
    fn metres_in_a_mm_column_are_suspected() {
        let m: Vec<f64> = (0..=40).map(|i| 0.02 * i as f64).collect();
        let e: Vec<f64> = m
            .iter()
            .map(|v| 15.0 * v + 0.3 * (v * 40.0).sin())
            .collect();
        let w = suspect(&line(m.clone(), e.clone()));
        assert!(w.iter().any(|w| w.detail.contains("metres")), "{w:?}");
        // The same errors over the travel in mm are an ordinary scale error.
        let mm: Vec<f64> = m.iter().map(|v| v * 1000.0).collect();
        assert!(suspect(&line(mm, e)).is_empty());
    }
}
