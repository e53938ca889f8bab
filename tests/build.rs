//! Puts the repository's memory.x (the one memory map, also QEMU's: the
//! netduinoplus2 machine models the STM32F405's 1 MiB flash at 0x0800_0000 and
//! its SRAM at 0x2000_0000) on the linker path, with the RAM region set to
//! QEMU's 192 KiB SRAM and moved up to make room for the stack below it
//! (see qemu.x and `flip_ram`), links every image, test
//! suite included, with cortex-m-rt's and defmt's linker scripts and
//! qemu.x (the stack below the statics, so an overflow faults), and
//! encodes the bench tables (build/tables.rs, and golden/rigid21.bin: the
//! engine's export of a fitted rigid21 model, copied) into OUT_DIR for the bench
//! image (with its table list, `bench_tables.rs`) and the model-core suite
//! to `include_bytes!`, with the host's
//! evaluation of each on seeded inputs (`<name>.vectors`, records of
//! `tables::RECORD_WORDS` little-endian i32).
use std::io::Write;
use std::process::{Command, Stdio};
use std::{env, fs, path::PathBuf};

#[path = "build/tables.rs"]
#[allow(dead_code)] // shared with the e2e runner, which uses other parts
mod tables;

#[path = "build/cost_tables.rs"]
mod cost_tables;

#[path = "build/random.rs"]
mod random;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../memory.x");
    let map = fs::read_to_string(&memory_x).expect("read ../memory.x");
    fs::write(out.join("memory.x"), flip_ram(&map, qemu_ram()))
        .expect("write memory.x into OUT_DIR");
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
    let mut tables: Vec<(&str, Vec<u8>)> = benches
        .iter()
        .map(|&(name, build)| {
            let bytes = build(0x7E57_AB1E).unwrap_or_else(|e| panic!("bench table {name}: {e}"));
            (name, bytes)
        })
        .collect();
    // The engine's export of a fitted rigid21:4 model (issue 26), checked
    // in: host-tool/engine/tests/rigid21_board_table.rs writes it and
    // requires today's export to equal it.
    let rigid21 = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden/rigid21.bin");
    println!("cargo:rerun-if-changed={}", rigid21.display());
    tables.push((
        "rigid21",
        fs::read(&rigid21).unwrap_or_else(|e| panic!("{}: {e}", rigid21.display())),
    ));
    for (name, bytes) in &tables {
        let (name, bytes) = (*name, bytes.as_slice());
        // The host's evaluation of the same table on seeded inputs: the
        // on-target suite must reproduce it (fixed point bit for bit).
        let table = model_core::parse(bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let model =
            Box::new(model_core::Model::load(&table).unwrap_or_else(|e| panic!("{name}: {e:?}")));
        let mut vectors = Vec::new();
        for inp in tables::vector_inputs(tables::vector_seed(name), 200) {
            for w in tables::vector_record(&model, &inp) {
                vectors.extend_from_slice(&w.to_le_bytes());
            }
        }
        fs::write(out.join(format!("{name}.bin")), bytes).expect("write a bench table");
        fs::write(out.join(format!("{name}.vectors")), vectors).expect("write vectors");
    }
    bench_list(
        &out,
        &tables.iter().map(|(name, _)| *name).collect::<Vec<_>>(),
    );
    // The safety suite's table that the board must refuse (issue 25).
    let off = tables::off_definition(0x0FFD_EF00).unwrap_or_else(|e| panic!("off_definition: {e}"));
    fs::write(out.join("off_definition.bin"), off).expect("write off_definition.bin");
    random::write(&out);
}

/// The bench image's table list (`bench_tables.rs` in OUT_DIR): the three
/// tables of build/tables.rs and the engine's rigid21 export
/// (golden/rigid21.bin; the bench names of docs/qemu.md, "Instruction counts"), two checked-in golden
/// tables of model-core (`grid_17x11`; `all_kinds`, every term kind in one
/// table: the worst realistic case), and build/cost_tables.rs (one table
/// per evaluation path, for the check of model-core's cost estimate). With
/// the package's `calibrate` feature (`cargo xtask bench-mcu --calibrate`)
/// also the cost estimate's calibration set, `cost_tables::calibration`.
fn bench_list(out: &std::path::Path, contract: &[&str]) {
    let mut names: Vec<String> = contract.iter().map(|s| s.to_string()).collect();
    let golden = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../model-core/tests/golden");
    for name in ["grid_17x11", "all_kinds"] {
        let src = golden.join(format!("{name}.bin"));
        println!("cargo:rerun-if-changed={}", src.display());
        fs::copy(&src, out.join(format!("{name}.bin"))).expect("copy a golden table");
        names.push(name.into());
    }
    println!("cargo:rerun-if-changed=build/cost_tables.rs");
    for (name, bytes) in cost_tables::all().unwrap_or_else(|e| panic!("cost tables: {e}")) {
        fs::write(out.join(format!("{name}.bin")), bytes).expect("write a cost table");
        names.push(name.into());
    }
    if env::var_os("CARGO_FEATURE_CALIBRATE").is_some() {
        for (name, bytes) in
            cost_tables::calibration().unwrap_or_else(|e| panic!("calibration tables: {e}"))
        {
            fs::write(out.join(format!("{name}.bin")), bytes).expect("write a calibration table");
            names.push(name);
        }
    }
    let mut rs = String::from(
        "/// (name, table) of every bench table, generated by build.rs.\n\
         pub static BENCH_TABLES: &[(&str, &[u8])] = &[\n",
    );
    for n in &names {
        rs.push_str(&format!(
            "    (\"{n}\", include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{n}.bin\"))),\n"
        ));
    }
    rs.push_str("];\n");
    fs::write(out.join("bench_tables.rs"), rs).expect("write bench_tables.rs");
}

/// How the `qemu-system-arm` the images run on maps RAM for netduinoplus2.
/// Measured with `info mtree`: QEMU 7.2 (Debian bookworm) maps 192 KiB of
/// SRAM contiguously at 0x2000_0000 (the real chip's 112 + 16 KiB SRAM and
/// its 64 KiB CCM lumped together) and nothing at 0x1000_0000; QEMU 10.0
/// (bookworm-backports) maps it like the chip: 128 KiB SRAM at 0x2000_0000
/// and the 64 KiB CCM at 0x1000_0000. An image linked for the 7.2 map puts
/// its statics above 128 KiB and faults on QEMU 10 while zeroing .bss.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum QemuRam {
    /// 192 KiB at 0x2000_0000 (QEMU 7.2).
    Sram192,
    /// 128 KiB SRAM at 0x2000_0000 and 64 KiB CCM at 0x1000_0000 (QEMU ≥ 8).
    SramCcm,
}

/// The RAM map of the QEMU on PATH, asked from QEMU itself (`info mtree`
/// on a stopped netduinoplus2): the map, not a version number, decides.
/// `TRUEAXIS_QEMU_RAM=sram192|ccm` overrides it. Without a QEMU the images
/// are only built (clippy), never run, and the 7.2 map is used.
fn qemu_ram() -> QemuRam {
    println!("cargo:rerun-if-env-changed=TRUEAXIS_QEMU_RAM");
    match env::var("TRUEAXIS_QEMU_RAM").as_deref() {
        Ok("sram192") => return QemuRam::Sram192,
        Ok("ccm") => return QemuRam::SramCcm,
        Ok(other) => panic!("TRUEAXIS_QEMU_RAM={other}: expected sram192 or ccm"),
        Err(_) => {}
    }
    let Some(bin) = env::var_os("PATH").and_then(|paths| {
        env::split_paths(&paths)
            .map(|d| d.join("qemu-system-arm"))
            .find(|p| p.is_file())
    }) else {
        println!(
            "cargo:warning=no qemu-system-arm on PATH: QEMU images linked for QEMU 7.2's RAM map"
        );
        return QemuRam::Sram192;
    };
    // Another QEMU first on PATH, or a new one in place (apt): probe again.
    println!("cargo:rerun-if-env-changed=PATH");
    println!("cargo:rerun-if-changed={}", bin.display());
    let mut child = Command::new(&bin)
        .args(["-M", "netduinoplus2", "-S", "-nographic", "-serial", "null"])
        .args(["-monitor", "stdio"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("start {}: {e}", bin.display()));
    child
        .stdin
        .take()
        .expect("piped stdin")
        .write_all(b"info mtree\nquit\n")
        .expect("write to the QEMU monitor");
    let out = child.wait_with_output().expect("QEMU monitor output");
    let mtree = String::from_utf8_lossy(&out.stdout);
    if mtree.contains("STM32F405.ccm") {
        QemuRam::SramCcm
    } else if mtree.contains("0000000020000000-000000002002ffff") {
        QemuRam::Sram192
    } else {
        panic!(
            "{}: unknown netduinoplus2 RAM map (set TRUEAXIS_QEMU_RAM=sram192|ccm):\n{mtree}",
            bin.display()
        )
    }
}

/// Stack size of the QEMU images, bytes. Generous on purpose: model-core's
/// `Model::load` returns a 26 KiB model by value, and the app's
/// `model::load_into` frame measured 81 408 bytes in release — more than the
/// real chip could give it (reported; the images here test logic, not RAM
/// fit). 72 KiB overflows in the app and model_core suites (measured).
const QEMU_STACK_SRAM192: u32 = 112 * 1024;

/// The root memory map with its RAM region replaced by where QEMU lets the
/// statics live, and the stack placed so that it grows down into unmapped
/// memory (qemu.x): a stack overflow faults at once instead of silently
/// running into the statics. Everything else (flash, table slots) is the
/// root map, unchanged.
/// - 7.2 map: stack 0x2000_0000..+112 KiB, statics the 80 KiB above it.
/// - chip-like map: stack the whole 128 KiB SRAM, statics in the 64 KiB CCM
///   (nothing in these images uses DMA, which could not reach the CCM).
fn flip_ram(map: &str, ram: QemuRam) -> String {
    let mut found = false;
    let mut out = String::new();
    for line in map.lines() {
        let t = line.trim_start();
        if t.starts_with("RAM ") || t.starts_with("RAM:") {
            // "RAM : ORIGIN = 0x2000A000, LENGTH = 88K": the board's statics,
            // above its STACK region; both inside QEMU's SRAM.
            let origin = t
                .split("ORIGIN")
                .nth(1)
                .and_then(|r| r.split(',').next())
                .map(|r| r.trim_start_matches([' ', '=']).trim().to_owned())
                .expect("memory.x: RAM line without ORIGIN");
            assert!(
                origin.starts_with("0x2000"),
                "memory.x: RAM {origin} is not where QEMU's SRAM is"
            );
            out.push_str(&match ram {
                QemuRam::Sram192 => format!(
                    "  RAM : ORIGIN = 0x20000000 + {QEMU_STACK_SRAM192}, LENGTH = {} - {QEMU_STACK_SRAM192}\n",
                    192 * 1024
                ),
                QemuRam::SramCcm => "  RAM : ORIGIN = 0x10000000, LENGTH = 64K\n".to_string(),
            });
            found = true;
        } else if (t.starts_with("CCMRAM ") || t.starts_with("CCMRAM:")) && ram == QemuRam::SramCcm
        {
            // The statics take the CCM; no second region may overlap it.
        } else if t.starts_with("STACK ")
            || t.starts_with("STACK:")
            || t.starts_with("_stack_start")
            || t.starts_with("_stack_end")
        {
            // The board's stack region and its symbols: the QEMU images
            // place their (larger) stack themselves (qemu.x), the same way.
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    assert!(found, "memory.x has no RAM region to flip");
    let (top, size) = match ram {
        QemuRam::Sram192 => (0x2000_0000 + QEMU_STACK_SRAM192, QEMU_STACK_SRAM192),
        QemuRam::SramCcm => (0x2000_0000 + 128 * 1024, 128 * 1024),
    };
    out.push_str(&format!(
        "QEMU_STACK_TOP = {top:#010x};\nQEMU_STACK = {size};\n"
    ));
    out
}
