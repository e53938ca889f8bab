//! Links with the repository's memory.x and encodes the benchmark table
//! (the simulated board's sample table: polynomials, reversal, thermal)
//! into OUT_DIR.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../memory.x");
    fs::copy(&memory_x, out.join("memory.x")).unwrap();
    fs::write(out.join("sample.bin"), trueaxis_app::sim::sample_table(0)).unwrap();
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
