//! `trueaxis export` — a fitted model as the firmware table (with the
//! accuracy check of docs/cli.md), a controller's compensation file
//! (LinuxCNC `COMP_FILE_TYPE = 1`, Sinumerik LEC) or a bed mesh. The
//! formats, units, sign conventions and defaults are in
//! docs/export-formats.md.
//!
//! This file parses the flags (and refuses one that does not apply to the
//! format), turns them into the engine's options, and prints what the
//! engine made; every decision — defaults, the checks and refusals, the
//! formats' sign conventions — is the engine's (`trueaxis_engine::export`).
//! The engine words its refusals in its options' terms; here they name the
//! flags.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use serde_json::json;

use crate::cmd::out::outln;
use crate::workflow::{export_table, max_corr_refusal, tiny_refusal, write_file};
use trueaxis_engine::data::{Dataset, AXES, TARGETS};
use trueaxis_engine::export::checks::{axis_list, FileError};
use trueaxis_engine::export::controller::{self, Controller, ControllerOptions};
use trueaxis_engine::export::mesh::{self, MeshFormat, MeshOptions};
use trueaxis_engine::export::skew::{self, SkewFormat, SkewOptions};
use trueaxis_engine::export::table::TableOptions;
use trueaxis_engine::export::{fmt_no_neg_zero, Warning};
use trueaxis_engine::import;
use trueaxis_engine::model::ModelFile;

/// Output format of `trueaxis export`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The trueaxis firmware table (model-core format v1).
    Table,
    /// LinuxCNC screw compensation, COMP_FILE_TYPE = 1, one axis.
    Linuxcnc,
    /// Sinumerik leadscrew error compensation ($AA_ENC_COMP), one axis.
    Sinumerik,
    /// RepRapFirmware bed height map (heightmap.csv, `G29 S1` loads it):
    /// the model's ez over x and y.
    RrfHeightmap,
    /// Klipper bed mesh profile (`#*# [bed_mesh NAME]`, for printer.cfg):
    /// the model's ez over x and y.
    KlipperMesh,
    /// Klipper skew correction (`[skew_correction NAME]` and `SET_SKEW`):
    /// the squarenesses of a rigid21 model.
    KlipperSkew,
    /// Marlin skew correction (`M852 I J K`): the squarenesses of a rigid21
    /// model.
    MarlinSkew,
    /// LinuxCNC matrixkins calibration matrix (`setp matrixkins.C_xy …`):
    /// the squarenesses of a rigid21 model.
    Matrixkins,
}

/// Arguments of `trueaxis export`. Each flag applies to the formats named
/// in its help; one given with another format is a usage error (exit 2),
/// never silently ignored.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The fitted model (MODEL.json written by `trueaxis fit`).
    pub model: PathBuf,
    /// Output file.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    pub format: Format,
    /// [linuxcnc, sinumerik] Axis of the one-axis controller file; default:
    /// the only axis the model uses.
    #[arg(long, value_parser = ["x", "y", "z"])]
    pub axis: Option<String>,
    /// [linuxcnc, sinumerik] Points of the controller table (LinuxCNC reads
    /// at most 256; a Sinumerik 808D at most 200). Default: 201 for
    /// linuxcnc, 200 for sinumerik.
    #[arg(long, allow_negative_numbers = true)]
    pub points: Option<usize>,
    /// [sinumerik] Sinumerik axis name in the table's variables [default: AX1].
    #[arg(long)]
    pub sinumerik_axis: Option<String>,
    /// [rrf-heightmap, klipper-mesh] Nodes of the mesh along x and y, `N`
    /// or `NX,NY` [default: 11,11].
    #[arg(long)]
    pub mesh_points: Option<String>,
    /// [klipper-mesh, klipper-skew] Name of the bed mesh or skew profile
    /// [default: trueaxis].
    #[arg(long)]
    pub profile: Option<String>,
    /// [klipper-skew, marlin-skew, matrixkins] Tool length, mm, at which
    /// what the file leaves out of the model (the tilt and the angles act
    /// through it) is evaluated [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub tool_mm: Option<f64>,
    /// [rrf-heightmap, klipper-mesh] The probed points to check the mesh at
    /// (default: the data the model was fitted to, when that file is found
    /// unchanged).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// [rrf-heightmap, klipper-mesh] Largest accepted departure of the mesh
    /// from a probed reading, µm; above it the mesh is refused [default: 40].
    #[arg(long, allow_negative_numbers = true)]
    pub max_departure_um: Option<f64>,
    /// [every format but the skew ones] Largest |correction| the export may hold, µm (default:
    /// 1.5 × the largest the model asks for, at least 1; at most 4000). The
    /// firmware table clamps there (warned when below the model's largest);
    /// a controller file, which cannot clamp, is refused then.
    #[arg(long, allow_negative_numbers = true)]
    pub max_corr_um: Option<f64>,
    /// [every format but the skew ones] Export even when every correction is below 0.05 µm
    /// (refused otherwise: nothing worth compensating, or errors in mm
    /// written into µm columns).
    #[arg(long)]
    pub accept_tiny_corrections: bool,
    /// [table] Largest change of the correction, nm/ms (default: 1.5 × the
    /// model's largest gradient × --max-feed-mm-per-min).
    #[arg(long, allow_negative_numbers = true)]
    pub max_slew_nm_per_ms: Option<f64>,
    /// [table] The machine's fastest feed, mm/min, for the default slew
    /// limit [default: 10000].
    #[arg(long, allow_negative_numbers = true)]
    pub max_feed_mm_per_min: Option<f64>,
    /// [table] Travel over which a reversal (backlash) correction ramps, µm
    /// [default: 20].
    #[arg(long, allow_negative_numbers = true)]
    pub reversal_transition_um: Option<f64>,
    /// [table] Valid temperature range of every channel, °C, as `LO..HI`
    /// (default: per channel the range measured in the fitted data).
    #[arg(long, allow_hyphen_values = true)]
    pub temp_range_c: Option<String>,
    /// [table] Valid tool-arm range, mm, as `LO..HI` (default 0..300 with an
    /// Abbe term, else 0..0).
    #[arg(long, allow_hyphen_values = true)]
    pub tool_range_mm: Option<String>,
    /// [table] Export a thermal term with a lag as its steady state (the
    /// table has no lag); without it such a model is refused.
    #[arg(long)]
    pub drop_lag: bool,
    /// [table] Largest accepted difference between the firmware's evaluation
    /// (f32 and fixed point) and the host model, nm (a finite number ≥ 0);
    /// above it export fails [default: 1].
    #[arg(long, value_parser = parse_allow_error_nm, allow_negative_numbers = true)]
    pub allow_error_nm: Option<f64>,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--allow-error-nm`: a finite number ≥ 0 — NaN or inf would switch the
/// accuracy check off.
fn parse_allow_error_nm(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("expected a number of nm, found `{s}`"))?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!(
            "expected a finite number of nm ≥ 0, found `{s}` (NaN, inf or a negative limit would switch the accuracy check off or fail every table)"
        ));
    }
    Ok(v)
}

/// The formats each format-specific flag applies to (the rest apply to
/// every format).
const TABLE_ONLY: &[Format] = &[Format::Table];
const CONTROLLERS: &[Format] = &[Format::Linuxcnc, Format::Sinumerik];
const SINUMERIK_ONLY: &[Format] = &[Format::Sinumerik];
const MESHES: &[Format] = &[Format::RrfHeightmap, Format::KlipperMesh];
const KLIPPERS: &[Format] = &[Format::KlipperMesh, Format::KlipperSkew];
const SKEWS: &[Format] = &[Format::KlipperSkew, Format::MarlinSkew, Format::Matrixkins];
const CORRECTION_FILES: &[Format] = &[
    Format::Table,
    Format::Linuxcnc,
    Format::Sinumerik,
    Format::RrfHeightmap,
    Format::KlipperMesh,
];

fn format_name(f: Format) -> &'static str {
    match f {
        Format::Table => "table",
        Format::Linuxcnc => "linuxcnc",
        Format::Sinumerik => "sinumerik",
        Format::RrfHeightmap => "rrf-heightmap",
        Format::KlipperMesh => "klipper-mesh",
        Format::KlipperSkew => "klipper-skew",
        Format::MarlinSkew => "marlin-skew",
        Format::Matrixkins => "matrixkins",
    }
}

/// `--mesh-points`: `N` or `NX,NY`, each 2…[`mesh::MAX_NODES`].
fn parse_mesh_points(s: &str) -> Result<[usize; 2]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let n = |p: &str| -> Result<usize> {
        match p.parse::<usize>() {
            Ok(v) if (2..=mesh::MAX_NODES).contains(&v) => Ok(v),
            _ => bail!(
                "--mesh-points `{s}`: expected N or NX,NY with whole numbers from 2 to {}",
                mesh::MAX_NODES
            ),
        }
    };
    match parts.as_slice() {
        [a] => Ok([n(a)?; 2]),
        [a, b] => Ok([n(a)?, n(b)?]),
        _ => bail!("--mesh-points `{s}`: expected N or NX,NY"),
    }
}

/// The table's creation time: `SOURCE_DATE_EPOCH` when set (the
/// reproducible-builds convention: the same model then gives the same bytes
/// and CRC), else now.
fn created_unix_s() -> Result<i64> {
    match std::env::var("SOURCE_DATE_EPOCH") {
        Ok(v) => v.trim().parse::<i64>().with_context(|| {
            format!("SOURCE_DATE_EPOCH={v:?}: expected whole seconds since 1970-01-01 UTC")
        }),
        Err(_) => Ok(std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64)),
    }
}

impl Args {
    /// The format-specific flags given, with the formats each applies to.
    fn given_flags(&self) -> Vec<(&'static str, &'static [Format], &'static str)> {
        let table_why = "a one-axis controller file has no envelope, temperature, tool or lag input and no firmware accuracy check";
        let mut v = Vec::new();
        let mut flag = |given: bool, name, formats, why| {
            if given {
                v.push((name, formats, why));
            }
        };
        flag(
            self.axis.is_some(),
            "--axis",
            CONTROLLERS,
            "a firmware table holds every axis of the model",
        );
        flag(
            self.points.is_some(),
            "--points",
            CONTROLLERS,
            "only a one-axis controller file is a list of points; a bed mesh takes --mesh-points",
        );
        flag(
            self.sinumerik_axis.is_some(),
            "--sinumerik-axis",
            SINUMERIK_ONLY,
            "only the Sinumerik program names its axis",
        );
        flag(
            self.mesh_points.is_some(),
            "--mesh-points",
            MESHES,
            "only a bed mesh is a grid over x and y",
        );
        flag(
            self.data.is_some(),
            "--data",
            MESHES,
            "only a bed mesh is checked at the probed points",
        );
        flag(
            self.max_departure_um.is_some(),
            "--max-departure-um",
            MESHES,
            "only a bed mesh is checked at the probed points",
        );
        flag(
            self.profile.is_some(),
            "--profile",
            KLIPPERS,
            "only a Klipper mesh or skew correction is a named profile",
        );
        let skew_why = "a skew file holds three factors, not a table of corrections; what it corrects is reported as squareness_um";
        flag(
            self.max_corr_um.is_some(),
            "--max-corr-um",
            CORRECTION_FILES,
            skew_why,
        );
        flag(
            self.accept_tiny_corrections,
            "--accept-tiny-corrections",
            CORRECTION_FILES,
            skew_why,
        );
        flag(
            self.tool_mm.is_some(),
            "--tool-mm",
            SKEWS,
            "only a skew file is evaluated at one tool length",
        );
        flag(
            self.max_slew_nm_per_ms.is_some(),
            "--max-slew-nm-per-ms",
            TABLE_ONLY,
            table_why,
        );
        flag(
            self.max_feed_mm_per_min.is_some(),
            "--max-feed-mm-per-min",
            TABLE_ONLY,
            table_why,
        );
        flag(
            self.reversal_transition_um.is_some(),
            "--reversal-transition-um",
            TABLE_ONLY,
            table_why,
        );
        flag(
            self.temp_range_c.is_some(),
            "--temp-range-c",
            TABLE_ONLY,
            table_why,
        );
        flag(
            self.tool_range_mm.is_some(),
            "--tool-range-mm",
            TABLE_ONLY,
            table_why,
        );
        flag(self.drop_lag, "--drop-lag", TABLE_ONLY, table_why);
        flag(
            self.allow_error_nm.is_some(),
            "--allow-error-nm",
            TABLE_ONLY,
            table_why,
        );
        v
    }

    /// A flag that does not apply to `--format`, as the usage error (exit
    /// 2) it is: a silently ignored flag is a setting the user believes in
    /// and the machine does not have.
    fn check_flags(&self) {
        let Some((name, formats, why)) = self
            .given_flags()
            .into_iter()
            .find(|(_, formats, _)| !formats.contains(&self.format))
        else {
            return;
        };
        let list: Vec<&str> = formats.iter().map(|&f| format_name(f)).collect();
        let msg = format!(
            "{name} applies to --format {} only, not to --format {} ({why})",
            list.join(" and "),
            format_name(self.format)
        );
        let mut cmd = <Args as clap::Args>::augment_args(clap::Command::new("export"))
            .bin_name("trueaxis export");
        crate::cmd::out::usage_exit(
            cmd.error(clap::error::ErrorKind::ArgumentConflict, msg),
            self.json,
        )
    }

    pub fn run(self) -> Result<()> {
        self.check_flags();
        crate::input::refuse_overwrite(
            &[("the model file", &self.model)],
            &[("-o", &self.output)],
        )?;
        let model = crate::input::load_model(&self.model)?;
        let (mut doc, mut warnings, text) = match self.format {
            Format::Table => self.table(&model)?,
            Format::Linuxcnc => self.controller(&model, Controller::Linuxcnc)?,
            Format::Sinumerik => self.controller(&model, Controller::Sinumerik)?,
            Format::RrfHeightmap => self.mesh(&model, MeshFormat::RrfHeightmap)?,
            Format::KlipperMesh => self.mesh(&model, MeshFormat::KlipperMesh)?,
            Format::KlipperSkew => self.skew(&model, SkewFormat::Klipper)?,
            Format::MarlinSkew => self.skew(&model, SkewFormat::Marlin)?,
            Format::Matrixkins => self.skew(&model, SkewFormat::Matrixkins)?,
        };
        // Rows the model was fitted without (outside its travel): every
        // format says so, first.
        if let Some(w) = trueaxis_engine::export::outside_travel(&model) {
            if let Some(list) = doc["warnings"].as_array_mut() {
                list.insert(0, serde_json::to_value(&w)?);
            }
            warnings.insert(0, w);
        }
        for w in &warnings {
            eprintln!("warning ({}): {}", w.code, w.detail);
        }
        if self.json {
            outln!("{doc}")?;
        } else {
            crate::cmd::out::print(&text)?;
        }
        Ok(())
    }

    /// The JSON document (with `format` and `output`) of what the engine
    /// made.
    fn doc(&self, made: &impl serde::Serialize) -> Result<serde_json::Value> {
        let mut doc = serde_json::to_value(made)?;
        doc["format"] = json!(format_name(self.format));
        doc["output"] = json!(self.output.display().to_string());
        Ok(doc)
    }

    /// The firmware table, with the accuracy check.
    fn table(&self, model: &ModelFile) -> Result<Printed> {
        let d = TableOptions::default();
        let opts = TableOptions {
            max_corr_um: self.max_corr_um,
            max_slew_nm_per_ms: self.max_slew_nm_per_ms,
            max_feed_mm_per_min: self.max_feed_mm_per_min.unwrap_or(d.max_feed_mm_per_min),
            reversal_transition_um: self
                .reversal_transition_um
                .unwrap_or(d.reversal_transition_um),
            temp_range_c: self
                .temp_range_c
                .as_deref()
                .map(|s| crate::cmd::parse_range(s, "--temp-range-c"))
                .transpose()?,
            tool_range_mm: self
                .tool_range_mm
                .as_deref()
                .map(|s| crate::cmd::parse_range(s, "--tool-range-mm"))
                .transpose()?,
            drop_lag: self.drop_lag,
            created_unix_s: created_unix_s()?,
            accept_tiny: self.accept_tiny_corrections,
            allow_error_nm: self.allow_error_nm.unwrap_or(d.allow_error_nm),
        };
        let e = export_table(model, &self.output, &opts, opts.allow_error_nm)?;
        let text = format!(
            "{}: {} bytes, crc32 {}, {} terms; firmware vs model over {} points: f32 {:.3} nm, fixed {:.3} nm\n",
            self.output.display(),
            e.bytes,
            e.crc32,
            e.terms,
            e.sweep_points,
            e.max_f32_error_nm,
            e.max_fixed_error_nm
        );
        Ok((self.doc(&e)?, e.warnings.clone(), text))
    }

    /// A controller's one-axis compensation file (docs/export-formats.md).
    fn controller(&self, model: &ModelFile, format: Controller) -> Result<Printed> {
        let opts = ControllerOptions {
            axis: self
                .axis
                .as_deref()
                .map(|a| AXES.iter().position(|x| *x == a).context("axis"))
                .transpose()?,
            points: self.points,
            axis_name: self.sinumerik_axis.clone(),
            max_corr_um: self.max_corr_um,
            accept_tiny: self.accept_tiny_corrections,
        };
        let e =
            controller::export(model, format, &opts).map_err(|e| file_refusal(e, &self.output))?;
        write_file(&self.output, e.body.as_bytes())?;
        let text = format!(
            "{}: {} table for {}, {} points {:.3}…{:.3} mm (step {:.4} mm); the controller's interpolation of it differs from the full model by at most {:.3} µm{}; mean reversal (fwd − rev) {} µm{}\n",
            self.output.display(),
            format_name(self.format),
            AXES[e.axis],
            e.points,
            e.min_mm,
            e.max_mm,
            e.step_mm,
            e.max_interp_error_um,
            if e.terms_left_out() {
                " (terms left out included)"
            } else {
                ""
            },
            fmt_no_neg_zero(e.backlash_um, 3),
            e.note
                .as_deref()
                .map_or(String::new(), |n| format!(" — {n}"))
        );
        Ok((self.doc(&e)?, e.warnings.clone(), text))
    }

    /// A bed mesh (docs/export-formats.md § Bed meshes).
    fn mesh(&self, model: &ModelFile, format: MeshFormat) -> Result<Printed> {
        let opts = MeshOptions {
            nodes: self
                .mesh_points
                .as_deref()
                .map(parse_mesh_points)
                .transpose()?,
            profile: self.profile.clone(),
            source: self.model.display().to_string(),
            max_corr_um: self.max_corr_um,
            accept_tiny: self.accept_tiny_corrections,
            max_departure_um: self.max_departure_um,
        };
        if let Some(v) = self
            .max_departure_um
            .filter(|v| !(v.is_finite() && *v >= 0.0))
        {
            bail!("--max-departure-um {v}: expected a finite number of µm ≥ 0");
        }
        let (probed_data, fitted, mut notes) = self.probed_points(model)?;
        let probed = probed_data
            .as_ref()
            .map(|data| mesh::Probed { data, fitted });
        let mut e = mesh::export(model, format, &opts, probed)
            .map_err(|e| file_refusal(e, &self.output))?;
        write_file(&self.output, e.body.as_bytes())?;
        e.warnings.append(&mut notes);
        let probed_line = e.probed.as_ref().map_or(String::new(), |c| {
            format!(
                "; at the {} probed readings{} it departs from them by at most {:.3} µm at x {:.2}, y {:.2} mm (line {}; the model itself misses that reading by {:.3} µm), RMS {:.3} µm, limit {} µm",
                c.points,
                if c.fitted_data { "" } else { " given" },
                c.max_departure_um,
                c.at_mm[0],
                c.at_mm[1],
                c.line,
                c.model_miss_um,
                c.rms_departure_um,
                c.limit_um
            )
        });
        let text = format!(
            "{}: {}, {} × {} nodes over x {:.2}…{:.2} mm, y {:.2}…{:.2} mm; heights up to {:.3} µm; bilinear interpolation of the nodes differs from the model by at most {:.3} µm{probed_line} (height = −ez: the firmware lifts the tool where ez is negative)\n",
            self.output.display(),
            format_name(self.format),
            e.nodes[0],
            e.nodes[1],
            e.x_mm[0],
            e.x_mm[1],
            e.y_mm[0],
            e.y_mm[1],
            e.largest_height_um,
            e.max_interp_error_um
        );
        Ok((self.doc(&e)?, e.warnings.clone(), text))
    }
}

impl Args {
    /// A skew correction from a rigid21 model's squarenesses, with what it
    /// leaves out (docs/export-formats.md § Skew corrections).
    fn skew(&self, model: &ModelFile, format: SkewFormat) -> Result<Printed> {
        let opts = SkewOptions {
            tool_mm: self.tool_mm.unwrap_or(0.0),
            profile: self.profile.clone(),
        };
        if !opts.tool_mm.is_finite() {
            bail!("--tool-mm {}: expected a finite number of mm", opts.tool_mm);
        }
        let e = skew::export(model, format, &opts).map_err(|e| file_refusal(e, &self.output))?;
        write_file(&self.output, e.body.as_bytes())?;
        let sq: Vec<String> = e
            .squareness_urad
            .iter()
            .map(|(n, v)| format!("{n} {v:.3} µrad"))
            .collect();
        let kinds: Vec<String> = e
            .left_out_by_kind_um
            .iter()
            .map(|(k, v)| format!("{k} {v:.3}"))
            .collect();
        let unknown = if e.cannot_know.is_empty() {
            String::new()
        } else {
            format!(
                "; the data cannot know {} (no value, not counted{})",
                e.cannot_know.join(", "),
                e.hidden_um.map_or(String::new(), |h| format!(
                    "; they may hide up to {h:.3} µm"
                ))
            )
        };
        let text = format!(
            "{}: {} from the squarenesses ({}), which give up to {:.3} µm over the working volume (the numbers as written leave {:.6} µm of it); the model's error, up to {:.3} µm, falls to what the file leaves out, the rest of the model: up to {:.3} µm at x {:.1}, y {:.1}, z {:.1} mm, tool {} mm ({} µm){unknown}\n",
            self.output.display(),
            format_name(self.format),
            sq.join(", "),
            e.squareness_um,
            e.max_written_error_um,
            e.model_um,
            e.left_out_um,
            e.left_out_at_mm[0],
            e.left_out_at_mm[1],
            e.left_out_at_mm[2],
            e.tool_mm,
            kinds.join(", ")
        );
        Ok((self.doc(&e)?, e.warnings.clone(), text))
    }

    /// The probed readings a bed mesh is checked at: `--data`, else the
    /// file the model was fitted to (as fit recorded it, from here or from
    /// the model's folder) when its content is unchanged; whether they are
    /// the fitted data; and the warnings when no check is possible.
    fn probed_points(&self, model: &ModelFile) -> Result<(Option<Dataset>, bool, Vec<Warning>)> {
        let fitted_hash = &model.data.sha256;
        if let Some(path) = &self.data {
            let data = crate::input::load_data(path, None)?;
            let fitted = &import::content_hash(&data) == fitted_hash;
            let mut w = Vec::new();
            if !fitted {
                w.push(Warning::new(
                    "probed_points_other_data",
                    format!(
                        "{} is not the data the model was fitted to ({}): the mesh was checked at its readings",
                        path.display(),
                        model.data.source
                    ),
                ));
            }
            return Ok((Some(data), fitted, w));
        }
        let source = &model.data.source;
        let unchecked = |why: String| {
            Ok((
                None,
                false,
                vec![Warning::new(
                    "probed_points_unchecked",
                    format!("the mesh was not checked at the probed points: {why}; pass --data FILE to check it"),
                )],
            ))
        };
        let stored = Path::new(source);
        let beside = self
            .model
            .parent()
            .map(|dir| dir.join(stored))
            .filter(|_| stored.is_relative());
        let Some(path) = std::iter::once(stored.to_path_buf())
            .chain(beside)
            .find(|p| p.is_file())
        else {
            return unchecked(format!(
                "the data it was fitted to ({source}) are not found"
            ));
        };
        let Ok(data) = import::load_with_axis(&path, None) else {
            return unchecked(format!("the data it was fitted to ({source}) do not read"));
        };
        if &import::content_hash(&data) != fitted_hash {
            return unchecked(format!(
                "{} has changed since the model was fitted to it",
                path.display()
            ));
        }
        Ok((Some(data), true, Vec::new()))
    }
}

/// What a format prints: the JSON document, the warnings, the text.
type Printed = (serde_json::Value, Vec<Warning>, String);

/// A refused controller file or bed mesh in the words of `trueaxis
/// export` (flags named; `output` was not written).
fn file_refusal(e: FileError, output: &Path) -> anyhow::Error {
    let out = output.display();
    let msg = match e {
        FileError::AxisAmbiguous { used } => format!(
            "the model uses the axes {}: say which one with --axis",
            axis_list(&used)
        ),
        FileError::AxisNotUsed { axis, fitted } => format!(
            "the model does not depend on {} (fitted axes: {}); choose --axis among them",
            AXES[axis],
            axis_list(&fitted)
        ),
        FileError::TooManyPoints {
            controller,
            points,
            max,
        } => format!("--points {points}: {controller} reads at most {max} entries"),
        FileError::Tiny(t) => format!("{}; {out} was not written", tiny_refusal(&t)),
        FileError::MaxCorr(m) => format!("{}; {out} was not written", max_corr_refusal(&m)),
        FileError::AboveLimit {
            target,
            format,
            holder,
            largest_nm,
            limit_nm,
        } => format!(
            "{}: the {format} file would hold corrections up to {:.3} µm, above --max-corr-um {}: {holder} cannot clamp, so {out} was not written — check the model, or raise --max-corr-um",
            TARGETS[target],
            largest_nm / 1000.0,
            limit_nm / 1000.0
        ),
        e @ FileError::Departs { .. } => format!(
            "{e}; {out} was not written — add nodes (--mesh-points), fit a model that follows the readings (a grid model), or accept it with --max-departure-um"
        ),
        e @ FileError::CannotKnow { .. } => format!("{e}; {out} was not written"),
        FileError::Other(e) => return e,
    };
    anyhow!(msg)
}
