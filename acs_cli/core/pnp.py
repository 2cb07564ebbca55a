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

__all__ = ["BoardPose", "board_pose", "camera_in_board"]

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
