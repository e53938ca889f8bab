//! The travel a model is fitted on — and with it the envelope of every
//! table exported from it: per axis the machine's limits when the user
//! gives them (`fit --travel x=0..800`), else the **bulk** of the data.
//! Rows outside it are named (file, line, position), left out of the fit
//! and recorded in MODEL.json (`data.outside_travel`), so that `export`
//! names them again; the travel is never silently widened by one row. (One
//! row at x = 1999 mm in 0–800 mm data used to make the table's travel
//! 0–1999 mm, raise its max-correction clamp fivefold and its held-out
//! error twentyfold, unremarked.)
//!
//! **The bulk's rule** (docs/cli.md § fit, "Travel"), per axis, on the
//! distinct positions (to 1 nm) in order. The *core* is what is left when
//! the outermost positions that hold at most [`STRAY_SHARE`] (1 %) of the
//! rows are set aside at each end. A *tail* — the positions beyond one gap
//! outside the core, at either end — is a stray when that gap is wider
//! than [`STRAY_SPACINGS`] (2.5) times the widest gap inside the core
//! *and* than [`STRAY_SPAN`] (10 %) of the core's span. So a measured
//! plane or line (more than 1 % of the rows) is never a stray, whatever its
//! place; a coarse grid, a plan with uneven steps, a dense stretch with
//! coarse steps beyond it, or scattered positions have no such gap; a row
//! off an axis held at one position on every other row is one (the core
//! has no span). The widest stray tail at each end is cut. Fewer than 100
//! rows never have a stray (1 % of them is less than one row): the rule
//! judges a bulk, and a small data set has none to judge by.

use serde::{Deserialize, Serialize};

use crate::data::{Dataset, AXES};

/// A tail holds at most this share of the rows to be a stray.
pub const STRAY_SHARE: f64 = 0.01;
/// A stray tail's gap is wider than this many times the widest gap inside
/// the bulk …
pub const STRAY_SPACINGS: f64 = 2.5;
/// … and than this share of the bulk's span.
pub const STRAY_SPAN: f64 = 0.1;

/// Per axis (x, y, z) the travel `(lo, hi)`, mm; `None` = not given.
pub type Limits = [Option<(f64, f64)>; 3];

/// Which travel a row lies outside of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// The travel the user gave for the axis.
    Given,
    /// The bulk of the data (module doc).
    Bulk,
}

/// One row outside the travel on one axis (a row outside on two axes is
/// listed twice).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutsideRow {
    /// Line of the row in the source file (1-based); null for data that did
    /// not come from a file.
    pub line: Option<usize>,
    /// Data row (0-based, the order of the file's data rows).
    pub row: usize,
    /// `x`, `y` or `z`.
    pub axis: String,
    /// The row's position on the axis, mm.
    pub position_mm: f64,
    /// The travel of the axis, `[lo, hi]` mm.
    pub travel_mm: [f64; 2],
    /// Which travel: the one given or the bulk's.
    pub rule: Rule,
    /// Per target measured on the row, measured − model, µm, of the model
    /// fitted without it (evaluated outside its travel: how far the model
    /// misses the row it was not fitted to); empty until a model is made.
    #[serde(default)]
    pub resid_um: std::collections::BTreeMap<String, f64>,
}

impl OutsideRow {
    /// `d.csv:332: x = 1999 mm, outside the travel x 0…800 mm (the data's
    /// bulk); the model fitted without it misses it by ex 12.3 µm`.
    pub fn text(&self, source: &str) -> String {
        let at = match self.line {
            Some(l) => format!("{source}:{l}"),
            None => format!("{source} row {}", self.row + 1),
        };
        let whose = match self.rule {
            Rule::Given => "as given",
            Rule::Bulk => "the data's bulk",
        };
        let mut s = format!(
            "{at}: {ax} = {} mm, outside the travel {ax} {}…{} mm ({whose})",
            self.position_mm,
            self.travel_mm[0],
            self.travel_mm[1],
            ax = self.axis
        );
        if !self.resid_um.is_empty() {
            let misses: Vec<String> = self
                .resid_um
                .iter()
                .map(|(t, r)| format!("{t} {r:.3} µm"))
                .collect();
            s.push_str(&format!(
                "; the model fitted without it misses it by {}",
                misses.join(", ")
            ));
        }
        s
    }
}

/// The travel of a data set and the rows outside it.
#[derive(Clone, Debug, PartialEq)]
pub struct Screen {
    /// Per axis present in the data, the travel: given, or the bulk's
    /// span (a subset of the data's span).
    pub travel_mm: Limits,
    /// The rows outside it, by axis then row.
    pub outside: Vec<OutsideRow>,
    /// The rows inside on every axis, in order.
    kept: Vec<usize>,
}

/// A travel given for an axis the data does not have, or an empty one.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TravelError {
    /// `lo > hi`, or a bound that is not a finite number.
    #[error("travel {axis}: {lo}…{hi} mm is empty (expected finite numbers, low ≤ high)")]
    Empty {
        /// `x`, `y` or `z`.
        axis: &'static str,
        /// The low end given, mm.
        lo: f64,
        /// The high end given, mm.
        hi: f64,
    },
    /// An axis the data has no column for.
    #[error("travel {axis}: the data has no {axis}_mm column")]
    NoAxis {
        /// `x`, `y` or `z`.
        axis: &'static str,
    },
    /// Every row outside the travel.
    #[error("every row lies outside the travel {axis} {lo}…{hi} mm")]
    NothingInside {
        /// `x`, `y` or `z`.
        axis: &'static str,
        /// mm.
        lo: f64,
        /// mm.
        hi: f64,
    },
}

/// Whole nanometres: the resolution positions are told apart at.
fn nm(p: f64) -> i64 {
    (p * 1e6).round() as i64
}

/// The travel of `data` on each axis (`given`, else the bulk's rule of the
/// module doc) and the rows outside it.
pub fn screen(data: &Dataset, given: &Limits) -> Result<Screen, TravelError> {
    let n = data.len();
    let mut travel_mm: Limits = [None; 3];
    let mut outside = Vec::new();
    let mut out_row = vec![false; n];
    for a in 0..3 {
        let Some(col) = &data.pos_mm[a] else {
            if given[a].is_some() {
                return Err(TravelError::NoAxis { axis: AXES[a] });
            }
            continue;
        };
        let (lo, hi, rule) = match given[a] {
            Some((lo, hi)) => {
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                    return Err(TravelError::Empty {
                        axis: AXES[a],
                        lo,
                        hi,
                    });
                }
                (lo, hi, Rule::Given)
            }
            None => {
                let (lo, hi) = bulk(col);
                (lo, hi, Rule::Bulk)
            }
        };
        let (lo_nm, hi_nm) = (nm(lo), nm(hi));
        for (r, &p) in col.iter().enumerate() {
            if nm(p) < lo_nm || nm(p) > hi_nm {
                out_row[r] = true;
                outside.push(OutsideRow {
                    line: data.line.get(r).copied(),
                    row: r,
                    axis: AXES[a].to_string(),
                    position_mm: p,
                    travel_mm: [lo, hi],
                    rule,
                    resid_um: Default::default(),
                });
            }
        }
        travel_mm[a] = Some((lo, hi));
        if n > 0 && out_row.iter().all(|&o| o) {
            return Err(TravelError::NothingInside {
                axis: AXES[a],
                lo,
                hi,
            });
        }
    }
    let kept = (0..n).filter(|&r| !out_row[r]).collect();
    Ok(Screen {
        travel_mm,
        outside,
        kept,
    })
}

impl Screen {
    /// The data rows outside the travel (each once), in order.
    pub fn outside_rows(&self) -> Vec<usize> {
        let mut rows: Vec<usize> = self.outside.iter().map(|o| o.row).collect();
        rows.sort_unstable();
        rows.dedup();
        rows
    }

    /// `data` without the rows outside the travel (`data` itself when
    /// there are none): what the fit sees.
    pub fn inside<'a>(&self, data: &'a Dataset) -> std::borrow::Cow<'a, Dataset> {
        if self.outside.is_empty() {
            std::borrow::Cow::Borrowed(data)
        } else {
            std::borrow::Cow::Owned(crate::data::subset(data, &self.kept))
        }
    }

    /// The file's row of row `r` of [`Screen::inside`] (a data row index of
    /// the fitted data back in the order of the file).
    pub fn file_row(&self, r: usize) -> usize {
        if self.outside.is_empty() {
            r
        } else {
            self.kept[r]
        }
    }
}

/// Rows named in [`summary`]; the rest are counted.
const NAMED: usize = 3;

/// `2 rows lie outside the travel and were left out of the fit: d.csv:332:
/// x = 1999 mm, …; …` (the first three named), or `None` when none do.
/// `source` names the data file.
pub fn summary(source: &str, outside: &[OutsideRow]) -> Option<String> {
    let rows = {
        let mut r: Vec<usize> = outside.iter().map(|o| o.row).collect();
        r.sort_unstable();
        r.dedup();
        r.len()
    };
    if rows == 0 {
        return None;
    }
    let mut named: Vec<String> = outside.iter().take(NAMED).map(|o| o.text(source)).collect();
    if outside.len() > NAMED {
        named.push(format!("and {} more", outside.len() - NAMED));
    }
    Some(format!(
        "{rows} {} outside the travel and {} left out of the fit: {}",
        if rows == 1 { "row lies" } else { "rows lie" },
        if rows == 1 { "was" } else { "were" },
        named.join("; ")
    ))
}

/// Per axis with rows outside, the travel that would hold them too:
/// `(axis, lo, hi)`, mm.
pub fn widened(outside: &[OutsideRow]) -> Vec<(String, f64, f64)> {
    let mut out: Vec<(String, f64, f64)> = Vec::new();
    for o in outside {
        let [lo, hi] = o.travel_mm;
        match out.iter_mut().find(|(a, _, _)| *a == o.axis) {
            Some((_, l, h)) => {
                *l = l.min(o.position_mm);
                *h = h.max(o.position_mm);
            }
            None => out.push((o.axis.clone(), lo.min(o.position_mm), hi.max(o.position_mm))),
        }
    }
    out
}

/// The bulk's travel `(lo, hi)` of one axis' positions, mm (module doc):
/// their whole span unless a tail at either end is a stray.
pub fn bulk(positions: &[f64]) -> (f64, f64) {
    let mut sorted: Vec<f64> = positions.to_vec();
    sorted.sort_unstable_by(f64::total_cmp);
    let (Some(&first), Some(&last)) = (sorted.first(), sorted.last()) else {
        return (0.0, 0.0);
    };
    // Distinct positions (to 1 nm) with their rows: the first value of
    // each run stands for it.
    let mut pos: Vec<(f64, usize)> = Vec::new();
    for &p in &sorted {
        match pos.last_mut() {
            Some((q, c)) if nm(*q) == nm(p) => *c += 1,
            _ => pos.push((p, 1)),
        }
    }
    let most = (positions.len() as f64 * STRAY_SHARE).floor() as usize;
    let k = pos.len();
    if most == 0 || k < 2 {
        return (first, last);
    }
    // The core: the positions left when as many outermost positions as
    // hold at most `most` rows are set aside at each end — no stray is in
    // it, so neither end's strays widen the gap the other end's are
    // judged against.
    let set_aside = |order: &mut dyn Iterator<Item = usize>| {
        let mut rows = 0;
        for i in order {
            rows += pos[i].1;
            if rows > most {
                return i;
            }
        }
        0
    };
    let core_lo = set_aside(&mut (0..k));
    let core_hi = set_aside(&mut (0..k).rev()).max(core_lo);
    let widest = (core_lo..core_hi)
        .map(|i| pos[i + 1].0 - pos[i].0)
        .fold(0.0, f64::max);
    let span = pos[core_hi].0 - pos[core_lo].0;
    let stray = |gap: f64| gap > STRAY_SPACINGS * widest && gap > STRAY_SPAN * span;
    // The widest stray tail at each end: the innermost gap outside the
    // core that is a stray's.
    let hi = (core_hi..k - 1)
        .find(|&i| stray(pos[i + 1].0 - pos[i].0))
        .unwrap_or(k - 1);
    let lo = (1..=core_lo)
        .rev()
        .find(|&i| stray(pos[i].0 - pos[i - 1].0))
        .unwrap_or(0);
    // The bulk's ends: the extreme values of its end positions' runs.
    let lo_mm = sorted
        .iter()
        .copied()
        .find(|&p| nm(p) == nm(pos[lo].0))
        .unwrap_or(first);
    let hi_mm = sorted
        .iter()
        .rev()
        .copied()
        .find(|&p| nm(p) == nm(pos[hi].0))
        .unwrap_or(last);
    (lo_mm, hi_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `reps` rows at each of `positions`.
    fn repeated(positions: &[f64], reps: usize) -> Vec<f64> {
        positions
            .iter()
            .flat_map(|&p| std::iter::repeat_n(p, reps))
            .collect()
    }

    fn grid(lo: f64, step: f64, n: usize) -> Vec<f64> {
        (0..n).map(|i| lo + step * i as f64).collect()
    }

    #[test]
    fn one_row_far_beyond_the_grid_is_a_stray() {
        // The case: 0…800 mm in 100 mm steps, 36 rows each, and
        // one row at 1999 mm.
        let mut x = repeated(&grid(0.0, 100.0, 9), 36);
        x.push(1999.0);
        assert_eq!(bulk(&x), (0.0, 800.0));
        // At the low end, and two rows together (a tail of two positions).
        let mut x = repeated(&grid(0.0, 100.0, 9), 36);
        x.extend([-900.0, -905.0]);
        assert_eq!(bulk(&x), (0.0, 800.0));
        // Both ends at once.
        x.push(2500.0);
        assert_eq!(bulk(&x), (0.0, 800.0));
        // A dense line with one row 150 mm beyond it.
        let mut x = grid(0.0, 1.0, 801);
        x.push(950.0);
        assert_eq!(bulk(&x), (0.0, 800.0));
        // A coarse grid of three planes and a row far beyond.
        let mut x = repeated(&[0.0, 400.0, 800.0], 100);
        x.push(1999.0);
        assert_eq!(bulk(&x), (0.0, 800.0));
    }

    #[test]
    fn an_axis_held_on_every_row_but_one_is_held() {
        let mut y = vec![250.0; 300];
        y.push(1999.0);
        assert_eq!(bulk(&y), (250.0, 250.0));
    }

    #[test]
    fn legitimate_plans_have_no_stray() {
        let whole = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(bulk(v), (lo, hi), "{v:?}");
        };
        // A coarse grid (three planes), a single dense line, one row per
        // position.
        whole(&repeated(&[0.0, 400.0, 800.0], 100));
        whole(&grid(0.0, 4.0, 201));
        // ISO 230-2 targets with uneven steps, 10 readings each.
        whole(&repeated(
            &[0.0, 97.5, 201.3, 302.1, 398.8, 505.0, 601.9, 700.4, 800.0],
            10,
        ));
        // A plane measured far from the others holds many rows: a plan.
        let mut z = repeated(&grid(0.0, 10.0, 5), 40);
        z.extend(repeated(&[900.0], 40));
        whole(&z);
        // A stray step of one spacing or two (the grid goes on).
        let mut x = repeated(&grid(0.0, 100.0, 9), 36);
        x.push(1000.0);
        whole(&x);
        // Scattered positions: the ends' gaps are like the inner ones.
        let mut rng = trueaxis_test_support::SplitMix64(7);
        for n in [100, 300, 3000] {
            let v: Vec<f64> = (0..n).map(|_| rng.range(0.0, 800.0)).collect();
            whole(&v);
        }
        // Dense where it matters, coarse beyond, one row per position.
        let mut x = grid(0.0, 1.0, 101);
        x.extend(grid(200.0, 100.0, 7));
        whole(&x);
        // Fewer than 100 rows: no bulk to judge by.
        let mut x = grid(0.0, 100.0, 9);
        x.push(1999.0);
        whole(&x);
        // A dense y line and a coarse grid in y over the same travel.
        let mut y = grid(0.0, 0.5, 1001);
        y.extend(repeated(&grid(0.0, 50.0, 11), 20));
        whole(&y);
    }

    #[test]
    fn screen_names_rows_and_keeps_the_rest() {
        let mut x = repeated(&grid(0.0, 100.0, 9), 12);
        x.push(1999.0);
        let n = x.len();
        let d = Dataset {
            source: "d.csv".into(),
            pos_mm: [Some(x), Some(vec![5.0; n]), None],
            err_um: [Some(vec![Some(1.0); n]), None, None],
            line: (0..n).map(|r| r + 2).collect(),
            ..Dataset::default()
        };
        let s = screen(&d, &[None; 3]).unwrap();
        assert_eq!(s.travel_mm, [Some((0.0, 800.0)), Some((5.0, 5.0)), None]);
        assert_eq!(s.outside_rows(), vec![n - 1]);
        assert_eq!(
            s.outside[0].text("d.csv"),
            format!(
                "d.csv:{}: x = 1999 mm, outside the travel x 0…800 mm (the data's bulk)",
                n + 1
            )
        );
        let inside = s.inside(&d);
        assert_eq!(inside.len(), n - 1);
        assert_eq!(s.file_row(3), 3);
        // The user's travel keeps the row, and cuts where it says.
        let s = screen(&d, &[Some((0.0, 2000.0)), None, None]).unwrap();
        assert!(s.outside.is_empty());
        let s = screen(&d, &[Some((50.0, 2000.0)), None, None]).unwrap();
        assert_eq!(s.outside.len(), 12);
        assert!(s.outside.iter().all(|o| o.rule == Rule::Given));
        assert_eq!(s.file_row(0), 12);
        assert_eq!(
            screen(&d, &[None, None, Some((0.0, 1.0))]),
            Err(TravelError::NoAxis { axis: "z" })
        );
        assert_eq!(
            screen(&d, &[Some((2.0, 1.0)), None, None])
                .unwrap_err()
                .to_string(),
            "travel x: 2…1 mm is empty (expected finite numbers, low ≤ high)"
        );
        assert_eq!(
            screen(&d, &[Some((3000.0, 4000.0)), None, None])
                .unwrap_err()
                .to_string(),
            "every row lies outside the travel x 3000…4000 mm"
        );
    }
}
