"""Bundle adjustment on checkerboard corners with the joint as a constraint.

A fixed joint leaves each frame of a camera only a rotation: with the joint at ``o`` in the
camera's frame and at ``p_w`` in the board's (world) frame, frame ``i``'s pose is
``T_w_c = [R_i, p_w - R_i o]``, so a board point ``X`` is at

    x_cam = R_i^T (X - p_w) + o

in the camera. Fitting the intrinsics, ``o``, ``p_w`` and the rotations directly to the
detected corners (pixels) is the maximum-likelihood calibration under pixel noise: the
motion constraint also pins down the intrinsics, which a separate ``calibrateCamera``
cannot use. The camera model is OpenCV's pinhole with radial-tangential distortion
``(k1, k2, p1, p2, k3)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

#: Intrinsic parameters in the order they are optimised.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def project_points(x_cam: FloatArray, intrinsics: FloatArray) -> FloatArray:
    """Pinhole + radial-tangential projection of camera-frame points.

    Parameters
    ----------
    x_cam : ndarray, shape (..., 3)
        Points in the camera's frame (metres), ``z > 0``.
    intrinsics : ndarray, shape (9,)
        ``fx, fy, cx, cy`` (pixels) and ``k1, k2, p1, p2, k3`` (OpenCV's order).

    Returns
    -------
    ndarray, shape (..., 2)
        Pixel coordinates (as ``cv2.projectPoints``).
    """
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = intrinsics
    x = x_cam[..., 0] / x_cam[..., 2]
    y = x_cam[..., 1] / x_cam[..., 2]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([fx * xd + cx, fy * yd + cy], axis=-1)


def projection_jacobians(
    x_cam: FloatArray, intrinsics: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Derivatives of :func:`project_points` for ``(k, 3)`` points.

    Returns
    -------
    d_intrinsics : ndarray, shape (k, 2, 9)
    d_point : ndarray, shape (k, 2, 3)
        With respect to the camera-frame point.
    """
    fx, fy, _cx, _cy, k1, k2, p1, p2, k3 = intrinsics
    X, Y, Z = x_cam[:, 0], x_cam[:, 1], x_cam[:, 2]
    x, y = X / Z, Y / Z
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d rad / d r2
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    k = x.size
    Di = np.zeros((k, 2, 9))
    Di[:, 0, 0], Di[:, 1, 1] = xd, yd
    Di[:, 0, 2], Di[:, 1, 3] = 1.0, 1.0
    for j, power in ((4, 1), (5, 2), (8, 3)):  # k1, k2, k3
        Di[:, 0, j] = fx * x * r2**power
        Di[:, 1, j] = fy * y * r2**power
    Di[:, 0, 6], Di[:, 1, 6] = fx * 2.0 * x * y, fy * (r2 + 2.0 * y * y)  # p1
    Di[:, 0, 7], Di[:, 1, 7] = fx * (r2 + 2.0 * x * x), fy * 2.0 * x * y  # p2
    # d(xd, yd) / d(x, y)
    a = rad + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
    b = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
    d = rad + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
    Dd = np.stack([np.stack([fx * a, fx * b], -1), np.stack([fy * b, fy * d], -1)], axis=1)
    # d(x, y) / d(X, Y, Z)
    Dn = np.zeros((k, 2, 3))
    Dn[:, 0, 0] = Dn[:, 1, 1] = 1.0 / Z
    Dn[:, 0, 2], Dn[:, 1, 2] = -x / Z, -y / Z
    return Di, np.matmul(Dd, Dn)


def right_jacobians(rotvec: FloatArray) -> FloatArray:
    """``(n, 3, 3)`` right Jacobians of SO(3): ``Exp(phi + d) = Exp(phi) Exp(Jr(phi) d)``."""
    th = np.linalg.norm(rotvec, axis=1)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0 - th**2 / 120.0, (ths - np.sin(ths)) / ths**3)
    S = se3.skew(rotvec)
    return np.eye(3) - a[:, None, None] * S + b[:, None, None] * np.matmul(S, S)


def intrinsics_vector(K: FloatArray, dist: FloatArray) -> FloatArray:
    """``(9,)`` vector from a camera matrix ``(3, 3)`` and 5 distortion coefficients."""
    d = np.zeros(5)
    dist = np.asarray(dist, dtype=float).ravel()
    if dist.size not in (4, 5):
        raise InputError(
            f"expected 4 or 5 distortion coefficients (k1 k2 p1 p2 [k3]), got {dist.size}"
        )
    d[: dist.size] = dist
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])


def camera_matrix(intrinsics: FloatArray) -> FloatArray:
    """``(3, 3)`` camera matrix from the ``(9,)`` vector."""
    fx, fy, cx, cy = intrinsics[:4]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class FixedJointBundle:
    """Result of :func:`bundle_adjust_fixed_joint`.

    Attributes
    ----------
    intrinsics : ndarray, shape (9,)
        ``fx fy cx cy k1 k2 p1 p2 k3``.
    joint_in_cam : ndarray, shape (3,)
        The joint in the camera's frame (metres, the board's unit).
    joint_in_world : ndarray, shape (3,)
        The joint in the board's frame.
    T_world_cam : ndarray, shape (n, 4, 4)
        Refined poses of the frames.
    covariance : ndarray, shape (15, 15)
        Of ``(intrinsics, joint_in_cam, joint_in_world)`` (pixel noise estimated).
    rms_px : float
        Reprojection RMS over the corners used.
    per_frame_rms_px : ndarray, shape (n,)
    sigma_px : float
        Estimated standard deviation of a corner coordinate.
    """

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
    def joint_std(self) -> FloatArray:
        return np.sqrt(np.diag(self.covariance)[9:12])


def _check_observations(corners: FloatArray, valid: FloatArray, board: FloatArray) -> None:
    if corners.ndim != 3 or corners.shape[2] != 2:
        raise InputError(f"corners must have shape (n, m, 2), got {corners.shape}")
    if valid.shape != corners.shape[:2]:
        raise InputError(f"valid must have shape {corners.shape[:2]}, got {valid.shape}")
    if board.shape != (corners.shape[1], 3):
        raise InputError(f"board points must have shape ({corners.shape[1]}, 3), got {board.shape}")


def bundle_adjust_fixed_joint(
    corners: FloatArray,
    valid: FloatArray,
    board_points: FloatArray,
    intrinsics0: FloatArray,
    T_world_cam0: FloatArray,
    joint_in_cam0: FloatArray,
    joint_in_world0: FloatArray,
    *,
    fix_k3: bool = True,
) -> FixedJointBundle:
    """Maximum-likelihood fixed-joint calibration of one camera from its corners.

    Parameters
    ----------
    corners : ndarray, shape (n, m, 2)
        Detected corners of ``n`` frames (pixels), in board-point order.
    valid : ndarray of bool, shape (n, m)
        Which corners were detected.
    board_points : ndarray, shape (m, 3)
        The corners in the board's frame (metres).
    intrinsics0 : ndarray, shape (9,)
        Initial intrinsics (e.g. from ``cv2.calibrateCamera``).
    T_world_cam0 : ndarray, shape (n, 4, 4)
        Initial poses (e.g. from PnP); only their rotations are used.
    joint_in_cam0, joint_in_world0 : ndarray, shape (3,)
        Initial joint (e.g. from :func:`acs_cli.core.joint.estimate_joint_fixed`).
    fix_k3 : bool
        Keep ``k3`` at its initial value (as OpenCV's default five-parameter fits often
        should for moderate lenses).

    Returns
    -------
    FixedJointBundle
    """
    corners = np.asarray(corners, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    board = np.asarray(board_points, dtype=float)
    _check_observations(corners, valid, board)
    T0 = se3.check_transforms(T_world_cam0, "initial poses")
    n = valid.shape[0]
    if T0.shape[0] != n:
        raise InputError(f"{T0.shape[0]} initial poses for {n} frames")
    free_intr = [k for k in range(9) if not (fix_k3 and k == 8)]
    ni = len(free_intr)
    rot0 = se3.rotvec_from_matrix(T0[:, :3, :3])
    p0 = np.concatenate([intrinsics0[free_intr], joint_in_cam0, joint_in_world0, rot0.ravel()])
    frame_idx, corner_idx = np.nonzero(valid)
    obs = corners[frame_idx, corner_idx]
    rel = board[corner_idx]  # (k, 3)

    def unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        intr = np.asarray(intrinsics0, dtype=float).copy()
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
        return (project_points(x_cam, intr) - obs).ravel()

    n_shared = ni + 6
    n_obs = obs.shape[0]

    def jacobian(p: FloatArray) -> FloatArray:
        intr, o, pw, R = unpack(p)
        v = np.einsum("kji,kj->ki", R[frame_idx], rel - pw)  # R_i^T (X - p_w)
        Di, Dp = projection_jacobians(v + o, intr)
        Jr = right_jacobians(p[ni + 6 :].reshape(n, 3))[frame_idx]
        Jac = np.zeros((n_obs, 2, n_shared + 3 * n))
        Jac[:, :, :ni] = Di[:, :, free_intr]
        Jac[:, :, ni : ni + 3] = Dp  # d x_cam / d o = I
        Jac[:, :, ni + 3 : ni + 6] = -np.matmul(Dp, np.swapaxes(R[frame_idx], 1, 2))
        # x_cam = Exp(-dtheta) R^T (X - p_w) + o: d/d dtheta = [v]x, then the right Jacobian
        Jrot = np.matmul(np.matmul(Dp, se3.skew(v)), Jr)
        cols = n_shared + 3 * frame_idx[:, None] + np.arange(3)
        Jac[np.arange(n_obs)[:, None, None], np.arange(2)[None, :, None], cols[:, None, :]] = Jrot
        return Jac.reshape(2 * n_obs, -1)

    sol = least_squares(
        residuals, p0, jac=jacobian, method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12
    )
    intr, o, pw, R = unpack(sol.x)
    r = sol.fun.reshape(-1, 2)
    dof = max(r.size - sol.x.size, 1)
    sigma2 = float(np.sum(r**2) / dof)
    J = sol.jac.toarray() if hasattr(sol.jac, "toarray") else np.asarray(sol.jac)
    cov_full = sigma2 * np.linalg.pinv(J.T @ J, hermitian=True)
    cov = np.zeros((15, 15))
    idx = [*free_intr, *range(9, 15)]
    cov[np.ix_(idx, idx)] = cov_full[:n_shared, :n_shared]
    t = pw - se3.rotate(R, o)
    per_frame = np.sqrt(
        np.bincount(frame_idx, weights=np.sum(r**2, axis=1), minlength=n)
        / np.maximum(np.bincount(frame_idx, minlength=n), 1)
    )
    return FixedJointBundle(
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
