//! ISO 230-2 runs in the `*_ISO230.dat` format of the ecmc motion-control
//! stack (its `ecmcISO230-2` scripts read it) into the contract's
//! [`Dataset`]: one row per (cycle, direction, position) with the target
//! position, the error `reference − target` converted to µm, `dir_<axis>`
//! and `pass_id`.
//!
//! The layout (one `KEY=VALUE` per line, `#` comments, blank lines):
//! ```text
//! UNIT=mm                       optional, mm when absent (also um, µm, nm, m)
//! CYCLES=5  POSITIONS=8         optional; checked against the data when given
//! TGT_DATA[i]=15                target position i (1-based)
//! REF_DATA_FWD[i,j]=15.00474    reference-system position at target i, cycle j, forward
//! REF_DATA_BWD[i,j]=14.99876    … backward
//! ```
//! Every target must have a reading in every cycle of each direction
//! present (a file with no `REF_DATA_BWD` at all is a one-direction run).
//! The file does not name the machine axis, so `--axis` is required.
//! Forward is taken as the positive direction (`dir = +1`), as ISO 230-2
//! defines it. Rows are in the order of the test: cycle 1 forward (targets
//! ascending), cycle 1 backward (descending), cycle 2 …; `pass_id` is
//! `2j − 1` forward and `2j` backward.

use std::collections::BTreeMap;

use super::{shown, ImportError, Needs};
use crate::data::{Dataset, AXES, ERR_PLAUSIBLE_UM, POS_PLAUSIBLE_MM};

/// True when `text` looks like an ecmc ISO 230-2 data file.
pub fn is_ecmc_iso230(text: &str) -> bool {
    text.lines()
        .any(|l| l.trim_start().starts_with("TGT_DATA["))
}

/// Millimetres per unit of the `UNIT=` line; `None` for anything that is
/// not a length (a rotary axis in degrees, counts).
fn mm_per_unit(unit: &str) -> Option<f64> {
    Some(match unit.trim().to_ascii_lowercase().as_str() {
        "mm" => 1.0,
        "um" | "µm" | "micron" | "microns" => 1e-3,
        "nm" => 1e-6,
        "m" => 1e3,
        _ => return None,
    })
}

/// `NAME[a]` or `NAME[a,b]` → the indices.
fn indices(key: &str, name: &str) -> Option<Vec<String>> {
    let inner = key
        .strip_prefix(name)?
        .trim()
        .strip_prefix('[')?
        .strip_suffix(']')?;
    Some(inner.split(',').map(|s| s.trim().to_string()).collect())
}

/// Parses an ecmc `*_ISO230.dat` file; `name` labels messages, `axis`
/// (0 = x) is the machine axis the run was measured on.
pub fn read_ecmc(text: &str, name: &str, axis: Option<usize>) -> Result<Dataset, ImportError> {
    let err = |line: usize, col: Option<usize>, m: String| ImportError::at(name, line, col, m);
    let mut unit: Option<(usize, String)> = None;
    let mut declared: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
    let mut targets: BTreeMap<usize, (usize, f64)> = BTreeMap::new();
    // (direction 0 = FWD, 1 = BWD) → (position, cycle) → (line, value)
    let mut refs: [BTreeMap<(usize, usize), (usize, f64)>; 2] = Default::default();
    let mut metadata = vec![("format".to_string(), "ecmc ISO230.dat".to_string())];
    let mut last_line = 1;
    for (i, raw) in text.trim_start_matches('\u{feff}').lines().enumerate() {
        let ln = i + 1;
        last_line = ln;
        let l = raw.trim_end_matches('\r').trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let Some((k, v)) = l.split_once('=') else {
            return Err(err(
                ln,
                None,
                format!("expected `KEY=VALUE`, found `{}`", shown(l)),
            ));
        };
        let (k, v) = (k.trim(), v.trim());
        let value_col = Some(2);
        let number = |what: &str| -> Result<f64, ImportError> {
            match v.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(err(
                    ln,
                    value_col,
                    format!("{what}: expected a finite number, found `{}`", shown(v)),
                )),
            }
        };
        let index = |s: &str| -> Result<usize, ImportError> {
            match s.parse::<usize>() {
                Ok(n) if n > 0 => Ok(n),
                _ => Err(err(
                    ln,
                    Some(1),
                    format!(
                        "`{}`: expected a positive whole index, found `{}`",
                        shown(k),
                        shown(s)
                    ),
                )),
            }
        };
        if k == "UNIT" {
            if mm_per_unit(v).is_none() {
                return Err(err(
                    ln,
                    value_col,
                    format!("UNIT `{}` is not a length; expected mm, um, nm or m (a rotary axis cannot be compensated as a linear one)", shown(v)),
                ));
            }
            unit = Some((ln, v.to_string()));
        } else if k == "CYCLES" || k == "POSITIONS" {
            let n = number(k)?;
            if n.fract() != 0.0 || n < 1.0 {
                return Err(err(
                    ln,
                    value_col,
                    format!(
                        "{k}: expected a positive whole number, found `{}`",
                        shown(v)
                    ),
                ));
            }
            declared.insert(
                if k == "CYCLES" { "CYCLES" } else { "POSITIONS" },
                (ln, n as usize),
            );
        } else if let Some(ix) = indices(k, "TGT_DATA") {
            if ix.len() != 1 {
                return Err(err(
                    ln,
                    Some(1),
                    format!("`{}`: expected TGT_DATA[position]", shown(k)),
                ));
            }
            let p = index(&ix[0])?;
            let x = number(k)?;
            if let Some((first, _)) = targets.insert(p, (ln, x)) {
                return Err(err(
                    ln,
                    Some(1),
                    format!("TGT_DATA[{p}] given twice (first on line {first})"),
                ));
            }
        } else if let Some((d, ix)) = indices(k, "REF_DATA_FWD")
            .map(|ix| (0, ix))
            .or_else(|| indices(k, "REF_DATA_BWD").map(|ix| (1, ix)))
        {
            if ix.len() != 2 {
                return Err(err(
                    ln,
                    Some(1),
                    format!(
                        "`{}`: expected REF_DATA_{}[position,cycle]",
                        shown(k),
                        ["FWD", "BWD"][d]
                    ),
                ));
            }
            let (p, c) = (index(&ix[0])?, index(&ix[1])?);
            let x = number(k)?;
            if let Some((first, _)) = refs[d].insert((p, c), (ln, x)) {
                return Err(err(
                    ln,
                    Some(1),
                    format!("`{}` given twice (first on line {first})", shown(k)),
                ));
            }
        } else {
            // REF_PV, TEST_PV, TGT_SET_PV, DEC …: kept as they are.
            metadata.push((k.to_string(), v.to_string()));
        }
    }
    let axis = axis.ok_or_else(|| {
        err(
            1,
            None,
            "an ecmc ISO230 file does not name its machine axis; expected it from the reader (x, y or z)".into(),
        )
        .needing(Needs::EcmcAxis)
    })?;
    if targets.is_empty() {
        return Err(err(
            last_line,
            None,
            "no TGT_DATA[i] line; expected the target positions".into(),
        ));
    }
    if refs[0].is_empty() && refs[1].is_empty() {
        return Err(err(
            last_line,
            None,
            "no REF_DATA_FWD / REF_DATA_BWD line; expected the measured positions".into(),
        ));
    }
    let n_pos = targets.len();
    if let Some((&p, &(ln, _))) = targets.iter().find(|(&p, _)| p > n_pos) {
        return Err(err(ln, Some(1), format!("TGT_DATA[{p}] but only {n_pos} targets; expected indices 1 to {n_pos} without gaps")));
    }
    let n_cyc = refs
        .iter()
        .flat_map(|r| r.keys().map(|k| k.1))
        .max()
        .unwrap_or(0);
    for (key, n) in [("POSITIONS", n_pos), ("CYCLES", n_cyc)] {
        if let Some(&(ln, d)) = declared.get(key) {
            if d != n {
                return Err(err(ln, Some(2), format!("{key}={d} but the data have {n}")));
            }
        }
    }
    let scale = unit
        .as_ref()
        .map_or(1.0, |(_, u)| mm_per_unit(u).expect("checked"));
    metadata.push((
        "unit".into(),
        unit.map_or_else(|| "mm (no UNIT line)".into(), |u| u.1),
    ));
    metadata.push(("axis".into(), AXES[axis].into()));
    // Targets in ascending order: the forward run visits them so.
    let mut order: Vec<usize> = (1..=n_pos).collect();
    order.sort_by(|a, b| targets[a].1.total_cmp(&targets[b].1));
    let mut rows: Vec<(usize, f64, f64, i8, i64)> = Vec::new(); // line, pos mm, err µm, dir, pass
    for c in 1..=n_cyc {
        for d in 0..2 {
            if refs[d].is_empty() {
                continue;
            }
            let seq: Vec<usize> = if d == 0 {
                order.clone()
            } else {
                order.iter().rev().copied().collect()
            };
            for p in seq {
                let Some(&(ln, r)) = refs[d].get(&(p, c)) else {
                    return Err(err(
                        last_line,
                        None,
                        format!(
                            "no REF_DATA_{}[{p},{c}]; expected every target in every cycle of each direction",
                            ["FWD", "BWD"][d]
                        ),
                    ));
                };
                let (tln, t) = targets[&p];
                let pos_mm = t * scale;
                if pos_mm.abs() > POS_PLAUSIBLE_MM {
                    return Err(err(
                        tln,
                        Some(2),
                        format!(
                            "target {pos_mm} mm is beyond ±{POS_PLAUSIBLE_MM} mm; is UNIT right?"
                        ),
                    ));
                }
                let err_um = (r - t) * scale * 1000.0;
                if err_um.abs() > ERR_PLAUSIBLE_UM {
                    return Err(err(
                        ln,
                        Some(2),
                        format!(
                            "reading {r} is {:.3} mm from its target {t}; expected an error within ±{} mm (is the reference offset or UNIT right?)",
                            err_um / 1000.0,
                            ERR_PLAUSIBLE_UM / 1000.0
                        ),
                    ));
                }
                rows.push((
                    ln,
                    pos_mm,
                    err_um,
                    if d == 0 { 1 } else { -1 },
                    (2 * c - 1 + d) as i64,
                ));
            }
        }
    }
    for d in 0..2 {
        if let Some((&(p, c), &(ln, _))) =
            refs[d].iter().find(|((p, c), _)| *p > n_pos || *c > n_cyc)
        {
            return Err(err(
                ln,
                Some(1),
                format!(
                    "REF_DATA_{}[{p},{c}] has no TGT_DATA[{p}]",
                    ["FWD", "BWD"][d]
                ),
            ));
        }
    }
    let mut ds = Dataset {
        source: name.to_string(),
        metadata,
        ..Dataset::default()
    };
    ds.pos_mm[axis] = Some(rows.iter().map(|r| r.1).collect());
    ds.err_um[axis] = Some(rows.iter().map(|r| Some(r.2)).collect());
    ds.dir[axis] = Some(rows.iter().map(|r| r.3).collect());
    ds.pass_id = Some(rows.iter().map(|r| r.4).collect());
    ds.line = rows.iter().map(|r| r.0).collect();
    Ok(ds)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two targets, two cycles, both directions, in µm-ish mm values.
    fn file() -> String {
        let mut s = String::from("# Input data file for ISO230-2 calcs\nREF_PV=IOC:Enc01-PosAct\nUNIT=mm\nCYCLES=2\nPOSITIONS=2\n");
        s += "TGT_DATA[1]=10\nTGT_DATA[2]=20\n";
        for c in 1..=2 {
            for p in 1..=2 {
                s += &format!(
                    "REF_DATA_FWD[{p},{c}]={:.3}\n",
                    10.0 * p as f64 + 0.001 * p as f64
                );
                s += &format!("REF_DATA_BWD[{p}, {c}] = {:.3}\n", 10.0 * p as f64 - 0.002);
            }
        }
        s
    }

    #[test]
    fn an_ecmc_run_gives_rows_in_test_order_with_errors_in_um() {
        let t = file();
        assert!(is_ecmc_iso230(&t));
        let ds = read_ecmc(&t, "a_ISO230.dat", Some(0)).unwrap();
        assert_eq!(ds.len(), 8);
        let x = ds.pos_mm[0].as_ref().unwrap();
        let e = ds.err_um[0].as_ref().unwrap();
        let dir = ds.dir[0].as_ref().unwrap();
        let pass = ds.pass_id.as_ref().unwrap();
        assert_eq!(x[..4], [10.0, 20.0, 20.0, 10.0]);
        assert_eq!(dir[..4], [1, 1, -1, -1]);
        assert_eq!(pass[..], [1, 1, 2, 2, 3, 3, 4, 4]);
        assert!((e[1].unwrap() - 2.0).abs() < 1e-6, "{:?}", e[1]);
        assert!((e[2].unwrap() + 2.0).abs() < 1e-6);
        assert!(ds
            .metadata
            .iter()
            .any(|(k, v)| k == "REF_PV" && v == "IOC:Enc01-PosAct"));
        // In µm the same file gives errors 1000 times smaller.
        let um = read_ecmc(&t.replace("UNIT=mm", "UNIT=um"), "a.dat", Some(0)).unwrap();
        assert!((um.err_um[0].as_ref().unwrap()[1].unwrap() - 0.002).abs() < 1e-9);
        assert!((um.pos_mm[0].as_ref().unwrap()[1] - 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_damaged_ecmc_file_is_refused_with_its_line() {
        let t = file();
        let e = read_ecmc(&t, "a.dat", None).unwrap_err();
        assert_eq!(e.needs, Some(Needs::EcmcAxis), "{e}");
        assert!(!e.message.contains("--"), "{e}");
        let missing = t.replace("REF_DATA_BWD[1, 2] = 9.998\n", "");
        let e = read_ecmc(&missing, "a.dat", Some(0)).unwrap_err();
        assert!(e.message.contains("REF_DATA_BWD[1,2]"), "{e}");
        let twice = format!("{t}TGT_DATA[2]=20\n");
        let e = read_ecmc(&twice, "a.dat", Some(0)).unwrap_err();
        assert!(e.message.contains("first on line 7"), "{e}");
        let deg = t.replace("UNIT=mm", "UNIT=deg");
        let e = read_ecmc(&deg, "a.dat", Some(0)).unwrap_err();
        assert_eq!((e.line, e.column), (3, Some(2)), "{e}");
        let bad = t.replace("TGT_DATA[2]=20", "TGT_DATA[2]=2O");
        let e = read_ecmc(&bad, "a.dat", Some(0)).unwrap_err();
        assert_eq!(e.line, 7, "{e}");
        let cycles = t.replace("CYCLES=2", "CYCLES=5");
        let e = read_ecmc(&cycles, "a.dat", Some(0)).unwrap_err();
        assert!(e.message.contains("CYCLES=5 but the data have 2"), "{e}");
        let offset = t.replace("REF_DATA_FWD[2,1]=20.002", "REF_DATA_FWD[2,1]=45.002");
        let e = read_ecmc(&offset, "a.dat", Some(0)).unwrap_err();
        assert!(e.message.contains("reference offset"), "{e}");
    }
}
