"""The throwaway OpenCV venv of the comparison scripts (calibrate_vs_opencv.py,
detect_vs_opencv.py): created on first use, with opencv-python-headless and numpy from pip.

Test binaries run their tests in parallel, so several scripts may ask for the venv at once:
it is made under an exclusive lock (`<venv>.lock`) and the others wait for it instead of
using a half-made venv. Without network, pip fails and the caller exits with SKIP (3)."""

import fcntl
import os
import subprocess
import sys

SKIP = 3


def ensure_venv(venv, script):
    """Re-executes `script` (with this process's arguments) in the venv, creating it first
    when missing; returns at once when already running inside it."""
    python = os.path.join(venv, "bin", "python")
    if os.path.realpath(sys.prefix) == os.path.realpath(venv):
        return
    try:
        with open(venv.rstrip("/") + ".lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            make_venv(venv, python)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired, OSError) as e:
        print(f"SKIP: cannot create the OpenCV venv {venv}: {e}")
        sys.exit(SKIP)
    os.execv(python, [python, os.path.abspath(script)] + sys.argv[1:])


def make_venv(venv, python):
    """Creates the venv and installs OpenCV into it unless both are there (exit SKIP when
    pip cannot install, e.g. offline)."""
    if not os.path.exists(python):
        subprocess.run([sys.executable, "-m", "venv", venv], check=True,
                       capture_output=True)
    probe = subprocess.run([python, "-c", "import cv2, numpy"], capture_output=True)
    if probe.returncode != 0:
        pip = subprocess.run(
            [python, "-m", "pip", "install", "-q", "--disable-pip-version-check",
             "opencv-python-headless", "numpy"],
            capture_output=True, text=True, timeout=600)
        if pip.returncode != 0:
            last = (pip.stderr.strip().splitlines() or ["no output"])[-1]
            print(f"SKIP: cannot install opencv-python-headless into {venv} "
                  f"(offline?): {last}")
            sys.exit(SKIP)
