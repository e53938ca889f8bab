//! Spec strings for plans and effects (`--plan grid:50`, `--effect
//! periodic:axis=y,period_mm=5.08,amp_um=3`): `FromStr` to parse, `Display`
//! to print the canonical form that the CSV metadata records — parsing the
//! printed form gives the same value back. The pairs are the effect
//! grammar's ([`Pairs`]); an effect's keys and its canonical form are its
//! family's (`effect/<family>.rs`, the simulated form), and follow `fit
//! --add` where the two overlap: `target`, `axis`, `period_mm`,
//! `harmonics`, `channel`, `times`, `lag_s`, `t_ref_c`.

use std::fmt;
use std::str::FromStr;

use anyhow::{anyhow, bail, Context, Result};

use super::bump::Bump;
use super::{Effect, Plan};
use crate::data::AXES;
use crate::effect::{parse_axis, Family, Pairs};

/// `x=`, `y=`, `z=`: a fixed position per axis, where given.
fn at(kv: &Pairs) -> Result<[Option<f64>; 3]> {
    Ok([kv.f64("x")?, kv.f64("y")?, kv.f64("z")?])
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
                    .map(|c| parse_axis(&c.to_string(), "axes").map(|a| a.index()))
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
            let kv = Pairs::parse_with_flags(opts)?;
            let at_mm = at(&kv)?;
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
            let axis = parse_axis(a.trim(), "axis")?.index();
            let kv = Pairs::parse_with_flags(opts)?;
            let at_mm = at(&kv)?;
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
            let kv = Pairs::parse_with_flags(rest)?;
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
            let kv = Pairs::parse_with_flags(opts)?;
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

/// A family's simulated form (its file in `effect/` parses the pairs) or
/// a guide bump.
fn parse_effect(s: &str) -> Result<Effect> {
    let (family, kv) = Pairs::of_effect(
        s,
        "expected <family>:<key>=<value>,…, e.g. periodic:axis=y,period_mm=5.08,amp_um=3",
    )?;
    if family == "bump" {
        return Bump::parse(&kv).map(Effect::new);
    }
    let simulate = family
        .parse::<Family>()
        .ok()
        .and_then(|f| f.info().simulate)
        .ok_or_else(|| {
            anyhow!(
                "unknown effect `{family}` (expected {})",
                Family::simulated_names(&["bump"])
            )
        })?;
    simulate(&kv).map(Effect::from)
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
