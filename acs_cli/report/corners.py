"""Per-corner reprojection errors, recomputed from what a poses NPZ stores.

A poses NPZ keeps each image's detected corners, the board's points and the board pose
(``T_world_cam``, world = the board); the intrinsics the poses were solved with are in
``intrinsics.yaml``. :func:`corner_residuals` projects the board through them (the camera
model's projection, as OpenCV's ``projectPoints``) and returns every seen corner's error.
Corners not seen (NaN, on partial views of an AprilGrid or ChArUco) are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acs_cli.core.camera_models import camera_model
from acs_cli.core.se3 import FloatArray, invert_transforms

__all__ = ["CornerResiduals", "corner_residuals"]


@dataclass(frozen=True)
class CornerResiduals:
    """Every seen corner's reprojection error.

    Attributes
    ----------
    observed : ndarray, shape (k, 2)
        The detected corners, pixels.
    residual : ndarray, shape (k, 2)
        Detected minus projected, pixels.
    image : ndarray of int, shape (k,)
        The index of each corner's image.
    """

    observed: FloatArray
    residual: FloatArray
    image: np.ndarray


def corner_residuals(
    corners: FloatArray,
    board_points: FloatArray,
    T_board_cam: FloatArray,
    model: str,
    camera_matrix: FloatArray,
    distortion: FloatArray,
) -> CornerResiduals:
    """Reproject a board's points through each pose and compare with the detected corners.

    Parameters
    ----------
    corners : ndarray, shape (n, m, 2)
        Detected corners per image (pixels, board-point order; NaN where not seen).
    board_points : ndarray, shape (m, 3)
        The corners in the board's frame.
    T_board_cam : ndarray, shape (n, 4, 4)
        Each image's camera pose in the board's frame (a poses NPZ's ``T_world_cam``).
    model : str
        The camera model (``pinhole``, ``rational``, ``fisheye``).
    camera_matrix : ndarray, shape (3, 3)
    distortion : ndarray
        The model's coefficients.

    Returns
    -------
    CornerResiduals
        Seen corners in front of the camera only.
    """
    uv = np.asarray(corners, dtype=float)
    T_cam_board = invert_transforms(np.asarray(T_board_cam, dtype=float))
    P = np.asarray(board_points, dtype=float)
    x_cam = np.einsum("nij,mj->nmi", T_cam_board[:, :3, :3], P) + T_cam_board[:, None, :3, 3]
    seen = np.all(np.isfinite(uv), axis=2) & (x_cam[..., 2] > 0.0)
    cam = camera_model(model)
    projected = cam.project(x_cam[seen], cam.vector(camera_matrix, distortion))
    image = np.nonzero(seen)[0]
    return CornerResiduals(uv[seen], uv[seen] - projected, image)
