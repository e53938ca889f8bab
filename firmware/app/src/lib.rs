//! The firmware's application core: hardware-agnostic, generic over traits,
//! so the same code runs on the board, in QEMU and in host tests with fakes.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
