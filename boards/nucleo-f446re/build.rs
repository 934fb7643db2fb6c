//! Puts this board's `memory.x` on the linker search path, ahead of the one the firmware
//! library's build script adds (QEMU's map): cortex-m-rt's `link.x` includes the first
//! `memory.x` found, and `tools/board.sh size` checks that the vector table is at 0x0800_0000.

use std::{env, fs, path::PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);
    fs::copy("memory.x", out.join("memory.x"))
        .map_err(|e| format!("copy memory.x to {}: {e}", out.display()))?;
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
