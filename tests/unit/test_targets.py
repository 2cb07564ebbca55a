"""AprilGrid and ChArUco targets: geometry, detection on rendered frames, partial views."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.pnp import board_pose
from acs_cli.core.targets import (
    AprilGrid,
    Charuco,
    Checkerboard,
    MarkerTarget,
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
