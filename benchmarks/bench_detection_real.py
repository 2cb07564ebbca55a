"""Checkerboard detection on real photographs: accuracy and speed (issue 11, item 2).

Renders are too clean to show a detector's real-world error, so this runs on real frames
from ``../shared/data`` (relative to the repository; ``--data`` to point elsewhere):

- ``rwhe_kuka1``: 30 photographs, 1928x1208, a 28x17 board of 20 mm squares (a colour
  camera's frames converted to grey: its demosaicing leaves 2-pixel periodic patterns along
  the edges);
- ``opencv_chessboard``: OpenCV's 13 ``left*.jpg`` and 13 ``right*.jpg`` samples, 640x480
  JPEG, a 9x6 board, two cameras (two data sets);
- ``blank`` (not in the default ``--sets``): every sixth ``rwhe_kuka1`` frame with the board
  painted over (its grid extended by two squares each side, filled with the frame's median
  grey; located by ``findChessboardCorners``), real clutter without a board, to time the
  frames a detector must reject (the plain loop takes about a second on each).

Methods, each in a plain loop over the frames (already decoded in memory):

1. ``acscal``: :func:`acs_cli.core.checkerboard.detect_checkerboard`;
2. ``classic``: ``cv2.findChessboardCorners`` (default flags) + ``cv2.cornerSubPix`` with
   the usual 11x11 window (criteria 30 iterations, 0.001 px), the time reference; and the
   same with ``CALIB_CB_FAST_CHECK`` added, as in OpenCV's calibration sample (a loop over
   frames that may show no board needs it, or it stalls seconds on each);
3. ``SB+ACCURACY``: ``cv2.findChessboardCornersSB`` with ``CALIB_CB_ACCURACY``, retried
   with ``CALIB_CB_EXHAUSTIVE`` added on a frame where it finds nothing (both counted).

Times: each repeat runs every method once over the data set (methods interleaved, their
order rotating between repeats, so a change in the machine's load hits all of them); the
table gives the median over repeats of the loop's wall time. OpenCV runs single-threaded
(``cv2.setNumThreads(1)``) unless ``--threads default``.

Accuracy, on the frames every method detects (same frames, same model):

- **calibration RMS**: ``cv2.calibrateCamera`` (pinhole, 5 distortion coefficients) on
  each method's corners, px;
- **local-homography residual**: each corner predicted by the homography fitted to its
  grid neighbours, the 3x3 block without it (8 neighbours) or the 5x5 block (24); px RMS
  of the prediction errors over every corner with a full block in every common frame. A
  homography holds over a few squares up to the lens distortion's curvature there (the
  same for all methods), so this needs no camera model. It includes the neighbours'
  errors, so it reads above the per-corner error; the 3x3 block weighs errors that differ
  between neighbouring corners most, the 5x5 one averages more of them out.

Prints one Markdown table. Exits 0 with a message when the data is absent.

    .venv/bin/python benchmarks/bench_detection_real.py [--repeat 3] [--threads 1|default]
        [--sets kuka,left,right,blank] [--methods acscal,classic,classic_fast,sb]
        [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from acs_cli.core.checkerboard import (  # noqa: E402
    DETECTOR_VERSION,
    detect_checkerboard,
    normalise_order,
)
from acs_cli.core.intrinsics import board_points  # noqa: E402

_CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
Detector = Callable[[np.ndarray, int, int], np.ndarray | None]


@dataclass(frozen=True)
class DataSet:
    """Real frames of one camera and one board."""

    key: str
    folder: str
    pattern: str
    cols: int
    rows: int
    square: float  # metres (OpenCV's samples do not state it: any value gives the same RMS)
    blank: bool = False  # every sixth frame, the board painted over


SETS = {
    "kuka": DataSet("kuka", "rwhe_kuka1", "*.png", 28, 17, 0.020),
    "left": DataSet("left", "opencv_chessboard", "left*.jpg", 9, 6, 0.025),
    "right": DataSet("right", "opencv_chessboard", "right*.jpg", 9, 6, 0.025),
    "blank": DataSet("blank", "rwhe_kuka1", "*.png", 28, 17, 0.020, blank=True),
}


# --------------------------------------------------------------------------- detectors


def acscal(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    return detect_checkerboard(gray, cols, rows)


def classic(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    ok, c = cv2.findChessboardCorners(gray, (cols, rows))
    if not ok:
        return None
    return np.asarray(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), _CRIT)).reshape(-1, 2)


def classic_fast_check(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    ok, c = cv2.findChessboardCorners(gray, (cols, rows), flags=flags)
    if not ok:
        return None
    return np.asarray(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), _CRIT)).reshape(-1, 2)


def sb_accuracy(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    for flags in (cv2.CALIB_CB_ACCURACY, cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_EXHAUSTIVE):
        ok, c = cv2.findChessboardCornersSB(gray, (cols, rows), flags=flags)
        if ok:
            return np.asarray(c).reshape(-1, 2)
    return None


METHODS: dict[str, tuple[str, Detector]] = {
    "acscal": ("acscal detect_checkerboard", acscal),
    "classic": ("findChessboardCorners + cornerSubPix 11x11", classic),
    "classic_fast": (
        "same with CALIB_CB_FAST_CHECK (as OpenCV's calibration sample)",
        classic_fast_check,
    ),
    "sb": ("findChessboardCornersSB ACCURACY (+EXHAUSTIVE on a miss)", sb_accuracy),
}
REFERENCE = "classic"


# --------------------------------------------------------------------------- accuracy


def calibration(
    corners: list[np.ndarray], ds: DataSet, size: tuple[int, int]
) -> tuple[float, float]:
    """RMS (px) and fx (px) of one pinhole + 5-coefficient ``calibrateCamera``."""
    obj = board_points(ds.cols, ds.rows, ds.square).astype(np.float32)
    rms, K, *_ = cv2.calibrateCamera(
        [obj] * len(corners),
        [c.astype(np.float32).reshape(-1, 1, 2) for c in corners],
        size,
        np.zeros((3, 3)),
        np.zeros((5, 1)),
    )
    return float(rms), float(K[0, 0])


def local_homography_errors(corners: np.ndarray, cols: int, rows: int, k: int) -> np.ndarray:
    """Prediction errors (px), shape (m, 2), of each corner from its grid neighbours.

    For every corner with a full ``(2k + 1) x (2k + 1)`` block around it, the homography
    from grid indices (offsets ``-k..k``) to pixels is fitted (DLT, in coordinates centred
    on the neighbours' mean and scaled by their spread) to the block without the corner,
    and the corner compared with the homography's image of its own index.
    """
    g = np.asarray(corners, float).reshape(rows, cols, 2)
    dj, di = np.mgrid[-k : k + 1, -k : k + 1]
    ring = ~((di == 0) & (dj == 0))
    di, dj = di[ring], dj[ring]
    jj, ii = np.mgrid[k : rows - k, k : cols - k]
    jj, ii = jj.ravel(), ii.ravel()
    nb = g[jj[:, None] + dj[None], ii[:, None] + di[None]]  # (m, n, 2)
    centre = g[jj, ii]
    mu = nb.mean(axis=1, keepdims=True)
    scale = np.sqrt(((nb - mu) ** 2).sum(-1).mean(-1))[:, None, None]
    x = (nb - mu) / scale
    X, Y = x[..., 0], x[..., 1]
    u = np.broadcast_to(di.astype(float), X.shape)
    v = np.broadcast_to(dj.astype(float), X.shape)
    z, o = np.zeros_like(X), np.ones_like(X)
    A = np.concatenate(
        [
            np.stack([u, v, o, z, z, z, -X * u, -X * v, -X], -1),
            np.stack([z, z, z, u, v, o, -Y * u, -Y * v, -Y], -1),
        ],
        axis=1,
    )
    h = np.linalg.svd(A)[2][:, -1].reshape(-1, 3, 3)
    p = h[:, :, 2]  # image of the index offset (0, 0)
    pred = p[:, :2] / p[:, 2:] * scale[:, 0] + mu[:, 0]
    return np.asarray(centre - pred)


def local_homography_rms(found: list[np.ndarray], cols: int, rows: int, k: int) -> float:
    """px RMS of :func:`local_homography_errors` over every corner of every frame."""
    e = np.concatenate([local_homography_errors(c, cols, rows, k) for c in found])
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


# --------------------------------------------------------------------------- main


def load(ds: DataSet, data: Path) -> list[np.ndarray]:
    files = sorted((data / ds.folder).glob(ds.pattern))
    images: list[np.ndarray] = []
    for f in files:
        im = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if im is None:
            raise SystemExit(f"cannot read {f}")
        images.append(np.asarray(im))
    if not images:
        raise SystemExit(f"no images {data / ds.folder / ds.pattern}")
    return [paint_over_board(im, ds) for im in images[::6]] if ds.blank else images


def paint_over_board(gray: np.ndarray, ds: DataSet) -> np.ndarray:
    """The frame with its board, grid extended by two squares, filled with its median."""
    ok, c = cv2.findChessboardCorners(gray, (ds.cols, ds.rows))
    if not ok:
        raise SystemExit("blank set: a frame's board was not found, cannot paint it over")
    j, i = np.mgrid[0 : ds.rows, 0 : ds.cols]
    grid = np.column_stack([i.ravel(), j.ravel()]).astype(np.float32)
    H = cv2.findHomography(grid, np.asarray(c, np.float32).reshape(-1, 2))[0]
    ext = [[-2, -2], [ds.cols + 1, -2], [ds.cols + 1, ds.rows + 1], [-2, ds.rows + 1]]
    quad = cv2.perspectiveTransform(np.array(ext, np.float32).reshape(-1, 1, 2), H)
    out = gray.copy()
    cv2.fillConvexPoly(out, np.round(quad.reshape(-1, 2)).astype(np.int32), int(np.median(gray)))
    return out


def run_set(ds: DataSet, data: Path, repeat: int, keys: list[str]) -> list[str]:
    images = load(ds, data)
    h, w = images[0].shape[:2]
    for key in keys:  # warm up: first calls allocate and initialise
        METHODS[key][1](images[0], ds.cols, ds.rows)
    times: dict[str, list[float]] = {k: [] for k in keys}
    found: dict[str, list[np.ndarray | None]] = {}
    for r in range(repeat):
        order = keys[r % len(keys) :] + keys[: r % len(keys)]
        for key in order:
            fn = METHODS[key][1]
            t0 = time.perf_counter()
            out = [fn(im, ds.cols, ds.rows) for im in images]
            times[key].append(time.perf_counter() - t0)
            found[key] = out
        print(
            f"  {ds.key} repeat {r + 1}/{repeat}: "
            + ", ".join(f"{k} {times[k][-1]:.2f} s" for k in keys),
            file=sys.stderr,
            flush=True,
        )
    common = [i for i in range(len(images)) if all(found[k][i] is not None for k in keys)]
    ref = float(np.median(times[REFERENCE]))
    rows = []
    for key in keys:
        hits = sum(c is not None for c in found[key])
        total = float(np.median(times[key]))
        if len(common) >= 3:
            corners = [normalise_order(np.asarray(found[key][i]), ds.cols, ds.rows) for i in common]
            rms, fx = calibration(corners, ds, (w, h))
            lh1 = local_homography_rms(corners, ds.cols, ds.rows, 1)
            lh2 = local_homography_rms(corners, ds.cols, ds.rows, 2)
            acc = f"{rms:.4f} | {lh1:.4f} | {lh2:.4f} | {fx:.1f}"
        else:
            acc = "n/a | n/a | n/a | n/a"
        rows.append(
            f"| {ds.folder} {ds.pattern}{', board painted over' if ds.blank else ''} "
            f"({len(images)} x {w}x{h}, {ds.cols}x{ds.rows}) "
            f"| {METHODS[key][0]} | {hits}/{len(images)} | {acc} | {total:.2f} "
            f"| {1000 * total / len(images):.1f} | {total / ref:.2f}x |"
        )
    spread = f"{REFERENCE} {min(times[REFERENCE]):.2f}-{max(times[REFERENCE]):.2f} s"
    if "acscal" in keys:  # the same repeat's runs are close in time: their ratio is steadier
        ratio = np.array(times["acscal"]) / np.array(times[REFERENCE])
        spread += (
            f"; acscal / {REFERENCE} per repeat: median {np.median(ratio):.2f}x, "
            f"{ratio.min():.2f}-{ratio.max():.2f}x"
        )
    rows.append(f"| | *common frames: {len(common)}* | | | | | | | ({spread}) | |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument(
        "--sets", default="kuka,left,right", help="comma-separated: kuka,left,right,blank"
    )
    ap.add_argument("--repeat", type=int, default=3, help="runs per method; the median is shown")
    ap.add_argument(
        "--methods",
        default=",".join(METHODS),
        help=f"comma-separated, from {','.join(METHODS)} (classic is the time reference)",
    )
    ap.add_argument(
        "--threads", default="1", help="OpenCV threads: 1 (default) or 'default' (OpenCV's own)"
    )
    args = ap.parse_args()
    wanted = [SETS[k] for k in args.sets.split(",")]
    keys = args.methods.split(",")
    if REFERENCE not in keys or any(k not in METHODS for k in keys):
        raise SystemExit(f"--methods: choose from {', '.join(METHODS)}, with {REFERENCE}")
    missing = [ds.folder for ds in wanted if not (args.data / ds.folder).is_dir()]
    if missing:
        print(
            f"skipped: the real frames are not there ({', '.join(sorted(set(missing)))} under "
            f"{args.data}); they live in ../shared/data next to the repository",
        )
        return
    if args.threads != "default":
        cv2.setNumThreads(int(args.threads))
    threads = "OpenCV default threads" if args.threads == "default" else f"{args.threads} thread"
    print(
        f"{os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), load "
        f"{os.getloadavg()[0]:.2f} at start; Python {platform.python_version()}, OpenCV "
        f"{cv2.__version__}, numpy {np.__version__}, {DETECTOR_VERSION}; {threads}; median "
        f"of {args.repeat} repeats, methods interleaved\n"
    )
    lines = [
        "| data set | method | frames detected | calibration RMS (px) "
        "| local-homography residual 3x3 (px) | 5x5 (px) | fx (px) | total (s) | ms / frame "
        "| vs classic |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for ds in wanted:
        lines += run_set(ds, args.data, args.repeat, keys)
    print("\n".join(lines))
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
