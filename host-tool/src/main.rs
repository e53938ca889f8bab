//! `trueaxis` — the host tool. `main` only parses the command line and
//! dispatches to one module per subcommand (src/cmd/).
fn main() {}
