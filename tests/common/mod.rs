//! Scaffolding shared by the integration tests that drive the binary.

use std::process::{Command, Output};

/// The `tortwin` binary of this build.
pub fn tortwin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tortwin"))
}

/// Panics with the command's output unless it succeeded.
pub fn check(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed ({})\n{}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}
