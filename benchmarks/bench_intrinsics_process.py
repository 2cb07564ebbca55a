"""``acscal intrinsics`` as a whole process against a plain OpenCV script (issue 21, item 6).

Issue 21 asks that ``acscal intrinsics`` on 30 real frames take no more than a plain
``findChessboardCorners`` + ``cornerSubPix`` + ``calibrateCamera`` script, both timed as
whole processes (start-up, imports, reading, detection, calibration, writing, exit). This
runs both on ``../shared/data/rwhe_kuka1`` (30 frames of 1928x1208, a 28x17 board of 20 mm
squares), interleaved, each ``acscal`` run with an empty output folder (no detections
cache), and prints the median and the fastest wall time of each, with the processes' CPU
time (user + system, the detection workers included).

Python's compiled bytecode is cached as on a user's machine (pip compiles an installed
package's; an editable install writes ``__pycache__`` on first use): the runs take
``PYTHONPYCACHEPREFIX`` in the work folder, without ``PYTHONDONTWRITEBYTECODE``, after one
untimed run of each. Without bytecode, compiling acscal's modules adds about 0.2 s a run.

``--tree DIR`` adds ``acscal`` from another source tree (a ``git worktree`` of an older
commit), run from the same virtual environment, so that a change is measured against its
parent in the same minutes: the timings of this shared 2-core machine drift by 20-30%
within an hour.

Run: ``.venv/bin/python benchmarks/bench_intrinsics_process.py --repeats 11 [--tree DIR]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "rwhe_kuka1"
ACSCAL = Path(sys.executable).with_name("acscal")

PLAIN = """
import sys, glob, cv2, numpy as np
cols, rows, sq = 28, 17, 0.02
obj = np.zeros((cols * rows, 3), np.float32)
obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * sq
crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
objs, imgs = [], []
for f in sorted(glob.glob(sys.argv[1] + '/*.png')):
    g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
    ok, c = cv2.findChessboardCorners(g, (cols, rows))
    if ok:
        imgs.append(cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit))
        objs.append(obj)
rms, K, d, *_ = cv2.calibrateCamera(objs, imgs, g.shape[::-1], None, None)
print(len(imgs), rms)
"""


def _timed(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU seconds (user + system, its children too) of one process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{res.stderr}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=11)
    ap.add_argument("--tree", type=Path, help="another source tree's acscal, run beside")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"rwhe_kuka1 not found at {DATA}")
    work = Path(tempfile.mkdtemp(prefix="bench_intrinsics_process_"))
    out = work / "out" / "intrinsics.yaml"
    board = ["intrinsics", str(DATA), "--board", "28x17", "--square", "0.02", "-o", str(out)]
    runs: dict[str, list[str]] = {"acscal": [str(ACSCAL), *board]}
    if args.tree is not None:
        tree = args.tree.resolve()
        code = (
            f"import sys; sys.path.insert(0, {str(tree)!r}); sys.argv[0] = 'acscal'; "
            "from acs_cli.cli.main import main; main()"
        )
        runs[f"acscal ({tree.name})"] = [sys.executable, "-c", code, *board]
    runs["plain loop"] = [sys.executable, "-c", PLAIN, str(DATA)]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(work / "pycache")
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in runs}
    try:
        for r in range(args.repeats + 1):
            for name, cmd in runs.items():
                shutil.rmtree(out.parent, ignore_errors=True)
                t = _timed(cmd, env)
                if r:  # the first: bytecode compiled and cached
                    times[name].append(t)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    plain = statistics.median(w for w, _ in times["plain loop"])
    print(f"rwhe_kuka1, 30 frames, {args.repeats} interleaved runs each")
    print("| process | wall median (s) | fastest (s) | CPU median (s) | median / plain loop's |")
    print("| --- | --- | --- | --- | --- |")
    for name, t in times.items():
        walls = [w for w, _ in t]
        med = statistics.median(walls)
        cpu = statistics.median(c for _, c in t)
        print(f"| {name} | {med:.2f} | {min(walls):.2f} | {cpu:.2f} | {med / plain:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
