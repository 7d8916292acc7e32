//! `scout`: the command-line tool.
fn main() {}
