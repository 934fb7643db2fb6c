//! Where tests find the real recordings, and the one rule for a test whose input is absent.
//!
//! The recordings live in `../shared/data` beside the project root, or in
//! `$MSREG_SHARED_DATA`. A user's fresh clone has none. When a test's input is absent:
//! - under CI (the environment variable `CI` set to anything but empty, `0` or `false`; CI
//!   services set `CI=true`), the test panics, so a CI run that checked nothing fails;
//! - otherwise it writes `SKIP: <test binary>::<test name>: <what> is absent ...` to the
//!   terminal and returns. The line goes to stderr past the test harness's capture, so a plain
//!   `cargo test` shows it beside the passing test, and is appended to the file
//!   `$MSREG_SKIP_LOG` when that is set (tools/test.sh sets it: cargo-nextest hides a passing
//!   test's stderr; the script lists every such line).
//!
//! Every test that needs an input from outside the repository goes through
//! [`dir_or_skip`], [`file_or_skip`] or [`present_or_skip`].

use std::ffi::OsStr;
use std::io::Write;
use std::path::{Path, PathBuf};

/// How to provide the shared data, for the notice.
const SHARED_HOW: &str = "a fresh clone has no ../shared; set MSREG_SHARED_DATA";

/// The shared data directory, whether or not it exists.
pub fn root() -> PathBuf {
    std::env::var_os("MSREG_SHARED_DATA").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
        PathBuf::from,
    )
}

/// `root()/relative` when it is a directory; otherwise the absent-input rule of this module
/// (a `SKIP:` line and `None`, or a panic under CI).
pub fn dir_or_skip(relative: &str) -> Option<PathBuf> {
    let dir = root().join(relative);
    if dir.is_dir() {
        return Some(dir);
    }
    absent(&[dir.display().to_string()], SHARED_HOW);
    None
}

/// `root()/relative` when it is a file; otherwise the absent-input rule of this module.
pub fn file_or_skip(relative: &str) -> Option<PathBuf> {
    let file = root().join(relative);
    if file.is_file() {
        return Some(file);
    }
    absent(&[file.display().to_string()], SHARED_HOW);
    None
}

/// Whether every path in `paths` exists (file or directory); otherwise the absent-input rule
/// of this module with `how` (how to provide them) in the notice. For inputs outside
/// `../shared/data`, e.g. a reference made by another tool.
///
/// # Panics
/// Under CI, when a path is absent.
pub fn present_or_skip(paths: &[&Path], how: &str) -> bool {
    let missing: Vec<String> = paths
        .iter()
        .filter(|p| !p.exists())
        .map(|p| p.display().to_string())
        .collect();
    if missing.is_empty() {
        return true;
    }
    absent(&missing, how);
    false
}

/// The rule: under CI a panic naming the test and the paths; otherwise the `SKIP:` line.
fn absent(paths: &[String], how: &str) {
    let what = format!(
        "{} {} absent ({how})",
        paths.join(" and "),
        verb(paths.len())
    );
    let test = current_test();
    if ci_from(std::env::var_os("CI").as_deref()) {
        panic!("REQUIRED under CI: {test}: {what}");
    }
    // Past the harness's capture (print!/eprint! are captured), so a plain `cargo test`
    // shows it; one write per line keeps parallel tests' lines whole.
    let line = format!("SKIP: {test}: {what}; under CI=true this fails\n");
    let _ = std::io::stderr().write_all(line.as_bytes());
    // A runner that captures whole processes (cargo-nextest hides a passing test's stderr)
    // collects the notices in this file instead (tools/test.sh sets it).
    if let Some(path) = std::env::var_os("MSREG_SKIP_LOG") {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path);
        if let Ok(mut file) = file {
            let _ = file.write_all(line.as_bytes());
        }
    }
}

fn verb(n: usize) -> &'static str {
    if n == 1 {
        "is"
    } else {
        "are"
    }
}

/// Whether the value of `CI` means a CI run: set and not empty, `0` or `false`.
fn ci_from(value: Option<&OsStr>) -> bool {
    value.is_some_and(|v| {
        let v = v.to_string_lossy();
        let v = v.trim();
        !(v.is_empty() || v == "0" || v.eq_ignore_ascii_case("false"))
    })
}

/// `<test binary>::<test name>`: the harness names each test's thread after the test; the
/// binary is the executable's name without cargo's `-<hash>` suffix.
fn current_test() -> String {
    let thread = std::thread::current();
    let name = thread.name().unwrap_or("(unnamed thread)");
    let exe = std::env::current_exe().ok();
    let stem = exe
        .as_deref()
        .and_then(Path::file_stem)
        .map(|s| s.to_string_lossy().into_owned());
    match stem {
        Some(stem) => format!("{}::{name}", binary_name(&stem)),
        None => name.to_string(),
    }
}

/// `bag_cli-0123abcd` -> `bag_cli` (cargo's hash suffix is 16 hex digits).
fn binary_name(stem: &str) -> &str {
    match stem.rsplit_once('-') {
        Some((name, hash)) if hash.len() == 16 && hash.bytes().all(|b| b.is_ascii_hexdigit()) => {
            name
        }
        _ => stem,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ci_is_on_for_true_and_1_and_off_for_unset_empty_0_false() {
        assert!(ci_from(Some(OsStr::new("true"))));
        assert!(ci_from(Some(OsStr::new("TRUE"))));
        assert!(ci_from(Some(OsStr::new("1"))));
        assert!(!ci_from(None));
        assert!(!ci_from(Some(OsStr::new(""))));
        assert!(!ci_from(Some(OsStr::new("0"))));
        assert!(!ci_from(Some(OsStr::new("false"))));
        assert!(!ci_from(Some(OsStr::new("False "))));
    }

    #[test]
    fn the_binary_name_drops_only_cargos_hash() {
        assert_eq!(binary_name("bag_cli-0123456789abcdef"), "bag_cli");
        assert_eq!(binary_name("msreg_host-fedcba9876543210"), "msreg_host");
        assert_eq!(binary_name("msreg-host"), "msreg-host");
        assert_eq!(binary_name("plain"), "plain");
    }

    #[test]
    fn the_test_name_is_the_harness_thread_name() {
        let name = current_test();
        assert!(
            name.ends_with("::shared_data::tests::the_test_name_is_the_harness_thread_name"),
            "{name}"
        );
    }

    #[test]
    fn present_paths_need_no_notice() {
        let here = Path::new(env!("CARGO_MANIFEST_DIR"));
        assert!(present_or_skip(&[here, &here.join("Cargo.toml")], "-"));
    }
}
