//! The measurement data set: one in-memory form of CONTRACT.md §1 that every
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

/// One measurement data set (CONTRACT.md §1).
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
}

impl Dataset {
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

    /// Indices (0 = ex, 1 = ey, 2 = ez) of the targets present.
    pub fn targets(&self) -> Vec<usize> {
        (0..3).filter(|&t| self.err_um[t].is_some()).collect()
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
}
