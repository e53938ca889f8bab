//! Puts the repository's memory.x (the one memory map, also QEMU's: the
//! netduinoplus2 machine models the STM32F405's 1 MiB flash at 0x0800_0000 and
//! its SRAM at 0x2000_0000) on the linker path, with the RAM region set to
//! QEMU's 192 KiB SRAM and moved up to make room for the stack below it
//! (see qemu.x and `flip_ram`), links every image, test
//! suite included, with cortex-m-rt's and defmt's linker scripts and
//! qemu.x (the stack below the statics, so an overflow faults), and
//! encodes the bench tables (build/tables.rs) into OUT_DIR for the bench
//! image and the model-core suite to `include_bytes!`, with the host's
//! evaluation of each on seeded inputs (`<name>.vectors`, records of
//! `tables::RECORD_WORDS` little-endian i32).
use std::{env, fs, path::PathBuf};

#[path = "build/tables.rs"]
#[allow(dead_code)] // shared with the e2e runner, which uses other parts
mod tables;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../memory.x");
    let map = fs::read_to_string(&memory_x).expect("read ../memory.x");
    fs::write(out.join("memory.x"), flip_ram(&map)).expect("write memory.x into OUT_DIR");
    let qemu_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("qemu.x");
    fs::copy(&qemu_x, out.join("qemu.x")).expect("copy qemu.x into OUT_DIR");
    println!("cargo:rerun-if-changed={}", qemu_x.display());
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=build/tables.rs");
    // `rustc-link-arg` (not `-bins`) so the defmt-test suites get them too.
    println!("cargo:rustc-link-arg=-Tlink.x");
    println!("cargo:rustc-link-arg=-Tdefmt.x");
    println!("cargo:rustc-link-arg=--nmagic");
    println!("cargo:rustc-link-arg=-Tqemu.x");

    type Build = fn(u64) -> Result<Vec<u8>, model_core::EncodeError>;
    let benches: [(&str, Build); 3] = [
        ("cubic19", tables::cubic19),
        ("full", tables::full),
        ("nn_3x16x3", tables::nn_3x16x3),
    ];
    for (name, build) in benches {
        let bytes = build(0x7E57_AB1E).unwrap_or_else(|e| panic!("bench table {name}: {e}"));
        // The host's evaluation of the same table on seeded inputs: the
        // on-target suite must reproduce it (fixed point bit for bit).
        let table = model_core::parse(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let model =
            Box::new(model_core::Model::load(&table).unwrap_or_else(|e| panic!("{name}: {e:?}")));
        let mut vectors = Vec::new();
        for inp in tables::vector_inputs(0x5EED_0000 + name.len() as u64, 200) {
            for w in tables::vector_record(&model, &inp) {
                vectors.extend_from_slice(&w.to_le_bytes());
            }
        }
        fs::write(out.join(format!("{name}.bin")), &bytes).expect("write a bench table");
        fs::write(out.join(format!("{name}.vectors")), vectors).expect("write vectors");
    }
}

/// QEMU's netduinoplus2 maps 192 KiB of SRAM contiguously at 0x2000_0000
/// (QEMU 7.2 `stm32f405_soc`: the real chip's 112 + 16 KiB SRAM plus the
/// 64 KiB CCM lumped together; the CCM address 0x1000_0000 is not mapped).
/// This is where the QEMU map differs from the real one.
const QEMU_SRAM: u32 = 192 * 1024;

/// Stack size of the QEMU images, bytes. Generous on purpose: model-core's
/// `Model::load` returns a 26 KiB model by value, and the app's
/// `model::load_into` frame measured 81 408 bytes in release — more than the
/// real chip could give it (reported; the images here test logic, not RAM
/// fit).
const QEMU_STACK: u32 = 112 * 1024;

/// The root memory map with its RAM region replaced by QEMU's SRAM minus
/// the stack, which goes below it (qemu.x). Everything else (flash, table
/// slots) is the root map, unchanged.
fn flip_ram(map: &str) -> String {
    let mut found = false;
    let mut out = String::new();
    for line in map.lines() {
        let t = line.trim_start();
        if t.starts_with("RAM ") || t.starts_with("RAM:") {
            // "RAM : ORIGIN = 0x20000000, LENGTH = 128K"
            let origin = t
                .split("ORIGIN")
                .nth(1)
                .and_then(|r| r.split(',').next())
                .map(|r| r.trim_start_matches([' ', '=']).trim().to_owned())
                .expect("memory.x: RAM line without ORIGIN");
            assert_eq!(
                origin, "0x20000000",
                "memory.x: RAM is not where QEMU's SRAM is"
            );
            out.push_str(&format!(
                "  RAM : ORIGIN = {origin} + {QEMU_STACK}, LENGTH = {QEMU_SRAM} - {QEMU_STACK}\n"
            ));
            found = true;
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    assert!(found, "memory.x has no RAM region to flip");
    out.push_str(&format!("QEMU_STACK = {QEMU_STACK};\n"));
    out
}
