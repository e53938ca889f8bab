//! A controller's own compensation table for one axis (LinuxCNC screw
//! compensation, Sinumerik LEC): every decision such a file takes, made
//! here — which axis, how many points, the max |correction| it may hold
//! and the refusal when it would hold more (a controller's table cannot
//! clamp), tiny corrections — and, per format, its defaults, limits, sign
//! convention and writer.
//!
//! **Formats.** Each format is one file implementing [`ControllerFormat`]
//! (`linuxcnc.rs`, `sinumerik.rs`) and one arm of [`Controller`]. A new
//! one-axis table (ISG/Beckhoff TF5280 spindle-pitch compensation, a
//! Sinumerik CEC table) is the same: a file with its defaults, its limit
//! on the points, its writer (sign and unit as its controller reads them,
//! docs/export-formats.md) and what the controller needs beside the file
//! (machine data, in [`ControllerFile`]); the pipeline in [`export`] and
//! the CLI stay as they are.
//!
//! **The pipeline** ([`export`]): the axis (the one given, else the only
//! axis the model uses), the points (given, else the format's default, at
//! most what the controller reads), the samples ([`sample_axis`]: both
//! approach directions at a fixed state, short waves and drift left out
//! with a warning), the checks every file that cannot clamp takes
//! ([`checks`](crate::export::checks)), then the format's writer.

pub mod linuxcnc;
mod samples;
pub mod sinumerik;

use std::collections::BTreeMap;

use serde::{Serialize, Serializer};

pub use samples::{sample_axis, AxisSamples};

use crate::data::AXES;
use crate::export::checks::{check_unclampable, FileError};
use crate::export::{axis_travel_mm, crc32_hex, Warning};
use crate::model::ModelFile;

/// Every controller format trueaxis writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Controller {
    /// LinuxCNC screw compensation, `COMP_FILE_TYPE = 1`.
    Linuxcnc,
    /// Sinumerik leadscrew error compensation (LEC, `$AA_ENC_COMP`).
    Sinumerik,
}

impl Controller {
    /// The format's defaults, limits and writer.
    pub fn format(self) -> &'static dyn ControllerFormat {
        match self {
            Controller::Linuxcnc => &linuxcnc::Linuxcnc,
            Controller::Sinumerik => &sinumerik::Sinumerik,
        }
    }
}

/// One controller's one-axis compensation table: its defaults, what it
/// reads and how it is written.
pub trait ControllerFormat: Sync {
    /// The format's name (`linuxcnc`): the JSON's `format`, and the file in
    /// messages.
    fn name(&self) -> &'static str;
    /// Points of the table when none are given.
    fn default_points(&self) -> usize;
    /// Refuses more points than the controller reads (by default any
    /// number is written).
    fn check_points(&self, _points: usize) -> Result<(), FileError> {
        Ok(())
    }
    /// The controller's name of the axis when none is given, for a format
    /// whose file names it (`None`: the file names no axis).
    fn default_axis_name(&self) -> Option<&'static str> {
        None
    }
    /// The file for `samples` (the axis named `axis_name` where the file
    /// names it), in the controller's sign and unit.
    fn write(
        &self,
        samples: &AxisSamples,
        axis_name: Option<&str>,
    ) -> anyhow::Result<ControllerFile>;
}

/// What a format writes: the file, what it says and what the controller
/// needs beside it.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerFile {
    /// The file's text.
    pub body: String,
    /// The first point, the step and the last point as the file states
    /// them (after its rounding), mm.
    pub min_mm: f64,
    /// See `min_mm`.
    pub step_mm: f64,
    /// See `min_mm`.
    pub max_mm: f64,
    /// Values the controller's machine data needs beside the file, by the
    /// JSON key that reports them (Sinumerik: `md32450_backlash_mm`).
    pub machine_data: BTreeMap<&'static str, f64>,
    /// What to set on the controller beside loading the file, in words
    /// (`None`: nothing).
    pub note: Option<String>,
}

/// Options of a controller file (the flags of `trueaxis export` for these
/// formats).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ControllerOptions {
    /// The axis (0 = x); `None` = the only axis the model uses.
    pub axis: Option<usize>,
    /// Points of the table; `None` = the format's default.
    pub points: Option<usize>,
    /// The controller's name of the axis, where the file names it; `None`
    /// = the format's default.
    pub axis_name: Option<String>,
    /// Largest |correction| the file may hold, µm; `None` = 1.5 × the
    /// largest it holds, at least 1 µm.
    pub max_corr_um: Option<f64>,
    /// Export even when every correction is tiny.
    pub accept_tiny: bool,
}

/// A controller file and what it holds (the JSON of `trueaxis export` for
/// these formats, without `format` and `output`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ControllerExport {
    /// The axis (0 = x; JSON: its name).
    #[serde(serialize_with = "axis_name")]
    pub axis: usize,
    /// Points in the table.
    pub points: usize,
    /// First point as the file states it, mm.
    pub min_mm: f64,
    /// Last point as the file states it, mm.
    pub max_mm: f64,
    /// Step between points as the file states it, mm.
    pub step_mm: f64,
    /// Where the other axes stood, mm (JSON: `{"x", "y", "z"}`).
    #[serde(serialize_with = "xyz")]
    pub at_mm: [f64; 3],
    /// Size of the file, bytes.
    pub bytes: usize,
    /// CRC-32 of the file, `0x…`.
    pub crc32: String,
    /// What linear interpolation of the table loses against the full
    /// model, µm (see [`AxisSamples::max_interp_error_um`]).
    pub max_interp_error_um: f64,
    /// The max |correction| limit, µm (whole nm, rounded up as the
    /// table's).
    pub max_corr_um: f64,
    /// Mean reversal of the model along the axis, forward − reverse, µm.
    pub backlash_um: f64,
    /// Values the controller's machine data needs beside the file.
    #[serde(flatten)]
    pub machine_data: BTreeMap<&'static str, f64>,
    /// What was left out or changed, and why.
    pub warnings: Vec<Warning>,
    /// The file's text.
    #[serde(skip)]
    pub body: String,
    /// What to set on the controller beside loading the file, in words.
    #[serde(skip)]
    pub note: Option<String>,
}

impl ControllerExport {
    /// Whether terms of the model were left out of the table (their loss is
    /// in `max_interp_error_um`).
    pub fn terms_left_out(&self) -> bool {
        self.warnings.iter().any(|w| w.code.ends_with("_left_out"))
    }
}

fn axis_name<S: Serializer>(axis: &usize, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(AXES[*axis])
}

fn xyz<S: Serializer>(v: &[f64; 3], s: S) -> Result<S::Ok, S::Error> {
    let map: BTreeMap<&str, f64> = AXES.iter().copied().zip(*v).collect();
    map.serialize(s)
}

/// The axis of a one-axis file: `given`, else the only axis the model uses.
pub fn choose_axis(model: &ModelFile, given: Option<usize>) -> Result<usize, FileError> {
    if let Some(a) = given {
        return Ok(a);
    }
    let used: Vec<usize> = (0..3)
        .filter(|&a| axis_travel_mm(&model.model, a).is_some())
        .collect();
    match used.as_slice() {
        [a] => Ok(*a),
        _ => Err(FileError::AxisAmbiguous { used }),
    }
}

/// Makes `controller`'s file for `model` (see the module docs). Nothing is
/// written: the caller writes [`ControllerExport::body`].
pub fn export(
    model: &ModelFile,
    controller: Controller,
    opts: &ControllerOptions,
) -> Result<ControllerExport, FileError> {
    let format = controller.format();
    let axis = choose_axis(model, opts.axis)?;
    let points = opts.points.unwrap_or(format.default_points());
    format.check_points(points)?;
    let s = sample_axis(model, axis, points)?;
    let corr_nm: Vec<f64> = s
        .err_fwd_um
        .iter()
        .chain(&s.err_rev_um)
        .map(|v| 1000.0 * v)
        .collect();
    let (max_corr_nm, _) = check_unclampable(
        axis,
        corr_nm,
        opts.max_corr_um,
        opts.accept_tiny,
        format.name(),
        "a controller's compensation table",
    )?;
    let axis_name = opts.axis_name.as_deref().or(format.default_axis_name());
    let file = format.write(&s, axis_name)?;
    Ok(ControllerExport {
        axis,
        points,
        min_mm: file.min_mm,
        max_mm: file.max_mm,
        step_mm: file.step_mm,
        at_mm: s.at_mm,
        bytes: file.body.len(),
        crc32: crc32_hex(file.body.as_bytes()),
        max_interp_error_um: s.max_interp_error_um,
        max_corr_um: max_corr_nm.ceil() / 1000.0,
        backlash_um: s.backlash_mean_um(),
        machine_data: file.machine_data,
        warnings: s.warnings,
        body: file.body,
        note: file.note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::checks::TinyCorrections;
    use crate::export::fixtures::{linear, mono};
    use crate::features::Feature;

    /// ex = offset + slope·u + reversal·dir along x over 0…200 mm.
    fn line_x(offset_um: f64, slope_um: f64, reversal_um: f64) -> ModelFile {
        linear(
            0,
            &[
                (mono([0, 0, 0]), offset_um),
                (mono([1, 0, 0]), slope_um),
                (Feature::Reversal { axis: 0 }, reversal_um),
            ],
        )
    }

    fn opts() -> ControllerOptions {
        ControllerOptions::default()
    }

    #[test]
    fn each_format_has_its_default_points_and_the_only_axis_is_taken() {
        let m = line_x(3.0, 1.0, 2.4);
        let l = export(&m, Controller::Linuxcnc, &opts()).unwrap();
        assert_eq!((l.axis, l.points), (0, 201));
        assert_eq!((l.min_mm, l.step_mm, l.max_mm), (0.0, 1.0, 200.0));
        assert_eq!(l.body.lines().count(), 201);
        let s = export(&m, Controller::Sinumerik, &opts()).unwrap();
        assert_eq!((s.axis, s.points), (0, 200));
        assert!(s.body.contains("$AA_ENC_COMP[0,199,AX1]="), "{}", s.body);
        let named = ControllerOptions {
            axis_name: Some("X1".into()),
            points: Some(11),
            ..opts()
        };
        let s = export(&m, Controller::Sinumerik, &named).unwrap();
        assert!(s.body.contains("$AA_ENC_COMP[0,10,X1]="), "{}", s.body);
    }

    #[test]
    fn linuxcnc_keeps_both_directions_and_sinumerik_their_mean_with_md32450() {
        // e = 3 + u + 2.4·dir: at x = 0 (u = −1) 4.4 µm forward, −0.4 µm
        // reverse; fwd − rev = 4.8 µm everywhere.
        let m = line_x(3.0, 1.0, 2.4);
        let l = export(&m, Controller::Linuxcnc, &opts()).unwrap();
        assert_eq!(l.body.lines().next(), Some("0.000000 -0.004400 0.000400"));
        assert!(l.machine_data.is_empty() && l.note.is_none());
        assert!((l.backlash_um - 4.8).abs() < 1e-9, "{}", l.backlash_um);
        // Sinumerik: +e, the mean of both directions (2 µm at x = 0); the
        // reversal goes to MD32450 as rev − fwd, in mm.
        let s = export(&m, Controller::Sinumerik, &opts()).unwrap();
        assert!(
            s.body.contains("$AA_ENC_COMP[0,0,AX1]=0.002000\n"),
            "{}",
            s.body
        );
        assert_eq!(s.machine_data["md32450_backlash_mm"], -0.0048);
        let note = s.note.as_deref().unwrap();
        assert!(
            note.contains("MD32450 $MA_BACKLASH = -0.004800 mm"),
            "{note}"
        );
        // The JSON carries it beside the shared keys.
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["md32450_backlash_mm"], -0.0048);
        assert_eq!(json["axis"], "x");
        // The other axes stand where the model does not depend on them.
        assert_eq!(
            json["at_mm"],
            serde_json::json!({"x": 0.0, "y": 0.0, "z": 0.0})
        );
        assert!(json.get("body").is_none() && json.get("note").is_none());
    }

    #[test]
    fn linuxcnc_refuses_more_points_than_it_reads() {
        let m = line_x(3.0, 1.0, 0.0);
        let many = |n| ControllerOptions {
            points: Some(n),
            ..opts()
        };
        let e = export(&m, Controller::Linuxcnc, &many(257)).unwrap_err();
        assert!(
            matches!(
                e,
                FileError::TooManyPoints {
                    controller: "LinuxCNC",
                    points: 257,
                    max: 256
                }
            ),
            "{e}"
        );
        assert_eq!(
            export(&m, Controller::Linuxcnc, &many(256)).unwrap().points,
            256
        );
        // Sinumerik checks no count of its own (the machine data does).
        assert!(export(&m, Controller::Sinumerik, &many(257)).is_ok());
    }

    #[test]
    fn a_file_above_the_limit_given_is_refused_not_clamped() {
        // Largest |e| = 3 + 1 + 2.4 = 6.4 µm (x = 200 forward).
        let m = line_x(3.0, 1.0, 2.4);
        let low = ControllerOptions {
            max_corr_um: Some(5.0),
            ..opts()
        };
        match export(&m, Controller::Sinumerik, &low).unwrap_err() {
            FileError::AboveLimit {
                target: 0,
                format: "sinumerik",
                largest_nm,
                limit_nm,
                ..
            } => {
                assert!((largest_nm - 6400.0).abs() < 1e-6, "{largest_nm}");
                assert_eq!(limit_nm, 5000.0);
            }
            e => panic!("{e}"),
        }
        // The default limit is 1.5 × the largest, which never bites.
        let l = export(&m, Controller::Linuxcnc, &opts()).unwrap();
        assert_eq!(l.max_corr_um, 9.6);
    }

    #[test]
    fn the_axis_is_asked_for_when_the_model_uses_several() {
        let m = linear(0, &[(mono([1, 0, 0]), 2.0), (mono([0, 1, 0]), 1.0)]);
        let e = export(&m, Controller::Linuxcnc, &opts()).unwrap_err();
        assert!(
            matches!(&e, FileError::AxisAmbiguous { used } if used == &[0, 1]),
            "{e}"
        );
        let z = ControllerOptions {
            axis: Some(2),
            ..opts()
        };
        let e = export(&m, Controller::Linuxcnc, &z).unwrap_err();
        assert!(
            matches!(&e, FileError::AxisNotUsed { axis: 2, fitted } if fitted == &[0, 1]),
            "{e}"
        );
        let x = ControllerOptions {
            axis: Some(0),
            ..opts()
        };
        assert_eq!(export(&m, Controller::Linuxcnc, &x).unwrap().axis, 0);
    }

    #[test]
    fn tiny_corrections_are_refused_unless_accepted() {
        let m = line_x(0.01, 0.0, 0.0);
        let e = export(&m, Controller::Linuxcnc, &opts()).unwrap_err();
        match e {
            FileError::Tiny(TinyCorrections { largest_nm }) => {
                assert_eq!(largest_nm.len(), 1);
                assert_eq!(largest_nm[0].0, 0);
                assert!((largest_nm[0].1 - 10.0).abs() < 1e-9);
            }
            e => panic!("{e}"),
        }
        let accept = ControllerOptions {
            accept_tiny: true,
            ..opts()
        };
        assert!(export(&m, Controller::Linuxcnc, &accept).is_ok());
    }

    #[test]
    fn refusals_name_no_command_line_flag() {
        let m = line_x(3.0, 1.0, 2.4);
        let two = linear(0, &[(mono([1, 0, 0]), 2.0), (mono([0, 1, 0]), 1.0)]);
        let refusals = [
            export(&two, Controller::Linuxcnc, &opts()),
            export(
                &m,
                Controller::Linuxcnc,
                &ControllerOptions {
                    axis: Some(1),
                    ..opts()
                },
            ),
            export(
                &m,
                Controller::Linuxcnc,
                &ControllerOptions {
                    points: Some(300),
                    ..opts()
                },
            ),
            export(
                &m,
                Controller::Linuxcnc,
                &ControllerOptions {
                    max_corr_um: Some(1.0),
                    ..opts()
                },
            ),
            export(
                &m,
                Controller::Linuxcnc,
                &ControllerOptions {
                    max_corr_um: Some(0.0),
                    ..opts()
                },
            ),
            export(&line_x(0.01, 0.0, 0.0), Controller::Linuxcnc, &opts()),
        ];
        for r in refusals {
            let e = r.unwrap_err().to_string();
            assert!(!e.contains("--"), "{e}");
        }
    }
}
