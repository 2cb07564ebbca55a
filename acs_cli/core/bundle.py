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


# ------------------------------------------------------------------ two articulated cameras


@dataclass(frozen=True)
class ArticulatedBundle:
    """Result of :func:`bundle_adjust_articulated`.

    Attributes
    ----------
    model_a, model_b : str
        Each camera's model.
    intrinsics_a, intrinsics_b : ndarray, shape (p_a,) and (p_b,)
        Each camera's intrinsics, named by its model's ``names``.
    position_in_a, position_in_b : ndarray, shape (3,)
        The joint in each camera's frame (the boards' unit).
    covariance_a, covariance_b : ndarray, shape (3, 3)
        Of the joint in each camera's frame.
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Refined poses of the frames, each in its camera's world (board) frame.
    T_b_a : ndarray, shape (n, 4, 4)
        Relative pose of the frames (maps camera A's frame into B's).
    T_wb_wa : ndarray, shape (4, 4)
        World A into world B (the identity for one shared board).
    pose_covariances : ndarray, shape (n, 6, 6)
        Of ``T_b_a`` per frame: ``(rotation perturbation on the right (rad), t_b_a)``.
    intrinsics_std_a, intrinsics_std_b : ndarray, shape (p_a,) and (p_b,)
        Standard deviations of the intrinsics (0 for held ones).
    intrinsics_covariance_a, intrinsics_covariance_b : ndarray, shape (p_a, p_a) and (p_b, p_b)
        Their covariances (0 rows and columns for held ones).
    rms_px : dict
        Reprojection RMS of each camera (``"a"``, ``"b"``).
    sigma_px : float
        Estimated standard deviation of a corner coordinate.
    success : bool
    """

    model_a: str
    model_b: str
    intrinsics_a: FloatArray
    intrinsics_b: FloatArray
    position_in_a: FloatArray
    position_in_b: FloatArray
    covariance_a: FloatArray
    covariance_b: FloatArray
    T_wa_a: FloatArray
    T_wb_b: FloatArray
    T_b_a: FloatArray
    T_wb_wa: FloatArray
    pose_covariances: FloatArray
    intrinsics_std_a: FloatArray
    intrinsics_std_b: FloatArray
    intrinsics_covariance_a: FloatArray
    intrinsics_covariance_b: FloatArray
    rms_px: dict[str, float]
    sigma_px: float
    success: bool


@dataclass(frozen=True)
class _Art:
    """Layout of the articulated bundle's parameter vector."""

    n: int
    free_a: list[int]
    free_b: list[int]
    shared_world: bool

    @property
    def k_oa(self) -> int:
        """Column of ``o_a`` (after both cameras' free intrinsics)."""
        return len(self.free_a) + len(self.free_b)

    @property
    def n_shared(self) -> int:
        return self.k_oa + 6 + (0 if self.shared_world else 6)

    def split(self, p: FloatArray) -> dict[str, FloatArray]:
        na, n, k = len(self.free_a), self.n, self.k_oa
        out = {"ia": p[:na], "ib": p[na:k], "oa": p[k : k + 3], "ob": p[k + 3 : k + 6]}
        k += 6
        if not self.shared_world:
            out["w"] = p[k : k + 6]
            k += 6
        frames = p[k:].reshape(n, 9)
        out["r"], out["t"], out["q"] = frames[:, :3], frames[:, 3:6], frames[:, 6:]
        return out


def _whitener(cov: FloatArray) -> FloatArray:
    """``W`` with ``W^T W = cov^-1`` (``(3, 3)``), for prior residuals."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    vals = np.maximum(vals, 1e-30 * max(float(vals.max()), 1e-300))
    return (vecs / np.sqrt(vals)).T


def bundle_adjust_articulated(
    corners_a: FloatArray,
    valid_a: FloatArray | None,
    board_a: FloatArray,
    corners_b: FloatArray,
    valid_b: FloatArray | None,
    board_b: FloatArray,
    intrinsics_a0: FloatArray,
    intrinsics_b0: FloatArray,
    T_wa_a0: FloatArray,
    T_wb_b0: FloatArray,
    position_in_a0: FloatArray,
    position_in_b0: FloatArray,
    *,
    T_wb_wa0: FloatArray | None = None,
    prior_a: tuple[FloatArray, FloatArray] | None = None,
    prior_b: tuple[FloatArray, FloatArray] | None = None,
    models: tuple[str, str] = ("pinhole", "pinhole"),
    held: tuple[Sequence[str] | None, Sequence[str] | None] = (None, None),
) -> ArticulatedBundle:
    """Maximum-likelihood calibration of two cameras joined by a ball joint, from corners.

    Frame ``i`` has camera A's pose in world A, ``T_wa_a_i`` (6 unknowns), and the joint's
    rotation ``R_a_b_i`` (3 unknowns): the joint at ``o_a`` in A and ``o_b`` in B fixes the
    translation, ``T_a_b_i = [R_a_b_i, o_a - R_a_b_i o_b]`` (the paper's eq. (2) constraint,
    ``O_A = H_AB O_B``). Camera B's pose in world B is ``T_wb_wa T_wa_a_i T_a_b_i``. With
    one shared board (the overlap scenario, ``T_wb_wa0`` None) world B is world A; with
    two boards (the general scenario) ``T_wb_wa`` is one more unknown. The intrinsics of
    both cameras, ``o_a``, ``o_b`` and every frame's unknowns are fitted to the detected
    corners of both cameras.

    Parameters
    ----------
    corners_a, corners_b : ndarray, shape (n, m_a, 2) and (n, m_b, 2)
        Detected corners of the ``n`` paired frames (pixels), in board-point order; NaN
        where a frame did not see the corner.
    valid_a, valid_b : ndarray of bool, shape (n, m_a) and (n, m_b), or None
        Which corners to use (besides the finite ones); None: every finite corner.
    board_a, board_b : ndarray, shape (m_a, 3) and (m_b, 3)
        The corners in each board's frame (metres).
    intrinsics_a0, intrinsics_b0 : ndarray, shape (p_a,) and (p_b,)
        Initial intrinsics of each camera's model.
    T_wa_a0, T_wb_b0 : ndarray, shape (n, 4, 4)
        Initial poses (e.g. from PnP), each camera in its board's frame.
    position_in_a0, position_in_b0 : ndarray, shape (3,)
        Initial joint.
    T_wb_wa0 : ndarray, shape (4, 4), optional
        Initial world A -> world B transform; None for one shared board.
    prior_a, prior_b : (mean (3,), covariance (3, 3)), optional
        Independent estimates of the joint (e.g. from a fixed-joint session), fused with
        the corners.
    models : (str, str)
        Camera A's and B's models (:data:`acs_cli.core.camera_models.CAMERA_MODELS`).
    held : (sequence of str or None, sequence of str or None)
        Intrinsics of A and B held at their initial values; None: the model's default
        (``k3`` of the pinhole model).

    Returns
    -------
    ArticulatedBundle

    Raises
    ------
    InputError
        Shapes that do not fit, or a frame where a camera sees fewer than
        :data:`MIN_FRAME_CORNERS` corners.
    """
    cam_a, cam_b = camera_model(models[0]), camera_model(models[1])
    ca, cb = np.asarray(corners_a, float), np.asarray(corners_b, float)
    Xa, Xb = np.asarray(board_a, float), np.asarray(board_b, float)
    va = observed(ca, valid_a, Xa, "camera A's corners")
    vb = observed(cb, valid_b, Xb, "camera B's corners")
    check_frame_corners(va, "camera A")
    check_frame_corners(vb, "camera B")
    Ta0 = se3.check_transforms(T_wa_a0, "initial poses of A")
    Tb0 = se3.check_transforms(T_wb_b0, "initial poses of B")
    n = ca.shape[0]
    if not (cb.shape[0] == Ta0.shape[0] == Tb0.shape[0] == n):
        raise InputError(
            f"corners and poses must describe the same paired frames: {n}, {cb.shape[0]}, "
            f"{Ta0.shape[0]}, {Tb0.shape[0]}"
        )
    shared = T_wb_wa0 is None
    W0 = np.eye(4)
    if T_wb_wa0 is not None:
        W0 = se3.check_transforms(T_wb_wa0, "initial T_wb_wa")[0]
    L = _Art(n=n, free_a=cam_a.free(held[0]), free_b=cam_b.free(held[1]), shared_world=shared)
    ia0, ib0 = np.asarray(intrinsics_a0, float), np.asarray(intrinsics_b0, float)
    for cam, i0, c in ((cam_a, ia0, "A"), (cam_b, ib0, "B")):
        if i0.shape != (cam.size,):
            raise InputError(
                f"camera {c}'s {cam.name} model takes {cam.size} intrinsics, got {i0.shape}"
            )
    # initial relative rotations from the initial poses: T_a_b = T_a_wa T_wa_wb T_wb_b
    T_a_b0 = np.matmul(se3.invert_transforms(Ta0), np.linalg.inv(W0) @ Tb0)
    Ra0, Rab0, Rw0 = Ta0[:, :3, :3], T_a_b0[:, :3, :3], W0[:3, :3]
    p0 = np.concatenate(
        [
            ia0[L.free_a],
            ib0[L.free_b],
            np.asarray(position_in_a0, float),
            np.asarray(position_in_b0, float),
            [] if shared else np.concatenate([np.zeros(3), W0[:3, 3]]),
            np.concatenate([np.zeros((n, 3)), Ta0[:, :3, 3], np.zeros((n, 3))], 1).ravel(),
        ]
    )
    fa, ka = np.nonzero(va)
    fb, kb = np.nonzero(vb)
    obs = np.concatenate([ca[fa, ka], cb[fb, kb]])
    priors = [
        (s, m, _whitener(c))
        for s, pr in (("oa", prior_a), ("ob", prior_b))
        if pr
        for m, c in [(np.asarray(pr[0], float), np.asarray(pr[1], float))]
    ]

    def model(p: FloatArray) -> dict[str, Any]:
        s = L.split(p)
        ia, ib = ia0.copy(), ib0.copy()
        ia[L.free_a], ib[L.free_b] = s["ia"], s["ib"]
        R = np.matmul(Ra0, se3.matrix_from_rotvec(s["r"]))
        Rab = np.matmul(Rab0, se3.matrix_from_rotvec(s["q"]))
        Rw: FloatArray = np.eye(3)
        tw: FloatArray = np.zeros(3)
        if not shared:
            Rw, tw = Rw0 @ se3.matrix_from_rotvec(s["w"][:3]), s["w"][3:]
        # camera B in world A, then in world B (eq. (2): the joint ties the translation)
        R_wa_b = np.matmul(R, Rab)
        t_a_b = s["oa"] - se3.rotate(Rab, s["ob"])
        t_wa_b = s["t"] + np.einsum("nij,nj->ni", R, t_a_b)
        R_wb_b = np.matmul(Rw, R_wa_b)
        t_wb_b = t_wa_b @ Rw.T + tw
        return {
            "ia": ia,
            "ib": ib,
            "R": R,
            "t": s["t"],
            "Rab": Rab,
            "Rw": Rw,
            "tw": tw,
            "R_wb_b": R_wb_b,
            "t_wb_b": t_wb_b,
            "oa": s["oa"],
            "ob": s["ob"],
        }

    def project_all(m: dict[str, Any]) -> FloatArray:
        xa = np.einsum("kji,kj->ki", m["R"][fa], Xa[ka] - m["t"][fa])
        xb = np.einsum("kji,kj->ki", m["R_wb_b"][fb], Xb[kb] - m["t_wb_b"][fb])
        return np.concatenate([cam_a.project(xa, m["ia"]), cam_b.project(xb, m["ib"])])

    prior_scale = [1.0]

    def residuals(p: FloatArray) -> FloatArray:
        m = model(p)
        r = (project_all(m) - obs).ravel()
        if not priors:
            return r
        extra = [prior_scale[0] * (W @ (m[key] - mean)) for key, mean, W in priors]
        return np.concatenate([r, *extra])

    n_obs_a, n_obs_b = fa.size, fb.size
    n_px = 2 * (n_obs_a + n_obs_b)
    n_par = L.n_shared + 9 * n
    na, nb, k_oa = len(L.free_a), len(L.free_b), L.k_oa

    def jacobian(p: FloatArray) -> sparse.csr_array:
        s = L.split(p)
        m = model(p)
        J = _SparseRows((n_px + 3 * len(priors), n_par))
        R, Rab = m["R"], m["Rab"]
        # camera A: x_a = R_i^T (X - t_i), R_i = R0_i Exp(r_i)
        xa = np.einsum("kji,kj->ki", R[fa], Xa[ka] - m["t"][fa])
        Di, Dp = cam_a.jacobians(xa, m["ia"])
        J.add(0, Di[:, :, L.free_a], np.arange(na))
        col = L.n_shared + 9 * fa[:, None] + np.arange(3)
        Jr_r = right_jacobians(s["r"])
        J.add(0, np.matmul(np.matmul(Dp, se3.skew(xa)), Jr_r[fa]), col)
        J.add(0, -np.matmul(Dp, np.swapaxes(R[fa], 1, 2)), col + 3)
        # camera B: y = Rw^T (Y - tw) in world A, u = R_i^T (y - t_i) in A,
        # x_b = Rab_i^T (u - o_a) + o_b  (the joint, eq. (2))
        b0 = 2 * n_obs_a
        Rw, tw = m["Rw"], m["tw"]
        y = (Xb[kb] - tw) @ Rw
        u = np.einsum("kji,kj->ki", R[fb], y - m["t"][fb])
        RabT = np.swapaxes(Rab[fb], 1, 2)
        xb = np.einsum("kij,kj->ki", RabT, u - m["oa"]) + m["ob"]
        Di, Dp = cam_b.jacobians(xb, m["ib"])
        DpR = np.matmul(Dp, RabT)  # d pixels / d u
        J.add(b0, Di[:, :, L.free_b], na + np.arange(nb))
        J.add(b0, -DpR, k_oa + np.arange(3))
        J.add(b0, Dp, k_oa + 3 + np.arange(3))
        col = L.n_shared + 9 * fb[:, None] + np.arange(3)
        J.add(b0, np.matmul(np.matmul(DpR, se3.skew(u)), Jr_r[fb]), col)
        DpRR = np.matmul(DpR, np.swapaxes(R[fb], 1, 2))  # d pixels / d y
        J.add(b0, -DpRR, col + 3)
        Jr_q = right_jacobians(s["q"])
        J.add(b0, np.matmul(np.matmul(Dp, se3.skew(xb - m["ob"])), Jr_q[fb]), col + 6)
        if not shared:
            Jr_w = right_jacobians(s["w"][None, :3])[0]
            k_w = k_oa + 6
            J.add(b0, np.matmul(np.matmul(DpRR, se3.skew(y)), Jr_w), k_w + np.arange(3))
            J.add(b0, -np.matmul(DpRR, Rw.T), k_w + 3 + np.arange(3))
        for j, (key, _mean, Wp) in enumerate(priors):
            c0 = k_oa + (0 if key == "oa" else 3)
            J.add_dense(n_px + 3 * j, c0, prior_scale[0] * Wp)
        return J.tocsr()

    def solve(p_start: FloatArray) -> lsq.Solution:
        return lsq.solve(residuals, p_start, jac=jacobian, method="normal")

    sol = solve(p0)
    dof = max(n_px - n_par, 1)
    sigma2 = float(np.sum(sol.fun[:n_px] ** 2) / dof)
    if priors:
        # priors are in metres and pixel residuals have sigma_px: weigh them alike
        prior_scale[0] = float(np.sqrt(sigma2))
        sol = solve(sol.x)
        sigma2 = float(np.sum(sol.fun[:n_px] ** 2) / dof)
    # information: pixels over their variance, plus the priors' own
    info = information(sol.jac[:n_px]) / max(sigma2, 1e-300)
    for key, _mean, Wp in priors:
        c0 = k_oa + (0 if key == "oa" else 3)
        info[c0 : c0 + 3, c0 : c0 + 3] += Wp.T @ Wp
    cov = np.linalg.pinv(info, hermitian=True)
    m = model(sol.x)
    s = L.split(sol.x)
    # relative pose per frame and its covariance, by a numerical chain rule on the few
    # parameters it depends on (o_a, o_b, the frame's q)
    T_a_b = se3.transforms_from_rt(m["Rab"], m["oa"] - se3.rotate(m["Rab"], m["ob"]))
    T_b_a = se3.invert_transforms(T_a_b)
    pose_cov = np.empty((n, 6, 6))
    idx_q = L.n_shared + 9 * np.arange(n)[:, None] + 6 + np.arange(3)
    for_cols = np.concatenate(
        [np.broadcast_to(np.arange(k_oa, k_oa + 6), (n, 6)), idx_q], axis=1
    )  # (n, 9)
    G = _relpose_jacobian(m["Rab"], m["oa"], right_jacobians(s["q"]))  # (n, 6, 9)
    C = cov[for_cols[:, :, None], for_cols[:, None, :]]  # (n, 9, 9)
    pose_cov[:] = np.matmul(np.matmul(G, C), np.swapaxes(G, 1, 2))
    r = sol.fun[:n_px].reshape(-1, 2)
    cov_a, cov_b = np.zeros((cam_a.size, cam_a.size)), np.zeros((cam_b.size, cam_b.size))
    cov_a[np.ix_(L.free_a, L.free_a)] = cov[:na, :na]
    cov_b[np.ix_(L.free_b, L.free_b)] = cov[na:k_oa, na:k_oa]
    T_wb_wa = np.eye(4)
    T_wb_wa[:3, :3], T_wb_wa[:3, 3] = m["Rw"], m["tw"]
    return ArticulatedBundle(
        model_a=cam_a.name,
        model_b=cam_b.name,
        intrinsics_a=m["ia"],
        intrinsics_b=m["ib"],
        position_in_a=m["oa"],
        position_in_b=m["ob"],
        covariance_a=cov[k_oa : k_oa + 3, k_oa : k_oa + 3],
        covariance_b=cov[k_oa + 3 : k_oa + 6, k_oa + 3 : k_oa + 6],
        T_wa_a=se3.transforms_from_rt(m["R"], m["t"]),
        T_wb_b=se3.transforms_from_rt(m["R_wb_b"], m["t_wb_b"]),
        T_b_a=T_b_a,
        T_wb_wa=T_wb_wa,
        pose_covariances=pose_cov,
        intrinsics_std_a=np.sqrt(np.clip(np.diag(cov_a), 0.0, None)),
        intrinsics_std_b=np.sqrt(np.clip(np.diag(cov_b), 0.0, None)),
        intrinsics_covariance_a=cov_a,
        intrinsics_covariance_b=cov_b,
        rms_px={
            "a": float(np.sqrt(np.mean(np.sum(r[:n_obs_a] ** 2, 1)))) if n_obs_a else 0.0,
            "b": float(np.sqrt(np.mean(np.sum(r[n_obs_a:] ** 2, 1)))) if n_obs_b else 0.0,
        },
        sigma_px=float(np.sqrt(sigma2)),
        success=bool(sol.success),
    )


def _relpose_jacobian(Rab: FloatArray, oa: FloatArray, Jr: FloatArray) -> FloatArray:
    """``(n, 6, 9)`` derivative of ``T_b_a``'s (right rotation perturbation, translation)
    with respect to ``(o_a, o_b, q)``, where ``R_a_b = R0 Exp(q)`` and ``Jr`` ``(n, 3, 3)``
    are the right Jacobians at ``q``.

    ``T_b_a = [R_b_a, o_b - R_b_a o_a]`` with ``R_b_a = R_a_b^T``. A right perturbation
    ``e`` of ``R_a_b`` gives ``R_b_a Exp(-R_a_b e)`` and moves the translation by
    ``-[R_b_a o_a]x e``.
    """
    n = Rab.shape[0]
    G = np.zeros((n, 6, 9))
    Rt = np.swapaxes(Rab, 1, 2)
    G[:, :3, 6:] = -np.matmul(Rab, Jr)
    G[:, 3:, :3] = -Rt  # d t_b_a / d o_a
    G[:, 3:, 3:6] = np.eye(3)  # d t_b_a / d o_b
    v = np.einsum("nij,j->ni", Rt, oa)  # R_b_a o_a
    G[:, 3:, 6:] = -np.matmul(se3.skew(v), Jr)
    return G
