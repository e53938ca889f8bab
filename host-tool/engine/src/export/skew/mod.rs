//! The linear part of a `rigid21` model as the skew correction of an
//! open-source controller (docs/export-formats.md § Skew): Klipper
//! `[skew_correction]` (a profile and the equivalent `SET_SKEW`), Marlin
//! `M852` and LinuxCNC `matrixkins`. Each holds the three squarenesses
//! (C0Y, B0Z, A0Z) and nothing else; what it leaves out of the model —
//! positioning, straightness, the angles through their arms, the spindle
//! tilt at the tool length — is measured over the working volume and
//! reported, and an error the data cannot determine is never written.
//!
//! **The firmware's model.** All three apply a shear to the requested
//! position p and command q = F·p, assuming the machine puts the tool at
//! U·q with U = [[1, k_xy, k_xz], [0, 1, k_yz], [0, 0, 1]] (Klipper's
//! `calc_unskew`, Marlin's `unskew`; matrixkins' joints = C·p with C = U⁻¹).
//! The model's squareness part is e = S·q (µm, q in mm; docs/volumetric.md):
//! e_x = −C0Y·y + B0Z·z, e_y = −A0Z·z (µrad·mm·1e-3), so
//! k_xy = −C0Y·1e-6, k_xz = B0Z·1e-6, k_yz = −A0Z·1e-6 make U = I + S
//! exactly, and the corrected tool point U·F·p is p.
//!
//! The check before anything is returned: the written numbers (as the file
//! states them, rounded) are applied the way each firmware does to a grid
//! over the working volume, and what the machine's squareness (the
//! model's) then leaves is `max_written_error_um` — round-off.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use anyhow::anyhow;
use serde::Serialize;

use super::checks::FileError;
use super::{crc32_hex, Warning};
use crate::model::rigid21::{ErrorKind, Rigid21Model, Status, ToolPoint};
use crate::model::{FittedModel, ModelFile};

/// The skew formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SkewFormat {
    /// Klipper `[skew_correction NAME]` profile (+ the `SET_SKEW` line).
    Klipper,
    /// Marlin `M852 I J K`.
    Marlin,
    /// LinuxCNC `matrixkins` HAL parameters `C_xx` … `C_zz`.
    Matrixkins,
}

impl SkewFormat {
    /// The format's name (`klipper-skew`): the JSON's `format`.
    pub fn name(self) -> &'static str {
        match self {
            SkewFormat::Klipper => "klipper-skew",
            SkewFormat::Marlin => "marlin-skew",
            SkewFormat::Matrixkins => "matrixkins",
        }
    }
}

/// The Klipper profile's name when none is given.
pub const DEFAULT_PROFILE: &str = "trueaxis";

/// Side of the virtual square whose diagonals `SET_SKEW` is given, mm.
pub const SQUARE_SIDE_MM: f64 = 100.0;

/// Points per axis of the grid over the working volume on which what the
/// file leaves out is measured.
const GRID: usize = 9;

/// Options of a skew export.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SkewOptions {
    /// Tool length at which what the file leaves out is evaluated, mm (the
    /// firmware has no tool length: the tilt and the angles act through it).
    pub tool_mm: f64,
    /// Klipper profile name; `None` = [`DEFAULT_PROFILE`].
    pub profile: Option<String>,
}

/// A skew export and what it leaves out (the JSON without `format` and
/// `output`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SkewExport {
    /// The squarenesses written, µrad, by ISO 230-1 name (those of the
    /// model's chain).
    pub squareness_urad: BTreeMap<String, f64>,
    /// The numbers the file holds, as written: Klipper/Marlin the skew
    /// factors `xy`, `xz`, `yz`; matrixkins `C_xy`, `C_xz`, `C_yz` (the
    /// other entries are the identity's).
    pub factors: BTreeMap<String, f64>,
    /// Size of the file, bytes.
    pub bytes: usize,
    /// CRC-32 of the file, `0x…`.
    pub crc32: String,
    /// The largest error the squarenesses give over the working volume
    /// (vector length), µm: what the file corrects.
    pub squareness_um: f64,
    /// Largest |squareness part − what the firmware removes with the
    /// numbers as written| over the volume, µm (round-off).
    pub max_written_error_um: f64,
    /// Tool length the rest is evaluated at, mm.
    pub tool_mm: f64,
    /// The largest error of the whole model over the working volume at
    /// `tool_mm` (vector length), µm: before the file.
    pub model_um: f64,
    /// The largest error of the model the file leaves out over the working
    /// volume at `tool_mm` (vector length), µm.
    pub left_out_um: f64,
    /// Where, mm (axis positions).
    pub left_out_at_mm: [f64; 3],
    /// The same per kind of error left out: `positioning`, `straightness`,
    /// `angles` (through their arms), `tilt` (µm each, their own maxima).
    pub left_out_by_kind_um: BTreeMap<&'static str, f64>,
    /// Errors of the model the data cannot determine (not in the file, not
    /// in `left_out_um`: no value exists for them).
    pub cannot_know: Vec<String>,
    /// The model's own `hidden_um`: the largest error these data cannot
    /// see at realistic sizes (fit's identifiability answer), µm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hidden_um: Option<f64>,
    /// What was left out or set, and why.
    pub warnings: Vec<Warning>,
    /// The file's text.
    #[serde(skip)]
    pub body: String,
}

/// The shear k_xy, k_xz, k_yz of the model's squarenesses (see the module
/// docs); `None` for a pair the chain lacks.
type Shear = [Option<f64>; 3];

const PAIRS: [(&str, &str); 3] = [("C0Y", "xy"), ("B0Z", "xz"), ("A0Z", "yz")];

/// Where the measurement that fixes a squareness comes from.
fn what_tells(name: &str) -> &'static str {
    match name {
        "C0Y" => "C0Y: XY face diagonals (ISO 230-6), a square artefact in XY, or tracker stations",
        "B0Z" => "B0Z: XZ face diagonals, a square artefact in XZ, or tracker stations",
        _ => "A0Z: YZ face diagonals, a square artefact in YZ, or tracker stations",
    }
}

/// Makes the skew file of `file` (a rigid21 model). Refused: another kind
/// of model; a squareness the data cannot determine (naming what to
/// measure). Nothing is written: the caller writes [`SkewExport::body`].
pub fn export(
    file: &ModelFile,
    format: SkewFormat,
    opts: &SkewOptions,
) -> Result<SkewExport, FileError> {
    let FittedModel::Rigid21(m) = &file.model else {
        return Err(anyhow!(
            "the {} export takes the squarenesses of a rigid21 model; this is a {} model: fit a rigid21 model",
            format.name(),
            file.model.kind()
        )
        .into());
    };
    if !opts.tool_mm.is_finite() {
        return Err(anyhow!("tool length {} mm: expected a finite number", opts.tool_mm).into());
    }
    let unknown: Vec<String> = PAIRS
        .iter()
        .filter_map(|(n, _)| m.error(n))
        .filter(|e| e.status == Status::CannotKnow)
        .map(|e| e.name.clone())
        .collect();
    if !unknown.is_empty() {
        return Err(FileError::CannotKnow {
            format: format.name(),
            names: unknown.clone(),
            measure: unknown
                .iter()
                .map(|n| what_tells(n))
                .collect::<Vec<_>>()
                .join("; "),
        });
    }
    let mut squareness_urad = BTreeMap::new();
    let mut shear: Shear = [None; 3];
    for (i, (name, _)) in PAIRS.iter().enumerate() {
        if let Some(e) = m.error(name) {
            let v = m.value(e, [0.0; 3]).unwrap_or(0.0);
            squareness_urad.insert(name.to_string(), v);
            shear[i] = Some((if i == 1 { v } else { -v }) * 1e-6);
        }
    }
    let mut warnings = Vec::new();
    let missing: Vec<&str> = PAIRS
        .iter()
        .zip(&shear)
        .filter(|(_, k)| k.is_none())
        .map(|((n, _), _)| *n)
        .collect();
    if !missing.is_empty() {
        warnings.push(Warning::new(
            "squareness_not_in_model",
            format!(
                "the model's chain has no {}: those skews are not corrected (left at the firmware's 0)",
                missing.join(", ")
            ),
        ));
    }
    let (body, factors, applied) = match format {
        SkewFormat::Klipper => {
            let profile = opts.profile.as_deref().unwrap_or(DEFAULT_PROFILE);
            write_klipper(&shear, &squareness_urad, profile).map_err(FileError::Other)?
        }
        SkewFormat::Marlin => write_marlin(&shear, &squareness_urad),
        SkewFormat::Matrixkins => write_matrixkins(&shear, &squareness_urad),
    };
    let grid = volume_grid(m);
    let max_written_error_um = applied
        .iter()
        .map(|f| residual_after(m, &grid, f))
        .fold(0.0, f64::max);
    let rest = left_out(m, &grid, opts.tool_mm);
    let cannot_know: Vec<String> = m
        .errors()
        .filter(|e| e.status == Status::CannotKnow)
        .map(|e| e.name.clone())
        .collect();
    Ok(SkewExport {
        squareness_urad,
        factors,
        bytes: body.len(),
        crc32: crc32_hex(body.as_bytes()),
        squareness_um: rest.squareness_um,
        max_written_error_um,
        tool_mm: opts.tool_mm,
        model_um: rest.model_um,
        left_out_um: rest.total_um,
        left_out_at_mm: rest.at_mm,
        left_out_by_kind_um: rest.by_kind_um,
        cannot_know,
        hidden_um: file.stats.volumetric.as_ref().map(|v| v.hidden_um),
        warnings,
        body,
    })
}

/// How a firmware turns a requested position p (mm) into the commanded
/// one, with the numbers as its file states them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Applied {
    /// Klipper `calc_skew` / Marlin `skew`: factors xy, xz, yz.
    Shear([f64; 3]),
    /// matrixkins `kinematicsInverse`: joints = C·p.
    Matrix([[f64; 3]; 3]),
}

impl Applied {
    /// The commanded position for the requested `p`.
    pub fn command(&self, p: [f64; 3]) -> [f64; 3] {
        match self {
            Applied::Shear([xy, xz, yz]) => [
                p[0] - p[1] * xy - p[2] * (xz - xy * yz),
                p[1] - p[2] * yz,
                p[2],
            ],
            Applied::Matrix(c) => [0, 1, 2].map(|r| (0..3).map(|k| c[r][k] * p[k]).sum()),
        }
    }
}

/// The factor as the file writes it (`decimals` decimals) and read back.
fn written(v: f64, decimals: usize) -> (String, f64) {
    let s = super::fmt_no_neg_zero(v, decimals);
    let back = s.parse().unwrap_or(v);
    (s, back)
}

/// The file's opening comment lines (COMMENT starts each): what it is, what
/// it leaves out, then `first_note`.
fn header(comment: &str, sq: &BTreeMap<String, f64>, first_note: &str) -> String {
    let mut out = String::new();
    let list: Vec<String> = sq
        .iter()
        .map(|(n, v)| format!("{n} = {v:.3} µrad"))
        .collect();
    let _ = writeln!(
        out,
        "{comment} trueaxis: skew correction from the squarenesses of a rigid21 model ({})",
        list.join(", ")
    );
    let _ = writeln!(
        out,
        "{comment} only the squareness: positioning, straightness, angles and tilt are left out (the export reports how much: left_out_um)"
    );
    let _ = writeln!(out, "{first_note}");
    out
}

/// Klipper: a `[skew_correction NAME]` profile (the factors
/// `SKEW_PROFILE LOAD=NAME` loads) and, as a comment, the `SET_SKEW` of a
/// virtual square of side [`SQUARE_SIDE_MM`] with the same factors.
fn write_klipper(
    shear: &Shear,
    sq: &BTreeMap<String, f64>,
    profile: &str,
) -> anyhow::Result<(String, BTreeMap<String, f64>, Vec<Applied>)> {
    // `SKEW_PROFILE LOAD=NAME` reads one word: a name with a space could
    // be written but never loaded.
    if profile.is_empty() || profile.contains(|c: char| c == ']' || c.is_whitespace()) {
        anyhow::bail!(
            "Klipper profile name `{profile}`: expected one word without `]` (SKEW_PROFILE LOAD= reads one word)"
        );
    }
    let mut out = header(
        "#",
        sq,
        &format!(
            "# include below [skew_correction] in printer.cfg, then: SKEW_PROFILE LOAD={profile}"
        ),
    );
    let mut set_skew = Vec::new();
    let mut from_lengths = [0.0; 3];
    for (i, (_, plane)) in PAIRS.iter().enumerate() {
        if let Some(k) = shear[i] {
            let (ac, bd, ad) = square_lengths(k);
            let (ac_s, ac_v) = written(ac, 9);
            let (bd_s, bd_v) = written(bd, 9);
            set_skew.push(format!("{}={ac_s},{bd_s},{ad}", plane.to_uppercase()));
            from_lengths[i] = klipper_factor(ac_v, bd_v, ad);
        }
    }
    let _ = writeln!(
        out,
        "# or, the same factors as the lengths AC, BD, AD of a {SQUARE_SIDE_MM} mm square: SET_SKEW {}",
        set_skew.join(" ")
    );
    let _ = writeln!(out, "[skew_correction {profile}]");
    let mut factors = BTreeMap::new();
    let mut profile_k = [0.0; 3];
    for (i, (_, plane)) in PAIRS.iter().enumerate() {
        let (s, v) = written(shear[i].unwrap_or(0.0), 12);
        let _ = writeln!(out, "{plane}_skew = {s}");
        profile_k[i] = v;
        factors.insert(plane.to_string(), v);
    }
    Ok((
        out,
        factors,
        vec![Applied::Shear(profile_k), Applied::Shear(from_lengths)],
    ))
}

/// The diagonals AC, BD and the side AD (mm) of a rhombus of side
/// [`SQUARE_SIDE_MM`] whose Klipper skew factor is `k`: Klipper's
/// `calc_skew_factor` gives tan(π/2 − φ) with cos φ = (AC² − side² −
/// AD²)/(2·side·AD) and side = √(2AC² + 2BD² − 4AD²)/2.
fn square_lengths(k: f64) -> (f64, f64, f64) {
    let s = SQUARE_SIDE_MM;
    let c = k / (1.0 + k * k).sqrt();
    (
        s * (2.0 * (1.0 + c)).sqrt(),
        s * (2.0 * (1.0 - c)).sqrt(),
        s,
    )
}

/// Klipper's `calc_skew_factor(ac, bd, ad)`.
pub fn klipper_factor(ac: f64, bd: f64, ad: f64) -> f64 {
    let side = (2.0 * ac * ac + 2.0 * bd * bd - 4.0 * ad * ad).sqrt() / 2.0;
    (std::f64::consts::FRAC_PI_2 - ((ac * ac - side * side - ad * ad) / (2.0 * side * ad)).acos())
        .tan()
}

/// Marlin: `M852 I<xy> J<xz> K<yz>` (J and K only for a chain with Z).
fn write_marlin(
    shear: &Shear,
    sq: &BTreeMap<String, f64>,
) -> (String, BTreeMap<String, f64>, Vec<Applied>) {
    let mut out = header(";", sq, "; needs SKEW_CORRECTION and SKEW_CORRECTION_GCODE (J, K: SKEW_CORRECTION_FOR_Z); in mm (G21); M500 keeps it");
    let mut words = Vec::new();
    let mut factors = BTreeMap::new();
    let mut k = [0.0; 3];
    for (i, ((_, plane), letter)) in PAIRS.iter().zip(["I", "J", "K"]).enumerate() {
        if let Some(v) = shear[i] {
            let (s, back) = written(v, 9);
            words.push(format!("{letter}{s}"));
            factors.insert(plane.to_string(), back);
            k[i] = back;
        }
    }
    let _ = writeln!(out, "M852 {}", words.join(" "));
    (out, factors, vec![Applied::Shear(k)])
}

/// matrixkins: `setp matrixkins.C_rc v` for the nine entries of
/// C = (I + S)⁻¹ = I − S + S² (S strictly upper triangular).
fn write_matrixkins(
    shear: &Shear,
    sq: &BTreeMap<String, f64>,
) -> (String, BTreeMap<String, f64>, Vec<Applied>) {
    let [xy, xz, yz] = shear.map(|k| k.unwrap_or(0.0));
    let c = [[1.0, -xy, -xz + xy * yz], [0.0, 1.0, -yz], [0.0, 0.0, 1.0]];
    let mut out = header(
        "#",
        sq,
        "# LinuxCNC matrixkins (INI: [KINS] KINEMATICS=matrixkins); joint = C · axis position",
    );
    let names = ["x", "y", "z"];
    let mut factors = BTreeMap::new();
    let mut applied = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            let (s, v) = written(c[r][k], 12);
            let _ = writeln!(out, "setp matrixkins.C_{}{} {s}", names[r], names[k]);
            applied[r][k] = v;
            if r < k {
                factors.insert(format!("C_{}{}", names[r], names[k]), v);
            }
        }
    }
    (out, factors, vec![Applied::Matrix(applied)])
}

/// A grid of [`GRID`] points per axis over the model's travel (0 on an
/// axis the chain lacks).
fn volume_grid(m: &Rigid21Model) -> Vec<[f64; 3]> {
    let along = |a: usize| -> Vec<f64> {
        match m.travel_mm[a] {
            Some([lo, hi]) => (0..GRID)
                .map(|i| lo + (hi - lo) * i as f64 / (GRID - 1) as f64)
                .collect(),
            None => vec![0.0],
        }
    };
    let (xs, ys, zs) = (along(0), along(1), along(2));
    let mut out = Vec::new();
    for &x in &xs {
        for &y in &ys {
            for &z in &zs {
                out.push([x, y, z]);
            }
        }
    }
    out
}

/// The model's error from the errors of `kinds` at `pt`, µm.
pub fn part_um(m: &Rigid21Model, pt: &ToolPoint, kinds: &[ErrorKind]) -> [f64; 3] {
    let mut e = [0.0; 3];
    for term in m.errors().filter(|t| kinds.contains(&t.kind)) {
        let Some(coef) = &term.coef else { continue };
        for (&d, &c) in term.degrees.iter().zip(coef) {
            let u = m.unit_response(term, d, pt).e_um;
            for i in 0..3 {
                e[i] += c * u[i];
            }
        }
    }
    e
}

/// The largest |squareness part − what the firmware removes| over `grid`,
/// µm: the machine puts the tool at q + S·q for the commanded q.
fn residual_after(m: &Rigid21Model, grid: &[[f64; 3]], applied: &Applied) -> f64 {
    grid.iter()
        .map(|&p| {
            let q = applied.command(p);
            let pt = ToolPoint {
                pos_mm: q,
                ..ToolPoint::default()
            };
            let s = part_um(m, &pt, &[ErrorKind::Squareness]);
            (0..3)
                .map(|i| ((q[i] - p[i]) * 1000.0 + s[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

/// What the file leaves out over the grid.
struct LeftOut {
    total_um: f64,
    at_mm: [f64; 3],
    by_kind_um: BTreeMap<&'static str, f64>,
    squareness_um: f64,
    model_um: f64,
}

/// The largest vector length over `grid` of the part of `kinds` at tool
/// `tool_mm`, and where.
fn spread(
    m: &Rigid21Model,
    grid: &[[f64; 3]],
    tool_mm: f64,
    kinds: &[ErrorKind],
) -> (f64, [f64; 3]) {
    let vals: Vec<[f64; 3]> = grid
        .iter()
        .map(|&q| {
            let pt = ToolPoint {
                pos_mm: q,
                tool_mm,
                tool_lat_mm: [0.0; 2],
            };
            part_um(m, &pt, kinds)
        })
        .collect();
    let mut best = (0.0f64, grid[0]);
    for (v, q) in vals.iter().zip(grid) {
        let len = v.iter().map(|c| c * c).sum::<f64>().sqrt();
        if len > best.0 {
            best = (len, *q);
        }
    }
    best
}

fn left_out(m: &Rigid21Model, grid: &[[f64; 3]], tool_mm: f64) -> LeftOut {
    use ErrorKind::*;
    let (total_um, at_mm) = spread(m, grid, tool_mm, &[Positioning, Straightness, Angle, Tilt]);
    let mut by_kind_um = BTreeMap::new();
    for (name, kind) in [
        ("positioning", Positioning),
        ("straightness", Straightness),
        ("angles", Angle),
        ("tilt", Tilt),
    ] {
        by_kind_um.insert(name, spread(m, grid, tool_mm, &[kind]).0);
    }
    LeftOut {
        total_um,
        at_mm,
        by_kind_um,
        squareness_um: spread(m, grid, tool_mm, &[Squareness]).0,
        model_um: spread(
            m,
            grid,
            tool_mm,
            &[Positioning, Straightness, Angle, Squareness, Tilt],
        )
        .0,
    }
}

#[cfg(test)]
mod tests;
