# Sourced by tools/firmware.sh and tools/board.sh: Debian's cargo with Debian's rustc (the
# toolchain with the bare-metal target and rust-src for build-std, tools/setup.sh), run from
# inside a crate directory so that its .cargo/config.toml (target, linker, build-std, runner)
# applies. Variables that would override that config (RUSTFLAGS replaces target.rustflags, a
# CARGO_TARGET_DIR moves the output) are dropped.
#
#   debian_cargo_in DIR CARGO_ARGS...
debian_cargo_in() {
  local dir=$1
  shift
  (
    cd "$dir"
    env -u RUSTFLAGS -u CARGO_ENCODED_RUSTFLAGS -u CARGO_BUILD_TARGET -u CARGO_TARGET_DIR \
      -u RUSTUP_TOOLCHAIN -u CARGO_BUILD_RUSTFLAGS \
      RUSTC_BOOTSTRAP=1 RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc \
      /usr/bin/cargo "$@"
  )
}
