//! The seed of a model — what `--model` names (`cubic19`, `kinematic`,
//! `nn:<hidden>`, `grid:<step_mm>`) — as a type, and the `seed` field of
//! MODEL.json, which adds ` --local` for piecewise local fits. The strings
//! are parsed here once; inside the engine the seed travels as [`Seed`].

use std::fmt;
use std::str::FromStr;

use anyhow::{bail, Result};

use crate::features::{kinematic, CUBIC19};

/// What a seed spec asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Seed {
    /// The 19-term cubic polynomial per target.
    Cubic19,
    /// The kinematic (rigid-body) polynomial.
    Kinematic,
    /// A tanh network with one hidden layer (`nn:<hidden>`).
    Nn {
        /// Hidden neurons, 1 to 256.
        hidden: usize,
    },
    /// A grid table (`grid:<step_mm>`).
    Grid {
        /// Node spacing, mm (finite, > 0).
        step_mm: f64,
    },
    /// The volumetric model of the 21 geometric errors (`rigid21`,
    /// `rigid21:<degree>`; docs/volumetric.md).
    Rigid21 {
        /// Highest Legendre degree of each error function.
        degree: usize,
    },
}

impl Seed {
    /// Parses a `--model` spec.
    pub fn parse(spec: &str) -> Result<Seed> {
        let expected =
            "expected cubic19, kinematic, nn:<hidden>, grid:<step_mm> or rigid21[:<degree>]";
        if spec == "rigid21" {
            return Ok(Seed::Rigid21 {
                degree: crate::model::rigid21::DEFAULT_DEGREE,
            });
        }
        if let Some(d) = spec.strip_prefix("rigid21:") {
            let max = crate::model::rigid21::MAX_DEGREE;
            let d: usize = d.parse().map_err(|_| {
                anyhow::anyhow!(
                    "model `{spec}`: the degree must be a whole number 1..={max} ({expected})"
                )
            })?;
            if !(1..=max).contains(&d) {
                bail!("model `{spec}`: the degree must be 1..={max}");
            }
            return Ok(Seed::Rigid21 { degree: d });
        }
        if let Some(h) = spec.strip_prefix("nn:") {
            let h: usize = h.parse().map_err(|_| {
                anyhow::anyhow!(
                    "model `{spec}`: hidden neurons must be a whole number ({expected})"
                )
            })?;
            if !(1..=256).contains(&h) {
                bail!("model `{spec}`: hidden neurons must be 1..=256");
            }
            return Ok(Seed::Nn { hidden: h });
        }
        if let Some(s) = spec.strip_prefix("grid:") {
            let s: f64 = s.parse().map_err(|_| {
                anyhow::anyhow!("model `{spec}`: grid step must be a number of mm ({expected})")
            })?;
            if !(s.is_finite() && s > 0.0) {
                bail!("model `{spec}`: grid step must be a positive number of mm");
            }
            return Ok(Seed::Grid { step_mm: s });
        }
        match spec {
            "cubic19" => Ok(Seed::Cubic19),
            "kinematic" => Ok(Seed::Kinematic),
            other => bail!("unknown model `{other}` ({expected})"),
        }
    }
}

impl Seed {
    /// The monomials of a polynomial seed (`cubic19`, `kinematic`) for
    /// target `t`, restricted to `axes` — the data's varying axes
    /// (`Dataset::varying_axes`): a monomial in an absent axis, or in one
    /// held at a single position, is constant on the data and would
    /// duplicate `1` (or vanish). An error for a seed without monomials.
    pub fn monomials(&self, t: usize, axes: &[usize]) -> Result<Vec<[u8; 3]>> {
        let all: Vec<[u8; 3]> = match self {
            Seed::Cubic19 => CUBIC19.to_vec(),
            Seed::Kinematic => kinematic(t).to_vec(),
            other => bail!("unknown polynomial seed `{other}` (expected cubic19 or kinematic)"),
        };
        Ok(all
            .into_iter()
            .filter(|e| (0..3).all(|a| e[a] == 0 || axes.contains(&a)))
            .collect())
    }
}

impl FromStr for Seed {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Seed> {
        Seed::parse(s)
    }
}

impl fmt::Display for Seed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Seed::Cubic19 => f.write_str("cubic19"),
            Seed::Kinematic => f.write_str("kinematic"),
            Seed::Nn { hidden } => write!(f, "nn:{hidden}"),
            Seed::Grid { step_mm } => write!(f, "grid:{step_mm}"),
            Seed::Rigid21 { degree } if *degree == crate::model::rigid21::DEFAULT_DEGREE => {
                f.write_str("rigid21")
            }
            Seed::Rigid21 { degree } => write!(f, "rigid21:{degree}"),
        }
    }
}

/// The `seed` field of MODEL.json: the seed, and whether it was fitted as
/// piecewise local polynomials (written `<seed> --local`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelSeed {
    /// The seed.
    pub seed: Seed,
    /// Fitted with `--local`.
    pub local: bool,
}

/// The suffix MODEL.json's `seed` carries for a `--local` fit.
const LOCAL_SUFFIX: &str = " --local";

impl ModelSeed {
    /// Parses the `seed` field of a model file.
    pub fn parse(s: &str) -> Result<ModelSeed> {
        let (spec, local) = match s.strip_suffix(LOCAL_SUFFIX) {
            Some(spec) => (spec, true),
            None => (s, false),
        };
        Ok(ModelSeed {
            seed: Seed::parse(spec)?,
            local,
        })
    }
}

impl fmt::Display for ModelSeed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.seed)?;
        if self.local {
            f.write_str(LOCAL_SUFFIX)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_to_seeds_and_print_back() {
        for (s, want) in [
            ("cubic19", Seed::Cubic19),
            ("kinematic", Seed::Kinematic),
            ("nn:16", Seed::Nn { hidden: 16 }),
            ("grid:50", Seed::Grid { step_mm: 50.0 }),
            ("grid:12.5", Seed::Grid { step_mm: 12.5 }),
            ("rigid21", Seed::Rigid21 { degree: 4 }),
            ("rigid21:6", Seed::Rigid21 { degree: 6 }),
        ] {
            let seed: Seed = s.parse().unwrap();
            assert_eq!(seed, want);
            assert_eq!(seed.to_string(), s);
        }
        let m = ModelSeed::parse("kinematic --local").unwrap();
        assert_eq!(m.seed, Seed::Kinematic);
        assert!(m.local);
        assert_eq!(m.to_string(), "kinematic --local");
        assert!(!ModelSeed::parse("nn:4").unwrap().local);
    }

    #[test]
    fn seeds_are_model_cores_lists_in_its_order() {
        // The host fits, and export writes, exactly model-core's sets.
        for t in 0..3 {
            assert_eq!(
                Seed::Kinematic.monomials(t, &[0, 1, 2]).unwrap(),
                model_core::monomials::kinematic(t)
            );
            assert_eq!(
                Seed::Cubic19.monomials(t, &[0, 1, 2]).unwrap(),
                model_core::monomials::CUBIC19
            );
        }
        assert!(Seed::Nn { hidden: 4 }.monomials(0, &[0]).is_err());
    }

    #[test]
    fn seed_drops_absent_axes() {
        let m = Seed::Cubic19.monomials(0, &[0]).unwrap();
        assert_eq!(m, vec![[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]);
    }

    #[test]
    fn bad_specs_say_what_is_expected() {
        for (s, needle) in [
            ("cubic20", "unknown model `cubic20`"),
            ("nn:0", "1..=256"),
            ("nn:x", "whole number"),
            ("grid:-1", "positive number of mm"),
            ("grid:abc", "number of mm"),
            ("rigid21:0", "1..=10"),
            ("rigid21:x", "whole number"),
        ] {
            let e = Seed::parse(s).unwrap_err().to_string();
            assert!(e.contains(needle), "{s}: {e}");
        }
    }
}
