//! Bed height maps of 3-D printers and routers into the contract's
//! [`Dataset`]: RepRapFirmware's `heightmap.csv` (written by `G29 S0` /
//! `M374`) and the `[bed_mesh …]` profiles Klipper saves at the end of
//! `printer.cfg`. Both hold the height of the bed, in mm, on a regular x–y
//! grid; each probed node becomes one row `x_mm, y_mm, ez_um`.
//!
//! **Sign.** A map value `h` is how far the bed lies above its nominal
//! plane at that node; the firmware lifts the nozzle by `h` there. Relative
//! to the bed the tool then stands `h` too low, so the error (actual −
//! nominal, docs/cli.md § Measurement CSV) is `ez_um = −1000 · h`, and a
//! trueaxis table that subtracts the error lifts the tool by `h` like the
//! firmware's own mesh compensation does.
//!
//! Layouts read (RepRapFirmware's three label lines, `Grid.cpp`):
//! ```text
//! RepRapFirmware height map file v2 generated at …
//! xmin,xmax,ymin,ymax,radius,xspacing,yspacing,xnum,ynum        (v2, RRF ≤ 3.2)
//! xmin,xmax,ymin,ymax,radius,spacing,xnum,ynum                  (v1)
//! axis0,axis1,min0,max0,min1,max1,radius,spacing0,spacing1,num0,num1  (RRF ≥ 3.3; data line starts `X,Y,`)
//! <one line per y node, ymin first: xnum heights>
//! ```
//! A bare `0` (no decimal point) is RepRapFirmware's "not probed" mark: the
//! node is listed in [`Dataset::skipped`], never read as a height of zero.
//! Klipper:
//! ```text
//! #*# [bed_mesh default]
//! #*# version = 1
//! #*# points =
//! #*#     -0.0125, 0.0100, 0.0150        (one line per y node, min_y first)
//! #*# x_count = 3
//! #*# y_count = 3
//! #*# min_x = 35.0 …  max_x, min_y, max_y (keys in any order)
//! ```

use super::{shown, ImportError, Needs};
use crate::data::{Dataset, SkippedRow, ERR_PLAUSIBLE_UM, POS_PLAUSIBLE_MM};

/// First words of a RepRapFirmware height map file.
pub const RRF_MAGIC: &str = "RepRapFirmware height map file";

/// True when `text` is a RepRapFirmware height map (its first line).
pub fn is_rrf_heightmap(text: &str) -> bool {
    text.trim_start_matches('\u{feff}').starts_with(RRF_MAGIC)
}

/// One grid node read from a map: source line, column (1-based field on
/// that line), x and y index, the height in mm (`None`: not probed).
struct Node {
    line: usize,
    column: usize,
    xi: usize,
    yi: usize,
    height_mm: Option<f64>,
}

/// The grid a map was probed on.
struct Grid {
    min: [f64; 2],
    spacing: [f64; 2],
    count: [usize; 2],
}

impl Grid {
    /// The position of node `i` along `axis`, rounded to 1 nm: min + i ×
    /// spacing in binary floating point leaves `247.46999999999997` where
    /// the probe stood at 247.47 (issue 28), which the CSV and every page
    /// would then print.
    fn pos(&self, axis: usize, i: usize) -> f64 {
        ((self.min[axis] + self.spacing[axis] * i as f64) * 1e6).round() / 1e6
    }
}

/// The cell `s` (trimmed) as `read` reads it, or the error at
/// FILE:LINE:COLUMN "WHAT: expected …, found `S`", with what `read` says it
/// expected.
fn parse_cell<T>(
    file: &str,
    (line, column): (usize, usize),
    what: &str,
    s: &str,
    read: fn(&str) -> Result<T, &'static str>,
) -> Result<T, ImportError> {
    let s = s.trim();
    read(s).map_err(|expected| {
        let msg = format!("{what}: expected {expected}, found `{}`", shown(s));
        ImportError::at(file, line, Some(column), msg)
    })
}

/// A finite number.
fn read_num(s: &str) -> Result<f64, &'static str> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err("a finite number"),
        Err(_) => Err("a number"),
    }
}

/// A node count. RepRapFirmware writes counts as integers; accept `8.0`
/// too, refuse fractions and anything below 2 (a map needs two nodes per
/// axis).
fn read_count(s: &str) -> Result<usize, &'static str> {
    match s.parse::<f64>() {
        Ok(v) if v.fract() == 0.0 && (2.0..=10_000.0).contains(&v) => Ok(v as usize),
        _ => Err("a whole number of nodes from 2 to 10000"),
    }
}

/// Builds the data set from the grid and its nodes; `format` names the
/// source format in the metadata.
fn grid_dataset(
    name: &str,
    mut metadata: Vec<(String, String)>,
    grid: &Grid,
    nodes: Vec<Node>,
) -> Result<Dataset, ImportError> {
    let mut ds = Dataset {
        source: name.to_string(),
        ..Dataset::default()
    };
    let (mut x, mut y, mut ez) = (Vec::new(), Vec::new(), Vec::new());
    for n in nodes {
        let Some(h) = n.height_mm else {
            ds.skipped.push(SkippedRow {
                line: n.line,
                reason: format!(
                    "node x = {} mm, y = {} mm (field {}) not probed (a bare `0` in the map)",
                    grid.pos(0, n.xi),
                    grid.pos(1, n.yi),
                    n.column
                ),
            });
            continue;
        };
        let err_um = -1000.0 * h;
        if err_um.abs() > ERR_PLAUSIBLE_UM {
            return Err(ImportError::at(
                name,
                n.line,
                Some(n.column),
                format!(
                    "height {h} mm is beyond ±{} mm; expected a bed map in mm",
                    ERR_PLAUSIBLE_UM / 1000.0
                ),
            ));
        }
        x.push(grid.pos(0, n.xi));
        y.push(grid.pos(1, n.yi));
        ez.push(Some(err_um));
        ds.line.push(n.line);
    }
    for (a, p) in [&x, &y].into_iter().enumerate() {
        if let Some(v) = p.iter().find(|v| v.abs() > POS_PLAUSIBLE_MM) {
            return Err(ImportError::at(
                name,
                1,
                None,
                format!(
                    "the grid reaches {} = {v} mm, beyond ±{POS_PLAUSIBLE_MM} mm; expected positions in mm",
                    ["x", "y"][a]
                ),
            ));
        }
    }
    if ez.is_empty() {
        return Err(ImportError::at(
            name,
            1,
            None,
            "no probed node in the map (every height is the `0` of a node not probed)",
        ));
    }
    metadata.push((
        "sign".into(),
        "ez_um = -1000 * bed height (mm): the tool stands that much low over a high bed".into(),
    ));
    ds.metadata = metadata;
    ds.pos_mm[0] = Some(x);
    ds.pos_mm[1] = Some(y);
    ds.err_um[2] = Some(ez);
    Ok(ds)
}

/// Parses a RepRapFirmware `heightmap.csv`; `name` labels messages.
pub fn read_rrf_heightmap(text: &str, name: &str) -> Result<Dataset, ImportError> {
    let err = |line: usize, col: Option<usize>, m: String| ImportError::at(name, line, col, m);
    let mut lines = text
        .trim_start_matches('\u{feff}')
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let (_, first) = lines.next().unwrap_or((1, ""));
    if !first.starts_with(RRF_MAGIC) {
        return Err(err(
            1,
            None,
            format!("expected the first line to start with `{RRF_MAGIC}`"),
        ));
    }
    let (label_ln, label) = lines.next().ok_or_else(|| {
        err(
            1,
            None,
            "the file ends after its first line; expected the grid's label line".into(),
        )
    })?;
    let labels: Vec<String> = label
        .split(',')
        .map(|s| s.trim().to_ascii_lowercase())
        .collect();
    let (values_ln, values) = lines.next().ok_or_else(|| {
        err(
            label_ln,
            None,
            "the file ends after the label line; expected the grid's values".into(),
        )
    })?;
    let fields: Vec<&str> = values.split(',').map(str::trim).collect();
    if fields.len() != labels.len() {
        return Err(err(
            values_ln,
            None,
            format!(
                "{} values for the {} labels of line {label_ln} ({})",
                fields.len(),
                labels.len(),
                labels.join(",")
            ),
        ));
    }
    let get = |key: &str| -> Result<(usize, &str), ImportError> {
        labels
            .iter()
            .position(|l| l == key)
            .map(|i| (i + 1, fields[i]))
            .ok_or_else(|| {
                err(
                    label_ln,
                    None,
                    format!(
                        "no `{key}` in the label line; expected one of RepRapFirmware's layouts (xmin,xmax,ymin,ymax,radius,…)"
                    ),
                )
            })
    };
    let num = |key: &str| -> Result<f64, ImportError> {
        let (c, s) = get(key)?;
        parse_cell(name, (values_ln, c), &format!("`{key}`"), s, read_num)
    };
    let count = |key: &str| -> Result<usize, ImportError> {
        let (c, s) = get(key)?;
        parse_cell(name, (values_ln, c), &format!("`{key}`"), s, read_count)
    };
    let mut metadata = vec![(
        "format".to_string(),
        "RepRapFirmware heightmap.csv".to_string(),
    )];
    metadata.push(("header".into(), first.trim().to_string()));
    let grid = if labels.iter().any(|l| l == "axis0") {
        // RRF ≥ 3.3: the axes are named; only an X–Y map is a bed map here.
        let (c0, a0) = get("axis0")?;
        let (c1, a1) = get("axis1")?;
        if !a0.eq_ignore_ascii_case("x") {
            return Err(err(
                values_ln,
                Some(c0),
                format!("axis0 is `{a0}`; expected X (a map over x and y)"),
            ));
        }
        if !a1.eq_ignore_ascii_case("y") {
            return Err(err(
                values_ln,
                Some(c1),
                format!("axis1 is `{a1}`; expected Y (a map over x and y)"),
            ));
        }
        Grid {
            min: [num("min0")?, num("min1")?],
            spacing: [num("spacing0")?, num("spacing1")?],
            count: [count("num0")?, count("num1")?],
        }
    } else if labels.iter().any(|l| l == "xspacing") {
        Grid {
            min: [num("xmin")?, num("ymin")?],
            spacing: [num("xspacing")?, num("yspacing")?],
            count: [count("xnum")?, count("ynum")?],
        }
    } else {
        let s = num("spacing")?;
        Grid {
            min: [num("xmin")?, num("ymin")?],
            spacing: [s, s],
            count: [count("xnum")?, count("ynum")?],
        }
    };
    // RepRapFirmware writes the spacing with two decimals (a 185 mm span
    // over 9 nodes is written 23.12, not 23.125): where the span divided by
    // the node count rounds to the written spacing, the exact quotient is
    // the spacing the nodes were probed at, and the last row lands on the
    // written maximum instead of 0.04 mm short of it.
    let max = if labels.iter().any(|l| l == "axis0") {
        [num("max0")?, num("max1")?]
    } else {
        [num("xmax")?, num("ymax")?]
    };
    let mut grid = grid;
    for (a, top) in max.iter().enumerate() {
        let exact = (top - grid.min[a]) / (grid.count[a] - 1) as f64;
        if (exact - grid.spacing[a]).abs() <= 0.005 + 1e-9 {
            grid.spacing[a] = exact;
        }
    }
    for (a, s) in grid.spacing.iter().enumerate() {
        if s.is_nan() || *s <= 0.0 {
            return Err(err(
                values_ln,
                None,
                format!(
                    "{} spacing is {s} mm; expected a positive spacing",
                    ["x", "y"][a]
                ),
            ));
        }
    }
    if let Ok(r) = num("radius") {
        metadata.push(("radius_mm".into(), format!("{r}")));
    }
    let mut nodes = Vec::with_capacity(grid.count[0] * grid.count[1]);
    let mut yi = 0;
    for (ln, l) in lines {
        if l.trim().is_empty() {
            continue;
        }
        if yi == grid.count[1] {
            return Err(err(
                ln,
                None,
                format!(
                    "more than the {} rows of heights the grid line declares",
                    grid.count[1]
                ),
            ));
        }
        let cells: Vec<&str> = l.split(',').collect();
        if cells.len() != grid.count[0] {
            return Err(err(
                ln,
                None,
                format!(
                    "{} heights on this row; expected {} (the grid's x count)",
                    cells.len(),
                    grid.count[0]
                ),
            ));
        }
        for (xi, c) in cells.iter().enumerate() {
            let c = c.trim();
            // RepRapFirmware writes an unprobed node as a bare `0`, a probed
            // one with three decimals (`0.000` is a real height of zero).
            let height_mm = if c == "0" {
                None
            } else {
                Some(parse_cell(name, (ln, xi + 1), "height", c, read_num)?)
            };
            nodes.push(Node {
                line: ln,
                column: xi + 1,
                xi,
                yi,
                height_mm,
            });
        }
        yi += 1;
    }
    if yi < grid.count[1] {
        return Err(err(
            text.lines().count().max(1),
            None,
            format!(
                "{yi} rows of heights; the grid line declares {} (file cut short?)",
                grid.count[1]
            ),
        ));
    }
    grid_dataset(name, metadata, &grid, nodes)
}

/// The profile name of a `#*# [bed_mesh NAME]` line.
fn klipper_section(line: &str) -> Option<&str> {
    let rest = line.trim().strip_prefix("#*#")?.trim();
    let inner = rest.strip_prefix('[')?.strip_suffix(']')?.trim();
    let name = inner.strip_prefix("bed_mesh")?;
    if name.is_empty() {
        return Some("default");
    }
    name.starts_with(char::is_whitespace).then(|| name.trim())
}

/// The names of the `[bed_mesh …]` profiles saved in a Klipper config.
pub fn klipper_profiles(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(klipper_section)
        .map(str::to_string)
        .collect()
}

/// Parses the Klipper bed mesh profile `profile` (or the only one in the
/// file when `None`) from a `printer.cfg`; `name` labels messages.
pub fn read_klipper_mesh(
    text: &str,
    name: &str,
    profile: Option<&str>,
) -> Result<Dataset, ImportError> {
    let err = |line: usize, col: Option<usize>, m: String| ImportError::at(name, line, col, m);
    let profiles = klipper_profiles(text);
    let want = match (profile, profiles.as_slice()) {
        (_, []) => {
            return Err(err(
                1,
                None,
                "no `#*# [bed_mesh …]` profile in this file; expected a Klipper printer.cfg after BED_MESH_CALIBRATE and SAVE_CONFIG".into(),
            ))
        }
        (Some(p), _) => {
            if !profiles.iter().any(|q| q == p) {
                return Err(err(
                    1,
                    None,
                    format!("no bed mesh profile `{p}`; the file has {}", profiles.join(", ")),
                ));
            }
            p.to_string()
        }
        (None, [one]) => one.clone(),
        (None, _) => {
            return Err(err(
                1,
                None,
                format!(
                    "{} bed mesh profiles ({}); expected the one to read",
                    profiles.len(),
                    profiles.join(", ")
                ),
            )
            .needing(Needs::Profile {
                profiles: profiles.clone(),
            }))
        }
    };
    let lines: Vec<(usize, &str)> = text
        .trim_start_matches('\u{feff}')
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .collect();
    let start = lines
        .iter()
        .position(|(_, l)| klipper_section(l) == Some(want.as_str()))
        .expect("the profile was listed");
    let section_ln = lines[start].0;
    let mut keys: Vec<(String, usize, String)> = Vec::new();
    let mut rows: Vec<(usize, &str)> = Vec::new();
    let mut in_points = false;
    for &(ln, l) in &lines[start + 1..] {
        let Some(body) = l.trim_start().strip_prefix("#*#") else {
            break;
        };
        if body.trim().starts_with('[') {
            break;
        }
        if body.trim().is_empty() {
            if in_points {
                in_points = false;
            }
            continue;
        }
        if let Some((k, v)) = body.split_once('=') {
            in_points = k.trim() == "points" && v.trim().is_empty();
            keys.push((k.trim().to_string(), ln, v.trim().to_string()));
        } else if in_points {
            rows.push((ln, body));
        } else {
            return Err(err(
                ln,
                None,
                format!(
                    "expected `key = value` in profile `{want}`, found `{}`",
                    shown(body.trim())
                ),
            ));
        }
    }
    let get = |key: &str| -> Result<(usize, &str), ImportError> {
        keys.iter()
            .find(|(k, _, _)| k == key)
            .map(|(_, ln, v)| (*ln, v.as_str()))
            .ok_or_else(|| {
                err(
                    section_ln,
                    None,
                    format!("profile `{want}` has no `{key} = …` line"),
                )
            })
    };
    let num = |key: &str| -> Result<f64, ImportError> {
        let (ln, v) = get(key)?;
        parse_cell(name, (ln, 1), &format!("`{key}`"), v, read_num)
    };
    let count = |key: &str| -> Result<usize, ImportError> {
        let (ln, v) = get(key)?;
        parse_cell(name, (ln, 1), &format!("`{key}`"), v, read_count)
    };
    let count = [count("x_count")?, count("y_count")?];
    let (min, max) = (
        [num("min_x")?, num("min_y")?],
        [num("max_x")?, num("max_y")?],
    );
    for a in 0..2 {
        if max[a] <= min[a] {
            return Err(err(
                get(["max_x", "max_y"][a])?.0,
                None,
                format!(
                    "max_{0} = {1} is not above min_{0} = {2}",
                    ["x", "y"][a],
                    max[a],
                    min[a]
                ),
            ));
        }
    }
    let grid = Grid {
        min,
        spacing: [0, 1].map(|a| (max[a] - min[a]) / (count[a] - 1) as f64),
        count,
    };
    if rows.len() != count[1] {
        let at = rows.last().map_or(get("points")?.0, |r| r.0);
        return Err(err(
            at,
            None,
            format!(
                "{} rows of points; expected y_count = {}",
                rows.len(),
                count[1]
            ),
        ));
    }
    let mut nodes = Vec::new();
    for (yi, (ln, body)) in rows.into_iter().enumerate() {
        let cells: Vec<&str> = body.split(',').map(str::trim).collect();
        if cells.len() != count[0] {
            return Err(err(
                ln,
                None,
                format!(
                    "{} points on this row; expected x_count = {}",
                    cells.len(),
                    count[0]
                ),
            ));
        }
        for (xi, c) in cells.into_iter().enumerate() {
            let h = parse_cell(name, (ln, xi + 1), "point", c, read_num)?;
            nodes.push(Node {
                line: ln,
                column: xi + 1,
                xi,
                yi,
                height_mm: Some(h),
            });
        }
    }
    let mut metadata = vec![
        ("format".to_string(), "Klipper bed_mesh".to_string()),
        ("profile".into(), want.clone()),
    ];
    for key in ["algo", "mesh_x_pps", "mesh_y_pps", "tension", "version"] {
        if let Ok((_, v)) = get(key) {
            metadata.push((key.into(), v.to_string()));
        }
    }
    grid_dataset(name, metadata, &grid, nodes)
}

#[cfg(test)]
mod tests {
    use super::*;

    const RRF_V2: &str = "RepRapFirmware height map file v2 generated at 2026-01-01 12:00, min error -0.100, max error 0.200, mean 0.050, deviation 0.100\n\
xmin,xmax,ymin,ymax,radius,xspacing,yspacing,xnum,ynum\n\
10.00,30.00,0.00,20.00,-1.00,10.00,10.00,3,3\n\
  0.000,  0.100,  0.200\n\
  0.100,  0.150,  0.200\n\
 -0.100,      0,  0.050\n";

    #[test]
    fn an_rrf_map_gives_one_row_per_probed_node_with_the_sign_of_an_error() {
        let ds = read_rrf_heightmap(RRF_V2, "h.csv").unwrap();
        assert_eq!(ds.len(), 8);
        let x = ds.pos_mm[0].as_ref().unwrap();
        let y = ds.pos_mm[1].as_ref().unwrap();
        let ez = ds.err_um[2].as_ref().unwrap();
        // Row 2 (y = 10), node 2 (x = 20): height 0.150 mm → −150 µm.
        let i = (0..ds.len())
            .find(|&i| x[i] == 20.0 && y[i] == 10.0)
            .unwrap();
        assert!((ez[i].unwrap() + 150.0).abs() < 1e-9);
        assert_eq!(ds.line[i], 5);
        // 0.000 is a probed zero, the bare 0 is not probed.
        assert!(ez[0] == Some(0.0) || ez[0] == Some(-0.0));
        assert_eq!(ds.skipped.len(), 1);
        assert_eq!(ds.skipped[0].line, 6);
        assert!(
            ds.skipped[0].reason.contains("x = 20 mm, y = 20 mm"),
            "{}",
            ds.skipped[0].reason
        );
        assert!(ds.pos_mm[2].is_none() && ds.err_um[0].is_none());
    }

    #[test]
    fn every_rrf_label_layout_is_read() {
        let v1 = "RepRapFirmware height map file v1\nxmin,xmax,ymin,ymax,radius,spacing,xnum,ynum\n0,10,0,10,-1,10,2,2\n0.010,0.020\n0.030,0.040\n";
        let v33 = "RepRapFirmware height map file v2 generated at x\naxis0,axis1,min0,max0,min1,max1,radius,spacing0,spacing1,num0,num1\nX,Y,0.00,10.00,0.00,20.00,-1.00,10.00,20.00,2,2\n0.010,0.020\n0.030,0.040\n";
        for (t, ymax) in [(v1, 10.0), (v33, 20.0)] {
            let ds = read_rrf_heightmap(t, "h.csv").unwrap();
            assert_eq!(ds.len(), 4);
            let y = ds.pos_mm[1].as_ref().unwrap();
            assert_eq!(y[3], ymax);
            assert!((ds.err_um[2].as_ref().unwrap()[3].unwrap() + 40.0).abs() < 1e-9);
        }
    }

    #[test]
    fn a_damaged_rrf_map_is_refused_with_its_line_and_field() {
        let short_row = RRF_V2.replace("-0.100,      0,  0.050", "-0.100,      0");
        let e = read_rrf_heightmap(&short_row, "h.csv").unwrap_err();
        assert_eq!((e.line, e.column), (6, None));
        assert!(e.message.contains("expected 3"), "{e}");
        let bad = RRF_V2.replace("0.150", "0.1x0");
        let e = read_rrf_heightmap(&bad, "h.csv").unwrap_err();
        assert_eq!((e.line, e.column), (5, Some(2)), "{e}");
        let cut: String = RRF_V2.lines().take(5).collect::<Vec<_>>().join("\n");
        let e = read_rrf_heightmap(&cut, "h.csv").unwrap_err();
        assert!(e.message.contains("2 rows of heights"), "{e}");
        let um = RRF_V2.replace("0.100,  0.150", "200.000,  0.150");
        let e = read_rrf_heightmap(&um, "h.csv").unwrap_err();
        assert!(e.message.contains("expected a bed map in mm"), "{e}");
        let zaxis = "RepRapFirmware height map file v2\naxis0,axis1,min0,max0,min1,max1,radius,spacing0,spacing1,num0,num1\nX,Z,0,10,0,10,-1,10,10,2,2\n0.1,0.1\n0.1,0.1\n";
        let e = read_rrf_heightmap(zaxis, "h.csv").unwrap_err();
        assert_eq!((e.line, e.column), (3, Some(2)), "{e}");
    }

    const KLIPPER: &str = "[printer]\nkinematics: cartesian\n\n#*# <---------------------- SAVE_CONFIG ---------------------->\n\
#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n#*# [bltouch]\n#*# z_offset = 2.750\n#*#\n\
#*# [bed_mesh default]\n#*# version = 1\n#*# points =\n\
#*# \t-0.275000, -0.037500, 0.137500\n\
#*# \t-0.067500, 0.000000, 0.055000\n\
#*# tension = 0.2\n#*# min_x = 23.0\n#*# algo = bicubic\n#*# y_count = 2\n#*# mesh_y_pps = 2\n#*# min_y = 25.0\n\
#*# x_count = 3\n#*# max_y = 288.0\n#*# mesh_x_pps = 2\n#*# max_x = 268.0\n#*#\n#*# [extruder]\n#*# control = pid\n";

    #[test]
    fn a_klipper_profile_is_read_with_keys_in_any_order() {
        assert!(!is_rrf_heightmap(KLIPPER));
        let ds = read_klipper_mesh(KLIPPER, "printer.cfg", None).unwrap();
        assert_eq!(ds.len(), 6);
        let x = ds.pos_mm[0].as_ref().unwrap();
        let y = ds.pos_mm[1].as_ref().unwrap();
        assert_eq!((x[1], y[1]), (145.5, 25.0));
        assert_eq!((x[5], y[5]), (268.0, 288.0));
        assert!((ds.err_um[2].as_ref().unwrap()[0].unwrap() - 275.0).abs() < 1e-9);
        assert_eq!(ds.line[3], 14);
        assert!(ds
            .metadata
            .iter()
            .any(|(k, v)| k == "algo" && v == "bicubic"));
    }

    #[test]
    fn several_klipper_profiles_need_a_choice() {
        let two = format!(
            "{KLIPPER}#*#\n#*# [bed_mesh hot]\n#*# version = 1\n#*# points =\n#*# \t0.1, 0.2\n#*# \t0.3, 0.4\n#*# x_count = 2\n#*# y_count = 2\n#*# min_x = 0\n#*# max_x = 10\n#*# min_y = 0\n#*# max_y = 10\n"
        );
        assert_eq!(klipper_profiles(&two), ["default", "hot"]);
        let e = read_klipper_mesh(&two, "p.cfg", None).unwrap_err();
        assert_eq!(
            e.needs,
            Some(Needs::Profile {
                profiles: vec!["default".into(), "hot".into()]
            }),
            "{e}"
        );
        let hot = read_klipper_mesh(&two, "p.cfg", Some("hot")).unwrap();
        assert_eq!(hot.len(), 4);
        assert!((hot.err_um[2].as_ref().unwrap()[3].unwrap() + 400.0).abs() < 1e-9);
        let e = read_klipper_mesh(&two, "p.cfg", Some("cold")).unwrap_err();
        assert!(e.message.contains("default, hot"), "{e}");
    }

    #[test]
    fn a_damaged_klipper_profile_is_refused_with_its_line() {
        let short = KLIPPER.replace(
            "#*# \t-0.067500, 0.000000, 0.055000\n",
            "#*# \t-0.067500, 0.000000\n",
        );
        let e = read_klipper_mesh(&short, "p.cfg", None).unwrap_err();
        assert_eq!(e.line, 14);
        let no_max = KLIPPER.replace("#*# max_x = 268.0\n", "");
        let e = read_klipper_mesh(&no_max, "p.cfg", None).unwrap_err();
        assert!(e.message.contains("max_x"), "{e}");
        let e = read_klipper_mesh("[printer]\n", "p.cfg", None).unwrap_err();
        assert!(e.message.contains("no `#*# [bed_mesh"), "{e}");
    }

    #[test]
    fn node_positions_print_as_probed() {
        let g = Grid {
            min: [20.0, 10.1],
            spacing: [32.67, 23.13],
            count: [9, 9],
        };
        for a in 0..2 {
            for i in 0..9 {
                let p = g.pos(a, i).to_string();
                let decimals = p.split('.').nth(1).map_or(0, str::len);
                assert!(decimals <= 2, "{p}");
            }
        }
        assert_eq!(g.pos(0, 7), 248.69);
    }
}
