//! The engine's layering (lib.rs, docs/host.md) checked on its sources: a
//! module may name `crate::<module>` only for modules in a lower layer, so
//! no import goes upward and none runs in a circle. A new top-level module
//! must be given its layer here. The family rooms (`effect/`, one file per
//! effect family, and `diagnose/search/`, how the search proposes each)
//! have a narrower rule: what their files may name of the crate, and that
//! a family's file names no other family (docs/host.md § Adding an effect
//! family).
//!
//! And the rule of docs/host.md § Messages: the engine says what is wrong
//! in its own terms — its options, its numbers — and the CLI names the
//! flag that changes it; no code in the folders that keep the rule
//! (strings included, comments not) names a `--flag`.

use std::path::{Path, PathBuf};

/// Layer of each top-level engine module, lowest first.
const LAYERS: &[(&str, u8)] = &[
    ("data", 0),
    ("warning", 0),
    ("progress", 0),
    ("import", 1),
    ("features", 1),
    ("units", 1),
    ("effect", 2),
    ("linalg", 2),
    ("lines", 2),
    ("regions", 2),
    ("simulate", 3),
    ("holdout", 3),
    ("probe", 3),
    ("separate", 2),
    ("workpiece", 3),
    ("part_diagnosis", 4),
    ("model", 4),
    ("fit", 5),
    ("diagnose", 6),
    ("compare", 6),
    ("export", 6),
    ("history", 6),
    ("iso230", 6),
    ("improve", 7),
];

/// Folders of one file per effect family: the crate modules their files
/// may name (their own module's shared files — `mod.rs`, and those listed
/// as shared — are named through `super::`), and the files that are not
/// a family.
const FAMILY_ROOMS: &[(&str, &[&str], &[&str])] = &[
    (
        "effect",
        &["data", "features"],
        &["mod", "pairs", "sim", "tests"],
    ),
    (
        "diagnose/search",
        &["data", "effect", "features", "linalg", "lines"],
        &["mod"],
    ),
];

fn layer(module: &str) -> Option<u8> {
    LAYERS.iter().find(|(m, _)| *m == module).map(|(_, l)| *l)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The `crate::<name>` paths a source names, outside comments.
fn crate_paths(src: &str) -> Vec<String> {
    let mut v = Vec::new();
    for line in src.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            v.push(name);
        }
    }
    v
}

#[test]
fn no_engine_module_imports_from_its_own_layer_or_above() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    assert!(files.len() > 20, "found only {} source files", files.len());
    let mut bad = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string();
        if top == "lib" {
            continue;
        }
        let own = layer(&top).unwrap_or_else(|| panic!("{top}: give the module its layer"));
        let text = std::fs::read_to_string(f).unwrap();
        for m in crate_paths(&text) {
            if m == top {
                continue;
            }
            match layer(&m) {
                Some(l) if l < own => {}
                _ => bad.push(format!("{}: crate::{m}", rel.display())),
            }
        }
    }
    assert!(
        bad.is_empty(),
        "imports against the layering:\n{}",
        bad.join("\n")
    );
}

/// Whether `code` names `module::` as a path segment (not the tail of
/// another name).
fn names(code: &str, module: &str) -> bool {
    let pat = format!("{module}::");
    code.match_indices(&pat).any(|(i, _)| {
        !code[..i]
            .chars()
            .next_back()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
    })
}

/// What family file `stem` (of a room that may name `allowed` of the crate,
/// beside the families `families`) names against its room's rule.
fn room_violations(stem: &str, src: &str, allowed: &[&str], families: &[&str]) -> Vec<String> {
    let code: String = src
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n");
    let mut bad: Vec<String> = crate_paths(src)
        .into_iter()
        .filter(|m| !allowed.contains(&m.as_str()))
        .map(|m| format!("crate::{m}"))
        .collect();
    if families.contains(&stem) {
        bad.extend(
            families
                .iter()
                .filter(|f| **f != stem && names(&code, f))
                .map(|f| format!("{f}:: (another family)")),
        );
    }
    bad
}

#[test]
fn a_family_file_names_only_its_room_s_modules_and_no_other_family() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut bad = Vec::new();
    for (folder, allowed, shared) in FAMILY_ROOMS {
        let dir = src.join(folder);
        let mut files = Vec::new();
        rust_files(&dir, &mut files);
        let stems: Vec<String> = files
            .iter()
            .map(|f| f.file_stem().unwrap().to_string_lossy().into_owned())
            .collect();
        let families: Vec<&str> = stems
            .iter()
            .map(String::as_str)
            .filter(|s| !shared.contains(s))
            .collect();
        assert!(families.len() >= 7, "{folder}: {families:?}");
        let own = folder.split('/').next().unwrap();
        for (f, stem) in files.iter().zip(&stems) {
            let text = std::fs::read_to_string(f).unwrap();
            let mut allowed_here: Vec<&str> = allowed.to_vec();
            allowed_here.push(own);
            for v in room_violations(stem, &text, &allowed_here, &families) {
                bad.push(format!("{folder}/{stem}.rs: {v}"));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "family rooms naming what they may not:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_checker_sees_an_upward_import() {
    assert_eq!(
        crate_paths("use crate::fit::Seed; // crate::history"),
        ["fit"]
    );
    assert!(layer("model") < layer("fit"));
    // A family file that reaches for another family or out of its room.
    let families = ["periodic", "thermal"];
    let v = room_violations(
        "periodic",
        "use super::thermal::Sim; // periodic::x\nuse crate::model::Seed;\nlet a = my_thermal::x;",
        &["data", "effect"],
        &families,
    );
    assert_eq!(v, ["crate::model", "thermal:: (another family)"]);
    assert!(room_violations("mod", "use super::thermal::Sim;", &[], &families).is_empty());
}

/// Engine folders whose messages name no command-line flag.
const ROOMS: &[&str] = &["export", "effect", "diagnose/search"];

/// `--name` flags a source line names outside a comment.
fn flags(line: &str) -> Vec<String> {
    let code = line.split("//").next().unwrap_or("");
    let mut v = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("--") {
        rest = &rest[i + 2..];
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || *c == '-')
            .collect();
        if name.starts_with(|c: char| c.is_ascii_lowercase()) {
            v.push(format!("--{name}"));
        }
    }
    v
}

#[test]
fn no_engine_message_names_a_cli_flag() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut bad = Vec::new();
    for room in ROOMS {
        let mut files = Vec::new();
        rust_files(&src.join(room), &mut files);
        assert!(!files.is_empty(), "{room}: no sources");
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            for (i, line) in text.lines().enumerate() {
                for flag in flags(line) {
                    let rel = f.strip_prefix(&src).unwrap().display();
                    bad.push(format!("{rel}:{}: {flag}", i + 1));
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "CLI flags named in the engine:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_checker_sees_a_flag_in_a_string_and_not_in_a_comment() {
    assert_eq!(
        flags(r#"bail!("--max-corr-um must be positive"); // --drop-lag"#),
        ["--max-corr-um"]
    );
    assert!(flags("/// give it with --temp-range-c").is_empty());
    assert!(flags("let i = n - -1;").is_empty());
}
