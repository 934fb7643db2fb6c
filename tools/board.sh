#!/usr/bin/env bash
# Builds and sizes the real-board target boards/nucleo-f446re (NUCLEO-F446RE: STM32F446RE,
# Cortex-M4F at 180 MHz, 512 KiB flash, 128 KiB RAM) with Debian's Rust toolchain and
# build-std, as tools/firmware.sh does for the QEMU board. No hardware is needed.
#
#   tools/board.sh build    release ELF (boards/nucleo-f446re/target/thumbv7em-none-eabihf/
#                           release/msreg-nucleo-f446re)
#   tools/board.sh size     build, then flash (.vector_table+.text+.rodata+.data) and static
#                           RAM (.data+.bss+.uninit) against 512 KiB / 128 KiB, the stack
#                           reservation, and a check that the vector table is at 0x0800_0000
#   tools/board.sh clippy   Debian's clippy over the board crate (-D warnings)
#   tools/board.sh run      flash and run on an attached board (cargo run: probe-rs)
#
# Needs tools/setup.sh to have run. BOARD_FEATURES (e.g. session-local-imu) is passed to cargo.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
board="$root/boards/nucleo-f446re"
target=thumbv7em-none-eabihf
bin=msreg-nucleo-f446re
elf="$board/target/$target/release/$bin"
features=(${BOARD_FEATURES:+--features "$BOARD_FEATURES"})

usage() {
  sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  exit 2
}

# Debian's cargo from inside the crate directory (tools/debian_cargo.sh).
source "$root/tools/debian_cargo.sh"
debian_cargo() {
  debian_cargo_in "$board" "$@"
}

build() {
  debian_cargo build --release "${features[@]}"
}

# section_sizes ELF: "name size" per allocated section.
section_sizes() {
  local name size
  readelf -SW "$1" | sed 's/^ *\[ *[0-9]*\]//' | awk '$1 ~ /^\./ { print $1, $3, $5 }' |
    while read -r name addr size; do echo "$name $((16#$addr)) $((16#$size))"; done
}

# symbol ELF NAME: the value of a symbol, decimal.
symbol() {
  local hex
  hex=$(readelf -sW "$1" | awk -v s="$2" '$8 == s { print $2; exit }')
  [[ -n "$hex" ]] || { echo "board.sh: no symbol $2 in $1" >&2; exit 1; }
  echo $((16#$hex))
}

cmd_size() {
  build
  local sizes
  sizes=$(section_sizes "$elf")
  get() { awk -v s="$1" -v f="$2" '$1 == s { print $f; found = 1 } END { if (!found) print 0 }' <<<"$sizes"; }
  local vt_addr text rodata data bss uninit
  vt_addr=$(get .vector_table 2)
  if ((vt_addr != 0x08000000)); then
    printf 'board.sh: .vector_table at 0x%08x, not 0x08000000: the wrong memory.x was linked\n' \
      "$vt_addr" >&2
    exit 1
  fi
  text=$(( $(get .vector_table 3) + $(get .text 3) ))
  rodata=$(get .rodata 3)
  data=$(get .data 3)
  bss=$(get .bss 3)
  uninit=$(get .uninit 3)
  local flash=$((text + rodata + data)) ram=$((data + bss + uninit))
  local reserve stack_start stack_end
  reserve=$(symbol "$elf" STACK_RESERVE)
  stack_start=$(symbol "$elf" _stack_start)
  stack_end=$(symbol "$elf" _stack_end)
  local flash_budget=$((512 * 1024)) ram_budget=$((128 * 1024))
  pct() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f%%", 100 * a / b }'; }
  echo "board size ($bin, release, $target, STM32F446RE${BOARD_FEATURES:+, features $BOARD_FEATURES}):"
  echo
  echo "| region | bytes | of budget |"
  echo "|---|---:|---:|"
  echo "| flash (.vector_table+.text+.rodata+.data) | $flash | $(pct "$flash" "$flash_budget") of 512 KiB |"
  echo "| static RAM (.data+.bss+.uninit) | $ram | $(pct "$ram" "$ram_budget") of 128 KiB |"
  echo "| stack reservation (memory.x STACK_RESERVE, link-checked) | $reserve | $(pct "$reserve" "$ram_budget") of 128 KiB |"
  echo "| RAM left to the stack (top of RAM - end of statics) | $((stack_start - stack_end)) | $(pct $((stack_start - stack_end)) "$ram_budget") of 128 KiB |"
  echo
  echo "(.text $text incl. vector table at 0x08000000, .rodata $rodata, .data $data, .bss $bss, .uninit $uninit)"
}

[[ $# -ge 1 ]] || usage
case "$1" in
  build) build ;;
  size) cmd_size ;;
  clippy) PATH=/usr/bin:$PATH debian_cargo clippy --release "${features[@]}" -- -D warnings ;;
  run) debian_cargo run --release "${features[@]}" ;;
  *) usage ;;
esac
