#!/usr/bin/env bash
# The infrastructure bundle adjustment benchmark (issue 14): msreg vs Ceres on the same
# problem, side by side in one run, full size (2000 keyframes, 50k points, 40 cameras,
# ~3.7 M keypoints) and quarter size (500 keyframes, 12.5k points, ~0.93 M keypoints).
#
#   tools/infra_ba_bench.sh [workdir] [sizes: "full quarter"]
#
# msreg runs twice: with conjugate-gradient steps (the default, as `calibrate infra`) and
# with every step exact (`solve --exact`).
# Needs Debian's libceres-dev (apt-get install libceres-dev) for the Ceres side,
# tools/infra_ba_ceres.cc. Both solvers get 2 threads; wall time, CPU time and peak RSS
# from /usr/bin/time -v; both final states are evaluated with msreg's robust cost
# (`infra_ba_bench eval`), so the costs compare one function. Prints a markdown table.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-/tmp/infra-ba-bench}
SIZES=${2:-"full quarter"}
mkdir -p "$WORK"
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-target}
nice -n 10 cargo build --release -p msreg-host --example infra_ba_bench >&2
BENCH=$CARGO_TARGET_DIR/release/examples/infra_ba_bench
CERES=$WORK/infra_ba_ceres
if [[ ! -x $CERES || tools/infra_ba_ceres.cc -nt $CERES ]]; then
  g++ -O2 -march=native -std=c++17 -I/usr/include/eigen3 tools/infra_ba_ceres.cc \
    -o "$CERES" -lceres -lglog -lgflags -lpthread
fi

timed() { # log cmd... -> prints "wall_s cpu_s rss_mb load_start/load_end" (1-min load)
  local log=$1 l0
  shift
  l0=$(cut -d' ' -f1 /proc/loadavg)
  /usr/bin/time -v "$@" >"$log" 2>&1
  awk -F': ' -v l0="$l0" -v l1="$(cut -d' ' -f1 /proc/loadavg)" \
    '/Elapsed \(wall clock\)/ { n = split($2, t, ":"); w = 0; for (i = 1; i <= n; i++) w = w * 60 + t[i] }
     /User time/ { u = $2 } /System time/ { s = $2 }
     /Maximum resident/ { r = $2 / 1024 }
     END { printf "%.1f %.1f %.0f %s/%s", w, u + s, r, l0, l1 }' "$log"
}

echo "| size | solver | observations | final cost (msreg's function) | wall s | CPU s | peak RSS MB | iterations | load start/end |"
echo "|---|---|---|---|---|---|---|---|---|"
for size in $SIZES; do
  case $size in
    full) args=(--keyframes 2000 --points 50000) ;;
    quarter) args=(--keyframes 500 --points 12500) ;;
    *) echo "unknown size $size" >&2; exit 2 ;;
  esac
  P=$WORK/$size.txt
  obs=$("$BENCH" gen "$P" "${args[@]}" | sed 's/.*observations //')
  read -r xw xu xr xl <<<"$(timed "$WORK/$size.exact.log" env RAYON_NUM_THREADS=2 "$BENCH" solve "$P" "$WORK/$size.exact.state" --exact)"
  read -r mw mu mr ml <<<"$(timed "$WORK/$size.msreg.log" env RAYON_NUM_THREADS=2 "$BENCH" solve "$P" "$WORK/$size.msreg.state")"
  read -r cw cu cr cl <<<"$(timed "$WORK/$size.ceres.log" "$CERES" "$P" "$WORK/$size.ceres.state" 2)"
  "$BENCH" eval "$P" "$WORK/$size.exact.state" "$WORK/$size.msreg.state" "$WORK/$size.ceres.state" >"$WORK/$size.eval.log"
  xc=$(awk '/exact.state cost/ { print $3 }' "$WORK/$size.eval.log")
  xi=$(sed -n 's/.*iterations \([0-9]*\).*/\1/p' "$WORK/$size.exact.log")
  mc=$(awk '/msreg.state cost/ { print $3 }' "$WORK/$size.eval.log")
  cc=$(awk '/ceres.state cost/ { print $3 }' "$WORK/$size.eval.log")
  mi=$(sed -n 's/.*iterations \([0-9]*\).*/\1/p' "$WORK/$size.msreg.log")
  ci=$(sed -n 's/^ceres.*iterations \([0-9]*\).*/\1/p' "$WORK/$size.ceres.log")
  echo "| $size | msreg (conjugate-gradient steps, the default) | $obs | $mc | $mw | $mu | $mr | $mi | $ml |"
  echo "| $size | msreg --exact (every step exact) | $obs | $xc | $xw | $xu | $xr | $xi | $xl |"
  echo "| $size | Ceres $(pkg-config --modversion ceres 2>/dev/null || echo 2.1) SPARSE_SCHUR | $obs | $cc | $cw | $cu | $cr | $ci | $cl |"
done
echo
echo "start cost and per-solver logs: $WORK/*.log; load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
