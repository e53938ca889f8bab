//! Puts the repository's memory.x (the one memory map, also QEMU's: the
//! netduinoplus2 machine models the STM32F405's 1 MiB flash at 0x0800_0000 and
//! its SRAM at 0x2000_0000) on the linker path, and links every image, test
//! suite included, with cortex-m-rt's and defmt's linker scripts.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../memory.x");
    fs::copy(&memory_x, out.join("memory.x")).expect("copy ../memory.x into OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    // `rustc-link-arg` (not `-bins`) so the defmt-test suites get them too.
    println!("cargo:rustc-link-arg=-Tlink.x");
    println!("cargo:rustc-link-arg=-Tdefmt.x");
    println!("cargo:rustc-link-arg=--nmagic");
}
