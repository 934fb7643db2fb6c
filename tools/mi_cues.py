#!/usr/bin/env python3
"""Independent cues on the CalibAnything extrinsic (issue 15, docs/prior_map.md).

For each single-frame objective between the LiDAR scan and the image, the rotation
optimum (right increment about the LiDAR axes from the published reference, translation
held at the reference; coordinate pattern search 0.4 -> 0.025 deg, best of three starts:
the reference, the marking-aligned pose, the ground-MI maximum), its curvature sigma
(central second differences at 0.1 deg; MI: information n_eff (-H) with n_eff = occupied
3 px cells, as the command; chamfer: chi^2 = N C / C_opt with N = occupied 10 px cells)
and a 4-strip block jackknife (leave out one quarter of the image columns, re-optimise
from the optimum): the curvature sigma assumes independent samples, the jackknife does
not. Then the inverse-variance mean of the independent cues (lane markings, ground MI,
off-ground MI), each sigma the largest of its curvature, jackknife and systematic ones,
inflated by the Birge ratio when they scatter more than their sigmas.

Usage (NumPy, SciPy, OpenCV in a throwaway venv):
  python3 tools/mi_cues.py [--data ../shared/data/real/calibanything-1]
The lane-marking row is `cargo test --release -p msreg-host --test mi_reference_markings --
--nocapture` (defaults below: its fit, sigmas widened to half the spread over the
detector thresholds, docs/prior_map.md).
"""
import argparse
import os
import sys

import cv2
import numpy as np
from scipy import ndimage

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mi_real_evidence import (Camera, bilinear, equalize, expso3, ground_height, mi,  # noqa: E402
                              ranknorm, read_pcd, read_yaml_numbers, retract)

STARTS = {'reference': (0.0, 0.0, 0.0), 'markings': (0.238, -0.271, -0.014),
          'mi_max': (-0.30, -0.37, 0.16)}


def rot_vec_deg(w0, w):
    """Rotation vector (deg) of Exp(w0) Exp(w)."""
    rv, _ = cv2.Rodrigues(expso3(np.radians(w0)) @ expso3(np.radians(w)))
    return np.degrees(rv.ravel())


def ring_jumps(xyz, ring, min_jump=0.5):
    """Per point: the range step to a farther ring neighbour (foreground side of a
    depth discontinuity), 0 elsewhere."""
    rng, az = np.linalg.norm(xyz, axis=1), np.arctan2(xyz[:, 1], xyz[:, 0])
    jump = np.zeros(len(xyz))
    for r in np.unique(ring):
        idx = np.where(ring == r)[0]
        idx = idx[np.argsort(az[idx])]
        d, gap = np.diff(rng[idx]), np.diff(az[idx]) < np.radians(0.6)
        left, right = gap & (d > min_jump), gap & (-d > min_jump)
        jump[idx[:-1][left]] = np.maximum(jump[idx[:-1][left]], d[left])
        jump[idx[1:][right]] = np.maximum(jump[idx[1:][right]], -d[right])
    return jump


class Frame:
    def __init__(self, data):
        self.cam = Camera(os.path.join(data, 'cam0/camera.yaml'))
        t = read_yaml_numbers(os.path.join(data, 'groundtruth/extrinsics.yaml'), 'T_cam_lidar:')
        self.ref = t.reshape(4, 4)
        xyz, inten, ring = read_pcd(os.path.join(data, 'lidar0/1700000000000000000.pcd'))
        ok = np.isfinite(xyz).all(1)
        xyz, inten, ring = xyz[ok], inten[ok], ring[ok]
        img = cv2.imread(os.path.join(data, 'cam0/data/1700000000000000000.png'),
                         cv2.IMREAD_GRAYSCALE).astype(np.float32)
        u, v, _, vis = self.cam.project(self.ref, xyz)
        # Cross-check of the projection (radtan, 4 coefficients) against OpenCV.
        rv, _ = cv2.Rodrigues(self.ref[:3, :3])
        k = np.array([[self.cam.k[0], 0, self.cam.k[2]], [0, self.cam.k[1], self.cam.k[3]],
                      [0, 0, 1]])
        q, _ = cv2.projectPoints(xyz[vis], rv, self.ref[:3, 3], k, np.r_[self.cam.d, 0.0])
        self.cv_diff = np.abs(q.reshape(-1, 2) - np.c_[u[vis], v[vis]]).max()
        # The command's selection: 100 px inside the image at the reference.
        vis &= (u > 100) & (u < self.cam.w - 100) & (v > 100) & (v < self.cam.h - 100)
        self.p, self.i, self.ring = xyz[vis], inten[vis], ring[vis]
        self.gz = ground_height(self.p[:, 2])
        hp = img - cv2.GaussianBlur(img, (0, 0), 30) + 128
        self.hp = equalize(cv2.GaussianBlur(hp, (0, 0), 1.0))
        can = cv2.Canny(np.clip(cv2.GaussianBlur(img, (0, 0), 1.5), 0, 255).astype(np.uint8),
                        20, 60)
        self.dt = cv2.distanceTransform((can == 0).astype(np.uint8), cv2.DIST_L2, 5)
        self.jump = ring_jumps(xyz, ring)[vis]

    def band(self, b):
        return np.abs(self.p[:, 2] - self.gz) < b

    def ring_highpassed(self):
        """Reflectivity minus its ring-local median (31 points): removes the range /
        incidence / per-beam gain trends."""
        az = np.arctan2(self.p[:, 1], self.p[:, 0])
        out = np.zeros(len(self.p))
        for r in np.unique(self.ring):
            idx = np.where(self.ring == r)[0]
            idx = idx[np.argsort(az[idx])]
            out[idx] = self.i[idx] - ndimage.median_filter(self.i[idx], size=31, mode='nearest')
        return out

    def vertical_edges(self):
        """Range-edge points above the ground with an edge on a neighbouring ring within
        0.4 deg of azimuth and 0.5 m of range (poles, trunks, vehicle sides)."""
        e = (self.jump > 0.5) & (self.p[:, 2] > self.gz + 0.3)
        az, rng = np.arctan2(self.p[:, 1], self.p[:, 0]), np.linalg.norm(self.p, axis=1)
        keep = np.zeros(len(e), bool)
        for k in np.where(e)[0]:
            keep[k] = (e & (np.abs(self.ring - self.ring[k]) == 1)
                       & (np.abs(az - az[k]) < np.radians(0.4))
                       & (np.abs(rng - rng[k]) < 0.5)).any()
        return e & keep

    def pose(self, w_deg):
        return retract(self.ref, np.r_[np.radians(w_deg), 0, 0, 0])

    def project(self, w_deg, mask, strip=None):
        u, v, _, ok = self.cam.project(self.pose(w_deg), self.p[mask])
        if strip is not None:
            ok &= ~((u >= strip[0]) & (u < strip[1]))
        return u, v, ok


def mi_cue(frame, groups):
    """Cost -sum_k n_k MI_k / sum_k n_k over (mask, values) groups, high-passed image."""
    def cost(w, strip=None):
        tot = n = 0
        for m, vals in groups:
            u, v, ok = frame.project(w, m, strip)
            k = ok.sum()
            tot += k * mi(vals[ok], bilinear(frame.hp, u[ok], v[ok]), smooth=1.0)
            n += k
        return -tot / max(n, 1)
    return cost


def chamfer_cue(frame, mask, tau=10.0):
    """Mean squared distance (capped at tau px) of LiDAR range edges to image Canny edges."""
    def cost(w, strip=None):
        u, v, ok = frame.project(w, mask, strip)
        d = np.minimum(bilinear(frame.dt, u[ok], v[ok]), tau)
        return np.mean(d * d)
    return cost


def optimise(cost, start, strip=None, limit=2.5):
    best, fb = np.zeros(3), cost(start, strip)
    for step in (0.4, 0.2, 0.1, 0.05, 0.025):
        improved = True
        while improved:
            improved = False
            for k in range(3):
                for s in (-1, 1):
                    c = best.copy()
                    c[k] += s * step
                    if np.abs(c).max() > limit:
                        continue
                    fc = cost(rot_vec_deg(start, c), strip)
                    if fc < fb:
                        best, fb, improved = c, fc, True
    return rot_vec_deg(start, best), fb


def hessian(cost, w, h=0.1):
    e = np.eye(3) * h
    f = lambda d: cost(rot_vec_deg(w, d))  # noqa: E731
    hm = np.array([[(f(e[i] + e[j]) - f(e[i] - e[j]) - f(e[j] - e[i]) + f(-e[i] - e[j]))
                    / (4 * h * h) for j in range(3)] for i in range(3)])
    return hm, f(np.zeros(3))


def evaluate(frame, name, cost, mask, kind):
    ends = [(sn,) + optimise(cost, np.array(s, float)) for sn, s in STARTS.items()]
    _, w, fbest = min(ends, key=lambda x: x[2])
    hm, f0 = hessian(cost, w)
    u, v, ok = frame.project(w, mask)
    cell = 3 if kind == 'mi' else 10
    n_eff = len(set(zip((u[ok] // cell).astype(int), (v[ok] // cell).astype(int))))
    info = n_eff * hm if kind == 'mi' else n_eff * hm / (2 * f0)
    curv = (np.sqrt(np.diag(np.linalg.inv(info))) if np.linalg.eigvalsh(info).min() > 0
            else np.full(3, np.inf))
    jk = np.array([optimise(cost, w, (k * 480, (k + 1) * 480))[0] for k in range(4)])
    jack = np.sqrt(0.75 * ((jk - jk.mean(0)) ** 2).sum(0))
    extra = ''
    if kind == 'chamfer':
        d = bilinear(frame.dt, u[ok], v[ok])
        extra = f'; {np.mean(d >= 10) * 100:.0f} % of edge points >= 10 px from any image edge'
    value = -fbest if kind == 'mi' else fbest
    others = ', '.join(f'{sn} -> ({a:+.2f}, {b:+.2f}, {c:+.2f}) {(-f if kind == "mi" else f):.4f}'
                       for sn, (a, b, c), f in ends)
    print(f'| {name} | {w[0]:+.2f}, {w[1]:+.2f}, {w[2]:+.2f} | {value:.4f} | '
          f'{curv[0]:.3f}, {curv[1]:.3f}, {curv[2]:.3f} | {jack[0]:.2f}, {jack[1]:.2f}, '
          f'{jack[2]:.2f} | {np.linalg.norm(w):.2f} | {others}{extra} |', flush=True)
    return w, np.maximum(curv, jack)


def combine(rows):
    """Inverse-variance mean per axis with the Birge ratio (scatter / sigmas) when > 1."""
    w = np.array([r[0] for r in rows])
    s = np.maximum(np.array([r[1] for r in rows]), 0.025)  # the search's 0.025 deg step
    wt = 1 / s ** 2
    mean = (wt * w).sum(0) / wt.sum(0)
    chi2 = (wt * (w - mean) ** 2).sum(0) / max(len(rows) - 1, 1)
    return mean, np.sqrt(1 / wt.sum(0)) * np.sqrt(np.maximum(chi2, 1.0)), np.sqrt(chi2)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--data', default='../shared/data/real/calibanything-1')
    ap.add_argument('--markings', type=float, nargs=3, default=(0.238, -0.271, -0.014))
    ap.add_argument('--markings-sigma', type=float, nargs=3, default=(0.22, 0.05, 0.08))
    a = ap.parse_args()
    fr = Frame(a.data)
    print(f'projection vs cv2.projectPoints: max |diff| {fr.cv_diff:.1e} px')
    g, ng = fr.band(0.25), ~fr.band(0.25)
    ghp = fr.ring_highpassed()
    ve = fr.vertical_edges()
    edges = (fr.jump > 0.5) & (fr.p[:, 2] > fr.gz + 0.3)
    print(f'{len(fr.p)} points in view, {g.sum()} ground (band 0.25 m), {edges.sum()} range '
          f'edges, {ve.sum()} on vertical structures')
    print('| cue | optimum rx, ry, rz (deg from the reference) | value | curvature sigma '
          '(deg) | jackknife sigma (deg) | angle to the reference (deg) | ends from the '
          'three starts |')
    print('|---|---|---:|---|---|---:|---|')
    rk = lambda m, x: ranknorm(x[m])  # noqa: E731
    cues = [
        ('ground MI (the command: band 0.25 m)', [(g, rk(g, fr.i))], g, 'mi', True),
        ('ground MI, band 0.15 m', [(fr.band(0.15), rk(fr.band(0.15), fr.i))],
         fr.band(0.15), 'mi', False),
        ('ground MI, band 0.40 m', [(fr.band(0.40), rk(fr.band(0.40), fr.i))],
         fr.band(0.40), 'mi', False),
        ('ground MI, ring-high-passed reflectivity', [(g, rk(g, ghp))], g, 'mi', False),
        ('off-ground MI', [(ng, rk(ng, fr.i))], ng, 'mi', True),
        ('ground + off-ground MI (grouped)', [(g, rk(g, fr.i)), (ng, rk(ng, fr.i))],
         np.ones(len(fr.p), bool), 'mi', False),
    ]
    independent = [(np.array(a.markings), np.array(a.markings_sigma))]
    for name, groups, mask, kind, use in cues:
        r = evaluate(fr, name, mi_cue(fr, groups), mask, kind)
        if use:
            independent.append(r)
    for name, mask in (('range-edge chamfer (all)', edges),
                       ('range-edge chamfer (vertical structures)', ve)):
        evaluate(fr, name, chamfer_cue(fr, mask), mask, 'chamfer')
    mean, sigma, birge = combine(independent)
    print(f'combined (markings, ground MI, off-ground MI): ({mean[0]:+.3f}, {mean[1]:+.3f}, '
          f'{mean[2]:+.3f}) +- ({sigma[0]:.3f}, {sigma[1]:.3f}, {sigma[2]:.3f}) deg, Birge '
          f'ratio ({birge[0]:.1f}, {birge[1]:.1f}, {birge[2]:.1f}); pitch {-mean[1] / sigma[1]:.1f} '
          f'sigma from the reference')


if __name__ == '__main__':
    main()
