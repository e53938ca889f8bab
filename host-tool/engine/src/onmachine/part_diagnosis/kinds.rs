//! The three kinds of part scan (docs/on-machine.md § diagnose-part):
//! what a straightness run, a roundness turn and an arc of probe centres
//! each identify, given the evidence — and the sums they can only read as
//! sums.

use anyhow::Result;

use super::*;

/// Readings with a linear drift in time removed.
fn without_drift(r: &[f64], t: Option<&[f64]>, rate_per_s: Option<f64>) -> Vec<f64> {
    match (t, rate_per_s) {
        (Some(t), Some(k)) => r.iter().zip(t).map(|(v, ti)| v - k * (ti - t[0])).collect(),
        _ => r.to_vec(),
    }
}

const PROBE_ONE_DIRECTION: &str = "the probe touches the part in one direction all along: its radius and form add a constant, which carries no form";

pub(super) fn straightness(pos: &[f64], d: &[f64], ev: &Evidence) -> Result<PartDiagnosis> {
    let noise = separate::noise(d);
    let t = ev.t_s.as_deref();
    let (th, rate) = thermal(
        d,
        t,
        noise,
        |j| (pos[j] - pos[0]).abs() < 1e-6,
        "read the start position again at the end",
    );
    let d = without_drift(d, t, rate);
    let (sum, _) = remove_fit(pos, &d, |x| vec![1.0, x])?;
    let mut findings = vec![
        not_in_scan(Source::ProbeRadius, "mm", PROBE_ONE_DIRECTION),
        not_in_scan(Source::ProbeForm, "nm", PROBE_ONE_DIRECTION),
    ];
    let mut combined = Vec::new();
    if let Some(r180) = &ev.reversal {
        let run1: Vec<(f64, f64)> = pos.iter().copied().zip(d.iter().copied()).collect();
        let rv = separate::reversal(&run1, r180)?;
        let ci = z_all(rv.pos_mm.len()) * rv.point_sigma_um.unwrap_or(f64::NAN);
        let left = "line removed; an error that changed between the two runs (drift between them) is in both halves";
        findings.push(pv_estimated(
            Source::PartForm,
            rv.part_pv_um,
            ci,
            "µm",
            format!("peak to valley from the reversal pair, {left}"),
        ));
        findings.push(pv_estimated(
            Source::SlideStraightness,
            rv.slide_pv_um,
            ci,
            "µm",
            format!("peak to valley from the reversal pair, {left}"),
        ));
    } else {
        let why = format!(
            "one orientation reads part form + slide straightness as one sum ({:.3} µm PV together, line removed)",
            pv(&sum)
        );
        let m = Measure(vec![
            Piece::Say(
                "turn the part 180° about the travel, reverse the probe and scan again: ".into(),
            ),
            Piece::Give(Input::Reversal),
            Piece::Say(" (separate reversal)".into()),
        ]);
        findings.push(cannot_know(Source::PartForm, "µm", why.clone(), m.clone()));
        findings.push(cannot_know(Source::SlideStraightness, "µm", why, m.clone()));
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SlideStraightness],
            pv(&sum),
            noise.map(|n| z_all(pos.len()) * n),
            "µm",
            "the readings along the travel, line removed".into(),
            m,
        ));
    }
    findings.push(not_in_scan(
        Source::SpindleErrorMotion,
        "µm",
        "the spindle does not turn during a straightness scan",
    ));
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "straightness",
        points: pos.len(),
        noise_um: noise,
        findings,
        combined,
        profile: pos.iter().copied().zip(sum).collect(),
        profile_unit: "µm",
    })
}

pub(super) fn roundness(c_deg: &[f64], p: &[f64], ev: &Evidence) -> Result<PartDiagnosis> {
    let noise = separate::noise(p);
    let t = ev.t_s.as_deref();
    let same = |j: usize| {
        let d = (c_deg[j] - c_deg[0]).rem_euclid(360.0);
        d.min(360.0 - d) < 1e-6
    };
    let (th, rate) = thermal(
        p,
        t,
        noise,
        same,
        "close the turn (read the start angle again at the end)",
    );
    let p = without_drift(p, t, rate);
    let (sum, _) = remove_fit(c_deg, &p, |c| {
        let r = c.to_radians();
        vec![1.0, r.cos(), r.sin()]
    })?;
    let mut findings = vec![
        not_in_scan(Source::ProbeRadius, "mm", "a fixed probe touches the turning part in one direction: its radius only adds to the size"),
        not_in_scan(Source::ProbeForm, "nm", "a fixed probe touches the turning part in one direction: its form adds a constant, which is not roundness"),
    ];
    let mut combined = Vec::new();
    if let Some(steps) = &ev.multi_step {
        let ms = separate::multi_step(steps, ev.upr)?;
        let list: Vec<String> = ms
            .inseparable_harmonics
            .iter()
            .take(4)
            .map(|k| k.to_string())
            .collect();
        let list = format!("{}, …", list.join(", "));
        let mut part = estimated(
            Source::PartForm,
            ms.part_pv_um,
            0.0,
            "µm",
            format!("roundness (harmonics 2…) from the multi-step set of {} steps, without its harmonics {list}", ms.steps),
        );
        part.ci95 = Some(ms.part_ci95_um);
        let remedy = format!(
            "the part's harmonics {list} cannot be told from the spindle's with {} steps: a multi-step whose number of steps divides none of the lobes you look for, or three probes (separate three-probe)",
            ms.steps
        );
        part.measure = Some(Measure::say(remedy.clone()));
        findings.push(part);
        let em = &ms.error_motion;
        let mut spin = estimated(
            Source::SpindleErrorMotion,
            em.synchronous_um,
            0.0,
            "µm",
            format!(
                "synchronous radial error motion along the probe (ISO 230-7: the turn average, its once-per-turn term — centring, {:.3} µm — left out) from the multi-step set, without harmonics {list}",
                em.centring_um
            ),
        );
        spin.ci95 = Some(em.synchronous_ci95_um);
        spin.measure = Some(Measure::say(remedy.clone()));
        findings.push(spin);
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SpindleErrorMotion],
            ms.error_motion.excluded_pv_um,
            Some(z_all(ms.samples) * ms.point_sigma_um),
            "µm",
            format!(
                "harmonics {list}: the part's and the spindle's, which {} steps cannot tell apart",
                ms.steps
            ),
            Measure::say(remedy),
        ));
    } else {
        let why = format!(
            "one orientation reads part roundness + spindle error motion as one sum ({:.3} µm PV together, harmonics 0 and 1 removed)",
            pv(&sum)
        );
        let m = Measure(vec![
            Piece::Say("remount the part at N equally spaced steps and read a turn at each: ".into()),
            Piece::Give(Input::MultiStep),
            Piece::Say(" (separate multi-step; the part's lobes at multiples of N stay inseparable, so choose N dividing none you look for), or read it with three probes (separate three-probe)".into()),
        ]);
        findings.push(cannot_know(Source::PartForm, "µm", why.clone(), m.clone()));
        findings.push(cannot_know(
            Source::SpindleErrorMotion,
            "µm",
            why,
            m.clone(),
        ));
        combined.push(combined_sum(
            vec![Source::PartForm, Source::SpindleErrorMotion],
            pv(&sum),
            noise.map(|n| z_all(c_deg.len()) * n),
            "µm",
            "the readings round the turn, harmonics 0 and 1 removed".into(),
            m,
        ));
    }
    findings.insert(
        3,
        not_in_scan(
            Source::SlideStraightness,
            "µm",
            "no slide moves during a roundness scan",
        ),
    );
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "roundness",
        points: c_deg.len(),
        noise_um: noise,
        findings,
        combined,
        profile: c_deg.iter().copied().zip(sum).collect(),
        profile_unit: "µm",
    })
}

pub(super) fn arc(p: &[[f64; 2]], side: probe::Side, ev: &Evidence) -> Result<PartDiagnosis> {
    let (c, rc) = probe::kasa(p)?;
    let theta: Vec<f64> = p.iter().map(|q| (q[1] - c[1]).atan2(q[0] - c[0])).collect();
    let dev_um: Vec<f64> = p
        .iter()
        .map(|q| ((q[0] - c[0]).hypot(q[1] - c[1]) - rc) * 1e3)
        .collect();
    let noise = separate::noise(&dev_um);
    let t = ev.t_s.as_deref();
    let (th, _) = thermal(
        &dev_um,
        t,
        noise,
        |j| (p[j][0] - p[0][0]).hypot(p[j][1] - p[0][1]) < 0.01,
        "probe the first point again at the end",
    );
    // The deviations from the circle, radius and centre removed (as a
    // linear fit they carry the radius's standard deviation per unit noise).
    let (resid, sol) = remove_fit(&theta, &dev_um, |t| vec![1.0, t.cos(), t.sin()])?;
    let sd_unit = sol.coef_sd[0] / (sol.rss / sol.dof.max(1) as f64).sqrt();
    let sigma = noise.unwrap_or(f64::NAN);
    // Positions logged at a coarse resolution: no interval below it.
    let quantum_nm = probe::robust::quantum(p.iter().flatten().copied())
        .filter(|&q| q > 1e-7)
        .map_or(0.0, |q| q * 1e6);
    let point_ci_nm = (z_all(p.len()) * sigma * 1e3).max(quantum_nm);
    let raw_pv_nm = pv(&resid) * 1e3;
    // Convex (probed from outside): the centre path's radius is the part's
    // plus the probe's; a bore's is the part's minus the probe's.
    let mid = p[p.len() / 2];
    let convex = match side {
        probe::Side::Out => true,
        probe::Side::In => false,
        probe::Side::Toward(d) => (mid[0] - c[0]) * d[0] + (mid[1] - c[1]) * d[1] > 0.0,
    };
    let sign = if convex { 1.0 } else { -1.0 };
    let from_diameter = ev.part_diameter_mm.map(|d| {
        (
            sign * (rc - d / 2.0),
            (Z95 * sigma * sd_unit * 1e-3).max(quantum_nm * 1e-6),
        )
    });
    let mut findings = Vec::new();
    let mut combined = Vec::new();
    findings.push(match (&ev.probe, from_diameter) {
        (Some(k), d) => {
            let mut f = estimated(Source::ProbeRadius, k.radius_mm, k.radius_ci95_mm, "mm", "effective radius from the ball calibration".into());
            if let Some((r, h)) = d {
                f.what.push_str(&format!(
                    "; the known diameter gives {r:.6} ± {h:.6} mm (with the form of zero mean over these contact angles)"
                ));
            }
            f
        }
        (None, Some((r, h))) => estimated(
            Source::ProbeRadius,
            r,
            h,
            "mm",
            format!(
                "the centre path's radius {rc:.6} mm {} the known radius; with the probe's and the part's form of zero mean and no tilt over these contact angles, the diameter taken as exact",
                if convex { "less" } else { "from" }
            ),
        ),
        (None, None) => cannot_know(
            Source::ProbeRadius,
            "mm",
            format!("the centre path's radius ({rc:.6} mm) holds the part's radius and the probe's as one sum"),
            Measure(vec![
                Piece::Say("calibrate the probe on a master ball (probe calibrate, then ".into()),
                Piece::Give(Input::Probe),
                Piece::Say(") or scan a part of known diameter (".into()),
                Piece::Give(Input::PartDiameter),
                Piece::Say(")".into()),
            ]),
        ),
    });
    let slide = cannot_know(
        Source::SlideStraightness,
        "nm",
        "an arc is scanned by moving two slides: their straightness adds to the form at the same points".into(),
        Measure::say("run a reversal along each slide (separate reversal)"),
    );
    match &ev.probe {
        Some(k) => {
            let contacts = probe::correct_with(p, side, k.radius_mm, |t| (k.form)(t))?;
            let outside = contacts.iter().filter(|x| !x.calibrated).count();
            // What the probe's form puts into this scan's form: its values
            // at the calibrated contacts less what the least-squares circle
            // takes (1, cos θ, sin θ over these angles) — the same whatever
            // convention the probe file keeps (a 2-D file's form has no
            // mean or tilt over the ball's arc, a 3-D file's over the
            // sphere). The interval is the series' (a smooth function: its
            // error at the peak and at the valley each within that).
            let cal: Vec<&probe::Contact> = contacts.iter().filter(|x| x.calibrated).collect();
            let in_scan = if cal.len() >= 4 {
                let t: Vec<f64> = cal.iter().map(|x| x.theta_deg.to_radians()).collect();
                let f: Vec<f64> = cal.iter().map(|x| x.form_nm).collect();
                pv(&remove_fit(&t, &f, |t| vec![1.0, t.cos(), t.sin()])?.0)
            } else {
                0.0
            };
            let mut pf = pv_estimated(
                Source::ProbeForm,
                in_scan,
                k.form_ci95_nm,
                "nm",
                format!(
                    "peak to valley of its form over this scan's contact angles less what a circle takes there, from the ball calibration ({:.1} nm PV over all the calibrated directions)",
                    k.form_pv_nm
                ),
            );
            if outside > 0 {
                pf.measure = Some(Measure::say(format!("{outside} contact(s) lie outside the calibrated directions (corrected with the radius only): calibrate over the angles the part presents")));
            }
            findings.push(pf);
            // The corrected contacts still hold the straightness of the
            // slides that carried the probe along the arc: a sum, said as
            // one (its interval is the noise's; the split is unknown).
            let s: Vec<[f64; 2]> = contacts.iter().map(|x| x.surface_mm).collect();
            let dev = probe::form_deviation_nm(&s, true)?;
            let by_reversal = Measure::say("run a reversal along each slide (separate reversal), or scan the part turned on the table so the slides' errors move with it");
            findings.push(cannot_know(
                Source::PartForm,
                "nm",
                format!("the probe-corrected arc holds the part's form and the straightness of the slides that moved the probe along it as one sum ({:.1} nm PV together, against the least-squares circle)", pv(&dev)),
                by_reversal.clone(),
            ));
            combined.push(combined_sum(
                vec![Source::PartForm, Source::SlideStraightness],
                pv(&dev),
                Some(point_ci_nm),
                "nm",
                "the arc corrected with the probe's radius and form, against the least-squares circle".into(),
                by_reversal,
            ));
        }
        None => {
            let why = format!("on one scan the probe's form at a contact angle and the part's form there are one sum ({raw_pv_nm:.1} nm PV together, against the least-squares circle)");
            let calibrate = |how: &str| {
                Measure(vec![
                    Piece::Say(format!(
                        "calibrate the probe on a master ball{how} (probe calibrate, then "
                    )),
                    Piece::Give(Input::Probe),
                    Piece::Say(")".into()),
                ])
            };
            findings.push(cannot_know(
                Source::ProbeForm,
                "nm",
                why.clone(),
                calibrate(" over the same contact angles"),
            ));
            findings.push(cannot_know(Source::PartForm, "nm", why, calibrate("")));
            combined.push(combined_sum(
                vec![
                    Source::ProbeForm,
                    Source::PartForm,
                    Source::SlideStraightness,
                ],
                raw_pv_nm,
                Some(point_ci_nm),
                "nm",
                "the probe centres against their least-squares circle".into(),
                calibrate(""),
            ));
        }
    }
    findings.push(slide);
    findings.push(not_in_scan(
        Source::SpindleErrorMotion,
        "µm",
        "the spindle does not turn during the scan",
    ));
    findings.push(th);
    Ok(PartDiagnosis {
        kind: "arc",
        points: p.len(),
        noise_um: noise,
        findings,
        combined,
        profile: theta
            .iter()
            .zip(&resid)
            .map(|(t, r)| (t.to_degrees(), r * 1e3))
            .collect(),
        profile_unit: "nm",
    })
}
