//! A deliberately overflowing image: unbounded recursion must stop the
//! emulation with a fault as soon as the stack leaves RAM (the stack sits
//! below the statics, see qemu.x), not corrupt the statics and carry on.
//! xtask requires exit 1 with the HardFault handler's stack-overflow
//! report (the board's fault entry, trueaxis_stack_guard, reaches the
//! handler on a fresh stack) — not a clean exit, a lockup or a hang.
#![no_std]
#![no_main]

#[path = "../rig.rs"]
#[allow(dead_code)] // each image uses part of it
mod rig;

use rig::deeper;

#[cortex_m_rt::entry]
fn main() -> ! {
    defmt::info!("recursing until the stack overflows");
    let n = deeper(0);
    defmt::error!("the recursion returned ({}): the stack never overflowed", n);
    trueaxis_qemu::exit(0)
}
