#!/usr/bin/env bash
# Installs what tools/test.sh needs on a Debian machine of the project's kind, idempotently:
# Debian's Rust toolchain with the standard library sources (rustc-web, rust-web-src,
# cargo-web: the rustup toolchain has no bare-metal target and no rust-src, and rustup cannot
# download them), the lld linker, and QEMU for the Cortex-M4F board (qemu-system-arm).
# See docs/firmware.md. When everything is present it touches apt not at all and
# takes well under a second.
#
# The host workspace uses the rustup toolchain already on the machine (cargo, rustfmt,
# clippy); those cannot be installed from here, so they are only checked.
#
# Instruction counts use SysTick under `qemu -icount shift=0`, so no QEMU plugin and no
# plugin header are needed (Debian ships no qemu-plugin.h package).
set -euo pipefail

# fonts-dejavu-core: the font of the convergence plots (`--plot`; plotters renders text in pure
# Rust with ab_glyph and reads DejaVuSans.ttf at run time, so no fontconfig/freetype build dep).
packages=(rustc-web rust-web-src cargo-web lld qemu-system-arm fonts-dejavu-core rust-web-clippy)
# A file per package that proves it is usable, in the order of `packages`.
witnesses=(
  /usr/bin/rustc
  /usr/lib/rustlib/src/rust/library/core/Cargo.toml
  /usr/bin/cargo
  /usr/bin/ld.lld
  /usr/bin/qemu-system-arm
  /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf
  /usr/bin/cargo-clippy
)

missing=()
for i in "${!packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "${packages[$i]}" 2>/dev/null || true)
  if [[ "$status" != "install ok installed" || ! -e "${witnesses[$i]}" ]]; then
    missing+=("${packages[$i]}")
  fi
done

if ((${#missing[@]} > 0)); then
  echo "setup: installing ${missing[*]} (apt, ~1.5 min, ~850 MB)"
  sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    sudo=(sudo)
  fi
  export DEBIAN_FRONTEND=noninteractive
  # Another apt (e.g. unattended upgrades) may hold the lock for a while: wait for it.
  apt_opts=(-o DPkg::Lock::Timeout=600 -q)
  "${sudo[@]}" apt-get "${apt_opts[@]}" update
  "${sudo[@]}" apt-get "${apt_opts[@]}" install -y --no-install-recommends "${missing[@]}"
else
  echo "setup: Debian toolchain and QEMU already installed (${packages[*]})"
fi

# Checks that cannot be fixed from here.
cargo_bin="${CARGO_HOME:-$HOME/.cargo}/bin"
for tool in cargo rustfmt cargo-clippy; do
  if [[ ! -x "$cargo_bin/$tool" ]] && ! command -v "$tool" >/dev/null; then
    echo "setup: the rustup toolchain lacks $tool (expected in $cargo_bin)" >&2
    exit 1
  fi
done
if ! /usr/bin/rustc --print target-list | grep -qx thumbv7em-none-eabihf; then
  echo "setup: /usr/bin/rustc does not know thumbv7em-none-eabihf" >&2
  exit 1
fi
echo "setup: ok ($(/usr/bin/rustc --version); $(qemu-system-arm --version | head -n 1))"
