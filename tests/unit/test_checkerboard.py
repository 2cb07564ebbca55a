"""Checkerboard detection, intrinsic calibration and PnP on synthetic images with known truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from acs_cli.core.checkerboard import (
    check_levels,
    check_widths,
    corner_spacing_px,
    detect_checkerboard,
    normalise_order,
    refine_saddle,
    refine_x_junction,
    reseed_outliers,
    smooth_grid,
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


def test_blurred_large_image_fit_from_the_coarse_corners_converges() -> None:
    """On a large image the fit starts at the half-resolution search's corners; on a frame
    blurred well beyond the model's edge width its steps fall short, and the step gain
    estimated from its first two rounds still brings it to the corners."""
    S = np.array([[3.0, 0, 1.0], [0, 3.0, 1.0], [0, 0, 1]])
    H = S @ _tilted_view(0.25, -0.2, 0.15)
    img, truth = render_board(9, 6, H, (1920, 1440), square=40, blur=2.5)
    corners = detect_checkerboard(img, 9, 6)
    assert corners is not None
    assert _rms(corners, normalise_order(truth, 9, 6)) < 0.01


def _distorted_grid(cols: int, rows: int) -> np.ndarray:
    """The true corners of a 24x17-like board seen steeply and through strong barrel
    distortion (pixels, row by row)."""
    K = np.array([[1900.0, 0, 960.0], [0, 1900.0, 600.0], [0, 0, 1]])
    obj = board_points(cols, rows, 0.015).astype(float)
    rvec, tvec = np.array([0.6, -0.5, 0.3]), np.array([-0.17, -0.12, 0.75])
    dist = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    uv, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return np.asarray(uv).reshape(-1, 2)


def test_smooth_grid_follows_perspective_and_distortion() -> None:
    truth = _distorted_grid(24, 17)
    got = smooth_grid(truth, 24, 17)
    assert got is not None
    grid, step = got
    assert np.max(np.linalg.norm(grid - truth, axis=1) / step) < 0.05
    moved_to, moved, _ = reseed_outliers(truth, 24, 17)
    assert not np.any(moved) and np.array_equal(moved_to, truth)


def test_reseed_outliers_puts_a_wrong_border_column_back(rng: np.random.Generator) -> None:
    """A coarse search through motion blur put several corners of the board's first column
    0.4-0.6 of the corner spacing off (5-8 px of 13, seen on renders); the smooth grid,
    fitted without them, puts them back within a fraction of a pixel, and the other
    corners stay where they were."""
    truth = _distorted_grid(24, 17)
    start = truth + rng.normal(scale=0.3, size=truth.shape)
    wrong = np.array([24, 48, 120, 144, 168, 192])
    ang = rng.uniform(0, 2 * np.pi, wrong.size)
    # the corner spacing is 23-34 px here
    start[wrong] += rng.uniform(10, 14, wrong.size)[:, None] * np.column_stack(
        [np.cos(ang), np.sin(ang)]
    )
    got, moved, _ = reseed_outliers(start, 24, 17)
    assert set(np.flatnonzero(moved)) == set(wrong)
    assert np.max(np.linalg.norm(got[wrong] - truth[wrong], axis=1)) < 0.5
    assert np.array_equal(got[~moved], start[~moved])


def test_smooth_grid_needs_a_board_of_16_corners() -> None:
    assert smooth_grid(np.zeros((15, 2)), 5, 3) is None
    c = np.zeros((4, 2))
    assert not np.any(reseed_outliers(c, 2, 2)[1])


def test_check_widths_grow_with_the_number_of_squares() -> None:
    assert check_widths(640, 9, 6) == [320, 640]
    assert check_widths(1920, 9, 6) == [320, 640]  # a 9x6 board's squares are big enough
    assert check_widths(300, 9, 6) == [300]
    # 24x17 squares are too small at 320 px; the second check is where a board half the
    # image wide shows 13 px squares, one more where a board a quarter of it wide does
    assert check_widths(1920, 24, 17) == [702, 1404]
    assert check_widths(1000, 24, 17) == [702, 1000]
    assert check_widths(1928, 28, 17) == [806, 1612]


def test_check_levels_are_pyramid_levels_at_least_as_wide_as_needed() -> None:
    assert check_levels(640, 9, 6) == [1, 0]  # 320, 640
    assert check_levels(1920, 9, 6) == [2, 1]  # 480, 960
    assert check_levels(1928, 28, 17) == [1, 0]  # 964 (>= 0.8 x 806), 1928
    assert check_levels(300, 9, 6) == [0]


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


def _x_junction_image(
    size: int, centre: tuple[float, float], angles: tuple[float, float], blur: float, ss: int = 24
) -> np.ndarray:
    """A float image of one X-junction: +-1 by the signs of the distances to two lines
    through ``centre`` (normals at ``angles``, radians), box-averaged over ss x ss
    sub-pixels (the pixel's area, OpenCV's centre convention), then blurred."""
    g = (np.arange(size * ss) + 0.5) / ss - 0.5
    X, Y = np.meshgrid(g, g)
    d1 = np.cos(angles[0]) * (X - centre[0]) + np.sin(angles[0]) * (Y - centre[1])
    d2 = np.cos(angles[1]) * (X - centre[0]) + np.sin(angles[1]) * (Y - centre[1])
    fine = np.sign(d1) * np.sign(d2)
    img = fine.reshape(size, ss, size, ss).mean(axis=(1, 3))
    return np.asarray(cv2.GaussianBlur(img, (0, 0), blur), float)


def test_refine_x_junction_is_subpixel_on_blurred_noisy_corners(rng: np.random.Generator) -> None:
    """A 2x2 grid of sheared X-junctions, blurred and noisy, started up to 0.6 px off: the
    fit lands within 0.04 px RMS whatever the blur, though the grid's directions (all the
    fit knows of the edges) differ from the junctions' by up to 0.1 rad."""
    for blur in (0.7, 1.5, 2.5):
        truth, starts, tiles = [], [], []
        for k in range(4):
            centre = (22.0 + rng.uniform(-0.5, 0.5), 22.0 + rng.uniform(-0.5, 0.5))
            angles = (rng.uniform(-0.1, 0.1), np.pi / 2 + rng.uniform(-0.1, 0.1))
            tile = 100.0 + 80.0 * _x_junction_image(45, centre, angles, blur)
            tiles.append(tile + rng.normal(0.0, 2.0, tile.shape))
            truth.append(np.array(centre) + np.array([45.0 * (k % 2), 45.0 * (k // 2)]))
            starts.append(truth[-1] + rng.uniform(-0.6, 0.6, 2))
        img = np.block([[tiles[0], tiles[1]], [tiles[2], tiles[3]]])
        out = refine_x_junction(img, np.array(starts), 2, 2, radius=10.0, iterations=6)
        assert _rms(out, np.array(truth)) < 0.04, (blur, _rms(out, np.array(truth)))


def _demosaic_pattern(img: np.ndarray, strength: float) -> np.ndarray:
    """Add a colour camera's 2-pixel periodic pattern along edges: +-``strength`` x the
    Sobel gradient magnitude, the sign alternating like a checkerboard of pixels (the real
    frames of ``rwhe_kuka1`` show about +-12 grey levels on edges of 150)."""
    f = np.asarray(img, float)
    edge = np.abs(cv2.Sobel(f, cv2.CV_64F, 1, 0)) + np.abs(cv2.Sobel(f, cv2.CV_64F, 0, 1))
    h, w = f.shape
    checker = np.where((np.add.outer(np.arange(h), np.arange(w)) % 2) == 0, 1.0, -1.0)
    return f + strength * edge * checker


def test_refine_x_junction_ignores_the_demosaicing_pattern(rng: np.random.Generator) -> None:
    """The 2-pixel periodic pattern of colour cameras along edges does not bias the fit."""
    centre = (40.3, 39.8)
    img = 120.0 + 75.0 * _x_junction_image(81, centre, (0.1, np.pi / 2 + 0.1), 0.8)
    img = _demosaic_pattern(img, 0.025) + rng.normal(0.0, 1.0, img.shape)
    # a 2x2 grid of which only the first corner is a junction (the grid gives directions)
    starts = np.array(centre) + np.array([[0.4, -0.3], [30.0, 0.0], [0.0, 30.0], [30.0, 30.0]])
    out = refine_x_junction(img, starts, 2, 2, radius=12.0, iterations=5)
    assert np.linalg.norm(out[0] - centre) < 0.05


def test_refine_x_junction_samples_8bit_images_like_float_ones(
    rng: np.random.Generator,
) -> None:
    """An 8-bit image is sampled without conversion (values rounded to whole grey levels
    after interpolation): the corners match the same image's as float to 0.01 px."""
    starts, tiles = [], []
    for k in range(4):
        centre = (22.0 + rng.uniform(-0.5, 0.5), 22.0 + rng.uniform(-0.5, 0.5))
        tiles.append(100.0 + 80.0 * _x_junction_image(45, centre, (0.05, np.pi / 2), 1.0))
        tile_origin = np.array([45.0 * (k % 2), 45.0 * (k // 2)])
        starts.append(np.array(centre) + tile_origin + rng.uniform(-1, 1, 2))
    img = np.round(
        np.block([[tiles[0], tiles[1]], [tiles[2], tiles[3]]]) + rng.normal(0, 2, (90, 90))
    )
    img8 = np.clip(img, 0, 255).astype(np.uint8)
    a = refine_x_junction(img8, np.array(starts), 2, 2, radius=10.0, iterations=6)
    b = refine_x_junction(img8.astype(float), np.array(starts), 2, 2, radius=10.0, iterations=6)
    assert np.abs(a - b).max() < 0.01


def test_refine_x_junction_rejects_bad_input() -> None:
    img = np.zeros((20, 20))
    with pytest.raises(ValueError):
        refine_x_junction(img, np.zeros((3, 2)), 2, 2, radius=5.0)
    with pytest.raises(ValueError):
        refine_x_junction(img, np.zeros((4, 2)), 2, 2, radius=1.0)


def test_detector_is_subpixel_on_a_board_with_a_demosaicing_pattern(
    rng: np.random.Generator,
) -> None:
    """The whole detector on a 1920x1200 render with the 2-pixel periodic edge pattern of a
    colour camera: corners within 0.05 px RMS of the truth. (Renders are too clean to show
    the fit's gain over gradients: benchmarks/bench_detection_real.py measures it.)"""
    K = np.array([[1900.0, 0, 959.5], [0, 1900.0, 599.5], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.35, -0.2, 0.1]))[0]
    t = np.array([0.0, 0.0, 0.9]) - R @ (np.array([6.0, 4.0, 0.0]) * 0.03)
    H = view_homography(K, cv2.Rodrigues(R)[0], t, 0.03)
    img, truth = render_board(13, 9, H, (1920, 1200), square=40, blur=0.7)
    f = _demosaic_pattern(img, 0.025) + rng.normal(0.0, 1.5, img.shape)
    img = np.clip(np.round(f), 0, 255).astype(np.uint8)
    corners = detect_checkerboard(img, 13, 9)
    assert corners is not None
    assert _rms(corners, normalise_order(truth, 13, 9)) < 0.05


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
    pose = board_pose(obj, proj.reshape(-1, 2).astype(float), K_TRUE, np.zeros(5))
    assert pose is not None and pose.rms_px < 1e-6
    np.testing.assert_allclose(pose.T_cam_board[:3, 3], tv, atol=1e-8)
    T_bc = camera_in_board(pose.T_cam_board)
    np.testing.assert_allclose(T_bc @ pose.T_cam_board, np.eye(4), atol=1e-12)
