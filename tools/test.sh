#!/usr/bin/env bash
# The project's test command (README, .ci/run): installs the embedded toolchain if missing,
# checks formatting and lints, runs the host workspace's tests, then builds the Cortex-M4F
# firmware, runs its self-test in QEMU and prints its flash/RAM use, then the HIL suite
# (hil-tests/: the link firmware in QEMU driven over a pty by `msreg link`), then builds the
# NUCLEO-F446RE board target (tools/board.sh) and cross-builds msreg for aarch64 Linux (in the
# background from the acceptance runs on) and runs it under qemu-aarch64 (tools/aarch64.sh).
# Idempotent; needs no stdin; CI runs it as `bash .ci/run` in a fresh clone with CI=true.
#
# Tests on inputs from outside the repository (the real recordings of ../shared/data or
# $MSREG_SHARED_DATA; the OpenCV ArUco reference made below) follow one rule
# (host/src/shared_data.rs): with CI set (CI=true) an absent input fails the test, so the run
# fails; without CI the test prints `SKIP: <binary>::<test>: ...` and passes, and the step
# "real-data tests: skip notices" lists every such test by name.
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

step "lint (cargo clippy --release --workspace --all-targets -D warnings; the HIL test target too)"
# --release: the build scripts (with the C of zstd/lz4/bzip2) and proc macros it compiles are
# the ones the release test build below reuses, instead of a second, debug set.
cargo clippy --release --workspace --all-targets -- -D warnings
# `--all-targets` skips `test = false` targets: the HIL suite (run by tools/hil.sh below)
# is linted, and so compiled, here, before the long steps.
cargo clippy --release --workspace --test hil -- -D warnings

step "import graph (tools/import_graph.py: imports point down, no cycle, no CLI crate in the library)"
python3 tools/import_graph.py

step "OpenCV ArUco reference for host/tests/aruco_opencv.rs (opencv-doc photos, OpenCV 5.0 in a venv)"
# The photos come from Debian's opencv-doc package, OpenCV's own detections from pip's
# opencv-python-headless (the version docs/aruco.md was measured with), both kept under
# target/ so a second run reuses them. If they cannot be made (offline), the test skips
# without CI and fails with CI=true.
fixtures=${MSREG_FIXTURES:-$root/target/fixtures}
aruco_html=$fixtures/opencv-doc/usr/share/doc/opencv-doc/opencv4/html
aruco_reference=$fixtures/aruco_reference.csv
# Run as a condition (so without `set -e`): every step returns on failure.
make_aruco_reference() {
  local venv=$fixtures/venv deb photo photos members=()
  mkdir -p "$fixtures/opencv-doc" || return 1
  if ! "$venv/bin/python" -c 'import cv2' 2>/dev/null; then
    python3 -m venv "$venv" || return 1
    "$venv/bin/pip" install -q "opencv-python-headless==5.0.0.93" || return 1
  fi
  # The photos tools/aruco_opencv_reference.py reads (its PHOTOS list), from the package.
  photos=$(cd tools && "$venv/bin/python" -c \
    'import aruco_opencv_reference as a; print("\n".join(a.PHOTOS))') || return 1
  rm -f "$fixtures"/opencv-doc_*.deb
  if ! (cd "$fixtures" && apt-get download -q opencv-doc); then
    "${sudo[@]}" apt-get "${apt_opts[@]}" update || return 1
    (cd "$fixtures" && apt-get download -q opencv-doc) || return 1
  fi
  for photo in $photos; do
    members+=("./usr/share/doc/opencv-doc/opencv4/html/$photo")
  done
  deb=$(echo "$fixtures"/opencv-doc_*.deb)
  dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$fixtures/opencv-doc" "${members[@]}" || return 1
  rm -f "$deb"
  # (It prints a line per photo, then the summary: keep the summary.)
  "$venv/bin/python" tools/aruco_opencv_reference.py --html "$aruco_html" \
    --out "$aruco_reference.tmp" 2>&1 >/dev/null | tail -n 1 || return 1
  mv "$aruco_reference.tmp" "$aruco_reference"
}
sudo=()
if [[ $(id -u) -ne 0 ]]; then
  sudo=(sudo)
fi
apt_opts=(-o DPkg::Lock::Timeout=600 -q)
if [[ -s "$aruco_reference" && -d "$aruco_html" ]]; then
  echo "present: $aruco_reference"
elif ! make_aruco_reference; then
  echo "NOTICE: the OpenCV ArUco reference could not be made: aruco_opencv skips (fails with CI=true)"
fi
export MSREG_OPENCV_DOC_HTML=$aruco_html MSREG_ARUCO_REFERENCE=$aruco_reference

step "test (cargo nextest run --workspace --release, then the doc tests)"
# cargo-nextest (on the machine image; `cargo test` when absent) runs every test of every
# binary on both cores: `cargo test` runs the binaries one after another, so a binary with one
# long test leaves a core idle. Each test is its own process, so the tests' `SKIP:` notices
# (host/src/shared_data.rs) are collected in $MSREG_SKIP_LOG as well as in the log.
test_log=$(mktemp)
skip_log=$(mktemp)
trap 'rm -f "$test_log" "$skip_log"' EXIT
export MSREG_SKIP_LOG=$skip_log
if cargo nextest --version >/dev/null 2>&1; then
  use_nextest=1
  cargo nextest run --workspace --release --no-fail-fast --profile ci 2>&1 | tee "$test_log"
  cargo test --workspace --release --doc 2>&1 | tee -a "$test_log"
else
  use_nextest=0
  echo "NOTICE: cargo-nextest absent: cargo test runs the binaries one after another"
  cargo test --workspace --release 2>&1 | tee "$test_log"
fi

# The acceptance runs that a plain `cargo test` skips (#[ignore]: seconds to a minute of
# seeds each) but that fit CI: each under ~60 s on 2 cores (README, "Acceptance tests": this list, the
# times measured, and the runs left out with the reason). One line per test:
# package, test target, exact test name.
acceptance=(
  "msreg-host imu_timing ten_seeds_pose_imu"
  "msreg-host imu_timing ten_seeds_pose_imu_precise_odometry"
  "msreg-host imu_timing ten_seeds_moving_start_pose_imu"
  "msreg-host imu_timing ten_seeds_camera_imu"
  "msreg-host imu_timing ten_seeds_moving_start_camera_imu"
  "msreg-host monitor_drive camera_knock_ten_seeds"
  "msreg-host monitor_drive lidar_knock_ten_seeds"
  "msreg-host monitor_drive no_alarm_in_ten_unknocked_drives"
  "msreg-host monitor_drive false_alarms_in_forty_unknocked_drives"
  "msreg-host infra_calibrate acceptance_five_seeds"
  "msreg-host camera_imu_rig two_camera_rig_is_accurate_and_consistent_over_ten_seeds"
  "msreg-host monitor_pose_sensors one_pose_sensor_false_alarms_in_forty_unknocked_drives"
  "msreg-host camera_imu_real_halves euroc_halves_agree_within_the_written_sigma"
  "msreg-host pose_imu_real real_pnp_pose_imu_halves_agree_within_the_written_sigma"
  "msreg euroc_camera_imu_real euroc_imu_april_matches_kalibr"
)
# The companion computer's cross-build (tools/aarch64.sh: ~9 min of CPU, Debian's cargo, its
# own target dir) starts now in the background: the steps until its own (acceptance runs,
# firmware and board builds with their single-threaded LTO links, QEMU, HIL) leave a core
# idle much of the time. Its log is shown at its step.
aarch64_log=$(mktemp)
trap 'rm -f "$test_log" "$skip_log" "$aarch64_log"' EXIT
tools/aarch64.sh build >"$aarch64_log" 2>&1 &
aarch64_build=$!

step "acceptance runs (${#acceptance[@]} ignored tests by name, --run-ignored only)"
if ((use_nextest)); then
  # One nextest run over the list, both cores busy; it prints each test's time.
  filter=""
  for entry in "${acceptance[@]}"; do
    read -r package target name <<<"$entry"
    filter+="${filter:+ | }(package($package) & binary($target) & test(=$name))"
  done
  # A name that matches nothing would pass silently: the list must find every entry.
  found=$(cargo nextest list --workspace --release --run-ignored only -E "$filter" 2>/dev/null |
    grep -c '::' || true)
  if ((found != ${#acceptance[@]})); then
    echo "tools/test.sh: the acceptance list names ${#acceptance[@]} tests, nextest finds $found" >&2
    exit 1
  fi
  cargo nextest run --workspace --release --profile ci --no-fail-fast --run-ignored only \
    -E "$filter" 2>&1 | tee -a "$test_log"
else
  for entry in "${acceptance[@]}"; do
    read -r package target name <<<"$entry"
    started=$SECONDS
    cargo test --release -q -p "$package" --test "$target" -- --ignored --exact "$name"
    printf '  %s %s::%s passed (%ss)\n' "$package" "$target" "$name" $((SECONDS - started))
  done
fi

# Every test whose input is absent printed a `SKIP:` line past cargo's capture
# (host/src/shared_data.rs); with CI=true those tests failed in the test step instead.
step "real-data tests: skip notices"
skips=$(cat "$test_log" "$skip_log" | grep -o 'SKIP: .*' | sort -u || true)
if [[ -z $skips ]]; then
  echo "no test skipped: every real-data test ran on its data"
else
  echo "NOTICE: $(wc -l <<<"$skips") tests checked nothing, their input is absent (CI=true makes this a failure):"
  echo "$skips"
fi

step "firmware build (tools/firmware.sh build)"
tools/firmware.sh build

step "firmware lint (tools/firmware.sh clippy: -D warnings)"
tools/firmware.sh clippy

step "firmware self-test in QEMU (tools/firmware.sh run)"
tools/firmware.sh run

step "firmware size (tools/firmware.sh size)"
tools/firmware.sh size

step "real board: NUCLEO-F446RE format, lint, build and size (tools/board.sh)"
rustfmt --edition 2021 --check boards/nucleo-f446re/build.rs boards/nucleo-f446re/src/*.rs
tools/board.sh clippy
tools/board.sh size

step "HIL: link firmware in QEMU over a pty (tools/hil.sh)"
tools/hil.sh

step "companion computer: aarch64 build + qemu-aarch64 run (tools/aarch64.sh)"
aarch64_status=0
wait "$aarch64_build" || aarch64_status=$?
cat "$aarch64_log"
if ((aarch64_status != 0)); then
  echo "tools/aarch64.sh build failed (exit $aarch64_status)" >&2
  exit 1
fi
# The build is done: `test` finds it up to date and runs the emulated checks.
tools/aarch64.sh test

printf '(%ss)\n\ntools/test.sh: all steps passed in %ss\n' \
  $((SECONDS - step_start)) $((SECONDS - total_start))
