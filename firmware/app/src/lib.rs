//! The firmware's application core: hardware-agnostic, generic over traits,
//! so the same code runs on the board, in QEMU and in host tests with fakes.
//!
//! - [`engine`]: the fixed-rate correction (sensors → model → envelope →
//!   slew limit → step pulses, faults ramp to zero).
//! - [`boot`]: the boot fallback (a table on trial until it has run
//!   without a fault reset; a failed trial falls back to the other slot).
//! - [`store`]: the A/B table slots in NOR flash, power-cut safe.
//! - [`server`]: the link server (bytes in, bytes out) for upload, commit,
//!   activate, rollback, status and injection.
//! - [`hw`]: the traits the board implements; [`memflash`]: a RAM-backed
//!   NOR flash that can lose power, for tests and emulators.
//! - [`sensors`]: encoder counter widening, thermistor conversion.
//! - [`model`]: the adapter to model-core's evaluation.
//! - `sim` (feature `std`): the simulated board served over TCP, for the
//!   host tool's end-to-end tests.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod boot;
pub mod engine;
pub mod hw;
pub mod memflash;
pub mod model;
pub mod sensors;
pub mod server;
#[cfg(feature = "std")]
pub mod sim;
pub mod store;

/// This firmware's version (major, minor, patch), from Cargo.toml.
pub const FIRMWARE_VERSION: [u16; 3] = [
    parse_u16(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_u16(env!("CARGO_PKG_VERSION_MINOR")),
    parse_u16(env!("CARGO_PKG_VERSION_PATCH")),
];

const fn parse_u16(s: &str) -> u16 {
    let b = s.as_bytes();
    let mut v: u16 = 0;
    let mut i = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u16;
        i += 1;
    }
    v
}
