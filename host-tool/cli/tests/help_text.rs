//! Every `--help` reads cleanly: no flag says its default twice (issue 28:
//! "[default: x] [default: x]", a `[default: …]` in the doc comment on top
//! of clap's own from `default_value`).

mod common;

use common::run;

/// The subcommands `trueaxis [PATH…] help` lists.
fn subcommands(path: &[&str]) -> Vec<String> {
    let mut args: Vec<&str> = path.to_vec();
    args.push("--help");
    let out = run(&args);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let Some(start) = text.find("Commands:") else {
        return Vec::new();
    };
    text[start..]
        .lines()
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(String::from)
        .collect()
}

#[test]
fn no_help_says_a_default_twice() {
    let mut stack: Vec<Vec<String>> = vec![Vec::new()];
    let mut seen = 0;
    while let Some(path) = stack.pop() {
        let p: Vec<&str> = path.iter().map(String::as_str).collect();
        let mut args = p.clone();
        args.push("--help");
        let out = run(&args);
        let text = String::from_utf8_lossy(&out.stdout);
        seen += 1;
        for line in text.lines() {
            assert!(
                line.matches("[default: ").count() <= 1,
                "trueaxis {} --help: {line}",
                p.join(" ")
            );
        }
        for sub in subcommands(&p) {
            let mut q = path.clone();
            q.push(sub);
            stack.push(q);
        }
    }
    assert!(seen > 15, "only {seen} help pages found");
}
