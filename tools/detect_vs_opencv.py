#!/usr/bin/env python3
"""Checkerboard detection, msreg against OpenCV, side by side in one run (issue 16).

Every real image set of ../shared/data, each image decoded once per side, then `--repeats`
rounds; in every round each image is detected once by OpenCV (`findChessboardCorners`,
default flags, + `cornerSubPix` with winSize (11, 11), 30 iterations, eps 1e-4: how the
reference corners were made) and once by msreg (`detect_checkerboard`, through
`cargo run --release -p msreg-host --example detect_timing`), alternating which goes first, so
the load of the shared machine falls on both. Per image: the minimum over the rounds of
each side, whether each found the board, and how far msreg's corners lie from OpenCV's of
this run (median / max over the corners, nearest-corner match). `uptime`'s load averages
are printed before and after.

OpenCV comes from pip (`opencv-python-headless` and numpy) in a throwaway venv, created
by this script when missing (idempotent):

    python3 tools/detect_vs_opencv.py [--repeats 15] [--threads 1] [--settings default]
        [--data ../shared/data] [--venv /tmp/msreg-opencv-venv]

`--threads` is given to both sides (`cv2.setNumThreads`, `RAYON_NUM_THREADS`).
`--baseline EXE` adds a third contestant, another build of `detect_timing` (e.g. from an
older commit: `git archive <rev> | tar -x -C /tmp/before`, copy `detect_timing.rs` in, build
there with its own CARGO_TARGET_DIR, copy the binary), timed in the same rounds: before /
after / OpenCV from one run. Do not share this worktree's target dir with that build: cargo
names a workspace package's artifacts without its path and fingerprints its sources by
relative path, so the old library would replace this one and look fresh (then `touch` the
sources here to rebuild).
"""
import argparse
import os
import statistics
import subprocess
import sys
import time

from opencv_venv import ensure_venv

# (set directory, file suffix, rows, cols, what a detector should report)
SETS = [
    ("checkerboard-opencv", ".jpg", 6, 9, "9x6 board, 640x480 (left.jpg: no full board)"),
    ("checkerboard-fisheye", ".png", 6, 8, "8x6 board, 800x503 fisheye"),
    ("real/calibanything-1/cam0/data", ".png", 6, 9, "1920x1200 road scene, no board"),
]

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_avg():
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


class Msreg:
    """The `detect_timing` example, driven line by line."""

    def __init__(self, settings, threads, exe=None):
        env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
        if exe is None:
            subprocess.run(
                ["cargo", "build", "--release", "-q", "-p", "msreg", "--example",
                 "detect_timing"],
                cwd=REPO,
                check=True,
            )
            exe = os.path.join(REPO, "target", "release", "examples", "detect_timing")
        self.proc = subprocess.Popen(
            [exe, settings], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
        )

    def ask(self, line):
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        reply = self.proc.stdout.readline().rstrip("\n")
        if reply.startswith("err "):
            raise RuntimeError(f"detect_timing: {line!r}: {reply}")
        return reply

    def load(self, rows, cols, path):
        return int(self.ask(f"load {rows} {cols} {path}").split()[1])

    def time(self, index):
        wall, cpu, outcome = self.ask(f"time {index}").split()
        return float(wall), float(cpu), outcome

    def corners(self, index):
        text = self.ask(f"corners {index}")
        return [tuple(map(float, p.split(","))) for p in text.split()]


def opencv_detect(cv2, gray, rows, cols):
    found, corners = cv2.findChessboardCorners(gray, (cols, rows))
    if found:
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-4)
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria)
    return found, corners


def agreement(ours, theirs):
    """Median and max distance from each of our corners to the nearest of theirs."""
    if not ours or theirs is None:
        return None
    pts = [tuple(p) for p in theirs.reshape(-1, 2)]
    d = [min(((x - u) ** 2 + (y - v) ** 2) ** 0.5 for u, v in pts) for x, y in ours]
    return statistics.median(d), max(d)


def images(data):
    for set_dir, suffix, rows, cols, what in SETS:
        d = os.path.join(data, set_dir)
        if not os.path.isdir(d):
            print(f"SKIP {set_dir}: absent", file=sys.stderr)
            continue
        for name in sorted(os.listdir(d)):
            if name.endswith(suffix):
                yield set_dir, what, rows, cols, os.path.join(d, name)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--settings", default="default", choices=["default", "opencv"])
    ap.add_argument("--data", default=os.path.join(REPO, "..", "shared", "data"))
    ap.add_argument("--venv", default="/tmp/msreg-opencv-venv")
    ap.add_argument("--exe", help="the detect_timing executable (default: cargo builds it)")
    ap.add_argument("--baseline", help="another detect_timing executable, timed alongside")
    args = ap.parse_args()
    ensure_venv(args.venv, __file__)
    import cv2

    cv2.setNumThreads(args.threads)
    msreg = Msreg(args.settings, args.threads, args.exe)
    before = Msreg(args.settings, args.threads, args.baseline) if args.baseline else None
    items = []
    for set_dir, what, rows, cols, path in images(os.path.realpath(args.data)):
        gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        items.append(dict(set=set_dir, what=what, rows=rows, cols=cols, path=path,
                          gray=gray, index=msreg.load(rows, cols, path), cv=[], ms=[],
                          before=[]))
        if before:
            before.load(rows, cols, path)
    if not items:
        sys.exit(f"no images under {args.data}")
    load_before = load_avg()
    for round_ in range(args.repeats):
        for k, it in enumerate(items):
            def run_cv():
                t0, c0 = time.perf_counter(), time.process_time()
                it["found_cv"], it["corners_cv"] = opencv_detect(cv2, it["gray"], it["rows"], it["cols"])
                c1, t1 = time.process_time(), time.perf_counter()
                it["cv"].append(((t1 - t0) * 1e3, (c1 - c0) * 1e3))

            def run_ms():
                wall, cpu, it["outcome"] = msreg.time(it["index"])
                it["ms"].append((wall, cpu))

            def run_before():
                if before:
                    wall, cpu, it["outcome_before"] = before.time(it["index"])
                    it["before"].append((wall, cpu))

            order = [run_cv, run_ms, run_before]
            shift = (round_ + k) % 3
            for run in order[shift:] + order[:shift]:
                run()
    load_after = load_avg()
    report(args, items, msreg, cv2.__version__, load_before, load_after)


def report(args, items, msreg, cv_version, load_before, load_after):
    print(f"# msreg ({args.settings} settings) vs OpenCV {cv_version}, {args.threads} thread(s) "
          f"each, min of {args.repeats} interleaved rounds (wall-clock and process CPU time, "
          f"ms); load average before {load_before}, after {load_after}; "
          f"{os.uname().machine}, {os.cpu_count()} cores")
    has_before = bool(items[0]["before"])
    before_head = "| msreg before wall / CPU " if has_before else ""
    print(f"| set | image | OpenCV wall / CPU {before_head}| msreg wall / CPU "
          "| msreg / OpenCV (CPU) | OpenCV found | msreg outcome "
          "| msreg vs OpenCV corners, median / max px |")
    print("|---|---|---:|" + ("---:|" if has_before else "") + "---:|---:|---|---|---|")
    per_set = {}
    for it in items:
        cv = tuple(min(x[k] for x in it["cv"]) for k in (0, 1))
        ms = tuple(min(x[k] for x in it["ms"]) for k in (0, 1))
        bf = tuple(min(x[k] for x in it["before"]) for k in (0, 1)) if has_before else None
        before_cell = f"| {bf[0]:.2f} / {bf[1]:.2f} " if has_before else ""
        agree = agreement(msreg.corners(it["index"]) if it["outcome"] == "found" else None,
                          it["corners_cv"] if it["found_cv"] else None)
        agree_text = "-" if agree is None else f"{agree[0]:.3f} / {agree[1]:.3f}"
        print(f"| {os.path.basename(it['set'])} | {os.path.basename(it['path'])} "
              f"| {cv[0]:.2f} / {cv[1]:.2f} {before_cell}| {ms[0]:.2f} / {ms[1]:.2f} "
              f"| {ms[1] / max(cv[1], 1e-3):.2f} | {'yes' if it['found_cv'] else 'no'} "
              f"| {it['outcome']} | {agree_text} |")
        s = per_set.setdefault(it["set"], dict(what=it["what"], cv=[], ms=[], before=[], both=0,
                                               cv_only=0, ms_only=0))
        s["cv"].append(cv)
        s["ms"].append(ms)
        if has_before:
            s["before"].append(bf)
        found_ms = it["outcome"] == "found"
        s["both"] += found_ms and bool(it["found_cv"])
        s["cv_only"] += bool(it["found_cv"]) and not found_ms
        s["ms_only"] += found_ms and not it["found_cv"]
    print()
    before_head = "| msreg before median wall / CPU " if has_before else ""
    print(f"| set | images | OpenCV median wall / CPU {before_head}| msreg median wall / CPU "
          "| OpenCV total CPU | msreg total CPU | found by both | OpenCV only | msreg only |")
    print("|---|---:|---:|" + ("---:|" if has_before else "") + "---:|---:|---:|---:|---:|---:|")
    for name, s in per_set.items():
        med = lambda xs, k: statistics.median(x[k] for x in xs)
        tot = lambda xs: sum(x[1] for x in xs)
        print(f"| {name} ({s['what']}) | {len(s['cv'])} "
              f"| {med(s['cv'], 0):.2f} / {med(s['cv'], 1):.2f} "
              + (f"| {med(s['before'], 0):.2f} / {med(s['before'], 1):.2f} " if has_before else "")
              + f"| {med(s['ms'], 0):.2f} / {med(s['ms'], 1):.2f} "
              f"| {tot(s['cv']):.1f} | {tot(s['ms']):.1f} "
              f"| {s['both']} | {s['cv_only']} | {s['ms_only']} |")


if __name__ == "__main__":
    main()
