"""Chen & Wong's four algorithms, as published: one function each (pairwise, two cameras).

This is the index a reader of the paper starts from. Each function runs the paper's own
formulation (``method="paper"``) and names the equations it solves. Algorithms I and II are
solved here (the refined estimators share their motion checks, and the rig engine starts
from Algorithm I's linear solution); III and IV in :mod:`acs_cli.core.relpose`:

==========  =====================================  ==========================================
Algorithm   here                                   solved in
==========  =====================================  ==========================================
I           :func:`algorithm_1_overlap`            here (:func:`algorithm_1_solve`)
II          :func:`algorithm_2_fixed_joint`        here (:func:`algorithm_2_pivot`)
III         :func:`algorithm_3_relative_pose`      here (:func:`relative_pose_paper`)
IV          :func:`algorithm_4_unknown_scale`      here (:func:`relative_pose_paper`)
==========  =====================================  ==========================================

Rigs of more than two cameras, hinges and rigid pairs go beyond the paper: one solve over
the whole tree, :func:`acs_cli.core.rig_solve.estimate_rig`.

Frames: the paper's ``H_BA`` is our ``T_b_a``, its ``O_A`` our ``position_in_a``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acs_cli.core import lsq, se3
from acs_cli.core.joint import (
    JointEstimate,
    PivotEstimate,
    articulation_motion,
    hinge_explains,
    joint_of_pivots,
    motion_summary,
    overlap_motion,
    pivot_motion,
)
from acs_cli.core.rig_start import kron_rows, lstsq_scaled
from acs_cli.core.se3 import FloatArray

__all__ = [
    "PaperRelativePose",
    "algorithm_1_overlap",
    "algorithm_1_solve",
    "algorithm_2_fixed_joint",
    "algorithm_2_pivot",
    "algorithm_3_relative_pose",
    "algorithm_4_unknown_scale",
    "relative_pose_paper",
]


def algorithm_1_solve(T_w_a: FloatArray, T_w_b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Algorithm I's linear least squares, eq. (9), without checks.

    At every instant ``i`` the joint is one world point seen from both cameras,
    ``R_wa_i O_A + t_wa_i = R_wb_i O_B + t_wb_i`` (eq. (8)); stacked over the frames,

        [R_wa_i, -R_wb_i] [O_A; O_B] = t_wb_i - t_wa_i                          (eq. (9))

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_cam`` of cameras A and B in the same world.

    Returns
    -------
    x : ndarray, shape (6,)
        ``[O_A; O_B]`` (the minimum-norm solution when the system is rank deficient).
    residuals : ndarray, shape (n, 3)
        ``[R_wa_i, -R_wb_i] x - (t_wb_i - t_wa_i)``.
    """
    A = np.concatenate([T_w_a[:, :3, :3], -T_w_b[:, :3, :3]], axis=2)
    rhs = T_w_b[:, :3, 3] - T_w_a[:, :3, 3]
    x, *_ = np.linalg.lstsq(A.reshape(-1, 6), rhs.reshape(-1), rcond=None)
    return x, np.einsum("nij,j->ni", A, x) - rhs


def algorithm_1_overlap(T_w_a: FloatArray, T_w_b: FloatArray) -> JointEstimate:
    """Algorithm I (section 2): the joint from two cameras with overlapping views.

    Both trajectories are in one world (a shared board). At every instant the joint is one
    point, ``R_wa_i O_A + t_wa_i = R_wb_i O_B + t_wb_i`` (eq. (8)), stacked over the frames
    into the linear system ``[R_wa_i, -R_wb_i] [O_A; O_B] = t_wb_i - t_wa_i`` (eq. (9)) and
    solved by least squares (:func:`algorithm_1_solve`). The covariance is the regression's,
    ``s^2 (A^T A)^-1`` with ``s^2`` the residuals' variance: no noise model, no outlier
    rejection.

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_cam`` of cameras A and B in the same world.

    Returns
    -------
    JointEstimate
        ``scenario="overlap"``, ``method="paper"``; ``residual_rms`` and ``inliers`` (every
        frame) keyed ``"ab"``.

    Raises
    ------
    DegenerateMotionError
        Fewer than 3 frames, a rigid pair, or an articulation about one axis
        (:func:`acs_cli.core.joint.overlap_motion`, :func:`acs_cli.core.joint.hinge_explains`).
    """
    motion = overlap_motion(T_w_a, T_w_b)
    Ta, Tb = motion.T_w_a, motion.T_w_b
    x, res = algorithm_1_solve(Ta, Tb)
    A = np.concatenate([Ta[:, :3, :3], -Tb[:, :3, :3]], axis=2).reshape(-1, 6)
    cov = float(np.sum(res**2) / max(res.size - 6, 1)) * np.linalg.inv(A.T @ A)
    if hinge_explains(motion.spread, cov[3:, 3:], x[3:], None):
        raise motion.hinge_error()
    n = Ta.shape[0]
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return JointEstimate(
        x[:3],
        cov[:3, :3],
        x[3:],
        cov[3:, 3:],
        "overlap",
        "paper",
        {"ab": rms},
        {"ab": np.ones(n, bool)},
        motion=articulation_motion(Ta[:, :3, :3], Tb[:, :3, :3], "a", "b"),
    )


def algorithm_2_pivot(T_w_c: FloatArray, what: str = "camera") -> PivotEstimate:
    """Algorithm II (section 3.1) for one camera: the joint from a fixed-joint motion.

    While the joint stays at one world point, the camera's motion relative to its first
    frame, ``H^i = inv(T_w_c[0]) T_w_c[i] = [R^i, T^i]``, keeps the joint ``O`` (camera
    frame) where it was: ``O = H^i O`` (eq. (11)), that is

        (R^i - I) O = -T^i,      i = 1 .. n-1                                 (eq. (12))

    stacked and solved by linear least squares. The covariance is the regression's,
    ``s^2 (M^T M)^-1``: it ignores that every row shares the first frame's error and is
    optimistic. No noise model, no outlier rejection.

    Parameters
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        ``T_world_cam`` while the joint is fixed (any world fixed during the motion).
    what : str
        Name used in messages.

    Returns
    -------
    PivotEstimate
        ``position_in_world`` is ``T_w_c[0] O``; ``noise`` empty; every frame an inlier.

    Raises
    ------
    DegenerateMotionError
        Fewer than 3 poses, too little rotation, or rotation about one axis
        (:func:`acs_cli.core.joint.pivot_motion`, :func:`acs_cli.core.joint.hinge_explains`).
    """
    T, spread, hinge = pivot_motion(T_w_c, what)
    H = se3.invert_transforms(T[0]) @ T[1:]
    M = (H[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = -H[:, :3, 3].reshape(-1)
    o, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    res = (M @ o - rhs).reshape(-1, 3)
    cov = float(np.sum(res**2) / max(res.size - 3, 1)) * np.linalg.inv(M.T @ M)
    if hinge_explains(spread, cov, o, None):
        raise hinge()
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    p_w = se3.transform_points(T[0], o)
    return PivotEstimate(o, cov, p_w, rms, np.ones(T.shape[0], bool), {}, motion_summary(spread))


def algorithm_2_fixed_joint(T_wa_a: FloatArray, T_wb_b: FloatArray | None = None) -> JointEstimate:
    """Algorithm II (section 3.1): the joint from a fixed-joint motion (pivot calibration),
    eq. (11)-(12) for each camera (:func:`algorithm_2_pivot`).

    Parameters
    ----------
    T_wa_a : ndarray, shape (n, 4, 4)
        Camera A's ``T_world_cam`` while the joint is fixed.
    T_wb_b : ndarray, shape (m, 4, 4), optional
        Camera B's, in its own world (need not be paired with A's).

    Returns
    -------
    JointEstimate
        ``scenario="fixed_joint"``, ``method="paper"``.
    """
    a = algorithm_2_pivot(T_wa_a, "camera A")
    b = None if T_wb_b is None else algorithm_2_pivot(T_wb_b, "camera B")
    return joint_of_pivots(a, b, "paper")


def algorithm_3_relative_pose(
    T_wa_a: FloatArray, T_wb_b: FloatArray, o_a: FloatArray, reference: int = 0
) -> PaperRelativePose:
    """Algorithm III (section 3.2): the relative pose of non-overlapping cameras.

    With camera motions relative to the reference frame, ``H_A^i`` and ``H_B^i``, the joint
    constraint ``H_B^i H_BA O_A' = H_BA H_A^i O_A'`` (eq. (24), ``O_A' = [O_A; 1]``) is
    linear in ``vec(R_BA)`` and ``T_BA``; the linear solution is projected onto a rotation
    and refined by Levenberg-Marquardt over roll, pitch, yaw, ``T_BA`` and ``O_A``
    (eq. (25)).

    Parameters
    ----------
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Paired poses of general motion, each camera in its own world.
    o_a : ndarray, shape (3,)
        The joint in camera A (from Algorithm I or II).
    reference : int
        The frame of ``H_BA``.
    """
    return relative_pose_paper(T_wa_a, T_wb_b, o_a, reference, unknown_scale=False)


def algorithm_4_unknown_scale(
    T_wa_a: FloatArray, T_wb_b: FloatArray, o_a: FloatArray, reference: int = 0
) -> PaperRelativePose:
    """Algorithm IV (section 4): Algorithm III when each trajectory has its own scale.

    The translations carry unknown factors ``mu_A``, ``mu_B``; eq. (24) holds with
    ``phi_BA = mu_B / mu_A`` multiplying ``R_BA`` (the linear solution's ``phi R_BA`` has
    singular values ``phi``: ``phi = trace(D) / 3``, eq. (38)-(43)), refined by
    Levenberg-Marquardt with ``phi`` (eq. (44)).

    Parameters
    ----------
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Paired poses of general motion, each camera in its own world and scale.
    o_a : ndarray, shape (3,)
        The joint in camera A, in A's trajectory units.
    reference : int
    """
    return relative_pose_paper(T_wa_a, T_wb_b, o_a, reference, unknown_scale=True)


@dataclass(frozen=True)
class PaperRelativePose:
    """Algorithm III's or IV's result (see :func:`relative_pose_paper`).

    ``T_b_a`` ``(4, 4)`` (the paper's ``H_BA``, B's units) with the covariance ``(6, 6)`` of
    (right rotation perturbation (rad), translation); ``phi_ba`` (1 under known scale) and
    its std; ``O_A`` refined (``position_in_a``, A's units) and ``O_B = phi R_BA O_A + T_BA``
    (B's units) with covariances ``(3, 3)``; ``T_wb_wa`` the similarity's rotation and
    translation from world A to world B that eq. (24) implies at the reference frame;
    ``residuals`` ``(n, 3)`` of eq. (25) / (44).
    """

    T_b_a: FloatArray
    covariance: FloatArray
    phi_ba: float
    phi_std: float
    position_in_a: FloatArray
    position_in_b: FloatArray
    covariance_a: FloatArray
    covariance_b: FloatArray
    T_wb_wa: FloatArray
    residuals: FloatArray
    reference: int
    method: str = "paper"


def relative_pose_paper(
    T_wa_a: FloatArray,
    T_wb_b: FloatArray,
    o_a: FloatArray,
    reference: int = 0,
    unknown_scale: bool = False,
) -> PaperRelativePose:
    """Algorithms III and IV as published (sections 3.2 and 4).

    With motions relative to the reference frame ``k``, ``H_A^i = inv(T_wa_a[k]) T_wa_a[i]``
    and ``H_B^i`` likewise, eq. (24) ``H_B^i H_BA O_A' = H_BA H_A^i O_A'`` is linear in
    ``vec(R_BA)`` and ``T_BA``:

        [R_B^i K(O_A) - K(R_A^i O_A + T_A^i)] vec(R_BA) + (R_B^i - I) T_BA = -T_B^i

    (``K(v) vec(M) = M v``), solved by least squares; ``R_BA`` is the nearest rotation
    (``U V^T`` of the SVD, with ``phi = trace(D) / 3`` under unknown scale, eq. (38)-(43)),
    then Levenberg-Marquardt over roll, pitch, yaw, ``T_BA``, ``O_A`` (and ``phi``) minimises
    eq. (25) (eq. (44)). The reference frame is taken as exact; the covariance is the
    Gauss-Newton one with the residual variance.

    Parameters
    ----------
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_cam`` of A and B, each in its own world (and units).
    o_a : ndarray, shape (3,)
        ``O_A``: the joint in camera A (A's units).
    reference : int
        Index of the reference frame ``k`` (negative counts from the end).
    unknown_scale : bool
        Algorithm IV: estimate ``phi_BA = mu_B / mu_A``.

    Returns
    -------
    PaperRelativePose
    """
    Ta, Tb = np.asarray(T_wa_a, float), np.asarray(T_wb_b, float)
    n = Ta.shape[0]
    reference = reference % n
    o_a = np.asarray(o_a, dtype=float)
    Ha = se3.invert_transforms(Ta[reference]) @ Ta  # H_A^i
    Hb = se3.invert_transforms(Tb[reference]) @ Tb  # H_B^i
    c = np.ascontiguousarray
    RA, TA, RB, TB = c(Ha[:, :3, :3]), c(Ha[:, :3, 3]), c(Hb[:, :3, :3]), c(Hb[:, :3, 3])
    RAf, RBf = RA.reshape(-1, 3), RB.reshape(-1, 3)
    # eq. (24), linear in vec(R_BA) and T_BA
    KO = kron_rows(np.broadcast_to(o_a, (n, 3)))
    A_rot = np.einsum("nij,njk->nik", RB, KO) - kron_rows(np.einsum("nij,j->ni", RA, o_a) + TA)
    A = np.concatenate([A_rot, RB - np.eye(3)], axis=2).reshape(-1, 12)
    x, _ = lstsq_scaled(A, -TB.reshape(-1))
    # eq. (38)-(43): R = U V^T, phi = trace(D) / 3
    R0, s = se3.project_to_rotation(x[:9].reshape(3, 3))
    phi0 = float(np.sum(s) / 3.0) if unknown_scale else 1.0
    rpy0 = np.radians(se3.rpy_deg_from_matrix(R0))

    def unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        R = se3.matrix_from_rpy_deg(np.degrees(p[:3]))
        return R, p[3:6], p[6:9], (float(p[9]) if unknown_scale else 1.0)

    def res(p: FloatArray) -> FloatArray:
        # eq. (25) / (44)
        R, T, O, phi = unpack(p)
        ja = (RAf @ O).reshape(-1, 3) + TA
        r = phi * (RBf @ (R @ O)).reshape(-1, 3) + (RBf @ T).reshape(-1, 3) - T
        return np.asarray((r - phi * ja @ R.T + TB).reshape(-1))

    def jac(p: FloatArray) -> FloatArray:
        R, _T, O, phi = unpack(p)
        ja = (RAf @ O).reshape(-1, 3) + TA
        # d R / d rpy_k = R [e_k]x with e_k the columns of rpy_right_jacobian
        dR = np.matmul(R, se3.skew(se3.rpy_right_jacobian(p[:3]).T))  # (3, 3, 3): k, i, j
        Jr = phi * (np.einsum("nij,kjl,l->nik", RB, dR, O) - np.einsum("nj,kij->nik", ja, dR))
        JT = RB - np.eye(3)
        JO = phi * ((RBf @ R).reshape(-1, 3, 3) - np.matmul(R, RA))
        blocks = [Jr, JT, JO]
        if unknown_scale:
            blocks.append(((RBf @ (R @ O)).reshape(-1, 3) - ja @ R.T)[:, :, None])
        return np.concatenate(blocks, axis=2).reshape(3 * n, -1)

    p0 = np.concatenate([rpy0, x[9:], o_a] + ([[phi0]] if unknown_scale else []))
    sol = lsq.solve(res, p0, jac=jac, method="lm")
    R, T, O, phi = unpack(sol.x)
    r = sol.fun.reshape(-1, 3)
    Jm = sol.jac
    dof = max(r.size - Jm.shape[1], 1)
    cov = float(np.sum(r**2) / dof) * np.linalg.pinv(Jm.T @ Jm)
    # covariance of (R perturbation, T): rpy -> right perturbation
    G = np.zeros((6, cov.shape[0]))
    G[:3, :3] = se3.rpy_right_jacobian(np.radians(se3.rpy_deg_from_matrix(R)))
    G[3:, 3:6] = np.eye(3)
    O_b = phi * R @ O + T
    JOb = np.concatenate([-phi * R @ se3.skew(O) @ G[:3, :3], np.eye(3), phi * R], axis=1)
    if unknown_scale:
        JOb = np.concatenate([JOb, (R @ O)[:, None]], axis=1)
    # the similarity world A -> world B: j_b = phi R_X j_a + t_X (eq. (24) at the reference)
    R_X = Tb[reference, :3, :3] @ R @ Ta[reference, :3, :3].T
    t_X = Tb[reference, :3, 3] + Tb[reference, :3, :3] @ T - phi * R_X @ Ta[reference, :3, 3]
    return PaperRelativePose(
        T_b_a=se3.transforms_from_rt(R, T),
        covariance=G @ cov @ G.T,
        phi_ba=phi,
        phi_std=float(np.sqrt(cov[9, 9])) if unknown_scale else 0.0,
        position_in_a=O,
        position_in_b=O_b,
        covariance_a=cov[6:9, 6:9],
        covariance_b=JOb @ cov[: JOb.shape[1], : JOb.shape[1]] @ JOb.T,
        T_wb_wa=se3.transforms_from_rt(R_X, t_X),
        residuals=r,
        reference=reference,
    )
