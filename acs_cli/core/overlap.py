"""Algorithm I through the rig engine: two cameras in one world as a two-body rig.

With overlapping views (both cameras see one board, or one motion-capture lab tracks both
bodies) every pose is in one world and the joint satisfies, at every instant,

    R_wa_i o_a + t_wa_i = R_wb_i o_b + t_wb_i                       (the paper's eq. (8))

That is a rig of two bodies ``a`` (the reference) and ``b`` joined by a ball joint, with
one recording whose bodies share a world (:meth:`acs_cli.core.rig_solve.Recordings.single`
with ``shared_world=True``): :func:`acs_cli.core.rig_solve.estimate_rig` solves it by
maximum likelihood from the paper's linear solution (:func:`acs_cli.core.paper.
algorithm_1_solve`), the noise levels fitted, outliers rejected by the studentised test.
This module builds that rig, keeps the two-camera messages for a motion that cannot locate
the joint (:func:`acs_cli.core.joint.overlap_motion`), and reads the rig's result as a
:class:`~acs_cli.core.joint.JointEstimate` (what ``joint.yaml`` holds).
"""

from __future__ import annotations

import numpy as np

from acs_cli.core import se3
from acs_cli.core.joint import (
    JointEstimate,
    OverlapMotion,
    _check_method,
    hinge_explains,
    overlap_motion,
    rotation_spread,
)
from acs_cli.core.paper import algorithm_1_overlap, algorithm_1_solve
from acs_cli.core.relpose import check_joint_type
from acs_cli.core.rig import RigTopology, rig_topology
from acs_cli.core.rig_solve import (
    CameraTrack,
    Recordings,
    RigEstimate,
    edge_motion,
    estimate_rig,
)
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = [
    "JOINT",
    "OVERLAP_RIG",
    "check_overlap_joint_type",
    "estimate_joint_overlap",
    "estimate_overlap_rig",
    "joint_of_rig",
    "overlap_rig",
]

#: The joint's name in the two-body rig.
JOINT = "joint"
#: Camera A (the reference) and camera B joined by a ball joint.
OVERLAP_RIG = rig_topology(["a", "b"], [(JOINT, ["a", "b"], "ball")], "a")


def overlap_rig(joint_type: str = "ball") -> RigTopology:
    """:data:`OVERLAP_RIG` with its joint declared ``joint_type`` (ball or hinge)."""
    if joint_type == "ball":
        return OVERLAP_RIG
    check_overlap_joint_type(joint_type)
    return rig_topology(["a", "b"], [(JOINT, ["a", "b"], joint_type)], "a")


def check_overlap_joint_type(joint_type: str, method: str = "refined") -> None:
    """Refuse a joint type an overlap cannot locate (a rigid pair has no joint point), or
    one the paper's method does not model (ball only)."""
    if joint_type == "rigid":
        raise InputError(
            "a rigid pair has no joint point for `joint --overlap` to locate; calibrate a "
            "rigid pair's T_b_a with `acscal relpose --joint-type rigid`"
        )
    check_joint_type(joint_type, method)  # unknown types, and the paper's ball only


def overlap_tracks(T_w_a: FloatArray, T_w_b: FloatArray) -> dict[str, CameraTrack]:
    """The two cameras' paired poses ``(n, 4, 4)`` as the rig's tracks (every frame valid)."""
    n = T_w_a.shape[0]
    return {"a": CameraTrack(T_w_a, np.ones(n, bool)), "b": CameraTrack(T_w_b, np.ones(n, bool))}


def estimate_overlap_rig(
    T_w_a: FloatArray,
    T_w_b: FloatArray,
    *,
    reject_outliers: bool = True,
    joint_type: str = "ball",
    noise_tolerance: float = 0.0,
) -> RigEstimate:
    """The two-body rig of Algorithm I, solved by the rig engine.

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_a`` and ``T_world_b`` in the same world frame.
    reject_outliers : bool
    noise_tolerance : float
        When the noise levels' refits stop (:func:`acs_cli.core.rig_solve.estimate_rig`;
        0: at their fixed point).
    joint_type : {"ball", "hinge"}
        A hinge's point is the one on its axis nearest camera A's centre, its axis in
        ``axis_in``; an articulation about one axis is then what is expected, not refused.

    Returns
    -------
    RigEstimate
        Of :data:`OVERLAP_RIG`: the joint is ``edges[JOINT]``, its position ``position_in``
        ``"a"`` and ``"b"``. A joint whose std alone is large is returned (the stage's
        verdict judges it); a null direction is refused.

    Raises
    ------
    InputError
        Poses that are not paired rigid transforms.
    DegenerateMotionError
        Too few frames, a rigid pair, or an articulation about one axis (the hinge's axis
        in both frames in ``details``, as :func:`acs_cli.core.joint.overlap_motion`).
    """
    hinge = joint_type == "hinge"
    motion = _hinge_motion(T_w_a, T_w_b) if hinge else overlap_motion(T_w_a, T_w_b)
    n = motion.T_w_a.shape[0]
    # the reference instant is never rejected (its poses are corrected to fit): the frame
    # that fits eq. (9) best, where no gross outlier is
    residuals = algorithm_1_solve(motion.T_w_a, motion.T_w_b)[1]
    try:
        est = estimate_rig(
            overlap_rig(joint_type),
            overlap_tracks(motion.T_w_a, motion.T_w_b),
            reference_frame=int(np.argmin(np.sum(residuals**2, axis=1))),
            reject_outliers=reject_outliers,
            noise_tolerance=noise_tolerance,
            accept_weak=True,
            recordings=Recordings.single(n, shared_world=True),
        )
    except DegenerateMotionError:
        if motion.spread.candidate_hinge and not hinge:
            raise motion.hinge_error() from None
        raise
    if hinge:
        return est
    e = est.edges[JOINT]
    # the articulation carries both cameras' rotation noise
    sigma_rel = float(np.sqrt(2.0) * np.radians(e.noise.get("sigma_rot_deg", 0.0)))
    if hinge_explains(motion.spread, e.motion_cov_in("b"), e.position_in["b"], sigma_rel):
        raise motion.hinge_error()
    return est


def _hinge_motion(T_w_a: FloatArray, T_w_b: FloatArray) -> OverlapMotion:
    """:func:`acs_cli.core.joint.overlap_motion` for a declared hinge: a rigid pair is still
    refused, an articulation about one axis is what a hinge does."""
    Ta, Tb = se3.check_paired_transforms(T_w_a, T_w_b, "overlap")
    if Ta.shape[0] < 3:
        raise DegenerateMotionError(
            f"{Ta.shape[0]} paired poses; an overlap calibration needs at least 3"
        )
    R_ab = np.einsum("nji,njk->nik", Ta[:, :3, :3], Tb[:, :3, :3])
    try:
        spread = rotation_spread(R_ab, "relative rotation between A and B")
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(
            "the hinge cannot be observed: " + exc.message + " Turn the hinge between frames.",
            details=exc.details,
        ) from None
    return OverlapMotion(Ta, Tb, spread)


def joint_of_rig(est: RigEstimate, n: int) -> JointEstimate:
    """The overlap's :class:`~acs_cli.core.joint.JointEstimate` from its rig estimate (or its
    bundle adjustment's) over ``n`` paired frames: the joint and its covariance in each
    camera, and the residual, frames used and pose noise (per camera, keyed ``"ab"``) of
    the pose-based solve."""
    e = est.edges[JOINT]
    inliers = np.zeros(n, bool)
    inliers[e.inliers] = True
    noise: dict[str, float] = {
        k: float(e.noise[k]) for k in ("sigma_trans", "sigma_rot_deg") if k in e.noise
    }
    return JointEstimate(
        position_in_a=np.asarray(e.position_in["a"], float),
        covariance_a=np.asarray(e.position_cov_in["a"], float),
        position_in_b=np.asarray(e.position_in["b"], float),
        covariance_b=np.asarray(e.position_cov_in["b"], float),
        scenario="overlap",
        method="refined",
        residual_rms={"ab": float(e.residual_rms)},
        inliers={"ab": inliers},
        noise={"ab": noise} if noise else {},
        motion=edge_motion(est, JOINT),
        joint_type=e.joint.type,
        axis_in={c: np.asarray(u, float) for c, u in e.axis_in.items()},
        axis_std_deg_in={c: float(v) for c, v in e.axis_std_deg_in.items()},
        correlated={"ab": est.correlated},
    )


def estimate_joint_overlap(
    T_w_a: FloatArray, T_w_b: FloatArray, method: str = "refined", joint_type: str = "ball"
) -> JointEstimate:
    """Algorithm I: the joint from paired poses of two cameras in one world.

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired poses ``T_world_a`` and ``T_world_b`` in the same world frame.
    method : {"refined", "paper"}
        ``"refined"``: the two-body rig in one world (:func:`estimate_overlap_rig`): the
        constraint weighted by the covariance both cameras' pose noise induces, noise
        levels estimated, outliers rejected. ``"paper"``: the least squares of eq. (9),
        :func:`acs_cli.core.paper.algorithm_1_overlap`.

    Raises
    ------
    InputError
        An unknown method, or poses that are not paired rigid transforms.
    DegenerateMotionError
        Too few frames, or a relative rotation between the cameras that does not change
        enough (a rigid pair: no articulation), or that changes about one axis only.
    """
    _check_method(method)
    check_overlap_joint_type(joint_type, method)
    if method == "paper":
        return algorithm_1_overlap(T_w_a, T_w_b)
    est = estimate_overlap_rig(T_w_a, T_w_b, joint_type=joint_type)
    return joint_of_rig(est, est.cameras["a"].poses_in_reference_world.shape[0])
