"""Joint accuracy from rendered images: the plain OpenCV chain against acscal's.

The issue's configuration: two 1024x768 cameras, the board about 0.75 m away, the joint
about 0.25 m from each camera, 20 fixed-joint frames a camera. For each seed and camera it
measures the joint error in per cent of ``|O|`` for

* ``plain``: ``findChessboardCorners`` + ``cornerSubPix(11x11)``, ``calibrateCamera``,
  ``solvePnP``, the paper's linear pivot (Algorithm II);
* ``acscal``: acscal's detector, intrinsics and PnP, the refined fixed-joint estimator;
* ``bundle``: the same, then the fixed-joint bundle adjustment on the corners;
* ``true-K``: acscal's corners, PnP with the true intrinsics, the refined estimator
  (what perfect intrinsics would give);
* ``bundle-ideal``: the bundle adjustment on the true corner projections plus white noise
  of the detector's measured RMS (what the bundle adjustment gives when the corners have
  no systematic error).

It also prints the detector's corner error against the true projections, and (with
``--monte-carlo N``) repeats each camera's geometry N times with fresh white corner noise of
the detector's measured RMS, which separates the estimators' accuracy from the luck of a
few renders.

    python benchmarks/bench_image_chain.py --seeds 5 --work /tmp/acs_chain --monte-carlo 40
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from acs_cli.core.bundle import intrinsics_vector
from acs_cli.core.checkerboard import detect_checkerboard
from acs_cli.core.intrinsics import board_points, calibrate
from acs_cli.core.joint import estimate_pivot
from acs_cli.core.paper import algorithm_2_pivot
from acs_cli.core.pnp import board_pose, camera_in_board
from acs_cli.core.rig_bundle import bundle_adjust_fixed_joint
from acs_cli.errors import DegenerateMotionError
from sample_data_gen.render import render_scenario

METHODS = ("plain", "acscal", "bundle", "true-K", "bundle-ideal")


def _plain_corners(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    found, c = cv2.findChessboardCorners(gray, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not found:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    c = cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), crit)
    return np.asarray(c, float).reshape(-1, 2)


def _order_like(c: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Reverse a detection if that matches the true projections better (board symmetry)."""
    return c if np.sum((c - truth) ** 2) <= np.sum((c[::-1] - truth) ** 2) else c[::-1]


def _poses(obj: np.ndarray, corners: list[np.ndarray], K: np.ndarray, d: np.ndarray) -> np.ndarray:
    out = []
    for c in corners:
        bp = board_pose(obj, c, K, d)
        if bp is None:
            raise RuntimeError("PnP failed")
        out.append(camera_in_board(bp.T_cam_board))
    return np.array(out)


def _camera(folder: Path, truth: dict[str, Any], cam: str, rng: np.random.Generator) -> dict:
    doc = truth[f"cam_{cam}"]
    board = truth["boards"][f"board_{cam}"]
    cols, rows, sq = board["cols"], board["rows"], board["square"]
    K = np.array(doc["K"], float)
    dist = np.array(doc["dist"], float)
    obj = board_points(cols, rows, sq)
    o_true = np.array(truth["joint"][f"position_in_{cam}"], float)
    ours, plain, true_px = [], [], []
    for i, T_wc in enumerate(doc["T_world_cam"]):
        if doc["visibility"][i] != "full":
            continue
        # each camera's world is its board's frame (truth.yaml)
        T_cam_board = np.linalg.inv(np.array(T_wc, float))
        proj, _ = cv2.projectPoints(obj, *_rt(T_cam_board), K, dist)
        proj = proj.reshape(-1, 2)
        img = cv2.imread(str(folder / f"cam_{cam}" / f"img_{i:05d}.png"), cv2.IMREAD_GRAYSCALE)
        c = detect_checkerboard(img, cols, rows)
        p = _plain_corners(img, cols, rows)
        if c is None or p is None:
            continue
        ours.append(_order_like(c, proj))
        plain.append(_order_like(p, proj))
        true_px.append(proj)
    size = tuple(truth["image_size"])
    objs = [obj] * len(ours)
    err = np.concatenate([o - t for o, t in zip(ours, true_px, strict=True)])
    err_plain = np.concatenate([o - t for o, t in zip(plain, true_px, strict=True)])
    res: dict[str, Any] = {
        "frames": len(ours),
        "corner_rms": float(np.sqrt(np.mean(np.sum(err**2, 1)))),
        "corner_rms_plain": float(np.sqrt(np.mean(np.sum(err_plain**2, 1)))),
        "corner_bias": err.mean(0),
    }

    def pct(o: np.ndarray) -> float:
        return float(100 * np.linalg.norm(o - o_true) / np.linalg.norm(o_true))

    # plain: classic corners, calibrateCamera, solvePnP, linear pivot
    cal_p = calibrate(objs, plain, size)
    T = _poses(obj, plain, cal_p.camera_matrix, cal_p.distortion)
    try:
        res["plain"] = pct(algorithm_2_pivot(T, cam).position_in_cam)
    except DegenerateMotionError:  # the paper's method sees a hinge in noisy poses
        res["plain"] = float("nan")
    # acscal
    cal = calibrate(objs, ours, size)
    T = _poses(obj, ours, cal.camera_matrix, cal.distortion)
    est = estimate_pivot(T, "refined", cam)
    res["acscal"] = pct(est.position_in_cam)
    corners = np.array(ours)
    valid = np.ones(corners.shape[:2], bool)
    ba = bundle_adjust_fixed_joint(
        corners,
        valid,
        obj,
        intrinsics_vector(cal.camera_matrix, cal.distortion),
        T,
        est.position_in_cam,
        est.position_in_world,
    )
    res["bundle"] = pct(ba.joint_in_cam)
    res["ba_rms"] = ba.rms_px
    res["f_err_pct"] = float(100 * (cal.camera_matrix[0, 0] / K[0, 0] - 1))
    res["f_err_ba_pct"] = float(100 * (ba.intrinsics[0] / K[0, 0] - 1))
    T_true_k = _poses(obj, ours, K, dist)
    res["true-K"] = pct(estimate_pivot(T_true_k, "refined", cam).position_in_cam)
    ideal = np.array(true_px) + rng.normal(0, res["corner_rms"] / np.sqrt(2), corners.shape)
    ba_i = bundle_adjust_fixed_joint(
        ideal,
        valid,
        obj,
        intrinsics_vector(cal.camera_matrix, cal.distortion),
        T,
        est.position_in_cam,
        est.position_in_world,
    )
    res["bundle-ideal"] = pct(ba_i.joint_in_cam)
    res["ba_std_pct"] = float(100 * np.linalg.norm(ba.joint_std) / np.linalg.norm(o_true))
    res["ideal_std_pct"] = float(100 * np.linalg.norm(ba_i.joint_std) / np.linalg.norm(o_true))
    ba_t = bundle_adjust_fixed_joint(
        ideal, valid, obj, intrinsics_vector(K, dist), T_true_k, o_true, ba_i.joint_in_world
    )
    res["ideal_from_truth"] = pct(ba_t.joint_in_cam)
    res["_mc"] = (obj, np.array(true_px), K, dist, o_true, size, res["corner_rms"])
    return res


def _monte_carlo(mc: tuple, trials: int, rng: np.random.Generator) -> dict[str, float]:
    """Mean joint error (% of |O|) over fresh corner noise on one camera's geometry."""
    obj, px, K, dist, o_true, size, rms = mc
    sigma = rms / np.sqrt(2.0)
    out: dict[str, list[float]] = {"acscal": [], "bundle": [], "true-K": []}
    n_o = float(np.linalg.norm(o_true))
    for _ in range(trials):
        c = px + rng.normal(0, sigma, px.shape)
        cal = calibrate([obj] * len(c), list(c), size)
        T = _poses(obj, list(c), cal.camera_matrix, cal.distortion)
        est = estimate_pivot(T, "refined", "mc")
        ba = bundle_adjust_fixed_joint(
            c, np.ones(c.shape[:2], bool), obj,
            intrinsics_vector(cal.camera_matrix, cal.distortion),
            T, est.position_in_cam, est.position_in_world,
        )  # fmt: skip
        tk = estimate_pivot(_poses(obj, list(c), K, dist), "refined", "mc")
        for key, o in (("acscal", est.position_in_cam), ("bundle", ba.joint_in_cam),
                       ("true-K", tk.position_in_cam)):  # fmt: skip
            out[key].append(100 * float(np.linalg.norm(o - o_true)) / n_o)
    return {k: float(np.mean(v)) for k, v in out.items()}


def _rt(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    return rvec, T[:3, 3].copy()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--work", default="/tmp/acs_chain")
    p.add_argument("--size", default="1024x768")
    p.add_argument("--frames", type=int, default=20)
    p.add_argument("--noise", type=float, default=2.0, help="sensor noise, grey levels")
    p.add_argument("--monte-carlo", type=int, default=0, metavar="N", help="noise draws a camera")
    args = p.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    rows = []
    for seed in range(args.seeds):
        root = Path(args.work) / f"seed{seed}"
        folder = root / "fixed_joint"
        if not (folder / "truth.yaml").is_file():
            t0 = time.perf_counter()
            render_scenario(
                root,
                "fixed_joint",
                seed=seed,
                frames=args.frames,
                size=size,  # type: ignore[arg-type]
                board_distance=0.75,
                joint_distance=0.25,
                noise_sigma=args.noise,
            )
            print(f"rendered seed {seed} in {time.perf_counter() - t0:.1f} s")
        truth = yaml.safe_load((folder / "truth.yaml").read_text())
        for cam in "ab":
            r = _camera(folder, truth, cam, np.random.default_rng([seed, ord(cam)]))
            rows.append(r)
            print(
                f"seed {seed} cam {cam}: n={r['frames']} corners {r['corner_rms']:.3f} px "
                f"(plain {r['corner_rms_plain']:.3f}) ba_rms {r['ba_rms']:.3f} "
                f"f err {r['f_err_pct']:+.3f}% -> {r['f_err_ba_pct']:+.3f}%  "
                + "  ".join(f"{m} {r[m]:.3f}" for m in METHODS)
                + f"  | std ba {r['ba_std_pct']:.3f} ideal {r['ideal_std_pct']:.3f}"
                + f" ideal-from-truth {r['ideal_from_truth']:.3f}"
            )
    print("\nmean joint error, % of |O| (rendered images):")
    for m in METHODS:
        v = np.array([r[m] for r in rows])
        print(f"  {m:13s} {np.nanmean(v):.3f}  (max {np.nanmax(v):.3f})")
    if args.monte_carlo:
        rng = np.random.default_rng(2026)
        mc = [_monte_carlo(r["_mc"], args.monte_carlo, rng) for r in rows]
        print(f"\nmean joint error, % of |O| ({args.monte_carlo} corner-noise draws a camera):")
        for m in ("acscal", "bundle", "true-K"):
            v = np.array([r[m] for r in mc])
            print(f"  {m:13s} {v.mean():.3f}  (per camera {np.round(v, 2).tolist()})")


if __name__ == "__main__":
    main()
