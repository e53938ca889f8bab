//! A deliberately overflowing image: unbounded recursion must stop the
//! emulation with a fault as soon as the stack leaves RAM (the stack sits
//! below the statics, see qemu.x), not corrupt the statics and carry on.
//! xtask requires exit 1 with the HardFault handler's stack-overflow
//! report (the board's fault entry, trueaxis_stack_guard, reaches the
//! handler on a fresh stack) — not a clean exit, a lockup or a hang.
#![no_std]
#![no_main]

use trueaxis_qemu as _;

/// Recurses with 1 KiB frames until the stack runs out.
#[inline(never)]
#[allow(unconditional_recursion)] // the point of this image
fn deeper(depth: u32) -> u32 {
    let frame = core::hint::black_box([depth as u8; 1024]);
    deeper(depth + 1).wrapping_add(u32::from(frame[1000]))
}

#[cortex_m_rt::entry]
fn main() -> ! {
    defmt::info!("recursing until the stack overflows");
    let n = deeper(0);
    defmt::error!("the recursion returned ({}): the stack never overflowed", n);
    trueaxis_qemu::exit(0)
}
