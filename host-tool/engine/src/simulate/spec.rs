//! Spec strings for plans and effects (`--plan grid:50`, `--effect
//! periodic:axis=y,period_mm=5.08,amp_um=3`): `FromStr` to parse, `Display`
//! to print the canonical form that the CSV metadata records — parsing the
//! printed form gives the same value back. Key names follow `fit --add`
//! (features.rs) where the two overlap: `target`, `axis`, `period_mm`,
//! `harmonics`, `channel`, `times`, `lag_s`, `t_ref_c`.

use std::fmt;
use std::str::FromStr;

use anyhow::{anyhow, bail, Context, Result};

use super::{Effect, Plan};
use crate::data::{AXES, TARGETS};

/// `key=value` pairs (and bare flags) after the family / kind.
struct Kv<'a> {
    pairs: Vec<(&'a str, Option<&'a str>)>,
    used: Vec<bool>,
}

impl<'a> Kv<'a> {
    fn parse(s: &'a str) -> Result<Kv<'a>> {
        let mut pairs: Vec<(&str, Option<&str>)> = Vec::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = match part.split_once('=') {
                Some((k, v)) => (k.trim(), Some(v.trim())),
                None => (part, None),
            };
            if pairs.iter().any(|(k2, _)| *k2 == k) {
                bail!("key `{k}` given twice");
            }
            pairs.push((k, v));
        }
        let used = vec![false; pairs.len()];
        Ok(Kv { pairs, used })
    }

    fn get(&mut self, key: &str) -> Result<Option<&'a str>> {
        match self.pairs.iter().position(|(k, _)| *k == key) {
            Some(i) => {
                self.used[i] = true;
                match self.pairs[i].1 {
                    Some(v) => Ok(Some(v)),
                    None => bail!("`{key}`: expected `{key}=<value>`"),
                }
            }
            None => Ok(None),
        }
    }

    fn flag(&mut self, key: &str) -> Result<bool> {
        match self.pairs.iter().position(|(k, _)| *k == key) {
            Some(i) => {
                self.used[i] = true;
                match self.pairs[i].1 {
                    None | Some("1") | Some("true") => Ok(true),
                    Some("0") | Some("false") => Ok(false),
                    Some(v) => bail!("`{key}={v}`: expected a bare `{key}` or {key}=0/1"),
                }
            }
            None => Ok(false),
        }
    }

    fn f64(&mut self, key: &str) -> Result<Option<f64>> {
        self.get(key)?
            .map(|v| {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| anyhow!("`{key}={v}`: expected a finite number"))
            })
            .transpose()
    }

    fn need_f64(&mut self, key: &str) -> Result<f64> {
        self.f64(key)?.ok_or_else(|| anyhow!("missing `{key}=`"))
    }

    fn usize(&mut self, key: &str) -> Result<Option<usize>> {
        self.get(key)?
            .map(|v| {
                v.parse::<usize>()
                    .map_err(|_| anyhow!("`{key}={v}`: expected a non-negative integer"))
            })
            .transpose()
    }

    fn axis(&mut self, key: &str) -> Result<Option<usize>> {
        self.get(key)?.map(|v| parse_axis(v, key)).transpose()
    }

    fn target(&mut self, default: usize) -> Result<usize> {
        match self.get("target")? {
            None => Ok(default),
            Some(v) => TARGETS
                .iter()
                .position(|t| *t == v)
                .ok_or_else(|| anyhow!("`target={v}`: expected ex, ey or ez")),
        }
    }

    fn at(&mut self) -> Result<[Option<f64>; 3]> {
        Ok([self.f64("x")?, self.f64("y")?, self.f64("z")?])
    }

    /// Fails on any key nobody asked for, listing the ones allowed.
    fn finish(&self, allowed: &str) -> Result<()> {
        if let Some(i) = self.used.iter().position(|u| !u) {
            bail!("unknown key `{}` (expected {allowed})", self.pairs[i].0);
        }
        Ok(())
    }
}

fn parse_axis(v: &str, key: &str) -> Result<usize> {
    AXES.iter()
        .position(|a| *a == v)
        .ok_or_else(|| anyhow!("`{key}={v}`: expected x, y or z"))
}

fn parse_step(v: &str) -> Result<f64> {
    v.parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s > 0.0)
        .ok_or_else(|| anyhow!("step `{v}`: expected a positive number of mm"))
}

impl FromStr for Plan {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Plan> {
        parse_plan(s).with_context(|| format!("bad plan `{s}`"))
    }
}

fn parse_plan(s: &str) -> Result<Plan> {
    let (kind, rest) = s.split_once(':').ok_or_else(|| {
        anyhow!("expected grid:<step_mm>, plane:<ab>:<step_mm>, line:<a>:<step_mm>, iso230:<a>, point:x=…,y=…,z=… or pause:<s>")
    })?;
    let raster_keys = "x, y, z, bidir, runs";
    match kind {
        "grid" | "plane" | "line" => {
            let (axes, rest) = if kind == "grid" {
                (vec![0, 1, 2], rest)
            } else {
                let (names, rest) = rest
                    .split_once(':')
                    .ok_or_else(|| anyhow!("expected {kind}:<axes>:<step_mm>"))?;
                let axes: Vec<usize> = names
                    .chars()
                    .map(|c| parse_axis(&c.to_string(), "axes"))
                    .collect::<Result<_>>()?;
                let want = if kind == "plane" { 2 } else { 1 };
                if axes.len() != want || (want == 2 && axes[0] == axes[1]) {
                    bail!(
                        "`{names}`: expected {want} different axis name(s), e.g. {}",
                        if want == 2 { "xy" } else { "y" }
                    );
                }
                (axes, rest)
            };
            let (step, opts) = rest.split_once(',').unwrap_or((rest, ""));
            let step_mm = parse_step(step.trim())?;
            let mut kv = Kv::parse(opts)?;
            let at_mm = kv.at()?;
            let bidir = kv.flag("bidir")?;
            let runs = kv.usize("runs")?.unwrap_or(1);
            kv.finish(raster_keys)?;
            if axes.iter().any(|&a| at_mm[a].is_some()) {
                bail!("a fixed position is given for a moving axis");
            }
            if runs == 0 {
                bail!("`runs=0`: expected at least 1");
            }
            Ok(Plan::Raster {
                axes,
                step_mm,
                at_mm,
                bidir,
                runs,
            })
        }
        "iso230" => {
            let (a, opts) = rest.split_once(',').unwrap_or((rest, ""));
            let axis = parse_axis(a.trim(), "axis")?;
            let mut kv = Kv::parse(opts)?;
            let at_mm = kv.at()?;
            let targets = kv.usize("targets")?.unwrap_or(11);
            let runs = kv.usize("runs")?.unwrap_or(5);
            let overrun_mm = kv.f64("overrun_mm")?.unwrap_or(5.0);
            kv.finish("targets, runs, overrun_mm, x, y, z")?;
            if at_mm[axis].is_some() {
                bail!("a fixed position is given for the axis under test");
            }
            Ok(Plan::Iso230 {
                axis,
                targets,
                runs,
                overrun_mm,
                at_mm,
            })
        }
        "point" => {
            let mut kv = Kv::parse(rest)?;
            let p = [kv.need_f64("x")?, kv.need_f64("y")?, kv.need_f64("z")?];
            let repeats = kv.usize("repeats")?.unwrap_or(1);
            kv.finish("x, y, z, repeats")?;
            Ok(Plan::Point { pos_mm: p, repeats })
        }
        "pause" => {
            let (d, opts) = rest.split_once(',').unwrap_or((rest, ""));
            let duration_s = d
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| anyhow!("pause `{d}`: expected a duration in s ≥ 0"))?;
            let mut kv = Kv::parse(opts)?;
            let new_session = kv.flag("new_session")?;
            kv.finish("new_session")?;
            Ok(Plan::Pause {
                duration_s,
                new_session,
            })
        }
        other => {
            bail!("unknown plan `{other}` (expected grid, plane, line, iso230, point or pause)")
        }
    }
}

fn write_at(f: &mut fmt::Formatter<'_>, at: &[Option<f64>; 3]) -> fmt::Result {
    for a in 0..3 {
        if let Some(v) = at[a] {
            write!(f, ",{}={v}", AXES[a])?;
        }
    }
    Ok(())
}

impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Plan::Raster {
                axes,
                step_mm,
                at_mm,
                bidir,
                runs,
            } => {
                let names: String = axes.iter().map(|&a| AXES[a]).collect();
                match axes.len() {
                    1 => write!(f, "line:{names}:{step_mm}")?,
                    2 => write!(f, "plane:{names}:{step_mm}")?,
                    _ if *axes == [0, 1, 2] => write!(f, "grid:{step_mm}")?,
                    _ => write!(f, "raster:{names}:{step_mm}")?,
                }
                write_at(f, at_mm)?;
                if *bidir {
                    write!(f, ",bidir")?;
                }
                if *runs != 1 {
                    write!(f, ",runs={runs}")?;
                }
                Ok(())
            }
            Plan::Iso230 {
                axis,
                targets,
                runs,
                overrun_mm,
                at_mm,
            } => {
                write!(
                    f,
                    "iso230:{},targets={targets},runs={runs},overrun_mm={overrun_mm}",
                    AXES[*axis]
                )?;
                write_at(f, at_mm)
            }
            Plan::Pause {
                duration_s,
                new_session,
            } => {
                write!(f, "pause:{duration_s}")?;
                if *new_session {
                    write!(f, ",new_session")?;
                }
                Ok(())
            }
            Plan::Point { pos_mm, repeats } => {
                write!(f, "point:x={},y={},z={}", pos_mm[0], pos_mm[1], pos_mm[2])?;
                if *repeats != 1 {
                    write!(f, ",repeats={repeats}")?;
                }
                Ok(())
            }
        }
    }
}

impl FromStr for Effect {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Effect> {
        parse_effect(s).with_context(|| format!("bad effect `{s}`"))
    }
}

fn parse_effect(s: &str) -> Result<Effect> {
    let (family, rest) = s.split_once(':').ok_or_else(|| {
        anyhow!("expected <family>:<key>=<value>,…, e.g. periodic:axis=y,period_mm=5.08,amp_um=3")
    })?;
    let mut kv = Kv::parse(rest)?;
    let e = match family {
        "periodic" => {
            let axis = kv.axis("axis")?.ok_or_else(|| anyhow!("missing `axis=`"))?;
            let period_mm = kv.need_f64("period_mm")?;
            if period_mm <= 0.0 {
                bail!("`period_mm={period_mm}`: expected a positive period");
            }
            let e = Effect::Periodic {
                target: kv.target(axis)?,
                axis,
                period_mm,
                amp_um: kv.need_f64("amp_um")?,
                harmonics: match kv.usize("harmonics")?.unwrap_or(1) {
                    h @ 1..=16 => h as u8,
                    h => bail!("`harmonics={h}`: expected 1..=16"),
                },
                phase_deg: kv.f64("phase_deg")?.unwrap_or(0.0),
            };
            kv.finish("axis, period_mm, amp_um, harmonics, target, phase_deg")?;
            e
        }
        "thermal" => {
            let channel = kv
                .get("channel")?
                .ok_or_else(|| anyhow!("missing `channel=` (the sensor: bed → T_bed_C)"))?
                .to_string();
            if channel.is_empty() || channel.contains([',', '"', '\n']) {
                bail!("`channel={channel}`: expected a plain name such as bed");
            }
            let target = kv.target(0)?;
            let times = match kv.get("times")? {
                None => Some(target),
                Some("none") => None,
                Some(v) => Some(parse_axis(v, "times")?),
            };
            let nonneg = |v: f64, k: &str| -> Result<f64> {
                if v < 0.0 {
                    bail!("`{k}={v}`: expected a value ≥ 0");
                }
                Ok(v)
            };
            let e = Effect::Thermal {
                target,
                channel,
                times,
                cte_um_per_m_k: kv.f64("cte_um_per_m_k")?.unwrap_or(11.5),
                offset_um_per_k: kv.f64("offset_um_per_k")?.unwrap_or(0.0),
                t_ref_c: kv.f64("t_ref_c")?.unwrap_or(20.0),
                start_c: kv.f64("start_c")?.unwrap_or(20.0),
                rise_c: kv.f64("rise_c")?.unwrap_or(3.0),
                tau_s: nonneg(kv.f64("tau_s")?.unwrap_or(3600.0), "tau_s")?,
                lag_s: nonneg(kv.f64("lag_s")?.unwrap_or(0.0), "lag_s")?,
                swing_c: kv.f64("swing_c")?.unwrap_or(0.0),
                swing_period_s: match kv.f64("swing_period_s")?.unwrap_or(1800.0) {
                    p if p > 0.0 => p,
                    p => bail!("`swing_period_s={p}`: expected a positive period"),
                },
            };
            kv.finish("channel, target, times, cte_um_per_m_k, offset_um_per_k, t_ref_c, start_c, rise_c, tau_s, lag_s, swing_c, swing_period_s")?;
            e
        }
        "reversal" => {
            let axis = kv.axis("axis")?.ok_or_else(|| anyhow!("missing `axis=`"))?;
            let e = Effect::Reversal {
                target: kv.target(axis)?,
                axis,
                backlash_um: kv.need_f64("backlash_um")?,
            };
            kv.finish("axis, backlash_um, target")?;
            e
        }
        "abbe" => {
            let tools = kv
                .get("tools_mm")?
                .ok_or_else(|| anyhow!("missing `tools_mm=` (e.g. 0/50/100)"))?;
            let tools_mm = tools
                .split(['/', ';', '|'])
                .map(|t| {
                    t.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            anyhow!("`tools_mm={tools}`: expected numbers separated by /")
                        })
                })
                .collect::<Result<Vec<f64>>>()?;
            let e = Effect::Abbe {
                target: kv.target(0)?,
                angle_urad: kv.need_f64("angle_urad")?,
                tools_mm,
            };
            kv.finish("angle_urad, tools_mm, target")?;
            e
        }
        "bump" => {
            let axis = kv.axis("axis")?.ok_or_else(|| anyhow!("missing `axis=`"))?;
            let width_mm = kv.need_f64("width_mm")?;
            if width_mm <= 0.0 {
                bail!("`width_mm={width_mm}`: expected a positive width");
            }
            let e = Effect::Bump {
                target: kv.target(axis)?,
                axis,
                at_mm: kv.need_f64("at_mm")?,
                width_mm,
                amp_um: kv.need_f64("amp_um")?,
            };
            kv.finish("axis, at_mm, width_mm, amp_um, target")?;
            e
        }
        "drift" => {
            let e = Effect::Drift {
                target: kv.target(0)?,
                um_per_h: kv.need_f64("um_per_h")?,
            };
            kv.finish("um_per_h, target")?;
            e
        }
        other => {
            bail!("unknown effect `{other}` (expected periodic, thermal, reversal, abbe, bump or drift)")
        }
    };
    Ok(e)
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Effect::Periodic { target, axis, period_mm, amp_um, harmonics, phase_deg } => write!(
                f,
                "periodic:axis={},period_mm={period_mm},amp_um={amp_um},harmonics={harmonics},target={},phase_deg={phase_deg}",
                AXES[*axis], TARGETS[*target]
            ),
            Effect::Thermal {
                target,
                channel,
                times,
                cte_um_per_m_k,
                offset_um_per_k,
                t_ref_c,
                start_c,
                rise_c,
                tau_s,
                lag_s,
                swing_c,
                swing_period_s,
            } => write!(
                f,
                "thermal:channel={channel},target={},times={},cte_um_per_m_k={cte_um_per_m_k},offset_um_per_k={offset_um_per_k},t_ref_c={t_ref_c},start_c={start_c},rise_c={rise_c},tau_s={tau_s},lag_s={lag_s},swing_c={swing_c},swing_period_s={swing_period_s}",
                TARGETS[*target],
                times.map_or("none", |a| AXES[a])
            ),
            Effect::Reversal { target, axis, backlash_um } => write!(
                f,
                "reversal:axis={},backlash_um={backlash_um},target={}",
                AXES[*axis], TARGETS[*target]
            ),
            Effect::Abbe { target, angle_urad, tools_mm } => {
                let tools: Vec<String> = tools_mm.iter().map(f64::to_string).collect();
                write!(
                    f,
                    "abbe:angle_urad={angle_urad},tools_mm={},target={}",
                    tools.join("/"),
                    TARGETS[*target]
                )
            }
            Effect::Bump {
                target,
                axis,
                at_mm,
                width_mm,
                amp_um,
            } => write!(
                f,
                "bump:axis={},at_mm={at_mm},width_mm={width_mm},amp_um={amp_um},target={}",
                AXES[*axis], TARGETS[*target]
            ),
            Effect::Drift { target, um_per_h } => {
                write!(f, "drift:um_per_h={um_per_h},target={}", TARGETS[*target])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_round_trip_through_display() {
        for s in [
            "grid:50",
            "plane:xz:25,y=250",
            "line:y:0.5,x=400,z=250,bidir,runs=3",
            "iso230:x,targets=11,runs=5,overrun_mm=5",
            "point:x=0,y=0,z=0,repeats=3",
            "pause:600",
            "pause:0,new_session",
        ] {
            let p: Plan = s.parse().unwrap();
            assert_eq!(p.to_string(), s);
            assert_eq!(p.to_string().parse::<Plan>().unwrap(), p);
        }
    }

    #[test]
    fn effects_round_trip_through_display() {
        for s in [
            "periodic:axis=y,period_mm=5.08,amp_um=3",
            "thermal:channel=bed,cte_um_per_m_k=11.5,rise_c=2,lag_s=600",
            "thermal:channel=air,rise_c=0,swing_c=0.5,swing_period_s=2400",
            "thermal:channel=spindle,target=ez,times=none,cte_um_per_m_k=0,offset_um_per_k=-1.5",
            "reversal:axis=x,backlash_um=8",
            "abbe:angle_urad=48.5,tools_mm=0/50/100",
            "drift:um_per_h=0.5,target=ey",
            "bump:axis=x,at_mm=400,width_mm=40,amp_um=1.5,target=ey",
        ] {
            let e: Effect = s.parse().unwrap();
            assert_eq!(e.to_string().parse::<Effect>().unwrap(), e, "{s}");
        }
    }

    #[test]
    fn bad_specs_say_what_was_expected() {
        let msg = |s: &str| format!("{:#}", s.parse::<Effect>().unwrap_err());
        assert!(msg("periodic:axis=q,period_mm=5,amp_um=1").contains("expected x, y or z"));
        assert!(msg("periodic:axis=x,amp_um=1").contains("missing `period_mm=`"));
        assert!(msg("drift:um_per_h=1,speed=3").contains("unknown key `speed`"));
        assert!(msg("wobble:x=1").contains("unknown effect"));
        assert!(msg("bump:axis=x,at_mm=400,amp_um=1").contains("missing `width_mm=`"));
        assert!(msg("bump:axis=x,at_mm=400,width_mm=0,amp_um=1").contains("positive width"));
        let pmsg = |s: &str| format!("{:#}", s.parse::<Plan>().unwrap_err());
        assert!(pmsg("grid:-5").contains("positive"));
        assert!(pmsg("line:y:1,y=3").contains("moving axis"));
    }
}
