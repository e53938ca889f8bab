//! `trueaxis export` — a fitted model as the firmware table (with the
//! accuracy check of CONTRACT §2) or as a controller's compensation file
//! (LinuxCNC `COMP_FILE_TYPE = 1`, Sinumerik LEC). The formats, units, sign
//! conventions and envelope defaults are in docs/export-formats.md.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out::outln;
use crate::data::AXES;
use crate::export::table::{self, TableExport, TableOptions};
use crate::export::{crc32_hex, linuxcnc, sample_axis, sinumerik, Warning};
use crate::model::ModelFile;

/// Output format of `trueaxis export`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The trueaxis firmware table (model-core format v1).
    Table,
    /// LinuxCNC screw compensation, COMP_FILE_TYPE = 1, one axis.
    Linuxcnc,
    /// Sinumerik leadscrew error compensation ($AA_ENC_COMP), one axis.
    Sinumerik,
}

/// Arguments of `trueaxis export`.
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
    /// Axis of a one-axis controller file (linuxcnc, sinumerik); default:
    /// the only axis the model uses.
    #[arg(long, value_parser = ["x", "y", "z"])]
    pub axis: Option<String>,
    /// Points of a controller table (LinuxCNC reads at most 256; a Sinumerik
    /// 808D at most 200). Default: 201 for linuxcnc, 200 for sinumerik.
    #[arg(long)]
    pub points: Option<usize>,
    /// Sinumerik axis name in the table's variables.
    #[arg(long, default_value = "AX1")]
    pub sinumerik_axis: String,
    /// Largest |correction| the firmware may apply, µm (default: 1.5 × the
    /// model's largest over the envelope).
    #[arg(long)]
    pub max_corr_um: Option<f64>,
    /// Largest change of the correction, nm/ms (default: 1.5 × the model's
    /// largest gradient × --max-feed-mm-per-min).
    #[arg(long)]
    pub max_slew_nm_per_ms: Option<f64>,
    /// The machine's fastest feed, mm/min, for the default slew limit.
    #[arg(long, default_value_t = 10_000.0)]
    pub max_feed_mm_per_min: f64,
    /// Travel over which a reversal (backlash) correction ramps, µm.
    #[arg(long, default_value_t = 20.0)]
    pub reversal_transition_um: f64,
    /// Valid temperature range of every channel, °C, as `LO..HI`.
    #[arg(long, default_value = "10..40")]
    pub temp_range_c: String,
    /// Valid tool-arm range, mm, as `LO..HI` (default 0..300 with an Abbe
    /// term, else 0..0).
    #[arg(long)]
    pub tool_range_mm: Option<String>,
    /// Export a thermal term with a lag as its steady state (the table has
    /// no lag); without it such a model is refused.
    #[arg(long)]
    pub drop_lag: bool,
    /// Largest accepted difference between the firmware's evaluation (f32
    /// and fixed point) and the host model, nm; above it export fails.
    #[arg(long, default_value_t = 1.0)]
    pub allow_error_nm: f64,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
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

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// Exports `model` as a firmware table to `output` and fails when the
/// accuracy check is above `allow_error_nm` (the file is not written then).
/// The building block `export` and `demo` share.
pub fn export_table(
    model: &ModelFile,
    output: &Path,
    opts: &TableOptions,
    allow_error_nm: f64,
) -> Result<TableExport> {
    let e = table::export(model, opts)?;
    let worst = e.max_f32_error_nm.max(e.max_fixed_error_nm);
    if worst.is_nan() || worst > allow_error_nm {
        bail!(
            "accuracy check failed: the firmware's evaluation differs from the model by up to {worst:.3} nm (f32 {:.3}, fixed {:.3}) over {} sweep points, above the {allow_error_nm} nm allowed (--allow-error-nm); {} was not written",
            e.max_f32_error_nm,
            e.max_fixed_error_nm,
            e.sweep_points,
            output.display()
        );
    }
    write_file(output, &e.table)?;
    Ok(e)
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
    pub fn run(self) -> Result<()> {
        crate::cmd::input::refuse_overwrite(
            &[("the model file", &self.model)],
            &[("-o", &self.output)],
        )?;
        let model = ModelFile::load(&self.model)?;
        let (doc, warnings, text) = match self.format {
            Format::Table => {
                if let Some(a) = &self.axis {
                    bail!(
                        "--axis {a} applies to the one-axis controller formats (linuxcnc, sinumerik); a firmware table holds every axis of the model"
                    );
                }
                let opts = TableOptions {
                    max_corr_um: self.max_corr_um,
                    max_slew_nm_per_ms: self.max_slew_nm_per_ms,
                    max_feed_mm_per_min: self.max_feed_mm_per_min,
                    reversal_transition_um: self.reversal_transition_um,
                    temp_range_c: parse_range(&self.temp_range_c, "--temp-range-c")?,
                    tool_range_mm: self
                        .tool_range_mm
                        .as_deref()
                        .map(|s| parse_range(s, "--tool-range-mm"))
                        .transpose()?,
                    drop_lag: self.drop_lag,
                    created_unix_s: created_unix_s()?,
                };
                let e = export_table(&model, &self.output, &opts, self.allow_error_nm)?;
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

    fn controller(&self, model: &ModelFile) -> Result<(serde_json::Value, Vec<Warning>, String)> {
        let axis = match self.axis.as_deref() {
            Some(a) => AXES.iter().position(|x| *x == a).context("axis")?,
            None => {
                let used: Vec<usize> = (0..3)
                    .filter(|&a| crate::export::axis_travel_mm(&model.model, a).is_some())
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
        let (body, name) = if linux {
            (
                linuxcnc::write(&s.nominal_mm, &s.err_fwd_um, &s.err_rev_um)?,
                "linuxcnc",
            )
        } else {
            let mean: Vec<f64> = s
                .err_fwd_um
                .iter()
                .zip(&s.err_rev_um)
                .map(|(f, r)| 0.5 * (f + r))
                .collect();
            let step =
                (s.nominal_mm[s.nominal_mm.len() - 1] - s.nominal_mm[0]) / (points - 1) as f64;
            (
                sinumerik::write(&self.sinumerik_axis, s.nominal_mm[0], step, &mean)?,
                "sinumerik",
            )
        };
        write_file(&self.output, body.as_bytes())?;
        // The reversal part (forward − reverse), which Sinumerik keeps in MD32450.
        let backlash: Vec<f64> = s
            .err_fwd_um
            .iter()
            .zip(&s.err_rev_um)
            .map(|(f, r)| f - r)
            .collect();
        let backlash_mean_um = backlash.iter().sum::<f64>() / backlash.len() as f64;
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
        let md32450_mm = -backlash_mean_um * 1e-3;
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
            "backlash_um": backlash_mean_um,
            "warnings": s.warnings,
        });
        if !linux {
            doc["md32450_backlash_mm"] = json!(md32450_mm);
        }
        let text = format!(
            "{}: {name} table for {}, {points} points {:.3}…{:.3} mm (step {step_mm:.4} mm); linear interpolation loses at most {:.3} µm against the model; mean reversal (fwd − rev) {backlash_mean_um:.3} µm{}\n",
            self.output.display(),
            AXES[axis],
            min_mm,
            max_mm,
            s.max_interp_error_um,
            if linux {
                String::new()
            } else {
                format!(" — the table holds the mean of both directions; set MD32450 $MA_BACKLASH = {md32450_mm:.6} mm (rev − fwd: positive when the axis falls short in the direction of travel, Siemens' normal case)")
            }
        );
        Ok((doc, s.warnings.clone(), text))
    }
}
