//! The board's definition check on the emulated STM32F405 (issue 25):
//! `model_core::definition::check_definition`, what a commit and the
//! boot's scan of the slots run after loading a table, once per bench
//! table (the bench image's list, `BENCH_TABLES`), its instructions counted
//! with TIM2 (exact under `-icount shift=0`, see `icount`). One `CHECK
//! <name> instructions=N accepted=…` line per table and the board's model
//! budget (`MODEL_BUDGET instructions=N`); `cargo xtask test` requires
//! every bench table accepted and the check within its budget where the
//! board takes the table, `cargo xtask bench-mcu` prints the counts
//! (docs/qemu.md, "Instruction counts"). An image of its own: linked into
//! the bench image, the check's calls changed how the evaluations there
//! were compiled (`poly_deg5_f32` +345 instructions), and those are what
//! the bench image measures.
#![no_std]
#![no_main]

use core::hint::black_box;

use trueaxis_app::model::Model;
use trueaxis_qemu::icount::InstructionCounter;

include!(concat!(env!("OUT_DIR"), "/bench_tables.rs"));

#[cortex_m_rt::entry]
fn main() -> ! {
    let counter = InstructionCounter::start();
    let model = cortex_m::singleton!(: Model = Model::empty()).expect("once");
    defmt::info!(
        "MODEL_BUDGET instructions={=u32}",
        model_core::board::MODEL_BUDGET_INSTR
    );
    for &(name, bytes) in BENCH_TABLES {
        let Ok(table) = model_core::parse(bytes) else {
            defmt::panic!("bench table {=str} does not parse", name)
        };
        if model.load_into(&table).is_err() {
            defmt::panic!("bench table {=str} does not load", name);
        }
        let (d, n) = counter.measure(|| {
            model_core::definition::check_definition(black_box(&table), black_box(&*model))
        });
        defmt::info!(
            "CHECK {=str} instructions={=u32} accepted={=bool}",
            name,
            n,
            d.is_none()
        );
    }
    trueaxis_qemu::exit(0)
}
