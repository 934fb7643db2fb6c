#!/usr/bin/env python3
"""Turns RESULT lines (stdin) and pairs.txt into the markdown table of docs/ndt.md.

Errors: pairs with a `matrix` reference get |dt| and the angle of R_ref^T R;
room-pcl (`t_yaw`: the consensus of four registrations gives t and yaw only)
gets |t - t_consensus| and |yaw - 40.8 deg|.
Usage: summarise.py <prepared-dir> < results.txt
"""
import math
import sys
from pathlib import Path

import numpy as np


def main() -> None:
    refs = {}
    for line in (Path(sys.argv[1]) / "pairs.txt").read_text().splitlines():
        f = line.split()
        refs[f[0]] = (f[19], [float(v) for v in f[20:]])
    print("| method | pair | time (median) | iterations | converged | translation error | rotation error |")
    print("|---|---|---:|---:|---|---:|---:|")
    for line in sys.stdin:
        if not line.startswith("RESULT"):
            continue
        _, method, pair, ms, iterations, converged, *m = line.split()
        t = np.array([float(v) for v in m]).reshape(4, 4)
        kind, ref = refs[pair]
        if kind == "matrix":
            r = np.array(ref).reshape(4, 4)
            dt = np.linalg.norm(t[:3, 3] - r[:3, 3])
            c = (np.trace(r[:3, :3].T @ t[:3, :3]) - 1.0) / 2.0
            dr = math.degrees(math.acos(max(-1.0, min(1.0, c))))
            rot = f"{dr:.3f} deg"
        else:
            dt = np.linalg.norm(t[:3, 3] - np.array(ref[:3]))
            yaw = math.degrees(math.atan2(t[1, 0], t[0, 0]))
            rot = f"{abs(yaw - ref[3]):.3f} deg (yaw)"
        ok = "yes" if converged == "1" else "no"
        print(f"| {method} | {pair} | {float(ms):.1f} ms | {iterations} | {ok} | {dt * 100:.2f} cm | {rot} |")


if __name__ == "__main__":
    main()
