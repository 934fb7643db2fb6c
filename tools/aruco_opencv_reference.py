#!/usr/bin/env python3
"""OpenCV's ArUco detections on the real marker photos of Debian's opencv-doc package:
the reference that `msreg`'s detector is judged against (docs/aruco.md).

Setup (throwaway, never committed):
    cd /tmp && apt-get download opencv-doc && dpkg-deb -x opencv-doc*.deb /tmp/opencv-doc
    python3 -m venv /tmp/venv-aruco && /tmp/venv-aruco/bin/pip install opencv-python-headless
Run:
    /tmp/venv-aruco/bin/python tools/aruco_opencv_reference.py [--out /tmp/aruco_reference.csv]

Writes `image,dictionary,id,u0,v0,u1,v1,u2,v2,u3,v3` (corners in OpenCV order, sub-pixel
refined with CORNER_REFINE_SUBPIX, otherwise default DetectorParameters), one line per
marker OpenCV decodes, for every photo in PHOTOS x dictionary in DICTS.
"""
import argparse
import os
import sys

import cv2
import numpy as np

HTML = "/tmp/opencv-doc/usr/share/doc/opencv-doc/opencv4/html"
# The marker images of the package: photos of printed markers (singlemarkers*, gb*,
# screen_charuco: a photo of a screen) and two renderings (board, charucoboard,
# singlemarkerssource). gboriginal/gbocclusion decode nothing in OpenCV with these dictionaries.
PHOTOS = [
    "singlemarkersoriginal.jpg",
    "singlemarkersrejected.jpg",
    "singlemarkersaxes.jpg",
    "singlemarkersaxes2.jpg",
    "singlemarkersdetection.jpg",
    "gboriginal.png",
    "gbocclusion.png",
    "screen_charuco.jpg",
    "board.jpg",
    "charucoboard.jpg",
    "singlemarkerssource.png",
]
# The dictionaries msreg implements.
DICTS = ["DICT_4X4_50", "DICT_6X6_250", "DICT_ARUCO_ORIGINAL"]


def grey_like_msreg(bgr):
    """Colour to grey as msreg's image reader (the `image` crate) does it, Rec. 709 integer
    weights (2126 R + 7152 G + 722 B) / 10000, so both detectors see the same pixels
    (OpenCV's own IMREAD_GRAYSCALE weighs 0.299 / 0.587 / 0.114)."""
    if bgr is None:
        return None
    b, g, r = (bgr[..., i].astype(np.uint32) for i in range(3))
    return ((2126 * r + 7152 * g + 722 * b) // 10000).astype(np.uint8)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/aruco_reference.csv")
    ap.add_argument("--html", default=HTML)
    ap.add_argument(
        "--opencv-grey",
        action="store_true",
        help="convert colour with OpenCV's IMREAD_GRAYSCALE weights instead of msreg's",
    )
    args = ap.parse_args()
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    lines = ["image,dictionary,id,u0,v0,u1,v1,u2,v2,u3,v3"]
    for name, dict_name in [(n, d) for n in PHOTOS for d in DICTS]:
        path = os.path.join(args.html, name)
        if args.opencv_grey:
            img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        else:
            img = grey_like_msreg(cv2.imread(path, cv2.IMREAD_COLOR))
        if img is None:
            sys.exit(f"{path}: cannot read (see the setup in this script's docstring)")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dict_name))
        detector = cv2.aruco.ArucoDetector(dictionary, params)
        corners, ids, _ = detector.detectMarkers(img)
        n = 0 if ids is None else len(ids)
        for c, i in zip(corners, [] if ids is None else ids.ravel()):
            xy = ",".join(f"{v:.4f}" for v in c.reshape(-1))
            lines.append(f"{name},{dict_name},{i},{xy}")
        print(f"{name} {dict_name}: {n} markers", file=sys.stderr)
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {args.out} (OpenCV {cv2.__version__})", file=sys.stderr)


if __name__ == "__main__":
    main()
