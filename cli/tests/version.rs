//! `msreg --version` names the git revision it was built from (build.rs).

use std::process::Command;

#[test]
fn version_shows_the_git_revision_of_the_build() {
    let out = Command::new(env!("CARGO_BIN_EXE_msreg"))
        .arg("--version")
        .output()
        .expect("msreg runs");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let expected = Command::new("git")
        .args(["describe", "--always", "--abbrev=12"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    let Some(revision) = expected else {
        eprintln!("SKIP version: not a git checkout; msreg says {text}");
        assert!(text.contains("(git unknown)"), "{text}");
        return;
    };
    assert_eq!(
        text.trim(),
        format!("msreg {} (git {revision})", env!("CARGO_PKG_VERSION"))
    );
}
