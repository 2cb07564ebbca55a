"""Chen & Wong's four algorithms, as published: one function each (pairwise, two cameras).

This is the index a reader of the paper starts from. Each function runs the paper's own
formulation (``method="paper"``) and names the equations it solves; the code that solves
them lives beside the refined estimators that share its inputs and checks:

==========  =====================================  ==========================================
Algorithm   here                                   solved in
==========  =====================================  ==========================================
I           :func:`algorithm_1_overlap`            :func:`acs_cli.core.joint.estimate_joint_overlap`
II          :func:`algorithm_2_fixed_joint`        :func:`acs_cli.core.joint.estimate_pivot`
III         :func:`algorithm_3_relative_pose`      :func:`acs_cli.core.relpose._paper`
IV          :func:`algorithm_4_unknown_scale`      :func:`acs_cli.core.relpose._paper`
==========  =====================================  ==========================================

Rigs of more than two cameras, hinges and rigid pairs go beyond the paper: one solve over
the whole tree, :func:`acs_cli.core.rig_solve.estimate_rig`.

Frames: the paper's ``H_BA`` is our ``T_b_a``, its ``O_A`` our ``position_in_a``.
"""

from __future__ import annotations

from acs_cli.core.joint import JointEstimate, estimate_joint_fixed, estimate_joint_overlap
from acs_cli.core.relpose import JointPrior, RelposeEstimate, estimate_relpose
from acs_cli.core.se3 import FloatArray

__all__ = [
    "algorithm_1_overlap",
    "algorithm_2_fixed_joint",
    "algorithm_3_relative_pose",
    "algorithm_4_unknown_scale",
]


def algorithm_1_overlap(T_w_a: FloatArray, T_w_b: FloatArray) -> JointEstimate:
    """Algorithm I (section 2): the joint from two cameras with overlapping views.

    Both trajectories are in one world (a shared board). At every instant the joint is one
    point, ``R_wa_i O_A + t_wa_i = R_wb_i O_B + t_wb_i`` (eq. (8)), stacked over the frames
    into the linear system ``[R_wa_i, -R_wb_i] [O_A; O_B] = t_wb_i - t_wa_i`` (eq. (9)) and
    solved by least squares.

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_cam`` of cameras A and B in the same world.
    """
    return estimate_joint_overlap(T_w_a, T_w_b, method="paper")


def algorithm_2_fixed_joint(T_wa_a: FloatArray, T_wb_b: FloatArray | None = None) -> JointEstimate:
    """Algorithm II (section 3.1): the joint from a fixed-joint motion (pivot calibration).

    While the joint stays at one world point, each camera's motion relative to its first
    frame, ``H^i = inv(T_w_c[0]) T_w_c[i] = [R^i, T^i]``, fixes the joint:
    ``(R^i - I) O = -T^i`` (eq. (11)-(12)), solved by least squares for each camera.

    Parameters
    ----------
    T_wa_a : ndarray, shape (n, 4, 4)
        Camera A's ``T_world_cam`` while the joint is fixed.
    T_wb_b : ndarray, shape (m, 4, 4), optional
        Camera B's, in its own world.
    """
    return estimate_joint_fixed(T_wa_a, T_wb_b, method="paper")


def algorithm_3_relative_pose(
    T_wa_a: FloatArray, T_wb_b: FloatArray, o_a: FloatArray, reference: int = 0
) -> RelposeEstimate:
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
    return estimate_relpose(
        T_wa_a, T_wb_b, JointPrior(position_in_a=o_a), reference=reference, method="paper"
    )


def algorithm_4_unknown_scale(
    T_wa_a: FloatArray, T_wb_b: FloatArray, o_a: FloatArray, reference: int = 0
) -> RelposeEstimate:
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
    return estimate_relpose(
        T_wa_a,
        T_wb_b,
        JointPrior(position_in_a=o_a),
        unknown_scale=True,
        reference=reference,
        method="paper",
    )
