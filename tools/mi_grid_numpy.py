#!/usr/bin/env python3
"""NumPy anchor for the prior-map MI benchmark of issue 15 (docs/benchmarks.md).

Runs the grid of `msreg calibrate prior-map` on exactly the problem that
`cargo run --release -p msreg-host --example prior_map_bench` writes to its directory (default
/tmp/prior_map_bench): the same grid points with their rank-normalised reflectivity
(points.bin), the same equalised and blurred fisheye image (image.f32), the same
equidistant camera, start pose and lattice (problem.txt). A plain vectorised implementation
of the same score: every candidate pose projects all grid points (depth > min depth,
equidistant model), samples the image bilinearly where the 2 x 2 neighbourhood is inside,
bins both values into `bins` x `bins` hard bins and takes the plug-in MI. The lattice is
the coarse-to-fine one of `msreg_host::mi::search::grid_search`: 2 steps + 1 values per
axis around the best so far, the spacing divided by `steps` per level. No refinement.

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy
    /tmp/venv/bin/python tools/mi_grid_numpy.py /tmp/prior_map_bench
"""
import itertools
import os
import sys
import time

import numpy as np


def load(d):
    pts = np.fromfile(f"{d}/points.bin", dtype="<f8").reshape(-1, 4)
    lines = [l.split() for l in open(f"{d}/problem.txt") if not l.startswith("#")]
    w, h = map(int, lines[0])
    img = np.fromfile(f"{d}/image.f32", dtype="<f4").reshape(h, w).astype(np.float64)
    cam = list(map(float, lines[1]))
    start = np.array(list(map(float, lines[2]))).reshape(4, 4)
    truth = np.array(list(map(float, lines[3]))).reshape(4, 4)
    g = lines[4]
    grid = {
        "half": np.array(list(map(float, g[:4]))),
        "steps": int(g[4]),
        "levels": int(g[5]),
        "bins": int(g[6]),
        "min_depth": float(g[7]),
    }
    return pts, img, cam, start, truth, grid


def project(cam, pc):
    """Equidistant fisheye (msreg's estimator/src/camera/equidistant.rs)."""
    fu, fv, cu, cv, k1, k2, k3, k4 = cam
    rho = np.hypot(pc[:, 0], pc[:, 1])
    th = np.arctan2(rho, pc[:, 2])
    t2 = th * th
    thd = th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    s = np.where(rho > 1e-12, thd / np.maximum(rho, 1e-12), 1.0 / pc[:, 2])
    return fu * pc[:, 0] * s + cu, fv * pc[:, 1] * s + cv, th


def mi(xyz, vals, img, cam, t_world_cam, bins, min_depth):
    r, t = t_world_cam[:3, :3], t_world_cam[:3, 3]
    pc = (xyz - t) @ r
    u, v, th = project(cam, pc)
    h, w = img.shape
    ok = (pc[:, 2] >= min_depth) & (th <= 3.0) & (u >= 0) & (v >= 0) & (u < w - 1) & (v < h - 1)
    u, v, a = u[ok], v[ok], vals[ok]
    x0, y0 = u.astype(np.int64), v.astype(np.int64)
    fx, fy = u - x0, v - y0
    top = img[y0, x0] + (img[y0, x0 + 1] - img[y0, x0]) * fx
    bot = img[y0 + 1, x0] + (img[y0 + 1, x0 + 1] - img[y0 + 1, x0]) * fx
    b = top + (bot - top) * fy
    ia = np.minimum((np.clip(a, 0, 1) * bins).astype(np.int64), bins - 1)
    ib = np.minimum((np.clip(b, 0, 1) * bins).astype(np.int64), bins - 1)
    joint = np.bincount(ia * bins + ib, minlength=bins * bins).astype(np.float64)
    p = joint / max(joint.sum(), 1)
    pa, pb = p.reshape(bins, bins).sum(1), p.reshape(bins, bins).sum(0)

    def ent(q):
        q = q[q > 0]
        return -(q * np.log(q)).sum()

    return float(ent(pa) + ent(pb) - ent(p))


def pose(start, c):
    """`msreg_host::mi::prior_map::grid_pose`: translation added in W, yaw about W z."""
    cy, sy = np.cos(c[3]), np.sin(c[3])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    out = np.eye(4)
    out[:3, :3] = rz @ start[:3, :3]
    out[:3, 3] = start[:3, 3] + c[:3]
    return out


def yaw_error_deg(x, truth):
    r = x[:3, :3] @ truth[:3, :3].T
    angle = np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    n = np.linalg.norm(axis)
    return float(np.degrees(angle * axis[2] / n)) if n > 0 else 0.0


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "/tmp/prior_map_bench"
    pts, img, cam, start, truth, g = load(d)
    xyz, vals = pts[:, :3], pts[:, 3]
    steps, levels = g["steps"], g["levels"]
    centre = np.zeros(4)
    spacing = g["half"] / max(steps, 1)
    best_mi, evals = -np.inf, 0
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(levels):
        best = None
        for k in itertools.product(range(-steps, steps + 1), repeat=4):
            c = centre + np.array(k) * spacing
            m = mi(xyz, vals, img, cam, pose(start, c), g["bins"], g["min_depth"])
            evals += 1
            if best is None or m > best[0]:
                best = (m, c)
        if best[0] > best_mi:
            best_mi, centre = best
        spacing /= max(steps, 2)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    x = pose(start, centre)
    dp = np.linalg.norm(x[:3, 3] - truth[:3, 3]) * 100
    print(
        f"| NumPy 4-DoF grid ({levels} levels x {(2 * steps + 1) ** 4} candidates, hard MI, "
        f"{len(xyz)} points) | {wall:.3f} | {cpu:.2f} | {evals} | {best_mi:.5f} | "
        f"d = ({centre[0]:.3f}, {centre[1]:.3f}, {centre[2]:.3f}) m, "
        f"{np.degrees(centre[3]):.3f} deg; error {dp:.1f} cm, yaw {yaw_error_deg(x, truth):.3f} deg |"
    )
    print(f"numpy {np.__version__}, OMP/BLAS threads {os.environ.get('OMP_NUM_THREADS', 'default')}")


if __name__ == "__main__":
    main()
