//! How the binary's tests run `msreg`: the helpers every `cli/tests/*.rs` shares, in one home
//! (each test file includes it with `#[path = "support/run.rs"] mod run;`).
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs the `msreg` binary built for these tests with `args` (panics if it cannot start).
pub fn msreg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(args)
        .output()
        .expect("the msreg binary runs")
}

/// Asserts that `out` exited 0, showing its stderr otherwise.
pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
