//! A stack overflow faults instead of corrupting the boot record (issue
//! 25), on the emulated STM32F405 with the board's guard
//! (trueaxis_stack_guard: the stack below the statics, an MPU no-access
//! region below SRAM, a HardFault entry that moves to a fresh stack).
//!
//! 1. cold boot: a table is on trial in the `.uninit` boot record (as the
//!    link server writes it before the table's first tick), a canary fills
//!    the `.uninit` words next to it, the guard is enabled, and a
//!    recursion with 1 KiB frames runs the stack out of SRAM. The fault
//!    reaches the HardFault handler (not a lockup: its entry left the
//!    overflowed stack), which records `HardFault` in the boot record and
//!    resets, as the board's does (firmware/board/src/reset.rs);
//! 2. the next boot finds the record whole — magic and check word, the
//!    table, the fault — and the canary untouched, and
//!    `boot::failed_trial` says the table on trial failed with a
//!    HardFault (the boot would fall back to the previous table). Exit 0.
//!
//! Without the guard entry the overflow locked the core up (the old
//! `overflow` image's verdict) and the handler never recorded anything;
//! with cortex-m-rt's default layout the stack ran into the statics.
#![no_std]
#![no_main]
#![allow(unsafe_code)] // `.uninit` statics: RAM that survives the reset

#[path = "../rig.rs"]
#[allow(dead_code)] // each image uses part of it
mod rig;

use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use rig::deeper;
use trueaxis_app::boot::{failed_trial, BootRecord, Fault, ResetCause, RECORD_WORDS};
use trueaxis_protocol::{Slot, SlotInfo};
use trueaxis_qemu::{exit, set_fault_hook, FaultKind};

/// Marks the image's own `.uninit` words as written (not a cold boot).
const MAGIC: u32 = 0x57AC_6A4D;
/// The canary's words.
const CANARY_WORDS: usize = 256;

#[unsafe(link_section = ".uninit.stack_guard_record")]
static mut RECORD: MaybeUninit<[u32; RECORD_WORDS]> = MaybeUninit::uninit();
#[unsafe(link_section = ".uninit.stack_guard_canary")]
static mut CANARY: MaybeUninit<[u32; CANARY_WORDS]> = MaybeUninit::uninit();
/// [MAGIC, boot number].
#[unsafe(link_section = ".uninit.stack_guard_step")]
static mut STEP: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

/// The table on trial when the stack overflows.
const ON_TRIAL: SlotInfo = SlotInfo {
    slot: Slot::B,
    seq: 7,
    len: 1234,
    crc32: 0xC0FF_EE00,
};

fn record_ptr() -> *mut [u32; RECORD_WORDS] {
    addr_of_mut!(RECORD).cast()
}

fn canary_ptr() -> *mut [u32; CANARY_WORDS] {
    addr_of_mut!(CANARY).cast()
}

fn step_ptr() -> *mut [u32; 2] {
    addr_of_mut!(STEP).cast()
}

fn canary(i: usize) -> u32 {
    0xA5A5_0000 ^ (i as u32).wrapping_mul(0x9E37_79B9)
}

/// The board's fault handlers: record the fault, reset.
fn record_and_reset(kind: FaultKind) -> ! {
    // SAFETY: single-threaded, volatile; nothing runs after this.
    unsafe { rig::record_and_reset(record_ptr(), "stack_guard", kind) }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    trueaxis_stack_guard::enable();
    // SAFETY: single-threaded; the `.uninit` words are plain integers.
    let step = unsafe { read_volatile(step_ptr()) };
    let boot = if step[0] == MAGIC { step[1] } else { 0 };
    unsafe { write_volatile(step_ptr(), [MAGIC, boot + 1]) };
    match boot {
        0 => {
            unsafe {
                write_volatile(record_ptr(), BootRecord::trial(Some(ON_TRIAL)).encode());
                write_volatile(canary_ptr(), core::array::from_fn(canary));
            }
            set_fault_hook(record_and_reset);
            defmt::info!("stack_guard: a table on trial; recursing until the stack overflows");
            let n = deeper(0);
            defmt::error!("the recursion returned ({}): the stack never overflowed", n);
            exit(1)
        }
        1 => {
            let record = BootRecord::decode(unsafe { &read_volatile(record_ptr()) });
            defmt::assert_eq!(
                record,
                Some(BootRecord {
                    table: Some(ON_TRIAL),
                    confirmed: false,
                    fault: Some(Fault::HardFault),
                }),
                "the boot record is not what the fault handler left"
            );
            let words = unsafe { read_volatile(canary_ptr()) };
            let bad = (0..CANARY_WORDS).filter(|&i| words[i] != canary(i)).count();
            defmt::assert_eq!(bad, 0, "{} canary words overwritten", bad);
            let failed = failed_trial(record, ResetCause::Other, Some(ON_TRIAL));
            defmt::assert_eq!(failed.map(|f| f.fault), Some(Fault::HardFault));
            defmt::info!(
                "a stack overflow faulted: the boot record kept its table and the HardFault, the trial failed"
            );
            exit(0)
        }
        n => {
            defmt::error!("stack_guard: unexpected boot {}", n);
            exit(1)
        }
    }
}
