//! The trueaxis engine: everything that computes, as a library with no
//! command line, no terminal output and no board link (those live in the
//! `trueaxis` binary crate). Layered bottom-up — a module imports only from
//! the layers below it:
//!
//! data → features → effect / linalg / lines / regions → holdout / travel → model →
//! fit → diagnose / compare / export / history / iso230 → improve → (the
//! CLI's commands). `import` (files ↔ data sets) and `units` (units the
//! data probably do not have) sit beside `data`, and so do `warning`,
//! `progress` and `files`, which import nothing;
//! `simulate` makes data sets from the effect families' simulated forms;
//! of the pipeline only `fit/rigid21` imports it (the simulator's
//! instruments are the menu `measure` chooses from, docs/volumetric.md).
//!
//! Beside the pipeline stands the **on-machine wing**, `onmachine/`: parts
//! and probes measured on the machine (probe calibration, error
//! separation, workpiece form, the part-scan diagnosis, the simulated
//! campaign). It uses the plumbing below it (`data`, `import`, `linalg`'s
//! least squares, `simulate`'s normal deviates) and nothing of the pipeline imports it.
//!
//! - `data`: the measurement data set (docs/cli.md § Measurement CSV) every command works on.
//! - `import`: measurement files in (the trueaxis CSV, Renishaw .rtl, ecmc ISO 230-2 .dat, RepRapFirmware and Klipper bed maps) and the CSV out.
//! - `units`: `units_suspect` — errors in mm in µm columns, nm as µm, positions in metres.
//! - `simulate`: the synthetic machine (21 geometric errors, effects, plans, noise).
//! - `features`: the model's terms — the cubic monomials and the effects' columns.
//! - `effect`: effects as types, one file per family (keys, columns, words, physical parameter, simulated form) — Family, Target, Axis, EffectSpec, Effect, and the one `key=value` grammar.
//! - `warning`: the one warning type (code + detail) every result carries.
//! - `progress`: the one progress event type long computations emit; the caller renders it.
//! - `files`: every output file written whole or not at all (temporary file, sync, rename) and one writer at a time (a lock file).
//! - `linalg`: the linear algebra — least squares with rank and conditioning checks (`lsq`), diagnose's basis and small fits (`basis`), Brent's minimisation (`brent`).
//! - `holdout`: block-held-out validation (spatial blocks, not random rows).
//! - `travel`: the travel a model is fitted on — the user's, or the data's bulk — and the rows outside it.
//! - `lines`: lines and planes of a measurement plan (compare's plots, diagnose's periodic search).
//! - `regions`: where a residual concentrates — one region type and binning for compare and diagnose.
//! - `model`: the saved model file and its evaluation.
//! - `fit`: training — linear/kinematic, local, grid and tanh-network models.
//! - `compare`: where a model fails — residual statistics, regions, channels.
//! - `diagnose`: which physical effect the model is missing, and how sure.
//! - `history`: the steps of the error falling, fit by fit.
//! - `improve`: the loop fit → diagnose → add the missing effects → refit, to the noise floor.
//! - `iso230`: ISO 230-2 evaluation of bidirectional positioning runs.
//! - `export`: the binary table for the board, controller compensation files and bed meshes.
//! - `onmachine`: the on-machine wing — probe calibration, error separation (reversal, three-probe, multi-step), workpiece form and pass, part-scan diagnosis, the probe columns of the measurement CSV and the simulated campaign.

pub mod compare;
pub mod data;
pub mod diagnose;
pub mod effect;
pub mod export;
pub mod features;
pub mod files;
pub mod fit;
pub mod history;
pub mod holdout;
pub mod import;
pub mod improve;
pub mod iso230;
pub mod linalg;
pub mod lines;
pub mod model;
pub mod onmachine;
pub mod progress;
pub mod regions;
pub mod simulate;
pub mod travel;
pub mod units;
pub mod warning;
