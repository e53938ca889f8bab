//! The compensation board's fixed resources (STM32F405RG, `firmware/board`),
//! defined once: the firmware sizes its buffers with these constants and
//! admits tables by the loop budget below, and the host checks a table
//! against the same limits before it touches a board (`trueaxis flash`,
//! `trueaxis upload`; `trueaxis export` warns), so a table the board
//! cannot hold or evaluate in time is refused on the desk with the limit
//! it exceeds and by how much — not by the board after an upload, nor
//! (for `flash`, which writes the slot directly) silently at the next boot.

use core::fmt;

use crate::cost::{estimate, CostEstimate};
use crate::definition::{check_definition, Departure, DEFINITION_BOUND_NM};
use crate::eval::{LoadError, ModelCap};
use crate::table::Table;

/// Largest table the board takes, bytes: its RAM staging buffer. An upload
/// is received into it, and at boot each flash slot is read into it to be
/// validated, so this — not the 128 KiB flash slot — bounds a table.
pub const STAGE_BYTES: usize = 24 * 1024;

/// Parameter capacity (coefficients, weights) of the board's models:
/// cubic19 on three outputs needs 57, a 3-16-3 MLP 115.
pub const MODEL_PARAMS: usize = 768;

/// Grid value capacity of the board's models (e.g. a 32 × 32 grid).
pub const MODEL_GRID: usize = 1024;

/// The board's prepared model: model-core's evaluator with the capacities
/// above (≈ 16.3 KiB; the board keeps two). Evaluation is the same code
/// whatever the capacity, so results are bit-identical to any other
/// [`ModelCap`]'s.
pub type BoardModel = ModelCap<MODEL_PARAMS, MODEL_GRID>;

/// Core clock of the board's STM32F405, Hz.
pub const CPU_HZ: u32 = 168_000_000;

/// Rate of the board's correction loop, Hz.
pub const LOOP_HZ: u32 = 20_000;

/// One loop period in core clock cycles (8 400): the most instructions a
/// tick could take at one instruction per cycle.
pub const PERIOD_INSTR: u32 = CPU_HZ / LOOP_HZ;

/// Share of the period a tick may not use, percent: kept for what the
/// instruction counts of QEMU do not see — interrupt entry and exit, the
/// executor, the link tasks holding the engine's lock for a request, and
/// cycles beyond one per instruction (flash wait states the ART
/// accelerator misses, loads, divisions). The 20 % is a judgement, not a
/// measurement: on hardware `worst_tick_us` in `trueaxis status` is the
/// measured answer.
pub const TICK_MARGIN_PERCENT: u32 = 20;

/// The instructions one tick may take (6 720): [`PERIOD_INSTR`] less the
/// margin. `cargo xtask test` fails when a table the board accepts ticks
/// longer than this under QEMU (firmware/tickbench).
pub const TICK_BUDGET_INSTR: u32 = PERIOD_INSTR / 100 * (100 - TICK_MARGIN_PERCENT);

/// The engine's own share of a tick, instructions, at most: sensors,
/// direction tracking, slew limit, pulses and the call of the model.
/// Measured by firmware/tickbench: 1 060 without a table, 1 050–1 350 as
/// a whole tick less the bench count of the table's evaluation; `cargo
/// xtask test` checks that every measured tick is at most this plus the
/// table's estimate.
pub const ENGINE_TICK_INSTR: u32 = 1_400;

/// The most instructions a table's fixed-point evaluation may be
/// estimated to take ([`crate::cost::estimate`]) for the board to accept
/// it (5 320): what the tick budget leaves after the engine's share.
pub const MODEL_BUDGET_INSTR: u32 = TICK_BUDGET_INSTR - ENGINE_TICK_INSTR;

/// A limit of the board a table exceeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LimitError {
    /// The table is larger than [`STAGE_BYTES`].
    TooLarge {
        /// Its size, bytes.
        bytes: u32,
        /// [`STAGE_BYTES`].
        max: u32,
    },
    /// It needs more parameters than [`MODEL_PARAMS`].
    Params {
        /// Parameters needed.
        needed: u32,
        /// [`MODEL_PARAMS`].
        max: u32,
    },
    /// It needs more grid values than [`MODEL_GRID`].
    Grid {
        /// Grid values needed.
        needed: u32,
        /// [`MODEL_GRID`].
        max: u32,
    },
    /// It cannot be loaded for another reason (terms, MLP inputs,
    /// coefficient ranges: the same for every capacity).
    Load(LoadError),
    /// Its fixed-point or f32 evaluation departs from its own definition
    /// by more than [`DEFINITION_BOUND_NM`] ([`crate::definition`]): the
    /// board would not correct by what the table says.
    OffDefinition(Departure),
    /// Its fixed-point evaluation is estimated above [`MODEL_BUDGET_INSTR`]:
    /// the correction loop could not evaluate it every period.
    TooSlow {
        /// The estimate, instructions.
        estimate: u32,
        /// The budget, instructions.
        budget: u32,
    },
}

impl fmt::Display for LimitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            LimitError::TooLarge { bytes, max } => write!(
                f,
                "the table is {bytes} bytes, the board takes at most {max} (its staging buffer): {} bytes over",
                bytes.saturating_sub(max)
            ),
            LimitError::Params { needed, max } => write!(
                f,
                "the table needs {needed} model parameters, the board's models hold {max}: {} over",
                needed.saturating_sub(max)
            ),
            LimitError::Grid { needed, max } => write!(
                f,
                "the table needs {needed} grid values, the board's models hold {max}: {} over",
                needed.saturating_sub(max)
            ),
            LimitError::Load(e) => write!(f, "the board cannot load the table: {e}"),
            LimitError::OffDefinition(d) => {
                let axis = ["ex", "ey", "ez"][usize::from(d.output % 3)];
                let path = d.path.name();
                let nm = d.error_nm;
                match d.at {
                    Some(i) => write!(
                        f,
                        "its {path} evaluation departs from the table's own definition (the f64 sum \
                         of its terms) by {nm} nm on {axis} at x = {:.6} mm, y = {:.6} mm, \
                         z = {:.6} mm, tool arm {:.6} mm, temperatures {:?} m°C, reversal {:?} \
                         (Q30)",
                        f64::from(i.pos_nm[0]) / 1e6,
                        f64::from(i.pos_nm[1]) / 1e6,
                        f64::from(i.pos_nm[2]) / 1e6,
                        f64::from(i.tool_nm) / 1e6,
                        i.temp_mc,
                        i.rev_q30
                    )?,
                    None => {
                        write!(
                            f,
                            "its {path} evaluation can depart from the table's own definition (the \
                             f64 sum of its terms) by up to {nm} nm on {axis} wherever the \
                             definition is not clamped: the rounding"
                        )?;
                        if let Some((k, kind)) = d.term {
                            write!(f, " of term {k} ({})", kind.name())?;
                        }
                        write!(
                            f,
                            " (its coefficients, weights or factor range are beyond what the \
                             evaluation represents: a value rounded to its binary scale, then \
                             multiplied by a tool arm, a temperature difference or a network's \
                             weights)"
                        )?
                    }
                }
                write!(f, "; the board allows {DEFINITION_BOUND_NM} nm")
            }
            LimitError::TooSlow { estimate, budget } => write!(
                f,
                "its evaluation is estimated at {estimate} instructions, the board's {} Hz \
                 correction loop leaves {budget} for it: {} over (a tick may take {} of the \
                 {} a period has, {} of them the engine's own)",
                LOOP_HZ,
                estimate.saturating_sub(budget),
                TICK_BUDGET_INSTR,
                PERIOD_INSTR,
                ENGINE_TICK_INSTR
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LimitError {}

/// Whether the correction loop can evaluate `table` every period: its
/// fixed-point cost estimate against `budget_instr` (the board uses
/// [`MODEL_BUDGET_INSTR`]). The firmware's admission at commit and the
/// host's checks call this one function.
pub fn check_cost(table: &Table<'_>, budget_instr: u32) -> Result<CostEstimate, LimitError> {
    let est = estimate(table);
    if est.fixed_instr > budget_instr {
        return Err(LimitError::TooSlow {
            estimate: est.fixed_instr,
            budget: budget_instr,
        });
    }
    Ok(est)
}

/// Checks `table` against the board's limits: its size, whether it loads
/// into a [`BoardModel`] (built in `model`, which is left loaded when it
/// fits; ≈ 16.3 KiB, so callers with a small stack pass a static), whether
/// the loop can evaluate it ([`check_cost`]) and whether its evaluations
/// are its definition ([`check_definition`]).
#[inline] // see `definition`'s module doc: compiled only where it is called
pub fn check_into(table: &Table<'_>, model: &mut BoardModel) -> Result<(), LimitError> {
    let bytes = table.bytes().len();
    if bytes > STAGE_BYTES {
        return Err(LimitError::TooLarge {
            bytes: bytes.min(u32::MAX as usize) as u32,
            max: STAGE_BYTES as u32,
        });
    }
    model.load_into(table).map_err(|e| match e {
        LoadError::ParamCapacity { needed, capacity } => LimitError::Params {
            needed,
            max: capacity,
        },
        LoadError::GridCapacity { needed, capacity } => LimitError::Grid {
            needed,
            max: capacity,
        },
        e => LimitError::Load(e),
    })?;
    check_cost(table, MODEL_BUDGET_INSTR)?;
    // Last: the dearest check (DEFINITION_POINTS evaluations in f64, f32
    // and fixed point; BENCHMARKS.md), run only on a table the board
    // would otherwise take.
    match check_definition(table, model) {
        Some(d) => Err(LimitError::OffDefinition(d)),
        None => Ok(()),
    }
}

/// [`check_into`] with a model of its own (host: it is boxed).
#[cfg(feature = "std")]
pub fn check(table: &Table<'_>) -> Result<(), LimitError> {
    let mut m = std::boxed::Box::new(BoardModel::empty());
    check_into(table, &mut m)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::spec::{GridAxisSpec, GridSpec, TableSpec, TermSpec};
    use crate::{Envelope, InputScaling};

    /// A valid table with one grid of `nx` × `ny` values.
    fn grid_table(nx: u16, ny: u16) -> std::vec::Vec<u8> {
        let t = 400_000_000;
        let ax = |n: u16| GridAxisSpec {
            nodes: n,
            origin_nm: -t,
            step_nm: 2 * t / (i32::from(n) - 1),
        };
        TableSpec {
            created_unix_s: 0,
            source_hash: [0; 32],
            channels: std::vec::Vec::new(),
            envelope: Envelope {
                travel_min_nm: [-t; 3],
                travel_max_nm: [t; 3],
                max_corr_nm: [100_000; 3],
                max_slew_nm_per_ms: 100,
                ..Envelope::default()
            },
            scaling: InputScaling {
                centre_nm: [0; 3],
                half_span_nm: [t; 3],
            },
            outputs: [true, false, false],
            terms: std::vec![TermSpec::Grid(GridSpec {
                output: 0,
                axes: [
                    ax(nx),
                    ax(ny),
                    GridAxisSpec {
                        nodes: 1,
                        origin_nm: 0,
                        step_nm: 1,
                    },
                ],
                values_nm: (0..usize::from(nx) * usize::from(ny))
                    .map(|i| (i % 97) as f64)
                    .collect(),
            })],
        }
        .encode()
        .unwrap()
    }

    #[test]
    fn limits_name_what_is_exceeded_and_by_how_much() {
        // 32 × 32 = 1024 values: exactly the capacity.
        let fits = grid_table(32, 32);
        assert_eq!(check(&crate::parse(&fits).unwrap()), Ok(()));
        // 40 × 40 = 1600 values, 12.8 KB: over the grid capacity by 576.
        let big = grid_table(40, 40);
        let e = check(&crate::parse(&big).unwrap()).unwrap_err();
        assert_eq!(
            e,
            LimitError::Grid {
                needed: 1600,
                max: MODEL_GRID as u32
            }
        );
        assert!(e.to_string().contains("576 over"), "{e}");
        // 60 × 60 values, 28.8 KB: over the staging buffer first.
        let huge = grid_table(60, 60);
        let e = check(&crate::parse(&huge).unwrap()).unwrap_err();
        let over = huge.len() - STAGE_BYTES;
        assert_eq!(
            e,
            LimitError::TooLarge {
                bytes: huge.len() as u32,
                max: STAGE_BYTES as u32
            }
        );
        assert!(
            e.to_string().contains(&std::format!("{over} bytes over")),
            "{e}"
        );
    }

    #[test]
    fn tables_too_slow_for_the_loop_are_refused_by_their_estimate() {
        let all = crate::parse(include_bytes!("../tests/golden/all_kinds.bin")).unwrap();
        let est = crate::cost::estimate(&all).fixed_instr;
        assert!(est > MODEL_BUDGET_INSTR, "{est}");
        let e = check(&all).unwrap_err();
        assert_eq!(
            e,
            LimitError::TooSlow {
                estimate: est,
                budget: MODEL_BUDGET_INSTR
            }
        );
        let over = est - MODEL_BUDGET_INSTR;
        assert!(e.to_string().contains(&std::format!("{over} over")), "{e}");
        // A larger budget takes it; a small table fits the board's.
        assert!(check_cost(&all, est).is_ok());
        let nn = crate::parse(include_bytes!("../tests/golden/nn_3x16x3.bin")).unwrap();
        assert_eq!(check(&nn), Ok(()));
        const { assert!(TICK_BUDGET_INSTR == ENGINE_TICK_INSTR + MODEL_BUDGET_INSTR) };
        const { assert!(TICK_BUDGET_INSTR < PERIOD_INSTR) };
    }
}
