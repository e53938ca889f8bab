//! Checks the QEMU infrastructure itself, so that a broken harness cannot
//! pass silently: defmt logging and the semihosting exit work (this suite
//! runs at all), and the instruction counter reports a known instruction
//! sequence exactly, cross-checked against SysTick's 168 MHz clock.
#![no_std]
#![no_main]

use trueaxis_qemu as _;

/// `N` nops, exactly `N` instructions (no loop around them).
macro_rules! nops {
    ($n:literal) => {{
        // The asm! block is the point of the test: a sequence whose length is
        // known by construction.
        #[allow(unsafe_code)]
        #[inline(always)]
        fn block() {
            unsafe {
                core::arch::asm!(
                    concat!(".rept ", stringify!($n)),
                    "nop",
                    ".endr",
                    options(nomem, nostack)
                )
            }
        }
        block()
    }};
}

#[defmt_test::tests]
mod tests {
    use cortex_m::peripheral::{syst::SystClkSource, SYST};
    use trueaxis_qemu::icount::InstructionCounter;

    #[init]
    fn init() -> InstructionCounter {
        InstructionCounter::start()
    }

    #[test]
    fn empty_closure_counts_at_most_two(counter: &mut InstructionCounter) {
        defmt::info!("counter read overhead: {} instructions", counter.overhead());
        // Each closure is its own monomorphisation of the outlined call, so an
        // empty one may differ from the calibration by the odd instruction.
        for _ in 0..4 {
            let ((), n) = counter.measure(|| ());
            defmt::assert!(n <= 2, "empty closure counted {} instructions", n);
        }
    }

    #[test]
    fn counts_nops_exactly(counter: &mut InstructionCounter) {
        let ((), n0) = counter.measure(|| ());
        let ((), n1000) = counter.measure(|| nops!(1000));
        let ((), n10000) = counter.measure(|| nops!(10000));
        defmt::info!(
            "0 nops: {}, 1000 nops: {}, 10000 nops: {}",
            n0,
            n1000,
            n10000
        );
        // Exact in the difference; within the call overhead absolutely.
        defmt::assert_eq!(n10000 - n1000, 9000);
        defmt::assert!(
            (1000..=1002).contains(&n1000),
            "1000 nops counted {}",
            n1000
        );
        defmt::assert!(n0 <= 2);
    }

    #[test]
    fn systick_agrees_at_168_mhz(counter: &mut InstructionCounter) {
        // SysTick counts down at the core clock, 168 MHz: 10 000 instructions
        // (10 µs of virtual time) are 1680 ticks, ±1 for where the reads fall.
        #[allow(unsafe_code)] // the suite owns the core peripherals
        let mut syst = unsafe { cortex_m::Peripherals::steal() }.SYST;
        syst.set_reload(0x00ff_ffff);
        syst.clear_current();
        syst.set_clock_source(SystClkSource::Core);
        syst.enable_counter();
        let s0 = SYST::get_current();
        let ((), n) = counter.measure(|| nops!(10000));
        let s1 = SYST::get_current();
        syst.disable_counter();
        let ticks = s0.wrapping_sub(s1) & 0x00ff_ffff;
        defmt::info!("10000 nops: {} instructions, {} SysTick ticks", n, ticks);
        let expected = (u64::from(n) * 168).div_ceil(1000) as u32;
        defmt::assert!(
            ticks.abs_diff(expected) <= 2,
            "SysTick {} vs {}",
            ticks,
            expected
        );
    }
}
