"""AprilGrid and ChArUco targets: geometry, detection on rendered frames, partial views."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.pnp import board_pose
from acs_cli.core.targets import (
    AprilGrid,
    Charuco,
    Checkerboard,
    MarkerTarget,
    aprilgrid_tag_cells,
    detect_target,
    find_other_family,
    pose_ready,
)
from sample_data_gen.render import Camera, Photometry, _environment, make_camera
from sample_data_gen.target_render import project_corners, render_target_frame, target_texture

APRIL = AprilGrid(6, 6, 0.088, 0.3)
CHARUCO = Charuco(11, 8, 0.03, 0.022, "DICT_5X5_100")
Scene = tuple[Camera, np.ndarray]
CLEAN = Photometry(gain=1.0, offset=0.0, gradient=(0.0, 0.0), blur_sigma=0.5, noise_sigma=1.0)
#: tag36h11 codes of tags 0-5, as Kalibr's createTargetPDF.py (and the AprilTag library) list
#: them.
TAG36H11 = (0xD5D628584, 0xD97F18B49, 0xDD280910E, 0xE479E9C98, 0xEBCBCA822, 0xF31DAB3AC)


def _kalibr_black_bits(code: int) -> np.ndarray:
    """Kalibr's ``generateAprilTag``: the 6x6 data cells to fill black, row 0 drawn at the
    top; bit ``6 i + j`` clear means black, then the matrix turned by ``rotation=2``."""
    cells = np.array([[not code & (1 << (6 * i + j)) for j in range(6)] for i in range(6)])
    return np.rot90(cells, 2)


def _kalibr_print(
    cols: int, rows: int, texels_per_bit: int, margin_bits: int = 4
) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """Kalibr's ``generateAprilBoard`` (tagSpacing 0.3) rasterised without ``cv2.aruco``.

    Kalibr draws in a y-up frame, tag ``x + cols y`` at ``(x, y) (1 + spacing) tagSize``, a
    border of two bits, the data bits and the squares at the tag's corners. Returns the
    image (white 255, black 0) and a map from target points (in tag sizes) to its pixels
    (the centre of the top-left pixel at (0, 0)).
    """
    tag, gap, border = 10, 3, 2  # bits: tagSize spans 10, the gap 0.3 of it
    pitch = tag + gap
    off = gap + margin_bits  # Kalibr's origin, bits from the image's left and bottom edges
    w_bits, h_bits = cols * pitch + gap + 2 * margin_bits, rows * pitch + gap + 2 * margin_bits
    b = texels_per_bit
    img = np.full((h_bits * b, w_bits * b), 255, np.uint8)

    def fill(x: float, y: float, w: float, h: float) -> None:  # Kalibr's path.rect, y up
        r0, r1 = round((h_bits - off - y - h) * b), round((h_bits - off - y) * b)
        img[r0:r1, round((x + off) * b) : round((x + off + w) * b)] = 0

    for ty in range(rows):
        for tx in range(cols):
            x, y = tx * pitch, ty * pitch
            for rect in ((0, 0, tag, border), (0, tag - border, tag, border)):
                fill(x + rect[0], y + rect[1], rect[2], rect[3])
                fill(x + rect[1], y + rect[0], rect[3], rect[2])
            black = _kalibr_black_bits(TAG36H11[cols * ty + tx])
            for i, j in zip(*np.nonzero(black), strict=True):
                fill(x + j + border, y + (border - 1) + 6 - i, 1, 1)
            for cx, cy in ((-gap, -gap), (tag, -gap), (tag, tag), (-gap, tag)):
                fill(x + cx, y + cy, gap, gap)

    def to_pixels(pts: np.ndarray) -> np.ndarray:
        u = (pts[:, 0] * tag + off) * b - 0.5
        v = (h_bits - off - pts[:, 1] * tag) * b - 0.5
        return np.stack([u, v], axis=1)

    return img, to_pixels


def test_aprilgrid_points_follow_kalibr() -> None:
    # Kalibr's 2x2 grid: points 0-1 / 4-5 are tag 0's, 2-3 / 6-7 tag 1's (bottom row)
    g = AprilGrid(2, 2, 0.1, 0.3)
    pts = g.points()
    assert pts.shape == (16, 3)
    np.testing.assert_allclose(pts[[0, 1, 2, 3], 0], [0.0, 0.1, 0.13, 0.23])
    np.testing.assert_allclose(pts[[0, 4, 8, 12], 1], [0.0, 0.1, 0.13, 0.23])
    np.testing.assert_array_equal(pts[:, 2], 0.0)
    # tag t: bottom-left, bottom-right, top-right, top-left
    np.testing.assert_array_equal(
        g.tag_corner_ids(np.arange(4)),
        [[0, 1, 5, 4], [2, 3, 7, 6], [8, 9, 13, 12], [10, 11, 15, 14]],
    )
    corners = pts[g.tag_corner_ids(np.array([3]))[0]]
    np.testing.assert_allclose(corners[2] - corners[0], [0.1, 0.1, 0.0])  # a tag's diagonal


def test_aprilgrid_tags_look_as_kalibr_prints_them() -> None:
    cells = aprilgrid_tag_cells(np.arange(len(TAG36H11)))
    assert cells.shape == (6, 10, 10)
    assert not cells[:, :2].any() and not cells[:, -2:].any()  # the two-bit black border
    assert not cells[:, :, :2].any() and not cells[:, :, -2:].any()
    for t, code in enumerate(TAG36H11):
        np.testing.assert_array_equal(cells[t, 2:-2, 2:-2], ~_kalibr_black_bits(code))


@pytest.mark.parametrize("turn_deg", [0.0, 160.0])
def test_a_grid_printed_as_kalibr_prints_it_gets_kalibrs_corner_ids(turn_deg: float) -> None:
    # a 3x2 grid drawn from the tag codes by Kalibr's algorithm, seen through a homography
    # (turned in the image: the corner ids come from the codes, not the image's axes)
    g = AprilGrid(3, 2, 0.1, 0.3)
    tex, to_tex = _kalibr_print(g.tag_cols, g.tag_rows, texels_per_bit=8)
    th, tw = tex.shape
    src = np.array([[0, 0], [tw, 0], [tw, th], [0, th]], np.float64) - 0.5
    dst = np.array([[120, 110], [540, 80], [560, 400], [90, 370]], np.float64)
    a = np.radians(turn_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    centre = np.array([320.0, 240.0])
    dst = (dst - centre) @ rot.T + centre
    H = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
    s = 4  # rendered 4x finer, then box-filtered: pixel x is fine pixel s x + (s - 1) / 2
    S = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1.0]])
    fine = cv2.warpPerspective(tex, S @ H, (640 * s, 480 * s), flags=cv2.INTER_LINEAR,
                               borderValue=200)  # fmt: skip
    img = cv2.GaussianBlur(cv2.resize(fine, (640, 480), interpolation=cv2.INTER_AREA), (0, 0), 0.7)
    truth = cv2.perspectiveTransform(to_tex(g.points() / g.tag_size)[:, None], H)[:, 0]
    det = detect_target(img, g)
    np.testing.assert_array_equal(det.ids, np.arange(g.n_corners))
    assert np.linalg.norm(det.pixels - truth, axis=1).max() < 0.1


def test_charuco_points_are_opencvs_chessboard_corners() -> None:
    pts = CHARUCO.points()
    assert pts.shape == (70, 3) == (CHARUCO.n_corners, 3)
    np.testing.assert_allclose(pts[0], [0.03, 0.03, 0.0])
    np.testing.assert_allclose(pts[11], [0.03 * 2, 0.03 * 2, 0.0])  # second row, 10 a row


@pytest.mark.parametrize(
    "make",
    [
        lambda: AprilGrid(0, 6, 0.088, 0.3),
        lambda: AprilGrid(6, 6, -0.1, 0.3),
        lambda: AprilGrid(6, 6, 0.1, 0.0),
        lambda: AprilGrid(30, 30, 0.1, 0.3),  # more tags than tag36h11 has
        lambda: Charuco(11, 8, 0.03, 0.03, "DICT_5X5_100"),
        lambda: Charuco(11, 8, 0.03, 0.02, "DICT_9X9_50"),
        lambda: Charuco(30, 30, 0.03, 0.02, "DICT_4X4_50"),
        lambda: Checkerboard(1, 6, 0.02),
    ],
)
def test_bad_geometry_is_refused(make: Callable[[], object]) -> None:
    with pytest.raises(ValueError):
        make()


def test_pose_ready_needs_enough_non_collinear_corners() -> None:
    pts = APRIL.points()
    assert pose_ready(pts[APRIL.tag_corner_ids(np.array([0, 1])).ravel()])  # two tags
    assert not pose_ready(pts[:7])
    row = pts[: 2 * APRIL.tag_cols]  # one row of corners: on a line
    assert not pose_ready(row)


def _view(target: MarkerTarget, cam: Camera, tilt_deg: float, shift: float) -> np.ndarray:
    """``T_world_cam`` of a camera facing the target's printed side, upright, at a distance
    where the target spans 70 % of the image width head on, tilted about the target's x
    axis and moved ``shift`` target widths along it."""
    pts = target.points()
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    width = float(np.ptp(pts[:, 0]))
    dist = width * cam.K[0, 0] / (0.7 * cam.width)
    y_down = isinstance(target, Charuco)  # ChArUco: z into the board; AprilGrid: z out
    R_flip = np.eye(3) if y_down else np.diag([1.0, -1.0, -1.0])
    R = se3.matrix_from_rotvec(np.array([np.radians(tilt_deg), 0.0, 0.0])) @ R_flip
    P = centre - R[:, 2] * dist + np.array([shift * width, 0.0, 0.0])
    return se3.transforms_from_rt(R, P)


@pytest.fixture(scope="module")
def scene() -> Scene:
    cam = make_camera(np.random.default_rng([7, 1]), (640, 480), 2)
    env = _environment(np.random.default_rng([7, 2]), 256)
    return cam, env


@pytest.mark.parametrize("target", [APRIL, CHARUCO], ids=["aprilgrid", "charuco"])
def test_detection_finds_the_right_ids_to_a_tenth_of_a_pixel(
    scene: Scene, target: MarkerTarget
) -> None:
    cam, env = scene
    tex = target_texture(target)
    T_wc = _view(target, cam, 20.0, 0.0)
    img = render_target_frame(cam, T_wc, tex, env, CLEAN, np.random.default_rng(3))
    truth = project_corners(cam, T_wc, target.points())
    assert np.all(np.isfinite(truth)), "the test view must show the whole target"
    det = detect_target(img, target)
    assert len(det) >= 0.95 * target.n_corners
    assert np.all(np.diff(det.ids) > 0)
    err = np.linalg.norm(det.pixels - truth[det.ids], axis=1)
    assert err.max() < 0.1
    dense = det.dense(target.n_corners)
    assert dense.shape == (target.n_corners, 2)
    np.testing.assert_array_equal(dense[det.ids], det.pixels)


@pytest.mark.parametrize("target", [APRIL, CHARUCO], ids=["aprilgrid", "charuco"])
def test_partial_view_gives_a_pose(scene: Scene, target: MarkerTarget) -> None:
    cam, env = scene
    pts = target.points()
    T_wc = _view(target, cam, 10.0, 0.7)  # about half the target out of view
    img = render_target_frame(
        cam, T_wc, target_texture(target), env, CLEAN, np.random.default_rng(4)
    )
    truth = project_corners(cam, T_wc, pts)
    in_view = np.all(np.isfinite(truth), axis=1)
    assert 0.2 < in_view.mean() < 0.8
    det = detect_target(img, target)
    assert 8 <= len(det) <= np.count_nonzero(in_view)
    assert np.all(in_view[det.ids])
    assert np.linalg.norm(det.pixels - truth[det.ids], axis=1).max() < 0.1
    assert pose_ready(pts[det.ids])
    pose = board_pose(pts[det.ids], det.pixels, cam.K, cam.dist)
    assert pose is not None
    T_true = se3.invert_transforms(T_wc)
    np.testing.assert_allclose(pose.T_cam_board[:3, 3], T_true[:3, 3], atol=2e-3)


def test_other_family_is_named_and_blank_is_not(scene: Scene) -> None:
    cam, env = scene
    T_wc = _view(APRIL, cam, 15.0, 0.0)
    img = render_target_frame(
        cam, T_wc, target_texture(APRIL), env, CLEAN, np.random.default_rng(5)
    )
    assert len(detect_target(img, CHARUCO)) == 0
    assert find_other_family(img, CHARUCO) == "DICT_APRILTAG_36h11"
    blank = np.full((240, 320), 128, np.uint8)
    assert len(detect_target(blank, APRIL)) == 0
    assert find_other_family(blank, APRIL) is None
