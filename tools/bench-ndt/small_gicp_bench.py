#!/usr/bin/env python3
"""small_gicp GICP on the pre-voxelised pairs written by `ndt_bench prepare`.

Usage: small_gicp_bench.py <prepared-dir> <runs>
Prints one `RESULT small_gicp-GICP <pair> <median_ms> <iterations> <converged> <16 numbers>`
line per pair (the format of pcl_ndt.cpp and ndt_bench). The inputs are already
0.2 m voxel centroids, so small_gicp is told to downsample at the same 0.2 m
(a no-op up to its own voxel origin) and time covers its preprocessing
(normals/covariances, kd-tree) plus the registration, like the NDT timings.
"""
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import small_gicp


def read_binary_pcd(path: Path) -> np.ndarray:
    """x, y, z of a `DATA binary` PCD written by msreg (any F4 fields)."""
    data = path.read_bytes()
    header, _, body = data.partition(b"DATA binary\n")
    fields, sizes, n = [], [], 0
    for line in header.decode().splitlines():
        key, *values = line.split()
        if key == "FIELDS":
            fields = values
        elif key == "SIZE":
            sizes = [int(v) for v in values]
        elif key == "POINTS":
            n = int(values[0])
    types = {"TYPE": None}
    for line in header.decode().splitlines():
        if line.startswith("TYPE"):
            types = line.split()[1:]
    kind = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 4): "<u4", ("U", 2): "<u2", ("U", 1): "u1"}
    dtype = np.dtype([(f, kind[(t, s)]) for f, t, s in zip(fields, types, sizes)])
    record = np.frombuffer(body[: n * dtype.itemsize], dtype=dtype, count=n)
    return np.stack([record["x"], record["y"], record["z"]], axis=1).astype(np.float64)


def main() -> None:
    root, runs = Path(sys.argv[1]), int(sys.argv[2])
    for line in (root / "pairs.txt").read_text().splitlines():
        pair, target_file, source_file, *numbers = line.split()
        guess = np.array([float(v) for v in numbers[:16]]).reshape(4, 4)
        target = read_binary_pcd(root / target_file)
        source = read_binary_pcd(root / source_file)
        times, result = [], None
        for _ in range(runs):
            start = time.perf_counter()
            result = small_gicp.align(
                target,
                source,
                init_T_target_source=guess,
                registration_type="GICP",
                downsampling_resolution=0.2,
                max_correspondence_distance=1.0,
                num_threads=2,
            )
            times.append((time.perf_counter() - start) * 1e3)
        t = result.T_target_source
        print(
            f"RESULT small_gicp-GICP {pair} {statistics.median(times):.2f} {result.iterations} "
            f"{int(result.converged)} " + " ".join(f"{v:.9g}" for v in t.reshape(-1))
        )


if __name__ == "__main__":
    main()
