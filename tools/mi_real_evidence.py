#!/usr/bin/env python3
"""Evidence on the CalibAnything reference extrinsic (issue 15, docs/prior_map.md).

1-D slices through a pose, per DoF (right rotation increment about the LiDAR axes,
+-2.5 deg; additive camera-frame translation, +-15 cm), of several single-frame
objectives between the LiDAR scan and the image; prints the slice maximum per DoF and
writes `slices_<tag>.csv` and `slices_<tag>.png`. Also writes overlays of the LiDAR
lane-marking returns (ground points brighter than their ring neighbours) at the pose.

Usage (NumPy, SciPy, OpenCV in a throwaway venv):
  python3 tools/mi_real_evidence.py [--data ../shared/data/real/calibanything-1]
      [--out /tmp/mi_evidence] [--rot-deg RX RY RZ] [--tag NAME]
`--rot-deg` moves the slice centre from the reference by R Exp(w) (LiDAR axes, deg):
e.g. the marking-aligned rotation printed by
`cargo test --release -p msreg-host --test mi_reference_markings -- --nocapture`.
"""
import argparse
import os
import struct

import cv2
import numpy as np
from scipy import ndimage


def lzf(inp, outlen):
    out = bytearray(outlen)
    ip = op = 0
    while ip < len(inp):
        ctrl = inp[ip]
        ip += 1
        if ctrl < 32:
            n = ctrl + 1
            out[op:op + n] = inp[ip:ip + n]
            ip += n
            op += n
        else:
            n = ctrl >> 5
            ref = op - ((ctrl & 31) << 8) - 1
            if n == 7:
                n += inp[ip]
                ip += 1
            ref -= inp[ip]
            ip += 1
            for _ in range(n + 2):
                out[op] = out[ref]
                op += 1
                ref += 1
    return bytes(out)


def read_pcd(path):
    """binary_compressed PCD with fields x y z intensity ring timestamp (this file)."""
    b = open(path, 'rb').read()
    head, _, body = b.partition(b'DATA binary_compressed\n')
    hdr = dict(l.split(' ', 1) for l in head.decode().splitlines() if l and l[0] != '#')
    fields, sizes, types = hdr['FIELDS'].split(), hdr['SIZE'].split(), hdr['TYPE'].split()
    n = int(hdr['POINTS'])
    cs, us = struct.unpack('<II', body[:8])
    raw = lzf(body[8:8 + cs], us)
    cols, off = {}, 0
    for f, s, t in zip(fields, sizes, types):
        dt = {'F': 'f', 'U': 'u', 'I': 'i'}[t] + s
        cols[f] = np.frombuffer(raw[off:off + n * int(s)], dtype=dt)
        off += n * int(s)
    xyz = np.stack([cols['x'], cols['y'], cols['z']], 1).astype(np.float64)
    return xyz, cols['intensity'].astype(np.float64), cols['ring'].astype(int)


def read_yaml_numbers(path, key):
    txt = open(path).read()
    part = txt[txt.index(key):]
    nums = part[part.index('[') + 1:]
    depth, end = 1, 0
    for i, ch in enumerate(nums):
        depth += ch == '['
        depth -= ch == ']'
        if depth == 0:
            end = i
            break
    return np.array([float(x) for x in nums[:end].replace('[', ' ').replace(']', ' ')
                     .replace(',', ' ').split()])


def expso3(w):
    th = np.linalg.norm(w)
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * kx + (1 - np.cos(th)) * kx @ kx


def retract(t, d):
    out = t.copy()
    out[:3, :3] = t[:3, :3] @ expso3(d[:3])
    out[:3, 3] = t[:3, 3] + d[3:]
    return out


class Camera:
    def __init__(self, path):
        self.k = read_yaml_numbers(path, 'intrinsics:')
        self.d = read_yaml_numbers(path, 'distortion_coeffs:')
        self.w, self.h = read_yaml_numbers(path, 'resolution:').astype(int)

    def project(self, t, pts):
        pc = pts @ t[:3, :3].T + t[:3, 3]
        z = pc[:, 2]
        ok = z > 0.5
        zz = np.where(ok, z, 1.0)
        x, y = pc[:, 0] / zz, pc[:, 1] / zz
        k1, k2, p1, p2 = self.d
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 * r2
        xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        u = self.k[0] * xd + self.k[2]
        v = self.k[1] * yd + self.k[3]
        ok &= (u >= 0) & (u < self.w - 1) & (v >= 0) & (v < self.h - 1) & (r2 < 1.0)
        return u, v, z, ok


def bilinear(im, u, v):
    x0 = np.clip(np.floor(u).astype(int), 0, im.shape[1] - 2)
    y0 = np.clip(np.floor(v).astype(int), 0, im.shape[0] - 2)
    fx, fy = u - x0, v - y0
    a, b, c, d = im[y0, x0], im[y0, x0 + 1], im[y0 + 1, x0], im[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def mi(a, b, bins=24, norm=False, smooth=0.0):
    h, _, _ = np.histogram2d(a, b, bins=bins, range=[[0, 1], [0, 1]])
    if smooth > 0:
        h = ndimage.gaussian_filter(h, smooth, mode='nearest')
    p = h / h.sum()
    pa, pb = p.sum(1), p.sum(0)
    ent = lambda q: -np.sum(q[q > 0] * np.log(q[q > 0]))
    ha, hb, hab = ent(pa), ent(pb), ent(p)
    return (ha + hb) / hab if norm else ha + hb - hab


def ranknorm(x):
    return np.argsort(np.argsort(x, kind='stable'), kind='stable') / max(len(x) - 1, 1)


def equalize(im):
    return cv2.equalizeHist(np.clip(im, 0, 255).astype(np.uint8)).astype(np.float32) / 255


def ground_height(z):
    lower = np.sort(z)[:len(z) // 2]
    hi = np.searchsorted(lower, lower + 0.2)
    k = int(np.argmax(hi - np.arange(len(lower))))
    return lower[k] + 0.1


def ring_features(xyz, inten, ring):
    """Per point: depth-jump (Levinson: sqrt of the range step to the farther neighbour on
    its ring) and the reflectivity excess over the ring-local median (31 points)."""
    rng = np.linalg.norm(xyz, axis=1)
    az = np.arctan2(xyz[:, 1], xyz[:, 0])
    jump = np.zeros(len(xyz))
    excess = np.zeros(len(xyz))
    for r in np.unique(ring):
        idx = np.where(ring == r)[0]
        idx = idx[np.argsort(az[idx])]
        d, a = rng[idx], az[idx]
        gp, gn = np.r_[1, np.diff(a)], np.r_[np.diff(a), 1]
        prev = np.where(gp < 0.01, np.r_[d[0], d[:-1]], d)
        nxt = np.where(gn < 0.01, np.r_[d[1:], d[-1]], d)
        jump[idx] = np.maximum(np.maximum(prev - d, nxt - d), 0)
        excess[idx] = inten[idx] - ndimage.median_filter(inten[idx], size=31, mode='nearest')
    return jump, excess


def zbuffer(u, v, z, cell=12, tol=0.3):
    """Keep points within tol * z of the nearest point in their cell x cell px cell."""
    key = (v / cell).astype(int) * 100000 + (u / cell).astype(int)
    order = np.lexsort((z, key))
    k = key[order]
    first = np.r_[True, k[1:] != k[:-1]]
    head = np.maximum.accumulate(np.where(first, np.arange(len(k)), 0))
    keep = np.zeros(len(z), bool)
    keep[order] = z[order] <= z[order][head] * (1 + tol)
    return keep


class Objectives:
    def __init__(self, cam, img, xyz, inten, ring, t_sel):
        self.cam = cam
        u, v, z, ok = cam.project(t_sel, xyz)
        jump, excess = ring_features(xyz, inten, ring)
        self.p, self.val = xyz[ok], ranknorm(inten[ok])
        self.jump = jump[ok]
        g = np.abs(self.p[:, 2] - ground_height(self.p[:, 2])) < 0.25
        self.ground = g
        self.marking = g & (excess[ok] > 15)
        gb = cv2.GaussianBlur(img, (0, 0), 1.0)
        hp = img - cv2.GaussianBlur(img, (0, 0), 30) + 128
        self.eq = equalize(gb)
        self.hp = equalize(cv2.GaussianBlur(hp, (0, 0), 1.0))
        g15 = cv2.GaussianBlur(img, (0, 0), 1.5)
        gx = cv2.Sobel(g15, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(g15, cv2.CV_32F, 0, 1, ksize=3)
        gm = np.hypot(gx, gy)
        self.gm = gm / gm.max()
        self.gm_eq = equalize(self.gm * 255)
        can = cv2.Canny(np.clip(g15, 0, 255).astype(np.uint8), 20, 60)
        self.dt_canny = cv2.distanceTransform((can == 0).astype(np.uint8), cv2.DIST_L2, 5)
        # Levinson & Thrun: alpha E + (1 - alpha) max_nbr E gamma^dist (alpha 1/3, gamma 0.98)
        e, cur = self.gm.copy(), self.gm.copy()
        for _ in range(30):
            cur = ndimage.grey_dilation(cur, size=(3, 3)) * 0.98
            e = np.maximum(e, cur)
        self.lev = self.gm / 3 + 2 * e / 3
        th = cv2.morphologyEx(gb, cv2.MORPH_TOPHAT,
                              cv2.getStructuringElement(cv2.MORPH_RECT, (61, 1)))
        mask = (th > 25).astype(np.uint8)
        self.dt_mark = cv2.distanceTransform(1 - mask, cv2.DIST_L2, 5)

    def all(self, t):
        u, v, z, ok = self.cam.project(t, self.p)
        a, uu, vv, zz = self.val[ok], u[ok], v[ok], z[ok]
        g, e, m = self.ground[ok], np.sqrt(self.jump[ok]), self.marking[ok]
        kz = zbuffer(uu, vv, zz)
        big = ok & (self.jump > 1.0)
        out = {
            'mi_all': mi(a, bilinear(self.eq, uu, vv)),
            'nmi_all': mi(a, bilinear(self.eq, uu, vv), norm=True),
            'mi_kde_all': mi(a, bilinear(self.eq, uu, vv), bins=64, smooth=2.0),
            'mi_zbuf_all': mi(a[kz], bilinear(self.eq, uu[kz], vv[kz])),
            'mi_hp_all': mi(a, bilinear(self.hp, uu, vv)),
            'mi_hp_ground': mi(a[g], bilinear(self.hp, uu[g], vv[g])),
            'nmi_hp_ground': mi(a[g], bilinear(self.hp, uu[g], vv[g]), norm=True),
            'mi_edge_grad': mi(ranknorm(e), bilinear(self.gm_eq, uu, vv)),
            'levinson_edge': np.mean(e * bilinear(self.lev, uu, vv)),
            'levinson_zbuf': np.mean((e * bilinear(self.lev, uu, vv))[kz]),
            'edge_chamfer': -np.mean(np.minimum(
                bilinear(self.dt_canny, *self.cam.project(t, self.p[big])[:2]), 20)),
            'marking_dt': np.mean(np.exp(-np.minimum(
                bilinear(self.dt_mark, uu[m], vv[m]), 60) / 4.0)),
        }
        return out


def overlay(cam, img, xyz, inten, ring, t, path):
    u, v, z, ok = cam.project(t, xyz)
    _, excess = ring_features(xyz, inten, ring)
    g = ok & (np.abs(xyz[:, 2] - ground_height(xyz[ok, 2])) < 0.3)
    mk = g & (excess > 15)
    o = cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    for a, b in zip(u[g & ~mk], v[g & ~mk]):
        cv2.circle(o, (int(a), int(b)), 1, (255, 120, 0), -1)
    for a, b in zip(u[mk], v[mk]):
        cv2.circle(o, (int(a), int(b)), 3, (0, 0, 255), -1)
    crops = [o[780:1000, 150:760], o[700:820, 780:1400]]
    w = max(c.shape[1] for c in crops)
    pad = [cv2.copyMakeBorder(c, 0, 4, 0, w - c.shape[1], cv2.BORDER_CONSTANT) for c in crops]
    cv2.imwrite(path, np.vstack(pad))


def plot(rows, names, path):
    w, h = 300, 120
    canvas = np.full((h * len(names) + 20, w * 6 + 160, 3), 255, np.uint8)
    for d, (vals, ys) in enumerate(rows):
        cv2.putText(canvas, ['rx', 'ry', 'rz', 'tx', 'ty', 'tz'][d], (160 + d * w + 130, 15),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
        for i, n in enumerate(names):
            y = np.array([r[n] for r in ys])
            y = (y - y.min()) / max(y.max() - y.min(), 1e-12)
            x0, y0 = 160 + d * w + 10, 20 + i * h + 10
            pts = np.stack([x0 + np.linspace(0, w - 20, len(y)), y0 + (1 - y) * (h - 20)], 1)
            cv2.polylines(canvas, [pts.astype(np.int32)], False, (200, 60, 0), 1)
            cv2.line(canvas, (x0 + (w - 20) // 2, y0), (x0 + (w - 20) // 2, y0 + h - 20),
                     (0, 0, 200), 1)
            if d == 0:
                cv2.putText(canvas, n, (5, y0 + h // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                            (0, 0, 0), 1)
    cv2.imwrite(path, canvas)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--data', default='../shared/data/real/calibanything-1')
    ap.add_argument('--out', default='/tmp/mi_evidence')
    ap.add_argument('--rot-deg', type=float, nargs=3, default=[0, 0, 0])
    ap.add_argument('--tag', default='reference')
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    cam = Camera(os.path.join(args.data, 'cam0/camera.yaml'))
    img = cv2.imread(os.path.join(args.data, 'cam0/data/1700000000000000000.png'),
                     cv2.IMREAD_GRAYSCALE).astype(np.float32)
    xyz, inten, ring = read_pcd(os.path.join(args.data, 'lidar0/1700000000000000000.pcd'))
    ref = read_yaml_numbers(os.path.join(args.data, 'groundtruth/extrinsics.yaml'),
                            'T_cam_lidar:').reshape(4, 4)
    centre = retract(ref, np.r_[np.radians(args.rot_deg), 0, 0, 0])
    obj = Objectives(cam, img, xyz, inten, ring, ref)
    overlay(cam, img, xyz, inten, ring, centre,
            os.path.join(args.out, f'markings_{args.tag}.png'))
    names = list(obj.all(centre).keys())
    rows = []
    for d in range(6):
        vals = np.linspace(-2.5, 2.5, 51) if d < 3 else np.linspace(-0.15, 0.15, 61)
        ys = []
        for s in vals:
            dv = np.zeros(6)
            dv[d] = np.radians(s) if d < 3 else s
            ys.append(obj.all(retract(centre, dv)))
        rows.append((vals, ys))
    with open(os.path.join(args.out, f'slices_{args.tag}.csv'), 'w') as f:
        f.write('dof,offset,' + ','.join(names) + '\n')
        for d, (vals, ys) in enumerate(rows):
            for s, r in zip(vals, ys):
                f.write(f'{d},{s},' + ','.join(f'{r[n]:.6g}' for n in names) + '\n')
    plot(rows, names, os.path.join(args.out, f'slices_{args.tag}.png'))
    print(f'slice maxima around {args.tag} (rot deg, trans m); * = within 0.3 deg / 5 cm')
    print('%-15s' % 'objective' + ''.join('%9s' % n for n in
                                          ['rx', 'ry', 'rz', 'tx', 'ty', 'tz']) + '  all')
    for n in names:
        pk = [vals[int(np.argmax([r[n] for r in ys]))] for vals, ys in rows]
        good = [abs(p) <= (0.3 if d < 3 else 0.05) + 1e-9 for d, p in enumerate(pk)]
        print('%-15s' % n + ''.join(('%8.2f' if d < 3 else '%8.3f') % p + ('*' if g else ' ')
                                    for d, (p, g) in enumerate(zip(pk, good)))
              + ('  yes' if all(good) else '  no'))


if __name__ == '__main__':
    main()
