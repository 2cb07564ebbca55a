"""Distinct board poses among calibration views (issue 13, item 6): repeated frames of one
pose are one view; the calibration refuses fewer than MIN_VIEWS distinct poses."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from acs_cli.core.intrinsics import (
    MIN_VIEWS,
    board_points,
    calibrate,
    distinct_poses,
    honest_std,
    intrinsics_covariance,
)
from acs_cli.errors import DegenerateMotionError

K = np.array([[304.0, 0.0, 159.5], [0.0, 304.0, 119.5], [0.0, 0.0, 1.0]])
OBJ = board_points(9, 6, 0.025)
CENTRE = OBJ.mean(axis=0)


def _view(tilt_deg: float = 0.0, distance: float = 0.45, base: tuple = (20, 0, 0)) -> np.ndarray:
    """The corners seen with the board tilted ``tilt_deg`` about its centre's vertical."""
    R = Rotation.from_euler("y", tilt_deg, degrees=True).as_matrix()
    R = R @ Rotation.from_euler("xyz", base, degrees=True).as_matrix()
    t = np.array([0.0, 0.0, distance]) - R @ CENTRE
    uv, _ = cv2.projectPoints(OBJ, cv2.Rodrigues(R)[0], t, K, None)
    return uv.reshape(-1, 2)


def test_repeated_frames_are_one_pose(rng: np.random.Generator) -> None:
    frames = [_view() + rng.normal(0, 0.3, (OBJ.shape[0], 2)) for _ in range(20)]
    assert distinct_poses([OBJ] * 20, frames).tolist() == [0] * 20


@pytest.mark.parametrize(
    ("tilt", "distance", "same"),
    [(1.0, 0.45, True), (4.0, 0.45, False), (0.0, 0.451, True), (0.0, 0.465, False)],
)
def test_a_few_degrees_or_percent_make_a_new_pose(tilt: float, distance: float, same: bool) -> None:
    labels = distinct_poses([OBJ] * 2, [_view(), _view(tilt, distance)])
    assert labels.tolist() == ([0, 0] if same else [0, 1])


def test_groups_labelled_in_order_of_first_appearance() -> None:
    views = [_view(), _view(10), _view(), _view(-10), _view(10)]
    assert distinct_poses([OBJ] * 5, views).tolist() == [0, 1, 0, 2, 1]
    # a non-planar target cannot be judged by homographies: every view counts
    lifted = OBJ + np.array([0.0, 0.0, 0.01]) * (np.arange(OBJ.shape[0]) % 2)[:, None]
    assert distinct_poses([lifted] * 3, [_view()] * 3).tolist() == [0, 1, 2]


def test_calibration_refuses_two_poses_and_counts_each_once(rng: np.random.Generator) -> None:
    two = [_view(), _view(15, 0.5, (-20, 10, 0))]
    frames = [two[i % 2] + rng.normal(0, 0.1, (OBJ.shape[0], 2)) for i in range(20)]
    with pytest.raises(DegenerateMotionError, match="only 2 distinct poses") as exc:
        calibrate([OBJ] * 20, frames, (320, 240))
    assert exc.value.details == {"views": 20, "distinct_poses": 2}
    bases = [(20, 0, 0), (-15, 20, 5), (10, -25, -10), (-25, -10, 20)]
    poses = [_view(0, 0.45 + 0.05 * i, b) for i, b in enumerate(bases)]
    assert len(poses) > MIN_VIEWS
    once = [p + rng.normal(0, 0.1, p.shape) for p in poses]
    five = [p + rng.normal(0, 0.1, p.shape) for p in poses for _ in range(5)]
    std = {}
    for name, views in (("once", once), ("five", five)):
        res = calibrate([OBJ] * len(views), views, (320, 240))
        assert res.distinct == len(poses)
        std[name] = honest_std(res, intrinsics_covariance(res, [OBJ] * len(views), views))
    # five noisy copies of each pose do not make the focal length five times surer
    assert std["five"]["fx"] > 0.7 * std["once"]["fx"]
