//! Bed meshes for 3-D printer and router firmware: a model of `ez` over x
//! and y sampled on a regular grid and written as RepRapFirmware's
//! `heightmap.csv` (`G29 S1` loads it) or a Klipper `[bed_mesh NAME]`
//! profile — the smoother mesh a user gets back from a measured one.
//!
//! The value at a node is the bed height `h = −ez / 1000` mm, the sign the
//! importer reads (docs/cli.md § import): the firmware lifts the nozzle by
//! `h`, which cancels the error `ez`. The model is evaluated at the middle
//! of its z travel (if it has one), at the reference temperature of any
//! thermal term, as the mean of both approach directions, without drift;
//! each of these is a warning when it changes anything.

use std::fmt::Write as _;

use anyhow::{bail, Result};

use super::{axis_travel_mm, fmt_no_neg_zero, predict_points, thermal_channels, Point, Warning};
use crate::features::Feature;
use crate::model::{FittedModel, ModelFile};

/// The error `ez` of a model sampled on an x–y grid.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshSamples {
    /// Node positions along x, ascending, mm.
    pub x_mm: Vec<f64>,
    /// Node positions along y, ascending, mm.
    pub y_mm: Vec<f64>,
    /// Bed height per node, mm: `height_mm[j][i]` at (`x_mm[i]`, `y_mm[j]`).
    pub height_mm: Vec<Vec<f64>>,
    /// Where z stood, mm (the middle of the model's z travel, or 0).
    pub z_mm: f64,
    /// What the mesh leaves out and how it was evaluated.
    pub warnings: Vec<Warning>,
    /// Largest difference between bilinear interpolation of the nodes and
    /// the full model, on a grid 8× finer, µm.
    pub max_interp_error_um: f64,
}

/// The spacing a mesh file writes (RepRapFirmware: two decimals), and the
/// grid of `n` nodes from `lo` that it places, covering at most `hi`.
fn written_grid(lo: f64, hi: f64, n: usize) -> (f64, Vec<f64>) {
    // Round the spacing down to 0.01 mm so that the last node stays inside
    // the fitted travel (no extrapolation past the measured span).
    let spacing = ((hi - lo) / (n - 1) as f64 * 100.0 + 1e-9).floor() / 100.0;
    (spacing, (0..n).map(|i| lo + spacing * i as f64).collect())
}

/// Samples `ez` of `file` on `counts` = [nx, ny] nodes over the model's x
/// and y travel.
pub fn sample_mesh(file: &ModelFile, counts: [usize; 2]) -> Result<MeshSamples> {
    let model = &file.model;
    if !model.targets().contains(&2) {
        bail!("the model has no ez (the error along z): a bed mesh holds ez over x and y");
    }
    let mut span = [(0.0, 0.0); 2];
    for (a, s) in span.iter_mut().enumerate() {
        match axis_travel_mm(model, a) {
            Some((lo, hi)) if hi > lo => *s = (lo, hi),
            _ => bail!(
                "the model does not vary along {}: a bed mesh needs a model over x and y",
                ["x", "y"][a]
            ),
        }
        if counts[a] < 2 {
            bail!("a bed mesh needs at least 2 nodes along {}", ["x", "y"][a]);
        }
        if (s.1 - s.0) / ((counts[a] - 1) as f64) < 0.01 {
            bail!(
                "{} nodes along {} over {:.3} mm are closer than the 0.01 mm a mesh file writes",
                counts[a],
                ["x", "y"][a],
                s.1 - s.0
            );
        }
    }
    let (sx, x_mm) = written_grid(span[0].0, span[0].1, counts[0]);
    let (sy, y_mm) = written_grid(span[1].0, span[1].1, counts[1]);
    let mut warnings = Vec::new();
    // Periodic terms shorter than 4 mesh steps would alias into a wrong,
    // longer wave between the nodes; drift is the session, not the bed.
    let mut pruned = model.clone();
    if let FittedModel::Linear(m) = &mut pruned {
        for o in m.outputs.iter_mut().filter(|o| o.target == 2) {
            for (f, c) in o.features.iter().zip(o.coef_um.iter_mut()) {
                let left_out = match f {
                    Feature::Periodic {
                        axis,
                        period_mm,
                        harmonic,
                        ..
                    } if *axis < 2
                        && period_mm / f64::from(*harmonic) < 4.0 * [sx, sy][*axis] =>
                    {
                        Some(("periodic_left_out", format!("its period {:.3} mm is shorter than 4 mesh steps of {:.2} mm; use more nodes", period_mm / f64::from(*harmonic), [sx, sy][*axis])))
                    }
                    Feature::Drift { .. } => Some((
                        "drift_left_out",
                        "drift describes the measurement session, not the bed".to_string(),
                    )),
                    _ => None,
                };
                if let Some((code, why)) = left_out {
                    if *c != 0.0 {
                        warnings.push(Warning::new(
                            code,
                            format!("{f} ({:.3} µm) left out: {why}", c.abs()),
                        ));
                    }
                    *c = 0.0;
                }
            }
        }
    }
    let z_mm = axis_travel_mm(model, 2).map_or(0.0, |(lo, hi)| 0.5 * (lo + hi));
    if axis_travel_mm(model, 2).is_some() {
        warnings.push(Warning::new(
            "z_fixed",
            format!("the model varies with z; the mesh is its ez at z = {z_mm} mm (a bed mesh has no z input)"),
        ));
    }
    let chans = thermal_channels(model);
    let names: Vec<String> = chans.iter().map(|c| c.0.clone()).collect();
    if !chans.is_empty() {
        warnings.push(Warning::new(
            "thermal_at_reference",
            format!(
                "evaluated at the reference temperature ({}): a bed mesh has no temperature input",
                chans
                    .iter()
                    .map(|(c, t)| format!("T_{c}_C = {t} °C"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    let point = |x: f64, y: f64, dir: i8| Point {
        pos_mm: [x, y, z_mm],
        dir: [dir; 3],
        temp_c: chans.iter().map(|c| c.1).collect(),
        tool_mm: 0.0,
    };
    // Nodes, then a grid 8× finer for the interpolation check; both
    // directions (a mesh has none: it holds their mean).
    const FINE: usize = 8;
    let fine_x: Vec<f64> = (0..(counts[0] - 1) * FINE + 1)
        .map(|i| x_mm[0] + sx * i as f64 / FINE as f64)
        .collect();
    let fine_y: Vec<f64> = (0..(counts[1] - 1) * FINE + 1)
        .map(|j| y_mm[0] + sy * j as f64 / FINE as f64)
        .collect();
    let mut pts = Vec::new();
    for dir in [1i8, -1] {
        for &y in &fine_y {
            for &x in &fine_x {
                pts.push(point(x, y, dir));
            }
        }
    }
    let n = fine_x.len() * fine_y.len();
    let mesh = predict_points(&pruned, &names, &pts)?;
    let full = predict_points(model, &names, &pts)?;
    let (Some(mesh), Some(full)) = (&mesh[2], &full[2]) else {
        bail!("the model predicts no ez");
    };
    let mean = |v: &[f64], k: usize| 0.5 * (v[k] + v[n + k]);
    let reversal = (0..n).fold(0.0f64, |m, k| m.max((mesh[k] - mesh[n + k]).abs()));
    if reversal > 0.5 {
        warnings.push(Warning::new(
            "reversal_averaged",
            format!("the model's ez differs by up to {reversal:.3} µm between approach directions; a bed mesh holds the mean of both"),
        ));
    }
    let at = |i: usize, j: usize| j * fine_x.len() + i;
    let height_mm: Vec<Vec<f64>> = (0..counts[1])
        .map(|j| {
            (0..counts[0])
                .map(|i| -mean(mesh, at(i * FINE, j * FINE)) / 1000.0 + 0.0)
                .collect()
        })
        .collect();
    let mut max_interp_error_um = 0.0f64;
    for (j, _) in fine_y.iter().enumerate() {
        for (i, _) in fine_x.iter().enumerate() {
            let (ci, cj) = ((i / FINE).min(counts[0] - 2), (j / FINE).min(counts[1] - 2));
            let (u, v) = (
                (i - ci * FINE) as f64 / FINE as f64,
                (j - cj * FINE) as f64 / FINE as f64,
            );
            let h = |a: usize, b: usize| -height_mm[b][a] * 1000.0;
            let interp = (1.0 - u) * (1.0 - v) * h(ci, cj)
                + u * (1.0 - v) * h(ci + 1, cj)
                + (1.0 - u) * v * h(ci, cj + 1)
                + u * v * h(ci + 1, cj + 1);
            max_interp_error_um = max_interp_error_um.max((interp - mean(full, at(i, j))).abs());
        }
    }
    Ok(MeshSamples {
        x_mm,
        y_mm,
        height_mm,
        z_mm,
        warnings,
        max_interp_error_um,
    })
}

/// RepRapFirmware `heightmap.csv` (the v2 label line every RRF since 2.x
/// reads). Heights with three decimals; a height that rounds to zero is
/// written `0.000`, never the bare `0` that means "not probed". `header`
/// is appended to the first line (e.g. the source).
pub fn write_rrf(mesh: &MeshSamples, header: &str) -> String {
    let all: Vec<f64> = mesh.height_mm.iter().flatten().copied().collect();
    let n = all.len() as f64;
    let mean = all.iter().sum::<f64>() / n;
    let dev = (all.iter().map(|h| (h - mean).powi(2)).sum::<f64>() / n).sqrt();
    let (lo, hi) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    let (nx, ny) = (mesh.x_mm.len(), mesh.y_mm.len());
    let sx = mesh.x_mm[1] - mesh.x_mm[0];
    let sy = mesh.y_mm[1] - mesh.y_mm[0];
    let mut s = format!(
        "RepRapFirmware height map file v2 {header}, min error {}, max error {}, mean {}, deviation {}\n",
        fmt_no_neg_zero(lo, 3),
        fmt_no_neg_zero(hi, 3),
        fmt_no_neg_zero(mean, 3),
        fmt_no_neg_zero(dev, 3)
    );
    s.push_str("xmin,xmax,ymin,ymax,radius,xspacing,yspacing,xnum,ynum\n");
    let _ = writeln!(
        s,
        "{:.2},{:.2},{:.2},{:.2},-1.00,{:.2},{:.2},{nx},{ny}",
        mesh.x_mm[0],
        mesh.x_mm[nx - 1],
        mesh.y_mm[0],
        mesh.y_mm[ny - 1],
        sx,
        sy
    );
    for row in &mesh.height_mm {
        let cells: Vec<String> = row
            .iter()
            .map(|h| format!("{:>7}", fmt_no_neg_zero(*h, 3)))
            .collect();
        s.push_str(&cells.join(","));
        s.push('\n');
    }
    s
}

/// A Klipper `[bed_mesh NAME]` profile as `SAVE_CONFIG` writes it, to go
/// at the end of `printer.cfg` (inside the auto-generated block).
pub fn write_klipper(mesh: &MeshSamples, profile: &str) -> Result<String> {
    if profile.is_empty() || profile.contains([']', '\n', '\r']) {
        bail!("Klipper profile name `{profile}`: expected a name without `]` or line breaks");
    }
    let (nx, ny) = (mesh.x_mm.len(), mesh.y_mm.len());
    let mut s = format!("#*# [bed_mesh {profile}]\n#*# version = 1\n#*# points =\n");
    for row in &mesh.height_mm {
        let cells: Vec<String> = row.iter().map(|h| fmt_no_neg_zero(*h, 6)).collect();
        let _ = writeln!(s, "#*# \t  {}", cells.join(", "));
    }
    // Klipper's bicubic interpolation needs 4 nodes per axis; lagrange
    // takes up to 6.
    let algo = if nx >= 4 && ny >= 4 {
        "bicubic"
    } else {
        "lagrange"
    };
    let _ = write!(
        s,
        "#*# x_count = {nx}\n#*# y_count = {ny}\n#*# mesh_x_pps = 2\n#*# mesh_y_pps = 2\n#*# algo = {algo}\n#*# tension = 0.2\n#*# min_x = {}\n#*# max_x = {}\n#*# min_y = {}\n#*# max_y = {}\n",
        mesh.x_mm[0],
        mesh.x_mm[nx - 1],
        mesh.y_mm[0],
        mesh.y_mm[ny - 1]
    );
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::{read_klipper_mesh, read_rrf_heightmap};

    fn mesh() -> MeshSamples {
        MeshSamples {
            x_mm: vec![10.0, 20.0, 30.0],
            y_mm: vec![0.0, 15.5],
            height_mm: vec![vec![0.0001, -0.25, 0.5], vec![-0.0004, 0.125, 0.0]],
            z_mm: 0.0,
            warnings: vec![],
            max_interp_error_um: 0.0,
        }
    }

    #[test]
    fn a_written_rrf_map_reads_back_as_the_same_errors() {
        let text = write_rrf(&mesh(), "by trueaxis");
        // Rounded-to-zero heights are probed zeros, never the bare `0`.
        assert!(
            !text
                .lines()
                .skip(3)
                .any(|l| l.split(',').any(|c| c.trim() == "0")),
            "{text}"
        );
        let ds = read_rrf_heightmap(&text, "m.csv").unwrap();
        assert_eq!(ds.len(), 6);
        assert!(ds.skipped.is_empty());
        let ez = ds.err_um[2].as_ref().unwrap();
        assert_eq!(ez[1], Some(250.0));
        assert_eq!(ds.pos_mm[1].as_ref().unwrap()[5], 15.5);
    }

    #[test]
    fn a_written_klipper_profile_reads_back_as_the_same_errors() {
        let text = write_klipper(&mesh(), "trueaxis").unwrap();
        let ds = read_klipper_mesh(&text, "p.cfg", None).unwrap();
        let ez = ds.err_um[2].as_ref().unwrap();
        assert_eq!(ez[2], Some(-500.0));
        assert_eq!(ez[4], Some(-125.0));
        assert!(text.contains("algo = lagrange"));
        assert!(write_klipper(&mesh(), "a]b").is_err());
    }

    #[test]
    fn the_written_grid_stays_inside_the_travel() {
        let (s, g) = written_grid(10.0, 195.0, 9);
        assert_eq!(s, 23.12);
        assert!(*g.last().unwrap() <= 195.0);
        let (s, g) = written_grid(0.0, 200.0, 11);
        assert_eq!((s, g[10]), (20.0, 200.0));
    }
}
