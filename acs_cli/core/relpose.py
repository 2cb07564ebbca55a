"""Relative pose of non-overlapping cameras from the joint constraint (Algorithms III, IV).

Each camera's trajectory is known in its own world: ``T_wa_a[i]`` and ``T_wb_b[i]``. At
every instant the joint is one physical point, so its positions in the two worlds,

    j_a[i] = R_wa_i o_a + t_wa_i        j_b[i] = R_wb_i o_b + t_wb_i,

are related by one constant similarity ``X = T_wb_wa`` (rotation ``R_X``, translation
``t_X``, and scale ``phi_ba = mu_B / mu_A`` when each trajectory has its own unknown scale):

    j_b[i] = phi R_X j_a[i] + t_X.

The relative pose at the reference instant ``k`` follows as
``T_b_a = inv(T_wb_b[k]) X T_wa_a[k]`` (the paper's ``H_BA``).

``method="paper"`` runs the paper's own formulation (:func:`acs_cli.core.paper.relative_pose_paper`:
eq. (24) linear, then Levenberg-Marquardt taking the reference frame as exact). The refined
method is the rig engine on a two-body rig (:func:`acs_cli.core.rig_solve.estimate_rig`:
cameras ``a`` and ``b``, one joint (a ball unless ``joint_type`` says hinge or rigid),
each camera in its own world, ``b`` the reference so that lengths come out in B's units):
every frame alike, the joint in both cameras together
with ``X``, frames weighted by their noise, a joint from a fixed-joint calibration as a
prior, outliers rejected by the studentised test, and the two reference poses corrected by
the joint constraint. This module only translates between the pair's vocabulary and the
rig's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from acs_cli.core import se3
from acs_cli.core.joint import METHODS, MIN_ROTATION_SPREAD, MotionSummary, articulation_motion
from acs_cli.core.paper import PaperRelativePose, relative_pose_paper
from acs_cli.core.quality import OVERRIDE_HINT, largest_std, length_scale
from acs_cli.core.rig import RigJoint, RigTopology
from acs_cli.core.rig_solve import (
    SINGLE_AXIS_RATIO,
    UNDETERMINED_STD_FRACTION,
    CameraTrack,
    EdgePrior,
    RigEstimate,
    edge_motion,
    estimate_rig,
)
from acs_cli.core.rig_start import similarity_from_lifted
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = [
    "JOINT_TYPES",
    "SINGLE_AXIS_RATIO",
    "UNDETERMINED_STD_FRACTION",
    "JointPrior",
    "RelposeEstimate",
    "estimate_relpose",
    "in_pair_words",
    "motion_diagnosis",
    "paper_pose_std",
]

#: Smallest ratio of the second to the first singular value of the centred joint
#: trajectory (in world A) for the rotation between the worlds to be observable.
COLLINEAR_RATIO = 0.02
#: Fewest paired frames for a relative pose from a known joint, and for self-calibration.
MIN_FRAMES = 5
MIN_FRAMES_SELF_CALIBRATION = 14
#: Standard deviation (in the trajectory's units) assumed for a prior joint given without one.
DEFAULT_PRIOR_STD = 1e-6
#: The two-body rig's names: camera A, camera B and their joint.
_A, _B, _JOINT = "a", "b", "joint"
TWO_BODY_JOINT = _JOINT
#: The joint types a two-body rig can declare (``--joint-type``): a ball joint (the paper's),
#: a hinge (one axis) or a rigid mount (a constant ``T_b_a``, no joint point).
JOINT_TYPES = ("ball", "hinge", "rigid")


def check_joint_type(joint_type: str, method: str = "refined") -> None:
    """Refuse an unknown joint type, or one the paper's method does not have (ball only)."""
    if joint_type not in JOINT_TYPES:
        raise InputError(
            f"unknown joint type {joint_type!r}; choose one of {', '.join(JOINT_TYPES)}"
        )
    if method == "paper" and joint_type != "ball":
        raise InputError(
            f"the paper's method models a ball joint only; a {joint_type} needs the refined "
            "method (drop --method paper)"
        )


@dataclass(frozen=True)
class JointPrior:
    """A joint from an earlier calibration, used as a prior.

    Attributes
    ----------
    position_in_a, position_in_b : ndarray (3,) or None
    covariance_a, covariance_b : ndarray (3, 3) or None
        ``None`` means "exact" for the paper's method and a tight prior for ours.
    metric : bool
        True when the positions are in metres while the trajectories have unknown scales
        (``--joint-metric``): then ``mu_a`` and ``mu_b`` are estimated too.
    """

    position_in_a: FloatArray | None = None
    position_in_b: FloatArray | None = None
    covariance_a: FloatArray | None = None
    covariance_b: FloatArray | None = None
    metric: bool = False


@dataclass(frozen=True)
class RelposeEstimate:
    """Relative pose of camera B with respect to camera A at the reference instant.

    Attributes
    ----------
    T_b_a : ndarray, shape (4, 4)
        Maps points of camera A's frame into camera B's at the reference instant; its
        translation is in B's units (metres under known scale).
    covariance : ndarray, shape (6, 6)
        Of ``(rotation perturbation of R_b_a on the right (rad), t_b_a)``.
    reference : int
    phi_ba, phi_std : float
        Relative scale ``mu_B / mu_A`` (1 and 0 under known scale).
    mu_a, mu_b, mu_a_std, mu_b_std : float or None
        Absolute scales, when a metric joint was given under unknown scale.
    position_in_a, position_in_b : ndarray (3,)
        Joint in A's frame (A's units) and B's frame (B's units).
    covariance_a, covariance_b : ndarray (3, 3)
    T_wb_wa : ndarray, shape (4, 4)
        Rotation and translation of the similarity from world A to world B.
    residual_rms : float
        RMS of the joint-constraint residual (B's units) over the frames used.
    inliers : ndarray of bool, shape (n,)
    noise : dict
    method : str
    unknown_scale, self_calibrated : bool
    """

    T_b_a: FloatArray
    covariance: FloatArray
    reference: int
    phi_ba: float
    phi_std: float
    position_in_a: FloatArray
    position_in_b: FloatArray
    covariance_a: FloatArray
    covariance_b: FloatArray
    T_wb_wa: FloatArray
    residual_rms: float
    inliers: np.ndarray
    method: str
    unknown_scale: bool
    self_calibrated: bool
    mu_a: float | None = None
    mu_b: float | None = None
    mu_a_std: float | None = None
    mu_b_std: float | None = None
    noise: dict[str, float] = field(default_factory=dict)
    residuals: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    #: the two-body rig's estimate behind a refined result (:func:`two_body_rig`), for the
    #: bundle adjustment to start from; None for the paper's method
    rig: RigEstimate | None = None
    #: the declared joint (:data:`JOINT_TYPES`); a rigid pair has no joint point (its
    #: ``position_in_*`` are zeros with zero covariances and mean nothing)
    joint_type: str = "ball"
    #: a hinge's axis in each camera's frame (unit vectors) and their std (deg); else None
    axis_in_a: FloatArray | None = None
    axis_in_b: FloatArray | None = None
    axis_in_a_std_deg: float | None = None
    axis_in_b_std_deg: float | None = None
    #: a ball joint: how it bent (its articulation), in A's and B's frames (``"a"``, ``"b"``:
    #: :func:`acs_cli.core.joint.articulation_motion`); empty for a hinge or a rigid mount
    motion: dict[str, MotionSummary] = field(default_factory=dict)

    @property
    def has_point(self) -> bool:
        """Whether the joint is a point (not a rigid mount)."""
        return self.joint_type != "rigid"

    @property
    def T_a_b(self) -> FloatArray:
        """Pose of camera B in camera A's frame (the paper's tables' relative pose)."""
        return np.asarray(se3.invert_transforms(self.T_b_a))

    @property
    def rpy_deg(self) -> FloatArray:
        """Roll, pitch, yaw (deg) of ``R_a_b`` (the paper's ``~R_BA = R_BA^T``)."""
        return np.asarray(se3.rpy_deg_from_matrix(self.T_a_b[:3, :3]))

    @property
    def translation_b_in_a(self) -> FloatArray:
        """``t_a_b = -R_BA^T T_BA`` (the paper's ``~T_BA``), B's units."""
        return np.asarray(self.T_a_b[:3, 3])


def estimate_relpose(
    T_wa_a: FloatArray,
    T_wb_b: FloatArray,
    prior: JointPrior | None = None,
    *,
    unknown_scale: bool = False,
    reference: int = 0,
    method: str = "refined",
    reject_outliers: bool = True,
    accept_weak: bool = False,
    noise_tolerance: float = 0.0,
    joint_type: str = "ball",
) -> RelposeEstimate:
    """Relative pose (and scale) of two cameras joined by a joint, from general motion.

    Parameters
    ----------
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Paired poses ``T_world_cam`` of camera A and B, each in its own world.
    prior : JointPrior, optional
        The joint from a fixed-joint calibration. Without it (or with neither position)
        the joint is self-calibrated from this motion (ours only; the paper needs ``O_A``).
    unknown_scale : bool
        Each trajectory's translations carry an unknown factor (Algorithm IV).
    reference : int
        Frame index at which ``T_b_a`` is reported (negative counts from the end).
    method : {"refined", "paper"}
        ``paper``: :func:`acs_cli.core.paper.relative_pose_paper`; ``refined``: the rig
        engine on the two-body rig (module doc).
    reject_outliers : bool
    accept_weak : bool
        Return a self-calibrated joint a narrow motion hardly determines instead of refusing
        it (``--accept-weak``; the stage marks the result weak); a joint that hardly bends
        or bends about one axis is refused whatever it says.
    joint_type : {"ball", "hinge", "rigid"}
        The two-body rig's joint (:data:`JOINT_TYPES`; refined method only for a hinge or
        a rigid mount). A hinge's point is the one on its axis nearest camera A's centre;
        a rigid mount has no point and takes no prior (``T_b_a`` is constant).
    noise_tolerance : float
        Passed to :func:`~acs_cli.core.rig_solve.estimate_rig` (a scan's quick fits).

    Returns
    -------
    RelposeEstimate

    Raises
    ------
    InputError
        Mismatched inputs, or ``method="paper"`` without ``prior.position_in_a``.
    DegenerateMotionError
        Too few frames or a motion that does not determine the answer.
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    check_joint_type(joint_type, method)
    Ta, Tb = _check_inputs(T_wa_a, T_wb_b, reference)
    n = Ta.shape[0]
    reference = reference % n
    prior = prior or JointPrior()
    self_cal = prior.position_in_a is None and prior.position_in_b is None
    if joint_type == "rigid" and not self_cal:
        raise InputError("a rigid joint has no joint point: give no joint file (--joint)")
    need = MIN_FRAMES_SELF_CALIBRATION if self_cal else MIN_FRAMES
    if n < need:
        raise DegenerateMotionError(
            f"{n} paired frames; {'self-calibration' if self_cal else 'a relative pose'} needs at "
            f"least {need} frames of general motion: record more, with the rig turning about "
            "several axes while it moves and bends"
        )
    if method == "paper" or self_cal:
        # eq. (24) and the self-calibration need camera A to turn about two axes or more
        notes = motion_diagnosis(Ta, Tb)
        if notes["camera"]:
            what = "the paper's Algorithm III/IV" if method == "paper" else "self-calibration"
            raise DegenerateMotionError(
                f"{what} cannot use this motion: {notes['camera']}. Record the rig turning "
                "about two or more axes"
                + (
                    ", or give the joint from a fixed-joint session (--joint)"
                    if self_cal and joint_type != "rigid"
                    else ", or use the refined method, which handles it with a known joint"
                ),
                details={"diagnosis": notes},
            )
    if method == "paper":
        return _paper(Ta, Tb, prior, unknown_scale, reference)
    est = _refined(
        Ta,
        Tb,
        prior,
        unknown_scale,
        reference,
        self_cal,
        reject_outliers,
        joint_type,
        noise_tolerance,
    )
    _check_determined(est, Ta, Tb, accept_weak)
    return est


def _paper(
    Ta: FloatArray, Tb: FloatArray, prior: JointPrior, unknown_scale: bool, reference: int
) -> RelposeEstimate:
    """:func:`acs_cli.core.paper.relative_pose_paper` in the pair's vocabulary."""
    if prior.position_in_a is None:
        raise InputError(
            "the paper's method needs the joint in camera A: give --joint (the joint.yaml "
            "of a fixed-joint calibration), or self-calibrate with the refined method"
        )
    if prior.metric and unknown_scale:
        raise InputError(
            "the paper's method takes the joint in camera A's own (scaled) units; with a "
            "metric joint use the refined method"
        )
    p: PaperRelativePose = relative_pose_paper(
        Ta, Tb, np.asarray(prior.position_in_a, float), reference, unknown_scale
    )
    _check_spread(se3.transform_points(Ta, p.position_in_a))
    r = p.residuals
    return RelposeEstimate(
        T_b_a=p.T_b_a,
        covariance=p.covariance,
        reference=reference,
        phi_ba=p.phi_ba,
        phi_std=p.phi_std,
        position_in_a=p.position_in_a,
        position_in_b=p.position_in_b,
        covariance_a=p.covariance_a,
        covariance_b=p.covariance_b,
        T_wb_wa=p.T_wb_wa,
        residual_rms=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
        inliers=np.ones(Ta.shape[0], dtype=bool),
        method="paper",
        unknown_scale=unknown_scale,
        self_calibrated=False,
        residuals=r,
        # the articulation with A's rotations carried into world B
        motion=articulation_motion(
            np.einsum("ij,njk->nik", p.T_wb_wa[:3, :3], Ta[:, :3, :3]), Tb[:, :3, :3], _A, _B
        ),
    )


def two_body_rig(joint_type: str = "ball") -> RigTopology:
    """The pair as a rig: cameras ``a`` and ``b``, one joint (a ball unless told), ``b`` the
    reference (the rig reports lengths in the reference's units: ``T_b_a``'s translation in
    B's)."""
    return RigTopology((_A, _B), (RigJoint(_JOINT, (_A, _B), joint_type),), _B)


def prior_for_rig(prior: JointPrior, unknown_scale: bool) -> EdgePrior | None:
    """A :class:`JointPrior` as the rig's :class:`~acs_cli.core.rig_solve.EdgePrior` of the
    two-body rig's joint: in each camera's own units (metres under known scale), or in
    metres with the scales to estimate (``metric`` under unknown scale)."""
    pos: dict[str, FloatArray] = {}
    cov: dict[str, FloatArray] = {}
    for cam, o, C in (
        (_A, prior.position_in_a, prior.covariance_a),
        (_B, prior.position_in_b, prior.covariance_b),
    ):
        if o is None:
            continue
        pos[cam] = np.asarray(o, float)
        C = np.eye(3) * DEFAULT_PRIOR_STD**2 if C is None else np.asarray(C, float)
        cov[cam] = C + np.eye(3) * 1e-12 * max(1.0, float(np.trace(C)))
    if not pos:
        return None
    units = "metre" if (prior.metric and unknown_scale) else "own"
    return EdgePrior(position_in=pos, covariance_in=cov, units=units)


def _inverse_covariance(T_a_b: FloatArray, C: FloatArray) -> FloatArray:
    """The covariance ``(6, 6)`` of ``inv(T_a_b)`` from that of ``T_a_b`` (both as (right
    rotation perturbation, translation)): ``R_b_a = R_a_b^T Exp(-R_a_b w)`` and
    ``t_b_a`` moves by ``[t_b_a]x w - R_a_b^T dt``."""
    R = T_a_b[:3, :3]
    t_ba = -R.T @ T_a_b[:3, 3]
    G = np.zeros((6, 6))
    G[:3, :3] = -R
    G[3:, :3] = se3.skew(t_ba)
    G[3:, 3:] = -R.T
    return G @ C @ G.T


def _refined(
    Ta: FloatArray,
    Tb: FloatArray,
    prior: JointPrior,
    unknown_scale: bool,
    reference: int,
    self_cal: bool,
    reject_outliers: bool,
    joint_type: str = "ball",
    noise_tolerance: float = 0.0,
) -> RelposeEstimate:
    """The two-body rig through the rig engine, its result in the pair's vocabulary."""
    n = Ta.shape[0]
    valid = np.ones(n, bool)
    tracks = {_A: CameraTrack(Ta, valid, unknown_scale), _B: CameraTrack(Tb, valid, unknown_scale)}
    edge_prior = prior_for_rig(prior, unknown_scale)
    if prior.position_in_a is not None and not (prior.metric and unknown_scale):
        # a joint path along a line leaves the rotation about it free: say so first
        _check_spread(se3.transform_points(Ta, np.asarray(prior.position_in_a, float)))
    try:
        rig = estimate_rig(
            two_body_rig(joint_type),
            tracks,
            reference_frame=reference,
            priors=None if edge_prior is None else {_JOINT: edge_prior},
            reject_outliers=reject_outliers,
            accept_weak=True,  # the std levels are judged below, in the pair's words
            noise_tolerance=noise_tolerance,
        )
    except DegenerateMotionError as e:
        if "model_refuse_deg" in (e.details or {}):
            # the poses do not fit the declared joint type: the rig's words say which
            raise DegenerateMotionError(in_pair_words(e.message), details=e.details) from None
        # what the motion lacks, with the worlds' rotation from the linear start
        R_w = se3.project_to_rotation(similarity_from_lifted(Ta, Tb, None)[0])[0]
        notes = motion_diagnosis(Ta, Tb, R_w)
        why = "; ".join(v for v in notes.values() if v) or "the motion is too narrow for the noise"
        wants_joint = self_cal and joint_type != "rigid"  # a rigid mount has no point
        raise DegenerateMotionError(
            "the motion does not determine the relative pose"
            + (" and the joint (self-calibration)" if wants_joint else "")
            + f" ({why}). Record general motion: the rig turning about several axes while it "
            "moves and bends"
            + (", or give the joint from a fixed-joint session (--joint)" if wants_joint else "")
            + f". (The rig's solve: {e.message})",
            details={"rig": e.details, "diagnosis": notes},
        ) from None
    est = relpose_from_rig(rig, n, unknown_scale, self_cal)
    if est.has_point:
        _check_spread(se3.transform_points(Ta, est.position_in_a)[est.inliers])
    return est


def in_pair_words(text: str) -> str:
    """A message of the two-body rig's solve (:func:`two_body_rig`) in the pair's words:
    its joint is "the joint (A-B)" and its bodies A and B, as the two-camera commands name
    them, not the rig's internal keys."""
    return (
        text.replace(f"joint {_JOINT} ({_A}-{_B})", "the joint (A-B)")
        .replace(f"when {_A}'s pose", "when A's pose")
        .replace(f"paired with {_B}'s", "paired with B's")
        .replace("declare it type: ", "--joint-type ")
    )


def relpose_from_rig(
    rig: RigEstimate, n: int, unknown_scale: bool, self_cal: bool
) -> RelposeEstimate:
    """A two-body rig's estimate (:func:`two_body_rig`) as a :class:`RelposeEstimate`."""
    a, b = rig.cameras[_A], rig.cameras[_B]
    edge = rig.edges[_JOINT]
    if a.T_cam_ref is None:  # estimate_rig poses both cameras at the reference instant
        raise DegenerateMotionError("camera A has no pose at the reference instant")
    T_a_b = a.T_cam_ref
    inliers = np.zeros(n, bool)
    inliers[edge.inliers] = True
    residuals = np.zeros((n, 3))
    # the rig's residual is j_a - j_b in world B; the pair's has the other sign
    if "pos" in edge.residual_blocks:
        residuals[edge.inliers] = -edge.residual_blocks["pos"]
    elif "trans" in edge.residual_blocks:  # a rigid mount: the translation rows
        residuals[edge.inliers] = -edge.residual_blocks["trans"]
    joint_type = edge.joint.type
    if edge.position_in:
        own = edge.position_own_in or {  # a metric rig (the bundle's): the same
            c: (edge.position_in[c], edge.position_cov_in[c]) for c in (_A, _B)
        }
    else:  # a rigid mount has no point: zeros that RelposeEstimate.has_point disowns
        own = {c: (np.zeros(3), np.zeros((3, 3))) for c in (_A, _B)}
    o_a, C_a = own[_A]
    o_b, C_b = own[_B]
    axis = edge.axis_in
    metric = a.units_per_metre is not None
    return RelposeEstimate(
        T_b_a=se3.invert_transforms(T_a_b),
        covariance=_inverse_covariance(T_a_b, a.covariance),
        reference=rig.reference_frame,
        phi_ba=float(a.scale) if unknown_scale else 1.0,
        phi_std=float(a.scale_std or 0.0) if unknown_scale else 0.0,
        position_in_a=np.asarray(o_a),
        position_in_b=np.asarray(o_b),
        covariance_a=np.asarray(C_a),
        covariance_b=np.asarray(C_b),
        T_wb_wa=np.asarray(a.world_to_reference_world),
        residual_rms=float(edge.residual_rms),
        inliers=inliers,
        method="refined",
        unknown_scale=unknown_scale,
        self_calibrated=self_cal,
        mu_a=a.units_per_metre if metric else None,
        mu_b=b.units_per_metre if metric else None,
        mu_a_std=a.units_per_metre_std if metric else None,
        mu_b_std=b.units_per_metre_std if metric else None,
        noise=dict(edge.noise),
        residuals=residuals,
        rig=rig,
        joint_type=joint_type,
        axis_in_a=np.asarray(axis[_A], float) if _A in axis else None,
        axis_in_b=np.asarray(axis[_B], float) if _B in axis else None,
        axis_in_a_std_deg=float(edge.axis_std_deg_in[_A]) if _A in axis else None,
        axis_in_b_std_deg=float(edge.axis_std_deg_in[_B]) if _B in axis else None,
        motion=edge_motion(rig, _JOINT),
    )


def relpose_refined_by(est: RelposeEstimate, rig: RigEstimate) -> RelposeEstimate:
    """``est`` with its relative pose, joint and world-to-world transform (and their
    covariances) from a refinement of its rig (the bundle adjustment); the frames, residuals
    and noise of the pose solve are kept."""
    r = relpose_from_rig(rig, est.inliers.size, est.unknown_scale, est.self_calibrated)
    return replace(
        est,
        T_b_a=r.T_b_a,
        covariance=r.covariance,
        position_in_a=r.position_in_a,
        covariance_a=r.covariance_a,
        position_in_b=r.position_in_b,
        covariance_b=r.covariance_b,
        T_wb_wa=r.T_wb_wa,
        rig=rig,
        axis_in_a=r.axis_in_a,
        axis_in_b=r.axis_in_b,
        axis_in_a_std_deg=r.axis_in_a_std_deg,
        axis_in_b_std_deg=r.axis_in_b_std_deg,
    )


def _check_inputs(
    T_wa_a: FloatArray, T_wb_b: FloatArray, reference: int
) -> tuple[FloatArray, FloatArray]:
    Ta, Tb = se3.check_paired_transforms(T_wa_a, T_wb_b, "relpose")
    n = Ta.shape[0]
    if not -n <= reference < n:
        raise InputError(
            f"reference frame {reference} is outside the {n} paired frames (0 to {n - 1}): "
            "give --reference (relpose.reference in a run config) within them"
        )
    return Ta, Tb


def _check_spread(j_a: FloatArray, what: str = "joint trajectory") -> None:
    c = j_a - j_a.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    if s[0] <= 0 or s[1] / s[0] < COLLINEAR_RATIO:
        raise DegenerateMotionError(
            f"the {what} is (nearly) a straight line (singular value ratio "
            f"{(s[1] / s[0]) if s[0] > 0 else 0.0:.4f} < {COLLINEAR_RATIO}); the rotation about it "
            "is not determined. Move the rig along a curved path, turning and translating in "
            "different directions.",
            details={"singular_values": s.tolist()},
        )


def motion_diagnosis(
    Ta: FloatArray, Tb: FloatArray, R_wb_wa: FloatArray | None = None
) -> dict[str, str]:
    """What a general motion lacks, in words: ``{"camera": ..., "joint": ...}`` ("" if fine).

    ``camera``: camera A hardly turns (pure translation) or turns about one axis only
    (planar motion). ``joint``: the joint hardly bends (a rigid pair) or bends about one
    axis only (a hinge); it needs the rotation from world A to world B, ``R_wb_wa``
    ``(3, 3)`` (identity for one world), and is left empty without it. Thresholds:
    :data:`MIN_ROTATION_SPREAD` (RMS, rad) and :data:`SINGLE_AXIS_RATIO`.
    """
    Ra = Ta[:, :3, :3]
    checks = [("camera", Ra)]
    if R_wb_wa is not None:
        # the articulation R_a_b = R_a_wa R_wa_wb R_wb_b
        checks.append(("joint", np.einsum("nji,jk,nkl->nil", Ra, R_wb_wa.T, Tb[:, :3, :3])))
    words = {
        "camera": ("camera A hardly turns (pure translation)",
                   "camera A turns about one axis only (planar motion)"),
        "joint": ("the joint hardly bends (a rigid pair)",
                  "the joint bends about one axis only (a hinge)"),
    }  # fmt: skip
    out = {"camera": "", "joint": ""}
    for key, R in checks:
        s = np.linalg.svd((R - R.mean(axis=0)).reshape(-1, 3), compute_uv=False)
        spread = float(s[0] / np.sqrt(R.shape[0]))
        if spread < MIN_ROTATION_SPREAD:
            out[key] = f"{words[key][0]}, RMS spread {np.degrees(spread):.2f} deg"
        elif s[2] < SINGLE_AXIS_RATIO * s[0]:
            out[key] = f"{words[key][1]}, singular value ratio {s[2] / s[0]:.3f}"
    return out


def _check_determined(
    est: RelposeEstimate, Ta: FloatArray, Tb: FloatArray, accept_weak: bool = False
) -> None:
    """Refuse a self-calibrated joint whose standard deviation says the motion did not
    determine it (more than :data:`UNDETERMINED_STD_FRACTION` of its distance from the
    camera). ``T_b_a``'s own spread is dominated by the reference poses' noise and is
    reported, not refused. ``accept_weak`` lets a merely narrow motion through, never a
    joint that hardly bends or bends about one axis (:func:`motion_diagnosis`): its point
    is then arbitrary, not weak."""
    if not est.self_calibrated or not est.has_point:
        return
    worst = {}
    for key, o, cov, T in (
        ("the joint in A", est.position_in_a, est.covariance_a, Ta),
        ("the joint in B", est.position_in_b, est.covariance_b, Tb),
    ):
        # the rig's length scale: |O|, or a tenth of the camera's travel for a joint near
        # the optical centre (a pan-tilt head), whose std does not shrink with |O|
        worst[key] = largest_std(cov) / length_scale(o, T)
    bad = {k: v for k, v in worst.items() if v > UNDETERMINED_STD_FRACTION}
    if not bad:
        return
    R_w = se3.project_to_rotation(est.T_wb_wa[:3, :3])[0]
    notes = motion_diagnosis(Ta, Tb, R_w)
    if est.joint_type == "hinge" and "one axis only" in notes["joint"]:
        notes["joint"] = ""  # what a hinge does
    if accept_weak and not notes["joint"]:
        return
    why = "; ".join(v for v in notes.values() if v) or "the motion is too narrow for the noise"
    text = ", ".join(f"{k} (std {100 * v:.0f}% of |O|)" for k, v in bad.items())
    raise DegenerateMotionError(
        f"the motion does not determine {text}: {why}. Record the rig turning about several "
        "axes while the joint bends about two or more axes"
        + (
            ", or give the joint from a fixed-joint session (--joint)"
            if est.self_calibrated
            else ""
        )
        + ("." if notes["joint"] else f"; {OVERRIDE_HINT}."),
        details={"relative_std": worst, "diagnosis": notes},
    )


def paper_pose_std(T_b_a: FloatArray, covariance: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Standard deviations of the paper's reported quantities from ``T_b_a``'s covariance.

    Parameters
    ----------
    T_b_a : ndarray, shape (4, 4)
    covariance : ndarray, shape (6, 6)
        Of ``(rotation perturbation of R_b_a on the right (rad), t_b_a)``.

    Returns
    -------
    rpy_std_deg : ndarray, shape (3,)
        Of roll, pitch, yaw of ``R_a_b`` (degrees).
    translation_b_in_a_std : ndarray, shape (3,)
        Of ``t_a_b = -R_b_a^T t_b_a``.
    """

    R0, t0 = T_b_a[:3, :3], T_b_a[:3, 3]
    R_ab = R0.T
    t_ab = -R_ab @ t0
    # R = R0 Exp(d) gives R_ab = Exp(-d) R0^T = R_ab Exp(-R0 d): a right perturbation of
    # R_ab, whose roll, pitch, yaw move by E^-1 of it (E: rpy_right_jacobian)
    E = se3.rpy_right_jacobian(np.radians(se3.rpy_deg_from_matrix(R_ab)))
    G = np.zeros((6, 6))
    G[:3, :3] = -np.degrees(np.linalg.solve(E, R0))
    G[3:, :3] = se3.skew(t_ab)  # t_ab = -Exp(-d) R0^T t: moves by [t_ab]x d
    G[3:, 3:] = -R_ab
    std = np.sqrt(np.maximum(np.diag(G @ covariance @ G.T), 0.0))
    return std[:3], std[3:]
