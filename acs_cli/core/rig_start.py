"""Starting points of the rig solve: one edge's world-to-world similarity from its two cameras.

The rig solve (:mod:`acs_cli.core.rig_solve`) reaches each world outward from the reference's
through an edge whose other world is already known. For a ball (or hinge) edge the joint is
one point at every instant:

    j_t[i] = phi R_X j_s[i] + t_X,     j_c[i] = R_c[i] o_c + t_c[i],

the paper's eq. (24) written in world coordinates (``X``: world ``s`` to world ``t``, ``phi``
its scale). The bilinear products ``phi R_X o_s`` are lifted to a linear system
(:func:`similarity_from_lifted`), which a narrow motion can leave far off; so a ball edge's
start is refined by a small weighted maximum-likelihood fit of that one constraint from three
starts (:func:`ball_similarity`), the most likely kept. Only the similarity and the joint come
out: the rig solve then refines everything together.
"""

from __future__ import annotations

import numpy as np

from acs_cli.core import estimation, se3
from acs_cli.core.joint import lever_shapes
from acs_cli.core.se3 import FloatArray

#: A similarity start: ``R_X`` (3, 3), ``t_X`` (3,), ``phi``, ``o_s`` (3,), ``o_t`` (3,).
Start = tuple[FloatArray, FloatArray, float, FloatArray, FloatArray]


def kron_rows(v: FloatArray) -> FloatArray:
    """``K(v)`` ``(n, 3, 9)`` with ``K(v) vec(M) = M v`` for row-major ``vec(M)``."""
    n = v.shape[0]
    K = np.zeros((n, 3, 9))
    for r in range(3):  # three rows of a 3x3 matrix, not frames
        K[:, r, 3 * r : 3 * r + 3] = v
    return K


def lstsq_scaled(A: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least squares with column equilibration; returns the solution and singular values."""
    if A.shape[0] < 20 * A.shape[1]:
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        x, _, _, s = np.linalg.lstsq(A / scale, b, rcond=None)
        return x / scale, s
    # tall: the same least-squares problem through its (equilibrated) Gram matrix
    G = A.T @ A
    scale = np.sqrt(np.diag(G))
    scale[scale == 0] = 1.0
    Gs = G / np.outer(scale, scale)
    x = np.linalg.lstsq(Gs, (A.T @ b) / scale, rcond=None)[0]
    s = np.sqrt(np.maximum(np.linalg.eigvalsh(Gs)[::-1], 0.0))
    return x / scale, s


def similarity_from_lifted(Ts: FloatArray, Tt: FloatArray, o_s: FloatArray | None) -> Start:
    """Linear ``R_X, t_X, phi, o_s, o_t`` from paired poses ``(n, 4, 4)`` of two worlds.

    ``j_t = M j_s + t_X`` with ``M = phi R_X`` is bilinear in ``M`` and ``o_s``; lifting the
    products ``W[r, j, k] = M[r, j] o_s[k]`` to 27 unknowns makes it linear in
    ``(W, M, o_t, t_X)`` (42 unknowns, 3 equations a frame). With ``o_s`` known, ``M j_s`` is
    linear directly (15 unknowns).
    """
    n = Ts.shape[0]
    Ra, ta, Rb, tb = Ts[:, :3, :3], Ts[:, :3, 3], Tt[:, :3, :3], Tt[:, :3, 3]
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    if o_s is None:
        AW = np.zeros((n, 3, 27))
        for r in range(3):  # the 3 rows of M, not frames
            AW[:, r, 9 * r : 9 * r + 9] = Ra.reshape(n, 9)
        A = np.concatenate([AW, kron_rows(ta), -Rb, eye], axis=2).reshape(-1, 42)
        x, _ = lstsq_scaled(A, tb.reshape(-1))
        W, M, o_t, t_X = x[:27].reshape(3, 3, 3), x[27:36].reshape(3, 3), x[36:39], x[39:42]
        o_s = np.einsum("rj,rjk->k", M, W) / float(np.sum(M * M))
    else:
        j_s = np.einsum("nij,j->ni", Ra, o_s) + ta
        A = np.concatenate([kron_rows(j_s), -Rb, eye], axis=2).reshape(-1, 15)
        x, _ = lstsq_scaled(A, tb.reshape(-1))
        M, o_t, t_X = x[:9].reshape(3, 3), x[9:12], x[12:15]
    R_X, s = se3.project_to_rotation(M)
    return R_X, t_X, float(np.mean(s)), np.asarray(o_s), o_t


#: Bound on the log of a scale factor inside the start's fit (phi within 1e-30..1e30).
_LOG_SCALE_BOUND = 69.0


def _pack(R_X: FloatArray, t_X: FloatArray, phi: float, o_s: FloatArray, o_t: FloatArray):
    return np.concatenate([se3.rotvec_from_matrix(R_X), t_X, o_s, o_t, [np.log(max(phi, 1e-9))]])


def _unpack(x: FloatArray) -> Start:
    phi = float(np.exp(np.clip(x[12], -_LOG_SCALE_BOUND, _LOG_SCALE_BOUND)))
    return se3.matrix_from_rotvec(x[:3]), x[3:6], phi, x[6:9], x[9:12]


def _starts(Ts: FloatArray, Tt: FloatArray) -> list[FloatArray]:
    """The lifted linear start, and the same with the joint at either camera's centre (from
    ``t``'s side: ``s`` and ``t`` swapped, the similarity inverted)."""
    zero = np.zeros(3)
    out = [_pack(*similarity_from_lifted(Ts, Tt, None))]
    out.append(_pack(*similarity_from_lifted(Ts, Tt, zero)))
    R_Y, t_Y, psi, o_t, o_s = similarity_from_lifted(Tt, Ts, zero)  # j_s = psi R_Y j_t + t_Y
    phi = 1.0 / max(psi, 1e-9)
    out.append(_pack(R_Y.T, -phi * R_Y.T @ t_Y, phi, o_s, o_t))
    return out


#: Reweighting rounds of a ball edge's start (:func:`ball_similarity`).
START_ROUNDS = 4


def ball_similarity(Ts: FloatArray, Tt: FloatArray) -> Start:
    """One ball edge's similarity and joint, by maximum likelihood over its frames.

    Weighted (each frame's covariance ``theta_t I + theta_r L_i``, the noise levels fitted,
    :func:`acs_cli.core.estimation.solve`), from the three starts of :func:`_starts`; no
    outlier rejection (the rig solve does that, edge by edge).

    Parameters
    ----------
    Ts, Tt : ndarray, shape (n, 4, 4)
        Paired ``T_world_cam`` of the two cameras, each in its own world (``s``'s may already be
        in the reference world).

    Returns
    -------
    R_X, t_X, phi, o_s, o_t
        ``j_t = phi R_X j_s + t_X``; ``o_s`` in ``s``'s units, ``o_t`` in ``t``'s.
    """
    c = np.ascontiguousarray
    Ra, ta, Rb, tb = c(Ts[:, :3, :3]), c(Ts[:, :3, 3]), c(Tt[:, :3, :3]), c(Tt[:, :3, 3])
    n = Ts.shape[0]

    def residuals(x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
        R, t, ph, oa, ob = _unpack(x)
        Rja = (se3.rotate(Ra, oa) + ta) @ R.T
        r = se3.rotate(Rb, ob) + tb - ph * Rja - t  # eq. (24) in world coordinates
        if not jac:
            return r, None
        J = np.zeros((n, 3, 13))
        J[:, :, 0:3] = ph * (se3.skew(Rja).reshape(-1, 3) @ R).reshape(n, 3, 3)  # [Rj]x R
        J[:, :, 3:6] = -np.eye(3)
        J[:, :, 6:9] = -ph * se3.left_multiply(R, Ra)
        J[:, :, 9:12] = Rb
        J[:, :, 12] = -ph * Rja
        return r, J

    def noise_shapes(x: FloatArray) -> FloatArray:
        R, _, ph, oa, ob = _unpack(x)
        return lever_shapes(Rb, ob) + ph**2 * lever_shapes(se3.left_multiply(R, Ra), oa)

    def retract(x: FloatArray, dx: FloatArray) -> FloatArray:
        out = x + dx
        out[:3] = se3.rotvec_from_matrix(
            se3.matrix_from_rotvec(x[:3]) @ se3.matrix_from_rotvec(dx[:3])
        )
        return out

    first, *others = _starts(Ts, Tt)
    problem = estimation.LeastSquaresProblem(residuals, noise_shapes, None, retract)
    # a start, not the answer: the rig engine refits everything (weights, outliers) from it,
    # so four rounds of reweighting pick the start's basin as well as thirty (a fifth of a
    # relative pose's time before; the same answers to its settling tolerance)
    sol = estimation.solve(
        problem, first, alternatives=others, reject_outliers=False, max_outer=START_ROUNDS
    )
    return _unpack(sol.x)
