//! The simulator's command line: usage errors exit 2. (This test also makes `cargo test
//! --workspace` build the `scout-sim` binary that the system tests in tests/ run.)

use std::process::Command;

const SIM: &str = env!("CARGO_BIN_EXE_scout-sim");

fn run(args: &[&str]) -> Option<i32> {
    Command::new(SIM)
        .args(args)
        .output()
        .expect("run scout-sim")
        .status
        .code()
}

#[test]
fn sim_needs_exactly_one_transport() {
    assert_eq!(run(&[]), Some(2));
    assert_eq!(run(&["--serial", "--slcan"]), Some(2));
}
