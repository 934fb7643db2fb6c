#!/usr/bin/env python3
"""How much an IMU recording turns, per gyro axis (the numbers of docs/recording.md).

    python3 tools/imu_rates.py <dataset>/imu0/data.csv [...] [--skip-s 2]

Reads an `imu0/data.csv` of the dataset layout (docs/formats.md: stamp [ns], w_x, w_y, w_z
[rad/s], a_x, a_y, a_z) and prints per axis: the rms rate after the first `--skip-s` seconds
(the simulator's still start), the peak rate and the angle turned (the integral of |w|).
Standard library only.
"""
import argparse
import math


def rates(path, skip_s):
    """(duration s, rms per axis, peak per axis, angle turned per axis) of one file."""
    stamps, gyro = [], []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split(",") if "," in line else line.split()
            stamps.append(int(fields[0]))
            gyro.append([float(x) for x in fields[1:4]])
    t = [(s - stamps[0]) * 1e-9 for s in stamps]
    moving = [w for ti, w in zip(t, gyro) if ti > skip_s]
    rms = [math.sqrt(sum(w[i] ** 2 for w in moving) / max(len(moving), 1)) for i in range(3)]
    peak = [max(abs(w[i]) for w in gyro) for i in range(3)]
    turned = [
        sum(abs(gyro[k][i]) * (t[k] - t[k - 1]) for k in range(1, len(t))) for i in range(3)
    ]
    return t[-1], rms, peak, turned


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="+")
    ap.add_argument("--skip-s", type=float, default=2.0)
    args = ap.parse_args()
    fmt = lambda v, p: ", ".join(f"{x:.{p}f}" for x in v)  # noqa: E731
    for path in args.files:
        duration, rms, peak, turned = rates(path, args.skip_s)
        print(
            f"{path}: {duration:.1f} s; rms [{fmt(rms, 2)}] rad/s, peak [{fmt(peak, 2)}] rad/s, "
            f"turned [{fmt(turned, 0)}] rad (x, y, z)"
        )


if __name__ == "__main__":
    main()
