//! A deliberately faulting image: xtask runs it and requires exit status 1
//! with the HardFault report, proving that a fault in any image fails the
//! run instead of hanging QEMU until the timeout.
#![no_std]
#![no_main]

use trueaxis_qemu as _;

#[cortex_m_rt::entry]
fn main() -> ! {
    defmt::info!("about to execute a permanently undefined instruction");
    // `udf` raises a UsageFault, escalated to HardFault (no handler enabled).
    cortex_m::asm::udf()
}
