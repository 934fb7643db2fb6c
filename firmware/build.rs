//! Puts `memory.x` on the linker search path (cortex-m-rt's `link.x` includes it) and
//! relinks when it changes; adds defmt's linker script.

use std::{env, fs, path::PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);
    fs::copy("memory.x", out.join("memory.x"))
        .map_err(|e| format!("copy memory.x to {}: {e}", out.display()))?;
    println!("cargo:rustc-link-search={}", out.display());
    // Only `link` logs with defmt (to semihosting) and links a defmt logger; the library's
    // interned log strings still reach the other binaries' objects, and without defmt.x
    // lld places them at address 0, over .text. defmt.x keeps them in a non-loaded section.
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
