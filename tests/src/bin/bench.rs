//! The bench image of `cargo xtask bench-mcu`: evaluates each benchmark
//! table (build/tables.rs, encoded by the build script) on a trajectory of
//! inputs and counts the instructions of every evaluation with the TIM2
//! counter (exact under `-icount shift=0`, see `icount`). One `BENCH` log
//! line per model kind; xtask turns them into CONTRACT.md §3 JSON lines.
//!
//! What is counted: one call of `eval_f32` / `eval_fixed` on a loaded
//! model, i.e. one 3-axis update of the model (all three outputs), from the
//! call to the return. Not counted: reading sensors, the direction tracker,
//! slew limiting and pulse output (the engine's share).
#![no_std]
#![no_main]

use core::hint::black_box;

use model_core::{Inputs, Model, Outputs};
use trueaxis_qemu::icount::InstructionCounter;

/// Inputs per benchmark: a trajectory through the whole travel.
const CALLS: usize = 64;

/// Travel of the bench tables, nm (build/tables.rs).
const TRAVEL_MAX_NM: [i32; 3] = [800_000_000, 500_000_000, 500_000_000];

static CUBIC19: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/cubic19.bin"));
static FULL: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/full.bin"));
static NN_3X16X3: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/nn_3x16x3.bin"));

/// Input `i` of the trajectory: a space-filling zig-zag with reversals,
/// temperatures between 18 and 28 °C, a 100 mm tool.
fn input(i: usize) -> Inputs {
    let t = i as i64;
    let n = CALLS as i64;
    let pos_nm = core::array::from_fn(|axis| {
        // Different speeds per axis so the points do not line up.
        let phase = (t * (axis as i64 + 2) * 7919) % (2 * n);
        let frac = if phase < n { phase } else { 2 * n - phase };
        (i64::from(TRAVEL_MAX_NM[axis]) * frac / n) as i32
    });
    let rev = if i.is_multiple_of(3) {
        -(1 << 30)
    } else {
        1 << 30
    };
    Inputs {
        pos_nm,
        rev_q30: [rev, -rev, rev],
        temp_mc: [18_000 + (i as i32 * 157) % 10_000, 0, 0, 0],
        tool_nm: 100_000_000,
    }
}

fn load(name: &str, bytes: &'static [u8]) -> Model {
    let table = match model_core::parse(bytes) {
        Ok(t) => t,
        Err(e) => defmt::panic!(
            "bench table {=str} does not parse: {}",
            name,
            defmt::Debug2Format(&e)
        ),
    };
    match Model::load(&table) {
        Ok(m) => m,
        Err(e) => defmt::panic!(
            "bench table {=str} does not load: {}",
            name,
            defmt::Debug2Format(&e)
        ),
    }
}

/// Counts `eval` over the trajectory and logs one BENCH line.
fn bench(
    counter: &InstructionCounter,
    name: &str,
    model: &Model,
    eval: fn(&Model, &Inputs) -> Outputs,
) {
    let (mut total, mut min, mut max) = (0u64, u32::MAX, 0u32);
    for i in 0..CALLS {
        let inp = black_box(input(i));
        let (out, n) = counter.measure(|| eval(black_box(model), &inp));
        black_box(out);
        total += u64::from(n);
        min = min.min(n);
        max = max.max(n);
    }
    defmt::info!(
        "BENCH {=str} total={=u64} calls={=u32} min={=u32} max={=u32}",
        name,
        total,
        CALLS as u32,
        min,
        max
    );
}

/// The f32 and fixed-point paths must agree (to a few nm) on every input,
/// or the counts would be of a broken evaluation.
fn sanity(name: &str, model: &Model) {
    for i in 0..CALLS {
        let inp = input(i);
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
    let models: [(&str, &'static [u8]); 3] = [
        ("cubic19", CUBIC19),
        ("full", FULL),
        ("nn_3x16x3", NN_3X16X3),
    ];
    for (name, bytes) in models {
        let model = load(name, bytes);
        sanity(name, &model);
        let label_f32 = match name {
            "cubic19" => "cubic19_f32",
            "full" => "full_f32",
            _ => "nn_3x16x3_f32",
        };
        bench(&counter, label_f32, &model, Model::eval_f32);
        let label_fixed = match name {
            "cubic19" => "cubic19_fixed",
            "full" => "full_fixed",
            _ => "nn_3x16x3_fixed",
        };
        bench(&counter, label_fixed, &model, Model::eval_fixed);
    }
    trueaxis_qemu::exit(0)
}
