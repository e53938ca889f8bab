//! QEMU support linked into every image of this crate (defmt-test suites, the
//! bench image, the end-to-end board image) running on `qemu-system-arm -M
//! netduinoplus2` (an STM32F405): the defmt logger over semihosting, exits
//! through semihosting so QEMU's exit status is the test verdict (0 pass,
//! 1 panic or fault), and an instruction counter.
//!
//! Why these choices: QEMU has no debug probe to notice a breakpoint or a
//! lockup, so every way an image can end must become a semihosting exit, or a
//! failure would look like a hang (xtask's timeout still catches real hangs).
#![no_std]

pub mod executor;
pub mod icount;
pub mod tim2;
pub mod time_driver;
pub mod usart;

use defmt_semihosting as _;
use trueaxis_stack_guard as _;

/// Ends the emulation with `code` as QEMU's exit status.
pub fn exit(code: i32) -> ! {
    semihosting::process::exit(code)
}

/// Which fault reached a handler (for [`set_fault_hook`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum FaultKind {
    /// The panic handler.
    Panic,
    /// The HardFault handler.
    HardFault,
}

/// What a panic or a HardFault does instead of exiting 1.
pub type FaultHook = fn(FaultKind) -> !;

/// The hook, when set.
static FAULT_HOOK: critical_section::Mutex<core::cell::Cell<Option<FaultHook>>> =
    critical_section::Mutex::new(core::cell::Cell::new(None));

/// Makes a panic or HardFault call `hook` instead of ending the run with
/// exit 1: the boot-fallback image (bin/fallback.rs) records the fault and
/// resets, as the board does. Every other image keeps "a fault fails".
pub fn set_fault_hook(hook: FaultHook) {
    critical_section::with(|cs| FAULT_HOOK.borrow(cs).set(Some(hook)));
}

fn fault_hook() -> Option<FaultHook> {
    critical_section::with(|cs| FAULT_HOOK.borrow(cs).get())
}

/// A panic is a failed test: log it (defmt-print shows it) and exit 1.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Print the location through defmt's Display2Format; the message itself
    // is formatted by core::fmt, which is fine on a failure path.
    defmt::error!("panicked: {}", defmt::Display2Format(info));
    if let Some(hook) = fault_hook() {
        hook(FaultKind::Panic)
    }
    exit(1)
}

// A fault must not hang QEMU: report the faulting PC and exit 1. defmt is not
// used here because the fault may have hit inside the logger's critical
// section (it would then panic re-entrantly); the semihosting stderr stream
// is separate from the defmt frames on stdout. Entered through
// trueaxis_stack_guard's HardFault entry (the board's), which moves to a
// fresh stack first: a stack overflow gets here too — its exception frame
// could not be pushed, so `sp` (the stack pointer at the fault) is below
// RAM and the report says so.
#[allow(unsafe_code)] // the symbol the fault entry branches to
#[unsafe(no_mangle)]
extern "C" fn trueaxis_hard_fault(sp: u32) -> ! {
    use core::fmt::Write as _;
    if let Some(hook) = fault_hook() {
        hook(FaultKind::HardFault)
    }
    let readable = (0x2000_0000..0x2002_0000 - 32).contains(&sp);
    if let Ok(mut err) = semihosting::io::stderr() {
        let mut w = FmtAdapter(&mut err);
        let _ = if readable {
            // SAFETY: the exception frame's eight words are in RAM (checked
            // above); pc and lr are its words 6 and 5.
            #[allow(unsafe_code)]
            let (pc, lr) = unsafe {
                let f = sp as *const u32;
                (f.add(6).read_volatile(), f.add(5).read_volatile())
            };
            writeln!(w, "HardFault: pc={pc:#010x} lr={lr:#010x}")
        } else {
            writeln!(
                w,
                "HardFault: stack overflow (stack pointer {sp:#010x} below RAM)"
            )
        };
    }
    exit(1)
}

/// Adapts a semihosting writer to `core::fmt::Write`.
struct FmtAdapter<'a, W>(&'a mut W);

impl<W: semihosting::io::Write> core::fmt::Write for FmtAdapter<'_, W> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.0.write_all(s.as_bytes()).map_err(|_| core::fmt::Error)
    }
}
