#!/usr/bin/env python3
"""False-alarm study of `msreg monitor` (docs/monitor.md, "False alarms"). Stdlib only.

  tools/monitor_false_alarms.py drives FIRST LAST [--confidence 99.999] [--knock none]
      simulates 60 s drives on seeds FIRST..LAST-1, replays the monitor, and prints per drive
      the smallest chi-square tail probability of any step detector's GLR test whose step is
      worth an alarm, the alarms, then per-test confidences the number of drives that cross
      them (the false-alarm count that threshold would give, up to the first alarm) and the
      rate per hour of driving. With --knock pose1/pose0: the first alarm's latency.
  tools/monitor_false_alarms.py h0 DOF THRESHOLD UPDATES
      the repeated-testing baseline: per-update crossing rate of the same exponentially
      forgotten GLR (forgetting 0.985, reset and 15-update refractory after a crossing) on
      white innovations with constant information.
"""
import json
import math
import os
import random
import subprocess
import sys
import tempfile

MSREG = os.environ.get("MSREG", "target/release/msreg")
MIN_STEP = {"rotation_glr": 0.25, "translation_glr": 5.0}  # deg, mm (HealthConfig defaults)


def tail(x, dof):
    """P(chi2(dof) > x)."""
    if dof == 1:
        return math.erfc(math.sqrt(x / 2))
    if dof == 2:
        return math.exp(-x / 2)
    return math.erfc(math.sqrt(x / 2)) + math.sqrt(2 * x / math.pi) * math.exp(-x / 2)


def replay(seed, confidence, knock, work):
    d = os.path.join(work, f"drive_{seed}")
    run = lambda *a: subprocess.run([MSREG, *a], check=False, capture_output=True)
    run("simulate", "drive", d, "--seed", str(seed), "--knock-sensor", knock)
    out = run("monitor", d, "--report", d + ".json", "--step-confidence", confidence)
    if out.returncode != 0:
        return None
    with open(d + ".json") as f:
        return json.load(f)


def smallest_tail(report, sensor):
    """Smallest tail probability of a test with a step worth an alarm (alarms included)."""
    best = 1.0
    dof = 3
    for p in sensor["nis"]:
        for key, min_step in MIN_STEP.items():
            g = p[key]
            if g:
                dof = g["dof"]
                if g["step"] >= min_step:
                    best = min(best, tail(g["statistic"], g["dof"]))
        for a in report["alarms"]:
            if a["sensor"] == sensor["name"] and abs(a["t_s"] - p["t_s"]) < 1e-9:
                best = min(best, tail(a["statistic"], dof))
    return best


def drives(first, last, confidence="99.999", knock="none"):
    rows, minutes = [], 0.0
    with tempfile.TemporaryDirectory() as work:
        for seed in range(first, last):
            r = replay(seed, confidence, knock, work)
            if r is None:
                print(f"seed {seed}: monitor did not start")
                continue
            p = [smallest_tail(r, s) for s in r["sensors"]]
            alarms = [(round(a["t_s"], 2), a["sensor"], round(a["statistic"], 1)) for a in r["alarms"]]
            print(f"seed {seed}: smallest tail pose0 {p[0]:.2e} pose1 {p[1]:.2e}; alarms {alarms}")
            rows.append((p, alarms))
            minutes += r["duration_s"] / 60
    n_alarms = sum(len(a) for _, a in rows)
    print(f"{len(rows)} drives, {minutes:.0f} min, {n_alarms} alarms at {confidence} %")
    if knock != "none":
        lat = [a[0][0] - 30.0 for _, a in rows if a]
        right = sum(1 for _, a in rows if a and a[0][1] == knock)
        print(f"first alarm on {knock}: {right} / {len(rows)}; latencies {[round(x, 2) for x in lat]}")
        return
    for alpha in [1e-3, 1e-4, 3e-5, 1e-5, 1e-6]:
        k = sum(1 for p, _ in rows if min(p) < alpha)
        print(f"per-test alpha {alpha:.0e}: {k} drives cross, {k / minutes * 60:.2f} per hour")


def h0(dof, threshold, updates, forgetting=0.985, seed=7):
    rng = random.Random(seed)
    b, a2, up, crossings = [0.0] * dof, 0.0, 0, 0
    for _ in range(updates):
        b = [forgetting * x + rng.gauss(0, 1) for x in b]
        a2 = forgetting * forgetting * a2 + 1
        up += 1
        if up >= 15 and sum(x * x for x in b) > threshold * a2:
            crossings, b, a2, up = crossings + 1, [0.0] * dof, 0.0, 0
    print(f"dof {dof} threshold {threshold}: {crossings} crossings in {updates} updates, "
          f"{crossings / updates:.2e} per update")


if __name__ == "__main__":
    args = sys.argv[1:]
    opts = dict(zip(args[3::2], args[4::2])) if args and args[0] == "drives" else {}
    if args[:1] == ["drives"]:
        drives(int(args[1]), int(args[2]), opts.get("--confidence", "99.999"), opts.get("--knock", "none"))
    elif args[:1] == ["h0"]:
        h0(int(args[1]), float(args[2]), int(float(args[3])))
    else:
        sys.exit(__doc__)
