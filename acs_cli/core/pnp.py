"""A camera's pose relative to a checkerboard from one view (PnP).

``cv2.solvePnP`` with ``SOLVEPNP_IPPE`` (exact for planar targets) gives ``T_cam_board``;
``cv2.solvePnPRefineLM`` then minimises the reprojection error. For the fisheye model the
corners are first undistorted to normalised coordinates. :func:`board_pose` returns
``T_cam_board``; a trajectory stores its inverse ``T_board_cam`` (the camera in the board's
world), see :func:`camera_in_board`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BoardPose",
    "board_pose",
    "camera_in_board",
    "consistent_corner_order",
    "reversed_order_transform",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BoardPose:
    """One view's board pose.

    Attributes
    ----------
    T_cam_board : ndarray, shape (4, 4)
        Maps board points into the camera's optical frame (translation in the board's
        length unit, e.g. metres).
    rms_px : float
        Reprojection RMS of the corners after refinement, pixels.
    """

    T_cam_board: FloatArray
    rms_px: float


def _transform(rvec: NDArray[np.floating], tvec: NDArray[np.floating]) -> FloatArray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, float).ravel()
    return T


def camera_in_board(T_cam_board: NDArray[np.floating]) -> FloatArray:
    """``T_board_cam``, the inverse of ``T_cam_board`` (shape (4, 4) or (n, 4, 4))."""
    T = np.asarray(T_cam_board, dtype=float)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def board_pose(
    object_points: NDArray[np.floating],
    image_points: NDArray[np.floating],
    camera_matrix: NDArray[np.floating],
    distortion: NDArray[np.floating],
    model: str = "pinhole",
) -> BoardPose | None:
    """Pose of a planar board in the camera frame from one view.

    Parameters
    ----------
    object_points : ndarray, shape (n, 3)
        Board corners in the board frame (z = 0), metres.
    image_points : ndarray, shape (n, 2)
        Their detections, pixels.
    camera_matrix : ndarray, shape (3, 3)
        ``K``, pixels.
    distortion : ndarray, shape (m,)
        Distortion coefficients of ``model`` (OpenCV's order).
    model : {"pinhole", "rational", "fisheye"}
        ``fisheye`` uses ``cv2.fisheye`` (4 coefficients); the others ``cv2.solvePnP``.

    Returns
    -------
    BoardPose or None
        None if OpenCV finds no pose (fewer than 4 points or a degenerate view).
    """
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    img = np.asarray(image_points, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(camera_matrix, dtype=np.float64)
    D = np.asarray(distortion, dtype=np.float64).ravel()
    if obj.shape[0] < 4 or obj.shape[0] != img.shape[0]:
        return None
    if model == "fisheye":
        und = cv2.fisheye.undistortPoints(img.reshape(-1, 1, 2), K, D[:4]).reshape(-1, 2)
        Kp, Dp, pts = np.eye(3), np.zeros(5), und
    else:
        Kp, Dp, pts = K, D, img
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, pts, Kp, Dp, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(obj, pts, Kp, Dp, rvec, tvec)
    except cv2.error:
        return None
    if model == "fisheye":
        proj, _ = cv2.fisheye.projectPoints(obj.reshape(-1, 1, 3), rvec, tvec, K, D[:4])
    else:
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, D)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
    T = _transform(np.asarray(rvec, float), np.asarray(tvec, float))
    if not np.all(np.isfinite(T)) or not np.isfinite(rms):
        return None
    return BoardPose(T, rms)


def reversed_order_transform(cols: int, rows: int, square: float) -> FloatArray:
    """``T_w1_w2``: the board frame of the reversed corner order (``w2``) in the frame of
    the original order (``w1``).

    A board of ``cols != rows`` inner corners looks the same turned by 180 degrees about
    its normal, so its corners can be labelled in two orders: corner ``k`` of one is
    corner ``m - 1 - k`` of the other, and ``X1 = Rz(180 deg) X2 + ((cols-1) s, (rows-1) s, 0)``.
    """
    T = np.eye(4)
    T[0, 0] = T[1, 1] = -1.0
    T[:3, 3] = [(cols - 1) * square, (rows - 1) * square, 0.0]
    return T


def consistent_corner_order(R_cam_board: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Which frames of a sequence to relabel so the board's frame does not jump by 180 deg.

    Each frame's corner order is chosen from the image alone (the board's x axis pointing
    right), so a camera that rolls past 90 degrees relative to the board flips the board's
    frame mid-sequence. Of the two labellings of every frame (``R`` and ``R Rz(180 deg)``)
    this picks the sequence with the least total rotation between consecutive frames
    (dynamic programming over the two states), and of that sequence and its complement
    (equally smooth) the one that relabels fewer frames.

    Parameters
    ----------
    R_cam_board : ndarray, shape (n, 3, 3)
        Rotations of ``T_cam_board`` in sequence order.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the frame's corner order should be reversed.
    """
    R = np.asarray(R_cam_board, dtype=float)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R_cam_board must have shape (n, 3, 3), got {R.shape}")
    n = R.shape[0]
    if n < 2:
        return np.zeros(n, dtype=bool)
    F = np.diag([-1.0, -1.0, 1.0])
    states = np.stack([R, R @ F], axis=1)  # (n, 2, 3, 3)
    # cost[i, a, b]: angle between frame i in state a and frame i+1 in state b
    rel = np.einsum("nakj,nbkl->nabjl", states[:-1], states[1:])
    tr = np.trace(rel, axis1=-2, axis2=-1)
    cost = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    best = np.zeros(2)
    back = np.zeros((n - 1, 2), dtype=int)
    for i in range(n - 1):  # Viterbi: two states a frame
        total = best[:, None] + cost[i]
        back[i] = np.argmin(total, axis=0)
        best = total[back[i], [0, 1]]
    path = np.zeros(n, dtype=int)
    path[-1] = int(np.argmin(best))
    for i in range(n - 2, -1, -1):
        path[i] = back[i, path[i + 1]]
    flips = path.astype(bool)
    return ~flips if flips.sum() * 2 > n else flips
