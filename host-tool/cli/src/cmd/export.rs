//! `trueaxis export` — a fitted model as the firmware table (with the
//! accuracy check of docs/cli.md) or as a controller's compensation file
//! (LinuxCNC `COMP_FILE_TYPE = 1`, Sinumerik LEC). The formats, units, sign
//! conventions and envelope defaults are in docs/export-formats.md.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out::outln;
use crate::workflow::{export_table, write_file};
use trueaxis_engine::data::{AXES, TARGETS};
use trueaxis_engine::export::table::TableOptions;
use trueaxis_engine::export::{
    bedmesh, crc32_hex, fmt_no_neg_zero, linuxcnc, sample_axis, sinumerik, Warning,
};
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
    /// [klipper-mesh] Name of the bed mesh profile [default: trueaxis].
    #[arg(long)]
    pub profile: Option<String>,
    /// [every format] Largest |correction| the export may hold, µm (default:
    /// 1.5 × the largest the model asks for, at least 1; at most 4000). The
    /// firmware table clamps there (warned when below the model's largest);
    /// a controller file, which cannot clamp, is refused then.
    #[arg(long, allow_negative_numbers = true)]
    pub max_corr_um: Option<f64>,
    /// [every format] Export even when every correction is below 0.05 µm
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
const KLIPPER_ONLY: &[Format] = &[Format::KlipperMesh];

fn format_name(f: Format) -> &'static str {
    match f {
        Format::Table => "table",
        Format::Linuxcnc => "linuxcnc",
        Format::Sinumerik => "sinumerik",
        Format::RrfHeightmap => "rrf-heightmap",
        Format::KlipperMesh => "klipper-mesh",
    }
}

/// `--mesh-points`: `N` or `NX,NY`, each 2…100.
fn parse_mesh_points(s: &str) -> Result<[usize; 2]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let n = |p: &str| -> Result<usize> {
        match p.parse::<usize>() {
            Ok(v) if (2..=100).contains(&v) => Ok(v),
            _ => bail!("--mesh-points `{s}`: expected N or NX,NY with whole numbers from 2 to 100"),
        }
    };
    match parts.as_slice() {
        [a] => Ok([n(a)?; 2]),
        [a, b] => Ok([n(a)?, n(b)?]),
        _ => bail!("--mesh-points `{s}`: expected N or NX,NY"),
    }
}

fn parse_range(s: &str, what: &str) -> Result<(f64, f64)> {
    let (a, b) = s
        .split_once("..")
        .with_context(|| format!("{what} `{s}`: expected LO..HI"))?;
    let lo: f64 = a
        .trim()
        .parse()
        .with_context(|| format!("{what} `{s}`: `{a}` is not a number"))?;
    let hi: f64 = b
        .trim()
        .parse()
        .with_context(|| format!("{what} `{s}`: `{b}` is not a number"))?;
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        bail!("{what} `{s}`: expected finite LO ≤ HI");
    }
    Ok((lo, hi))
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
            self.profile.is_some(),
            "--profile",
            KLIPPER_ONLY,
            "only a Klipper mesh is a named profile",
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
        cmd.error(clap::error::ErrorKind::ArgumentConflict, msg)
            .exit()
    }

    pub fn run(self) -> Result<()> {
        self.check_flags();
        crate::input::refuse_overwrite(
            &[("the model file", &self.model)],
            &[("-o", &self.output)],
        )?;
        let model = ModelFile::load(&self.model)?;
        let (doc, warnings, text) = match self.format {
            Format::Table => {
                let opts = TableOptions {
                    max_corr_um: self.max_corr_um,
                    max_slew_nm_per_ms: self.max_slew_nm_per_ms,
                    max_feed_mm_per_min: self.max_feed_mm_per_min.unwrap_or(10_000.0),
                    reversal_transition_um: self.reversal_transition_um.unwrap_or(20.0),
                    temp_range_c: self
                        .temp_range_c
                        .as_deref()
                        .map(|s| parse_range(s, "--temp-range-c"))
                        .transpose()?,
                    tool_range_mm: self
                        .tool_range_mm
                        .as_deref()
                        .map(|s| parse_range(s, "--tool-range-mm"))
                        .transpose()?,
                    drop_lag: self.drop_lag,
                    created_unix_s: created_unix_s()?,
                    accept_tiny: self.accept_tiny_corrections,
                };
                let e = export_table(
                    &model,
                    &self.output,
                    &opts,
                    self.allow_error_nm.unwrap_or(1.0),
                )?;
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
                let mut doc = serde_json::to_value(&e)?;
                doc["format"] = json!("table");
                doc["output"] = json!(self.output.display().to_string());
                (doc, e.warnings.clone(), text)
            }
            Format::Linuxcnc | Format::Sinumerik => self.controller(&model)?,
            Format::RrfHeightmap | Format::KlipperMesh => self.mesh(&model)?,
        };
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

    /// A bed mesh (docs/export-formats.md § Bed meshes): the model's ez on an
    /// x–y grid, with the max-correction rule of the controller files.
    fn mesh(&self, model: &ModelFile) -> Result<(serde_json::Value, Vec<Warning>, String)> {
        let counts = match self.mesh_points.as_deref() {
            Some(s) => parse_mesh_points(s)?,
            None => [11, 11],
        };
        let m = bedmesh::sample_mesh(model, counts)?;
        let name = format_name(self.format);
        let ez_nm: Vec<f64> = m.height_mm.iter().flatten().map(|h| -1e6 * h).collect();
        trueaxis_engine::export::refuse_tiny(
            &[None, None, Some(ez_nm)],
            self.accept_tiny_corrections,
        )
        .map_err(|e| anyhow::anyhow!("{e:#}; {} was not written", self.output.display()))?;
        let largest_nm = m
            .height_mm
            .iter()
            .flatten()
            .fold(0.0f64, |a, h| a.max(1e6 * h.abs()));
        let max_corr_nm =
            trueaxis_engine::export::max_corr_limit_nm(2, largest_nm, self.max_corr_um)
                .map_err(|e| anyhow::anyhow!("{e:#}; {} was not written", self.output.display()))?;
        if largest_nm > max_corr_nm {
            bail!(
                "ez: the {name} file would hold corrections up to {:.3} µm, above --max-corr-um {}: a firmware's bed mesh cannot clamp, so {} was not written — check the model, or raise --max-corr-um",
                largest_nm / 1000.0,
                max_corr_nm / 1000.0,
                self.output.display()
            );
        }
        let body = if self.format == Format::RrfHeightmap {
            bedmesh::write_rrf(
                &m,
                &format!("generated by trueaxis from {}", self.model.display()),
            )
        } else {
            bedmesh::write_klipper(&m, self.profile.as_deref().unwrap_or("trueaxis"))?
        };
        write_file(&self.output, body.as_bytes())?;
        let (nx, ny) = (m.x_mm.len(), m.y_mm.len());
        let doc = json!({
            "format": name,
            "output": self.output.display().to_string(),
            "nodes": [nx, ny],
            "x_mm": [m.x_mm[0], m.x_mm[nx - 1]],
            "y_mm": [m.y_mm[0], m.y_mm[ny - 1]],
            "spacing_mm": [m.x_mm[1] - m.x_mm[0], m.y_mm[1] - m.y_mm[0]],
            "z_mm": m.z_mm,
            "bytes": body.len(),
            "crc32": crc32_hex(body.as_bytes()),
            "max_interp_error_um": m.max_interp_error_um,
            "max_corr_um": max_corr_nm.ceil() / 1000.0,
            "largest_height_um": largest_nm / 1000.0,
            "warnings": m.warnings,
        });
        let text = format!(
            "{}: {name}, {nx} × {ny} nodes over x {:.2}…{:.2} mm, y {:.2}…{:.2} mm; heights up to {:.3} µm; bilinear interpolation of the nodes differs from the model by at most {:.3} µm (height = −ez: the firmware lifts the tool where ez is negative)\n",
            self.output.display(),
            m.x_mm[0],
            m.x_mm[nx - 1],
            m.y_mm[0],
            m.y_mm[ny - 1],
            largest_nm / 1000.0,
            m.max_interp_error_um
        );
        Ok((doc, m.warnings.clone(), text))
    }

    fn controller(&self, model: &ModelFile) -> Result<(serde_json::Value, Vec<Warning>, String)> {
        let axis = match self.axis.as_deref() {
            Some(a) => AXES.iter().position(|x| *x == a).context("axis")?,
            None => {
                let used: Vec<usize> = (0..3)
                    .filter(|&a| trueaxis_engine::export::axis_travel_mm(&model.model, a).is_some())
                    .collect();
                match used.as_slice() {
                    [a] => *a,
                    _ => bail!(
                        "the model uses the axes {}: say which one with --axis",
                        used.iter().map(|&a| AXES[a]).collect::<Vec<_>>().join(", ")
                    ),
                }
            }
        };
        let linux = self.format == Format::Linuxcnc;
        let points = self.points.unwrap_or(if linux { 201 } else { 200 });
        if linux && points > linuxcnc::MAX_ENTRIES {
            bail!(
                "--points {points}: LinuxCNC reads at most {} entries",
                linuxcnc::MAX_ENTRIES
            );
        }
        let s = sample_axis(model, axis, points)?;
        let name = format_name(self.format);
        let corr_nm: Vec<f64> = s
            .err_fwd_um
            .iter()
            .chain(&s.err_rev_um)
            .map(|v| 1000.0 * v)
            .collect();
        let mut host: [Option<Vec<f64>>; 3] = [None, None, None];
        host[axis] = Some(corr_nm);
        trueaxis_engine::export::refuse_tiny(&host, self.accept_tiny_corrections)
            .map_err(|e| anyhow::anyhow!("{e:#}; {} was not written", self.output.display()))?;
        // The same max-correction rule as the firmware table, on the values
        // the file holds (the controller interpolates between them, so they
        // bound what it applies). A controller file cannot clamp: above an
        // explicit --max-corr-um it is refused, not written.
        let largest_nm = s
            .err_fwd_um
            .iter()
            .chain(&s.err_rev_um)
            .fold(0.0f64, |m, v| m.max(1000.0 * v.abs()));
        let max_corr_nm =
            trueaxis_engine::export::max_corr_limit_nm(axis, largest_nm, self.max_corr_um)
                .map_err(|e| anyhow::anyhow!("{e:#}; {} was not written", self.output.display()))?;
        if largest_nm > max_corr_nm {
            bail!(
                "{}: the {name} file would hold corrections up to {:.3} µm, above --max-corr-um {}: a controller's compensation table cannot clamp, so {} was not written — check the model, or raise --max-corr-um",
                TARGETS[axis],
                largest_nm / 1000.0,
                max_corr_nm / 1000.0,
                self.output.display()
            );
        }
        let body = if linux {
            linuxcnc::write(&s.nominal_mm, &s.err_fwd_um, &s.err_rev_um)?
        } else {
            let mean: Vec<f64> = s
                .err_fwd_um
                .iter()
                .zip(&s.err_rev_um)
                .map(|(f, r)| 0.5 * (f + r))
                .collect();
            let step =
                (s.nominal_mm[s.nominal_mm.len() - 1] - s.nominal_mm[0]) / (points - 1) as f64;
            sinumerik::write(
                self.sinumerik_axis.as_deref().unwrap_or("AX1"),
                s.nominal_mm[0],
                step,
                &mean,
            )?
        };
        write_file(&self.output, body.as_bytes())?;
        // The reversal part (forward − reverse), which Sinumerik keeps in MD32450.
        let backlash: Vec<f64> = s
            .err_fwd_um
            .iter()
            .zip(&s.err_rev_um)
            .map(|(f, r)| f - r)
            .collect();
        // + 0.0 turns a −0 into 0 (a −0.0 in JSON or text reads as a sign).
        let backlash_mean_um = backlash.iter().sum::<f64>() / backlash.len() as f64 + 0.0;
        let step_mm = (s.nominal_mm[points - 1] - s.nominal_mm[0]) / (points - 1) as f64;
        // What the file says: Sinumerik's _MIN/_STEP are rounded to the
        // written 1 nm and _MAX follows from them (see `sinumerik::write`).
        let (min_mm, step_mm, max_mm) = if linux {
            (s.nominal_mm[0], step_mm, s.nominal_mm[points - 1])
        } else {
            let (lo, st) = (
                sinumerik::written_mm(s.nominal_mm[0]),
                sinumerik::written_mm(step_mm),
            );
            (lo, st, lo + st * (points - 1) as f64)
        };
        // Siemens enters MD32450 positive when "the encoder is leading the
        // machine part (normal situation)": the slide falls short in the
        // direction of travel, e_fwd < 0 < e_rev. So the value is rev − fwd,
        // the opposite sign of `backlash_um`, in mm.
        // Rounded to the 1 nm the value is given in, without a −0.
        let md32450_mm = sinumerik::written_mm(-backlash_mean_um * 1e-3) + 0.0;
        let mut doc = json!({
            "format": name,
            "output": self.output.display().to_string(),
            "axis": AXES[axis],
            "points": points,
            "min_mm": min_mm,
            "max_mm": max_mm,
            "step_mm": step_mm,
            "at_mm": {"x": s.at_mm[0], "y": s.at_mm[1], "z": s.at_mm[2]},
            "bytes": body.len(),
            "crc32": crc32_hex(body.as_bytes()),
            "max_interp_error_um": s.max_interp_error_um,
            // Whole nm, rounded up as the table's.
            "max_corr_um": max_corr_nm.ceil() / 1000.0,
            "backlash_um": backlash_mean_um,
            "warnings": s.warnings,
        });
        if !linux {
            doc["md32450_backlash_mm"] = json!(md32450_mm);
        }
        let text = format!(
            "{}: {name} table for {}, {points} points {:.3}…{:.3} mm (step {step_mm:.4} mm); the controller's interpolation of it differs from the full model by at most {:.3} µm{}; mean reversal (fwd − rev) {} µm{}\n",
            self.output.display(),
            AXES[axis],
            min_mm,
            max_mm,
            s.max_interp_error_um,
            if s.warnings.iter().any(|w| w.code.ends_with("_left_out")) {
                " (terms left out included)"
            } else {
                ""
            },
            fmt_no_neg_zero(backlash_mean_um, 3),
            if linux {
                String::new()
            } else {
                format!(" — the table holds the mean of both directions; set MD32450 $MA_BACKLASH = {} mm (rev − fwd: positive when the axis falls short in the direction of travel, Siemens' normal case)", fmt_no_neg_zero(md32450_mm, 6))
            }
        );
        Ok((doc, s.warnings.clone(), text))
    }
}
