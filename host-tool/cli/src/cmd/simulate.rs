//! `trueaxis simulate` — measurements of a synthetic machine: a preset's 21
//! geometric errors, optional physical effects, measurement plans, Gaussian
//! noise and a seed. The same arguments and seed give a byte-identical CSV.
//! Spec syntax: docs/cli.md ("simulate"); parsing lives in `simulate::spec`.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::json;

use crate::cmd::out::outln;
use trueaxis_engine::import;
use trueaxis_engine::onmachine::simulate as onmachine;
use trueaxis_engine::simulate::{self, Effect, Plan, RefReturn, SimConfig};

/// Arguments of `trueaxis simulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Machine preset: mill800 (the seed's 800 × 500 × 500 mm vertical
    /// mill), mill800-wavy (plus shapes a cubic cannot follow), perfect800.
    #[arg(long, default_value = "mill800")]
    pub preset: String,
    /// Measurement plan(s), run in order: grid:<step_mm>,
    /// plane:<ab>:<step_mm>, line:<a>:<step_mm>, iso230:<a>, point:x=,y=,z=,
    /// pause:<s>[,new_session]
    /// (options after commas, see docs/cli.md).
    #[arg(long, required_unless_present = "scenario", num_args = 1..)]
    pub plan: Vec<String>,
    /// A whole measurement campaign instead of plans and effects:
    /// spindle-thermal (an ISO 230-3 thermal test at one point, 48 h, a
    /// reading a minute, 12 temperature sensors; see docs/cli.md),
    /// spindle-warmup (a one-day warm-up whose growth follows unlogged heat
    /// paths, one sensor), spindle-duty (48 h, 14 sensors, three driving
    /// the growth with lags, day 2 at another duty cycle), spindle-drift
    /// (its control: wandering sensors, an AR(1) drift), volumetric-lines /
    /// volumetric-tracker / volumetric-ballbar (the mill800-21 machine, all
    /// 21 geometric errors and the tilt, measured with laser lines, two
    /// tracker stations or ballbar circles in three planes;
    /// docs/volumetric.md), or on-machine (every file the on-machine
    /// commands read, with the hidden
    /// answers in truth.json; -o is then a directory; docs/on-machine.md).
    /// Only --seed, -o and --after-pass apply.
    #[arg(long, conflicts_with_all = ["plan", "effect", "reference"])]
    pub scenario: Option<String>,
    /// With `--scenario on-machine`: the correction pass (`trueaxis
    /// workpiece --pass-csv`) the simulated grinder grinds; -o is then the
    /// re-measured part's scan (CSV).
    #[arg(long, requires = "scenario")]
    pub after_pass: Option<PathBuf>,
    /// Physical effect (repeatable): periodic:…, thermal:…, reversal:…,
    /// abbe:…, drift:… (see docs/cli.md).
    #[arg(long)]
    pub effect: Vec<String>,
    /// Standard deviation of the Gaussian measurement noise, µm.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub noise_um: f64,
    /// Seed of the random stream (noise, ISO 230-2 targets).
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// Reference point `X,Y,Z` (mm) the machine returns to between passes.
    #[arg(long = "ref", value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub reference: Option<String>,
    /// Return to the reference point after every N passes.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub ref_every: usize,
    /// Tool length (Abbe arm along the spindle) when no abbe effect varies it, mm.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub tool_mm: f64,
    /// Traverse feed between points, mm/s (sets t_s).
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true)]
    pub feed_mm_s: f64,
    /// Time spent at each point (settle + read), s.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub dwell_s: f64,
    /// Spikes on top of the noise, `FRAC,AMP_UM`: each error value with
    /// probability FRAC gets ±AMP_UM…2·AMP_UM (beam breaks, e.g. 0.005,20).
    #[arg(long, value_name = "FRAC,AMP_UM")]
    pub spikes: Option<String>,
    /// Output CSV.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write one JSON document to stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Writes `data` to `path` as the measurement CSV.
/// Atomically (`files::write_with`): a failed write leaves no cut file.
fn write_data(data: &trueaxis_engine::data::Dataset, path: &std::path::Path) -> Result<()> {
    trueaxis_engine::files::write_with(path, |w| import::write_csv(data, w))
}

impl Args {
    /// `--scenario NAME`: the whole campaign from the engine's generator.
    fn run_scenario(&self, name: &str) -> Result<()> {
        if name == onmachine::ON_MACHINE {
            return self.run_on_machine();
        }
        if self.after_pass.is_some() {
            bail!("--after-pass goes with --scenario on-machine, not `{name}`");
        }
        let data = simulate::scenario(name, self.seed)?.data;
        write_data(&data, &self.output)?;
        let duration_s = data
            .t_s
            .as_ref()
            .and_then(|t| t.last().copied())
            .unwrap_or(0.0);
        if self.json {
            let doc = json!({
                "output": self.output.display().to_string(),
                "scenario": name,
                "rows": data.len(),
                "passes": 0,
                "duration_s": duration_s,
                "columns": import::column_names(&data),
                "seed": self.seed,
                "warnings": Vec::<String>::new(),
                "sha256": trueaxis_engine::import::content_hash(&data),
            });
            outln!("{doc}")?;
        } else {
            outln!(
                "simulated {} rows ({:.0} s) of scenario {name} → {}",
                data.len(),
                duration_s,
                self.output.display()
            )?;
            outln!(
                "next: {}",
                crate::workflow::next_for_data(&data, &self.output)
            )?;
        }
        Ok(())
    }

    /// `--scenario on-machine`: the campaign's files into the directory
    /// `-o`, or with `--after-pass` the part re-measured after that pass.
    fn run_on_machine(&self) -> Result<()> {
        if let Some(pass) = &self.after_pass {
            crate::input::refuse_overwrite(&[("the pass", pass)], &[("-o", &self.output)])?;
            let text = std::fs::read_to_string(pass)
                .with_context(|| format!("cannot read {}", pass.display()))?;
            let name = pass.display().to_string();
            let rows: Vec<[f64; 3]> = import::read_table(
                &text,
                &name,
                &["c_deg", "z_mm", "offset_um"],
                "the correction pass of `trueaxis workpiece --pass-csv`",
            )?
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
            let csv = onmachine::after_pass(self.seed, &rows)
                .with_context(|| format!("{name}: cannot grind this pass"))?;
            crate::workflow::write_file(&self.output, csv.as_bytes())?;
            let e = onmachine::REMOVAL_EFFICIENCY;
            if self.json {
                outln!(
                    "{}",
                    json!({"output": self.output.display().to_string(), "scenario": onmachine::ON_MACHINE,
                           "after_pass": name, "removal_efficiency": e, "seed": self.seed})
                )?;
            } else {
                outln!(
                    "ground the pass {name} (the grinder removes {:.0} % of each commanded depth) and measured the part again → {}",
                    e * 100.0,
                    self.output.display()
                )?;
                outln!(
                    "next: trueaxis workpiece {}",
                    crate::report::diagnose::shell_word(&self.output.display().to_string())
                )?;
            }
            return Ok(());
        }
        let dir = &self.output;
        if dir.is_file() {
            bail!(
                "-o {}: with --scenario on-machine -o is a directory, and this is a file",
                dir.display()
            );
        }
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the directory {}", dir.display()))?;
        let files = onmachine::campaign(self.seed);
        for (f, content) in &files {
            crate::workflow::write_file(&dir.join(f), content.as_bytes())?;
        }
        if self.json {
            outln!(
                "{}",
                json!({"output": dir.display().to_string(), "scenario": onmachine::ON_MACHINE,
                       "files": files.iter().map(|f| f.0).collect::<Vec<_>>(), "seed": self.seed,
                       "truth": onmachine::truth(self.seed)})
            )?;
        } else {
            outln!(
                "simulated an on-machine campaign ({} files, the hidden answers in truth.json) → {}",
                files.len(),
                dir.display()
            )?;
            outln!(
                "next: trueaxis probe calibrate {} --ball-diameter-mm {} -o probe.json --report probe",
                crate::report::diagnose::shell_word(&dir.join("ball.csv").display().to_string()),
                trueaxis_engine::lines::plot_num(onmachine::BALL_DIAMETER_MM)
            )?;
        }
        Ok(())
    }

    /// The simulation config these arguments describe.
    pub fn config(&self) -> Result<SimConfig> {
        let mut cfg = SimConfig::preset(&self.preset)?;
        cfg.plans = self
            .plan
            .iter()
            .map(|s| s.parse::<Plan>())
            .collect::<Result<_>>()?;
        cfg.effects = self
            .effect
            .iter()
            .map(|s| s.parse::<Effect>())
            .collect::<Result<_>>()?;
        // Every number is range-checked by `cfg.check()` below, with the
        // flag's name in the message (cmd/flags.rs).
        cfg.noise_um = self.noise_um;
        cfg.seed = self.seed;
        cfg.tool_mm = self.tool_mm;
        cfg.timing.feed_mm_s = self.feed_mm_s;
        cfg.timing.dwell_s = self.dwell_s;
        cfg.spikes = self.spikes.as_deref().map(str::parse).transpose()?;
        if let Some(r) = &self.reference {
            let v: Vec<f64> = r
                .split(',')
                .map(|p| p.trim().parse::<f64>())
                .collect::<std::result::Result<_, _>>()
                .ok()
                .filter(|v: &Vec<f64>| v.len() == 3 && v.iter().all(|x| x.is_finite()))
                .with_context(|| format!("--ref `{r}`: expected X,Y,Z in mm, e.g. 0,0,0"))?;
            cfg.reference = Some(RefReturn {
                pos_mm: [v[0], v[1], v[2]],
                every_passes: self.ref_every,
            });
        }
        cfg.check()?;
        Ok(cfg)
    }

    pub fn run(self) -> Result<()> {
        if let Some(name) = &self.scenario {
            return self.run_scenario(name);
        }
        let cfg = self.config()?;
        let data = simulate::simulate(&cfg);
        write_data(&data, &self.output)?;
        let passes = data
            .pass_id
            .as_ref()
            .map_or(0, |p| p.iter().max().map_or(0, |m| m + 1));
        let duration_s = data
            .t_s
            .as_ref()
            .and_then(|t| t.last().copied())
            .unwrap_or(0.0);
        let warnings: Vec<&String> = data
            .metadata
            .iter()
            .filter(|(k, _)| k == "warning")
            .map(|(_, v)| v)
            .collect();
        if self.json {
            let doc = json!({
                "output": self.output.display().to_string(),
                "preset": cfg.machine.name,
                "rows": data.len(),
                "passes": passes,
                "duration_s": duration_s,
                "columns": import::column_names(&data),
                "seed": cfg.seed,
                "noise_um": cfg.noise_um,
                "spikes": cfg.spikes.map(|s| s.to_string()),
                "plans": cfg.plans.iter().map(ToString::to_string).collect::<Vec<_>>(),
                "effects": cfg.effects.iter().map(ToString::to_string).collect::<Vec<_>>(),
                "warnings": warnings,
                "sha256": trueaxis_engine::import::content_hash(&data),
            });
            outln!("{doc}")?;
        } else {
            outln!(
                "simulated {} rows ({} passes, {:.0} s) of {} → {}",
                data.len(),
                passes,
                duration_s,
                cfg.machine.name,
                self.output.display()
            )?;
            outln!(
                "next: {}",
                crate::workflow::next_for_data(&data, &self.output)
            )?;
            for w in warnings {
                outln!("warning: {w}")?;
            }
        }
        Ok(())
    }
}
