"""Camera models (acs_cli.core.camera_models): OpenCV's projections and exact Jacobians."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from acs_cli.core.camera_models import CAMERA_MODELS, camera_model
from acs_cli.core.intrinsics import DISTORTION_NAMES
from acs_cli.errors import InputError

TRUTH = {
    "pinhole": np.array([900, 910, 500, 380, -0.2, 0.05, 0.001, -0.002, 0.01]),
    "rational": np.array([900, 910, 500, 380, 0.8, -0.3, 0.001, -0.002, 0.05, 1.1, -0.2, 0.03]),
    "fisheye": np.array([350, 352, 640, 400, 0.05, -0.02, 0.004, -0.001]),
}


def _points(rng: np.random.Generator, model: str, k: int = 200) -> np.ndarray:
    """Points in front of the camera: up to 35 degrees off axis, and up to 89 degrees for
    the fisheye model (a few on the optical axis itself)."""
    max_deg = 89.0 if model == "fisheye" else 35.0
    off = np.radians(rng.uniform(0, max_deg, k))
    az = rng.uniform(0, 2 * np.pi, k)
    d = np.stack([np.sin(off) * np.cos(az), np.sin(off) * np.sin(az), np.cos(off)], axis=1)
    d[:3] = [[0, 0, 1], [1e-9, 0, 1], [0, -3e-6, 1]]
    return d * rng.uniform(0.3, 5.0, (k, 1))


@pytest.mark.parametrize("model", list(CAMERA_MODELS))
def test_projection_is_opencvs(rng: np.random.Generator, model: str) -> None:
    m = camera_model(model)
    p = TRUTH[model]
    X = _points(rng, model)
    K = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1]])
    if model == "fisheye":
        uv, _ = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, p[4:])
    else:
        uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, p[4:])
    np.testing.assert_allclose(m.project(X, p), uv.reshape(-1, 2), rtol=0, atol=1e-9)
    # any leading shape
    np.testing.assert_allclose(m.project(X.reshape(4, -1, 3), p), m.project(X, p).reshape(4, -1, 2))
    assert m.names[4:] == DISTORTION_NAMES[model]


@pytest.mark.parametrize("model", list(CAMERA_MODELS))
def test_jacobians_are_central_differences(rng: np.random.Generator, model: str) -> None:
    m = camera_model(model)
    p = TRUTH[model]
    X = _points(rng, model, 60)
    Di, Dp = m.jacobians(X, p)
    assert Di.shape == (60, 2, m.size) and Dp.shape == (60, 2, 3)
    hi = 1e-6 * np.maximum(np.abs(p), 1e-2)
    num_i = np.stack(
        [(m.project(X, p + e * h) - m.project(X, p - e * h)) / (2 * h)
         for e, h in zip(np.eye(m.size), hi, strict=True)], axis=-1,
    )  # fmt: skip
    hp = 1e-7 * np.linalg.norm(X, axis=1)[:, None]
    num_p = np.stack(
        [(m.project(X + e * hp, p) - m.project(X - e * hp, p)) / (2 * hp) for e in np.eye(3)],
        axis=-1,
    )
    scale_i = np.abs(num_i).max(axis=(0, 1)) + 1.0
    np.testing.assert_allclose(Di / scale_i, num_i / scale_i, rtol=0, atol=1e-6)
    np.testing.assert_allclose(Dp, num_p, rtol=1e-6, atol=1e-3)


def test_parameters_and_bad_input() -> None:
    assert camera_model("pinhole").held == ("k3",)
    assert camera_model("pinhole").free() == list(range(8))
    assert camera_model("rational").free() == list(range(9))
    assert camera_model("rational").free(["k3"]) == [0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11]
    K = np.array([[900.0, 0, 500], [0, 910, 380], [0, 0, 1]])
    np.testing.assert_array_equal(
        camera_model("pinhole").vector(K, [0.1, 0.2, 0.3, 0.4]),
        [900, 910, 500, 380, 0.1, 0.2, 0.3, 0.4, 0.0],
    )
    with pytest.raises(InputError, match="takes 4 distortion"):
        camera_model("fisheye").vector(K, np.zeros(5))
    with pytest.raises(InputError, match="unknown camera model 'kb8'"):
        camera_model("kb8")
    with pytest.raises(ValueError, match="takes 12 intrinsics"):
        camera_model("rational").project(np.ones((2, 3)), TRUTH["pinhole"])
    with pytest.raises(ValueError, match="no parameter"):
        camera_model("fisheye").free(["p1"])
