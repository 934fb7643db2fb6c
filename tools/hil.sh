#!/usr/bin/env bash
# HIL suite: builds the link firmware (tools/firmware.sh build), then runs hil-tests/ (QEMU
# mps2-an386 with UART0 on a pty, datasets replayed through msreg_host::link, fault
# injection). hil-tests is a workspace member whose test target is left out of
# `cargo test --workspace` (it needs QEMU and the firmware); this script is its entry point.
#
#   tools/hil.sh [TEST_FILTER...]
#
# HIL_TIMEOUT (s, default 600) bounds the whole run; every QEMU is killed when its test ends.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
cargo_bin="${CARGO_HOME:-$HOME/.cargo}/bin"
if [[ -d "$cargo_bin" ]]; then
  PATH="$cargo_bin:$PATH"
fi
timeout_s=${HIL_TIMEOUT:-600}

command -v qemu-system-arm >/dev/null || {
  echo "tools/hil.sh: qemu-system-arm missing; run tools/setup.sh" >&2
  exit 1
}
tools/firmware.sh build
# --workspace, not -p msreg-hil-tests: the dependencies' features are then unified as for the
# workspace's test build, whose artifacts are reused (with -p, msreg-host and much of its
# dependency tree were compiled a second time: minutes in a clean CI run).
status=0
timeout --kill-after=10 "$timeout_s" \
  cargo test --workspace --release --test hil -- --nocapture "$@" || status=$?
if ((status == 124 || status == 137)); then
  echo "tools/hil.sh: HIL suite timed out after ${timeout_s}s (a hung firmware or link)" >&2
  exit 1
elif ((status != 0)); then
  echo "tools/hil.sh: HIL suite FAILED (exit status $status); see the test output above" >&2
  exit 1
fi
