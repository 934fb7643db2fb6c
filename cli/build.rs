//! Stamps the git revision into the binary for `msreg --version` (`MSREG_GIT_REVISION`):
//! `git describe --always --abbrev=12` of the source tree, or `unknown` outside a git
//! checkout (e.g. a source tarball). Reruns when HEAD or the branch it names moves (not on
//! every edit: a dirty flag would recompile the crate on each `git add`).

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
        .filter(|s| !s.is_empty())
}

/// Watches a git file if it exists (a missing path would rerun the script on every build).
fn watch(file: &str) {
    if let Some(path) = git(&["rev-parse", "--git-path", file]) {
        if Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
}

fn main() {
    let revision =
        git(&["describe", "--always", "--abbrev=12"]).unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=MSREG_GIT_REVISION={revision}");
    println!("cargo:rerun-if-changed=build.rs");
    watch("HEAD");
    watch("packed-refs");
    if let Some(reference) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watch(&reference);
    }
}
