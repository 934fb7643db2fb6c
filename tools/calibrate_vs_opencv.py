#!/usr/bin/env python3
"""OpenCV's intrinsic calibration on given corners, for the comparison with
`msreg calibrate cameras` (issue 33; cli/tests/cameras_vs_opencv.rs runs it).

Reads a corners CSV (`image,u,v,x,y,z`: pixel and target-frame point of every corner, the
corners msreg detected) and calibrates with the same model msreg fits:

- `pinhole-radtan`: `cv2.calibrateCamera` with `CALIB_FIX_K3` (Kalibr's four radtan
  coefficients k1 k2 p1 p2);
- `pinhole-equidistant`: `cv2.fisheye.calibrate` (Kannala-Brandt k1..k4) with
  `CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW`.

Prints one JSON object: `fu fv cu cv`, `coeffs`, `rms_opencv` (OpenCV's return value),
`rms_px` (recomputed here with `projectPoints`: sqrt of the mean squared corner distance,
msreg's definition), `seconds` (the calibration call alone), `excluded` (images OpenCV's fisheye calibration
could not start with, see `fisheye`; msreg is then run without them too).

OpenCV comes from pip (`opencv-python-headless`, numpy) in a throwaway venv created when
missing. When it cannot be made (offline), prints `SKIP: <why>` and exits with code 3.

    python3 tools/calibrate_vs_opencv.py --corners c.csv --model pinhole-radtan \
        --resolution 640 480 [--venv /tmp/msreg-opencv-venv]
"""
import argparse
import json
import os
import subprocess
import sys
import time

from opencv_venv import ensure_venv

SKIP = 3


def read_corners(path):
    import numpy as np
    images = {}
    with open(path) as f:
        next(f)
        for line in f:
            name, u, v, x, y, z = line.strip().split(",")
            images.setdefault(name, []).append((float(u), float(v), float(x), float(y), float(z)))
    names = sorted(images)
    obj = [np.array([[c[2], c[3], c[4]] for c in images[n]], np.float64) for n in names]
    img = [np.array([[c[0], c[1]] for c in images[n]], np.float64) for n in names]
    return obj, img, names


def rms_of(errors):
    import numpy as np
    e = np.concatenate(errors)
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def pinhole(obj, img, size):
    import cv2
    import numpy as np
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 300, 1e-15)
    obj32 = [o.astype(np.float32) for o in obj]
    img32 = [i.astype(np.float32) for i in img]
    t = time.perf_counter()
    rms, k, d, rv, tv = cv2.calibrateCamera(obj32, img32, size, None, None,
                                            flags=cv2.CALIB_FIX_K3, criteria=crit)
    seconds = time.perf_counter() - t
    errs = []
    for o, i, r, tt in zip(obj, img, rv, tv):
        p, _ = cv2.projectPoints(o, r, tt, k, d)
        errs.append(p.reshape(-1, 2) - i)
    d = d.ravel()
    return k, [float(x) for x in d[:4]], rms, rms_of(errs), seconds, []


def fisheye_once(obj, img, size, guess):
    import cv2
    import numpy as np
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 300, 1e-15)
    # OpenCV 5's fisheye wants (1, N, c) float64 arrays.
    o3 = [o.reshape(1, -1, 3) for o in obj]
    i2 = [i.reshape(1, -1, 2) for i in img]
    # OpenCV 4 names the flags under cv2.fisheye, OpenCV 5 at the top level.
    ns = cv2.fisheye if hasattr(cv2.fisheye, "CALIB_FIX_SKEW") else cv2
    flags = ns.CALIB_RECOMPUTE_EXTRINSIC | ns.CALIB_FIX_SKEW
    k0 = np.eye(3)
    if guess:
        # OpenCV's own start, given explicitly: f = max(w, h) / pi at the image centre.
        f = max(size) / np.pi
        k0 = np.array([[f, 0, size[0] / 2 - 0.5], [0, f, size[1] / 2 - 0.5], [0, 0, 1]])
        flags |= ns.CALIB_USE_INTRINSIC_GUESS
    t = time.perf_counter()
    rms, k, d, rv, tv = cv2.fisheye.calibrate(o3, i2, size, k0, np.zeros((4, 1)),
                                              flags=flags, criteria=crit)
    seconds = time.perf_counter() - t
    errs = []
    for o, i, r, tt in zip(o3, img, rv, tv):
        p, _ = cv2.fisheye.projectPoints(o, r, tt, k, d)
        errs.append(p.reshape(-1, 2) - i)
    return k, [float(x) for x in d.ravel()], rms, rms_of(errs), seconds


def fisheye(obj, img, size):
    """cv2.fisheye.calibrate. On checkerboard-fisheye OpenCV 4.14 and 5.0 fail from their
    implicit start (the `InitExtrinsics` assertion, or a divergence to > 10 px RMS); then the
    same start is given explicitly as an intrinsic guess, and images whose removal lets the
    extrinsic initialisation run are dropped one at a time and reported as `excluded`."""
    import cv2
    for guess in (False, True):
        keep = list(range(len(obj)))
        excluded = []
        while True:
            try:
                out = fisheye_once([obj[i] for i in keep], [img[i] for i in keep], size, guess)
            except cv2.error:
                for j in keep:
                    rest = [i for i in keep if i != j]
                    try:
                        fisheye_once([obj[i] for i in rest], [img[i] for i in rest], size, guess)
                    except cv2.error:
                        continue
                    keep = rest
                    excluded.append(j)
                    break
                else:
                    break
                continue
            if out[3] < 10.0:
                return out + (excluded,)
            break
    raise RuntimeError("cv2.fisheye.calibrate failed on every attempt")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--corners", required=True)
    ap.add_argument("--model", required=True, choices=["pinhole-radtan", "pinhole-equidistant"])
    ap.add_argument("--resolution", type=int, nargs=2, required=True)
    ap.add_argument("--venv", default="/tmp/msreg-opencv-venv")
    args = ap.parse_args()
    ensure_venv(args.venv, __file__)
    import cv2
    obj, img, names = read_corners(args.corners)
    size = tuple(args.resolution)
    run = pinhole if args.model == "pinhole-radtan" else fisheye
    k, coeffs, rms_cv, rms, seconds, excluded = run(obj, img, size)
    print(json.dumps({
        "opencv": cv2.__version__,
        "images": len(obj) - len(excluded),
        "excluded": [names[i] for i in excluded],
        "corners": int(sum(len(o) for i, o in enumerate(obj) if i not in excluded)),
        "fu": float(k[0, 0]), "fv": float(k[1, 1]), "cu": float(k[0, 2]), "cv": float(k[1, 2]),
        "coeffs": coeffs, "rms_opencv": float(rms_cv), "rms_px": rms, "seconds": seconds,
    }))


if __name__ == "__main__":
    main()
