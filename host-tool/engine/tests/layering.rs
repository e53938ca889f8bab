//! The engine's layering (lib.rs, docs/host.md) checked on its sources: a
//! module may name `crate::<module>` only for modules in a lower layer, so
//! no import goes upward and none runs in a circle. A new top-level module
//! must be given its layer here. The family rooms (`effect/`, one file per
//! effect family, and `diagnose/search/`, how the search proposes each)
//! have a narrower rule: what their files may name of the crate, and that
//! a family's file names no other family (docs/host.md § Adding an effect
//! family).
//!
//! The on-machine wing (`onmachine/`) stands beside that pipeline: it may
//! use only the plumbing in [`WING_USES`], its own modules only downward
//! ([`WING_LAYERS`]), and no module of the pipeline may name it.
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
    ("files", 0),
    ("import", 1),
    ("features", 1),
    ("units", 1),
    ("effect", 2),
    ("linalg", 2),
    ("lines", 2),
    ("regions", 2),
    ("simulate", 3),
    ("holdout", 3),
    ("travel", 3),
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

/// The wing's folder.
const WING: &str = "onmachine";

/// What of the engine the wing may use: the generic plumbing below the
/// pipeline (the CSV line reader, the data set's plausible ranges, least
/// squares, the simulator's seeded normal deviates).
const WING_USES: &[&str] = &["data", "import", "linalg", "simulate"];

/// Layer of each module of the wing, lowest first.
const WING_LAYERS: &[(&str, u8)] = &[
    ("clock", 0),
    ("separate", 0),
    ("probe_csv", 1),
    ("spindle_log", 1),
    ("probe", 1),
    ("workpiece", 1),
    ("simulate", 1),
    ("part_diagnosis", 2),
];

fn layer(module: &str) -> Option<u8> {
    LAYERS.iter().find(|(m, _)| *m == module).map(|(_, l)| *l)
}

fn wing_layer(module: &str) -> Option<u8> {
    WING_LAYERS
        .iter()
        .find(|(m, _)| *m == module)
        .map(|(_, l)| *l)
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

/// The `<prefix><name>` paths a source names, outside comments.
fn paths_after(src: &str, prefix: &str) -> Vec<String> {
    let mut v = Vec::new();
    for line in src.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(i) = rest.find(prefix) {
            rest = &rest[i + prefix.len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            v.push(name);
        }
    }
    v
}

/// The `crate::<name>` paths a source names, outside comments.
fn crate_paths(src: &str) -> Vec<String> {
    paths_after(src, "crate::")
}

/// The module a source file belongs to under `dir` (`a.rs` or `a/…` → `a`).
fn top_module(rel: &Path) -> String {
    rel.components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy()
        .trim_end_matches(".rs")
        .to_string()
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
        let top = top_module(rel);
        if top == "lib" || top == WING {
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
fn the_wing_uses_only_the_plumbing_its_own_modules_downward_and_nothing_imports_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let wing = src.join(WING);
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut bad = Vec::new();
    let mut in_wing = 0;
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let text = std::fs::read_to_string(f).unwrap();
        let Ok(inner) = f.strip_prefix(&wing) else {
            if crate_paths(&text).iter().any(|m| m == WING) {
                bad.push(format!(
                    "{}: crate::{WING} (the pipeline imports the wing)",
                    rel.display()
                ));
            }
            continue;
        };
        in_wing += 1;
        let own = top_module(inner);
        if own == "mod" {
            continue;
        }
        let own_layer =
            wing_layer(&own).unwrap_or_else(|| panic!("{WING}/{own}: give the module its layer"));
        for m in crate_paths(&text) {
            if m != WING && !WING_USES.contains(&m.as_str()) {
                bad.push(format!("{}: crate::{m}", rel.display()));
            }
        }
        // A module directly in the folder names its siblings as `super::`
        // too.
        let mut siblings = paths_after(&text, &format!("crate::{WING}::"));
        if inner.components().count() == 1 {
            siblings.extend(paths_after(&text, "super::"));
        }
        for m in siblings {
            match wing_layer(&m) {
                _ if m == own || m.is_empty() => {}
                Some(l) if l < own_layer => {}
                _ => bad.push(format!("{}: crate::{WING}::{m}", rel.display())),
            }
        }
    }
    assert!(in_wing >= 6, "found only {in_wing} files in {WING}/");
    assert!(
        bad.is_empty(),
        "imports against the wing's rules:\n{}",
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
    assert_eq!(
        paths_after(
            "use crate::onmachine::probe::{self, Contact};",
            "crate::onmachine::"
        ),
        ["probe"]
    );
    assert!(wing_layer("separate") < wing_layer("part_diagnosis"));
    assert_eq!(layer(WING), None);
}

/// Engine folders whose messages name no command-line flag.
const ROOMS: &[&str] = &["export", "effect", "diagnose/search", "onmachine"];

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
