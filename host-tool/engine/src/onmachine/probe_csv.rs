//! The measurement CSV's probe columns (docs/cli.md § Measurement CSV,
//! "Probe data"): a whole on-machine campaign in ONE file — every scan's
//! rows tagged with `session_id`, the probe reading in `d_um`, and the
//! columns that say how each reading was taken: `c_deg` (rotation angle of
//! a turned part), `orientation_deg` (0 or 180 for a reversal run),
//! `step_deg` (a multi-step position), `probe_no` (multi-probe runs),
//! `probe_id`, the surface normal `normal_x/y/z` and `contact_deg`; time
//! as `t_s` seconds or a `time` column of clock times. The
//! on-machine commands read one session of it as the small scan file they
//! read otherwise ([`ProbeTable::small`] writes that file's text), so both
//! ways give the same numbers. Values are checked here, where the line and
//! column are known. The file is recognised by its columns
//! ([`is_probe_csv`]); without `session_id` it is one session.

use anyhow::{bail, Result};

/// The columns this reader knows (other columns are ignored).
pub const COLUMNS: [&str; 15] = [
    "session_id",
    "x_mm",
    "y_mm",
    "z_mm",
    "t_s",
    "d_um",
    "c_deg",
    "step_deg",
    "orientation_deg",
    "probe_no",
    "probe_id",
    "normal_x",
    "normal_y",
    "normal_z",
    "contact_deg",
];

/// Columns no small scan file has: any one of them makes a file a probe
/// measurement CSV — `session_id` and [`COLUMNS`] from `orientation_deg` on.
fn campaign_only() -> impl Iterator<Item = &'static str> {
    let from_orientation = COLUMNS.iter().skip_while(|&&c| c != "orientation_deg");
    std::iter::once(COLUMNS[0]).chain(from_orientation.copied())
}

/// Whether `text` is a measurement CSV with probe data, by its columns: a
/// header with any of `session_id`, `orientation_deg`, `probe_no`,
/// `probe_id`, `normal_x/y/z`, `contact_deg`, or with the reading `d_um`
/// beside a rotation (`c_deg`, `step_deg`) — columns the small scan files
/// never hold together.
pub fn is_probe_csv(text: &str) -> bool {
    let head: Vec<&str> = text
        .trim_start_matches('\u{feff}')
        .lines()
        .find(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|l| l.split(',').map(str::trim).collect())
        .unwrap_or_default();
    let has = |c: &str| head.contains(&c);
    campaign_only().any(has) || (has("d_um") && (has("c_deg") || has("step_deg")))
}

/// One row: the value of each of [`COLUMNS`] (`None`: no such column or an
/// empty cell), `probe_id` as text, and the row's line.
#[derive(Clone, Debug)]
pub struct ProbeRow {
    /// 1-based line in the file.
    pub line: usize,
    /// Values in the order of [`COLUMNS`] (`probe_id` is `None` here).
    pub v: [Option<f64>; 15],
    /// The probe's id, if given.
    pub probe_id: Option<String>,
}

impl ProbeRow {
    /// The value of column `c` (one of [`COLUMNS`]).
    pub fn get(&self, c: &str) -> Option<f64> {
        self.v[COLUMNS
            .iter()
            .position(|k| *k == c)
            .expect("a known column")]
    }
}

/// A probe measurement CSV, read and checked.
#[derive(Clone, Debug)]
pub struct ProbeTable {
    /// The file's name in messages.
    pub name: String,
    /// Its rows.
    pub rows: Vec<ProbeRow>,
}

/// The limit and unit of a column's values.
fn limit(c: &str) -> (f64, &'static str) {
    if c.ends_with("_mm") {
        (crate::data::POS_PLAUSIBLE_MM, "mm")
    } else if c.ends_with("_um") {
        (crate::data::ERR_PLAUSIBLE_UM, "µm")
    } else if c.ends_with("_deg") {
        (3600.0, "°")
    } else if c == "t_s" {
        (3.2e7, "s")
    } else {
        (1.0 + 1e-9, "")
    }
}

/// Reads a probe measurement CSV: a header, `#` comment lines, one reading
/// per row. Errors name the file, line and column.
pub fn read(text: &str, name: &str) -> Result<ProbeTable> {
    let mut cols: Option<Vec<Option<usize>>> = None;
    let mut rows = Vec::new();
    // A `time` column of clock times (when there is no `t_s`): each row's
    // cell, turned into seconds from the first once all are read.
    let mut time_col: Option<usize> = None;
    let mut clock_cells: Vec<(usize, usize, String)> = Vec::new();
    for (ln, _, cells) in crate::import::data_lines(text) {
        let Some(c) = &cols else {
            let mut map = vec![None; COLUMNS.len()];
            for (j, cell) in cells.iter().enumerate() {
                if let Some(k) = COLUMNS.iter().position(|c| c == cell) {
                    if map[k].is_some() {
                        bail!("{name}:{ln}:{}: duplicate column `{cell}`", j + 1);
                    }
                    map[k] = Some(j);
                }
            }
            if map[4].is_none() {
                time_col = cells.iter().position(|c| *c == "time");
            }
            cols = Some(map);
            continue;
        };
        if let Some(j) = time_col {
            let cell = cells.get(j).copied().unwrap_or("");
            if !cell.is_empty() {
                clock_cells.push((rows.len(), ln, cell.to_string()));
            }
        }
        let mut v = [None; 15];
        let mut probe_id = None;
        for (k, col) in COLUMNS.iter().enumerate() {
            let Some(j) = c[k] else { continue };
            let cell = cells.get(j).copied().unwrap_or("");
            if cell.is_empty() {
                continue;
            }
            let at = |msg: String| {
                anyhow::anyhow!(
                    "{name}:{ln}:{}: `{col}`: {msg}, found `{}`",
                    j + 1,
                    crate::import::shown(cell)
                )
            };
            if *col == "probe_id" {
                probe_id = Some(cell.to_string());
                continue;
            }
            let x: f64 = cell
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| at("expected a finite number".into()))?;
            match *col {
                "session_id" | "probe_no" => {
                    if x.fract() != 0.0 || x.abs() > 1e9 || (*col == "probe_no" && x < 1.0) {
                        return Err(at(if *col == "probe_no" {
                            "expected a probe number 1, 2, 3, …".into()
                        } else {
                            "expected an integer".into()
                        }));
                    }
                }
                "orientation_deg" => {
                    let o = x.rem_euclid(360.0);
                    if o.abs() > 1e-6 && (o - 180.0).abs() > 1e-6 {
                        return Err(at(
                            "expected 0 or 180 (the part's orientation in a reversal run)".into(),
                        ));
                    }
                }
                _ => {
                    let (lim, unit) = limit(col);
                    if x.abs() > lim {
                        return Err(at(if unit.is_empty() {
                            "expected a unit vector's component, within ±1".into()
                        } else {
                            format!("expected a finite number within ±{lim} {unit}")
                        }));
                    }
                }
            }
            v[k] = Some(x);
        }
        // A normal is a unit vector (its three components together).
        if let (Some(a), Some(b), Some(d)) = (v[11], v[12], v[13]) {
            let l = (a * a + b * b + d * d).sqrt();
            if (l - 1.0).abs() > 1e-3 {
                bail!(
                    "{name}:{ln}:{}: `normal_x`…`normal_z`: expected a unit vector, found length {l:.4}",
                    c[11].unwrap_or(0) + 1
                );
            }
        }
        rows.push(ProbeRow {
            line: ln,
            v,
            probe_id,
        });
    }
    if cols.is_none() {
        bail!("{name}: no header line");
    }
    if let Some(j) = time_col {
        let refs: Vec<(usize, &str)> = clock_cells
            .iter()
            .map(|(_, l, c)| (*l, c.as_str()))
            .collect();
        let secs = crate::onmachine::clock::seconds(&refs, name, j + 1)?;
        for ((i, _, _), t) in clock_cells.iter().zip(secs) {
            rows[*i].v[4] = Some(t);
        }
    }
    Ok(ProbeTable {
        name: name.to_string(),
        rows,
    })
}

/// A file of several sessions read without saying which. Its text names
/// the choice in the engine's words; a caller with a flag for it writes
/// [`SessionNeeded::text`] with the flag.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}", self.text("the session's number"))]
pub struct SessionNeeded {
    /// The file's name in messages.
    pub file: String,
    /// Its sessions, in order of appearance.
    pub sessions: Vec<i64>,
}

impl SessionNeeded {
    /// The message, the choice of session called `how`.
    pub fn text(&self, how: &str) -> String {
        format!(
            "{}: {} sessions ({}): say which with {how}",
            self.file,
            self.sessions.len(),
            self.sessions
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// Which small scan file a session is read as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Small {
    /// Probe-centre positions: the position columns given (`x_mm`, …),
    /// and `t_s` when every row has it (ball and part scans).
    Positions,
    /// A straightness run: `<axis>_mm,d_um[,t_s]`, the rows of one
    /// orientation (0 or 180; all rows for 0 without the column).
    Straightness(char, u16),
    /// Three probes: `c_deg,p1_um,p2_um,p3_um`, each probe's rows in
    /// order (`probe_no` 1, 2, 3) side by side.
    ThreeProbe,
    /// A multi-step set: `c_deg,step_deg,p_um`.
    MultiStep,
    /// One probe round a turning part: `c_deg,p_um[,t_s]`.
    Roundness,
    /// A turned part's generatrices: `c_deg,z_mm,dev_um`.
    Workpiece,
}

fn num(x: f64) -> String {
    format!("{x}")
}

impl ProbeTable {
    /// The sessions in the file, in order of appearance.
    pub fn sessions(&self) -> Vec<i64> {
        let mut s: Vec<i64> = Vec::new();
        for r in &self.rows {
            if let Some(v) = r.get("session_id") {
                if !s.contains(&(v as i64)) {
                    s.push(v as i64);
                }
            }
        }
        s
    }

    /// The rows of `session`; `None` when the file holds one session (a
    /// file without `session_id` is one).
    pub fn select(&self, session: Option<i64>) -> Result<Vec<&ProbeRow>> {
        let all = self.sessions();
        if all.is_empty() {
            return match session {
                None => Ok(self.rows.iter().collect()),
                Some(s) => bail!(
                    "{}: no session {s} (the file has no `session_id` column: it is one session)",
                    self.name
                ),
            };
        }
        let s = match session {
            Some(s) if all.contains(&s) => s,
            Some(s) => bail!(
                "{}: no session {s} (sessions: {})",
                self.name,
                all.iter()
                    .map(|v| v.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            None if all.len() == 1 => all[0],
            None => {
                return Err(SessionNeeded {
                    file: self.name.clone(),
                    sessions: all,
                }
                .into())
            }
        };
        Ok(self
            .rows
            .iter()
            .filter(|r| r.get("session_id").map(|v| v as i64) == Some(s))
            .collect())
    }

    /// The nominal surface's outward normals of `session`'s rows in the
    /// scan plane `plane` (axis indices, 0 = x): `normal_<a>` and
    /// `normal_<b>` of each row, renormalised in the plane. None when no
    /// row gives a normal; an error names the line of a row without one
    /// when others have them, or of a normal nearly perpendicular to the
    /// plane (less than half of it in the plane: the scan does not lie in
    /// that surface's plane).
    pub fn normals(
        &self,
        session: Option<i64>,
        plane: [usize; 2],
    ) -> Result<Option<Vec<[f64; 2]>>> {
        let rows = self.select(session)?;
        let has = |r: &ProbeRow| {
            ["normal_x", "normal_y", "normal_z"]
                .iter()
                .any(|c| r.get(c).is_some())
        };
        if !rows.iter().any(|r| has(r)) {
            return Ok(None);
        }
        let names = ["normal_x", "normal_y", "normal_z"];
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            if !has(r) {
                bail!(
                    "{}:{}: no normal on this row, though other rows of the scan give one (give `normal_x`…`normal_z` on every row, or on none)",
                    self.name,
                    r.line
                );
            }
            let v = plane.map(|a| r.get(names[a]).unwrap_or(0.0));
            let len = (v[0] * v[0] + v[1] * v[1]).sqrt();
            if len.is_nan() || len < 0.5 {
                bail!(
                    "{}:{}: the normal has only {:.0} % of its length in the scan's plane: the scan does not cross that surface in this plane",
                    self.name,
                    r.line,
                    100.0 * len
                );
            }
            out.push([v[0] / len, v[1] / len]);
        }
        Ok(Some(out))
    }

    /// The text of the small scan file `kind` holding `session`'s rows
    /// (numbers written back exactly: the same values either way). A row
    /// without a value the kind needs is named by its line.
    pub fn small(&self, session: Option<i64>, kind: Small) -> Result<String> {
        let rows = self.select(session)?;
        let need = |r: &ProbeRow, c: &str| -> Result<f64> {
            r.get(c).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}:{}: no `{c}` value on this row (needed for this scan)",
                    self.name,
                    r.line
                )
            })
        };
        // A row's values of `cols`, comma-separated, as one line.
        let line = |r: &ProbeRow, cols: &[&str]| -> Result<String> {
            let v = cols
                .iter()
                .map(|c| need(r, c).map(num))
                .collect::<Result<Vec<_>>>()?;
            Ok(v.join(",") + "\n")
        };
        let timed = !rows.is_empty() && rows.iter().all(|r| r.get("t_s").is_some());
        let mut out = String::new();
        match kind {
            Small::Positions => {
                let pos: Vec<&str> = ["x_mm", "y_mm", "z_mm"]
                    .into_iter()
                    .filter(|c| rows.iter().any(|r| r.get(c).is_some()))
                    .collect();
                out.push_str(&pos.join(","));
                out.push_str(if timed { ",t_s\n" } else { "\n" });
                let cols: Vec<&str> = pos.into_iter().chain(timed.then_some("t_s")).collect();
                for r in &rows {
                    out.push_str(&line(r, &cols)?);
                }
            }
            Small::Straightness(axis, o) => {
                let pos = format!("{axis}_mm");
                let mine: Vec<&&ProbeRow> = rows
                    .iter()
                    .filter(|r| {
                        r.get("orientation_deg")
                            .map_or(0, |v| v.rem_euclid(360.0).round() as u16)
                            == o
                    })
                    .collect();
                // A touch-trigger probe gives positions, not readings: the
                // other position columns the rows hold take `d_um`'s place.
                let reading: Vec<String> = if mine.iter().all(|r| r.get("d_um").is_some()) {
                    vec!["d_um".into()]
                } else {
                    ["x_mm", "y_mm", "z_mm"]
                        .into_iter()
                        .filter(|c| *c != pos && mine.iter().any(|r| r.get(c).is_some()))
                        .map(String::from)
                        .collect()
                };
                if reading.is_empty() {
                    bail!(
                        "{}: no `d_um` reading and no touch position besides `{pos}` in the {o}° run",
                        self.name
                    );
                }
                out.push_str(&format!(
                    "{pos},{}{}\n",
                    reading.join(","),
                    if timed { ",t_s" } else { "" }
                ));
                let cols: Vec<&str> = std::iter::once(pos.as_str())
                    .chain(reading.iter().map(String::as_str))
                    .chain(timed.then_some("t_s"))
                    .collect();
                for r in mine {
                    out.push_str(&line(r, &cols)?);
                }
            }
            Small::ThreeProbe => {
                let mut per: [Vec<(f64, f64)>; 3] = Default::default();
                for r in &rows {
                    let k = need(r, "probe_no")? as usize;
                    if !(1..=3).contains(&k) {
                        bail!(
                            "{}:{}: probe {k}: a three-probe run has probes 1, 2 and 3",
                            self.name,
                            r.line
                        );
                    }
                    per[k - 1].push((need(r, "c_deg")?, need(r, "d_um")?));
                }
                out.push_str("c_deg,p1_um,p2_um,p3_um\n");
                let same = per[1].len() == per[0].len()
                    && per[2].len() == per[0].len()
                    && (0..per[0].len())
                        .all(|i| per[1][i].0 == per[0][i].0 && per[2][i].0 == per[0][i].0);
                if same {
                    // The three probes side by side, as a spindle
                    // analyser's row holds them.
                    for ((a, b), d) in per[0].iter().zip(&per[1]).zip(&per[2]) {
                        out.push_str(&format!(
                            "{},{},{},{}\n",
                            num(a.0),
                            num(a.1),
                            num(b.1),
                            num(d.1)
                        ));
                    }
                } else {
                    // Each probe at its own angles: a row per reading, the
                    // other probes' cells empty (resampled by angle).
                    for r in &rows {
                        let k = need(r, "probe_no")? as usize;
                        let mut cells = vec![String::new(); 3];
                        cells[k - 1] = num(need(r, "d_um")?);
                        out.push_str(&format!("{},{}\n", num(need(r, "c_deg")?), cells.join(",")));
                    }
                }
            }
            Small::MultiStep => {
                out.push_str("c_deg,step_deg,p_um\n");
                for r in &rows {
                    out.push_str(&line(r, &["c_deg", "step_deg", "d_um"])?);
                }
            }
            Small::Roundness => {
                out.push_str(&format!("c_deg,p_um{}\n", if timed { ",t_s" } else { "" }));
                let cols = ["c_deg", "d_um", "t_s"];
                for r in &rows {
                    out.push_str(&line(r, &cols[..if timed { 3 } else { 2 }])?);
                }
            }
            Small::Workpiece => {
                out.push_str("c_deg,z_mm,dev_um\n");
                for r in &rows {
                    out.push_str(&line(r, &["c_deg", "z_mm", "d_um"])?);
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_campaign_only_columns_are_the_ones_no_small_file_has() {
        let names: Vec<&str> = campaign_only().collect();
        assert_eq!(names.len(), 8, "{names:?}");
        let ends = (names[0], names[1], names[7]);
        assert_eq!(ends, ("session_id", "orientation_deg", "contact_deg"));
    }

    #[test]
    fn a_session_is_read_as_its_small_file_and_bad_values_are_placed() {
        let text = "# campaign\nsession_id,x_mm,z_mm,d_um,orientation_deg,probe_id\n\
                    1,0,,0.5,0,A\n1,10,,0.25,0,A\n1,0,,-0.5,180,A\n2,1.5,2.5,,,B\n";
        assert!(is_probe_csv(text));
        assert!(!is_probe_csv("x_mm,d_um\n0,1\n"));
        let t = read(text, "c.csv").unwrap();
        assert_eq!(t.sessions(), vec![1, 2]);
        assert_eq!(
            t.small(Some(1), Small::Straightness('x', 0)).unwrap(),
            "x_mm,d_um\n0,0.5\n10,0.25\n"
        );
        assert_eq!(
            t.small(Some(1), Small::Straightness('x', 180)).unwrap(),
            "x_mm,d_um\n0,-0.5\n"
        );
        assert_eq!(
            t.small(Some(2), Small::Positions).unwrap(),
            "x_mm,z_mm\n1.5,2.5\n"
        );
        let e = t.small(None, Small::Positions).unwrap_err();
        assert_eq!(
            e.downcast_ref::<SessionNeeded>().unwrap().sessions,
            vec![1, 2]
        );
        // Session 1 has no z: named by its line.
        let e = t.small(Some(1), Small::Workpiece).unwrap_err().to_string();
        assert!(e.contains("c.csv:3: no `c_deg`"), "{e}");
        // A bad value: file, line, column.
        let bad = text.replace("1,10,,0.25,0,A", "1,10,,0.25,90,A");
        let e = read(&bad, "c.csv").unwrap_err().to_string();
        assert!(
            e.starts_with("c.csv:4:5: `orientation_deg`: expected 0 or 180"),
            "{e}"
        );
    }
}
