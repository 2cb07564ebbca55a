"""Checkerboard detection, intrinsic calibration and PnP on synthetic images with known truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from acs_cli.core.checkerboard import (
    check_widths,
    corner_spacing_px,
    detect_checkerboard,
    normalise_order,
    refine_saddle,
)
from acs_cli.core.intrinsics import board_points, calibrate, calibrate_robust, outlier_views
from acs_cli.core.pnp import board_pose, camera_in_board
from acs_cli.errors import DegenerateMotionError

SS = 4  # supersampling of the renderer


def render_board(
    cols: int,
    rows: int,
    H: np.ndarray,
    size: tuple[int, int],
    *,
    square: int = 40,
    blur: float = 0.0,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A board of ``cols x rows`` inner corners seen through homography ``H``.

    ``H`` maps pattern coordinates (units of one square, the first inner corner at the
    origin) to image pixels (centre of the top-left pixel at 0, 0). Returns the uint8 image
    and the true corners (cols * rows, 2) row by row.
    """
    margin = 1  # white quiet zone, in squares
    nx, ny = cols + 1 + 2 * margin, rows + 1 + 2 * margin
    pat = np.full((ny * square, nx * square), 255, np.uint8)
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                y0, x0 = (j + margin) * square, (i + margin) * square
                pat[y0 : y0 + square, x0 : x0 + square] = 0
    # pattern pixel coords (centre convention) of pattern unit point (u, v):
    #   x = (u + 1 + margin) * square - 0.5
    A = np.array(
        [
            [square, 0, (1 + margin) * square - 0.5],
            [0, square, (1 + margin) * square - 0.5],
            [0, 0, 1],
        ],
        dtype=float,
    )
    # big image pixel = SS * (small + 0.5) - 0.5
    S = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1]], dtype=float)
    H_big = S @ H @ np.linalg.inv(A)
    w, h = size
    big = cv2.warpPerspective(
        pat, H_big, (w * SS, h * SS), flags=cv2.INTER_LINEAR, borderValue=(200,)
    )
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(float)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        assert rng is not None
        img = img + rng.normal(0.0, noise, img.shape)
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    j, i = np.mgrid[0:rows, 0:cols]
    uv = np.column_stack([i.ravel(), j.ravel(), np.ones(cols * rows)])
    p = (H @ uv.T).T
    return img, p[:, :2] / p[:, 2:]


def view_homography(
    K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, square_m: float
) -> np.ndarray:
    """Homography from pattern units (squares) to pixels for a board at ``T_cam_board``."""
    R = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    M = np.column_stack([R[:, 0] * square_m, R[:, 1] * square_m, np.asarray(tvec, float)])
    return K @ M


K_TRUE = np.array([[600.0, 0, 320.0], [0, 600.0, 240.0], [0, 0, 1]])


def _tilted_view(rx: float, ry: float, rz: float, z: float = 0.45) -> np.ndarray:
    c = np.array([4.0, 2.5, 0.0]) * 0.025  # board centre (9x6: 8 x 5 squares)
    R = cv2.Rodrigues(np.array([rx, ry, rz]))[0]
    t = np.array([0.0, 0.0, z]) - R @ c
    return view_homography(K_TRUE, cv2.Rodrigues(R)[0], t, 0.025)


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.05), (0.35, -0.25, 0.2), (-0.3, 0.4, -0.3)])
def test_detects_all_corners_subpixel(angles: tuple[float, float, float]) -> None:
    H = _tilted_view(*angles)
    img, truth = render_board(9, 6, H, (640, 480), blur=0.6)
    corners = detect_checkerboard(img, 9, 6)
    assert corners is not None and corners.shape == (54, 2)
    err = _rms(corners, normalise_order(truth, 9, 6))
    assert err < 0.1, err


def test_subpixel_with_noise_and_blur(rng: np.random.Generator) -> None:
    H = _tilted_view(0.3, 0.2, 0.1)
    img, truth = render_board(9, 6, H, (640, 480), blur=1.2, noise=3.0, rng=rng)
    corners = detect_checkerboard(img, 9, 6)
    assert corners is not None
    assert _rms(corners, normalise_order(truth, 9, 6)) < 0.15


def test_large_image_uses_coarse_search_and_stays_accurate() -> None:
    S = np.array([[3.0, 0, 1.0], [0, 3.0, 1.0], [0, 0, 1]])  # pixel-centre aware 3x scale
    H = S @ _tilted_view(0.25, -0.2, 0.15)
    img, truth = render_board(9, 6, H, (1920, 1440), square=40, blur=1.5)
    corners = detect_checkerboard(img, 9, 6)
    assert corners is not None
    assert _rms(corners, normalise_order(truth, 9, 6)) < 0.15


def test_check_widths_grow_with_the_number_of_squares() -> None:
    assert check_widths(640, 9, 6) == [320, 640]
    assert check_widths(1920, 9, 6) == [320, 640]  # a 9x6 board's squares are big enough
    assert check_widths(300, 9, 6) == [300]
    # 24x17 squares are too small at 320 px; one more check where a board a quarter of
    # the image wide shows 13 px squares
    assert check_widths(1920, 24, 17) == [640, 1404]
    assert check_widths(1000, 24, 17) == [640, 1000]


def test_dense_board_on_a_large_image_is_found() -> None:
    """A 24x17 board with ~30 px squares at 1920x1200: the 640 px check cannot see it."""
    K = np.array([[1900.0, 0, 959.5], [0, 1900.0, 599.5], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.6, 0.2, 0.1]))[0]
    t = np.array([0.0, 0.0, 1.2]) - R @ (np.array([11.5, 8.0, 0.0]) * 0.02)
    H = view_homography(K, cv2.Rodrigues(R)[0], t, 0.02)
    img, truth = render_board(24, 17, H, (1920, 1200), square=40, blur=0.8)
    corners = detect_checkerboard(img, 24, 17)
    assert corners is not None
    assert _rms(corners, normalise_order(truth, 24, 17)) < 0.05


def test_no_dense_board_in_a_large_cluttered_frame(rng: np.random.Generator) -> None:
    """Clutter of many sizes: shapes, edges and text on noise (as in a room). How fast it is
    refused is measured in benchmarks/bench_detection_hd.py, not asserted here."""
    base = rng.integers(60, 200, (30, 48)).astype(np.uint8)
    clutter = cv2.resize(base, (1920, 1200), interpolation=cv2.INTER_CUBIC)
    for _ in range(400):
        x, y = int(rng.integers(0, 1920)), int(rng.integers(0, 1200))
        sx, sy = (int(v) for v in rng.integers(4, 160, 2))
        val = int(rng.integers(0, 256))
        cv2.rectangle(clutter, (x, y), (x + sx, y + sy), val, int(rng.integers(-1, 4)))
        cv2.putText(clutter, "ACS-17x24", (x, y), cv2.FONT_HERSHEY_SIMPLEX, sx / 40, 255 - val, 2)
    assert detect_checkerboard(clutter, 24, 17) is None


def test_no_board_returns_none(rng: np.random.Generator) -> None:
    blank = np.full((480, 640), 128, np.uint8)
    noise = rng.integers(0, 256, (480, 640)).astype(np.uint8)
    for img in (blank, noise):
        assert detect_checkerboard(img, 9, 6) is None


def test_wrong_board_size_is_not_found() -> None:
    img, _ = render_board(9, 6, _tilted_view(0.1, 0.1, 0.0), (640, 480))
    assert detect_checkerboard(img, 8, 5) is None


def test_ordering_is_consistent_under_a_half_turn() -> None:
    img, truth = render_board(9, 6, _tilted_view(0.2, 0.1, 0.1), (640, 480))
    turned = np.ascontiguousarray(img[::-1, ::-1])
    a = detect_checkerboard(img, 9, 6)
    b = detect_checkerboard(turned, 9, 6)
    assert a is not None and b is not None
    for c in (a, b):
        assert c[8, 0] > c[0, 0]  # the board's x axis points right
    # the half-turned image's corners are the same physical corners, reversed
    mapped = np.column_stack([639 - truth[:, 0], 479 - truth[:, 1]])
    assert _rms(b, normalise_order(mapped, 9, 6)) < 0.1


def test_normalise_order_and_spacing() -> None:
    j, i = np.mgrid[0:3, 0:4]
    grid = np.column_stack([i.ravel() * 10.0, j.ravel() * 20.0])
    np.testing.assert_array_equal(normalise_order(grid[::-1], 4, 3), grid)
    np.testing.assert_array_equal(normalise_order(grid, 4, 3), grid)
    assert corner_spacing_px(grid, 4, 3) == pytest.approx(10.0)


def test_refine_saddle_recovers_a_displaced_corner() -> None:
    img, truth = render_board(9, 6, _tilted_view(0.0, 0.0, 0.0, z=0.35), (640, 480), blur=0.8)
    start = truth + np.array([1.2, -0.9])
    refined = refine_saddle(img, start, radius=5, iterations=6)
    assert _rms(refined, truth) < 0.1


def test_detect_rejects_tiny_board_spec() -> None:
    with pytest.raises(ValueError):
        detect_checkerboard(np.zeros((10, 10), np.uint8), 1, 6)


# ---------------------------------------------------------------- intrinsics and PnP


def _synthetic_views(rng: np.random.Generator, n: int, noise: float) -> list[np.ndarray]:
    obj = board_points(9, 6, 0.025)
    views = []
    for _ in range(n):
        rv = rng.normal(0.0, 0.3, 3)
        R = cv2.Rodrigues(rv)[0]
        t = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(0.35, 0.6)])
        t -= R @ np.array([0.1, 0.0625, 0.0])
        proj, _ = cv2.projectPoints(obj, rv, t, K_TRUE, np.zeros(5))
        views.append(proj.reshape(-1, 2) + rng.normal(0.0, noise, (54, 2)))
    return views


def test_calibrate_recovers_k(rng: np.random.Generator) -> None:
    views = _synthetic_views(rng, 12, 0.1)
    obj = board_points(9, 6, 0.025)
    res = calibrate([obj] * 12, views, (640, 480))
    assert abs(res.camera_matrix[0, 0] - 600.0) < 3.0
    assert abs(res.camera_matrix[0, 2] - 320.0) < 3.0
    assert res.rms_px < 0.2 and res.per_view_rms.shape == (12,)
    assert set(res.std_intrinsics) >= {"fx", "fy", "cx", "cy", "distortion"}


def test_calibrate_robust_drops_a_bad_view(rng: np.random.Generator) -> None:
    views = _synthetic_views(rng, 10, 0.1)
    views[3] = views[3] + rng.normal(0.0, 3.0, views[3].shape)
    obj = board_points(9, 6, 0.025)
    res = calibrate_robust([obj] * 10, views, (640, 480))
    assert res.dropped == (3,)
    assert 3 not in res.used and len(res.per_view_rms) == 9


def test_outlier_rule() -> None:
    assert outlier_views(np.array([0.2, 0.21, 0.19, 0.2, 1.0])).tolist() == [4]
    assert outlier_views(np.array([0.2, 0.21, 0.19, 0.25])).tolist() == []
    assert outlier_views(np.array([0.2, 5.0])).tolist() == []


def test_too_few_views_is_degenerate(rng: np.random.Generator) -> None:
    views = _synthetic_views(rng, 2, 0.1)
    obj = board_points(9, 6, 0.025)
    with pytest.raises(DegenerateMotionError):
        calibrate([obj] * 2, views, (640, 480))


def test_fisheye_and_rational_models_run(rng: np.random.Generator) -> None:
    views = _synthetic_views(rng, 12, 0.05)
    obj = board_points(9, 6, 0.025)
    for model, m in (("rational", 8), ("fisheye", 4)):
        res = calibrate([obj] * 12, views, (640, 480), model)
        assert res.distortion.shape == (m,)
        assert abs(res.camera_matrix[0, 0] - 600.0) < 10.0


def test_board_pose_inverts_to_camera_in_board() -> None:
    obj = board_points(9, 6, 0.025)
    rv, tv = np.array([0.2, -0.1, 0.05]), np.array([-0.1, -0.05, 0.5])
    proj, _ = cv2.projectPoints(obj, rv, tv, K_TRUE, np.zeros(5))
    pose = board_pose(obj, proj.reshape(-1, 2), K_TRUE, np.zeros(5))
    assert pose is not None and pose.rms_px < 1e-6
    np.testing.assert_allclose(pose.T_cam_board[:3, 3], tv, atol=1e-8)
    T_bc = camera_in_board(pose.T_cam_board)
    np.testing.assert_allclose(T_bc @ pose.T_cam_board, np.eye(4), atol=1e-12)
