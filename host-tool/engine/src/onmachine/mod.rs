//! The on-machine wing (docs/on-machine.md): parts and probes measured on
//! the machine itself, beside the compensation pipeline (data → features →
//! model → fit → diagnose → export), not a layer of it. The wing reads its
//! own small scan files and the measurement CSV's probe columns, and uses
//! the engine's generic plumbing below it — the CSV line reader
//! (`import`), the plausible ranges of positions and errors (`data`),
//! least squares (`lsq`) and the seeded normal deviates of the simulator
//! (`simulate`). No module of the compensation pipeline imports the wing
//! (`tests/layering.rs`).
//!
//! Inside, lowest first (a module uses only those above it in this list):
//!
//! - `clock`: time stamps — `t_s` seconds or clock times (ISO 8601,
//!   `hh:mm:ss`).
//! - `separate`: error separation — reversal (part form vs slide
//!   straightness), three-probe and multi-step (part roundness vs the
//!   spindle's ISO 230-7 error motion) from readings resampled by angle
//!   (`separate::turn`); `pv`, `z_all` and the second-difference `noise`
//!   every probing command uses.
//! - `probe_csv`: the measurement CSV's probe columns — one campaign in one
//!   file, a session read as the small scan file a command reads.
//! - `spindle_log`: readings round a turn as loggers write them — the
//!   angle from `c_deg`, encoder counts, an index pulse or the speed.
//! - `probe`: the probe's radius and form calibrated on a master ball
//!   (`probe::sphere` in 3-D) and a workpiece scan corrected with them.
//! - `workpiece`: a turned part's form from probed generatrices and the
//!   correction pass (G-code).
//! - `simulate`: the simulated campaign — every file the commands above
//!   read, from hidden effects with known values.
//! - `part_diagnosis`: which error is in a part scan — probe, part, slide,
//!   spindle or drift — and what the data cannot tell.

pub mod clock;
pub mod separate;

pub mod probe_csv;
pub mod spindle_log;

pub mod probe;
pub mod simulate;
pub mod workpiece;

pub mod part_diagnosis;
