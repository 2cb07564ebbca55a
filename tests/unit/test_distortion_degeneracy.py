"""Issue 11's degenerate-distortion warning (acs_cli.core.intrinsics): a rational fit of a
nearly pinhole lens is warned about, a pinhole fit of the same views is not; the
covariance it rests on is OpenCV's where OpenCV gives one."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.camera_models import camera_model
from acs_cli.core.intrinsics import (
    board_points,
    calibrate_robust,
    degenerate_distortion,
    intrinsics_covariance,
)

W, H = 1280, 800
#: A nearly pinhole lens (k1 = -0.02, k2 = 0.005).
NEAR_PINHOLE = np.array([1000.0, 1000.0, 640.0, 400.0, -0.02, 0.005, 0.0, 0.0, 0.0])


def _views(rng: np.random.Generator, n: int = 25) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """``n`` views (0.1 px noise) of a 9x6 board 0.5-0.8 m away, in the middle of the image."""
    cam = camera_model("pinhole")
    obj = board_points(9, 6, 0.04)
    views: list[np.ndarray] = []
    while len(views) < n:
        R = se3.matrix_from_rotvec(rng.normal(0, 0.35, 3))
        t = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(0.5, 0.8)])
        uv = cam.project((obj - obj.mean(axis=0)) @ R.T + t, NEAR_PINHOLE)
        if np.all(uv > 5) and np.all(uv < [W - 5, H - 5]):
            views.append(uv + rng.normal(0, 0.1, uv.shape))
    return [obj] * n, views


@pytest.mark.parametrize("seed", [0, 1])
def test_rational_fit_of_a_nearly_pinhole_lens_is_degenerate(seed: int) -> None:
    obj, img = _views(np.random.default_rng(seed))
    rational = calibrate_robust(obj, img, (W, H), "rational")
    cov = intrinsics_covariance(rational, obj, img)
    found = degenerate_distortion("rational", rational.distortion, cov[4:, 4:])
    assert found is not None and found.startswith("the rational distortion is degenerate")
    pinhole = calibrate_robust(obj, img, (W, H), "pinhole")
    cov = intrinsics_covariance(pinhole, obj, img)
    assert degenerate_distortion("pinhole", pinhole.distortion, cov[4:, 4:]) is None
    np.testing.assert_allclose(pinhole.distortion[:2], NEAR_PINHOLE[4:6], atol=0.01)


def test_covariance_is_opencvs_where_it_gives_one(rng: np.random.Generator) -> None:
    """The standard deviations from the Jacobian (poses marginalised) are OpenCV's, the
    held k3's is 0, and the covariance is symmetric."""
    obj, img = _views(rng)
    for model in ("pinhole", "rational"):
        res = calibrate_robust(obj, img, (W, H), model)
        cov = intrinsics_covariance(res, obj, img)
        std = np.sqrt(np.diag(cov))
        ocv = res.std_intrinsics
        np.testing.assert_allclose(std[:4], [ocv[k] for k in ("fx", "fy", "cx", "cy")], rtol=0.05)
        np.testing.assert_allclose(std[4:], ocv["distortion"], rtol=0.05, atol=1e-9)
        np.testing.assert_allclose(cov, cov.T, rtol=1e-9, atol=1e-15)
        assert (std[8] == 0.0) == (model == "pinhole")


def test_covariance_of_views_with_their_own_corners_is_opencvs(rng: np.random.Generator) -> None:
    """Views of different sizes (a partly seen target), one of them dropped as an outlier:
    each used view's pose is marginalised over its own corners, as OpenCV's are."""
    obj, img = _views(rng)
    keep = [rng.permutation(len(o))[: int(rng.integers(12, len(o) + 1))] for o in obj]
    obj = [o[k] for o, k in zip(obj, keep, strict=True)]
    img = [v[k] for v, k in zip(img, keep, strict=True)]
    img[3] = img[3] + rng.normal(0, 3.0, img[3].shape)  # an outlier view
    assert len({len(o) for o in obj}) > 3
    res = calibrate_robust(obj, img, (W, H), "pinhole")
    assert res.dropped == (3,)
    std = np.sqrt(np.diag(intrinsics_covariance(res, obj, img)))
    ocv = res.std_intrinsics
    np.testing.assert_allclose(std[:4], [ocv[k] for k in ("fx", "fy", "cx", "cy")], rtol=0.05)
    np.testing.assert_allclose(std[4:8], ocv["distortion"][:4], rtol=0.05)


def test_the_rules() -> None:
    """A large coefficient whose std exceeds it; two large coefficients correlated beyond
    0.999; neither for small or well-determined coefficients."""
    v = np.array([-0.3, 0.1, 1e-4, 1e-4, 0.0])
    assert degenerate_distortion("pinhole", v, np.diag([1e-4, 1e-4, 1e-6, 1e-6, 0.0])) is None
    v = np.array([19.0, -593.0, 1e-4, 1e-4, 3274.0])
    msg = degenerate_distortion("pinhole", v, np.diag([1.0, 100.0, 1e-6, 1e-6, 5000.0]) ** 2)
    assert msg is not None and "k3 = 3274 +- 5e+03" in msg and "k2" not in msg
    C = np.diag([0.1, 0.2, 0.01, 0.01]) ** 2
    C[0, 1] = C[1, 0] = 0.9995 * 0.1 * 0.2
    assert degenerate_distortion("fisheye", np.array([0.05, -0.01, 0.0, 0.0]), C) is None
    msg = degenerate_distortion("fisheye", np.array([5.0, -3.0, 0.0, 0.0]), C)
    assert msg is not None and "k1 = 5 and k2 = -3 correlated at +0.9995" in msg
    with pytest.raises(ValueError, match="4 coefficients"):
        degenerate_distortion("fisheye", np.zeros(5), np.eye(5))
