#!/usr/bin/env bash
# Builds, runs, sizes and benchmarks the Cortex-M4F firmware (firmware/) with Debian's Rust
# toolchain and build-std, on QEMU's mps2-an386 board (../shared/docs/EMBEDDED.md).
#
#   tools/firmware.sh build   build both binaries (release profile of firmware/Cargo.toml)
#   tools/firmware.sh run     boot the self-test in QEMU; fails unless it prints
#                             "firmware self-test: PASS" and exits 0
#   tools/firmware.sh size    flash (.text+.rodata+.data), static RAM (.data+.bss+.uninit)
#                             and the stack reservation, against the 1 MiB / 192 KiB budget
#   tools/firmware.sh bench [OPT_LEVEL...]
#                             instructions per IMU propagation and per relative-pose update
#                             (SysTick under -icount shift=0), one row per opt-level
#                             (default: the release profile's level, then "s")
#
# Needs tools/setup.sh to have run. Set FIRMWARE_TIMEOUT (s, default 120) for run/bench.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
fw="$root/firmware"
target=thumbv7em-none-eabihf
timeout_s=${FIRMWARE_TIMEOUT:-120}

usage() {
  sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  exit 2
}

# Debian's cargo with Debian's rustc, from inside firmware/ so that firmware/.cargo/config.toml
# (target, runner, linker, build-std) applies. Variables that would override that config
# (RUSTFLAGS replaces target.rustflags, a CARGO_TARGET_DIR moves the output) are dropped.
debian_cargo() {
  (
    cd "$fw"
    env -u RUSTFLAGS -u CARGO_ENCODED_RUSTFLAGS -u CARGO_BUILD_TARGET -u CARGO_TARGET_DIR \
      -u RUSTUP_TOOLCHAIN -u CARGO_BUILD_RUSTFLAGS \
      RUSTC_BOOTSTRAP=1 RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc \
      /usr/bin/cargo "$@"
  )
}

# The opt-level of [profile.release] in firmware/Cargo.toml.
profile_opt_level() {
  awk '/^\[/ { release = ($0 == "[profile.release]") }
       release && $1 == "opt-level" { gsub(/"/, "", $3); print $3; exit }' "$fw/Cargo.toml"
}

# build [OPT_LEVEL]: release build; another opt-level than the profile's goes to its own
# target dir (so the default build stays cached).
build() {
  local opt=${1:-}
  if [[ -z "$opt" || "$opt" == "$(profile_opt_level)" ]]; then
    debian_cargo build --release
    out_dir="$fw/target/$target/release"
  else
    CARGO_PROFILE_RELEASE_OPT_LEVEL=$opt debian_cargo build --release \
      --target-dir "$fw/target/opt-$opt"
    out_dir="$fw/target/opt-$opt/$target/release"
  fi
}

# The QEMU command line of the runner in firmware/.cargo/config.toml, so there is one copy.
qemu_cmd() {
  local runner
  runner=$(sed -n 's/^runner = "\(.*\)"$/\1/p' "$fw/.cargo/config.toml")
  [[ -n "$runner" ]] || { echo "firmware.sh: no runner in firmware/.cargo/config.toml" >&2; exit 1; }
  read -r -a qemu <<<"$runner"
}

# boot ELF [EXTRA_QEMU_ARGS...]: runs the ELF in QEMU (stdin closed) with a timeout; the
# guest's semihosting exit code is the status.
boot() {
  local elf=$1
  shift
  qemu_cmd
  local kernel_flag=${qemu[${#qemu[@]}-1]}
  timeout "$timeout_s" "${qemu[@]:0:${#qemu[@]}-1}" "$@" "$kernel_flag" "$elf" </dev/null
}

cmd_run() {
  build
  local log="$fw/target/selftest.log" status=0
  boot "$out_dir/msreg-firmware" | tee "$log" || status=$?
  if ((status == 124)); then
    echo "firmware.sh run: QEMU timed out after ${timeout_s}s" >&2
  fi
  if ((status != 0)) || ! grep -qx 'firmware self-test: PASS' "$log"; then
    echo "firmware.sh run: self-test FAILED (exit status $status)" >&2
    exit 1
  fi
}

# section_sizes ELF: "name size" per allocated section (llvm-size if present, else readelf).
section_sizes() {
  if command -v llvm-size >/dev/null; then
    llvm-size -A -d "$1" | awk 'NR > 2 && $1 ~ /^\./ { print $1, $2 }'
  else
    local name size
    readelf -SW "$1" | sed 's/^ *\[ *[0-9]*\]//' | awk '$1 ~ /^\./ { print $1, $5 }' |
      while read -r name size; do echo "$name $((16#$size))"; done
  fi
}

# symbol ELF NAME: the value of a symbol, decimal.
symbol() {
  local hex
  hex=$(readelf -sW "$1" | awk -v s="$2" '$8 == s { print $2; exit }')
  [[ -n "$hex" ]] || { echo "firmware.sh: no symbol $2 in $1" >&2; exit 1; }
  echo $((16#$hex))
}

cmd_size() {
  build
  local elf="$out_dir/msreg-firmware" sizes text rodata data bss uninit
  sizes=$(section_sizes "$elf")
  get() { awk -v s="$1" '$1 == s { print $2; f = 1 } END { if (!f) print 0 }' <<<"$sizes"; }
  text=$(( $(get .vector_table) + $(get .text) ))
  rodata=$(get .rodata)
  data=$(get .data)
  bss=$(get .bss)
  uninit=$(get .uninit)
  local flash=$((text + rodata + data)) ram=$((data + bss + uninit))
  local stack_start stack_end reserve
  stack_start=$(symbol "$elf" _stack_start)
  stack_end=$(symbol "$elf" _stack_end)
  reserve=$(symbol "$elf" STACK_RESERVE)
  local available=$((stack_start - stack_end))
  local flash_budget=$((1024 * 1024)) ram_budget=$((192 * 1024))
  pct() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f%%", 100 * a / b }'; }
  echo "firmware size (msreg-firmware, release, $target):"
  echo
  echo "| region | bytes | of budget |"
  echo "|---|---:|---:|"
  echo "| flash (.text+.rodata+.data) | $flash | $(pct "$flash" "$flash_budget") of 1 MiB |"
  echo "| static RAM (.data+.bss+.uninit) | $ram | $(pct "$ram" "$ram_budget") of 192 KiB |"
  echo "| stack reservation (memory.x STACK_RESERVE, link-checked) | $reserve | $(pct "$reserve" "$ram_budget") of 192 KiB |"
  echo "| RAM left to the stack (top of RAM - end of statics) | $available | $(pct "$available" "$ram_budget") of 192 KiB |"
  echo
  echo "(.text $text incl. vector table, .rodata $rodata, .data $data, .bss $bss, .uninit $uninit)"
  local log="$fw/target/selftest.log"
  if [[ -f "$log" ]] && grep -q '^stack:' "$log"; then
    echo "peak stack measured by the last 'run': $(grep '^stack:' "$log")"
  fi
}

# bench [OPT_LEVEL...]: one table row per opt-level.
cmd_bench() {
  local levels=("$@")
  ((${#levels[@]} > 0)) || levels=("$(profile_opt_level)" s)
  local rows=() opt log flash
  for opt in "${levels[@]}"; do
    echo "bench: building with opt-level=$opt" >&2
    build "$opt" >&2
    log="$fw/target/bench-opt-$opt.log"
    boot "$out_dir/bench" -icount shift=0 >"$log" || {
      cat "$log" >&2
      echo "firmware.sh bench: bench binary failed at opt-level=$opt" >&2
      exit 1
    }
    flash=$(section_sizes "$out_dir/bench" |
      awk '$1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" || $1 == ".data" { s += $2 }
           END { print s }')
    # BENCH <name> <calls> <mean instructions> <max instructions>
    rows+=("$(awk -v opt="$opt" -v flash="$flash" '
      $1 == "BENCH" { mean[$2] = $4; max[$2] = $5; calls[$2] = $3 }
      $1 == "STACK" { stack[$2] = $3 }
      $1 == "RATE" { rate = $2 }
      END {
        printf "| %s | %d | %d (max %d) | %d (max %d) | %d | %.1f | %d / %d |", opt, flash,
          mean["propagate"], max["propagate"], mean["update"], max["update"],
          mean["zero_velocity"], rate / 1e6, stack["propagate"], stack["update"]
      }' "$log")")
    echo "bench: opt-level=$opt done ($log)" >&2
  done
  echo
  echo "Instructions on the emulated Cortex-M4F (QEMU mps2-an386, SysTick under -icount shift=0,"
  echo "40 instructions per tick; per call, mean over the embedded 3 s sequence):"
  echo
  echo "| opt-level | flash (B) | instr / IMU propagation | instr / relative-pose update | instr / zero-velocity update | M instr / s of data (400 Hz IMU + 10 Hz poses) | stack propagate / update (B) |"
  echo "|---|---|---|---|---|---|---|"
  printf '%s\n' "${rows[@]}"
}

[[ $# -ge 1 ]] || usage
command=$1
shift
case "$command" in
  build) build ;;
  run) cmd_run ;;
  size) cmd_size ;;
  bench) cmd_bench "$@" ;;
  *) usage ;;
esac
