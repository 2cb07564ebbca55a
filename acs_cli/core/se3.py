"""Rigid transforms, rotations and their conversions (pure numpy/scipy).

Conventions (see ``docs/conventions.md``):

- ``T_a_b`` is a 4x4 homogeneous transform mapping points from frame ``b`` into frame
  ``a``: ``p_a = T_a_b @ p_b``; so ``T_a_c = T_a_b @ T_b_c``.
- Stacks of transforms have shape ``(n, 4, 4)``, of rotations ``(n, 3, 3)``.
- Quaternions are ``(x, y, z, w)`` (TUM and scipy order), unit norm.
- Roll, pitch and yaw (degrees) follow ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
- Rotation perturbations are applied on the right (body frame): ``R @ Exp(theta)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acs_cli.errors import InputError

FloatArray = NDArray[np.floating[Any]]

#: Largest ``|R^T R - I|`` entry accepted as a rotation matrix.
ORTHONORMAL_TOL = 1e-6


def check_vectors(v: ArrayLike, name: str = "vectors", dim: int = 3) -> FloatArray:
    """Validate a stack of vectors of shape ``(n, dim)`` (a single ``(dim,)`` is promoted)."""
    arr = np.asarray(v, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"{name} must have shape (n, {dim}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    return arr


def check_rotations(
    R: ArrayLike, name: str = "rotations", tol: float = ORTHONORMAL_TOL
) -> FloatArray:
    """Validate a stack of rotation matrices of shape ``(n, 3, 3)``.

    Raises
    ------
    InputError
        If the shape is wrong, a value is not finite, or a matrix is not a proper rotation.
    """
    arr = np.asarray(R, dtype=float)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (3, 3):
        raise InputError(f"{name} must have shape (n, 3, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    # a rotation's entries lie in [-1, 1]; far larger ones would overflow the products below
    huge = np.flatnonzero(np.abs(arr).max(axis=(1, 2)) > 1e3)
    if huge.size:
        raise InputError(
            f"{name}[{huge[0]}] is not a rotation matrix (an entry of "
            f"{np.abs(arr[huge[0]]).max():.3g}), {huge.size} such"
        )
    err = np.abs(np.matmul(arr.transpose(0, 2, 1), arr) - np.eye(3)).max(axis=(1, 2))
    det = np.einsum("ni,ni->n", arr[:, 0], np.cross(arr[:, 1], arr[:, 2]))
    bad = np.flatnonzero((err > tol) | (det <= 0))
    if bad.size:
        raise InputError(
            f"{name}[{bad[0]}] is not a rotation matrix (|R^T R - I| = {err[bad[0]]:.2e}, "
            f"{bad.size} such)"
        )
    return arr


def check_transforms(
    T: ArrayLike, name: str = "transforms", tol: float = ORTHONORMAL_TOL
) -> FloatArray:
    """Validate a stack of rigid transforms of shape ``(n, 4, 4)``."""
    arr = np.asarray(T, dtype=float)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise InputError(f"{name} must have shape (n, 4, 4), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    if np.abs(arr[:, 3, :] - [0.0, 0.0, 0.0, 1.0]).max(initial=0.0) > tol:
        raise InputError(f"{name} must have a last row of [0, 0, 0, 1]")
    check_rotations(arr[:, :3, :3], name=f"{name} rotation", tol=tol)
    return arr


def check_paired_transforms(
    T_a: ArrayLike, T_b: ArrayLike, what: str
) -> tuple[FloatArray, FloatArray]:
    """Validate two stacks of poses that must pair one to one (``(n, 4, 4)`` each)."""
    Ta = check_transforms(T_a, name="camera A poses")
    Tb = check_transforms(T_b, name="camera B poses")
    if Ta.shape[0] != Tb.shape[0]:
        raise InputError(
            f"{what} needs paired poses; got {Ta.shape[0]} for A and {Tb.shape[0]} for B"
        )
    return Ta, Tb


def skew(v: ArrayLike) -> FloatArray:
    """Cross-product matrices ``[v]x`` of shape ``(n, 3, 3)`` (or ``(3, 3)`` for one vector)."""
    arr = np.asarray(v, dtype=float)
    single = arr.ndim == 1
    arr = np.atleast_2d(arr)
    out = np.zeros((arr.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -arr[:, 2], arr[:, 1]
    out[:, 1, 0], out[:, 1, 2] = arr[:, 2], -arr[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -arr[:, 1], arr[:, 0]
    return out[0] if single else out


def rotate(R: ArrayLike, v: ArrayLike) -> FloatArray:
    """``R_i @ v`` for a stack ``R`` ``(n, 3, 3)`` and one vector ``v`` ``(3,)``: ``(n, 3)``."""
    arr = np.asarray(R, dtype=float)
    return np.asarray((arr.reshape(-1, 3) @ np.asarray(v, dtype=float)).reshape(-1, 3))


def left_multiply(A: ArrayLike, M: ArrayLike) -> FloatArray:
    """``A @ M_i`` for one ``A`` ``(3, 3)`` and a stack ``M`` ``(n, 3, k)``: ``(n, 3, k)``."""
    return np.asarray(
        np.tensordot(
            np.asarray(M, dtype=float), np.asarray(A, dtype=float), axes=([1], [1])
        ).transpose(0, 2, 1)
    )


def transforms_from_rt(R: ArrayLike, t: ArrayLike) -> FloatArray:
    """Stack rotations ``(n, 3, 3)`` and translations ``(n, 3)`` into ``(n, 4, 4)``."""
    R_arr = np.asarray(R, dtype=float)
    t_arr = np.asarray(t, dtype=float)
    single = R_arr.ndim == 2
    R_arr = R_arr.reshape(-1, 3, 3)
    t_arr = t_arr.reshape(-1, 3)
    if R_arr.shape[0] != t_arr.shape[0]:
        raise InputError(f"got {R_arr.shape[0]} rotations but {t_arr.shape[0]} translations")
    T = np.zeros((R_arr.shape[0], 4, 4))
    T[:, :3, :3] = R_arr
    T[:, :3, 3] = t_arr
    T[:, 3, 3] = 1.0
    return T[0] if single else T


def invert_transforms(T: ArrayLike) -> FloatArray:
    """Inverse of rigid transforms: ``T_b_a`` from ``T_a_b``; shape ``(n, 4, 4)`` or ``(4, 4)``."""
    arr = np.asarray(T, dtype=float)
    Rt = np.swapaxes(arr[..., :3, :3], -1, -2)
    out = np.zeros_like(arr)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, arr[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def transform_points(T: ArrayLike, p: ArrayLike) -> FloatArray:
    """Apply transforms ``(n, 4, 4)`` to points ``(n, 3)`` (or one point to all): ``(n, 3)``."""
    arr = np.asarray(T, dtype=float)
    pts = np.asarray(p, dtype=float)
    return np.einsum("...ij,...j->...i", arr[..., :3, :3], pts) + arr[..., :3, 3]


def _exp1(w: FloatArray) -> FloatArray:
    """Rodrigues for one rotation vector (no scipy call overhead)."""
    th2 = float(w @ w)
    if th2 < 1e-8:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = np.sqrt(th2)
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + a * K + b * (K @ K)


def matrix_from_rotvec(rotvec: ArrayLike) -> FloatArray:
    """``Exp``: rotation vectors (axis x angle, radians) ``(n, 3)`` to matrices ``(n, 3, 3)``."""
    arr = np.asarray(rotvec, dtype=float)
    if arr.shape == (3,):
        return _exp1(arr)
    w = arr.reshape(-1, 3)
    th2 = np.einsum("ni,ni->n", w, w)
    small = th2 < 1e-8
    th = np.sqrt(np.where(small, 1.0, th2))
    # Rodrigues, R = I + a K + b K^2, with its series near the identity
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(th) / th)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / np.where(small, 1.0, th2))
    # K^2 = w w^T - |w|^2 I
    R = b[:, None, None] * (w[:, :, None] * w[:, None, :])
    d = 1.0 - b * th2
    aw = a[:, None] * w
    R[:, 0, 0] += d
    R[:, 1, 1] += d
    R[:, 2, 2] += d
    R[:, 0, 1] -= aw[:, 2]
    R[:, 1, 0] += aw[:, 2]
    R[:, 0, 2] += aw[:, 1]
    R[:, 2, 0] -= aw[:, 1]
    R[:, 1, 2] -= aw[:, 0]
    R[:, 2, 1] += aw[:, 0]
    return R.reshape(*arr.shape[:-1], 3, 3)


def _quat_xyzw(R: FloatArray) -> FloatArray:
    """Unit quaternions ``(n, 4)`` ``(x, y, z, w)`` of matrices ``(n, 3, 3)``, either sign.

    Shepperd's method, as scipy's ``Rotation.from_matrix``: from the largest of the trace
    and the diagonal, so that no square root or division is of a small number; a matrix
    that is not orthogonal to 1e-12 is first replaced by its nearest rotation (``U V^T``
    of its SVD), as scipy does.

    Raises
    ------
    ValueError
        A matrix of non-positive determinant (a reflection or a null frame), as scipy.
    """
    n = R.shape[0]
    det = np.einsum("ni,ni->n", R[:, 0], np.cross(R[:, 1], R[:, 2]))
    if np.any(det <= 0):
        i = int(np.flatnonzero(det <= 0)[0])
        raise ValueError(f"non-positive determinant in rotation matrix {i}: {R[i]}")
    gap = np.abs(np.einsum("nij,nkj->nik", R, R) - np.eye(3))
    # scipy's test: within 1e-12, and 1e-5 relative on the diagonal
    off = np.any(gap > 1e-12 + 1e-5 * np.eye(3), axis=(-2, -1))
    if np.any(off):
        U, _, Vt = np.linalg.svd(R[off])
        R = R.copy()
        R[off] = U @ Vt
    d = np.stack([R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    tr = d.sum(axis=1)
    choice = np.argmax(np.concatenate([d, tr[:, None]], axis=1), axis=1)
    q = np.empty((n, 4))
    on_trace = choice == 3
    t = np.flatnonzero(on_trace)
    q[t, 0] = R[t, 2, 1] - R[t, 1, 2]
    q[t, 1] = R[t, 0, 2] - R[t, 2, 0]
    q[t, 2] = R[t, 1, 0] - R[t, 0, 1]
    q[t, 3] = 1.0 + tr[t]
    m = np.flatnonzero(~on_trace)
    i = choice[m]
    j = (i + 1) % 3
    k = (j + 1) % 3
    q[m, i] = 1.0 - tr[m] + 2.0 * R[m, i, i]
    q[m, j] = R[m, j, i] + R[m, i, j]
    q[m, k] = R[m, k, i] + R[m, i, k]
    q[m, 3] = R[m, k, j] - R[m, j, k]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _matrix_from_unit_quat(q: FloatArray) -> FloatArray:
    """Rotation matrices ``(n, 3, 3)`` of quaternions ``(n, 4)`` ``(x, y, z, w)``, normalised."""
    x, y, z, w = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def rotvec_from_matrix(R: ArrayLike) -> FloatArray:
    """``Log``: rotation matrices ``(n, 3, 3)`` to rotation vectors (radians) ``(n, 3)``."""
    arr = np.asarray(R, dtype=float)
    if arr.shape == (3, 3):
        c = (arr[0, 0] + arr[1, 1] + arr[2, 2] - 1.0) / 2.0
        if c > -0.99:  # away from a half turn: the skew part is well conditioned
            v = np.array([arr[2, 1] - arr[1, 2], arr[0, 2] - arr[2, 0], arr[1, 0] - arr[0, 1]])
            s = np.linalg.norm(v) / 2.0
            th = np.arctan2(s, c)
            f = 0.5 + th * th / 12.0 if th < 1e-4 else th / (2.0 * s)
            return f * v
    q = _quat_xyzw(arr.reshape(-1, 3, 3))
    q = np.where(q[:, 3:4] < 0, -q, q)  # the angle in [0, pi]
    v = q[:, :3]
    s = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(s, q[:, 3])
    small = angle <= 1e-3
    a2 = angle * angle
    # angle / sin(angle / 2), with its series near the identity (as scipy's as_rotvec)
    scale = np.where(
        small,
        2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0,
        angle / np.sin(np.where(small, 1.0, angle) / 2.0),
    )
    return (scale[:, None] * v).reshape(*arr.shape[:-2], 3)


def quat_xyzw_from_matrix(R: ArrayLike) -> FloatArray:
    """Unit quaternions ``(x, y, z, w)`` with ``w >= 0`` from rotation matrices ``(n, 3, 3)``."""
    arr = np.asarray(R, dtype=float)
    q = _quat_xyzw(arr.reshape(-1, 3, 3))
    q = np.where(q[:, 3:4] < 0, -q, q)
    return q.reshape(*arr.shape[:-2], 4)


def matrix_from_quat_xyzw(q: ArrayLike, tol: float = 1e-3) -> FloatArray:
    """Rotation matrices ``(n, 3, 3)`` from unit quaternions ``(x, y, z, w)`` of shape ``(n, 4)``.

    Raises
    ------
    InputError
        If a quaternion is not finite or its norm differs from 1 by more than ``tol``.
    """
    arr = check_vectors(q, "quaternions", dim=4)
    norm = np.linalg.norm(arr, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > tol)
    if bad.size:
        raise InputError(
            f"quaternion {bad[0]} has norm {norm[bad[0]]:.6f}, not 1 ({bad.size} such)"
        )
    return _matrix_from_unit_quat(arr)


def matrix_from_checked_quat_xyzw(q: FloatArray) -> FloatArray:
    """:func:`matrix_from_quat_xyzw` for quaternions ``(n, 4)`` a reader has checked
    already (finite, of norm near 1): normalised, no second check."""
    return _matrix_from_unit_quat(np.asarray(q, dtype=float).reshape(-1, 4))


def rpy_deg_from_matrix(R: ArrayLike) -> FloatArray:
    """Roll, pitch, yaw (deg) with ``R = Rz(yaw) Ry(pitch) Rx(roll)``; ``(n, 3)`` or ``(3,)``.

    At pitch +-90 deg (gimbal lock) roll and yaw are not unique: roll is 0 and yaw takes
    the whole turn about the vertical."""
    arr = np.asarray(R, dtype=float)
    M = arr.reshape(-1, 3, 3)
    cp = np.hypot(M[:, 0, 0], M[:, 1, 0])
    pitch = np.arctan2(-M[:, 2, 0], cp)
    locked = cp < 1e-7
    roll = np.where(locked, 0.0, np.arctan2(M[:, 2, 1], M[:, 2, 2]))
    # locked, R = Rz(yaw) Ry(+-90): yaw from the first two rows' second column
    yaw = np.where(locked, np.arctan2(-M[:, 0, 1], M[:, 1, 1]), np.arctan2(M[:, 1, 0], M[:, 0, 0]))
    rpy = np.degrees(np.stack([roll, pitch, yaw], axis=1))
    return rpy.reshape(*arr.shape[:-2], 3)


def matrix_from_rpy_deg(rpy: ArrayLike) -> FloatArray:
    """Inverse of :func:`rpy_deg_from_matrix`: roll, pitch, yaw (deg) to rotation matrices."""
    arr = np.asarray(rpy, dtype=float)
    r, p, y = np.radians(arr.reshape(-1, 3)).T
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    # Rz(yaw) @ Ry(pitch) @ Rx(roll)
    R = np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        axis=1,
    )
    return R.reshape(*arr.shape[:-1], 3, 3)


def rpy_right_jacobian(rpy_rad: ArrayLike) -> FloatArray:
    """``E`` ``(3, 3)`` with ``R(rpy + d) = R(rpy) Exp(E d + O(d^2))``.

    ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`matrix_from_rpy_deg`, here in radians): a
    change of roll turns ``R`` about its own x axis, of pitch about ``Rx^T e_y``, of yaw about
    ``(Ry Rx)^T e_z`` (body frame). Singular at pitch = +-90 deg (gimbal lock).

    Parameters
    ----------
    rpy_rad : ndarray, shape (3,)
        Roll, pitch, yaw (radians).

    Returns
    -------
    ndarray, shape (3, 3)
        Columns: the body-frame rotation axes of roll, pitch and yaw.
    """
    roll, pitch, _yaw = np.asarray(rpy_rad, dtype=float)
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    # Rx^T e_y = (0, cr, -sr); (Ry Rx)^T e_z = Rx^T (-sp, 0, cp) = (-sp, sr cp, cr cp)
    return np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])


def project_to_rotation(M: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Nearest rotation (Frobenius) to 3x3 matrices ``M`` and their singular values.

    Zhang's appendix C: with ``M = U D V^T``, ``R = U V^T`` (a reflection is flipped into a
    rotation by negating the last singular direction).

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
    singular_values : ndarray, shape (..., 3)
    """
    arr = np.asarray(M, dtype=float)
    U, s, Vt = np.linalg.svd(arr)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones((*arr.shape[:-2], 3))
    D[..., 2] = d
    R = np.einsum("...ij,...j,...jk->...ik", U, D, Vt)
    return R, s


def rotation_angle_deg(R: ArrayLike) -> FloatArray:
    """Rotation angle in degrees of each matrix in ``(n, 3, 3)``."""
    arr = np.asarray(R, dtype=float)
    c = (np.trace(arr, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def right_jacobians_inv(rotvec: ArrayLike) -> FloatArray:
    """``(n, 3, 3)`` inverse right Jacobians of SO(3) at rotation vectors ``(n, 3)``.

    ``Log(Exp(phi) Exp(d)) = phi + Jr^-1(phi) d`` to first order in ``d``.
    """
    phi = np.atleast_2d(np.asarray(rotvec, dtype=float))
    th = np.linalg.norm(phi, axis=1)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    c = np.where(
        small,
        1.0 / 12.0 + th**2 / 720.0,
        1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(np.where(small, 1.0, ths))),
    )
    S = skew(phi)
    return np.asarray(np.eye(3) + 0.5 * S + c[:, None, None] * np.matmul(S, S))
