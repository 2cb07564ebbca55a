"""Hand-eye leave-one-out on rwhe_kuka1: how much each choice of the protocol moves TSAI.

Why do two leave-one-out protocols on the same 30 frames report TSAI at 2.45 px and at
1.69 px? Each row below changes one thing of :mod:`bench_handeye`'s protocol for OpenCV's
TSAI (``cv2.calibrateHandEye``) and prints the error four ways: the RMS over the folds of
each left-out frame's RMS point distance (``bench_handeye``'s measure; with the same number
of corners in every frame it is also the RMS over all corners of all folds), their mean,
the RMS over the first 7 folds only, and the mean over the folds of the RMS *per
coordinate* (``sqrt(mean(d**2))`` over an ``(m, 2)`` array of pixel differences: the point
distance's RMS over ``sqrt(2)``).

Rows: the baseline (acscal's detector, ``cv2.calibrateCamera`` on the 29 training frames
with 5 coefficients, ``Z`` the chordal mean of the chain); fitted on all 30 frames and
evaluated on the same (not leave-one-out), TSAI and then ``X``, ``Z`` by least squares on
the corners; intrinsics from all 30 frames; 4 coefficients (``k3 = 0``); the 8-coefficient
rational model; ``findChessboardCornersSB``'s corners; ``Z`` by least squares on the
training corners (TSAI's ``X`` held); ``X`` and ``Z`` by least squares on the corners;
``X``, ``Z`` and the intrinsics by least squares on the corners (the robot's poses held in
all three); ``Z`` from the nearest training frame alone (a local predictor, not a
calibration); the robot's poses read the other way round.

Run (about 6 minutes on 2 shared cores)::

    PYTHONPATH=. .venv/bin/python benchmarks/bench_handeye_protocols.py [--data DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import scipy.optimize
from bench_handeye import (
    COLS,
    ROWS,
    SQUARE,
    chordal_mean,
    detect,
    hand_eye,
    refine_xz,
    reprojection,
)

from acs_cli.core import se3
from acs_cli.core.intrinsics import board_points

OBJ = board_points(COLS, ROWS, SQUARE).astype(np.float32)
TSAI = cv2.CALIB_HAND_EYE_TSAI


def calibrate(corners: np.ndarray, size: tuple[int, int], flags: int = 0):
    """``K``, distortion and every frame's ``T_cam_board`` by ``cv2.calibrateCamera``."""
    _rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        [OBJ] * len(corners),
        [c.astype(np.float32) for c in corners],
        size,
        None,
        None,
        flags=flags,
    )
    T = np.stack(
        [
            se3.transforms_from_rt(cv2.Rodrigues(r)[0], t.ravel())
            for r, t in zip(rvecs, tvecs, strict=True)
        ]
    )
    return K, dist.ravel(), T


def projector(K: np.ndarray, d: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    return lambda p: cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, d)[0][:, 0]


def refine_xzk(X, Z, T_base_flange, corners, K, d):
    """``X``, ``Z`` and ``fx fy cx cy k1 k2 p1 p2 k3`` by least squares on the corners."""
    k0 = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d[:5]])
    board = board_points(COLS, ROWS, SQUARE)
    T_flange_base = se3.invert_transforms(T_base_flange)

    def unpack(p):
        k = k0 + p[12:]
        Kp = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
        dX = se3.transforms_from_rt(se3.matrix_from_rotvec(p[:3]), p[3:6])
        dZ = se3.transforms_from_rt(se3.matrix_from_rotvec(p[6:9]), p[9:12])
        return X @ dX, Z @ dZ, Kp, k[4:]

    def fun(p):
        Xp, Zp, Kp, dp = unpack(p)
        T = se3.invert_transforms(Xp) @ T_flange_base @ Zp
        x_cam = np.einsum("nij,mj->nmi", T[:, :3, :3], board) + T[:, None, :3, 3]
        return (projector(Kp, dp)(x_cam.reshape(-1, 3)) - corners.reshape(-1, 2)).ravel()

    sol = scipy.optimize.least_squares(fun, np.zeros(21), method="lm", x_scale="jac")
    return unpack(sol.x)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    root = Path(__file__).resolve().parents[1]
    ap.add_argument("--data", type=Path, default=root.parent / "shared" / "data" / "rwhe_kuka1")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        corners, size = detect(args.data, Path(tmp) / "corners.npz")
    sb = np.full_like(corners, np.nan)
    for i, f in enumerate(sorted(args.data.glob("*.png"))):
        ok, c = cv2.findChessboardCornersSB(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE), (COLS, ROWS))
        if ok:  # the same corner order as acscal's (SB may start at the opposite corner)
            c = c[:, 0].astype(float)
            flip = np.linalg.norm(c[::-1] - corners[i], axis=1).mean()
            sb[i] = c[::-1] if flip < np.linalg.norm(c - corners[i], axis=1).mean() else c
    print(
        f"findChessboardCornersSB: {np.isfinite(sb).all(axis=(1, 2)).sum()}/{len(sb)} boards, "
        f"{np.nanmean(np.linalg.norm(sb - corners, axis=2)):.3f} px from acscal's (mean)"
    )
    M = np.loadtxt(args.data / "RobotPosesVec.txt").reshape(-1, 4, 4)
    n = len(M)
    err: dict[str, list[float]] = {}

    def add(name: str, X, Z, Tbf, c, K, d) -> None:
        err.setdefault(name, []).append(reprojection(X, Z, Tbf, c, projector(K, d)))

    K30, d30, T30 = calibrate(corners, size)
    X30 = hand_eye(M, T30, TSAI)
    Z30 = chordal_mean(M @ X30 @ T30)
    X30l, Z30l = refine_xz(X30, Z30, M, corners, projector(K30, d30))
    for i in range(n):
        add("fitted on all 30, evaluated in-sample", X30, Z30, M[i], corners[i], K30, d30)
    for i in range(n):
        add("X, Z by least squares, all 30, in-sample", X30l, Z30l, M[i], corners[i], K30, d30)
    for i in range(n):
        tr = np.flatnonzero(np.arange(n) != i)
        Tf = M[tr]
        K, d, T = calibrate(corners[tr], size)
        X = hand_eye(Tf, T, TSAI)
        Z = chordal_mean(Tf @ X @ T)
        add("baseline (bench_handeye's TSAI)", X, Z, M[i], corners[i], K, d)
        X3 = hand_eye(Tf, T30[tr], TSAI)
        Z3 = chordal_mean(Tf @ X3 @ T30[tr])
        add("intrinsics from all 30 frames", X3, Z3, M[i], corners[i], K30, d30)
        for name, flags in (
            ("4 coefficients (k3 = 0)", cv2.CALIB_FIX_K3),
            ("8 coefficients (rational)", cv2.CALIB_RATIONAL_MODEL),
        ):
            Kf, df, Tc = calibrate(corners[tr], size, flags)
            Xf = hand_eye(Tf, Tc, TSAI)
            add(name, Xf, chordal_mean(Tf @ Xf @ Tc), M[i], corners[i], Kf, df)
        Ks, ds, Ts = calibrate(sb[tr], size)
        Xs = hand_eye(Tf, Ts, TSAI)
        add("findChessboardCornersSB corners", Xs, chordal_mean(Tf @ Xs @ Ts), M[i], sb[i], Ks, ds)
        Zl = refine_xz(X, Z, Tf, corners[tr], projector(K, d), refine_x=False)[1]
        add("Z by least squares on the corners", X, Zl, M[i], corners[i], K, d)
        Xl, Zl = refine_xz(X, Z, Tf, corners[tr], projector(K, d))
        add("X, Z by least squares on the corners", Xl, Zl, M[i], corners[i], K, d)
        Xk, Zk, Kk, dk = refine_xzk(X, Z, Tf, corners[tr], K, d)
        add("X, Z, intrinsics by least squares on the corners", Xk, Zk, M[i], corners[i], Kk, dk)
        j = int(np.argmin(np.linalg.norm(Tf[:, :3, 3] - M[i, :3, 3], axis=1)))
        add("Z from the nearest training frame alone", X, Tf[j] @ X @ T[j], M[i], corners[i], K, d)
        Mi = se3.invert_transforms(M)
        Xi = hand_eye(Mi[tr], T, TSAI)
        add("robot poses read as M^-1", Xi, chordal_mean(Mi[tr] @ Xi @ T), Mi[i], corners[i], K, d)
        print(f"fold {i:2d}", flush=True)
    print(
        "\n| TSAI, protocol | RMS over folds | mean over folds | first 7 folds (RMS) | "
        "per coordinate, mean over folds |"
    )
    print("| --- | --- | --- | --- | --- |")
    for k, v in err.items():
        a = np.asarray(v)
        print(
            f"| {k} | {np.sqrt(np.mean(a**2)):.3f} | {a.mean():.3f} | "
            f"{np.sqrt(np.mean(a[:7] ** 2)):.3f} | {a.mean() / np.sqrt(2):.3f} |"
        )


if __name__ == "__main__":
    main()
