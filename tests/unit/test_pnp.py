"""Board poses (acs_cli.core.pnp): one board frame for a whole sequence."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.checkerboard import normalise_order
from acs_cli.core.intrinsics import board_points
from acs_cli.core.pnp import board_pose, consistent_corner_order, reversed_order_transform

COLS, ROWS, SQUARE = 9, 6, 0.03
K = np.array([[800.0, 0, 640], [0, 800.0, 480], [0, 0, 1]])
DIST = np.zeros(5)


def _rolling_views(rng: np.random.Generator, n: int = 40) -> np.ndarray:
    """``T_cam_board`` of a camera 0.8 m from the board, rolling from 0 to 200 degrees."""
    obj = board_points(COLS, ROWS, SQUARE)
    centre = obj.mean(axis=0)
    out = []
    for roll in np.linspace(0.0, np.radians(200.0), n):
        tilt = se3.matrix_from_rotvec(rng.normal(0, 0.15, (1, 3)))[0]
        R = se3.matrix_from_rotvec(np.array([[0.0, 0.0, roll]]))[0] @ tilt
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = np.array([0, 0, 0.8]) - R @ centre
        out.append(T)
    return np.array(out)


def test_reversed_order_maps_corner_k_to_m_minus_1_minus_k() -> None:
    obj = board_points(COLS, ROWS, SQUARE)
    T = reversed_order_transform(COLS, ROWS, SQUARE)
    np.testing.assert_allclose(se3.transform_points(T, obj), obj[::-1], atol=1e-12)


def test_rolling_camera_gets_one_board_frame(rng: np.random.Generator) -> None:
    """Past 90 degrees of roll the image rule relabels the board; the sequence rule undoes it."""
    obj = board_points(COLS, ROWS, SQUARE)
    truth = _rolling_views(rng)
    poses, corners = [], []
    for T in truth:
        rvec, _ = cv2.Rodrigues(T[:3, :3])
        px, _ = cv2.projectPoints(obj, rvec, T[:3, 3], K, DIST)
        c = normalise_order(px.reshape(-1, 2) + rng.normal(0, 0.05, (len(obj), 2)), COLS, ROWS)
        pose = board_pose(obj, c, K, DIST)
        assert pose is not None
        poses.append(pose.T_cam_board)
        corners.append(c)
    T_cb = np.array(poses)
    image_rule_wrong = np.linalg.norm(T_cb[:, :3, 3] - truth[:, :3, 3], axis=1) > 0.05
    assert image_rule_wrong.sum() >= 5  # the roll did relabel some frames
    flip = consistent_corner_order(T_cb[:, :3, :3])
    T_fixed = T_cb.copy()
    T_fixed[flip] = T_cb[flip] @ reversed_order_transform(COLS, ROWS, SQUARE)
    # one frame for the sequence: the truth's, or the truth's relabelled throughout
    err = np.linalg.norm(T_fixed[:, :3, 3] - truth[:, :3, 3], axis=1)
    alt = truth @ reversed_order_transform(COLS, ROWS, SQUARE)
    err_alt = np.linalg.norm(T_fixed[:, :3, 3] - alt[:, :3, 3], axis=1)
    assert err.max() < 0.01 or err_alt.max() < 0.01
    # the relabelled corners reproject onto the same pixels
    i = int(np.flatnonzero(flip)[0])
    rvec, _ = cv2.Rodrigues(T_fixed[i, :3, :3])
    px, _ = cv2.projectPoints(obj, rvec, T_fixed[i, :3, 3], K, DIST)
    np.testing.assert_allclose(px.reshape(-1, 2), corners[i][::-1], atol=0.5)


def test_steady_sequence_is_left_alone(rng: np.random.Generator) -> None:
    R = se3.matrix_from_rotvec(rng.normal(0, 0.3, (30, 3)))
    assert not consistent_corner_order(R).any()
    assert consistent_corner_order(R[:1]).shape == (1,)
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        consistent_corner_order(np.eye(3))
