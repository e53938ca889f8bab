//! Puts the repository's memory.x (the one memory map) on the linker path,
//! and turns its TABLE_A / TABLE_B regions into Rust constants
//! (`$OUT_DIR/slots.rs`) so the table store uses the very addresses the
//! linker reserves — nothing is written down twice.
use std::{env, fs, path::PathBuf};

/// ORIGIN and LENGTH of `region` in a memory.x `MEMORY { … }` block.
fn region(memory_x: &str, region: &str) -> (u32, u32) {
    let line = memory_x
        .lines()
        .map(str::trim)
        .find(|l| l.split(|c: char| c.is_whitespace() || c == ':').next() == Some(region))
        .unwrap_or_else(|| panic!("memory.x has no {region} region"));
    let field = |name: &str| -> u32 {
        let rest = line
            .split(name)
            .nth(1)
            .unwrap_or_else(|| panic!("{region}: no {name}"));
        let v = rest.trim_start().trim_start_matches('=').trim_start();
        let tok: String = v
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        if let Some(hex) = tok.strip_prefix("0x").or_else(|| tok.strip_prefix("0X")) {
            u32::from_str_radix(hex, 16).unwrap()
        } else if let Some(k) = tok.strip_suffix('K') {
            k.parse::<u32>().unwrap() * 1024
        } else if let Some(m) = tok.strip_suffix('M') {
            m.parse::<u32>().unwrap() * 1024 * 1024
        } else {
            tok.parse().unwrap()
        }
    };
    (field("ORIGIN"), field("LENGTH"))
}

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../memory.x");
    fs::copy(&memory_x, out.join("memory.x")).unwrap();
    let text = fs::read_to_string(&memory_x).unwrap();
    let (flash, _) = region(&text, "FLASH");
    let (a, a_len) = region(&text, "TABLE_A");
    let (b, b_len) = region(&text, "TABLE_B");
    assert_eq!(a_len, b_len, "TABLE_A and TABLE_B must have the same size");
    fs::write(
        out.join("slots.rs"),
        format!(
            "/// Start of flash (memory.x FLASH ORIGIN).\n\
             pub const FLASH_BASE: u32 = {flash:#010x};\n\
             /// TABLE_A origin (memory.x).\n\
             pub const TABLE_A: u32 = {a:#010x};\n\
             /// TABLE_B origin (memory.x).\n\
             pub const TABLE_B: u32 = {b:#010x};\n\
             /// Size of each slot (memory.x).\n\
             pub const SLOT_BYTES: u32 = {a_len:#x};\n"
        ),
    )
    .unwrap();
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
