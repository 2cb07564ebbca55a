"""Standard deviations of a fisheye calibration (``cv2.fisheye.calibrate`` gives none): from
the Jacobian with the views' poses marginalised (acs_cli.core.intrinsics), they are finite,
match the spread of repeated calibrations and are of the size OpenCV reports for a pinhole
lens seen the same way."""

from __future__ import annotations

import numpy as np

from acs_cli.core import se3
from acs_cli.core.camera_models import camera_model
from acs_cli.core.intrinsics import (
    board_points,
    calibrate_robust,
    intrinsics_covariance,
    std_from_covariance,
)

W, H = 640, 480
FISHEYE = np.array([330.0, 331.0, 321.0, 242.0, 0.03, -0.01, 0.004, -0.001])
PINHOLE = np.array([330.0, 331.0, 321.0, 242.0, -0.05, 0.01, 0.0, 0.0, 0.0])
NOISE_PX = 0.2


def _poses(rng: np.random.Generator, n: int = 20) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses (rotation, translation) that keep a 9x6 board of 0.03 m squares in
    both lenses' images."""
    obj = board_points(9, 6, 0.03)
    centred = obj - obj.mean(axis=0)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    while len(poses) < n:
        R = se3.matrix_from_rotvec(rng.normal(0, 0.4, 3))
        t = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.07, 0.07), rng.uniform(0.3, 0.5)])
        x = centred @ R.T + t
        ok = True
        for name, p in (("fisheye", FISHEYE), ("pinhole", PINHOLE)):
            uv = camera_model(name).project(x, p)
            ok &= bool(np.all(uv > 5) and np.all(uv < [W - 5, H - 5]))
        if ok:
            poses.append((R, t))
    return poses


def _views(
    model: str, params: np.ndarray, poses: list[tuple[np.ndarray, np.ndarray]],
    rng: np.random.Generator,
) -> tuple[list[np.ndarray], list[np.ndarray]]:  # fmt: skip
    obj = board_points(9, 6, 0.03)
    centred = obj - obj.mean(axis=0)
    cam = camera_model(model)
    img = [cam.project(centred @ R.T + t, params) for R, t in poses]
    return [obj] * len(img), [uv + rng.normal(0, NOISE_PX, uv.shape) for uv in img]


def test_fisheye_std_is_finite_and_matches_the_spread_of_repeated_calibrations(
    rng: np.random.Generator,
) -> None:
    poses = _poses(rng)
    fx, predicted = [], []
    for _ in range(24):
        obj, img = _views("fisheye", FISHEYE, poses, rng)
        res = calibrate_robust(obj, img, (W, H), "fisheye")
        assert res.std_intrinsics == {}  # OpenCV gives none
        std = std_from_covariance(intrinsics_covariance(res, obj, img))
        values = np.array([std[k] for k in ("fx", "fy", "cx", "cy", "distortion")], dtype=object)
        flat = np.concatenate([np.ravel(v) for v in values]).astype(float)
        assert flat.shape == (8,)
        assert np.all(np.isfinite(flat) & (flat > 0))
        fx.append(float(res.camera_matrix[0, 0]))
        predicted.append(flat[0])
    spread = float(np.std(fx, ddof=1))
    ratio = spread / float(np.mean(predicted))
    print(f"fisheye fx: spread {spread:.4f} px, predicted std {np.mean(predicted):.4f} px")
    assert 0.6 < ratio < 1.6
    assert abs(np.mean(fx) - FISHEYE[0]) < 4 * spread


def test_fisheye_std_is_near_opencvs_pinhole_std_for_the_same_views(
    rng: np.random.Generator,
) -> None:
    poses = _poses(rng)
    obj, img = _views("fisheye", FISHEYE, poses, rng)
    fish = calibrate_robust(obj, img, (W, H), "fisheye")
    fish_std = std_from_covariance(intrinsics_covariance(fish, obj, img))
    obj, img = _views("pinhole", PINHOLE, poses, rng)
    pin = calibrate_robust(obj, img, (W, H), "pinhole")
    for key in ("fx", "fy", "cx", "cy"):
        fish_px, pin_px = np.array([fish_std[key], pin.std_intrinsics[key]], dtype=float)
        print(f"{key}: fisheye {fish_px:.4f} px, pinhole (OpenCV) {pin_px:.4f} px")
        assert 1 / 3 < fish_px / pin_px < 3
