#!/usr/bin/env bash
# The project's test command (README, .ci/run): installs the embedded toolchain if missing,
# checks formatting and lints, runs the host workspace's tests, then builds the Cortex-M4F
# firmware, runs its self-test in QEMU and prints its flash/RAM use, then the HIL suite
# (hil-tests/: the link firmware in QEMU driven over a pty by `msreg link`).
# Idempotent; needs no stdin; CI runs it as `bash .ci/run` in a fresh clone with CI=true.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

# The host workspace uses the rustup toolchain (with rustfmt and clippy); Debian's
# /usr/bin/cargo, installed for the firmware, must not shadow it.
cargo_bin="${CARGO_HOME:-$HOME/.cargo}/bin"
if [[ -d "$cargo_bin" ]]; then
  PATH="$cargo_bin:$PATH"
fi

total_start=$SECONDS
step_start=$SECONDS
step() {
  if ((SECONDS > total_start)); then
    printf '(%ss)\n' $((SECONDS - step_start))
  fi
  step_start=$SECONDS
  printf '\n==== %s ====\n' "$*"
}

step "setup (tools/setup.sh)"
tools/setup.sh

step "format (cargo fmt --check; rustfmt --check firmware/)"
cargo fmt --all -- --check
# firmware/ is outside the workspace; rustfmt follows `mod` from the crate roots.
rustfmt --edition 2021 --check firmware/build.rs firmware/src/lib.rs firmware/src/main.rs \
  firmware/src/bin/*.rs

step "lint (cargo clippy --workspace --all-targets -D warnings)"
cargo clippy --workspace --all-targets -- -D warnings

step "test (cargo test --workspace --release)"
cargo test --workspace --release

step "firmware build (tools/firmware.sh build)"
tools/firmware.sh build

step "firmware lint (tools/firmware.sh clippy: -D warnings)"
tools/firmware.sh clippy

step "firmware self-test in QEMU (tools/firmware.sh run)"
tools/firmware.sh run

step "firmware size (tools/firmware.sh size)"
tools/firmware.sh size

step "HIL: link firmware in QEMU over a pty (tools/hil.sh)"
tools/hil.sh

printf '(%ss)\n\ntools/test.sh: all steps passed in %ss\n' \
  $((SECONDS - step_start)) $((SECONDS - total_start))
