#!/usr/bin/env python3
"""NumPy anchor for the MI benchmark of issue 15 (docs/prior_map.md, docs/benchmarks.md).

The same problem as `cargo run --release -p msreg --example mi_bench` (which writes it to
/tmp/mi_bench): 100k map points, a downward equidistant fisheye, the 4-DoF (x, y, z, yaw)
coarse-to-fine grid with 3 values per axis and 7 levels on every 8th point. A plain
vectorised implementation: project all candidate points, bilinear sampling, hard 24x24
joint histogram (np.histogram2d), MI. No refinement (the grid alone is timed).

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy
    /tmp/venv/bin/python tools/mi_grid_numpy.py /tmp/mi_bench
"""
import itertools
import sys
import time

import numpy as np


def load(d):
    pts = np.fromfile(f"{d}/points.bin", dtype="<f8").reshape(-1, 4)
    with open(f"{d}/image.pgm", "rb") as f:
        assert f.readline().strip() == b"P5"
        w, h = map(int, f.readline().split())
        f.readline()
        img = np.frombuffer(f.read(), dtype=np.uint8).reshape(h, w).astype(np.float64)
    lines = [l for l in open(f"{d}/problem.txt") if not l.startswith("#")]
    cam = list(map(float, lines[0].split()))
    start = np.array(list(map(float, lines[1].split()))).reshape(4, 4)
    truth = np.array(list(map(float, lines[2].split()))).reshape(4, 4)
    hx, hy, hz, hyaw, steps, levels, sub = lines[3].split()
    grid = ([float(hx), float(hy), float(hz), np.radians(float(hyaw))], int(steps), int(levels), int(sub))
    return pts, img, cam, start, truth, grid


def blur(img, sigma):
    r = int(np.ceil(3 * sigma))
    k = np.exp(-np.arange(-r, r + 1) ** 2 / (2 * sigma * sigma))
    k /= k.sum()
    pad = np.pad(img, r, mode="edge")
    rows = np.apply_along_axis(lambda m: np.convolve(m, k, mode="valid"), 1, pad)
    return np.apply_along_axis(lambda m: np.convolve(m, k, mode="valid"), 0, rows)


def equalize(img):
    hist = np.bincount(np.clip(np.round(img), 0, 255).astype(int).ravel(), minlength=256)
    cdf = (np.cumsum(hist) - 0.5 * hist) / img.size
    return cdf[np.clip(np.round(img), 0, 255).astype(int)]


def project(cam, pc):
    fu, fv, cu, cv, k1, k2, k3, k4 = cam
    r = np.hypot(pc[:, 0], pc[:, 1])
    th = np.arctan2(r, pc[:, 2])
    thd = th * (1 + k1 * th**2 + k2 * th**4 + k3 * th**6 + k4 * th**8)
    s = np.where(r > 1e-12, thd / np.maximum(r, 1e-12), 1.0)
    return fu * pc[:, 0] * s + cu, fv * pc[:, 1] * s + cv


def mi(pts, vals, img, cam, t_world_cam, bins=24):
    r, t = t_world_cam[:3, :3], t_world_cam[:3, 3]
    pc = (pts - t) @ r
    u, v = project(cam, pc)
    h, w = img.shape
    ok = (pc[:, 2] > 0.5) & (u >= 0) & (v >= 0) & (u < w - 1) & (v < h - 1)
    u, v, a = u[ok], v[ok], vals[ok]
    x0, y0 = u.astype(int), v.astype(int)
    fx, fy = u - x0, v - y0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bot = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    b = top * (1 - fy) + bot * fy
    joint, _, _ = np.histogram2d(a, b, bins=bins, range=[[0, 1], [0, 1]])
    p = joint / max(joint.sum(), 1)
    pa, pb = p.sum(1), p.sum(0)
    nz = p > 0
    return float((p[nz] * np.log(p[nz] / np.outer(pa, pb)[nz])).sum())


def pose(start, c):
    cy, sy = np.cos(c[3]), np.sin(c[3])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    out = np.eye(4)
    out[:3, :3] = rz @ start[:3, :3]
    out[:3, 3] = start[:3, 3] + c[:3]
    return out


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "/tmp/mi_bench"
    pts, img, cam, start, truth, (half, steps, levels, sub) = load(d)
    t0 = time.perf_counter()
    image = blur(equalize(img), 4.0)
    vals = np.argsort(np.argsort(pts[:, 3], kind="stable"), kind="stable") / (len(pts) - 1)
    p, a = pts[::sub, :3], vals[::sub]
    t_setup = time.perf_counter() - t0
    centre = np.zeros(4)
    spacing = np.array(half) / max(steps, 1)
    best_mi, evals = -np.inf, 0
    t0 = time.perf_counter()
    for _ in range(levels):
        best = None
        for k in itertools.product(range(-steps, steps + 1), repeat=4):
            c = centre + np.array(k) * spacing
            m = mi(p, a, image, cam, pose(start, c))
            evals += 1
            if best is None or m > best[0]:
                best = (m, c)
        if best[0] > best_mi:
            best_mi, centre = best
        spacing /= max(steps, 2)
    t_grid = time.perf_counter() - t0
    x = pose(start, centre)
    dp = np.linalg.norm(x[:3, 3] - truth[:3, 3]) * 100
    dr = np.degrees(np.arccos(np.clip((np.trace(truth[:3, :3].T @ x[:3, :3]) - 1) / 2, -1, 1)))
    print(f"| NumPy grid ({levels} levels x {(2 * steps + 1) ** 4} candidates, {len(p)} points) "
          f"| {t_grid:.3f} | {evals} | {dp:.1f} | {dr:.3f} |")
    print(f"setup {t_setup:.3f} s; numpy {np.__version__}")


if __name__ == "__main__":
    main()
