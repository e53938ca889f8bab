//! TIM2 as a free-running 32-bit counter from 0 at prescaler 0: under
//! `qemu-system-arm -icount shift=0` it counts one per executed instruction
//! (see `icount`). The one copy of the register sequence, used by this
//! crate's `icount::InstructionCounter` and by the tick bench
//! (`firmware/tickbench`, which includes this file by path: it does not
//! link this crate's logger and handlers). No pins: the timer runs on its
//! internal clock.

use stm32_metapac::{timer::vals::Urs, TIM2};

/// Stops TIM2, sets prescaler 0 and the full 32-bit reload, zeroes the
/// counter and starts it again.
pub fn start_free_running() {
    TIM2.cr1().write(|w| {
        w.set_cen(false);
        w.set_urs(Urs::COUNTER_ONLY);
    });
    TIM2.psc().write_value(0);
    TIM2.arr().write_value(u32::MAX);
    // UG loads the prescaler and zeroes the counter.
    TIM2.egr().write(|w| w.set_ug(true));
    TIM2.cr1().modify(|w| w.set_cen(true));
}
