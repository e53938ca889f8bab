//! The volumetric scenarios (`simulate --scenario volumetric-lines` and
//! `volumetric-tracker`, docs/volumetric.md § Scenarios): the `mill800-21`
//! machine — every one of the 21 geometric errors of ISO 230-1 and the
//! spindle-axis tilt at realistic sizes — measured as a calibration
//! engineer would, each reading relative to its own set-up and with its
//! instrument's noise (instruments.rs):
//!
//! - `volumetric-lines`: laser positioning and straightness lines along
//!   each axis at two parallel offsets and two tool lengths (0 and
//!   150 mm): 12 set-ups. Zeroed lines see neither the tilt nor the
//!   squarenesses, nor the yaw of Y and the roll of Z (no arm for a tool on
//!   the spindle axis): the fit says so.
//! - `volumetric-tracker`: two tracker stations (each an unknown frame)
//!   over the volume, every point at both tool lengths and at lateral
//!   offsets of ±100 mm: enough to determine every error.
//! - `volumetric-ballbar`: ballbar circles (ISO 230-4) in the XY, YZ and
//!   ZX planes about the centre of the volume at a 100 mm tool: the bar
//!   reads relative to its own length and centre, and three circles
//!   confound the squarenesses with the angles and straightnesses — the
//!   fit says nothing is known and names the measurement to add.
//!
//! Why scenarios and not `--plan` options: an instrument's set-up (its
//! zero, alignment and frame) is part of what it reads, and these
//! plans are the ones the documentation's claims are checked on; the
//! engine's [`Instrument`] list stays the one place they are defined.

use crate::data::Dataset;

use super::instruments::{ballbar_circles, laser_lines, measure, Instrument};
use super::{Machine, SimOutput};

/// `simulate --scenario volumetric-lines`.
pub const VOLUMETRIC_LINES: &str = "volumetric-lines";
/// `simulate --scenario volumetric-tracker`.
pub const VOLUMETRIC_TRACKER: &str = "volumetric-tracker";
/// `simulate --scenario volumetric-ballbar`.
pub const VOLUMETRIC_BALLBAR: &str = "volumetric-ballbar";
/// The tool length of the ballbar circles, mm.
pub const BALLBAR_TOOL_MM: f64 = 100.0;
/// The machine the scenarios measure.
pub const PRESET: &str = "mill800-21";
/// The two tool lengths every plan measures at, mm.
pub const TOOLS_MM: [f64; 2] = [0.0, 150.0];

/// The laser lines of `volumetric-lines` on a machine of `travel_mm`.
pub fn lines_plan(travel_mm: [f64; 3]) -> Vec<Instrument> {
    laser_lines(travel_mm, &TOOLS_MM)
}

/// The two tracker stations of `volumetric-tracker` (150 points each, at
/// both tool lengths and at lateral offsets on either side).
pub fn tracker_plan() -> Vec<Instrument> {
    [1.0, -1.0]
        .into_iter()
        .map(|side| Instrument::Tracker {
            tools_mm: TOOLS_MM.to_vec(),
            lateral_mm: vec![[0.0, 0.0], [100.0 * side, 0.0], [0.0, 100.0 * side]],
            points: 150,
        })
        .collect()
}

/// The scenario `name` with `seed`, or `None` when it is not one of these.
/// `truth_um` holds, per row, the machine's true error at the row's tool
/// point (what the reading would be without set-up unknowns and noise).
pub fn scenario(name: &str, seed: u64) -> anyhow::Result<Option<SimOutput>> {
    let m = Machine::preset(PRESET)?;
    let plan = match name {
        VOLUMETRIC_LINES => lines_plan(m.travel_mm),
        VOLUMETRIC_TRACKER => tracker_plan(),
        VOLUMETRIC_BALLBAR => ballbar_circles(m.travel_mm, BALLBAR_TOOL_MM),
        _ => return Ok(None),
    };
    let data = measure(&m, &plan, seed, true);
    let truth_um = truth(&m, &data);
    Ok(Some(SimOutput {
        data,
        truth_um,
        spikes: Vec::new(),
    }))
}

/// The machine's error at every row's tool point, µm.
fn truth(m: &Machine, data: &Dataset) -> [Vec<f64>; 3] {
    let mut out: [Vec<f64>; 3] = Default::default();
    for r in 0..data.len() {
        let e = m.error_at_um(
            [0, 1, 2].map(|a| data.pos(a, r)),
            data.tool(r),
            [data.tool_lat(0, r), data.tool_lat(1, r)],
        );
        for (o, v) in out.iter_mut().zip(e) {
            o.push(v);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scenarios_are_their_plans_with_set_ups_and_tool_lengths() {
        let lines = scenario(VOLUMETRIC_LINES, 3).unwrap().expect("known");
        let ids = lines.data.setup_id.as_ref().expect("set-ups");
        let mut set: Vec<i64> = ids.clone();
        set.sort_unstable();
        set.dedup();
        assert_eq!(set.len(), 12);
        let tools: Vec<f64> = (0..lines.data.len()).map(|r| lines.data.tool(r)).collect();
        assert!(tools.contains(&0.0) && tools.contains(&150.0));
        let tracker = scenario(VOLUMETRIC_TRACKER, 3).unwrap().expect("known");
        assert!((0..tracker.data.len()).any(|r| tracker.data.tool_lat(0, r) == -100.0));
        assert_eq!(tracker.truth_um[0].len(), tracker.data.len());
        let ballbar = scenario(VOLUMETRIC_BALLBAR, 3).unwrap().expect("known");
        assert_eq!(ballbar.data.len(), 270);
        assert!(ballbar.data.err_um.iter().all(Option::is_none));
        assert!((0..270).all(|r| ballbar.data.tool(r) == BALLBAR_TOOL_MM));
        // The same seed, the same rows; an unknown name is not ours.
        let again = scenario(VOLUMETRIC_LINES, 3).unwrap().unwrap();
        assert_eq!(again.data.err_um, lines.data.err_um);
        assert!(scenario("spindle-thermal", 3).unwrap().is_none());
    }
}
