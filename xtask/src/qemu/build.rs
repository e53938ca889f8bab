//! Building the QEMU images: the firmware workspace's binaries and the
//! defmt-test suites for the MCU (their executables read from cargo's JSON
//! messages), in the dev or release profile, into the firmware target
//! directory.

use std::path::PathBuf;
use std::process::{Command, Stdio};

use super::PACKAGE;
use crate::{Result, THUMB};

/// Cargo profile an image is built with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Profile {
    /// opt-level "s" with overflow checks: the test suites.
    Dev,
    /// The firmware's release profile (fat LTO, opt-level 3): what is
    /// benchmarked and what the board would run.
    Release,
}

impl Profile {
    pub(super) fn dir(self) -> &'static str {
        match self {
            Profile::Dev => "debug",
            Profile::Release => "release",
        }
    }
}

/// The firmware workspace, where cargo must run so that its
/// .cargo/config.toml (thumb target, DEFMT_LOG) applies.
pub(super) fn firmware_dir() -> PathBuf {
    crate::root().join("firmware")
}

/// The target directory cargo uses (honours CARGO_TARGET_DIR).
pub(super) fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) => {
            let d = PathBuf::from(d);
            if d.is_absolute() {
                d
            } else {
                firmware_dir().join(d)
            }
        }
        None => firmware_dir().join("target"),
    }
}

/// Builds one binary of the QEMU crate and returns the ELF's path.
pub(super) fn build_bin(bin: &str, profile: Profile) -> Result<PathBuf> {
    build_package_bin(PACKAGE, bin, profile, &[])
}

/// Builds binary `bin` of firmware-workspace package `package` with
/// `features`. (Cargo keeps each feature set's build apart and copies the
/// one just built to the ELF's path, so switching sets rebuilds nothing.)
pub(super) fn build_package_bin(
    package: &str,
    bin: &str,
    profile: Profile,
    features: &[&str],
) -> Result<PathBuf> {
    let mut args = vec!["build", "-p", package, "--target", THUMB, "--bin", bin];
    if profile == Profile::Release {
        args.push("--release");
    }
    let features = features.join(",");
    if !features.is_empty() {
        args.extend(["--features", &features]);
    }
    crate::run(&firmware_dir(), "cargo", &args)?;
    let elf = target_dir().join(THUMB).join(profile.dir()).join(bin);
    if elf.exists() {
        Ok(elf)
    } else {
        Err(format!(
            "cargo built `{bin}` but {} is missing",
            elf.display()
        ))
    }
}

/// Builds the defmt-test suites and returns (suite name, ELF) pairs, read
/// from cargo's JSON messages (the test executables carry a hash).
pub(super) fn build_suites() -> Result<Vec<(String, PathBuf)>> {
    let args = [
        "test",
        "-p",
        PACKAGE,
        "--target",
        THUMB,
        "--no-run",
        "--message-format=json-render-diagnostics",
    ];
    eprintln!("\n$ cargo {}", args.join(" "));
    let out = Command::new("cargo")
        .args(args)
        .current_dir(firmware_dir())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!("building the QEMU suites failed ({})", out.status));
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let mut suites = Vec::new();
    for line in stdout.lines() {
        if !line.contains(r#""reason":"compiler-artifact""#) || !line.contains(r#""test":true"#) {
            continue;
        }
        let (Some(name), Some(exe)) = (
            line.find(r#""target":{"#)
                .and_then(|i| json_str(&line[i..], "name")),
            json_str(line, "executable"),
        ) else {
            continue;
        };
        suites.push((name, PathBuf::from(exe)));
    }
    suites.sort();
    Ok(suites)
}

/// The string value of the first `"key":"…"` in a JSON text (cargo's
/// messages; paths with escaped quotes or backslashes are not expected).
pub(super) fn json_str(json: &str, key: &str) -> Option<String> {
    let pat = format!("\"{key}\":\"");
    let start = json.find(&pat)? + pat.len();
    let len = json[start..].find('"')?;
    Some(json[start..start + len].replace("\\\\", "\\"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_str_reads_cargo_messages() {
        let line = r#"{"reason":"compiler-artifact","package_id":"path+file:///x#trueaxis-qemu@0.1.0","target":{"kind":["test"],"crate_types":["bin"],"name":"infra","src_path":"/x/suites/infra.rs"},"profile":{"test":true},"executable":"/t/deps/infra-1ce9"}"#;
        let target = &line[line.find(r#""target":{"#).unwrap()..];
        assert_eq!(json_str(target, "name").as_deref(), Some("infra"));
        assert_eq!(
            json_str(line, "executable").as_deref(),
            Some("/t/deps/infra-1ce9")
        );
        assert_eq!(json_str(line, "missing"), None);
    }
}
