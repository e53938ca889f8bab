//! What survives a reset, and how the board resets on a fault (the boot
//! fallback of trueaxis_app::boot).
//!
//! - [`RECORD`]: the boot record, in a `.uninit` RAM section (cortex-m-rt
//!   neither zeroes nor initialises it, so it keeps its words through a
//!   system, watchdog or pin reset; after a power-up it holds noise, which
//!   its magic and check word refuse). Written by the link server (through
//!   [`RecordRam`]) and by the two handlers below, read once at boot.
//! - The panic handler and the HardFault handler record which fault it was
//!   and reset at once (`SCB::sys_reset`): the next boot decides whether
//!   the running table failed its trial. A stack overflow is a HardFault
//!   too: the stack sits below the statics with an MPU guard region under
//!   it, and the fault entry moves to a fresh stack before this handler
//!   runs (trueaxis_stack_guard). (A fault that cannot reach its handler —
//!   a lockup — stops the loop, and the watchdog resets; the reset flags
//!   say so.)
//! - [`reset_cause`]: RCC_CSR's reset flags, read and cleared at boot.
#![allow(unsafe_code)] // a `.uninit` static and the fault handlers

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use trueaxis_app::boot::{BootRecord, Fault, ResetCause, RECORD_WORDS};
use trueaxis_app::server::ResetRecord;

#[unsafe(link_section = ".uninit.trueaxis_boot_record")]
static mut RECORD: MaybeUninit<[u32; RECORD_WORDS]> = MaybeUninit::uninit();

fn record_ptr() -> *mut [u32; RECORD_WORDS] {
    // Only the address is taken; every access below is volatile and
    // single-threaded (boot, the link task, or a handler that never
    // returns).
    addr_of_mut!(RECORD).cast()
}

/// The record as the previous run left it (`None` after a power-up).
pub fn read_record() -> Option<BootRecord> {
    // SAFETY: any bit pattern is a valid `[u32; N]`; decode checks it.
    BootRecord::decode(&unsafe { core::ptr::read_volatile(record_ptr()) })
}

/// The server's way to the record.
pub struct RecordRam;

impl ResetRecord for RecordRam {
    fn write(&mut self, words: [u32; RECORD_WORDS]) {
        // SAFETY: see `record_ptr`.
        unsafe { core::ptr::write_volatile(record_ptr(), words) }
    }
}

fn record_fault_and_reset(fault: Fault) -> ! {
    // SAFETY: see `record_ptr`; nothing else runs after this.
    let mut w = unsafe { core::ptr::read_volatile(record_ptr()) };
    BootRecord::record_fault(&mut w, fault);
    unsafe { core::ptr::write_volatile(record_ptr(), w) };
    cortex_m::peripheral::SCB::sys_reset()
}

/// RCC_CSR (RM0090 §7.3.21): RCC at 0x4002_3800, CSR at offset 0x74.
/// (embassy-stm32 keeps its PAC private; this is the one register read
/// here.)
const RCC_CSR: *mut u32 = 0x4002_3874 as *mut u32;
/// RCC_CSR bits: remove flags, brown-out, power-on, independent watchdog.
const RMVF: u32 = 1 << 24;
const BORRSTF: u32 = 1 << 25;
const PORRSTF: u32 = 1 << 27;
const IWDGRSTF: u32 = 1 << 29;

/// Why the board started, from RCC_CSR (flags cleared after reading, so
/// the next reset reports only itself).
pub fn reset_cause() -> ResetCause {
    // SAFETY: RCC_CSR is a device register, readable and writable at any
    // time; setting RMVF only clears the reset flags.
    let csr = unsafe { core::ptr::read_volatile(RCC_CSR) };
    unsafe { core::ptr::write_volatile(RCC_CSR, csr | RMVF) };
    if csr & (PORRSTF | BORRSTF) != 0 {
        ResetCause::PowerOn
    } else if csr & IWDGRSTF != 0 {
        ResetCause::Watchdog
    } else {
        ResetCause::Other
    }
}

/// Set by the first panic: a panic inside the logger (or while logging
/// the panic) resets without logging again.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    record_fault_and_reset(Fault::Panic)
}

/// The HardFault handler, entered through trueaxis_stack_guard's entry on
/// a fresh stack (so a stack overflow, which left the stack pointer below
/// RAM, gets here too instead of locking the core up); `_sp` is the stack
/// pointer at the fault.
#[unsafe(no_mangle)]
extern "C" fn trueaxis_hard_fault(_sp: u32) -> ! {
    record_fault_and_reset(Fault::HardFault)
}
