"""Projections and corner bookkeeping shared by the bundle adjustments.

The bundle adjustment itself is the rig's (:mod:`acs_cli.core.rig_bundle`): a fixed-joint
session is the two-body rig of its world and the camera
(:func:`acs_cli.core.rig_bundle.bundle_adjust_fixed_joint`). Here: OpenCV's projection in
any of :mod:`acs_cli.core.camera_models`, the intrinsic vectors, and which corners a frame
saw (a corner not seen is NaN, or False in ``valid``: each frame may see a different set of
the target's corners, a partial view of an AprilGrid or ChArUco board).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse

from acs_cli.core import se3
from acs_cli.core.camera_models import camera_model
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

#: Fewest corners of each frame a bundle adjustment takes (a frame's pose, or rotation, is
#: then overdetermined; PnP needs as many).
MIN_FRAME_CORNERS = 4


def right_jacobians(rotvec: FloatArray) -> FloatArray:
    """``(n, 3, 3)`` right Jacobians of SO(3): ``Exp(phi + d) = Exp(phi) Exp(Jr(phi) d)``."""
    th = np.linalg.norm(rotvec, axis=1)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0 - th**2 / 120.0, (ths - np.sin(ths)) / ths**3)
    S = se3.skew(rotvec)
    return np.eye(3) - a[:, None, None] * S + b[:, None, None] * np.matmul(S, S)


def intrinsics_vector(K: FloatArray, dist: FloatArray, model: str = "pinhole") -> FloatArray:
    """The model's intrinsic vector from a camera matrix ``(3, 3)`` and its distortion
    coefficients (:meth:`CameraModel.vector`; ``(9,)`` for the pinhole model's 4 or 5)."""
    return camera_model(model).vector(K, dist)


def camera_matrix(intrinsics: FloatArray) -> FloatArray:
    """``(3, 3)`` camera matrix from an intrinsic vector ``(p,)`` (``fx fy cx cy ...``)."""
    fx, fy, cx, cy = intrinsics[:4]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def information(J: Any) -> FloatArray:
    """``J^T J`` ``(p, p)`` as a dense array, from a sparse or dense Jacobian ``(m, p)``."""
    H = J.T @ J
    return np.asarray(H.toarray() if sparse.issparse(H) else H)


def observed(
    corners: FloatArray, valid: FloatArray | None, board: FloatArray, what: str = "corners"
) -> np.ndarray:
    """The corners to fit: ``valid`` (all when None) where the corner is finite.

    A corner a frame did not see is NaN in ``corners`` (column ``j`` is the target's corner
    ``j``, ``board`` holds them all), so each frame may see a different set.

    Parameters
    ----------
    corners : ndarray, shape (n, m, 2)
        Pixels; NaN where not seen.
    valid : ndarray of bool, shape (n, m), or None
    board : ndarray, shape (m, 3)
        The target's corners in its frame (metres), all finite.
    what : str
        How messages name the corners (``"camera B's corners"``).

    Returns
    -------
    ndarray of bool, shape (n, m)

    Raises
    ------
    InputError
        Shapes that do not fit, or board points that are not finite.
    """
    if corners.ndim != 3 or corners.shape[2] != 2:
        raise InputError(f"{what} must have shape (n, m, 2), got {corners.shape}")
    seen = np.asarray(np.isfinite(corners).all(axis=2))
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != corners.shape[:2]:
            raise InputError(f"valid must have shape {corners.shape[:2]}, got {v.shape}")
        seen &= v
    if board.shape != (corners.shape[1], 3):
        raise InputError(f"board points must have shape ({corners.shape[1]}, 3), got {board.shape}")
    if not np.all(np.isfinite(board)):
        raise InputError("board points must be finite")
    return seen


def check_frame_corners(
    seen: np.ndarray, what: str = "a camera", frames: np.ndarray | None = None
) -> None:
    """``InputError`` naming the frames (rows of ``seen`` ``(n, m)``, numbered by
    ``frames`` ``(n,)`` when given) with fewer than :data:`MIN_FRAME_CORNERS` corners."""
    few = np.flatnonzero(seen.sum(axis=1) < MIN_FRAME_CORNERS)
    if few.size:
        names = few if frames is None else np.asarray(frames)[few]
        raise InputError(
            f"{what} sees fewer than {MIN_FRAME_CORNERS} corners at frame(s) "
            f"{', '.join(map(str, names[:5]))}{' ...' if few.size > 5 else ''}: a bundle "
            "adjustment takes frames where every camera sees its board"
        )
