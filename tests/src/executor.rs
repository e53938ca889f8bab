//! A thread-mode executor that sleeps with WFI, for QEMU.
//!
//! embassy-executor's Cortex-M thread executor sleeps with WFE, which QEMU
//! implements as a no-op: the idle image would spin and burn a host core for
//! as long as it runs (measured: 100 % of a core while waiting for the
//! link). WFI does halt QEMU's CPU. The classic race — an interrupt pends
//! work between the check and the sleep — is closed by checking with
//! interrupts masked: WFI still wakes on a pending interrupt while PRIMASK
//! is set, and the handler runs as soon as the mask is lifted.

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{raw, Spawner};

/// Set by embassy when a task was woken; cleared when the executor polls.
static WORK_PENDING: AtomicBool = AtomicBool::new(false);

// embassy's raw executor calls this symbol to request a poll.
#[allow(unsafe_code)] // export_name is how embassy finds the pender
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK_PENDING.store(true, Ordering::Release);
}

/// The executor: `run` never returns.
pub struct WfiExecutor {
    inner: raw::Executor,
}

impl WfiExecutor {
    /// A new executor (put it in a `static`, e.g. with `cortex_m::singleton!`).
    pub fn new() -> Self {
        Self {
            inner: raw::Executor::new(core::ptr::null_mut()),
        }
    }

    /// Spawns the first tasks with `init`, then polls forever, sleeping
    /// while there is nothing to do.
    pub fn run(&'static mut self, init: impl FnOnce(Spawner)) -> ! {
        init(self.inner.spawner());
        loop {
            // The executor lives for ever and is only polled from here
            // (thread mode), as `poll` requires.
            #[allow(unsafe_code)]
            unsafe {
                self.inner.poll()
            };
            cortex_m::interrupt::free(|_| {
                if !WORK_PENDING.swap(false, Ordering::AcqRel) {
                    cortex_m::asm::wfi();
                }
            });
        }
    }
}

impl Default for WfiExecutor {
    fn default() -> Self {
        Self::new()
    }
}
