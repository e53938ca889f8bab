//! The one place the application core touches model-core's evaluation API:
//! load a table into a RAM-resident model, evaluate it in fixed point, read
//! its envelope, track directions. Keeping it in one file keeps the engine
//! readable and makes a model-core API change a one-file change.
//!
//! A [`Model`] is large (≈ 16.3 KiB: fixed-capacity coefficient pools), so it
//! is never moved around: the board owns two buffers, the link server loads
//! a table into the spare one *outside* the engine's lock, and activation
//! swaps two references inside it — O(1) in the correction loop's critical
//! section instead of a 26 KiB copy that would cost a period.

use model_core::{DirTracker, Flags, Inputs, Transition, MAX_TEMPS};
use trueaxis_protocol::LINK_TEMPS;

pub use model_core::FORMAT_VERSION;

/// Parameter capacity of the firmware's models (model-core's
/// [`board`](model_core::board) limits, which the host checks too).
pub const FW_PARAMS: usize = model_core::board::MODEL_PARAMS;
/// Grid value capacity of the firmware's models.
pub const FW_GRID: usize = model_core::board::MODEL_GRID;

/// The firmware's prepared model: model-core's evaluator with capacities
/// sized for the F405's RAM ([`model_core::board::BoardModel`]).
/// A table that needs more is refused at commit (`InvalidTable::Load`),
/// never half loaded. Evaluation is the same code whatever the capacity, so results
/// are bit-identical to the host's.
pub type Model = model_core::board::BoardModel;

/// Why a table cannot become the active model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InvalidTable {
    /// model-core's `parse` refused it (format, version, CRC, envelope).
    Format(model_core::TableError),
    /// Valid, but it does not fit the firmware's model capacity.
    Load(model_core::LoadError),
    /// Its fixed-point or f32 evaluation departs from its own definition
    /// (`model_core::definition`, [`check_loaded`]).
    OffDefinition(model_core::definition::Departure),
    /// [`check_loaded`] on a buffer with no model in it.
    NotLoaded,
}

/// Everything the model is evaluated on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModelInputs {
    /// Position per axis, nm.
    pub pos_nm: [i32; 3],
    /// Reversal state per axis, Q30.
    pub rev_q30: [i32; 3],
    /// Temperatures, m°C (the link's channel count; the model reads the
    /// first `MAX_TEMPS`).
    pub temp_mc: [i32; LINK_TEMPS],
    /// Tool length, nm.
    pub tool_nm: i32,
}

/// One evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Evaluation {
    /// Correction per axis, nm (model-core applied the envelope: held at
    /// the travel edge, clamped to the max |correction|).
    pub corr_nm: [i32; 3],
    /// model-core's flags, raw bits.
    pub flags: u16,
    /// The model reports a non-finite result (forced to 0 by model-core).
    pub not_finite: bool,
}

// The link must carry at least the channels a model reads.
const _: () = assert!(LINK_TEMPS >= MAX_TEMPS);

/// A RAM buffer for one prepared model, empty until a table is loaded
/// (`const`-constructible, so the board can put it in a `static`). The
/// model is loaded in place ([`load_into`]): never built on the stack and
/// moved, which cost the board a 35 KiB stack frame (issue 25).
#[derive(Debug)]
pub struct ModelBuf {
    model: Model,
    loaded: bool,
}

impl ModelBuf {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            model: Model::empty(),
            loaded: false,
        }
    }

    /// The model, if one is loaded.
    pub fn get(&self) -> Option<&Model> {
        self.loaded.then_some(&self.model)
    }
}

impl Default for ModelBuf {
    fn default() -> Self {
        Self::new()
    }
}

/// Validates `bytes` fully (format, version, CRC, envelope) and prepares
/// the model in `dst`, in place (emptied first, so a refused table leaves
/// it empty).
pub fn load_into(bytes: &[u8], dst: &mut ModelBuf) -> Result<(), InvalidTable> {
    dst.loaded = false;
    let t = model_core::parse(bytes).map_err(InvalidTable::Format)?;
    load_table(&t, dst)
}

fn load_table(t: &model_core::Table<'_>, dst: &mut ModelBuf) -> Result<(), InvalidTable> {
    dst.loaded = false;
    dst.model.load_into(t).map_err(InvalidTable::Load)?;
    dst.loaded = true;
    Ok(())
}

/// [`load_into`], then [`check_loaded`]: what the boot's scan of the slots
/// runs on each stored table.
#[inline] // compiled only where called (model_core::definition)
pub fn load_checked(bytes: &[u8], dst: &mut ModelBuf) -> Result<(), InvalidTable> {
    dst.loaded = false;
    let t = model_core::parse(bytes).map_err(InvalidTable::Format)?;
    load_table(&t, dst)?;
    check_table(&t, dst)
}

/// The definition check (`model_core::definition`, what
/// `model_core::board::check` runs on the host last) on `bytes` loaded in
/// `dst`: a table whose fixed-point or f32 evaluation departs from its own
/// f64 definition by more than `DEFINITION_BOUND_NM` is refused and `dst`
/// left empty. What a commit runs before it writes a table.
#[inline] // compiled only where called (model_core::definition)
pub fn check_loaded(bytes: &[u8], dst: &mut ModelBuf) -> Result<(), InvalidTable> {
    let t = model_core::parse(bytes).map_err(InvalidTable::Format)?;
    check_table(&t, dst)
}

#[inline] // compiled only where called (model_core::definition)
fn check_table(t: &model_core::Table<'_>, dst: &mut ModelBuf) -> Result<(), InvalidTable> {
    if !dst.loaded {
        return Err(InvalidTable::NotLoaded);
    }
    if let Some(d) = model_core::definition::check_definition(t, &dst.model) {
        dst.loaded = false;
        return Err(InvalidTable::OffDefinition(d));
    }
    Ok(())
}

/// The model-core inputs for `i`.
pub fn inputs(i: &ModelInputs) -> Inputs {
    let mut temp_mc = [0; MAX_TEMPS];
    temp_mc.copy_from_slice(&i.temp_mc[..MAX_TEMPS]);
    Inputs {
        pos_nm: i.pos_nm,
        rev_q30: i.rev_q30,
        temp_mc,
        tool_nm: i.tool_nm,
    }
}

/// The model-core inputs of the sensors' readings (the tick's common
/// case: built once, no [`ModelInputs`] in between).
#[inline(always)]
pub fn sensor_inputs(
    pos_nm: [i32; 3],
    rev_q30: [i32; 3],
    temp_mc: &[i32; LINK_TEMPS],
    tool_nm: i32,
) -> Inputs {
    Inputs {
        pos_nm,
        rev_q30,
        temp_mc: core::array::from_fn(|c| temp_mc[c]),
        tool_nm,
    }
}

/// Fixed-point evaluation (bit-exact with the host's `eval_fixed`).
pub fn evaluate(m: &Model, i: &ModelInputs) -> Evaluation {
    evaluate_inputs(m, &inputs(i))
}

/// [`evaluate`] of model-core inputs.
#[inline(always)]
pub fn evaluate_inputs(m: &Model, i: &Inputs) -> Evaluation {
    let o = m.eval_fixed(i);
    Evaluation {
        corr_nm: o.corr_nm,
        flags: o.flags.bits(),
        not_finite: o.flags.contains(Flags::NOT_FINITE),
    }
}

/// The table's slew limit, nm/ms.
pub fn slew_nm_per_ms(m: &Model) -> i32 {
    m.envelope().max_slew_nm_per_ms()
}

/// Direction trackers for the three axes.
#[derive(Debug, Default, Clone, Copy)]
pub struct DirTrackers {
    t: [DirTracker; 3],
    /// The transition lengths with their swing constants, made when the
    /// table is activated (not on every tick).
    transition: [Transition; 3],
}

impl DirTrackers {
    /// Trackers with the model's reversal transition lengths (0: switch at
    /// once, for axes without a reversal term).
    pub fn for_model(m: &Model) -> Self {
        Self {
            t: [DirTracker::new(); 3],
            transition: core::array::from_fn(|a| {
                Transition::new(m.reversal_transition_nm(a).unwrap_or(0))
            }),
        }
    }

    /// Takes the model's reversal transition lengths, keeping each axis's
    /// state (the direction the machine last moved is not the table's: a
    /// table switch must not reset it).
    pub fn set_transitions(&mut self, m: &Model) {
        self.transition = Self::for_model(m).transition;
    }

    /// Feeds the positions of one tick; returns the reversal state per axis.
    #[inline]
    pub fn update(&mut self, pos_nm: [i32; 3]) -> [i32; 3] {
        core::array::from_fn(|a| self.t[a].update_with(pos_nm[a], &self.transition[a]))
    }
}
