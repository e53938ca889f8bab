//! The diagnosis's warnings that are not a candidate's own: the measurement
//! design (aliasing, one direction, no or constant temperature), an accepted
//! effect with an implausible parameter, and a residual left above the
//! noise floor.

use crate::data::{Dataset, AXES};
use crate::features::Norm;
use crate::lines::densest_lines;

use super::noise::NoiseFloor;
use super::search::fmt_num;
use super::{Candidate, Warning, ABOVE_NOISE_RATIO, ALIASING_SPACING_MM, CONSTANT_TEMPERATURE_K};

/// The `implausible_parameter` warning for an effect the diagnosis accepts
/// although its physical parameter lies outside the plausible range: the
/// effect is in the data, its size is suspicious — say which parameter,
/// the range, and what to check.
pub(super) fn plausibility_warning(c: &Candidate) -> Option<Warning> {
    let ph = c.physical.as_ref().filter(|p| !p.plausible)?;
    let check = c.effect.info().check;
    Some(Warning {
        code: "implausible_parameter".into(),
        detail: format!(
            "`{}`: {} {:.3} {} (95 % {:.3} … {:.3}) is outside the plausible range ({}); the effect is in the data (ΔBIC {:.0}, held-out gain {:.0} %) and is kept, but its size is suspicious: {check}",
            c.add,
            ph.name,
            ph.value,
            ph.unit,
            ph.ci95[0],
            ph.ci95[1],
            ph.expected,
            c.delta_bic.unwrap_or(f64::NAN),
            100.0 * c.gain.unwrap_or(f64::NAN),
        ),
    })
}

/// The `lags_unidentified` warning: `add` (in the final model of `target`)
/// has lags at the longest its search tries — the sum of squares was still
/// falling there, so each is a lower bound, not a found lag.
pub(super) fn lags_warning(
    target: &str,
    add: &crate::effect::EffectSpec,
    lags: &[(String, f64)],
) -> Warning {
    let named: Vec<String> = lags
        .iter()
        .map(|(ch, lag)| format!("T_{ch}_C lag {} s", super::search::fmt_num(*lag, 0)))
        .collect();
    Warning {
        code: "lags_unidentified".into(),
        detail: format!(
            "{target}: `{add}`: {} at the longest lag searched — not identified, only at least that long (the fit would take a longer one); its coefficient leans on the lag: measure longer than 3× the slow sensor's time constant, or with a cool-down, to identify it",
            named.join(", ")
        ),
    }
}

/// The `above_noise_floor` warning: the residual at the end is clearly
/// above the noise floor, so whatever the verdict says about the named
/// candidates, the data is not explained down to its noise.
pub(super) fn above_noise_warning(
    target: &str,
    rms: f64,
    nf: &NoiseFloor,
    after_path: bool,
) -> Option<Warning> {
    let ratio = above_noise(rms, nf.sigma_um)?;
    Some(Warning {
        code: "above_noise_floor".into(),
        detail: format!(
            "{target}: the residual {} is {rms:.3} µm RMS, {ratio:.1}× the noise floor {:.3} µm (from {}): systematic error is left that no candidate explains significantly — smooth shape the seed cannot follow (a finer model: grid or nn) or an effect outside the library; see worst_regions for where it is",
            if after_path { "after the path" } else { "of the model" },
            nf.sigma_um,
            nf.method.describe()
        ),
    })
}

/// `above_noise_floor` for a region far above the floor while the overall
/// RMS is within [`ABOVE_NOISE_RATIO`] of it.
pub(super) fn region_above_noise_warning(
    target: &str,
    rms: f64,
    region: &crate::regions::Region,
    nf: &NoiseFloor,
) -> Warning {
    Warning {
        code: "above_noise_floor".into(),
        detail: format!(
            "{target}: the residual is {rms:.3} µm RMS overall, within {ABOVE_NOISE_RATIO}× the noise floor {:.3} µm (from {}), but {:.3} µm ({:.1}×) over the {} readings in {}: the overall RMS is set by where most readings are (dense lines), and systematic error is left there that no candidate explains significantly — look at that region (a thermal growth measured on the grid only, a guide's shape) before calling the model done",
            nf.sigma_um,
            nf.method.describe(),
            region.rms_um,
            region.rms_um / nf.sigma_um,
            region.points,
            region.place()
        ),
    }
}

/// The residual RMS as a multiple of the noise floor, when it is above
/// `ABOVE_NOISE_RATIO` (the `above_noise_floor` rule, for the warning and
/// for `improve`).
pub fn above_noise(rms_um: f64, noise_um: f64) -> Option<f64> {
    let ratio = rms_um / noise_um;
    (ratio > ABOVE_NOISE_RATIO).then_some(ratio)
}

/// The dense line that shows short periods along axis `a`: "y from 0 to
/// 500 mm every 0.5 mm at x=400, z=250, forward and backward" (through the
/// middle of the other axes' travel) — the `aliasing` warning's and an
/// aliasing-suspect candidate's measurement.
pub(super) fn dense_line_text(data: &Dataset, a: usize) -> String {
    let norm = Norm::from_data(data);
    let lo = norm.centre_mm[a] - norm.half_span_mm[a];
    let hi = norm.centre_mm[a] + norm.half_span_mm[a];
    let at: Vec<String> = data
        .axes()
        .iter()
        .filter(|&&o| o != a)
        .map(|&o| format!("{}={}", AXES[o], fmt_num(norm.centre_mm[o], 1)))
        .collect();
    format!(
        "{ax} from {lo} to {hi} mm every 0.5 mm{at}, forward and backward",
        ax = AXES[a],
        lo = fmt_num(lo, 1),
        hi = fmt_num(hi, 1),
        at = if at.is_empty() {
            String::new()
        } else {
            format!(" at {}", at.join(", "))
        }
    )
}

/// A probed surface (a printer bed) is spoken of as a bed: no lead screws,
/// no approach direction, no ISO 230-2 runs (issue 28: a delta printer's
/// heightmap was told to measure a dense line every 0.5 mm, forward and
/// backward) — what its mesh spacing cannot show, and that the model for a
/// bed is a grid or a smoother mesh.
fn bed_warnings(data: &Dataset) -> Vec<Warning> {
    let all: Vec<usize> = (0..data.len()).collect();
    let mut w = Vec::new();
    let mut spacing = Vec::new();
    for a in [0, 1] {
        if let Some(dl) = densest_lines(data, a, &all) {
            spacing.push(format!(
                "{} mm along {}",
                fmt_num(dl.spacing_mm, 3),
                AXES[a]
            ));
        }
    }
    if !spacing.is_empty() {
        w.push(Warning {
            code: "aliasing".into(),
            detail: format!(
                "the bed was probed every {}: a bump or dip narrower than two probe spacings is not in the mesh; probe a denser mesh where the first layer fails",
                spacing.join(" and ")
            ),
        });
    }
    w.push(Warning {
        code: "bed_model".into(),
        detail: "a probed bed is modelled by a grid over its probe points (`--model grid:<spacing>`) or a smoother mesh, not by a machine's polynomial: fit a grid and export it as the firmware's bed mesh (`--format klipper-mesh` or `rrf-heightmap`)".into(),
    });
    w
}

pub(super) fn design_warnings(data: &Dataset) -> Vec<Warning> {
    if data.is_probed_surface() {
        return bed_warnings(data);
    }
    let mut w = Vec::new();
    let all: Vec<usize> = (0..data.len()).collect();
    let axes = data.axes();
    for &a in &axes {
        let Some(dl) = densest_lines(data, a, &all) else {
            continue;
        };
        if dl.spacing_mm > ALIASING_SPACING_MM {
            w.push(Warning {
                code: "aliasing".into(),
                detail: format!(
                    "the densest sampling along {ax} is every {sp} mm, so periods below {p2} mm (ball-screw leads are 2–40 mm) are invisible or aliased; add a dense line along {ax}: {line}",
                    ax = AXES[a],
                    sp = fmt_num(dl.spacing_mm, 3),
                    p2 = fmt_num(2.0 * dl.spacing_mm, 3),
                    line = dense_line_text(data, a),
                ),
            });
        }
    }
    // An axis that never moves (every axis of a thermal test at one point)
    // has no backlash to find: no direction warning for it.
    let moving = data.varying_axes();
    for &a in axes.iter().filter(|a| moving.contains(a)) {
        let fix = "measure bidirectionally (ISO 230-2: at least 5 runs each way) and record the approach direction";
        match &data.dir[a] {
            None => w.push(Warning {
                code: "one_direction".into(),
                detail: format!(
                    "no dir_{0} column: reversal (backlash) on {0} cannot be identified; {fix} in dir_{0}",
                    AXES[a]
                ),
            }),
            Some(d) => {
                let first = d.first().copied().unwrap_or(1);
                if d.iter().all(|&v| v == first) {
                    w.push(Warning {
                        code: "one_direction".into(),
                        detail: format!(
                            "every point on {} is approached from {}: reversal (backlash) cannot be identified; {fix}",
                            AXES[a],
                            if first > 0 { "below (+)" } else { "above (−)" }
                        ),
                    });
                }
            }
        }
    }
    if data.temps.is_empty() {
        w.push(Warning {
            code: "no_temperature".into(),
            detail: "no T_<name>_C column: thermal effects cannot be tested (an error that follows temperature may be found as drift, or not at all); record at least one temperature — the bed, the screw nut or the scale — through a warm-up".into(),
        });
    }
    for ch in &data.temps {
        let lo = ch.temp_c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ch.temp_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi - lo < CONSTANT_TEMPERATURE_K {
            w.push(Warning {
                code: "constant_temperature".into(),
                detail: format!(
                    "T_{}_C spans only {:.3} K: thermal effects cannot be identified; measure through a warm-up or over a day so that it changes by 2 K or more",
                    ch.name,
                    hi - lo
                ),
            });
        }
    }
    w
}

pub(super) fn dedup_warnings(w: &mut Vec<Warning>) {
    let mut seen = std::collections::BTreeSet::new();
    w.retain(|x| seen.insert((x.code.clone(), x.detail.clone())));
}
