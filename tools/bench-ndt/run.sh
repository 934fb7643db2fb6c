#!/usr/bin/env bash
# NDT benchmark (not a test): msreg's NDT vs PCL 1.13's NDT vs small_gicp's GICP
# on the real pairs of ../shared/data/lidar-pairs and a synthetic 128x1024 pair,
# same 0.2 m voxelised inputs (written once by `ndt_bench prepare`), same start
# guesses. Prints a markdown table (see docs/ndt.md).
# Usage: tools/bench-ndt/run.sh [runs=11] [shared-data-dir]
# Installs libpcl-dev (apt) and small_gicp (pip) when missing; idempotent.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
here="$root/tools/bench-ndt"
runs=${1:-11}
data=${2:-$root/../shared/data}
work=${BENCH_NDT_DIR:-$root/target/bench-ndt}
mkdir -p "$work"

cargo_bin="${CARGO_HOME:-$HOME/.cargo}/bin"
[[ -d "$cargo_bin" ]] && PATH="$cargo_bin:$PATH"
sudo=()
[[ $(id -u) -ne 0 ]] && sudo=(sudo)

if [[ ! -f /usr/include/pcl-1.13/pcl/registration/ndt.h ]]; then
  echo "bench-ndt: installing libpcl-dev (apt)" >&2
  "${sudo[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq libpcl-dev >&2
fi
if ! python3 -c 'import small_gicp' 2>/dev/null; then
  echo "bench-ndt: installing small_gicp (pip)" >&2
  python3 -m pip install -q small_gicp >&2
fi

if [[ ! -x "$work/pcl_ndt" || "$here/pcl_ndt.cpp" -nt "$work/pcl_ndt" ]]; then
  # No -march=native: Eigen alignment must match how Debian built PCL.
  echo "bench-ndt: compiling pcl_ndt.cpp" >&2
  g++ -O2 -std=c++17 -o "$work/pcl_ndt" "$here/pcl_ndt.cpp" \
    -I/usr/include/pcl-1.13 -I/usr/include/eigen3 \
    -lpcl_registration -lpcl_io -lpcl_kdtree -lpcl_search -lpcl_filters -lpcl_common \
    -lboost_system >&2
fi

(cd "$root" && cargo build -q --release -p msreg-host --example ndt_bench >&2)
bench="$root/target/release/examples/ndt_bench"
"$bench" prepare "$work" "$data"

results="$work/results.txt"
: > "$results"
"$bench" run "$work" "$runs" | tee -a "$results" >&2
while read -r pair target source rest; do
  read -r -a m <<< "$rest"
  # Start guess as x y z roll pitch yaw from the 4x4 (R = Rz Ry Rx).
  guess=$(python3 -c "
import math, sys
m = [float(v) for v in sys.argv[1:17]]
r = lambda i, j: m[4 * i + j]
yaw = math.atan2(r(1, 0), r(0, 0)); pitch = -math.asin(r(2, 0)); roll = math.atan2(r(2, 1), r(2, 2))
print(r(0, 3), r(1, 3), r(2, 3), roll, pitch, yaw)" "${m[@]:0:16}")
  # shellcheck disable=SC2086
  "$work/pcl_ndt" "$work/$target" "$work/$source" $guess 1.0 0.1 0.01 35 "$runs" \
    "PCL-NDT(eps=0.01)" "$pair" | tee -a "$results" >&2
  # shellcheck disable=SC2086
  "$work/pcl_ndt" "$work/$target" "$work/$source" $guess 1.0 0.1 1e-4 35 "$runs" \
    "PCL-NDT(eps=1e-4)" "$pair" | tee -a "$results" >&2
done < "$work/pairs.txt"
python3 "$here/small_gicp_bench.py" "$work" "$runs" | tee -a "$results" >&2

echo
echo "Machine: $(nproc) cores, $(lscpu | grep 'Model name' | sed 's/Model name:[[:space:]]*//')"
echo "Command: tools/bench-ndt/run.sh $runs"
echo
python3 "$here/summarise.py" "$work" < "$results"
grep '^TIMING' "$results" | sed 's/^TIMING /- /' || true
