//! The bench image of `cargo xtask bench-mcu`: evaluates each benchmark
//! table (build/tables.rs, encoded by the build script) on a trajectory of
//! inputs and counts the instructions of every evaluation with the TIM2
//! counter (exact under `-icount shift=0`, see `icount`). One `BENCH` log
//! line per model kind; xtask turns them into the JSON lines of
//! `cargo xtask bench-mcu` (docs/qemu.md, "Instruction counts").
//!
//! Tables: the list build.rs generates (`BENCH_TABLES`), each as
//! `<name>_f32` and `<name>_fixed`. What is counted: one call of
//! `eval_f32` / `eval_fixed` on a loaded model (the firmware's
//! `ModelCap` capacity), i.e. one 3-axis update of the model (all three outputs), from the
//! call to the return. Not counted: reading sensors, the direction tracker,
//! slew limiting and pulse output (the engine's share). Each line also
//! carries model-core's static cost estimate of the same evaluation
//! (`est=`), which `cargo xtask test` checks against the count.
#![no_std]
#![no_main]

use core::hint::black_box;

use model_core::{Envelope, Inputs, Outputs};
use trueaxis_app::model::Model;
use trueaxis_qemu::icount::InstructionCounter;

include!(concat!(env!("OUT_DIR"), "/bench_tables.rs"));

/// Inputs per benchmark: a trajectory through the whole travel.
const CALLS: usize = 64;

/// Input `i` of the trajectory through the table's travel: a space-filling
/// zig-zag with reversals, temperatures between 18 and 28 °C, a 100 mm tool.
fn input(env: &Envelope, i: usize) -> Inputs {
    let t = i as i64;
    let n = CALLS as i64;
    let pos_nm = core::array::from_fn(|axis| {
        // Different speeds per axis so the points do not line up.
        let phase = (t * (axis as i64 + 2) * 7919) % (2 * n);
        let frac = if phase < n { phase } else { 2 * n - phase };
        let (lo, hi) = (
            i64::from(env.travel_min_nm[axis]),
            i64::from(env.travel_max_nm[axis]),
        );
        (lo + (hi - lo) * frac / n) as i32
    });
    let rev = if i.is_multiple_of(3) {
        -(1 << 30)
    } else {
        1 << 30
    };
    let temp = 18_000 + (i as i32 * 157) % 10_000;
    Inputs {
        pos_nm,
        rev_q30: [rev, -rev, rev],
        temp_mc: [temp, temp - 500, 0, 0],
        tool_nm: 100_000_000,
    }
}

/// Loads `bytes` into `model` — the firmware's model type and capacity, in
/// a static buffer: `Model::load` returns the model by value, and with a
/// few of them on the stack the image overflowed its 112 KiB stack.
fn load(name: &str, bytes: &'static [u8], model: &mut Model) {
    let table = match model_core::parse(bytes) {
        Ok(t) => t,
        Err(e) => defmt::panic!(
            "bench table {=str} does not parse: {}",
            name,
            defmt::Debug2Format(&e)
        ),
    };
    if let Err(e) = model.load_into(&table) {
        defmt::panic!(
            "bench table {=str} does not load: {}",
            name,
            defmt::Debug2Format(&e)
        );
    }
}

/// Counts `eval` over the trajectory and logs one BENCH line, with
/// model-core's static estimate of the same evaluation (`est`).
fn bench(
    counter: &InstructionCounter,
    name: &str,
    path: &str,
    model: &Model,
    eval: fn(&Model, &Inputs) -> Outputs,
    est: u32,
) {
    let (mut total, mut min, mut max) = (0u64, u32::MAX, 0u32);
    for i in 0..CALLS {
        let inp = black_box(input(model.envelope(), i));
        let (out, n) = counter.measure(|| eval(black_box(model), &inp));
        black_box(out);
        total += u64::from(n);
        min = min.min(n);
        max = max.max(n);
    }
    defmt::info!(
        "BENCH {=str}_{=str} total={=u64} calls={=u32} min={=u32} max={=u32} est={=u32}",
        name,
        path,
        total,
        CALLS as u32,
        min,
        max,
        est
    );
}

/// The f32 and fixed-point paths must agree (to a few nm) on every input,
/// or the counts would be of a broken evaluation.
fn sanity(name: &str, model: &Model) {
    for i in 0..CALLS {
        let inp = input(model.envelope(), i);
        let (a, b) = (model.eval_f32(&inp), model.eval_fixed(&inp));
        for axis in 0..3 {
            let d = a.corr_nm[axis].abs_diff(b.corr_nm[axis]);
            if d > 10 {
                defmt::panic!(
                    "{=str}: f32 and fixed differ by {} nm on input {} axis {}",
                    name,
                    d,
                    i,
                    axis
                );
            }
        }
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let counter = InstructionCounter::start();
    let model = cortex_m::singleton!(: Model = Model::empty()).expect("once");
    for &(name, bytes) in BENCH_TABLES {
        load(name, bytes, model);
        sanity(name, model);
        let est = match model_core::parse(bytes) {
            Ok(t) => model_core::cost::estimate(&t),
            Err(_) => defmt::panic!("bench table {=str} does not parse", name),
        };
        bench(&counter, name, "f32", model, Model::eval_f32, est.f32_instr);
        bench(
            &counter,
            name,
            "fixed",
            model,
            Model::eval_fixed,
            est.fixed_instr,
        );
    }
    trueaxis_qemu::exit(0)
}
