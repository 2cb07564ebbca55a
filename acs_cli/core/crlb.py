"""Cramer-Rao lower bounds for the joint, under the pose noise model of the simulations.

Each pose ``T_w_c = [R, t]`` is observed as ``[R Exp(n_r), t + n_t]`` with
``n_r ~ N(0, sigma_rot^2 I)`` and ``n_t ~ N(0, sigma_trans^2 I)``. Eliminating the unknown
true rotations (a Schur complement of the Fisher information) leaves, for each frame, the
information ``A_i^T Sigma_i^{-1} A_i`` of the constraint residual with
``Sigma_i = sigma_trans^2 I + sigma_rot^2 R_i [o]x [o]x^T R_i^T``.
"""

from __future__ import annotations

import numpy as np

from acs_cli.core.joint import lever_shapes
from acs_cli.core.se3 import FloatArray


def crlb_pivot(
    T_w_c: FloatArray, o: FloatArray, sigma_rot_rad: float, sigma_trans: float
) -> FloatArray:
    """Lower bound ``(3, 3)`` on the covariance of the joint ``o`` from a fixed-joint motion.

    Parameters
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        True poses ``T_world_cam``.
    o : ndarray, shape (3,)
        True joint in the camera's frame.
    sigma_rot_rad, sigma_trans : float
        Pose noise (radians per axis, translation units per axis).
    """
    R = T_w_c[:, :3, :3]
    n = R.shape[0]
    A = np.concatenate([R, np.broadcast_to(-np.eye(3), (n, 3, 3))], axis=2)
    S = sigma_trans**2 * np.eye(3) + sigma_rot_rad**2 * lever_shapes(R, o)
    W = np.linalg.inv(S)
    info = np.einsum("nai,nab,nbj->ij", A, W, A)
    return np.asarray(np.linalg.inv(info)[:3, :3])


def crlb_overlap(
    T_w_a: FloatArray,
    T_w_b: FloatArray,
    o_a: FloatArray,
    o_b: FloatArray,
    sigma_rot_rad: float,
    sigma_trans: float,
) -> FloatArray:
    """Lower bound ``(6, 6)`` on the covariance of ``(o_a, o_b)`` from an overlap motion."""
    Ra, Rb = T_w_a[:, :3, :3], T_w_b[:, :3, :3]
    A = np.concatenate([Ra, -Rb], axis=2)
    S = 2 * sigma_trans**2 * np.eye(3) + sigma_rot_rad**2 * (
        lever_shapes(Ra, o_a) + lever_shapes(Rb, o_b)
    )
    info = np.einsum("nai,nab,nbj->ij", A, np.linalg.inv(S), A)
    return np.asarray(np.linalg.inv(info))
