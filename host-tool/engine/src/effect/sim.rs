//! What a family's simulated form is to the simulator: a physical effect
//! on top of the synthetic machine's geometric errors (`simulate --effect
//! <family>:…`). Each family that has one defines it in its own file
//! ([`super::Info::simulate`] parses it); `simulate` walks the plan, then
//! asks each form for the tool lengths it cycles through, the temperature
//! channel it records and the error it adds at every reading. Magnitudes
//! are checked against a [`Limit`] each, named as the spec names them.

use std::fmt;

use anyhow::Result;

use crate::data::TempChannel;

/// The readings of a simulated measurement, as the simulator walked them
/// (one entry per row).
#[derive(Debug)]
pub struct SimRows<'a> {
    /// Positions per axis, mm.
    pub pos_mm: &'a [Vec<f64>; 3],
    /// Approach direction per axis (±1).
    pub dir: &'a [Vec<i8>; 3],
    /// Time of each reading, s (rounded as written).
    pub t_s: &'a [f64],
    /// Session of each reading.
    pub session: &'a [i64],
    /// Tool length of each reading, mm.
    pub tool_mm: &'a [f64],
    /// The recorded temperature channels (rounded as written).
    pub temps: &'a [TempChannel],
}

/// A temperature sensor an effect records (`T_<name>_C`).
pub trait Sensor {
    /// The channel's name (`bed` → `T_bed_C`).
    fn name(&self) -> &str;
    /// Its reading at `t_s`, °C (the simulator rounds it as a display would).
    fn temp_c(&self, t_s: f64) -> f64;
}

/// A family's simulated form. `Display` is the canonical spec, with every
/// parameter (parsing it gives the same form back).
pub trait SimForm: fmt::Display + fmt::Debug + Send + Sync {
    /// Whether the form can be simulated at all (a period > 0, a tool
    /// list not empty): a form built in Rust may not be.
    fn valid(&self) -> bool {
        true
    }
    /// Every number finite and inside its [`Limit`]; `what(key)` names it
    /// in the message (`effect \`periodic\`: amp_um`).
    fn check_numbers(&self, what: &dyn Fn(&str) -> String) -> Result<()>;
    /// The tool lengths it cycles through, one per pass (abbe).
    fn tools_mm(&self) -> Option<&[f64]> {
        None
    }
    /// The temperature channel it records (thermal).
    fn sensor(&self) -> Option<&dyn Sensor> {
        None
    }
    /// Adds its error at every reading to `truth` (µm per target).
    fn add_error(&self, rows: &SimRows, truth: &mut [Vec<f64>; 3]);
    /// What the data cannot show of it, for the file's metadata (a
    /// reversal approached from one side only).
    fn warning(&self, _rows: &SimRows) -> Option<String> {
        None
    }
}

/// A sensible range for one simulation number: generous enough for any
/// real machine and instrument (ARCHITECTURE.md's magnitudes sit well
/// inside), tight enough that a typo (`1e300`, a NaN) is refused with its
/// name instead of silently producing a file of absurd or NaN errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// Smallest value allowed.
    pub min: f64,
    /// Largest value allowed.
    pub max: f64,
    /// `min` itself is allowed (false: strictly greater, e.g. a step).
    pub min_inclusive: bool,
    /// Unit for the message.
    pub unit: &'static str,
}

impl Limit {
    /// `min ≤ v ≤ max`.
    pub const fn closed(min: f64, max: f64, unit: &'static str) -> Limit {
        Limit {
            min,
            max,
            min_inclusive: true,
            unit,
        }
    }

    /// `min < v ≤ max`.
    pub const fn above(min: f64, max: f64, unit: &'static str) -> Limit {
        Limit {
            min,
            max,
            min_inclusive: false,
            unit,
        }
    }

    /// Tool length / probe offset (and every Abbe tool length).
    pub const TOOL_MM: Limit = Limit::closed(-1000.0, 1000.0, "mm");
    /// Cyclic error amplitude (1–8 µm typical), and a guide bump's height.
    pub const AMP_UM: Limit = Limit::closed(-100.0, 100.0, "µm");

    /// `Ok` when `v` is finite and inside; otherwise how it is not.
    pub fn test(&self, v: f64) -> Result<(), OutOfRange> {
        let low_ok = if self.min_inclusive {
            v >= self.min
        } else {
            v > self.min
        };
        if v.is_finite() && low_ok && v <= self.max {
            Ok(())
        } else {
            Err(OutOfRange {
                value: v,
                limit: *self,
            })
        }
    }

    /// `Ok` when `v` is finite and inside; otherwise an error naming `what`.
    pub fn check(&self, what: &str, v: f64) -> anyhow::Result<()> {
        self.test(v).map_err(|e| anyhow::anyhow!("{what} = {e}"))
    }
}

/// A number that is not finite or outside its [`Limit`]: `1e300: expected
/// a finite value ≥ 0 µm and ≤ 100 µm` (the caller names the number).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfRange {
    /// The number given.
    pub value: f64,
    /// Its range.
    pub limit: Limit,
}

impl fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = &self.limit;
        let lo = if l.min_inclusive { "≥" } else { ">" };
        let unit = if l.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", l.unit)
        };
        // `{:?}`: 1e300 prints as `1e300`, not as 301 digits.
        write!(
            f,
            "{:?}: expected a finite value {lo} {}{unit} and ≤ {}{unit}",
            self.value, l.min, l.max
        )
    }
}

impl std::error::Error for OutOfRange {}
