//! Time stamps as logs write them (docs/on-machine.md § "Time stamps"):
//! a `t_s` column of seconds, or a `time` column of clock times — ISO 8601
//! (`2024-03-05T14:03:07.25Z`, `2024-03-05 14:03:07+01:00`) or a time of
//! day (`14:03:07.250`, `14:03`) — read as seconds from the first row. A
//! time of day that goes back past midnight continues on the next day; any
//! other step back in time is refused, naming the line.

use anyhow::{bail, Result};

/// Days from 1970-01-01 to the civil date `y-m-d` (proleptic Gregorian;
/// H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// `hh:mm[:ss[.fff]]` as seconds of the day.
fn time_of_day(s: &str) -> Option<f64> {
    let mut it = s.split(':');
    let h: u32 = it.next()?.parse().ok()?;
    let m: u32 = it.next()?.parse().ok()?;
    let sec: f64 = match it.next() {
        Some(x) if !x.is_empty() && x.chars().all(|c| c.is_ascii_digit() || c == '.') => {
            x.parse().ok()?
        }
        Some(_) => return None,
        None => 0.0,
    };
    if it.next().is_some() || h > 23 || m > 59 || !(0.0..61.0).contains(&sec) {
        return None;
    }
    Some(f64::from(h) * 3600.0 + f64::from(m) * 60.0 + sec)
}

/// A clock time: `(seconds, whether it carries a date)` — seconds since
/// 1970-01-01 UTC for an ISO 8601 date and time, seconds of the day for a
/// time of day.
pub fn parse(cell: &str) -> Option<(f64, bool)> {
    let c = cell.trim();
    let Some(sep) = c.find(['T', 't', ' ']) else {
        return time_of_day(c).map(|s| (s, false));
    };
    let (date, rest) = (&c[..sep], c[sep + 1..].trim());
    let d: Vec<&str> = date.split('-').collect();
    let [y, mo, da] = d.as_slice() else {
        return None;
    };
    let (y, mo, da): (i64, i64, i64) = (y.parse().ok()?, mo.parse().ok()?, da.parse().ok()?);
    if !(1..=12).contains(&mo) || !(1..=31).contains(&da) {
        return None;
    }
    // The zone: `Z`, `±hh:mm`, `±hhmm` or none (local time, kept as is).
    let (clock, offset) = if let Some(t) = rest.strip_suffix(['Z', 'z']) {
        (t, 0.0)
    } else if let Some(i) = rest.rfind(['+', '-']).filter(|&i| i > 0) {
        let z = rest[i + 1..].replace(':', "");
        if z.len() != 4 || !z.chars().all(|ch| ch.is_ascii_digit()) {
            return None;
        }
        let (zh, zm): (f64, f64) = (z[..2].parse().ok()?, z[2..].parse().ok()?);
        let sign = if rest[i..].starts_with('-') {
            -1.0
        } else {
            1.0
        };
        (&rest[..i], sign * (zh * 3600.0 + zm * 60.0))
    } else {
        (rest, 0.0)
    };
    let tod = time_of_day(clock)?;
    Some((
        days_from_civil(y, mo, da) as f64 * 86_400.0 + tod - offset,
        true,
    ))
}

/// Seconds from the first of `cells` (`(line, text)` in file order), each
/// a clock time; `name` names the file in errors.
pub fn seconds(cells: &[(usize, &str)], name: &str, column: usize) -> Result<Vec<f64>> {
    let mut out = Vec::with_capacity(cells.len());
    let mut day = 0.0;
    let mut prev: Option<(f64, bool)> = None;
    for &(ln, cell) in cells {
        let Some((s, dated)) = parse(cell) else {
            bail!(
                "{name}:{ln}:{column}: `time`: expected a clock time (ISO 8601 `2024-03-05T14:03:07.25Z` or `hh:mm:ss`), found `{cell}`"
            );
        };
        let mut t = s + day;
        if let Some((p, pdated)) = prev {
            if pdated != dated {
                bail!(
                    "{name}:{ln}:{column}: `time`: `{cell}` mixes a time of day with dated times"
                );
            }
            if t < p {
                if !dated && p - t > 43_200.0 {
                    // Past midnight.
                    day += 86_400.0;
                    t += 86_400.0;
                } else {
                    bail!("{name}:{ln}:{column}: `time`: `{cell}` is earlier than the row before");
                }
            }
        }
        prev = Some((t, dated));
        out.push(t);
    }
    let t0 = out.first().copied().unwrap_or(0.0);
    Ok(out.into_iter().map(|t| t - t0).collect())
}

/// The time stamps of a small scan file's rows, seconds: its `t_s` column,
/// or its `time` column of clock times from the first row; `None` without
/// either. Rows are the data lines after the header, in order.
pub fn times(text: &str, name: &str) -> Result<Option<Vec<f64>>> {
    let mut lines = crate::import::data_lines(text);
    let Some((_, _, head)) = lines.next() else {
        return Ok(None);
    };
    let find = |c: &str| head.iter().position(|h| *h == c);
    if let Some(j) = find("t_s") {
        let mut v = Vec::new();
        for (ln, _, cells) in lines {
            let cell = cells.get(j).copied().unwrap_or("");
            match cell.parse::<f64>() {
                Ok(x) if x.is_finite() && x.abs() <= 3.2e7 => v.push(x),
                _ => bail!(
                    "{name}:{ln}:{}: `t_s`: expected a finite number within ±32000000 s, found `{cell}`",
                    j + 1
                ),
            }
        }
        return Ok(Some(v));
    }
    let Some(j) = find("time") else {
        return Ok(None);
    };
    let cells: Vec<(usize, String)> = lines
        .map(|(ln, _, cells)| (ln, cells.get(j).copied().unwrap_or("").to_string()))
        .collect();
    let refs: Vec<(usize, &str)> = cells.iter().map(|(l, c)| (*l, c.as_str())).collect();
    seconds(&refs, name, j + 1).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_times_become_seconds_from_the_first_row() {
        let iso = [
            (2, "2024-03-05T14:03:07.25Z"),
            (3, "2024-03-05T14:03:09.75Z"),
            (4, "2024-03-05 15:03:10+01:00"),
        ];
        assert_eq!(seconds(&iso, "a.csv", 3).unwrap(), vec![0.0, 2.5, 2.75]);
        // A time of day through midnight.
        let tod = [(2, "23:59:58.5"), (3, "23:59:59"), (4, "00:00:01")];
        assert_eq!(seconds(&tod, "a.csv", 1).unwrap(), vec![0.0, 0.5, 2.5]);
        let back = [(2, "12:00:05"), (3, "12:00:01")];
        let e = seconds(&back, "a.csv", 1).unwrap_err().to_string();
        assert!(e.starts_with("a.csv:3:1: `time`"), "{e}");
        let bad = [(2, "12:61:00")];
        assert!(seconds(&bad, "a.csv", 1).is_err());
        assert_eq!(parse("1970-01-02T00:00:00Z"), Some((86_400.0, true)));
        assert_eq!(parse("2000-03-01T00:00:00Z").unwrap().0, 951_868_800.0);
    }

    #[test]
    fn a_scan_gives_its_times_from_either_column() {
        let t = times("c_deg,p_um,t_s\n0,1,0\n1,2,2.5\n", "r.csv").unwrap();
        assert_eq!(t, Some(vec![0.0, 2.5]));
        let t = times(
            "# log\nc_deg,p_um,time\n0,1,10:00:00\n1,2,10:00:02\n",
            "r.csv",
        )
        .unwrap();
        assert_eq!(t, Some(vec![0.0, 2.0]));
        assert_eq!(times("c_deg,p_um\n0,1\n", "r.csv").unwrap(), None);
        let e = times("c_deg,time\n0,noon\n", "r.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("r.csv:2:2"), "{e}");
    }
}
