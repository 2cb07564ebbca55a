"""Bundle adjustment on checkerboard corners with the joint as a constraint.

A fixed joint leaves each frame of a camera only a rotation: with the joint at ``o`` in the
camera's frame and at ``p_w`` in the board's (world) frame, frame ``i``'s pose is
``T_w_c = [R_i, p_w - R_i o]``, so a board point ``X`` is at

    x_cam = R_i^T (X - p_w) + o

in the camera. Fitting the intrinsics, ``o``, ``p_w`` and the rotations directly to the
detected corners (pixels) is the maximum-likelihood calibration under pixel noise: the
motion constraint also pins down the intrinsics, which a separate ``calibrateCamera``
cannot use. The camera model is any of :mod:`acs_cli.core.camera_models` (OpenCV's pinhole
and rational models, and its equidistant fisheye), the intrinsic vector's length following
it. A corner not seen in a frame is NaN (or False in ``valid``): each frame may see a
different set of the target's corners (a partial view of an AprilGrid or ChArUco board).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse

from acs_cli.core import lsq, se3
from acs_cli.core.camera_models import camera_model
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

#: Fewest corners of each frame a bundle adjustment takes (a frame's pose, or rotation, is
#: then overdetermined; PnP needs as many).
MIN_FRAME_CORNERS = 4


def project_points(x_cam: FloatArray, intrinsics: FloatArray, model: str = "pinhole") -> FloatArray:
    """Projection of camera-frame points (:meth:`CameraModel.project` of ``model``).

    Parameters
    ----------
    x_cam : ndarray, shape (..., 3)
        Points in the camera's frame (metres), ``z > 0``.
    intrinsics : ndarray, shape (p,)
        ``fx, fy, cx, cy`` (pixels) and the model's distortion (OpenCV's order); ``p = 9``
        for the pinhole model (``k1, k2, p1, p2, k3``).
    model : {"pinhole", "rational", "fisheye"}

    Returns
    -------
    ndarray, shape (..., 2)
        Pixel coordinates (as OpenCV's ``projectPoints`` of the model).
    """
    return camera_model(model).project(x_cam, intrinsics)


def projection_jacobians(
    x_cam: FloatArray, intrinsics: FloatArray, model: str = "pinhole"
) -> tuple[FloatArray, FloatArray]:
    """Derivatives of :func:`project_points` for ``(k, 3)`` points.

    Returns
    -------
    d_intrinsics : ndarray, shape (k, 2, p)
    d_point : ndarray, shape (k, 2, 3)
        With respect to the camera-frame point.
    """
    return camera_model(model).jacobians(x_cam, intrinsics)


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


class _SparseRows:
    """A sparse Jacobian ``(m, p)`` assembled from per-observation blocks.

    Observation ``k`` owns the two pixel rows ``row0 + 2 k`` and ``row0 + 2 k + 1``; a
    block gives their derivatives ``(k, 2, c)`` with respect to the columns ``(k, c)`` (or
    ``(c,)`` for all observations alike). Only the non-zeros are stored, so a bundle of
    ``n`` frames costs ``O(n)`` memory instead of the dense ``O(n^2)``.
    """

    def __init__(self, shape: tuple[int, int]) -> None:
        self.shape = shape
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.vals: list[np.ndarray] = []

    def add(self, row0: int, values: FloatArray, cols: np.ndarray) -> None:
        k, two, c = values.shape
        rows = row0 + two * np.arange(k)[:, None, None] + np.arange(two)[None, :, None]
        cols = np.broadcast_to(np.asarray(cols).reshape(-1, 1, c), (k, two, c))
        self.rows.append(np.broadcast_to(rows, (k, two, c)).ravel())
        self.cols.append(cols.ravel())
        self.vals.append(np.asarray(values, dtype=float).ravel())

    def add_dense(self, row0: int, col0: int, block: FloatArray) -> None:
        """A dense block (e.g. prior rows) at ``(row0, col0)``."""
        r, c = block.shape
        rr, cc = np.meshgrid(np.arange(r) + row0, np.arange(c) + col0, indexing="ij")
        self.rows.append(rr.ravel())
        self.cols.append(cc.ravel())
        self.vals.append(np.asarray(block, dtype=float).ravel())

    def tocsr(self) -> sparse.csr_array:
        if not self.rows:
            return sparse.csr_array(self.shape)
        data = np.concatenate(self.vals)
        rc = (np.concatenate(self.rows), np.concatenate(self.cols))
        return sparse.csr_array(sparse.coo_array((data, rc), shape=self.shape))


def information(J: Any) -> FloatArray:
    """``J^T J`` ``(p, p)`` as a dense array, from a sparse or dense Jacobian ``(m, p)``."""
    H = J.T @ J
    return np.asarray(H.toarray() if sparse.issparse(H) else H)


@dataclass(frozen=True)
class FixedJointBundle:
    """Result of :func:`bundle_adjust_fixed_joint`.

    Attributes
    ----------
    model : str
        The camera model (:data:`acs_cli.core.camera_models.CAMERA_MODELS`).
    intrinsics : ndarray, shape (p,)
        Named by the model's ``names`` (``fx fy cx cy k1 k2 p1 p2 k3`` for pinhole).
    joint_in_cam : ndarray, shape (3,)
        The joint in the camera's frame (metres, the board's unit).
    joint_in_world : ndarray, shape (3,)
        The joint in the board's frame.
    T_world_cam : ndarray, shape (n, 4, 4)
        Refined poses of the frames.
    covariance : ndarray, shape (p + 6, p + 6)
        Of ``(intrinsics, joint_in_cam, joint_in_world)`` (pixel noise estimated; 0 rows
        and columns for held intrinsics).
    rms_px : float
        Reprojection RMS over the corners used.
    per_frame_rms_px : ndarray, shape (n,)
    sigma_px : float
        Estimated standard deviation of a corner coordinate.
    """

    model: str
    intrinsics: FloatArray
    joint_in_cam: FloatArray
    joint_in_world: FloatArray
    T_world_cam: FloatArray
    covariance: FloatArray
    rms_px: float
    per_frame_rms_px: FloatArray
    sigma_px: float
    success: bool

    @property
    def intrinsics_covariance(self) -> FloatArray:
        """``(p, p)`` covariance of the intrinsics."""
        p = self.intrinsics.size
        return self.covariance[:p, :p]

    @property
    def intrinsics_std(self) -> FloatArray:
        """``(p,)`` standard deviations of the intrinsics (0 for held ones)."""
        return np.sqrt(np.clip(np.diag(self.intrinsics_covariance), 0.0, None))

    @property
    def joint_covariance(self) -> FloatArray:
        """``(3, 3)`` covariance of ``joint_in_cam`` (metres squared)."""
        p = self.intrinsics.size
        return self.covariance[p : p + 3, p : p + 3]

    @property
    def joint_std(self) -> FloatArray:
        return np.sqrt(np.diag(self.joint_covariance))


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


def bundle_adjust_fixed_joint(
    corners: FloatArray,
    valid: FloatArray | None,
    board_points: FloatArray,
    intrinsics0: FloatArray,
    T_world_cam0: FloatArray,
    joint_in_cam0: FloatArray,
    joint_in_world0: FloatArray,
    *,
    model: str = "pinhole",
    held: Sequence[str] | None = None,
) -> FixedJointBundle:
    """Maximum-likelihood fixed-joint calibration of one camera from its corners.

    Parameters
    ----------
    corners : ndarray, shape (n, m, 2)
        Detected corners of ``n`` frames (pixels), in board-point order; NaN where a
        frame did not see the corner.
    valid : ndarray of bool, shape (n, m), or None
        Which corners to use (besides the finite ones); None: every finite corner.
    board_points : ndarray, shape (m, 3)
        The corners in the board's frame (metres).
    intrinsics0 : ndarray, shape (p,)
        Initial intrinsics of ``model`` (e.g. from ``cv2.calibrateCamera``).
    T_world_cam0 : ndarray, shape (n, 4, 4)
        Initial poses (e.g. from PnP); only their rotations are used.
    joint_in_cam0, joint_in_world0 : ndarray, shape (3,)
        Initial joint (e.g. from :func:`acs_cli.core.joint.estimate_joint_fixed`).
    model : {"pinhole", "rational", "fisheye"}
        The camera model of the intrinsics.
    held : sequence of str, optional
        Intrinsics held at their initial values; default the model's ``held`` (``k3`` of
        the pinhole model, as OpenCV's five-parameter fits often should for moderate
        lenses).

    Returns
    -------
    FixedJointBundle

    Raises
    ------
    InputError
        Shapes that do not fit, or a frame with fewer than :data:`MIN_FRAME_CORNERS`
        corners.
    """
    cam = camera_model(model)
    corners = np.asarray(corners, dtype=float)
    board = np.asarray(board_points, dtype=float)
    seen = observed(corners, valid, board)
    check_frame_corners(seen)
    intrinsics0 = np.asarray(intrinsics0, dtype=float)
    if intrinsics0.shape != (cam.size,):
        raise InputError(f"the {model} model takes {cam.size} intrinsics, got {intrinsics0.shape}")
    T0 = se3.check_transforms(T_world_cam0, "initial poses")
    n = seen.shape[0]
    if T0.shape[0] != n:
        raise InputError(f"{T0.shape[0]} initial poses for {n} frames")
    free_intr = cam.free(held)
    ni = len(free_intr)
    rot0 = se3.rotvec_from_matrix(T0[:, :3, :3])
    p0 = np.concatenate([intrinsics0[free_intr], joint_in_cam0, joint_in_world0, rot0.ravel()])
    frame_idx, corner_idx = np.nonzero(seen)
    obs = corners[frame_idx, corner_idx]
    rel = board[corner_idx]  # (k, 3)

    def unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        intr = intrinsics0.copy()
        intr[free_intr] = p[:ni]
        o = p[ni : ni + 3]
        pw = p[ni + 3 : ni + 6]
        R = se3.matrix_from_rotvec(p[ni + 6 :].reshape(n, 3))
        return intr, o, pw, R

    def residuals(p: FloatArray) -> FloatArray:
        intr, o, pw, R = unpack(p)
        # x_cam = R_i^T (X - p_w) + o, for every observed corner at once
        d = rel - pw
        x_cam = np.einsum("kji,kj->ki", R[frame_idx], d) + o
        return (cam.project(x_cam, intr) - obs).ravel()

    n_shared = ni + 6
    n_obs = obs.shape[0]

    def jacobian(p: FloatArray) -> sparse.csr_array:
        intr, o, pw, R = unpack(p)
        v = np.einsum("kji,kj->ki", R[frame_idx], rel - pw)  # R_i^T (X - p_w)
        Di, Dp = cam.jacobians(v + o, intr)
        Jr = right_jacobians(p[ni + 6 :].reshape(n, 3))[frame_idx]
        Jac = _SparseRows((2 * n_obs, n_shared + 3 * n))
        Jac.add(0, Di[:, :, free_intr], np.arange(ni))
        Jac.add(0, Dp, ni + np.arange(3))  # d x_cam / d o = I
        Jac.add(0, -np.matmul(Dp, np.swapaxes(R[frame_idx], 1, 2)), ni + 3 + np.arange(3))
        # x_cam = Exp(-dtheta) R^T (X - p_w) + o: d/d dtheta = [v]x, then the right Jacobian
        Jrot = np.matmul(np.matmul(Dp, se3.skew(v)), Jr)
        Jac.add(0, Jrot, n_shared + 3 * frame_idx[:, None] + np.arange(3))
        return Jac.tocsr()

    sol = lsq.solve(residuals, p0, jac=jacobian, method="normal")
    intr, o, pw, R = unpack(sol.x)
    r = sol.fun.reshape(-1, 2)
    dof = max(r.size - sol.x.size, 1)
    sigma2 = float(np.sum(r**2) / dof)
    cov_full = sigma2 * np.linalg.pinv(information(sol.jac), hermitian=True)
    cov = np.zeros((cam.size + 6, cam.size + 6))
    idx = [*free_intr, *range(cam.size, cam.size + 6)]
    cov[np.ix_(idx, idx)] = cov_full[:n_shared, :n_shared]
    t = pw - se3.rotate(R, o)
    per_frame = np.sqrt(
        np.bincount(frame_idx, weights=np.sum(r**2, axis=1), minlength=n)
        / np.maximum(np.bincount(frame_idx, minlength=n), 1)
    )
    return FixedJointBundle(
        model=model,
        intrinsics=intr,
        joint_in_cam=o,
        joint_in_world=pw,
        T_world_cam=se3.transforms_from_rt(R, t),
        covariance=cov,
        rms_px=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
        per_frame_rms_px=per_frame,
        sigma_px=float(np.sqrt(sigma2)),
        success=bool(sol.success),
    )
