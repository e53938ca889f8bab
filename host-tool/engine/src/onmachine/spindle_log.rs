//! Spindle logs (docs/on-machine.md § "Spindle logs"): the readings of
//! probes round a turning part, one row per sample, as a spindle analyser
//! or a data logger writes them — any number of samples per turn, any
//! number of turns, probes on one row or each on rows of its own (empty
//! cells), and the spindle angle known one of four ways:
//!
//! - `c_deg`: the angle itself (wrapped to a turn or counting on);
//! - `encoder`: encoder counts, with the counts per turn;
//! - `index`: a once-per-turn pulse (any two levels: a rising edge through
//!   the middle of its range marks 0°), the angle in between
//!   proportional to the time (`t_s` or `time`; without either, rows are
//!   taken as equally spaced in time);
//! - the spindle speed (an `rpm` column or one speed for the file) and the
//!   time: the angle integrated from the first row.
//!
//! Each probe's readings become a [`Track`] the separations resample by
//! angle themselves.

use anyhow::{anyhow, bail, Result};

use crate::onmachine::clock;
use crate::onmachine::separate::{Step, Track};

/// How the spindle angle of each row was known.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AngleFrom {
    /// A `c_deg` column.
    Angle,
    /// An `encoder` column of counts.
    Encoder,
    /// An `index` column: a once-per-turn pulse, the time in between.
    Index,
    /// The spindle speed and the time.
    Speed,
}

/// What the file alone may not say.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Options {
    /// Encoder counts per turn (for an `encoder` column).
    pub counts_per_turn: Option<f64>,
    /// The spindle speed, rev/min, when the file has no `rpm` column.
    pub rpm: Option<f64>,
}

/// Something a log needs that neither it nor the options give. The text
/// names it in the engine's words; a command with a flag for it says so.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Missing {
    /// An `encoder` column without the counts per turn.
    #[error("{file}: the `encoder` column counts, but the counts per turn are not given")]
    CountsPerTurn {
        /// The file.
        file: String,
    },
    /// Time stamps without an angle, an index or a speed.
    #[error("{file}: the rows have time stamps but no angle (`c_deg`), encoder counts (`encoder`), index pulse (`index`) or spindle speed (an `rpm` column or the speed given)")]
    Speed {
        /// The file.
        file: String,
    },
}

/// One log read: per channel asked for, its track; and the rows' steps.
#[derive(Clone, Debug)]
pub struct Log {
    /// How the angle was known.
    pub angle_from: AngleFrom,
    /// Per channel, the rows that read it.
    pub tracks: Vec<Track>,
    /// Per channel, each of its readings' `step_deg` (when the column is
    /// there).
    pub steps: Vec<Vec<f64>>,
}

/// Reads the channels `channels` (e.g. `p1_um`, `p2_um`, `p3_um`) of a
/// spindle log; `name` names the file in errors (file, line, column).
pub fn read(text: &str, name: &str, channels: &[&str], opts: &Options) -> Result<Log> {
    let mut lines = crate::import::data_lines(text);
    let Some((hl, head_line, head)) = lines.next() else {
        bail!("{name}: no header line");
    };
    let col = |c: &str| head.iter().position(|h| *h == c);
    let chan: Vec<usize> = channels
        .iter()
        .map(|c| col(c))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| {
            anyhow!(
                "{name}:{hl}: the header needs {} (the probe readings, µm), found `{head_line}`",
                channels
                    .iter()
                    .map(|c| format!("`{c}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?;
    let (c_deg, encoder, index, rpm, step) = (
        col("c_deg"),
        col("encoder"),
        col("index"),
        col("rpm"),
        col("step_deg"),
    );
    let (t_s, time) = (col("t_s"), col("time"));
    let num = |ln: usize, j: usize, c: &str, cell: &str, lim: f64, unit: &str| -> Result<f64> {
        match cell.parse::<f64>() {
            Ok(x) if x.is_finite() && x.abs() <= lim => Ok(x),
            _ => Err(anyhow!(
                "{name}:{ln}:{}: `{c}`: expected a finite number within ±{lim} {unit}, found `{cell}`",
                j + 1
            )),
        }
    };
    struct Row {
        angle: Option<f64>,
        enc: Option<f64>,
        idx: Option<f64>,
        rpm: Option<f64>,
        t: Option<f64>,
        step: Option<f64>,
        v: Vec<Option<f64>>,
    }
    let mut rows = Vec::new();
    let mut clock_cells: Vec<(usize, String)> = Vec::new();
    for (ln, _, cells) in lines {
        let get = |j: Option<usize>| j.map(|j| (j, cells.get(j).copied().unwrap_or("")));
        let need = |j: Option<usize>, c: &str, lim: f64, unit: &str| -> Result<Option<f64>> {
            get(j)
                .map(|(j, cell)| num(ln, j, c, cell, lim, unit))
                .transpose()
        };
        let mut v = Vec::with_capacity(chan.len());
        for (&j, c) in chan.iter().zip(channels) {
            let cell = cells.get(j).copied().unwrap_or("");
            v.push(if cell.is_empty() {
                None
            } else {
                Some(num(ln, j, c, cell, crate::data::ERR_PLAUSIBLE_UM, "µm")?)
            });
        }
        if let Some((_, cell)) = get(time) {
            clock_cells.push((ln, cell.to_string()));
        }
        rows.push(Row {
            angle: need(c_deg, "c_deg", 3.6e7, "°")?,
            enc: need(encoder, "encoder", 1e15, "counts")?,
            idx: need(index, "index", 1e9, "")?,
            rpm: need(rpm, "rpm", 1e6, "rev/min")?,
            t: need(t_s, "t_s", 3.2e7, "s")?,
            step: need(step, "step_deg", 3600.0, "°")?,
            v,
        });
    }
    if rows.is_empty() {
        bail!("{name}: no readings under the header");
    }
    let times: Option<Vec<f64>> = if t_s.is_some() {
        Some(rows.iter().map(|r| r.t.unwrap_or(0.0)).collect())
    } else if let Some(j) = time {
        let refs: Vec<(usize, &str)> = clock_cells.iter().map(|(l, c)| (*l, c.as_str())).collect();
        Some(clock::seconds(&refs, name, j + 1)?)
    } else {
        None
    };
    let (angle_from, angle): (AngleFrom, Vec<f64>) = if c_deg.is_some() {
        (
            AngleFrom::Angle,
            rows.iter().map(|r| r.angle.unwrap_or(0.0)).collect(),
        )
    } else if encoder.is_some() {
        let cpt = opts.counts_per_turn.ok_or_else(|| Missing::CountsPerTurn {
            file: name.to_string(),
        })?;
        if !(cpt.is_finite() && cpt > 0.0) {
            bail!("{cpt} counts per turn: expected a positive number");
        }
        (
            AngleFrom::Encoder,
            rows.iter()
                .map(|r| 360.0 * r.enc.unwrap_or(0.0) / cpt)
                .collect(),
        )
    } else if index.is_some() {
        let t: Vec<f64> = times
            .clone()
            .unwrap_or_else(|| (0..rows.len()).map(|i| i as f64).collect());
        let pulse: Vec<f64> = rows.iter().map(|r| r.idx.unwrap_or(0.0)).collect();
        (
            AngleFrom::Index,
            from_index(&t, &pulse).map_err(|e| anyhow!("{name}: {e}"))?,
        )
    } else if rpm.is_some() || opts.rpm.is_some() {
        let Some(t) = &times else {
            bail!(
                "{name}: the spindle speed gives the angle only with time stamps (`t_s` or `time`)"
            );
        };
        let speed: Vec<f64> = rows
            .iter()
            .map(|r| r.rpm.or(opts.rpm).unwrap_or(0.0))
            .collect();
        let mut a = vec![0.0; rows.len()];
        for i in 1..rows.len() {
            a[i] = a[i - 1] + 6.0 * 0.5 * (speed[i - 1] + speed[i]) * (t[i] - t[i - 1]);
        }
        (AngleFrom::Speed, a)
    } else if times.is_some() {
        return Err(Missing::Speed {
            file: name.to_string(),
        }
        .into());
    } else {
        bail!(
            "{name}:{hl}: the header needs the spindle angle: `c_deg`, `encoder` (counts), `index` (a once-per-turn pulse) or time stamps (`t_s` or `time`) with the spindle speed, found `{head_line}`"
        );
    };
    let mut tracks = vec![Track::default(); chan.len()];
    let mut steps = vec![Vec::new(); chan.len()];
    for (r, a) in rows.iter().zip(&angle) {
        for (k, v) in r.v.iter().enumerate() {
            if let Some(v) = v {
                tracks[k].angle_deg.push(*a);
                tracks[k].value_um.push(*v);
                steps[k].push(r.step.unwrap_or(0.0));
            }
        }
    }
    if let Some(k) = tracks.iter().position(|t| t.value_um.is_empty()) {
        bail!("{name}: no reading of `{}` in any row", channels[k]);
    }
    Ok(Log {
        angle_from,
        tracks,
        steps,
    })
}

/// The angle of each row from a once-per-turn pulse: 0° at each rising
/// edge through the middle of the pulse's range (placed between the two
/// rows by the values), the angle in between proportional to the time,
/// before the first and after the last edge at the neighbouring turn's
/// rate.
fn from_index(t: &[f64], pulse: &[f64]) -> Result<Vec<f64>> {
    let lo = pulse.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = pulse.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if hi <= lo {
        bail!("the `index` column never changes: no once-per-turn pulse in it");
    }
    let mid = 0.5 * (lo + hi);
    let mut edges = Vec::new();
    for i in 1..pulse.len() {
        if pulse[i - 1] < mid && pulse[i] >= mid {
            let f = (mid - pulse[i - 1]) / (pulse[i] - pulse[i - 1]);
            edges.push(t[i - 1] + f * (t[i] - t[i - 1]));
        }
    }
    if edges.len() < 2 {
        bail!(
            "the `index` column has {} rising edge(s): a whole turn needs two",
            edges.len()
        );
    }
    if let Some(w) = edges.windows(2).find(|w| w[1] <= w[0]) {
        bail!(
            "the time stamps go back between the index pulses at {} s and {} s",
            w[0],
            w[1]
        );
    }
    Ok(t.iter()
        .map(|&ti| {
            let k = edges
                .partition_point(|&e| e <= ti)
                .clamp(1, edges.len() - 1)
                - 1;
            let (e0, e1) = (edges[k], edges[k + 1]);
            360.0 * (k as f64 + (ti - e0) / (e1 - e0))
        })
        .collect())
}

/// A multi-step set from a log with a `step_deg` column: the readings of
/// `channel` grouped by step (in the order the steps first appear; step
/// values within 0.001° of one another are one step). Each step's angles
/// must be the spindle's: a speed alone restarts the angle in each step,
/// and is refused.
pub fn multi_step(
    text: &str,
    name: &str,
    channel: &str,
    opts: &Options,
) -> Result<(AngleFrom, Vec<Step>)> {
    let log = read(text, name, &[channel], opts)?;
    if !text
        .trim_start_matches('\u{feff}')
        .lines()
        .map(|l| l.trim_end_matches('\r'))
        .find(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .is_some_and(|h| h.split(',').any(|c| c.trim() == "step_deg"))
    {
        bail!("{name}: the header needs `step_deg` (the part's position on the spindle)");
    }
    if log.angle_from == AngleFrom::Speed {
        bail!(
            "{name}: a multi-step set needs the spindle's own angle (`c_deg`, `encoder` or `index`): a speed gives each step an angle from its own start"
        );
    }
    let mut steps: Vec<Step> = Vec::new();
    let tr = &log.tracks[0];
    for ((a, v), s) in tr.angle_deg.iter().zip(&tr.value_um).zip(&log.steps[0]) {
        let j = match steps.iter().position(|st| {
            (st.step_deg - s)
                .rem_euclid(360.0)
                .min((s - st.step_deg).rem_euclid(360.0))
                < 1e-3
        }) {
            Some(j) => j,
            None => {
                steps.push(Step {
                    step_deg: *s,
                    track: Track::default(),
                });
                steps.len() - 1
            }
        };
        steps[j].track.angle_deg.push(*a);
        steps[j].track.value_um.push(*v);
    }
    Ok((log.angle_from, steps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_angle_from_an_index_pulse_an_encoder_or_the_speed() {
        // Two turns of 8 samples at 0.5 s, the index high on the first
        // sample of each turn; the angle counts on.
        let mut s = String::from("time,index,p_um\n");
        for i in 0..17 {
            let sec = i as f64 * 0.5;
            let _ = std::fmt::Write::write_fmt(
                &mut s,
                format_args!(
                    "10:00:{:06.3},{},{}\n",
                    sec,
                    if i % 8 == 0 { 5 } else { 0 },
                    i
                ),
            );
        }
        let log = read(&s, "i.csv", &["p_um"], &Options::default()).unwrap();
        assert_eq!(log.angle_from, AngleFrom::Index);
        // Edges half way between the low and the high row: 0.25 s before.
        // Row 1 (0.5 s) is 3.25 s before the edge at 3.75 s, a turn of 4 s.
        let a = &log.tracks[0].angle_deg;
        assert!((a[1].rem_euclid(360.0) - 67.5).abs() < 1e-9, "{a:?}");
        assert!((a[9] - a[1] - 360.0).abs() < 1e-9, "{a:?}");
        let enc = "encoder,p_um\n0,1\n256,2\n1024,3\n";
        let opts = Options {
            counts_per_turn: Some(1024.0),
            rpm: None,
        };
        assert_eq!(
            read(enc, "e.csv", &["p_um"], &opts).unwrap().tracks[0].angle_deg,
            vec![0.0, 90.0, 360.0]
        );
        let e = read(enc, "e.csv", &["p_um"], &Options::default()).unwrap_err();
        assert!(matches!(
            e.downcast_ref::<Missing>(),
            Some(Missing::CountsPerTurn { .. })
        ));
        let sp = "t_s,rpm,p1_um,p2_um\n0,60,1,\n0.25,60,,2\n0.5,60,3,4\n";
        let log = read(sp, "s.csv", &["p1_um", "p2_um"], &Options::default()).unwrap();
        assert_eq!(log.tracks[0].angle_deg, vec![0.0, 180.0]);
        assert_eq!(log.tracks[1].angle_deg, vec![90.0, 180.0]);
        let e = read("t_s,p_um\n0,1\n", "n.csv", &["p_um"], &Options::default()).unwrap_err();
        assert!(matches!(
            e.downcast_ref::<Missing>(),
            Some(Missing::Speed { .. })
        ));
        let e = read("c_deg,p_um\n0,x\n", "b.csv", &["p_um"], &Options::default()).unwrap_err();
        assert!(e.to_string().starts_with("b.csv:2:2: `p_um`"), "{e}");
    }

    #[test]
    fn a_log_with_steps_is_a_multi_step_set() {
        let text = "c_deg,step_deg,p_um\n0,0,1\n90,0,2\n0,51.428571,3\n90,51.428571,4\n180,0,5\n";
        let (_, st) = multi_step(text, "m.csv", "p_um", &Options::default()).unwrap();
        assert_eq!(st.len(), 2);
        assert_eq!(st[0].track.value_um, vec![1.0, 2.0, 5.0]);
        assert!((st[1].step_deg - 51.428571).abs() < 1e-12);
    }
}
