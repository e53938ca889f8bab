//! Exact instruction counts under `qemu-system-arm -icount shift=0`.
//!
//! With `shift=0` QEMU advances virtual time by exactly 1 ns per executed
//! instruction, so any timer read before and after a call measures the
//! instructions in between. DWT CYCCNT reads 0 in QEMU, so timers it is.
//! (Instructions, not cycles: a real Cortex-M4 takes more cycles for loads,
//! branches and divisions; the count is a deterministic lower bound.)
//!
//! TIM2 is the counter: QEMU's STM32 timer model ticks at 1 GHz of virtual
//! time, so with prescaler 0 one count is one instruction, exactly, and its
//! 32-bit counter wraps only after 4.29 s of virtual time. SysTick (168 MHz,
//! 0.168 counts per instruction, 24 bits) would quantise to 6 instructions.
//! Both are checked against a block of `nop`s in the `infra` suite.

use stm32_metapac::TIM2;

/// A free-running TIM2 counting one per executed instruction (under
/// `-icount shift=0`), and the fixed cost of reading it.
#[derive(Debug)]
pub struct InstructionCounter {
    /// What [`measure`](Self::measure) reports for an empty closure: the
    /// instructions between the two counter reads that belong to the reads.
    overhead: u32,
}

impl InstructionCounter {
    /// Starts TIM2 free-running from 0 and calibrates the read overhead.
    pub fn start() -> Self {
        crate::tim2::start_free_running();
        let mut counter = Self { overhead: 0 };
        let (_, raw) = counter.measure(|| ());
        counter.overhead = raw;
        counter
    }

    /// The counter now (instructions since [`start`](Self::start), mod 2³²).
    #[inline(always)]
    pub fn now(&self) -> u32 {
        TIM2.cnt().read()
    }

    /// Runs `f` and returns its result with the instructions it executed
    /// (the read overhead removed). `f` is not inlined so that the compiler
    /// cannot move work across the counter reads; the count therefore
    /// includes the call and return.
    #[inline(always)]
    pub fn measure<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
        let t0 = self.now();
        let r = call_outlined(f);
        let t1 = self.now();
        (r, t1.wrapping_sub(t0).wrapping_sub(self.overhead))
    }

    /// The read overhead removed from every measurement.
    pub fn overhead(&self) -> u32 {
        self.overhead
    }
}

#[inline(never)]
fn call_outlined<R>(f: impl FnOnce() -> R) -> R {
    core::hint::black_box(f())
}
