//! A SysTick time driver for embassy-time, for the images that run the
//! application core under embassy-executor in QEMU (the board's
//! embassy-stm32 driver cannot run there: `embassy_stm32::init` waits for
//! RCC/PWR ready bits QEMU does not model).
//!
//! SysTick interrupts every millisecond (168 000 core clocks at 168 MHz,
//! QEMU's netduinoplus2 clock); `now()` is microseconds, read from the
//! millisecond count plus the SysTick counter so that timestamps are fine
//! grained, while wake-ups are resolved at the next millisecond tick (a
//! timer may fire late by up to 1 ms, never early — all embassy promises).

use core::cell::{Cell, RefCell};
use core::task::Waker;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;
use critical_section::Mutex;
use embassy_time_driver::Driver;

/// Core clock of QEMU's STM32F405 model.
const CORE_HZ: u32 = 168_000_000;
/// SysTick period: 1 ms.
const RELOAD: u32 = CORE_HZ / 1000 - 1;
/// How many timers may be pending at once (one per task that sleeps; the
/// images have a handful of tasks).
const SLOTS: usize = 8;

/// A pending wake-up: deadline in µs and the task to wake.
type Pending = Option<(u64, Waker)>;

struct SysTickDriver {
    /// Milliseconds since [`start`].
    ms: Mutex<Cell<u64>>,
    /// Pending wake-ups: (deadline in µs, waker).
    queue: Mutex<RefCell<[Pending; SLOTS]>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ms: Mutex::new(Cell::new(0)),
    queue: Mutex::new(RefCell::new([const { None }; SLOTS])),
});

/// Starts the 1 ms SysTick interrupt. Call once, before the executor runs.
pub fn start(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| {
            let mut ms = self.ms.borrow(cs).get();
            let mut down = SYST::get_current();
            // The counter may have wrapped since the last interrupt ran (we
            // are inside a critical section): count that millisecond too,
            // and re-read the counter so it belongs to the new period.
            if SCB::is_pendst_pending() {
                ms += 1;
                down = SYST::get_current();
            }
            let clocks_in_ms = RELOAD - down.min(RELOAD);
            ms * 1000 + u64::from(clocks_in_ms) / u64::from(CORE_HZ / 1_000_000)
        })
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut queue = self.queue.borrow_ref_mut(cs);
            // Same task again: move its deadline (keep the earlier one; an
            // early wake is harmless, the task polls and sleeps again).
            for (deadline, w) in queue.iter_mut().flatten() {
                if w.will_wake(waker) {
                    *deadline = (*deadline).min(at);
                    return;
                }
            }
            match queue.iter_mut().find(|slot| slot.is_none()) {
                Some(slot) => *slot = Some((at, waker.clone())),
                // Out of slots: a fixed-size image bug, not a runtime
                // condition — fail loudly rather than lose a wake-up.
                None => panic!("time driver: more than {} pending timers", SLOTS),
            }
        })
    }
}

#[exception]
fn SysTick() {
    let expired: [Option<Waker>; SLOTS] = critical_section::with(|cs| {
        let ms = DRIVER.ms.borrow(cs);
        ms.set(ms.get() + 1);
        let now_us = ms.get() * 1000;
        let mut queue = DRIVER.queue.borrow_ref_mut(cs);
        core::array::from_fn(|i| match &queue[i] {
            Some((at, _)) if *at <= now_us => queue[i].take().map(|(_, w)| w),
            _ => None,
        })
    });
    // Wake outside the critical section.
    for w in expired.into_iter().flatten() {
        w.wake();
    }
}
