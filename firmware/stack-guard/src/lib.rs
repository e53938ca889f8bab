//! The board's stack-overflow guard (issue 25), shared by the board binary
//! and the QEMU images that test it.
//!
//! **Layout** (memory.x): the stack sits at the *bottom* of SRAM, from
//! `_stack_start` down to 0x2000_0000, and the statics (the two models, the
//! staging buffer, the boot record in `.uninit`) above it — flip-link's
//! layout. Growing down, the stack runs out of RAM instead of into the
//! statics: cortex-m-rt's default layout (stack at the top, growing down
//! into `.uninit`) let an overflow overwrite the boot record and carry on.
//!
//! **Guard** ([`enable`]): below SRAM the F405 has the reserved space up
//! from its option bytes (0x1FFF_C010 …) and, further down, its system
//! memory; whether every write there faults is the bus's business, so an
//! MPU region makes the 32 KiB below SRAM (0x1FFF_8000 … 0x1FFF_FFFF:
//! option bytes and reserved space — not the system memory, OTP or the
//! unique ID at 0x1FFF_7A10, which nothing may find locked) no-access. Any
//! stack frame up to 32 KiB that runs off the stack's end faults there
//! (the board's largest frame is far below that: docs/firmware.md).
//!
//! **HardFault entry** ([`global_asm!`] below, the vector table's
//! `HardFault`): a stack overflow faults while pushing, and the exception
//! frame cannot be pushed either; the handler then starts with the stack
//! pointer still outside RAM, and cortex-m-rt's trampoline, whose Rust
//! handler pushes registers first, locks the core up (QEMU reports a
//! lockup; the chip stops until the watchdog resets it, the boot record
//! telling nothing). This entry first puts MSP back at `_stack_start` (the
//! stack's top — the fault handler never returns, so nothing on the old
//! stack is needed) and then calls `trueaxis_hard_fault(sp)`, with `sp`
//! the stack pointer at the fault (for a report), which the binary
//! defines: the board records the fault in the boot record and resets
//! (firmware/board/src/reset.rs), QEMU images report and exit.
#![no_std]
#![allow(unsafe_code)] // MPU registers and the fault entry's assembly

/// Base of the guard region: 32 KiB below SRAM (0x2000_0000).
pub const GUARD_BASE: u32 = 0x1FFF_8000;
/// Size of the guard region, bytes (a power of two, `GUARD_BASE` aligned
/// to it, as the Cortex-M4 MPU requires).
pub const GUARD_BYTES: u32 = 32 * 1024;

// MPU_RASR fields (ARMv7-M ARM B3.5.9): region enable, SIZE (2^(SIZE+1)
// bytes), AP = 0b000 (no access, privileged or not), XN.
const RASR_ENABLE: u32 = 1;
const RASR_SIZE_SHIFT: u32 = 1;
const RASR_XN: u32 = 1 << 28;
// MPU_CTRL: enable, and the default memory map for everything else in
// privileged code (PRIVDEFENA); HFNMIENA clear: the MPU is off while the
// HardFault handler runs.
const CTRL_ENABLE: u32 = 1;
const CTRL_PRIVDEFENA: u32 = 1 << 2;

/// The MPU_RASR word of the guard region.
pub const fn guard_rasr() -> u32 {
    // log2(GUARD_BYTES) − 1.
    let size = 31 - GUARD_BYTES.leading_zeros() - 1;
    RASR_ENABLE | (size << RASR_SIZE_SHIFT) | RASR_XN
}

const _: () = assert!(GUARD_BYTES.is_power_of_two() && GUARD_BASE.is_multiple_of(GUARD_BYTES));
const _: () = assert!(GUARD_BASE + GUARD_BYTES == 0x2000_0000);

/// Makes the [`GUARD_BYTES`] below SRAM a no-access MPU region (region 0),
/// everything else the default memory map. Call first thing in `main`.
pub fn enable() {
    // SAFETY: the MPU is only configured here, once, before anything runs
    // that could be affected; the barriers make the new map apply to the
    // next access.
    unsafe {
        let mpu = &*cortex_m::peripheral::MPU::PTR;
        mpu.ctrl.write(0);
        mpu.rnr.write(0);
        mpu.rbar.write(GUARD_BASE);
        mpu.rasr.write(guard_rasr());
        mpu.ctrl.write(CTRL_ENABLE | CTRL_PRIVDEFENA);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

// The vector table's HardFault (cortex-m-rt's link.x provides a default
// only when no `HardFault` symbol exists). r0 = the stack pointer at the
// fault (MSP or PSP, by EXC_RETURN's bit 2), then MSP = `_stack_start`.
// Kept in `.HardFault.*`, which link.x places next to the vector table.
#[cfg(target_os = "none")]
core::arch::global_asm!(
    ".section .HardFault.trueaxis_stack_guard, \"ax\"",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "mov r0, lr",
    "movs r1, #4",
    "tst r0, r1",
    "mrs r0, MSP",
    "beq 0f",
    "mrs r0, PSP",
    "0:",
    "ldr r1, =_stack_start",
    "msr MSP, r1",
    "isb",
    "b trueaxis_hard_fault",
    ".ltorg",
    ".size HardFault, . - HardFault",
);
