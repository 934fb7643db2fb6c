//! Where tests and benchmarks find the real recordings: `../shared/data` beside the project
//! root (or `$MSREG_SHARED_DATA`). A user's fresh clone has none, so every user of it skips
//! with a printed notice instead of failing.

use std::path::PathBuf;

/// The shared data directory, whether or not it exists.
pub fn root() -> PathBuf {
    std::env::var_os("MSREG_SHARED_DATA").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
        PathBuf::from,
    )
}

/// `root()/relative` when it is a directory; otherwise prints a `SKIP:` notice and returns
/// `None`.
pub fn dir_or_skip(relative: &str) -> Option<PathBuf> {
    let dir = root().join(relative);
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "SKIP: {} is absent (a fresh clone has no ../shared)",
            dir.display()
        );
        None
    }
}
