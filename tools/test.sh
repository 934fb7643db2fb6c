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

step "headless Chromium for the HTML report test (host/tests/report_html.rs)"
if command -v chromium >/dev/null; then
  echo "chromium present: $(chromium --version 2>/dev/null || true)"
else
  sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    sudo=(sudo)
  fi
  apt_opts=(-o DPkg::Lock::Timeout=600 -q)
  export DEBIAN_FRONTEND=noninteractive
  if ! { "${sudo[@]}" apt-get "${apt_opts[@]}" install -y --no-install-recommends chromium ||
    { "${sudo[@]}" apt-get "${apt_opts[@]}" update &&
      "${sudo[@]}" apt-get "${apt_opts[@]}" install -y --no-install-recommends chromium; }; }; then
    echo "NOTICE: chromium could not be installed (offline?): report_html skips its browser checks"
  fi
fi

step "format (cargo fmt --check; rustfmt --check firmware/)"
cargo fmt --all -- --check
# firmware/ is outside the workspace; rustfmt follows `mod` from the crate roots.
rustfmt --edition 2021 --check firmware/build.rs firmware/src/lib.rs firmware/src/main.rs \
  firmware/src/bin/*.rs

step "lint (cargo clippy --workspace --all-targets -D warnings; the HIL test target too)"
cargo clippy --workspace --all-targets -- -D warnings
# `--all-targets` skips `test = false` targets: the HIL suite (run by tools/hil.sh below)
# is linted, and so compiled, here, before the long steps.
cargo clippy -p msreg-hil-tests --test hil -- -D warnings

step "import graph (tools/import_graph.py: imports point down, no cycle, no CLI crate in the library)"
python3 tools/import_graph.py

step "test (cargo test --workspace --release)"
cargo test --workspace --release

# The real-data tests return early with a `SKIP:` line when ../shared/data is absent (a
# fresh clone); cargo captures a passing test's output, so show those notices here.
step "real-data tests: skip notices"
shared_data=${MSREG_SHARED_DATA:-$root/../shared/data}
if [[ -d "$shared_data" ]]; then
  echo "real data present at $shared_data: the real-data tests ran in the step above"
else
  # (The library's pointcloud::tests real-data test skips too; its SKIP stays captured.)
  skips=$(cargo test --release -p msreg --test checkerboard_real --test euroc_camera_imu_real \
    --test mi_targetless_real --test ndt_real_pairs --test bag_ros1 --test bag_cli \
    -- --nocapture 2>&1 | grep -o 'SKIP: .*' | sort | uniq -c || true)
  echo "NOTICE: $shared_data is absent; these real-data tests passed without checking anything:"
  echo "${skips:-  (no SKIP lines found)}"
fi

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
