#!/usr/bin/env bash
# The companion computer: cross-builds the host binary `msreg` for aarch64 Linux (a Raspberry
# Pi 4/5, Jetson or any arm64 board running Debian/Ubuntu) with Debian's Rust toolchain and
# cross gcc, and runs it under qemu-aarch64 user mode (docs/companion.md).
#
#   tools/aarch64.sh build   cross-build -p msreg --bin msreg into target/aarch64/; print
#                            `file` of the binary and its size
#   tools/aarch64.sh test    build, then under qemu-aarch64: `msreg --version`,
#                            `msreg demo --only pose-imu` (converged, errors inside 3 sigma),
#                            `msreg simulate drive` (20 s, camera knocked 1 deg at 10 s) and
#                            `msreg monitor` (the alarm: camera, after the knock, none before;
#                            the re-estimated camera mounting inside 3 sigma of the truth)
#
# Toolchain: the rustup toolchain has no aarch64 standard library and cannot download one, so
# Debian's rustc (rustc-web, tools/setup.sh) builds std from rust-web-src (`-Z build-std`,
# RUSTC_BOOTSTRAP=1, as tools/firmware.sh does for the M4F). Installs with apt when missing
# (idempotent, apt untouched when present): gcc-aarch64-linux-gnu + libc6-dev-arm64-cross (the
# linker, and the C compiler of zstd-sys, lz4-sys and bzip2-sys), qemu-user (qemu-aarch64).
#
# Profile `aarch64` (defined below, not in Cargo.toml): release with no debug info, the
# workspace crates at opt-level 3 and every dependency (std included) at opt-level 0. That
# halves the clean build's CPU time; the numerical code is generic and is compiled, at
# opt-level 3, in the workspace crates that instantiate it (measurements: docs/companion.md).
# AARCH64_DEPS_OPT_LEVEL overrides the dependencies' level.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
target=aarch64-unknown-linux-gnu
target_dir="$root/target/aarch64"
bin="$target_dir/$target/aarch64/msreg"
sysroot=/usr/aarch64-linux-gnu
timeout_s=${AARCH64_TIMEOUT:-600}
deps_opt=${AARCH64_DEPS_OPT_LEVEL:-0}
# `msreg monitor` exits with this code when a calibration changed (an alarm; docs/monitor.md).
monitor_alarm_exit=3

usage() {
  sed -n '2,13p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  exit 2
}

# Installs the cross toolchain and the emulator when a package or its witness is missing.
install_tools() {
  local packages=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user)
  local witnesses=(/usr/bin/aarch64-linux-gnu-gcc "$sysroot/lib/libc.so.6" /usr/bin/qemu-aarch64)
  local missing=() i status
  for i in "${!packages[@]}"; do
    status=$(dpkg-query -W -f='${Status}' "${packages[$i]}" 2>/dev/null || true)
    if [[ "$status" != "install ok installed" || ! -e "${witnesses[$i]}" ]]; then
      missing+=("${packages[$i]}")
    fi
  done
  if ((${#missing[@]} == 0)); then
    return
  fi
  echo "aarch64.sh: installing ${missing[*]} (apt, ~56 MB)"
  local sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    sudo=(sudo)
  fi
  local apt_opts=(-o DPkg::Lock::Timeout=600 -q)
  export DEBIAN_FRONTEND=noninteractive
  "${sudo[@]}" apt-get "${apt_opts[@]}" update
  "${sudo[@]}" apt-get "${apt_opts[@]}" install -y --no-install-recommends "${missing[@]}"
}

cmd_build() {
  install_tools
  [[ -x /usr/bin/rustc && -e /usr/lib/rustlib/src/rust/library/std/Cargo.toml ]] || {
    echo "aarch64.sh: Debian's rustc or rust-web-src missing; run tools/setup.sh" >&2
    exit 1
  }
  local start=$SECONDS
  # Variables that would override the target, its flags or the output dir are dropped
  # (RUSTFLAGS would also reach the build scripts' host builds here).
  (
    cd "$root"
    env -u RUSTFLAGS -u CARGO_ENCODED_RUSTFLAGS -u CARGO_BUILD_TARGET -u CARGO_TARGET_DIR \
      -u RUSTUP_TOOLCHAIN -u CARGO_BUILD_RUSTFLAGS \
      RUSTC_BOOTSTRAP=1 RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc \
      CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
      CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc \
      AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar \
      CARGO_PROFILE_AARCH64_INHERITS=release \
      CARGO_PROFILE_AARCH64_DEBUG=0 \
      CARGO_PROFILE_AARCH64_OPT_LEVEL=3 \
      /usr/bin/cargo build -Z build-std=std,panic_abort --target "$target" \
      --profile aarch64 --config "profile.aarch64.package.\"*\".opt-level=$deps_opt" \
      --target-dir "$target_dir" -p msreg --bin msreg
  )
  echo "aarch64.sh: build took $((SECONDS - start)) s"
  file "$bin"
  echo "size: $(stat -c %s "$bin") bytes"
}

# emulate ARGS...: runs the aarch64 binary under qemu-aarch64 user mode (time, exit status).
emulate() {
  local start=$SECONDS status=0
  echo "\$ qemu-aarch64 -L $sysroot msreg $*"
  timeout "$timeout_s" qemu-aarch64 -L "$sysroot" "$bin" "$@" </dev/null || status=$?
  echo "(${status}; $((SECONDS - start)) s under emulation)"
  return "$status"
}

fail() {
  echo "aarch64.sh test: FAILED: $*" >&2
  exit 1
}

check_version() {
  local out
  out=$(emulate --version) || fail "msreg --version exited non-zero"
  echo "$out"
  grep -Eq '^msreg [0-9]+\.[0-9]+\.[0-9]+' <<<"$out" || fail "msreg --version printed no version"
}

check_demo() {
  local out
  out=$(emulate demo --only pose-imu 2>&1) || fail "msreg demo --only pose-imu exited non-zero"
  echo "$out"
  # The table's pose-imu row: "pose0  <rot err> <3-sigma> <trans err> <3-sigma> <time err> yes".
  awk '$0 == "pose-imu:" { section = 1; next }
       section && $1 == "pose0" && NF == 7 && $7 == "yes" { found = 1 }
       END { exit !found }' <<<"$out" ||
    fail "demo: no pose-imu row with its errors inside 3 sigma"
  grep -Eq '^pose-imu +converged' <<<"$out" || fail "demo: pose-imu did not converge"
}

check_monitor() {
  local dir=$1 out status=0
  emulate simulate drive "$dir/drive" --seed 1 --duration 20 --knock-s 10 --knock-deg 1 \
    --knock-sensor pose1 || fail "msreg simulate drive exited non-zero"
  out=$(emulate monitor "$dir/drive" --report "$dir/report.json" 2>&1) ||
    status=$?
  echo "$out"
  ((status == monitor_alarm_exit)) ||
    fail "monitor exited $status, expected $monitor_alarm_exit (a calibration changed)"
  python3 - "$dir/report.json" "$dir/drive/groundtruth/extrinsics.yaml" <<'EOF' ||
import json, math, re, sys

report = json.load(open(sys.argv[1]))
knock_s = 10.0
alarms = [(a["sensor"], a["t_s"]) for a in report["alarms"]]
print(f"alarms (sensor, s): {alarms}")
assert alarms, "no alarm after a 1 deg camera knock"
assert all(s == "pose1" for s, _ in alarms), "an alarm on a sensor that was not knocked"
assert all(knock_s <= t <= knock_s + 5.0 for _, t in alarms), "an alarm before or long after the knock"
# The camera's mounting at the end (after the knock) against its re-estimate.
text = open(sys.argv[2]).read().split("\npose1:")[1]
truth = [[float(x) for x in row.split(",")] for row in re.findall(r"- \[([^\]]*)\]", text)[:3]]
sensor = next(s for s in report["sensors"] if s["name"] == "pose1")
est = sensor["final_t_imu_pose"]
trace = sum(est[i][j] * truth[i][j] for i in range(3) for j in range(3))
rot_err = math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1.0) / 2.0))))
trans_err = math.dist([est[i][3] for i in range(3)], [truth[i][3] for i in range(3)])
rot_3s = 3.0 * math.hypot(*sensor["final_sigma_rot_deg"])
trans_3s = 3.0 * math.hypot(*sensor["final_sigma_trans_m"])
print(f"camera after the knock: rotation error {rot_err:.3f} deg (3 sigma {rot_3s:.3f}), "
      f"translation error {trans_err * 1e3:.1f} mm (3 sigma {trans_3s * 1e3:.1f})")
assert rot_err < rot_3s and trans_err < trans_3s, "re-estimated camera mounting outside 3 sigma"
EOF
    fail "monitor: its report does not show the knock (see above)"
}

cmd_test() {
  cmd_build
  # Global: the EXIT trap runs after this function has returned.
  scratch=$(mktemp -d)
  trap 'rm -rf "$scratch"' EXIT
  local start=$SECONDS
  check_version
  check_demo
  check_monitor "$scratch"
  echo "aarch64.sh test: PASS (qemu-aarch64 runs took $((SECONDS - start)) s)"
}

case "${1:-}" in
  build) cmd_build ;;
  test) cmd_test ;;
  *) usage ;;
esac
