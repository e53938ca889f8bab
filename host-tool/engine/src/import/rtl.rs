//! Renishaw `.rtl` linear-laser files (plain text, usually CRLF) into the
//! contract's [`Dataset`]: one row per (run, target) with the axis position,
//! the deviation as the error on that axis, `dir_<axis>` and `pass_id`.
//!
//! The layout read here (sections end with `::`):
//! ```text
//! HEADER::            free `key: value` lines, kept as metadata
//! TARGET DATA::       Target-count: N / Targets : p1 p2 … (mm, may wrap
//!                     over several lines) / Flags: …
//! USER-TEXT::         Machine:, Serial No:, Date:, By:, Axis:, Location:
//! RUNS::              Run-count: M (both directions counted)
//! DEVIATIONS::        Run Target Data: then rows `run target deviation_um`
//!                     (the label may also prefix every row)
//! EQUIPMENT::         optional, kept as metadata
//! ENVIRONMENT::       optional, kept as metadata
//! EOF::
//! ```
//! Odd runs go forward (targets ascending), even runs backward (targets
//! listed in descending order); `target` is the 1-based index into
//! `Targets`. The order is checked — `Targets` strictly ascending, each run
//! in its direction's order, every run visiting every target — because a
//! file that breaks it has been misread, cut or edited, and the direction
//! of each row depends on it. A leading UTF-8 byte order mark is skipped.

use super::{shown, ImportError, Needs};
use crate::data::{Dataset, SkippedRow, AXES, ERR_PLAUSIBLE_UM, POS_PLAUSIBLE_MM};

/// A deviation at least this large (µm) is no reading but the laser
/// software's placeholder for one (−1e20 where the beam was lost): its run
/// is left out with a note naming it, the other runs are used.
pub const PLACEHOLDER_ABS: f64 = 1e19;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Section {
    None,
    Header,
    TargetData,
    UserText,
    Runs,
    Deviations,
    Equipment,
    Environment,
    Eof,
}

/// Which multi-line list a continuation line belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum List {
    None,
    Targets,
    Flags,
}

fn section_of(name: &str) -> Option<Section> {
    Some(match name.to_ascii_uppercase().as_str() {
        "HEADER" => Section::Header,
        "TARGET DATA" => Section::TargetData,
        "USER-TEXT" => Section::UserText,
        "RUNS" => Section::Runs,
        "DEVIATIONS" => Section::Deviations,
        "EQUIPMENT" => Section::Equipment,
        "ENVIRONMENT" => Section::Environment,
        "EOF" => Section::Eof,
        _ => return None,
    })
}

fn parse_count(v: &str, file: &str, line: usize, key: &str) -> Result<usize, ImportError> {
    match v.trim().parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(ImportError::at(
            file,
            line,
            None,
            format!(
                "`{key}`: expected a positive integer, found `{}`",
                shown(v.trim())
            ),
        )),
    }
}

/// `tok` parsed as a `T` and kept when `ok`; otherwise the error at `name`
/// line `ln`, field `col`: "EXPECTED, found `TOK`".
fn parse_field<T: std::str::FromStr>(
    tok: &str,
    ok: impl Fn(&T) -> bool,
    name: &str,
    ln: usize,
    col: usize,
    expected: &str,
) -> Result<T, ImportError> {
    let found = || format!("{expected}, found `{}`", shown(tok));
    let v = tok.parse().ok().filter(|v| ok(v));
    v.ok_or_else(|| ImportError::at(name, ln, Some(col), found()))
}

/// Parses `.rtl` text; `name` labels messages. `axis` (0 = x) overrides the
/// `Axis:` line of `USER-TEXT::`.
pub fn read_rtl(text: &str, name: &str, axis: Option<usize>) -> Result<Dataset, ImportError> {
    let err = |line: usize, col: Option<usize>, m: String| ImportError::at(name, line, col, m);
    // A UTF-8 byte order mark (Windows editors write one) is not part of
    // the first section name; the CSV reader strips it the same way.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut section = Section::None;
    let mut list = List::None;
    let mut metadata: Vec<(String, String)> = vec![("format".into(), "Renishaw .rtl".into())];
    let mut target_count: Option<(usize, usize)> = None; // (count, line)
    let mut targets: Vec<f64> = Vec::new();
    let mut targets_line = None::<usize>;
    let mut run_count: Option<(usize, usize)> = None;
    let mut axis_found: Option<usize> = axis;
    let mut seen_rtd = false;
    // (line, run, target index 0-based, deviation µm)
    let mut rows: Vec<(usize, usize, usize, f64)> = Vec::new();
    // Readings that are the laser's placeholder: (line, run, target, as written).
    let mut placeholders: Vec<(usize, usize, usize, String)> = Vec::new();
    let mut last_line = 0;

    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        last_line = ln;
        let line = raw.trim_end_matches('\r').trim();
        if line.is_empty() {
            continue;
        }
        if section == Section::Eof {
            return Err(err(
                ln,
                None,
                format!("expected nothing after EOF::, found `{}`", shown(line)),
            ));
        }
        if let Some(sec) = line.strip_suffix("::") {
            section = section_of(sec.trim()).ok_or_else(|| {
                err(
                    ln,
                    None,
                    format!(
                        "unknown section `{}`; expected HEADER::, TARGET DATA::, USER-TEXT::, RUNS::, DEVIATIONS::, EQUIPMENT::, ENVIRONMENT:: or EOF::",
                        shown(line)
                    ),
                )
            })?;
            list = List::None;
            continue;
        }
        match section {
            Section::None => {
                return Err(err(
                    ln,
                    None,
                    format!(
                        "expected a section such as HEADER::, found `{}`",
                        shown(line)
                    ),
                ))
            }
            Section::Eof => unreachable!("handled above"),
            Section::Header | Section::Equipment | Section::Environment => {
                let prefix = match section {
                    Section::Equipment => "equipment ",
                    Section::Environment => "environment ",
                    _ => "",
                };
                let (k, v) = line.split_once(':').unwrap_or(("", line));
                metadata.push((
                    format!("{prefix}{}", k.trim()).trim().to_string(),
                    v.trim().to_string(),
                ));
            }
            Section::UserText => {
                let (k, v) = line.split_once(':').unwrap_or(("", line));
                let (k, v) = (k.trim(), v.trim());
                if k.eq_ignore_ascii_case("axis") && axis.is_none() {
                    let first = v.chars().next().map(|c| c.to_ascii_lowercase());
                    axis_found = Some(
                        AXES.iter()
                            .position(|a| first == a.chars().next())
                            .ok_or_else(|| {
                                err(
                                    ln,
                                    None,
                                    format!("`Axis: {}`: expected X, Y or Z", shown(v)),
                                )
                            })?,
                    );
                }
                metadata.push((k.to_string(), v.to_string()));
            }
            Section::TargetData => {
                let (key, values) = match line.split_once(':') {
                    Some((k, v)) => (Some(k.trim()), v),
                    None => (None, line),
                };
                match key.map(|k| k.to_ascii_lowercase().replace(' ', "")) {
                    Some(k) if k == "target-count" => {
                        target_count = Some((parse_count(values, name, ln, "Target-count")?, ln));
                        list = List::None;
                        continue;
                    }
                    Some(k) if k == "targets" => {
                        list = List::Targets;
                        targets_line = Some(ln);
                    }
                    Some(k) if k == "flags" => list = List::Flags,
                    Some(k) => {
                        metadata.push((k, values.trim().to_string()));
                        list = List::None;
                        continue;
                    }
                    None => {}
                }
                match list {
                    List::Targets => {
                        for (field, tok) in values.split_whitespace().enumerate() {
                            let expected = "Targets: expected a finite position in mm";
                            let v: f64 = parse_field(
                                tok,
                                |v: &f64| v.is_finite(),
                                name,
                                ln,
                                field + 1,
                                expected,
                            )?;
                            if v.abs() > POS_PLAUSIBLE_MM {
                                return Err(err(ln, Some(field + 1), format!("Targets: expected a position in mm between -{POS_PLAUSIBLE_MM} and {POS_PLAUSIBLE_MM}, found `{}` — check the file's unit", shown(tok))));
                            }
                            // Forward (odd) runs get dir +1 because they
                            // move up the list: a list that is not
                            // ascending would give every row the wrong
                            // direction.
                            if let Some(&prev) = targets.last() {
                                if v <= prev {
                                    return Err(err(
                                        ln,
                                        Some(field + 1),
                                        format!("Targets: expected positions in ascending order (forward runs approach them in list order), found `{}` after {prev}", shown(tok)),
                                    ));
                                }
                            }
                            targets.push(v);
                        }
                    }
                    // Flags are not used; they are allowed to wrap like Targets.
                    List::Flags => {}
                    List::None => {
                        return Err(err(
                            ln,
                            None,
                            format!(
                                "expected `Target-count:`, `Targets :` or `Flags:`, found `{}`",
                                shown(line)
                            ),
                        ))
                    }
                }
            }
            Section::Runs => {
                let (k, v) = line.split_once(':').unwrap_or(("", line));
                if k.trim().eq_ignore_ascii_case("run-count") {
                    run_count = Some((parse_count(v, name, ln, "Run-count")?, ln));
                } else {
                    metadata.push((k.trim().to_string(), v.trim().to_string()));
                }
            }
            Section::Deviations => {
                // `Run Target Data:` opens the rows; some writers repeat it
                // in front of every row (`Run Target Data: 1 1 0.5`), so
                // the text after it, if any, is a row too.
                let mut line = line;
                if line
                    .to_ascii_lowercase()
                    .replace(' ', "")
                    .starts_with("runtargetdata:")
                {
                    seen_rtd = true;
                    line = line.split_once(':').map_or("", |(_, rest)| rest.trim());
                    if line.is_empty() {
                        continue;
                    }
                }
                if !seen_rtd {
                    return Err(err(
                        ln,
                        None,
                        format!("expected `Run Target Data:`, found `{}`", shown(line)),
                    ));
                }
                let toks: Vec<&str> = line.split_whitespace().collect();
                if toks.len() != 3 {
                    return Err(err(
                        ln,
                        None,
                        format!(
                            "expected `run target deviation` (3 fields), found {} fields",
                            toks.len()
                        ),
                    ));
                }
                let (count, _) = target_count
                    .ok_or_else(|| err(ln, None, "deviation before `Target-count:`".into()))?;
                let runs = run_count.map(|r| r.0);
                let expected = format!("expected a run number 1..={}", runs.unwrap_or(usize::MAX));
                let in_runs = |&r: &usize| r >= 1 && runs.is_none_or(|m| r <= m);
                let run: usize = parse_field(toks[0], in_runs, name, ln, 1, &expected)?;
                let expected = format!("expected a target number 1..={count}");
                let in_targets = |&t: &usize| t >= 1 && t <= count;
                let target: usize = parse_field(toks[1], in_targets, name, ln, 2, &expected)?;
                let expected = "expected a finite deviation in µm";
                let dev: f64 =
                    parse_field(toks[2], |v: &f64| v.is_finite(), name, ln, 3, expected)?;
                if dev.abs() >= PLACEHOLDER_ABS {
                    // No reading: kept through the order checks, its run
                    // left out below.
                    placeholders.push((ln, run, target, toks[2].to_string()));
                }
                if dev.abs() > ERR_PLAUSIBLE_UM && dev.abs() < PLACEHOLDER_ABS {
                    return Err(err(
                        ln,
                        Some(3),
                        format!(
                            "expected a deviation in µm between -{ERR_PLAUSIBLE_UM} and {ERR_PLAUSIBLE_UM}, found `{}` — a broken beam or another unit",
                            shown(toks[2])
                        ),
                    ));
                }
                if rows.iter().any(|r| r.1 == run && r.2 == target - 1) {
                    return Err(err(
                        ln,
                        Some(2),
                        format!("run {run}, target {target} given twice"),
                    ));
                }
                if let Some(prev) = rows.iter().rev().find(|r| r.1 == run) {
                    let forward = run % 2 == 1;
                    let ok = if forward {
                        target - 1 > prev.2
                    } else {
                        target - 1 < prev.2
                    };
                    if !ok {
                        let (kind, order) = if forward {
                            ("forward", "ascending")
                        } else {
                            ("backward", "descending")
                        };
                        return Err(err(
                            ln,
                            Some(2),
                            format!("run {run} is a {kind} run: expected targets in {order} order, found {target} after {}", prev.2 + 1),
                        ));
                    }
                }
                rows.push((ln, run, target - 1, dev));
            }
        }
    }
    if section != Section::Eof {
        return Err(err(
            last_line + 1,
            None,
            "expected `EOF::` (file truncated?)".into(),
        ));
    }
    let (count, count_line) = target_count.ok_or_else(|| {
        err(
            last_line,
            None,
            "no `Target-count:` in TARGET DATA::".into(),
        )
    })?;
    if targets.len() != count {
        return Err(err(
            targets_line.unwrap_or(count_line),
            None,
            format!(
                "Target-count is {count} but `Targets :` lists {} positions",
                targets.len()
            ),
        ));
    }
    let (runs, runs_line) =
        run_count.ok_or_else(|| err(last_line, None, "no `Run-count:` in RUNS::".into()))?;
    for r in 1..=runs {
        if !rows.iter().any(|row| row.1 == r) {
            return Err(err(
                runs_line,
                None,
                format!("Run-count is {runs} but run {r} has no deviations"),
            ));
        }
    }
    // Every run visits every target once: a run that stops early is a
    // broken or cut-off file, not a shorter run (ISO 230-2 needs each
    // target approached in every run).
    for r in 1..=runs {
        let seen: Vec<&(usize, usize, usize, f64)> = rows.iter().filter(|row| row.1 == r).collect();
        if seen.len() < count {
            let missing: Vec<String> = (0..count)
                .filter(|t| !seen.iter().any(|row| row.2 == *t))
                .map(|t| (t + 1).to_string())
                .collect();
            let last = seen.last().map_or(runs_line, |row| row.0);
            return Err(err(
                last,
                None,
                format!(
                    "run {r} has {} of the {count} targets (missing target {}); expected every run to visit every target",
                    seen.len(),
                    missing.join(", ")
                ),
            ));
        }
    }
    // Runs with a placeholder are left out whole (ISO 230-2 needs every
    // target of a run), each of their rows listed as skipped with why.
    let bad_runs: std::collections::BTreeSet<usize> = placeholders.iter().map(|p| p.1).collect();
    let mut skipped = Vec::new();
    for row in rows.iter().filter(|row| bad_runs.contains(&row.1)) {
        let reason = match placeholders.iter().find(|p| p.0 == row.0) {
            Some(p) => format!(
                "run {}, target {}: no reading (`{}`, the laser's placeholder) — run {} left out",
                p.1,
                p.2,
                shown(&p.3),
                p.1
            ),
            None => format!(
                "run {}, target {}: its run has a reading missing (placeholder) — run {} left out",
                row.1,
                row.2 + 1,
                row.1
            ),
        };
        skipped.push(SkippedRow {
            line: row.0,
            reason,
        });
    }
    rows.retain(|row| !bad_runs.contains(&row.1));
    if rows.is_empty() {
        return Err(err(
            placeholders.first().map_or(last_line, |p| p.0),
            Some(3),
            "every run has a placeholder instead of a reading (`-1e20`: no reading — a broken beam); no run is left to use".into(),
        ));
    }
    let axis = axis_found.ok_or_else(|| {
        err(
            last_line,
            None,
            "no `Axis:` line in USER-TEXT:: (expected X, Y or Z, or the axis from the reader)"
                .into(),
        )
        .needing(Needs::RtlAxis)
    })?;
    metadata.push(("axis".into(), AXES[axis].into()));

    let mut ds = Dataset {
        source: name.to_string(),
        metadata,
        ..Dataset::default()
    };
    ds.pos_mm[axis] = Some(rows.iter().map(|r| targets[r.2]).collect());
    ds.err_um[axis] = Some(rows.iter().map(|r| Some(r.3)).collect());
    ds.dir[axis] = Some(
        rows.iter()
            .map(|r| if r.1 % 2 == 1 { 1 } else { -1 })
            .collect(),
    );
    ds.pass_id = Some(rows.iter().map(|r| r.1 as i64).collect());
    ds.line = rows.iter().map(|r| r.0).collect();
    ds.skipped = skipped;
    Ok(ds)
}
