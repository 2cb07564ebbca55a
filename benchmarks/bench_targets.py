"""AprilGrid and ChArUco on rendered sequences: corner accuracy and intrinsics accuracy.

For each target and seed, :func:`sample_data_gen.target_render.render_target_sequence`
renders a camera (640x480, radial-tangential distortion, blur 0.3-1 px, noise 2 grey
levels) filming the target, half the frames showing 30-70 % of it. Then:

- **corners**: :func:`acs_cli.core.targets.detect_target` on every frame against the true
  projections (``truth_corners.npz``): RMS, 95th percentile and largest error (px), the
  share of the corners in view that were identified, and the time per frame; beside it
  OpenCV's own corners (``ArucoDetector`` with ``CORNER_REFINE_SUBPIX`` and Kalibr's two-bit
  tag border, or
  ``CharucoDetector.detectBoard``) on the same frames;
- **intrinsics**: the intrinsics stage (:func:`acs_cli.stages.intrinsics.run_intrinsics`,
  pinhole model, every view's own corners) against the rendered camera: fx, fy error (%),
  cx, cy error (px and % of fx).

    python benchmarks/bench_targets.py [--frames 40] [--seeds 0,1,2] [--keep DIR]

A Markdown table goes to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

from acs_cli.core.targets import (
    ARUCO_DICTIONARIES,
    KALIBR_BORDER_BITS,
    KALIBR_CORNERS_FROM_ARUCO,
    AprilGrid,
    Charuco,
    MarkerTarget,
    detect_target,
)
from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics
from sample_data_gen.target_render import default_target, render_target_sequence


def opencv_corners(gray: np.ndarray, target: MarkerTarget) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's corners as ``(ids, pixels)``: the ArUco detector's sub-pixel tag corners
    (AprilGrid, Kalibr's numbering) or the ChArUco detector's chessboard corners."""
    if isinstance(target, Charuco):
        det = cv2.aruco.CharucoDetector(target.board())
        c, ids, _, _ = det.detectBoard(gray)
        if ids is None:
            return np.zeros(0, int), np.zeros((0, 2))
        return np.asarray(ids).reshape(-1), np.asarray(c, float).reshape(-1, 2)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.markerBorderBits = KALIBR_BORDER_BITS
    d = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARIES[target.dictionary])
    q, tags, _ = cv2.aruco.ArucoDetector(d, params).detectMarkers(gray)
    if tags is None:
        return np.zeros(0, int), np.zeros((0, 2))
    t = np.asarray(tags, dtype=np.int64).reshape(-1)
    keep = t < target.tag_cols * target.tag_rows
    quads = np.asarray(q, float).reshape(-1, 4, 2)[keep][:, KALIBR_CORNERS_FROM_ARUCO]
    return target.tag_corner_ids(t[keep]).reshape(-1), quads.reshape(-1, 2)


def corner_errors(folder: Path, target: MarkerTarget) -> dict[str, tuple[np.ndarray, float, float]]:
    """Per method: the errors (px) of all identified corners, the share of the corners in
    view identified, and the seconds per frame."""
    truth = np.load(folder / "truth_corners.npz")["corners"]
    images = sorted((folder / "images").glob("*.png"))
    out: dict[str, tuple[np.ndarray, float, float]] = {}
    for name, fn in (
        ("acscal", lambda g: (lambda d: (d.ids, d.pixels))(detect_target(g, target))),
        ("OpenCV", lambda g: opencv_corners(g, target)),
    ):
        errs, found, in_view, secs = [], 0, 0, 0.0
        for i, p in enumerate(images):
            gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            t0 = time.perf_counter()
            ids, px = fn(gray)
            secs += time.perf_counter() - t0
            tr = truth[i][ids]
            ok = np.all(np.isfinite(tr), axis=1)
            errs.append(np.linalg.norm(px[ok] - tr[ok], axis=1))
            found += int(ok.sum())
            in_view += int(np.all(np.isfinite(truth[i]), axis=1).sum())
        out[name] = (np.concatenate(errs), found / max(in_view, 1), secs / len(images))
    return out


def intrinsics_errors(folder: Path, target: MarkerTarget, work: Path) -> dict[str, float]:
    """The intrinsics stage on the sequence against the rendered camera."""
    truth = yaml.safe_load((folder / "truth.yaml").read_text())
    K_true = np.asarray(truth["camera"]["camera_matrix"], float)
    run = run_intrinsics(
        folder / "images", work / "intrinsics.yaml", IntrinsicsConfig(target=target, workers=1)
    )
    K = run.calibration.camera_matrix
    f = K_true[0, 0]
    return {
        "fx %": 100 * (K[0, 0] / K_true[0, 0] - 1),
        "fy %": 100 * (K[1, 1] / K_true[1, 1] - 1),
        "cx px": K[0, 2] - K_true[0, 2],
        "cy px": K[1, 2] - K_true[1, 2],
        "cx,cy % of f": 100 * float(np.hypot(K[0, 2] - K_true[0, 2], K[1, 2] - K_true[1, 2])) / f,
        "rms px": run.calibration.rms_px,
        "views": len(run.calibration.used),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=40, help="frames a sequence (default 40)")
    ap.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    ap.add_argument("--keep", type=Path, help="render into this folder and keep it")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    with tempfile.TemporaryDirectory(prefix="bench-targets-") as tmp:
        root = args.keep or Path(tmp)
        rows_c: list[str] = []
        rows_i: list[str] = []
        for kind in ("aprilgrid", "charuco"):
            target: AprilGrid | Charuco = default_target(kind)
            for seed in seeds:
                folder = root / f"{kind}_{seed}"
                if not (folder / "truth.yaml").is_file():
                    t0 = time.perf_counter()
                    render_target_sequence(folder, target, seed=seed, frames=args.frames)
                    print(f"rendered {folder} in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
                for method, (e, share, secs) in corner_errors(folder, target).items():
                    rms = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
                    rows_c.append(
                        f"| {target.short()} | {seed} | {method} | {e.size} | {100 * share:.1f} | "
                        f"{rms:.4f} | {np.percentile(e, 95):.4f} | {e.max():.4f} | "
                        f"{1000 * secs:.1f} |"
                    )
                work = folder / "calib"
                work.mkdir(exist_ok=True)
                r = intrinsics_errors(folder, target, work)
                rows_i.append(
                    f"| {target.short()} | {seed} | {r['views']} | {r['fx %']:+.4f} | "
                    f"{r['fy %']:+.4f} | {r['cx px']:+.3f} | {r['cy px']:+.3f} | "
                    f"{r['cx,cy % of f']:.4f} | {r['rms px']:.4f} |"
                )
    print(f"Rendered sequences of {args.frames} frames (640x480; half show 30-70 % of the "
          "target), seeds " + ", ".join(map(str, seeds)) + ".\n")  # fmt: skip
    print("| target | seed | method | corners | in view found % | RMS px | p95 px | max px | "
          "ms/frame |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows_c))
    print()
    print("| target | seed | views | fx err % | fy err % | cx err px | cy err px | "
          "principal point err % of f | calibration RMS px |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows_i))
    print(
        f"\n{platform.platform()}, Python {platform.python_version()}, numpy {np.__version__}, "
        f"OpenCV {cv2.__version__}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
