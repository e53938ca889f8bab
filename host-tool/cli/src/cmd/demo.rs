//! `trueaxis demo` — the guided end-to-end job on built-in data, called by
//! `cargo xtask demo` with `--out out/demo`:
//!
//! 1. **simulate** the preset mill (800 × 500 × 500 mm) with a lead-screw
//!    periodic error on X and thermal growth of X during the measurement,
//!    on a 50 mm grid plus a dense bidirectional line along X →
//!    `DIR/data.csv`;
//! 2. **fit** the seed's cubic19 → `DIR/model.json`;
//! 3. **compare** → where it fails, `DIR/report/index.html`,
//!    `DIR/compare.json`;
//! 4. **diagnose** what the polynomial misses, name the physical effect,
//!    add it, refit, and repeat until the residual is at the noise floor
//!    → `DIR/model.json` (overwritten by the improved model, its history
//!    beside it), `DIR/report/diagnose/`, `DIR/report/history/`, and the
//!    improved model compared with the data → `DIR/report/final/`,
//!    `DIR/compare_final.json`;
//! 5. **export** the improved model's firmware table → `DIR/table.bin`,
//!    with the accuracy check in `DIR/table.json`;
//! 6. **on the machine**: a simulated on-machine campaign
//!    (`DIR/on-machine/`, docs/on-machine.md): calibrate the probe on the
//!    master ball, correct a part scan with it, fit a ground part's form,
//!    write the correction pass, grind it and measure again — the form
//!    falls by the grinder's removal efficiency.
//!
//! The file names are stable: the QEMU stage of `xtask demo` uploads
//! `table.bin` with `trueaxis upload` to the board firmware in QEMU and
//! checks the board's corrections along a path through the envelope
//! (positions, temperatures, directions) bit for bit against model-core's
//! fixed-point evaluation of the same table on the host; `table.json`
//! holds the table's agreement with `model.json`. Each stage is a
//! function; [`Demo::run`] is the story.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use trueaxis_engine::compare::Comparison;
use trueaxis_engine::data::{Dataset, AXES};
use trueaxis_engine::diagnose::{self, Options, Verdict};
use trueaxis_engine::effect::Effect;
use trueaxis_engine::export::table::{TableExport, TableOptions};
use trueaxis_engine::fit::{self, FitOptions};
use trueaxis_engine::history;
use trueaxis_engine::improve::{improve, Improvement};
use trueaxis_engine::model::ModelFile;
use trueaxis_engine::simulate::{self, SimConfig};

/// Arguments of `trueaxis demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directory for everything the demo writes (created if missing).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Write one JSON document to stdout (the numbers of every stage and
    /// the files written); the story goes to stderr instead.
    #[arg(long)]
    pub json: bool,
}

/// Where the story is told as it goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Story {
    /// On stdout (the human mode).
    Stdout,
    /// On stderr (with `--json`, whose stdout holds the one document).
    Stderr,
}

/// Per-target before/after figures of a comparison, for the JSON summary.
fn targets_json(c: &Comparison) -> serde_json::Value {
    c.targets
        .iter()
        .map(|(name, r)| {
            (
                name.clone(),
                serde_json::json!({
                    "raw_rms_um": r.before.rms_um,
                    "raw_max_abs_um": r.before.max_abs_um,
                    "rms_um": r.after.rms_um,
                    "max_abs_um": r.after.max_abs_um,
                    "p95_abs_um": r.after.p95_abs_um,
                    "improvement": r.improvement,
                }),
            )
        })
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// The simulated machine of the demo: plans, effects, noise and seed.
pub const PRESET: &str = "mill800";
/// Measurement plans: the seed's 50 mm grid, then a dense bidirectional
/// line along X through the middle of the work zone (the only way to see a
/// 5 mm lead error: on the 50 mm grid it aliases to a constant).
pub const PLANS: [&str; 2] = ["grid:50", "line:x:0.5,y=250,z=250,bidir"];
/// Hidden effects: a 5 mm lead screw's cyclic error on X (3 µm), and the
/// machine warming 3 K during the measurement, growing X like steel.
pub const EFFECTS: [&str; 2] = [
    "periodic:axis=x,period_mm=5,amp_um=3",
    "thermal:channel=bed,times=x,cte_um_per_m_k=11.5,rise_c=3,tau_s=3600",
];
/// Noise of the simulated interferometer, µm.
pub const NOISE_UM: f64 = 0.2;
/// Seed of the simulation.
pub const SEED: u64 = 7;
/// The seed model fitted first.
pub const SEED_MODEL: &str = "cubic19";

/// Paths of everything the demo writes under its output directory.
#[derive(Clone, Debug)]
pub struct Demo {
    /// The output directory.
    pub out: PathBuf,
}

impl Demo {
    /// `DIR/data.csv`: the simulated measurements.
    pub fn data_csv(&self) -> PathBuf {
        self.out.join("data.csv")
    }
    /// `DIR/model.json`: the fitted model that was exported.
    pub fn model_json(&self) -> PathBuf {
        self.out.join("model.json")
    }
    /// `DIR/table.bin`: the firmware table.
    pub fn table_bin(&self) -> PathBuf {
        self.out.join("table.bin")
    }
    /// `DIR/table.json`: the export's accuracy check (docs/cli.md).
    pub fn table_json(&self) -> PathBuf {
        self.out.join("table.json")
    }
    /// `DIR/compare.json`: the comparison of the model with the data.
    pub fn compare_json(&self) -> PathBuf {
        self.out.join("compare.json")
    }
    /// `DIR/report/`: the HTML report (index.html).
    pub fn report_dir(&self) -> PathBuf {
        self.out.join("report")
    }
    /// `DIR/compare_final.json`: the improved model against the data.
    pub fn compare_final_json(&self) -> PathBuf {
        self.out.join("compare_final.json")
    }
    /// `DIR/report/final/`: the report of the improved model.
    pub fn final_report_dir(&self) -> PathBuf {
        self.report_dir().join("final")
    }

    /// Stage 1: simulate the machine and write `data.csv`.
    pub fn simulate(&self) -> Result<Dataset> {
        let mut cfg = SimConfig::preset(PRESET)?;
        cfg.plans = PLANS
            .iter()
            .map(|p| p.parse())
            .collect::<Result<Vec<_>>>()
            .context("demo plans")?;
        cfg.effects = EFFECTS
            .iter()
            .map(|e| e.parse())
            .collect::<Result<Vec<_>>>()
            .context("demo effects")?;
        cfg.noise_um = NOISE_UM;
        cfg.seed = SEED;
        cfg.check()?;
        let data = simulate::simulate(&cfg);
        let path = self.data_csv();
        trueaxis_engine::files::write_with(&path, |w| {
            trueaxis_engine::import::write_csv(&data, w)
        })?;
        Ok(data)
    }

    /// Stage 2: fit `seed` plus `adds` (`fit --add` strings) and write
    /// `model.json`.
    pub fn fit(&self, data: &Dataset, seed: &str, adds: &[&str]) -> Result<ModelFile> {
        let effects = adds
            .iter()
            .map(|a| Effect::parse(a))
            .collect::<Result<Vec<_>>>()?;
        let model = fit::fit(data, seed, &effects, &FitOptions::default())?;
        model.save(self.model_json())?;
        Ok(model)
    }

    /// Stage 3: compare the model with the data, write the report and
    /// `compare.json`.
    pub fn compare(&self, data: &Dataset, model: &ModelFile) -> Result<Comparison> {
        self.compare_into(data, model, &self.report_dir(), &self.compare_json())
    }

    fn compare_into(
        &self,
        data: &Dataset,
        model: &ModelFile,
        report: &Path,
        json: &Path,
    ) -> Result<Comparison> {
        let (csv, mj) = (self.data_csv(), self.model_json());
        let sources = crate::report::compare::Sources {
            data: &csv,
            model: &mj,
        };
        let c = crate::workflow::run_compare(data, model, Some(report), Some(sources))?;
        crate::workflow::write_file(json, (serde_json::to_string_pretty(&c)? + "\n").as_bytes())?;
        Ok(c)
    }

    /// Stage 4: diagnose the fitted seed, add the effects it names, refit
    /// until the residual is at the noise floor; overwrites `model.json`
    /// with the improved model. Returns it and the story of the steps.
    pub fn improve(&self, data: &Dataset) -> Result<(ModelFile, String, Improvement)> {
        demo_stage(
            data,
            &self.data_csv(),
            SEED_MODEL,
            &self.model_json(),
            Some(&self.report_dir()),
        )
    }

    /// Stage 5: export the firmware table (accuracy check ≤ 1 nm) and write
    /// `table.bin` and `table.json`.
    pub fn export(&self, model: &ModelFile) -> Result<TableExport> {
        let opts = TableOptions {
            created_unix_s: 0, // reproducible bytes
            ..TableOptions::default()
        };
        let e = crate::workflow::export_table(model, &self.table_bin(), &opts, 1.0)?;
        crate::workflow::write_file(
            &self.table_json(),
            (serde_json::to_string_pretty(&e)? + "\n").as_bytes(),
        )?;
        Ok(e)
    }

    /// The whole story, told on `to` as it goes. Returns the summary that
    /// `demo --json` prints: every stage's numbers (per-target RMS before
    /// and after, each step of the diagnosis with the effect it named, the
    /// export's bytes, CRC and accuracy) and the files written.
    pub fn run(&self, to: Story) -> Result<serde_json::Value> {
        use serde_json::json;
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("cannot create {}", self.out.display()))?;
        let say = |s: String| -> Result<()> {
            match to {
                Story::Stdout => crate::cmd::out::print(&(s + "\n")),
                Story::Stderr => {
                    eprintln!("{s}");
                    Ok(())
                }
            }
        };
        let path = |p: PathBuf| p.display().to_string();
        let t0 = Instant::now();
        // A fresh story: the history of an earlier demo run in the same
        // directory would otherwise be continued.
        let old = trueaxis_engine::history::history_path(&self.model_json());
        if old.exists() {
            std::fs::remove_file(&old)
                .with_context(|| format!("cannot remove {}", old.display()))?;
        }

        say(format!("trueaxis demo → {}\n", self.out.display()))?;
        let data = self.simulate()?;
        let duration_h = data
            .t_s
            .as_ref()
            .and_then(|t| t.last())
            .map_or(0.0, |t| t / 3600.0);
        say(format!(
            "1. Measure. A simulated {PRESET} (X 800 × Y 500 × Z 500 mm) with two effects nobody tells the tool about: a 5 mm lead screw's 3 µm wobble on X, and X growing as the machine warms 3 K. Plans: {}. {} points over {duration_h:.1} h, noise {NOISE_UM} µm → {}",
            PLANS.join(" + "),
            data.len(),
            self.data_csv().display()
        ))?;

        let sim_json = json!({
            "preset": PRESET,
            "plans": PLANS,
            "effects": EFFECTS,
            "noise_um": NOISE_UM,
            "seed": SEED,
            "rows": data.len(),
            "duration_h": duration_h,
        });

        let model = self.fit(&data, SEED_MODEL, &[])?;
        let fit_json = json!({
            "model": SEED_MODEL,
            "rms_um": model.stats.rms_um,
            "held_out_rms_um": model.stats.held_out_rms_um,
        });
        let fmt_map = |m: &std::collections::BTreeMap<String, f64>| {
            m.iter()
                .map(|(k, v)| format!("{k} {v:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        say(format!(
            "2. Fit {SEED_MODEL} (19 terms per axis, the seed's volumetric polynomial): RMS µm {}; held out {} → {}",
            fmt_map(&model.stats.rms_um),
            fmt_map(&model.stats.held_out_rms_um),
            self.model_json().display()
        ))?;

        let c = self.compare(&data, &model)?;
        let compare_json = json!({
            "targets": targets_json(&c),
            "worst_regions": c.worst_regions,
        });
        let mut s = String::from("3. Compare — where does it fail?\n");
        for (name, r) in &c.targets {
            let _ = writeln!(
                s,
                "   {name}: raw error RMS {:.2} µm (max {:.2}) → residual RMS {:.2} µm (max {:.2}, p95 {:.2}), {:.1}× better",
                r.before.rms_um, r.before.max_abs_um, r.after.rms_um, r.after.max_abs_um, r.after.p95_abs_um, r.improvement
            );
        }
        if let Some(worst) = c
            .targets
            .iter()
            .max_by(|a, b| a.1.after.rms_um.total_cmp(&b.1.after.rms_um))
        {
            let name = worst.0;
            if let Some(region) = c.worst_regions.iter().find(|r| &r.target == name) {
                let bbox = trueaxis_engine::compare::bbox_text(&region.bbox_mm);
                let _ = writeln!(
                    s,
                    "   worst: {name} in {bbox} mm, RMS {:.2} µm ({:.1}× its average)",
                    region.rms_um,
                    region.ratio.unwrap_or(f64::NAN)
                );
            }
            let mut related: Vec<_> = c
                .channels
                .iter()
                .filter(|p| &p.target == name && p.corr.is_some())
                .collect();
            related.sort_by(|a, b| {
                b.corr
                    .unwrap_or(0.0)
                    .abs()
                    .total_cmp(&a.corr.unwrap_or(0.0).abs())
            });
            for p in related.iter().take(2) {
                let _ = writeln!(
                    s,
                    "   {name}'s residual follows {} (r = {:+.2}) — something the polynomial in x, y, z cannot hold",
                    p.channel,
                    p.corr.unwrap_or(0.0)
                );
            }
        }
        let _ = write!(s, "   report: {}", c.report.as_deref().unwrap_or("(none)"));
        say(s)?;

        let (model, text, imp) = self.improve(&data)?;
        let c = self.compare_into(
            &data,
            &model,
            &self.final_report_dir(),
            &self.compare_final_json(),
        )?;
        let improve_json = json!({
            "steps": imp.steps.iter().map(|st| json!({
                "step": st.step,
                "added": st.added_effects.iter().map(|a| &a.add).collect::<Vec<_>>(),
                "rms_um": st.rms_um,
                "held_out_rms_um": st.held_out_rms_um,
                "noise_floor_um": st.noise_floor_um,
            })).collect::<Vec<_>>(),
            "effects": model.adds,
            "model": imp.model,
            "verdict": imp.verdict,
            "outcome": imp.steps.last().map(|st| st.outcome()),
        });
        let final_json = json!({ "targets": targets_json(&c) });
        let mut text = text;
        let _ = write!(text, "\n   compare the improved model:");
        for (name, r) in &c.targets {
            let _ = write!(
                text,
                "\n   {name}: raw error RMS {:.2} µm → residual RMS {:.2} µm (max {:.2}), {:.0}× better",
                r.before.rms_um, r.after.rms_um, r.after.max_abs_um, r.improvement
            );
        }
        let _ = write!(
            text,
            "\n   report: {}",
            c.report.as_deref().unwrap_or("(none)")
        );
        say(format!("4. {text}"))?;

        let e = self.export(&model)?;
        let table_json = json!({
            "bytes": e.bytes,
            "crc32": e.crc32,
            "terms": e.terms,
            "max_f32_error_nm": e.max_f32_error_nm,
            "max_fixed_error_nm": e.max_fixed_error_nm,
            "sweep_points": e.sweep_points,
        });
        say(format!(
            "5. Export the firmware table: {} bytes, crc32 {}, {} terms; the board's evaluation differs from the host model by at most {:.3} nm (f32) and {:.3} nm (fixed point) over {} points of the envelope (travel {}) → {}",
            e.bytes,
            e.crc32,
            e.terms,
            e.max_f32_error_nm,
            e.max_fixed_error_nm,
            e.sweep_points,
            e.envelope
                .travel_mm
                .iter()
                .enumerate()
                .filter_map(|(a, t)| t.map(|t| format!("{} {:.0}…{:.0}", AXES[a], t[0], t[1])))
                .collect::<Vec<_>>()
                .join(", "),
            self.table_bin().display()
        ))?;
        let (story, on_machine_json) = self.on_machine()?;
        say(story)?;
        let (story, volumetric_json) = self.volumetric()?;
        say(story)?;
        let elapsed_s = t0.elapsed().as_secs_f64();
        say(format!(
            "Done in {elapsed_s:.1} s. Files for the board stage: {}, {}, {}",
            self.table_bin().display(),
            self.model_json().display(),
            self.data_csv().display()
        ))?;
        let summary = json!({
            "out": path(self.out.clone()),
            "simulate": sim_json,
            "fit": fit_json,
            "compare": compare_json,
            "improve": improve_json,
            "final": final_json,
            "table": table_json,
            "on_machine": on_machine_json,
            "volumetric": volumetric_json,
            "files": {
                "data_csv": path(self.data_csv()),
                "model_json": path(self.model_json()),
                "history_json": path(trueaxis_engine::history::history_path(&self.model_json())),
                "table_bin": path(self.table_bin()),
                "table_json": path(self.table_json()),
                "compare_json": path(self.compare_json()),
                "compare_final_json": path(self.compare_final_json()),
                "report": path(self.report_dir().join("index.html")),
                "diagnose_report": path(self.report_dir().join("diagnose").join("index.html")),
                "history_report": path(self.report_dir().join("history").join("index.html")),
                "final_report": path(self.final_report_dir().join("index.html")),
            },
            "elapsed_s": elapsed_s,
        });
        Ok(summary)
    }
}

impl Demo {
    /// Chapter 6: the on-machine loop on the simulated campaign
    /// (`DIR/on-machine/`): the probe calibrated on the master ball, a part
    /// scan corrected with it, the ground part's form, one correction pass
    /// ground and the part measured again. Returns the story and its
    /// numbers.
    pub fn on_machine(&self) -> Result<(String, serde_json::Value)> {
        use trueaxis_engine::import;
        use trueaxis_engine::onmachine::simulate as onmachine;
        use trueaxis_engine::onmachine::{probe, workpiece};
        let dir = self.out.join("on-machine");
        let files = onmachine::campaign(SEED);
        for (f, content) in &files {
            crate::workflow::write_file(&dir.join(f), content.as_bytes())?;
        }
        let text = |name: &str| -> Result<(String, String)> {
            let p = dir.join(name);
            let t = std::fs::read_to_string(&p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            Ok((t, p.display().to_string()))
        };
        // The probe on the master ball.
        let (t, n) = text("ball.csv")?;
        let ball = probe::read_scan(&t, &n, ["x", "z"])?;
        let cal = probe::calibrate(&ball, onmachine::BALL_DIAMETER_MM / 2.0)?;
        let pr = &cal.probe;
        crate::workflow::write_file(
            &dir.join("probe.json"),
            (serde_json::to_string_pretty(pr)? + "\n").as_bytes(),
        )?;
        // A part scanned with it: the form with the probe's radius only,
        // and with its form too.
        let (t, n) = text("part.csv")?;
        let scan = probe::read_scan(&t, &n, ["x", "z"])?;
        let contacts = probe::correct(pr, &scan, probe::Side::Toward([0.0, 1.0]))?;
        let surf: Vec<[f64; 2]> = contacts.iter().map(|c| c.surface_mm).collect();
        let radius_only: Vec<[f64; 2]> = contacts
            .iter()
            .map(|c| {
                let (t, d) = (c.theta_deg.to_radians(), c.form_nm * 1e-6);
                [c.surface_mm[0] + d * t.cos(), c.surface_mm[1] + d * t.sin()]
            })
            .collect();
        let part_pv = probe::pv(&probe::form_deviation_nm(&surf, true)?);
        let part_pv_radius_only = probe::pv(&probe::form_deviation_nm(&radius_only, true)?);
        // The ground part, its correction pass, ground and measured again.
        let read_part = |name: &str| -> Result<Vec<workpiece::Point>> {
            let (t, n) = text(name)?;
            Ok(
                import::read_table(&t, &n, &["c_deg", "z_mm", "dev_um"], "a part scan")?
                    .iter()
                    .map(|r| workpiece::Point {
                        c_deg: r[0],
                        z_mm: r[1],
                        dev_um: r[2],
                    })
                    .collect(),
            )
        };
        let mut warnings = Vec::new();
        let form0 = workpiece::fit(&read_part("grinder.csv")?, &mut warnings)?;
        let pass: Vec<[f64; 3]> = workpiece::pass_points(&form0, 5.0, 40)?
            .into_iter()
            .map(|[c, z]| [c, z, workpiece::correction_um(&form0, c, z)])
            .collect();
        let mut pass_csv = String::from("c_deg,z_mm,offset_um\n");
        for [c, z, o] in &pass {
            let _ = writeln!(pass_csv, "{c},{z},{o:.4}");
        }
        crate::workflow::write_file(&dir.join("pass.csv"), pass_csv.as_bytes())?;
        let after = onmachine::after_pass(SEED, &pass)?;
        crate::workflow::write_file(&dir.join("after.csv"), after.as_bytes())?;
        let form1 = workpiece::fit(&read_part("after.csv")?, &mut warnings)?;
        let story = format!(
            "6. On the machine ({}): the probe calibrated on a {} mm master ball — radius {:.5} mm ± {:.1} nm (nominal {} mm), its form {:.0} nm PV (the ball's PV {:.0} → {:.0} nm with it); a part scanned with it: {:.0} nm PV about its least-squares circle ({:.0} nm with the radius only; the scan's 5 nm noise is in both). A ground part: form {:.1} µm PV; the correction pass ground (the simulated grinder removes {:.0} % of each commanded depth) and measured again: {:.1} µm PV ({:.0} % left).",
            dir.display(),
            onmachine::BALL_DIAMETER_MM,
            pr.probe_radius_mm,
            pr.probe_radius_ci95_mm * 1e6,
            onmachine::PROBE_NOMINAL_RADIUS_MM,
            pr.form_pv_nm,
            cal.pv_without_form_nm,
            cal.pv_with_form_nm,
            part_pv,
            part_pv_radius_only,
            form0.form_pv_um,
            onmachine::REMOVAL_EFFICIENCY * 100.0,
            form1.form_pv_um,
            100.0 * form1.form_pv_um / form0.form_pv_um
        );
        let json = serde_json::json!({
            "dir": dir.display().to_string(),
            "probe_radius_mm": pr.probe_radius_mm,
            "probe_radius_ci95_mm": pr.probe_radius_ci95_mm,
            "probe_form_pv_nm": pr.form_pv_nm,
            "ball_pv_without_form_nm": cal.pv_without_form_nm,
            "ball_pv_with_form_nm": cal.pv_with_form_nm,
            "part_form_pv_nm": part_pv,
            "part_form_pv_radius_only_nm": part_pv_radius_only,
            "ground_form_pv_um": [form0.form_pv_um, form1.form_pv_um],
            "removal_efficiency": onmachine::REMOVAL_EFFICIENCY,
        });
        Ok((story, json))
    }
}

impl Args {
    pub fn run(self) -> Result<()> {
        let demo = Demo { out: self.out };
        if self.json {
            crate::cmd::out::json(&demo.run(Story::Stderr)?)
        } else {
            demo.run(Story::Stdout).map(|_| ())
        }
    }
}

/// The diagnosis stage of `trueaxis demo`: where the seed model fails, the
/// missing effect named, added and refitted until the noise floor, the
/// error falling step by step. Writes every fit to `model_path` (with its
/// history) and, with `report_dir`, the diagnosis of the seed model and the
/// history plot under `report_dir/diagnose` and `report_dir/history`.
/// Returns the final model, the story told and the steps.
fn demo_stage(
    data: &Dataset,
    data_path: &std::path::Path,
    seed: &str,
    model_path: &std::path::Path,
    report_dir: Option<&std::path::Path>,
) -> Result<(trueaxis_engine::model::ModelFile, String, Improvement)> {
    use std::fmt::Write as _;
    let mut s = String::new();
    let seed: trueaxis_engine::model::Seed = seed.parse()?;
    let first = diagnose::diagnose(data, &Options::seed(seed))?;
    let _ = writeln!(s, "Diagnose {seed} — which physical effect is missing?");
    let mut worst: Vec<&diagnose::Region> = first.worst_regions.iter().collect();
    worst.sort_by(|a, b| b.rms_um.total_cmp(&a.rms_um));
    if let Some(r) = worst.first() {
        let _ = writeln!(
            s,
            "   the model fails most on {} in {} mm (residual RMS {:.2} µm)",
            r.target,
            trueaxis_engine::compare::bbox_text(&r.bbox_mm),
            r.rms_um
        );
    }
    if let Some(dir) = report_dir {
        let p = crate::report::diagnose::write_for(
            &first,
            data,
            &data_path.display().to_string(),
            &model_path.display().to_string(),
            &dir.join("diagnose"),
            None,
        )?;
        let _ = writeln!(s, "   evidence: {}", p.display());
    }
    let fmt = |m: &BTreeMap<String, f64>| {
        m.iter()
            .map(|(k, v)| format!("{k} {v:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let r = improve(data, seed, model_path, false, |st| {
        match st.added_effects.as_slice() {
            [] => {
                let _ = writeln!(
                    s,
                    "   step {}: {seed} alone: RMS µm {}; held out {}",
                    st.step,
                    fmt(&st.rms_um),
                    fmt(&st.held_out_rms_um)
                );
            }
            added => {
                for a in added {
                    match &a.replaces {
                        Some(old) => {
                            let _ = writeln!(
                                s,
                                "   step {}: named `{}`, replacing `{old}`",
                                st.step, a.add
                            );
                        }
                        None => {
                            let _ = writeln!(s, "   step {}: named and added `{}`", st.step, a.add);
                        }
                    }
                    let _ = writeln!(s, "      because {}", a.evidence);
                }
                let _ = writeln!(
                    s,
                    "      refit: RMS µm {}; held out {}",
                    fmt(&st.rms_um),
                    fmt(&st.held_out_rms_um)
                );
            }
        }
        if st.verdict != Verdict::MissingEffect {
            let nf: Vec<String> = st
                .noise_floor_um
                .iter()
                .filter_map(|(k, v)| v.map(|v| format!("{k} {v:.2}")))
                .collect();
            let _ = writeln!(
                s,
                "   {} — noise floor µm: {}; no candidate is significant any more",
                st.outcome(),
                nf.join(", ")
            );
        }
    })?;
    if let Some(dir) = report_dir {
        let h = history::load(model_path)?;
        // The loop's last diagnosis measured the noise floor: the plot
        // draws it, and the verdict says whether the last fit reached it.
        let noise: BTreeMap<String, f64> = r
            .steps
            .last()
            .map(|st| {
                st.noise_floor_um
                    .iter()
                    .filter_map(|(t, v)| v.map(|v| (t.clone(), v)))
                    .collect()
            })
            .unwrap_or_default();
        let p = crate::report::history::write_report(
            &h,
            &model_path.display().to_string(),
            &data_path.display().to_string(),
            &dir.join("history"),
            &noise,
        )?;
        let _ = writeln!(s, "   the error falling: {}", p.display());
    }
    let _ = write!(s, "   model: {} → {}", r.model, r.model_file);
    Ok((trueaxis_engine::model::ModelFile::load(model_path)?, s, r))
}
