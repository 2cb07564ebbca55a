"""Checkerboard detection: OpenCV's classic loop vs findChessboardCornersSB vs acscal's.

For each detector: images with a board found, wall time per image, and the calibration
(pinhole + k1 k2 p1 p2 k3) RMS and fx from its corners; a Markdown table on stdout.

    python benchmarks/bench_detection.py [--glob '../shared/data/opencv_chessboard/left*.jpg']
        [--board 9x6] [--upscale 1.0] [--repeat 3]

The calibration RMS is the accuracy measure: with the same images and model, lower RMS
means corners more consistent with a pinhole camera seeing a planar grid.
"""

from __future__ import annotations

import argparse
import glob
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from acs_cli.core.checkerboard import detect_checkerboard
from acs_cli.core.intrinsics import board_points

DEFAULT_GLOB = str(
    Path(__file__).resolve().parents[1].parent
    / "shared"
    / "data"
    / "opencv_chessboard"
    / "left*.jpg"
)
_CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)

Detector = Callable[[np.ndarray, int, int], "np.ndarray | None"]


def classic(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    """cv2.findChessboardCorners + cornerSubPix(11x11), as in OpenCV's tutorial."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, c = cv2.findChessboardCorners(gray, (cols, rows), flags=flags)
    if not ok:
        return None
    return np.asarray(cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), _CRIT)).reshape(-1, 2)


def sb(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    """cv2.findChessboardCornersSB (exhaustive, accuracy)."""
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    ok, c = cv2.findChessboardCornersSB(gray, (cols, rows), flags=flags)
    return np.asarray(c).reshape(-1, 2) if ok else None


def ours(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    """acs_cli.core.checkerboard.detect_checkerboard."""
    return detect_checkerboard(gray, cols, rows)


def measure(
    fn: Detector, images: list[np.ndarray], cols: int, rows: int, repeat: int
) -> dict[str, float]:
    best = np.inf
    corners: list[np.ndarray | None] = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        corners = [fn(g, cols, rows) for g in images]
        best = min(best, time.perf_counter() - t0)
    found = [c for c in corners if c is not None]
    out = {"found": float(len(found)), "ms": 1000.0 * best / len(images), "rms": np.nan}
    out["fx"] = np.nan
    if len(found) >= 3:
        obj = board_points(cols, rows, 0.025).astype(np.float32)
        h, w = images[0].shape[:2]
        rms, K, *_ = cv2.calibrateCamera(
            [obj] * len(found),
            [c.astype(np.float32).reshape(-1, 1, 2) for c in found],
            (w, h),
            np.zeros((3, 3)),
            np.zeros((5, 1)),
        )
        out["rms"], out["fx"] = float(rms), float(K[0, 0])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--glob", default=DEFAULT_GLOB)
    ap.add_argument("--board", default="9x6")
    ap.add_argument("--upscale", type=float, default=1.0, help="resize images (e.g. 3)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    cols, rows = (int(v) for v in args.board.lower().split("x"))
    files = sorted(glob.glob(args.glob))
    if not files:
        raise SystemExit(f"no images match {args.glob}")
    images = [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files]
    if args.upscale != 1.0:
        images = [
            cv2.resize(g, None, fx=args.upscale, fy=args.upscale, interpolation=cv2.INTER_CUBIC)
            for g in images
        ]
    cv2.setNumThreads(1)  # one core each, as the tool's workers run
    h, w = images[0].shape[:2]
    print(f"{len(images)} images {w}x{h}, board {cols}x{rows}, best of {args.repeat}\n")
    print("| detector | boards found | calibration RMS (px) | fx (px) | ms / image |")
    print("| --- | --- | --- | --- | --- |")
    base = None
    for name, fn in (("classic + cornerSubPix 11x11", classic), ("SB", sb), ("acscal", ours)):
        r = measure(fn, images, cols, rows, args.repeat)
        base = base or r["ms"]
        print(
            f"| {name} | {int(r['found'])}/{len(images)} | {r['rms']:.4f} | {r['fx']:.2f} | "
            f"{r['ms']:.1f} ({r['ms'] / base:.2f}x) |"
        )


if __name__ == "__main__":
    main()
