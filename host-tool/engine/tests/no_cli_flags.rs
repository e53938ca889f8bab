//! The engine says what is wrong in its own terms — its options, its
//! numbers — and the CLI names the flag that changes it (docs/host.md,
//! "Messages"). Checked on the sources of the rooms that keep the rule: no
//! code there (strings included, comments not) names a `--flag`.

use std::path::{Path, PathBuf};

/// Engine folders whose messages name no command-line flag.
const ROOMS: &[&str] = &["export"];

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
