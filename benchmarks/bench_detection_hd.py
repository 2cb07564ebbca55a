"""Whole-process detection benchmark on a 1920x1200 folder of a 24x17 board (issue 3, §3).

The folder is rendered (seeded, deterministic) with ``sample_data_gen.render``: a camera
with real lens distortion, analytic anti-aliasing, blur, noise and lighting, in front of a
hard cluttered background (checker-like patches, edges, text-like blobs). Of the 28 frames,
3 show no board, 3 show it about half out of view and 22 show it whole at 0.75-1.05 m with
varied tilt. The images and their truth go to ``WORK/hd24x17`` (``/tmp`` by default) and
are reused when present; nothing is written into the repository.

Each row times the whole process, wall clock: read the images, detect, ``calibrateCamera``.

1. classic: ``cv2.findChessboardCorners`` (default flags) + ``cornerSubPix`` 11x11, in a
   loop in one process;
2. SB: ``cv2.findChessboardCornersSB`` (default flags) in a loop, and with
   ``EXHAUSTIVE | ACCURACY``;
3. acscal: ``acscal intrinsics FOLDER --board 24x17 --square 0.02 -o OUT/intrinsics.yaml``
   through the real command line, empty cache, both cores (its own robust calibration);
   also ``run_intrinsics`` in this process (no start-up) and ``detect_checkerboard`` in a
   plain loop on one core.

Accuracy, per row: the RMS of one common calibration (``cv2.calibrateCamera``, 5
distortion coefficients) from the detector's corners, and the corner error against the
true projections of the board's corners (px RMS over every corner of every detected frame).

    python benchmarks/bench_detection_hd.py [--work /tmp/acscal_bench] [--repeat 3]
        [--only classic,sb,sb_acc,acscal_loop,acscal,acscal_in_process] [--full-only]

Rendering the folder takes about 1.5 minutes the first time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import yaml  # noqa: E402

from acs_cli.core import se3  # noqa: E402
from acs_cli.core.checkerboard import DETECTOR_VERSION, detect_checkerboard  # noqa: E402
from acs_cli.core.intrinsics import board_points  # noqa: E402
from acs_cli.io.detections import read_detections  # noqa: E402
from acs_cli.io.images import list_images  # noqa: E402
from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics  # noqa: E402
from sample_data_gen import render  # noqa: E402

COLS, ROWS = 24, 17
SQUARE = 0.02  # m: the printed board is 0.54 x 0.40 m
SIZE = (1920, 1200)
N_FRAMES = 28
NO_BOARD = (5, 14, 23)  # frame indices without a board
PARTIAL = (9, 18, 26)  # frame indices with the board about half out of view
SEED = 2026
DATASET_VERSION = 1
_CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)


# --------------------------------------------------------------------------- data set


def hard_environment(rng: np.random.Generator, h: int = 3072) -> np.ndarray:
    """An equirectangular (h x 2h) clutter map that makes a checkerboard search work hard.

    The project's multi-scale noise and shapes, plus rotated checker-like patches (2-5
    squares a side), straight edges, rectangles and rows of text-like glyphs. At 3072 rows
    the 1920 px images see it at about 1.6 px per texel, so the clutter stays sharp.
    """
    tex = render._environment(rng, h)
    w = 2 * h
    for _ in range(260):  # checker-like patches: quads the classic search links up
        nx, ny = int(rng.integers(2, 6)), int(rng.integers(2, 6))
        sq = float(rng.uniform(10, 45))
        ang = rng.uniform(0, np.pi)
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        lo, hi = sorted(rng.uniform(0.05, 0.9, 2))
        if hi - lo < 0.25:
            hi = min(lo + 0.35, 0.95)
        R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        for j in range(ny):
            for i in range(nx):
                q = np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], float)
                q = (q - [nx / 2, ny / 2]) * sq @ R.T + [cx, cy]
                val = lo if (i + j) % 2 == 0 else hi
                cv2.fillConvexPoly(tex, np.round(q * 16).astype(np.int32), val, cv2.LINE_AA, 4)
    for _ in range(500):  # straight edges
        p0 = rng.uniform([0, 0], [w, h])
        p1 = p0 + rng.normal(scale=150.0, size=2)
        cv2.line(
            tex,
            (int(p0[0]), int(p0[1])),
            (int(p1[0]), int(p1[1])),
            float(rng.uniform(0.05, 0.9)),
            int(rng.integers(1, 6)),
            cv2.LINE_AA,
        )
    for _ in range(400):  # rectangles (windows, frames, boxes)
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        sx, sy = int(rng.integers(10, 120)), int(rng.integers(10, 120))
        cv2.rectangle(
            tex,
            (x0, y0),
            (x0 + sx, y0 + sy),
            float(rng.uniform(0.05, 0.9)),
            int(rng.integers(-1, 4)),
        )
    glyphs = "ABCDEFGHKMNPRSTUVWXYZ0123456789#%&@"
    fonts = (cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_TRIPLEX)
    for _ in range(700):  # lines of text-like blobs (labels, posters)
        text = "".join(rng.choice(list(glyphs), int(rng.integers(3, 14))))
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        cv2.putText(
            tex,
            text,
            (x0, y0),
            fonts[int(rng.integers(0, len(fonts)))],
            float(rng.uniform(0.6, 2.5)),
            float(rng.choice([rng.uniform(0.03, 0.2), rng.uniform(0.7, 0.95)])),
            int(rng.integers(1, 5)),
            cv2.LINE_AA,
        )
    return np.asarray(np.clip(cv2.GaussianBlur(tex, (0, 0), 0.7), 0.03, 0.95), np.float32)


def _half_view(cam: render.Camera, board: render.Board, T_world_cam: np.ndarray) -> bool:
    kind, n_in = render.classify_view(cam, board, T_world_cam)
    return kind == "partial" and 0.35 <= n_in / (board.cols * board.rows) <= 0.65


def _pose(
    rng: np.random.Generator, cam: render.Camera, board: render.Board, kind: str
) -> np.ndarray:
    for _ in range(20000):
        T = render._free_pose(rng, cam, board, 0.9, kind, 45.0)
        if kind == "partial":
            if _half_view(cam, board, T):
                return T
        elif render._view_ok(cam, board, T, kind):
            return T
    raise RuntimeError(f"could not place a {kind} view")


def make_dataset(work: Path) -> Path:
    """Render the folder into ``work / hd24x17`` (reused when complete); returns it."""
    root = work / "hd24x17"
    stamp = root / "dataset.json"
    spec = {
        "version": DATASET_VERSION,
        "seed": SEED,
        "size": SIZE,
        "board": [COLS, ROWS, SQUARE],
        "frames": N_FRAMES,
    }
    if stamp.is_file() and json.loads(stamp.read_text()) == json.loads(json.dumps(spec)):
        return root
    if root.exists():
        shutil.rmtree(root)
    (root / "images").mkdir(parents=True)
    t0 = time.perf_counter()
    cam = render.make_camera(np.random.default_rng([SEED, 1]), SIZE, supersample=2)
    board = render.Board(COLS, ROWS, SQUARE)
    env = hard_environment(np.random.default_rng([SEED, 2]))
    rng = np.random.default_rng([SEED, 3])
    kinds = [
        "none" if i in NO_BOARD else "partial" if i in PARTIAL else "full" for i in range(N_FRAMES)
    ]
    poses = np.stack([_pose(rng, cam, board, k) for k in kinds])
    img_rng = np.random.default_rng([SEED, 4])
    for i, (kind, T) in enumerate(zip(kinds, poses, strict=True)):
        ph = render._random_photometry(img_rng, True, 2.0)
        # the environment is fixed in the board's world; "none" frames look away from it
        img = render.render_view(
            cam, T, None if kind == "none" else board, np.eye(4), env, ph, img_rng
        )
        cv2.imwrite(str(root / "images" / f"img_{i:03d}.png"), img)
        print(f"  rendered {i + 1}/{N_FRAMES} ({kind})", file=sys.stderr, flush=True)
    np.savez(root / "truth.npz", K=cam.K, dist=cam.dist, T_world_cam=poses, kinds=np.array(kinds))
    stamp.write_text(json.dumps(spec))
    print(f"  data set rendered in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return root


def true_corners(truth: Any, i: int) -> np.ndarray:
    """The true (distorted) pixel positions of the board's inner corners in frame ``i``."""
    T_cb = se3.invert_transforms(truth["T_world_cam"][i])
    obj = board_points(COLS, ROWS, SQUARE).astype(float)
    rvec, _ = cv2.Rodrigues(T_cb[:3, :3])
    uv, _ = cv2.projectPoints(obj, rvec, T_cb[:3, 3], truth["K"], truth["dist"])
    return np.asarray(uv).reshape(-1, 2)


# --------------------------------------------------------------------------- detectors


def classic(gray: np.ndarray) -> np.ndarray | None:
    ok, c = cv2.findChessboardCorners(gray, (COLS, ROWS))
    if not ok:
        return None
    return np.asarray(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), _CRIT)).reshape(-1, 2)


def sb_default(gray: np.ndarray) -> np.ndarray | None:
    ok, c = cv2.findChessboardCornersSB(gray, (COLS, ROWS))
    return np.asarray(c).reshape(-1, 2) if ok else None


def sb_accuracy(gray: np.ndarray) -> np.ndarray | None:
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    ok, c = cv2.findChessboardCornersSB(gray, (COLS, ROWS), flags=flags)
    return np.asarray(c).reshape(-1, 2) if ok else None


def _calibrate(corners: list[np.ndarray]) -> tuple[float, float]:
    obj = board_points(COLS, ROWS, SQUARE).astype(np.float32)
    rms, K, *_ = cv2.calibrateCamera(
        [obj] * len(corners),
        [c.astype(np.float32).reshape(-1, 1, 2) for c in corners],
        SIZE,
        np.zeros((3, 3)),
        np.zeros((5, 1)),
    )
    return float(rms), float(K[0, 0])


def run_loop(
    fn: Callable[[np.ndarray], np.ndarray | None], files: list[Path]
) -> tuple[float, dict[int, np.ndarray], list[float]]:
    """The whole process in one loop: read, detect, calibrate. Wall time, corners, per-frame s."""
    per: list[float] = []
    found: dict[int, np.ndarray] = {}
    t0 = time.perf_counter()
    for i, f in enumerate(files):
        t = time.perf_counter()
        gray = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise SystemExit(f"cannot read {f}")
        c = fn(gray)
        if c is not None:
            found[i] = c
        per.append(time.perf_counter() - t)
    if len(found) >= 3:
        _calibrate(list(found.values()))
    return time.perf_counter() - t0, found, per


def ours(gray: np.ndarray) -> np.ndarray | None:
    return detect_checkerboard(gray, COLS, ROWS)


def run_acscal(folder: Path, out: Path) -> tuple[float, dict[int, np.ndarray], dict[str, Any]]:
    """``acscal intrinsics`` through the command line, empty cache; wall time."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    exe = Path(sys.executable).with_name("acscal")
    cmd = [str(exe), "intrinsics", str(folder), "--board", f"{COLS}x{ROWS}"]
    cmd += ["--square", str(SQUARE), "-o", str(out / "intrinsics.yaml")]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    doc = yaml.safe_load((out / "intrinsics.yaml").read_text())
    return wall, _cached_corners(folder, out / "intrinsics.detections.npz"), doc


def run_acscal_in_process(folder: Path, out: Path) -> tuple[float, dict[int, np.ndarray], float]:
    """``run_intrinsics`` (what the command runs, with both cores) in this process."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    config = IntrinsicsConfig(cols=COLS, rows=ROWS, square=SQUARE)
    t0 = time.perf_counter()
    run = run_intrinsics(folder, out / "intrinsics.yaml", config)
    wall = time.perf_counter() - t0
    return wall, _cached_corners(folder, out / "intrinsics.detections.npz"), run.calibration.rms_px


def _cached_corners(folder: Path, cache: Path) -> dict[int, np.ndarray]:
    names = [p.name for p in list_images(folder)]
    dets = {d.name: d for d in read_detections(cache).values()}
    return {
        i: np.asarray(dets[n].corners)
        for i, n in enumerate(names)
        if n in dets and dets[n].found and dets[n].corners is not None
    }


def corner_error(found: dict[int, np.ndarray], truth: Any) -> float:
    """px RMS of detected vs true corners (either of the two orders of a cols x rows grid)."""
    errs = []
    for i, c in found.items():
        t = true_corners(truth, i)
        e = min(np.sum((c - t) ** 2, axis=1).mean(), np.sum((c[::-1] - t) ** 2, axis=1).mean())
        errs.append(e)
    return float(np.sqrt(np.mean(errs))) if errs else float("nan")


# --------------------------------------------------------------------------- main


LOOPS: dict[str, tuple[str, Callable[[np.ndarray], np.ndarray | None]]] = {
    "classic": ("findChessboardCorners + cornerSubPix 11x11, loop", classic),
    "sb": ("findChessboardCornersSB (default flags), loop", sb_default),
    "sb_acc": ("findChessboardCornersSB (EXHAUSTIVE + ACCURACY), loop", sb_accuracy),
    "acscal_loop": ("acscal's detect_checkerboard, loop (one core)", ours),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/acscal_bench"))
    ap.add_argument(
        "--only",
        default="classic,sb,sb_acc,acscal_loop,acscal,acscal_in_process",
        help="comma-separated rows (the first is the time reference)",
    )
    ap.add_argument("--full-only", action="store_true", help="only the frames with a whole board")
    ap.add_argument("--repeat", type=int, default=1, help="best of N runs per row")
    args = ap.parse_args()
    which = args.only.split(",")
    root = make_dataset(args.work)
    truth = np.load(root / "truth.npz")
    kinds = [str(k) for k in truth["kinds"]]
    folder = root / "images"
    if args.full_only:  # a folder of links to the full views only, same indices in truth
        sub = root / "full_only"
        sub.mkdir(exist_ok=True)
        for i, k in enumerate(kinds):
            link = sub / f"img_{i:03d}.png"
            if k == "full" and not link.exists():
                link.symlink_to(folder / link.name)
        folder = sub
    files = list_images(folder)
    index = [int(f.stem.split("_")[1]) for f in files]
    for f in files:  # warm the page cache: every row reads from memory
        f.read_bytes()
    n_board = sum(1 for i in index if kinds[i] == "full")
    sub_kinds = [kinds[i] for i in index]
    print(
        f"{len(files)} images {SIZE[0]}x{SIZE[1]}, board {COLS}x{ROWS} x {SQUARE} m: "
        f"{n_board} whole, {sub_kinds.count('partial')} half out of view, "
        f"{sub_kinds.count('none')} without a board; {os.cpu_count()} CPUs, load "
        f"{os.getloadavg()[0]:.2f} at start; Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, {DETECTOR_VERSION}; best of {args.repeat}\n"
    )
    rows: list[tuple[str, float, dict[int, np.ndarray]]] = []
    per_kind: list[tuple[str, dict[str, list[float]]]] = []
    for key in which:
        best = np.inf
        found: dict[int, np.ndarray] = {}
        times: dict[str, list[float]] = {}
        for _ in range(args.repeat):
            if key in LOOPS:
                name, fn = LOOPS[key]
                wall, found_local, per = run_loop(fn, files)
                times = {}
                for i, p in enumerate(per):
                    times.setdefault(sub_kinds[i], []).append(p)
            elif key == "acscal":
                name = f"`acscal intrinsics` command, {os.cpu_count()} workers, empty cache"
                wall, found_local, doc = run_acscal(folder, args.work / "acscal_out")
                print(f"  (acscal's own calibration: {doc['rms_px']:.4f} px)", file=sys.stderr)
            elif key == "acscal_in_process":
                name = "acscal `run_intrinsics` in process (no start-up)"
                wall, found_local, rms = run_acscal_in_process(folder, args.work / "acscal_ip")
            else:
                raise SystemExit(f"unknown row {key!r}")
            found = {index[i]: c for i, c in found_local.items()}
            best = min(best, wall)
        print(f"  {name}: {best:.2f} s", file=sys.stderr, flush=True)
        rows.append((name, best, found))
        if times:
            per_kind.append((name, times))

    print(
        "| detector | boards found | calibration RMS (px) | corner error vs truth (px RMS) "
        f"| fx (px; true {truth['K'][0, 0]:.1f}) | whole process (s) | vs first row |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    base = rows[0][1] if rows else 1.0
    for name, wall, found in rows:
        rms, fx = _calibrate(list(found.values())) if len(found) >= 3 else (np.nan, np.nan)
        wrong = sum(1 for i in found if kinds[i] != "full")
        extra = f" (+{wrong} not whole)" if wrong else ""
        print(
            f"| {name} | {len(found)}/{n_board}{extra} | {rms:.4f} | "
            f"{corner_error(found, truth):.4f} | {fx:.1f} | {wall:.2f} | {wall / base:.2f}x |"
        )
    if per_kind:
        labels = [k for k in ("full", "partial", "none") if k in sub_kinds]
        head = {"full": "whole board", "partial": "half out of view", "none": "no board"}
        print("\nSeconds per frame (read + detect), mean / max, by frame kind:\n")
        print("| loop | " + " | ".join(head[k] for k in labels) + " |")
        print("| --- |" + " --- |" * len(labels))
        for name, times in per_kind:
            cells = [f"{np.mean(times[k]):.3f} / {np.max(times[k]):.3f}" for k in labels]
            print(f"| {name} | " + " | ".join(cells) + " |")
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
