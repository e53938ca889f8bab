//! The measurement data set: one in-memory form of docs/cli.md § Measurement CSV that every
//! command works on, whatever file it came from (CSV, Renishaw .rtl,
//! `simulate`). Columns are stored by meaning, not by position, so the
//! fitting and diagnosis code never looks at column names again; anything the
//! contract does not know is kept as an auxiliary channel, never dropped.
//!
//! Invariants (checked by the importers, relied on everywhere else):
//! every per-row vector has `len()` rows; at least one axis and one target
//! are present; all numbers are finite; `dir` values are -1 or +1.

use serde::{Deserialize, Serialize};

/// Axis names, in index order 0, 1, 2.
pub const AXES: [&str; 3] = ["x", "y", "z"];
/// Target (error) names, in index order 0, 1, 2: `ex`, `ey`, `ez`.
pub const TARGETS: [&str; 3] = ["ex", "ey", "ez"];
/// Angle reading names, in index order 0, 1, 2: rotation of the tool frame
/// relative to the workpiece about +X, +Y, +Z (docs/volumetric.md).
pub const ANGLES: [&str; 3] = ["ea", "eb", "ec"];

/// How far the length of a `beam_x, beam_y, beam_z` direction may be from 1
/// before the importers refuse it: direction cosines written with three
/// decimals (0.577, 0.577, 0.577 → 0.99993) are unit vectors; a direction
/// given in mm or left unnormalised (1, 1, 1) is not.
pub const BEAM_UNIT_TOL: f64 = 1e-3;

/// The largest |angle| an `e<a|b|c>_urad` cell may have, µrad: 0.1 rad. A
/// larger value is a unit mistake (arcsec, mrad·1000) or a broken reading.
pub const ANGLE_PLAUSIBLE_URAD: f64 = 100_000.0;

/// The temperatures a `T_<name>_C` reading may have, °C: a machine shop's
/// sensors (air, bed, spindle housing, coolant) read well inside −50…150 °C.
/// The importers refuse a value outside it as a unit mistake — most often
/// kelvin (250…400 read as °C), which would otherwise be fitted silently
/// and make the thermal terms meaningless.
pub const TEMP_PLAUSIBLE_C: (f64, f64) = (-50.0, 150.0);

/// The largest |position| a `<axis>_mm` cell may have, mm: 10 m, beyond
/// the travel of any machine the tool is for. A larger value is a unit or
/// export mistake (µm or nm in a mm column, a placeholder such as 1e308),
/// which would otherwise stretch or collapse the model's span silently.
pub const POS_PLAUSIBLE_MM: f64 = 10_000.0;

/// The largest |error| an `e<axis>_um` cell may have, µm: 10 mm, far beyond
/// any machine's positioning error. A larger value is a unit mistake (nm in
/// a µm column) or a broken beam's reading, which would otherwise set a
/// table's max correction.
pub const ERR_PLAUSIBLE_UM: f64 = 10_000.0;

/// A temperature sensor column `T_<name>_C`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TempChannel {
    /// The sensor name between `T_` and `_C` (`bed` for `T_bed_C`).
    pub name: String,
    /// One value per row, °C.
    pub temp_c: Vec<f64>,
}

/// A column the contract does not name: kept, reported, never dropped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AuxChannel {
    /// The header as written in the file.
    pub name: String,
    /// The raw cells, one per row.
    pub cells: Vec<String>,
}

/// One measurement data set (docs/cli.md § Measurement CSV).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// Where it came from (a path, or `simulate:<preset>`), for messages and reports.
    pub source: String,
    /// `# key: value` lines before the header, in file order.
    pub metadata: Vec<(String, String)>,
    /// Nominal positions x, y, z in mm; `None` for an axis not in the data.
    pub pos_mm: [Option<Vec<f64>>; 3],
    /// Measured errors ex, ey, ez in µm; `None` for a target not in the data,
    /// `Some(None)` cells for "not measured on this row".
    pub err_um: [Option<Vec<Option<f64>>>; 3],
    /// Time since the start of the session, s.
    pub t_s: Option<Vec<f64>>,
    /// Direction of the last approach per axis, -1 or +1.
    pub dir: [Option<Vec<i8>>; 3],
    /// Temperature channels, in file order.
    pub temps: Vec<TempChannel>,
    /// Tool length / probe offset along the spindle (Abbe arm), mm.
    pub tool_mm: Option<Vec<f64>>,
    /// One continuous traverse per id (block hold-out, ISO 230-2 runs).
    pub pass_id: Option<Vec<i64>>,
    /// Measurement session per row.
    pub session_id: Option<Vec<i64>>,
    /// Standard uncertainty of the error values per row, µm (fit weights).
    pub u_um: Option<Vec<f64>>,
    /// Columns the contract does not name.
    pub aux: Vec<AuxChannel>,
    /// Source line number of each row (1-based), for messages; empty when
    /// the data did not come from a file.
    pub line: Vec<usize>,
    /// Rows of the source that were left out, with the reason (docs/cli.md § Measurement CSV:
    /// nothing is silently skipped). Empty for simulated data.
    #[serde(default)]
    pub skipped: Vec<SkippedRow>,
    /// The set-up of an instrument that reads relative to its own zero and
    /// alignment (a laser line, an angular line, a diagonal, a tracker
    /// station), per row (docs/volumetric.md § Set-ups).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup_id: Option<Vec<i64>>,
    /// Lateral offsets of the measured point from the spindle axis along X
    /// and Y, mm (`tool_x_mm`, `tool_y_mm`); `tool_mm` is the offset along it.
    #[serde(default, skip_serializing_if = "no_columns")]
    pub tool_lat_mm: [Option<Vec<f64>>; 2],
    /// Angle readings `ea_urad`, `eb_urad`, `ec_urad`, µrad; `Some(None)`
    /// cells for "not measured on this row".
    #[serde(default, skip_serializing_if = "no_columns")]
    pub angle_urad: [Option<Vec<Option<f64>>>; 3],
    /// The unit direction `beam_x, beam_y, beam_z` of each row's
    /// `e_beam_um` reading; `None` on rows without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam_dir: Option<Vec<Option<[f64; 3]>>>,
    /// The error's component along the row's beam direction, µm
    /// (`e_beam_um`: a diagonal's displacement, a ballbar's radial reading).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam_um: Option<Vec<Option<f64>>>,
}

/// True when none of the columns is present (serde: old data sets keep
/// their JSON).
fn no_columns<T, const N: usize>(cols: &[Option<T>; N]) -> bool {
    cols.iter().all(Option::is_none)
}

/// A source row that was left out of the data set, and why.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SkippedRow {
    /// 1-based line number in the source file.
    pub line: usize,
    /// Why the row was left out (`no error value on this row`, …).
    pub reason: String,
}

/// The positions of a regular grid of `counts` nodes per axis, `step_mm`
/// apart from 0, x outermost and z innermost: `[x, y, z]` columns for a
/// data set (tests, benches and examples build their grids with it).
pub fn grid_positions(counts: [usize; 3], step_mm: [f64; 3]) -> [Vec<f64>; 3] {
    let mut p: [Vec<f64>; 3] = Default::default();
    for i in 0..counts[0] {
        for j in 0..counts[1] {
            for k in 0..counts[2] {
                for (a, n) in [i, j, k].into_iter().enumerate() {
                    p[a].push(n as f64 * step_mm[a]);
                }
            }
        }
    }
    p
}

impl Dataset {
    /// The fields in which `self` and `other` differ, by name: everything
    /// a data file holds — its metadata and every column — and not where
    /// it came from (`source`, file lines, skipped rows). Empty: what a
    /// write and read back must give.
    pub fn columns_differing(&self, other: &Dataset) -> Vec<&'static str> {
        let mut out = Vec::new();
        macro_rules! compare {
            ($($field:ident),*) => {
                $(if self.$field != other.$field {
                    out.push(stringify!($field));
                })*
            };
        }
        compare!(
            metadata,
            pos_mm,
            err_um,
            t_s,
            dir,
            temps,
            tool_mm,
            pass_id,
            session_id,
            u_um,
            aux,
            setup_id,
            tool_lat_mm,
            angle_urad,
            beam_dir,
            beam_um
        );
        out
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.pos_mm
            .iter()
            .flatten()
            .map(Vec::len)
            .next()
            .unwrap_or(0)
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Indices (0 = x, 1 = y, 2 = z) of the axes present.
    pub fn axes(&self) -> Vec<usize> {
        (0..3).filter(|&a| self.pos_mm[a].is_some()).collect()
    }

    /// Indices of the axes present that move: more than one position in the
    /// data. An axis held at one position (a single-axis line with y = z =
    /// 250 mm on every row) carries no information about how the error
    /// changes along it, so the models treat it like an axis absent from the
    /// data (no terms in it; grid nodes and network inputs only on moving
    /// axes).
    pub fn varying_axes(&self) -> Vec<usize> {
        self.axes()
            .into_iter()
            .filter(|&a| self.constant_position(a).is_none())
            .collect()
    }

    /// The position of `axis` when it is present and every row holds the
    /// same value, mm; `None` when the axis is absent or moves.
    pub fn constant_position(&self, axis: usize) -> Option<f64> {
        let col = self.pos_mm[axis].as_ref()?;
        let first = *col.first()?;
        col.iter().all(|&p| p == first).then_some(first)
    }

    /// A probed surface — a printer bed (RepRapFirmware heightmap, Klipper
    /// mesh, any z-only grid over x and y) rather than a machine-tool
    /// measurement: ez is the only target, x and y both vary, z is absent
    /// or constant and no approach direction is logged. Its pages speak of
    /// a bed (height up = warm, a grid or smoother mesh as the model).
    pub fn is_probed_surface(&self) -> bool {
        let varies = |a: usize| {
            self.pos_mm[a]
                .as_ref()
                .is_some_and(|c| c.iter().any(|&p| p != c[0]))
        };
        self.targets() == [2]
            && varies(0)
            && varies(1)
            && !varies(2)
            && self.dir.iter().all(Option::is_none)
    }

    /// Rows that repeat an earlier row exactly — every column equal,
    /// auxiliary cells too — as `(row, earlier row)`, in row order (each
    /// paired with the first row it repeats). A file written twice, or a
    /// logger that wrote one reading again: not a second reading, so the
    /// noise floor never counts them as repeats (docs/diagnose.md § Noise
    /// floor), and `import`, `fit`, `diagnose` and `improve` name their
    /// lines (`duplicate_rows`, docs/cli.md § Measurement CSV).
    pub fn duplicate_rows(&self) -> Vec<(usize, usize)> {
        // −0.0 and 0.0 are one value.
        let bits = |v: f64| (v + 0.0).to_bits();
        let mut first: std::collections::HashMap<(Vec<u64>, Vec<&str>), usize> =
            std::collections::HashMap::new();
        let mut out = Vec::new();
        for r in 0..self.len() {
            let mut k: Vec<u64> = Vec::new();
            k.extend(
                self.pos_mm
                    .iter()
                    .map(|c| c.as_ref().map_or(0, |c| bits(c[r]))),
            );
            for c in &self.err_um {
                // A missing cell differs from every value (NaN's bits).
                k.push(
                    c.as_ref()
                        .map_or(0, |c| c[r].map_or(f64::NAN.to_bits(), bits)),
                );
            }
            k.push(self.t_s.as_ref().map_or(0, |c| bits(c[r])));
            k.extend(
                self.dir
                    .iter()
                    .map(|c| c.as_ref().map_or(0, |c| c[r] as u64)),
            );
            k.extend(self.temps.iter().map(|c| bits(c.temp_c[r])));
            k.push(self.tool_mm.as_ref().map_or(0, |c| bits(c[r])));
            k.push(self.pass_id.as_ref().map_or(0, |c| c[r] as u64));
            k.push(self.session_id.as_ref().map_or(0, |c| c[r] as u64));
            k.push(self.u_um.as_ref().map_or(0, |c| bits(c[r])));
            // The volumetric columns (docs/volumetric.md): two readings of
            // one set-up at one point along other beams are no copies.
            let cell = |c: Option<f64>| c.map_or(f64::NAN.to_bits(), bits);
            k.push(self.setup_id.as_ref().map_or(0, |c| c[r] as u64));
            k.extend(
                self.tool_lat_mm
                    .iter()
                    .map(|c| c.as_ref().map_or(0, |c| bits(c[r]))),
            );
            k.extend(
                self.angle_urad
                    .iter()
                    .map(|c| c.as_ref().map_or(0, |c| cell(c[r]))),
            );
            if let Some(d) = &self.beam_dir {
                k.extend(d[r].map_or([f64::NAN; 3], |v| v).map(bits));
            }
            k.push(self.beam_um.as_ref().map_or(0, |c| cell(c[r])));
            let cells: Vec<&str> = self
                .aux
                .iter()
                .map(|c| c.cells.get(r).map_or("", String::as_str))
                .collect();
            match first.entry((k, cells)) {
                std::collections::hash_map::Entry::Occupied(e) => out.push((r, *e.get())),
                std::collections::hash_map::Entry::Vacant(e) => {
                    e.insert(r);
                }
            }
        }
        out
    }

    /// Indices (0 = ex, 1 = ey, 2 = ez) of the targets present.
    pub fn targets(&self) -> Vec<usize> {
        (0..3).filter(|&t| self.err_um[t].is_some()).collect()
    }

    /// True when the data hold a reading column beyond `ex_um`, `ey_um`,
    /// `ez_um` (an angle or a beam reading), which only the volumetric
    /// model reads (docs/volumetric.md).
    pub fn has_volumetric_readings(&self) -> bool {
        self.angle_urad.iter().any(Option::is_some) || self.beam_um.is_some()
    }

    /// Lateral offset of row `row`'s measured point from the spindle axis
    /// along X (`lat` = 0) or Y (`lat` = 1), mm; 0 without the column.
    pub fn tool_lat(&self, lat: usize, row: usize) -> f64 {
        self.tool_lat_mm[lat].as_ref().map_or(0.0, |v| v[row])
    }

    /// Tool length of row `row`, mm; 0 without the column.
    pub fn tool(&self, row: usize) -> f64 {
        self.tool_mm.as_ref().map_or(0.0, |v| v[row])
    }

    /// Position of row `row` on `axis` in mm; 0 for an axis not in the data
    /// (the machine sits at its reference there).
    pub fn pos(&self, axis: usize, row: usize) -> f64 {
        self.pos_mm[axis].as_ref().map_or(0.0, |v| v[row])
    }

    /// Rows where target `t` was measured, with the value in µm.
    pub fn measured(&self, t: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.err_um[t]
            .iter()
            .flat_map(|col| col.iter().enumerate())
            .filter_map(|(row, v)| v.map(|v| (row, v)))
    }

    /// The temperature channel named `name` (without `T_` / `_C`).
    pub fn temp(&self, name: &str) -> Option<&TempChannel> {
        self.temps.iter().find(|c| c.name == name)
    }

    /// Checks the invariants listed at the top of this module: equal column
    /// lengths, an axis and a target present, finite numbers, `dir` ±1.
    /// Importers and `simulate` call it before handing a data set out.
    pub fn validate(&self) -> anyhow::Result<()> {
        use anyhow::bail;
        let n = self.len();
        if self.axes().is_empty() {
            bail!(
                "{}: no position column (expected x_mm, y_mm or z_mm)",
                self.source
            );
        }
        if self.targets().is_empty() && !self.has_volumetric_readings() {
            bail!(
                "{}: no error column (expected ex_um, ey_um or ez_um)",
                self.source
            );
        }
        let mut lens: Vec<(String, usize)> = Vec::new();
        for a in 0..3 {
            if let Some(v) = &self.pos_mm[a] {
                lens.push((format!("{}_mm", AXES[a]), v.len()));
                if v.iter().any(|x| !x.is_finite()) {
                    bail!("{}: {}_mm holds a non-finite value", self.source, AXES[a]);
                }
            }
            if let Some(v) = &self.err_um[a] {
                lens.push((format!("{}_um", TARGETS[a]), v.len()));
                if v.iter().flatten().any(|x| !x.is_finite()) {
                    bail!(
                        "{}: {}_um holds a non-finite value",
                        self.source,
                        TARGETS[a]
                    );
                }
            }
            if let Some(v) = &self.dir[a] {
                lens.push((format!("dir_{}", AXES[a]), v.len()));
                if v.iter().any(|d| *d != 1 && *d != -1) {
                    bail!(
                        "{}: dir_{} holds a value other than -1/+1",
                        self.source,
                        AXES[a]
                    );
                }
            }
        }
        for (a, col) in self.angle_urad.iter().enumerate() {
            if let Some(v) = col {
                lens.push((format!("{}_urad", ANGLES[a]), v.len()));
                if v.iter().flatten().any(|x| !x.is_finite()) {
                    bail!(
                        "{}: {}_urad holds a non-finite value",
                        self.source,
                        ANGLES[a]
                    );
                }
            }
        }
        if let Some(v) = &self.beam_um {
            lens.push(("e_beam_um".into(), v.len()));
            if v.iter().flatten().any(|x| !x.is_finite()) {
                bail!("{}: e_beam_um holds a non-finite value", self.source);
            }
            let Some(dirs) = &self.beam_dir else {
                bail!(
                    "{}: e_beam_um without its direction beam_x, beam_y, beam_z",
                    self.source
                );
            };
            for (r, (b, d)) in v.iter().zip(dirs).enumerate() {
                match (b, d) {
                    (Some(_), None) => {
                        bail!(
                            "{}: row {} has e_beam_um but no beam direction",
                            self.source,
                            r + 1
                        )
                    }
                    (_, Some(d)) if !is_unit(*d) => bail!(
                        "{}: row {}: beam direction ({}, {}, {}) is not a unit vector",
                        self.source,
                        r + 1,
                        d[0],
                        d[1],
                        d[2]
                    ),
                    _ => {}
                }
            }
        }
        if let Some(v) = &self.beam_dir {
            lens.push(("beam_x".into(), v.len()));
        }
        let opt_f = [
            ("t_s", &self.t_s),
            ("tool_mm", &self.tool_mm),
            ("tool_x_mm", &self.tool_lat_mm[0]),
            ("tool_y_mm", &self.tool_lat_mm[1]),
            ("u_um", &self.u_um),
        ];
        for (name, col) in opt_f {
            if let Some(v) = col {
                lens.push((name.to_string(), v.len()));
                if v.iter().any(|x| !x.is_finite()) {
                    bail!("{}: {name} holds a non-finite value", self.source);
                }
            }
        }
        for (name, col) in [
            ("pass_id", &self.pass_id),
            ("session_id", &self.session_id),
            ("setup_id", &self.setup_id),
        ] {
            if let Some(v) = col {
                lens.push((name.to_string(), v.len()));
            }
        }
        for c in &self.temps {
            lens.push((format!("T_{}_C", c.name), c.temp_c.len()));
            if c.temp_c.iter().any(|x| !x.is_finite()) {
                bail!("{}: T_{}_C holds a non-finite value", self.source, c.name);
            }
        }
        for c in &self.aux {
            lens.push((c.name.clone(), c.cells.len()));
        }
        if !self.line.is_empty() {
            lens.push(("line numbers".into(), self.line.len()));
        }
        if let Some((name, len)) = lens.iter().find(|(_, len)| *len != n) {
            bail!(
                "{}: column {name} has {len} rows, expected {n}",
                self.source
            );
        }
        Ok(())
    }
}
/// True when the direction `d` has length 1 within [`BEAM_UNIT_TOL`].
pub fn is_unit(d: [f64; 3]) -> bool {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    d.iter().all(|c| c.is_finite()) && (len - 1.0).abs() <= BEAM_UNIT_TOL
}

/// The rows of `data` listed in `rows`, as a data set of their own (every
/// per-row column sliced; metadata and channel names kept). Used to refit
/// non-linear models (grid, local) without a block.
pub fn subset(data: &Dataset, rows: &[usize]) -> Dataset {
    fn pick<T: Clone>(v: &[T], rows: &[usize]) -> Vec<T> {
        rows.iter().map(|&r| v[r].clone()).collect()
    }
    let mut out = data.clone();
    out.pos_mm = data.pos_mm.clone().map(|c| c.map(|v| pick(&v, rows)));
    out.err_um = data.err_um.clone().map(|c| c.map(|v| pick(&v, rows)));
    out.dir = data.dir.clone().map(|c| c.map(|v| pick(&v, rows)));
    out.t_s = data.t_s.as_ref().map(|v| pick(v, rows));
    out.tool_mm = data.tool_mm.as_ref().map(|v| pick(v, rows));
    out.pass_id = data.pass_id.as_ref().map(|v| pick(v, rows));
    out.session_id = data.session_id.as_ref().map(|v| pick(v, rows));
    out.u_um = data.u_um.as_ref().map(|v| pick(v, rows));
    out.setup_id = data.setup_id.as_ref().map(|v| pick(v, rows));
    out.tool_lat_mm = data.tool_lat_mm.clone().map(|c| c.map(|v| pick(&v, rows)));
    out.angle_urad = data.angle_urad.clone().map(|c| c.map(|v| pick(&v, rows)));
    out.beam_dir = data.beam_dir.as_ref().map(|v| pick(v, rows));
    out.beam_um = data.beam_um.as_ref().map(|v| pick(v, rows));
    for t in &mut out.temps {
        t.temp_c = pick(&t.temp_c, rows);
    }
    for c in &mut out.aux {
        c.cells = pick(&c.cells, rows);
    }
    if !data.line.is_empty() {
        out.line = pick(&data.line, rows);
    }
    out
}
