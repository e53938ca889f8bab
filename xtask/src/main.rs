//! `cargo xtask …` — the repository's tasks (README.md, "Two commands";
//! `bench-mcu`'s output in docs/qemu.md, "Instruction counts").
//!
//! `setup` installs what a fresh machine lacks, `test` runs every check CI
//! runs, `demo` runs the main job end to end, `bench-mcu` counts instructions
//! under QEMU. Kept dependency-free on purpose: it is the first thing a fresh
//! clone compiles, and it must work before anything else is installed.

mod browser;
mod qemu;

use std::env;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// The target the MCU code is built for (STM32F405, Cortex-M4F).
pub const THUMB: &str = "thumbv7em-none-eabihf";

type Result<T> = std::result::Result<T, String>;

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let (cmd, rest) = match args.split_first() {
        Some((c, r)) => (c.as_str(), r),
        None => {
            eprintln!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    let result = match cmd {
        "setup" => setup(),
        "test" => test(rest),
        "demo" => demo(rest),
        "bench-mcu" => setup().and_then(|()| qemu::bench_mcu(rest)),
        "test-qemu" => setup().and_then(|()| qemu::test_all()),
        "test-browser" => setup().and_then(|()| browser::test(rest)),
        "-h" | "--help" | "help" => {
            println!("{USAGE}");
            Ok(())
        }
        other => {
            eprintln!("unknown task `{other}`\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

const USAGE: &str = "usage: cargo xtask <task>

tasks:
  setup       install what is missing (thumb target, qemu-system-arm, defmt-print,
              chromium)
  test        every test: fmt, clippy, host tests, no_std build, firmware, QEMU
  demo        the main job, end to end (writes into out/demo)
  test-qemu   only the QEMU suites and the end-to-end run (part of `test`)
  test-browser  every kind of report page (the demo's, ISO 230-2, on-machine, a
              bed) in headless Chromium at 1280 and 390 px: a viewport,
              figures drawn, nothing wider than the window, verdict first,
              weight and layout time within limits; screenshots in
              out/screens (part of `test`); --pages DIR checks pages already
              written to DIR (an earlier run's, or a demo's --out folder)
  bench-mcu   instruction counts per model update under QEMU (-icount shift=0);
              --calibrate: model-core's cost estimate against the counts of
              the bench tables and 191 seeded random ones (BENCHMARKS.md)";

/// The repository root (the parent of xtask/).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives one level below the root")
        .to_path_buf()
}

/// Runs a command in `dir`, echoing it, and fails with its exit status.
pub fn run(dir: &Path, program: &str, args: &[&str]) -> Result<()> {
    run_env(dir, program, args, &[])
}

/// Like [`run`], with extra environment variables.
pub fn run_env(dir: &Path, program: &str, args: &[&str], envs: &[(&str, &str)]) -> Result<()> {
    eprintln!("\n$ {program} {}", args.join(" "));
    let status = Command::new(program)
        .args(args)
        .current_dir(dir)
        .envs(envs.iter().copied())
        .status()
        .map_err(|e| format!("cannot start `{program}`: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{program} {}` failed ({status})", args.join(" ")))
    }
}

/// True when `program --version` (or `-V`) runs.
fn have(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

/// Installs what is missing. Each step checks first, so a second run is fast.
pub fn setup() -> Result<()> {
    let root = root();
    // rust-toolchain.toml names the target, but older rustups only honour it
    // on the first toolchain install; adding it explicitly is idempotent.
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .current_dir(&root)
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !installed.lines().any(|l| l.trim() == THUMB) {
        run(&root, "rustup", &["target", "add", THUMB])?;
    }
    if !have("qemu-system-arm") {
        if !is_root() {
            return Err("qemu-system-arm is missing and this is not root: \
                 run `sudo cargo xtask setup`, or install it as docs/qemu.md \
                 (\"Which QEMU\") says"
                .into());
        }
        install_qemu(&root)?;
    }
    if !have("defmt-print") {
        run(&root, "cargo", &["install", "defmt-print", "--locked"])?;
    }
    // The browser check of the report pages needs Chromium. Without root it
    // is not installed here (the demo does not need it); `test-browser`
    // then fails naming what to run.
    if browser::chromium().is_none() {
        if is_root() {
            run(&root, "apt-get", &["update", "-q"])?;
            run_env(
                &root,
                "apt-get",
                &chromium_install_args(),
                &[("DEBIAN_FRONTEND", "noninteractive")],
            )
            .map_err(|e| {
                format!("{e}\ninstalling chromium failed; nothing was removed (--no-remove)")
            })?;
        } else {
            eprintln!(
                "note: chromium is missing and this is not root: `cargo xtask test-browser` \
                 needs it (`sudo cargo xtask setup` installs the Debian package)"
            );
        }
    }
    Ok(())
}

/// `apt-get` arguments installing Debian's `chromium` (headless use only:
/// no recommends), never removing a package.
fn chromium_install_args() -> Vec<&'static str> {
    vec![
        "install",
        "-y",
        "-q",
        "--no-remove",
        "--no-install-recommends",
        "chromium",
    ]
}

/// Where `qemu-system-arm` comes from: the release's own archive, or its
/// backports when the machine already has `qemu-utils` from there.
#[derive(Debug, PartialEq, Eq)]
enum QemuSource {
    /// The release's package (bookworm: QEMU 7.2).
    Release,
    /// `<codename>-backports` (bookworm-backports: QEMU 10.0).
    Backports(String),
}

/// Picks the source from the installed `qemu-utils` version (None when it is
/// not installed) and the release codename. A backports `qemu-utils`
/// (`…~bpo12+1`) breaks the release's `qemu-system-common`, so installing
/// bookworm's `qemu-system-arm` next to it would remove `qemu-utils` — the
/// image this runs on ships qemu-utils 10.0.2 from bookworm-backports, and
/// apt did exactly that. The backports `qemu-system-arm` keeps it.
fn qemu_source(qemu_utils_version: Option<&str>, codename: &str) -> QemuSource {
    match qemu_utils_version {
        Some(v) if v.contains("bpo") => QemuSource::Backports(format!("{codename}-backports")),
        _ => QemuSource::Release,
    }
}

/// The `apt-get` arguments that install `qemu-system-arm` from `source`.
/// `--no-remove` makes apt abort instead of removing anything to make room
/// (it never silently uninstalls a package the machine relies on).
fn qemu_install_args(source: &QemuSource) -> Vec<String> {
    let mut args: Vec<String> = ["install", "-y", "-q", "--no-remove"]
        .map(String::from)
        .to_vec();
    if let QemuSource::Backports(suite) = source {
        args.extend(["-t".to_string(), suite.clone()]);
    }
    args.extend(["--no-install-recommends", "qemu-system-arm"].map(String::from));
    args
}

/// A deb822 source for `suite` from deb.debian.org (the keyring every
/// Debian install has).
fn backports_source(suite: &str) -> String {
    format!(
        "Types: deb\nURIs: http://deb.debian.org/debian\nSuites: {suite}\n\
         Components: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n"
    )
}

/// Where setup writes the backports source when apt has none.
const BACKPORTS_LIST: &str = "/etc/apt/sources.list.d/trueaxis-backports.sources";

/// The installed version of a Debian package (None if not installed).
fn dpkg_version(package: &str) -> Option<String> {
    let out = Command::new("dpkg-query")
        .args(["-W", "-f=${Status}|${Version}", package])
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let (status, version) = text.split_once('|')?;
    (out.status.success() && status.ends_with(" installed") && !version.is_empty())
        .then(|| version.to_string())
}

/// `VERSION_CODENAME` from /etc/os-release (bookworm if absent).
fn release_codename() -> String {
    std::fs::read_to_string("/etc/os-release")
        .ok()
        .and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix("VERSION_CODENAME="))
                .map(|v| v.trim_matches('"').to_string())
        })
        .filter(|c| !c.is_empty())
        .unwrap_or_else(|| "bookworm".into())
}

/// True when some apt source already names `suite`.
fn apt_has_suite(suite: &str) -> bool {
    let mut files = vec![PathBuf::from("/etc/apt/sources.list")];
    if let Ok(dir) = std::fs::read_dir("/etc/apt/sources.list.d") {
        files.extend(
            dir.flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "list" || x == "sources")),
        );
    }
    files.iter().any(|f| {
        std::fs::read_to_string(f).is_ok_and(|t| {
            t.lines()
                .filter(|l| !l.trim_start().starts_with('#'))
                .any(|l| l.split_whitespace().any(|w| w == suite))
        })
    })
}

/// Installs `qemu-system-arm` with apt (root only), from the source that
/// keeps what is installed (see [`qemu_source`]).
fn install_qemu(root: &Path) -> Result<()> {
    let utils = dpkg_version("qemu-utils");
    let source = qemu_source(utils.as_deref(), &release_codename());
    if let QemuSource::Backports(suite) = &source {
        eprintln!(
            "qemu-utils {} is from {suite}: installing qemu-system-arm from there too",
            utils.as_deref().unwrap_or("?")
        );
        if !apt_has_suite(suite) {
            eprintln!("adding {suite} as an apt source ({BACKPORTS_LIST})");
            std::fs::write(BACKPORTS_LIST, backports_source(suite))
                .map_err(|e| format!("write {BACKPORTS_LIST}: {e}"))?;
        }
    }
    run(root, "apt-get", &["update", "-q"])?;
    let args = qemu_install_args(&source);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    run_env(
        root,
        "apt-get",
        &args,
        &[("DEBIAN_FRONTEND", "noninteractive")],
    )
    .map_err(|e| {
        format!(
            "{e}\ninstalling qemu-system-arm ({source:?}) would need apt to remove \
             packages or failed otherwise; nothing was removed (--no-remove). \
             Install it by hand: docs/qemu.md, \"Which QEMU\""
        )
    })
}

/// Every check CI makes, in order of cost so a cheap failure shows first.
fn test(args: &[String]) -> Result<()> {
    let quick = args.iter().any(|a| a == "--no-qemu");
    setup()?;
    let root = root();
    let fw = root.join("firmware");

    // Formatting of every workspace (host, firmware, the end-to-end
    // runner and the fuzz targets, which are workspaces of their own), and
    // lints.
    run(&root, "cargo", &["fmt", "--all", "--check"])?;
    run(&fw, "cargo", &["fmt", "--all", "--check"])?;
    run(
        &root.join("tests/e2e"),
        "cargo",
        &["fmt", "--all", "--check"],
    )?;
    run(&root.join("fuzz"), "cargo", &["fmt", "--all", "--check"])?;
    run(
        &root,
        "cargo",
        &[
            "clippy",
            "--workspace",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ],
    )?;

    // Host tests (model-core, protocol, test-support, the host engine and CLI, xtask).
    run(&root, "cargo", &["test", "--workspace"])?;

    // The report pages in a real browser (a separate step: `test-browser`).
    browser::test(&[])?;

    // model-core and the link protocol must stay no_std: build and lint
    // them for the MCU.
    run(
        &root,
        "cargo",
        &[
            "clippy",
            "-p",
            "model-core",
            "-p",
            "trueaxis-protocol",
            "--target",
            THUMB,
            "--no-default-features",
            "--",
            "-D",
            "warnings",
        ],
    )?;

    // Firmware workspace: the hardware-agnostic core is tested on the host,
    // then everything is built and linted for the MCU.
    let host = host_triple()?;
    run(
        &fw,
        "cargo",
        &["test", "-p", "trueaxis-app", "--target", &host],
    )?;
    run(
        &fw,
        "cargo",
        &[
            "clippy",
            "--workspace",
            "--target",
            THUMB,
            "--",
            "-D",
            "warnings",
        ],
    )?;
    run(
        &fw,
        "cargo",
        &[
            "build",
            "--release",
            "-p",
            "trueaxis-board",
            "--target",
            THUMB,
        ],
    )?;

    if !quick {
        qemu::test_all()?;
    }
    eprintln!("\nxtask test: all checks passed");
    Ok(())
}

/// The host's target triple, from `rustc -vV`.
pub fn host_triple() -> Result<String> {
    let out = Command::new("rustc")
        .arg("-vV")
        .current_dir(root())
        .output()
        .map_err(|e| format!("cannot run rustc: {e}"))?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_owned))
        .ok_or_else(|| "rustc -vV printed no host line".into())
}

/// The main job end to end: the host tool's guided demo, then (when the QEMU
/// image exists) the board image running the fitted table.
fn demo(args: &[String]) -> Result<()> {
    setup()?;
    let root = root();
    let out = root.join("out").join("demo");
    std::fs::create_dir_all(&out).map_err(|e| format!("create {}: {e}", out.display()))?;
    let out_s = out.to_string_lossy().into_owned();
    let mut cargo_args = vec![
        "run",
        "--release",
        "--quiet",
        "-p",
        "trueaxis",
        "--",
        "demo",
        "--out",
        &out_s,
    ];
    cargo_args.extend(args.iter().map(String::as_str));
    run(&root, "cargo", &cargo_args)?;
    qemu::demo_board(&out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backports_qemu_utils_selects_backports_qemu() {
        // The version this image ships (dpkg-query -W qemu-utils).
        let bpo = "1:10.0.2+ds-2+deb13u1~bpo12+1";
        let src = qemu_source(Some(bpo), "bookworm");
        assert_eq!(src, QemuSource::Backports("bookworm-backports".into()));
        let args = qemu_install_args(&src);
        let t = args.iter().position(|a| a == "-t").expect("-t");
        assert_eq!(args[t + 1], "bookworm-backports");
        assert!(args.contains(&"--no-remove".to_string()));
        assert!(args.contains(&"--no-install-recommends".to_string()));
        assert_eq!(args.last().map(String::as_str), Some("qemu-system-arm"));
        assert!(backports_source("bookworm-backports").contains("Suites: bookworm-backports\n"));
    }

    #[test]
    fn chromium_is_installed_without_removing_anything() {
        let args = chromium_install_args();
        assert!(args.contains(&"--no-remove"));
        assert!(args.contains(&"--no-install-recommends"));
        assert_eq!(args.last(), Some(&"chromium"));
    }

    #[test]
    fn release_qemu_otherwise_and_never_removes() {
        for utils in [None, Some("1:7.2+dfsg-7+deb12u18+b3")] {
            let src = qemu_source(utils, "bookworm");
            assert_eq!(src, QemuSource::Release);
            let args = qemu_install_args(&src);
            assert!(!args.contains(&"-t".to_string()), "{args:?}");
            assert!(args.contains(&"--no-remove".to_string()));
        }
    }
}
