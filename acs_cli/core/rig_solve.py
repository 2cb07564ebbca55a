"""One maximum-likelihood solve over a whole rig: every edge at once.

Each camera ``c`` has a trajectory ``T_wc_c[i]`` in its own world ``wc`` and its own units.
A similarity ``X_c`` (rotation ``R_Xc``, translation ``t_Xc``, scale ``s_c``) maps it into the
reference camera's world and units, so every camera's pose in one frame is

    G_c[i] = [R_Xc R_c[i],  s_c R_Xc t_c[i] + t_Xc]                 (ref world, ref units)

(``X_ref`` is the identity). Each edge ``between: [p, q]`` adds its constraint at every
frame where both cameras have a pose (the paper's eq. (24) generalised from a pair to a tree),
given by its joint type's model (:mod:`acs_cli.core.joints`):

- ``ball``: ``G_p o_p = G_q o_q``: the joint is one point (eq. (24)).
- ``hinge``: the same for a point on the axis, and ``R_Gp u_p = R_Gq u_q``: one axis
  (``o_p . u_p = 0`` fixes which point: the one nearest ``p``'s centre).
- ``rigid``: ``G_p = G_q T_q_p``: the hand-eye constraint.

A rig may be seen in several **recordings** (:class:`Recordings`: each frame of the
timeline belongs to one). The similarity belongs to a *world*, not to a camera: each camera
has its own world in each recording, unless the recording's bodies share one world (one
board seen by every camera, one motion-capture lab: ``world: shared``), where one world
serves them all and the paper's Algorithm I holds inside the rig. A world's similarity is
estimated only where some edge ties it to another world at one instant; a group of worlds
tied to each other but not to the reference's (a second recording of other bodies) keeps
its first world as its own frame (no unknowns: nothing could tell them). The rig's geometry
(joints, rigid transforms) is shared by every recording.

A camera shared by two edges ties them together: its world's ``X`` appears in both. Scales are
free for every camera whose units differ from the reference's (unknown scale on either
side). Joint priors (e.g. from fixed-joint sessions) add rows. The reference instant's poses
get corrections tied to their measurements by the pose noise: held at zero while the rig is
estimated (every frame alike, so which instant is the reference moves no estimate), then
solved with the rest held and that instant's constraints made hard, so that ``T_cam_ref``
fits the joints and is not the noisy measured pose.

Weights: the point residual of a ball or hinge has covariance ``theta_t I + theta_r L_i``
with ``L_i`` the lever shapes of both cameras (as in :mod:`acs_cli.core.estimation`), the
noise levels fitted per edge; axis and rigid residuals have one fitted variance each. The
weights are fitted in the reference world and units and held while the rig is solved, in a
frame and units that follow the edge's two cameras' worlds halfway (:func:`_edge_frame`):
held in the reference world they would turn with the reference camera's world only, and
which camera is the reference would move the estimate. The
solve alternates the one least-squares engine (:func:`acs_cli.core.lsq.solve`:
Levenberg-Marquardt on the normal equations of the analytic sparse Jacobian) with
refitting the noise levels, and rejects per edge the frames whose externally studentised
residual is beyond the threshold the two-camera estimators use (:func:`_reject`), then, as
they do, the worst frames left out and predicted by a refit without them, alone or in
pairs (:func:`_reject_left_out`: outliers that hide each other).
Covariances come from the final whitened Jacobian.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix

from acs_cli.core import estimation, lsq, se3
from acs_cli.core.bundle import right_jacobians
from acs_cli.core.correlated import (
    NOT_TESTED,
    CorrelatedErrors,
    covariance_with_correlated_errors,
    frame_scores,
)
from acs_cli.core.estimation import fit_variance_components
from acs_cli.core.joint import (
    MIN_ROTATION_SPREAD,
    MotionSummary,
    articulation_motion,
    lever_shapes,
    near_hinge_warning,
)
from acs_cli.core.joints import joint_model
from acs_cli.core.joints.base import (
    SINGLE_AXIS_RATIO,
    geometry_jacobian,
    single_axis,
    tangent_basis,
)
from acs_cli.core.joints.base import unit as _unit
from acs_cli.core.quality import JOINT_STD, OVERRIDE_HINT
from acs_cli.core.rig import RigJoint, RigTopology
from acs_cli.core.rig_start import ball_similarity, similarity_from_lifted
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

#: An edge whose mean whitened residual power per row is below this fits its poses exactly
#: (a thousandth of the noise floors): rounding, not noise, and no frame is tested as an
#: outlier on it.
EXACT_POWER = 1e-6
#: Fewest frames an edge needs in common (as for a self-calibrated pair).
MIN_EDGE_FRAMES = 14
#: ... or, for a joint whose position is given (a prior): the relative pose alone.
MIN_PRIOR_EDGE_FRAMES = 5
#: A joint is "not determined" when its largest standard deviation exceeds this fraction of
#: its distance from the camera (seen in simulation: about 5% for general motion, 14-30% for
#: a rigid or hinged joint whatever the noise level).
UNDETERMINED_STD_FRACTION = JOINT_STD.refuse
#: ... or, where both its cameras are in one world (Algorithm I; stereo for a rigid edge).
MIN_SHARED_WORLD_FRAMES = 3
#: Largest share of an edge's frames rejected as outliers.
MAX_OUTLIER_FRACTION = 0.3
#: When the reference instant's pose corrections are solved (after the estimate), its
#: constraint rows are weighted this much more than the others: the corrected poses fit the
#: joints (nearly) exactly.
REFERENCE_GAIN = 1e2
#: Noise-level refits (each followed by a solve), at most; they stop when the levels settle
#: (move by less than SETTLED_NOISE, relative): the solution is then the fixed point of the
#: reweighting, whatever the start (a world frame, a reference camera, the order of ``between``).
REWEIGHT_ROUNDS = 12
SETTLED_NOISE = 1e-5
#: The fits of the outlier tests (without the suspects) settle their noise levels to this
#: (relative), in at most this many rounds.
TEST_SETTLED_NOISE = 0.02
TEST_REWEIGHT_ROUNDS = 4
#: The least-squares method of each solve (:func:`acs_cli.core.lsq.solve`).
RIG_METHOD = "normal"
#: Rounds of outlier tests (each followed by a refit), at most.
REJECTION_ROUNDS = 8
#: Normalised information eigenvalue below which a direction is not determined at all.
NULL_EIGENVALUE = 1e-9
#: Noise levels are kept above these (radians, and a share of the rig's length scale): a
#: noiseless recording would otherwise weigh its rows beyond what differences resolve.
NOISE_FLOOR_ROT = 1e-6
NOISE_FLOOR_LENGTH = 1e-6
#: A joint's point given without a covariance has this std per axis, as a share of the rig's
#: travel (the reference camera's RMS distance from its mean position).
PRIOR_STD_OF_TRAVEL = 1e-4


@dataclass(frozen=True)
class CameraTrack:
    """One camera's poses on the rig's common timeline.

    Attributes
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        ``T_world_cam`` in the camera's own world and units; rows where ``valid`` is False
        are ignored (fill them with the identity).
    valid : ndarray of bool, shape (n,)
    unknown_scale : bool
        The trajectory's translations carry an unknown factor (monocular SLAM).
    """

    T_w_c: FloatArray
    valid: np.ndarray
    unknown_scale: bool = False


@dataclass(frozen=True)
class Recordings:
    """Which recording each instant of the rig's timeline belongs to.

    Attributes
    ----------
    names : tuple of str
        The recordings' names (config keys).
    of_frame : ndarray of int, shape (n,)
        The recording (index into ``names``) of each instant.
    shared_world : tuple of bool
        Per recording: every body's poses are in one world (no world-to-world transform
        between them is estimated).
    """

    names: tuple[str, ...]
    of_frame: np.ndarray
    shared_world: tuple[bool, ...]
    #: per recording: the joints held still in it (fixed-joint motion: they enter the solve
    #: as priors from Algorithm II, and the recording adds no rows to them)
    held: tuple[tuple[str, ...], ...] = ()

    @staticmethod
    def single(n: int, shared_world: bool = False, name: str = "default") -> Recordings:
        """One recording of ``n`` instants."""
        return Recordings((name,), np.zeros(n, int), (shared_world,))

    def holds(self, joint: str, frames: np.ndarray) -> np.ndarray:
        """``(m,)`` bool: which of ``frames`` belong to a recording that holds ``joint``."""
        if not self.held:
            return np.zeros(frames.size, bool)
        by_rec = np.array([joint in h for h in self.held], bool)
        return by_rec[self.of_frame[frames]]


@dataclass(frozen=True)
class WorldEstimate:
    """One world of one recording (a camera's own, or the recording's shared one).

    ``T_ref_world`` ``(4, 4)`` maps the world (its translations multiplied by ``scale``) into
    the reference world, with the covariance ``(6, 6)`` of (right rotation perturbation
    (rad), translation (reference units)); ``tied`` is False for a world that no edge ties to
    the reference's (its transform is then the identity by choice, not estimated).
    """

    recording: str
    cameras: tuple[str, ...]
    shared: bool
    T_ref_world: FloatArray
    covariance: FloatArray
    scale: float = 1.0
    scale_std: float | None = None
    tied: bool = True

    @property
    def label(self) -> str:
        """``recording`` for a shared world, ``recording/camera`` for a camera's own."""
        return self.recording if self.shared else f"{self.recording}/{self.cameras[0]}"


@dataclass(frozen=True)
class EdgePrior:
    """A joint known beforehand (a fixed-joint session's result, or a measurement), in
    reference units and each camera's frame.

    Attributes
    ----------
    position_in, covariance_in : dict of camera to ndarray (3,) and (3, 3)
        The joint's point (a ball's centre; a hinge's point nearest the edge's first camera).
    line_in : dict of camera to (point (3,), direction (3,), std)
        A hinge's axis line in a camera (from a fixed-joint recording of the hinge): the
        joint's point lies on it, ``std`` (reference units) across it.
    axis_in : dict of camera to (direction (3,), std_rad)
        A hinge's axis direction (either sign).
    units : {"reference", "own", "metre"}
        The unit of ``position_in``, ``covariance_in`` and ``line_in``: the reference
        camera's (default), each camera's own trajectory units (a fixed-joint session of a
        camera of unknown scale), or metres while the reference's scale is unknown (then the
        reference's units per metre are estimated too, ``CameraEstimate.units_per_metre``).
    """

    position_in: dict[str, FloatArray] = field(default_factory=dict)
    covariance_in: dict[str, FloatArray] = field(default_factory=dict)
    line_in: dict[str, tuple[FloatArray, FloatArray, float]] = field(default_factory=dict)
    axis_in: dict[str, tuple[FloatArray, float]] = field(default_factory=dict)
    units: str = "reference"


def fixed_joint_prior(joint: RigJoint, camera: str, T_w_c: FloatArray, label: str) -> EdgePrior:
    """A joint held still while ``camera`` turned about it (the paper's Algorithm II), as a
    prior of the rig solve.

    Parameters
    ----------
    joint : RigJoint
        A ball (its centre, :func:`~acs_cli.core.joint.estimate_pivot`) or a hinge (its axis
        and line, :func:`~acs_cli.core.joint.estimate_hinge_fixed`; the point itself when
        ``camera`` is the edge's first, whose nearest axis point the rig reports).
    camera : str
    T_w_c : ndarray, shape (n, 4, 4)
        ``T_world_cam`` of the fixed-joint motion (metres, the reference's units).
    label : str
        Names the session in messages.

    Raises
    ------
    InputError
        A joint type without a point (rigid: nothing to hold still).
    DegenerateMotionError
        Too little rotation about the joint.
    """
    parts = joint_model(joint.type).fixed_joint_prior(joint, camera, T_w_c, label)
    return EdgePrior(
        position_in=parts.get("position_in", {}),
        covariance_in=parts.get("covariance_in", {}),
        line_in=parts.get("line_in", {}),
        axis_in=parts.get("axis_in", {}),
    )


def edge_prior_rows(
    topology: RigTopology, priors: dict[str, EdgePrior], travel: float
) -> list[tuple[str, int, FloatArray, FloatArray, str]]:
    """The rows of joints known beforehand: ``W (g[at : at + 3] - value)`` on each joint's
    geometry ``g`` (:meth:`~acs_cli.core.joints.base.JointModel.geometry`'s order: the points
    ``o_p``, ``o_q``, then a hinge's axes ``u_p``, ``u_q``), in each prior's units.

    Parameters
    ----------
    topology : RigTopology
    priors : dict of EdgePrior
        By joint name.
    travel : float
        The rig's length scale (the reference camera's RMS distance from its mean position,
        reference units): a point given without a covariance has the std
        :data:`PRIOR_STD_OF_TRAVEL` times it (at least times 1 mm).

    Returns
    -------
    list of (joint, at, value (3,), W (k, 3), camera)
        A point gives 3 rows (``at = 3 side``, ``W`` its covariance's inverse Cholesky
        factor); a hinge's line 2 (across it: its point at ``3 side``, ``W`` the basis
        across its direction over its std); its axis 2 (across the direction, either sign:
        ``at = 6 + 3 side``, over its std in radians).

    Raises
    ------
    InputError
        Unknown units, a joint without a point (rigid), an axis on a joint that is not a
        hinge, a camera not on the joint, a covariance that is not positive definite.
    """
    out: list[tuple[str, int, FloatArray, FloatArray, str]] = []
    for name, pr in priors.items():
        if pr.units not in ("reference", "own", "metre"):
            raise InputError(f"joints.{name}: unknown prior units {pr.units!r}")
        j = topology.joint(name)
        model = joint_model(j.type)
        if not model.has_point:
            raise InputError(f"joints.{name}: a {j.type} joint has no position to give")
        if (pr.line_in or pr.axis_in) and not model.has_axis:
            raise InputError(f"joints.{name}: an axis is given but the joint is a {j.type}")
        for c in [*pr.line_in, *pr.axis_in]:
            if c not in j.between:
                raise InputError(f"joints.{name}: {c} is not on this joint")
        for c, (point, direction, std) in pr.line_in.items():
            B = tangent_basis(_unit(np.asarray(direction, float)))
            out.append((name, 3 * j.between.index(c), np.asarray(point, float), B.T / std, c))
        for c, (direction, std_rad) in pr.axis_in.items():
            given = _unit(np.asarray(direction, float))
            side = j.between.index(c)
            out.append((name, 6 + 3 * side, given, tangent_basis(given).T / std_rad, c))
        for c, pos in pr.position_in.items():
            if c not in j.between:
                raise InputError(f"joints.{name}.position_in.{c}: {c} is not on this joint")
            C = pr.covariance_in.get(c)
            if C is None:
                C = np.eye(3) * (PRIOR_STD_OF_TRAVEL * max(travel, 1e-3)) ** 2
            try:
                Wh = np.linalg.inv(np.linalg.cholesky(np.asarray(C, float)))
            except np.linalg.LinAlgError:
                raise InputError(
                    f"joints.{name}: the covariance given for {c} is not positive definite"
                ) from None
            out.append((name, 3 * j.between.index(c), np.asarray(pos, float), Wh, c))
    return out


def merge_priors(first: EdgePrior, second: EdgePrior) -> EdgePrior:
    """Both priors of one joint; where both give the same part, ``first``'s."""
    if first.units != second.units and (second.position_in or second.line_in):
        raise InputError(
            "two priors of one joint in different units (a fixed-joint recording and the "
            "config's joints section): give one of them"
        )
    return EdgePrior(
        position_in={**second.position_in, **first.position_in},
        covariance_in={**second.covariance_in, **first.covariance_in},
        line_in={**second.line_in, **first.line_in},
        axis_in={**second.axis_in, **first.axis_in},
        units=first.units,
    )


def held_priors(
    topology: RigTopology, tracks: dict[str, CameraTrack], recs: Recordings
) -> dict[str, EdgePrior]:
    """The priors of the joints that recordings hold still: each camera of such a joint that
    the recording saw gives it by Algorithm II (:func:`fixed_joint_prior`)."""
    out: dict[str, EdgePrior] = {}
    for r, held in enumerate(recs.held):
        for name in held:
            j = topology.joint(name)
            for c in j.between:
                f = (recs.of_frame == r) & tracks[c].valid
                if not f.any():
                    continue
                if tracks[c].unknown_scale or tracks[topology.reference].unknown_scale:
                    raise InputError(
                        f"recordings.{recs.names[r]}.fixed_joints ({name}, camera {c}): a "
                        f"fixed-joint motion gives metres; it needs {c} and the reference "
                        "camera to be metric"
                    )
                label = f"recordings.{recs.names[r]}.fixed_joints ({name}, camera {c})"
                p = fixed_joint_prior(j, c, tracks[c].T_w_c[f], label)
                out[name] = merge_priors(out[name], p) if name in out else p
    return out


@dataclass(frozen=True)
class CameraEstimate:
    """``T_cam_ref`` ``(4, 4)`` with the covariance ``(6, 6)`` of (right rotation
    perturbation (rad), translation (ref units)); scale (ref units per own unit).

    ``T_cam_ref`` is None for a camera with no pose at the reference instant (a body seen
    only in another recording): its joints are calibrated, its pose then is not defined."""

    T_cam_ref: FloatArray | None
    covariance: FloatArray
    scale: float = 1.0
    scale_std: float | None = None
    #: the camera's trajectory in the reference world and units: ``(n, 4, 4)`` ``G_c[i]``
    #: (identity rows where the camera has no pose), with the reference instant corrected
    poses_in_reference_world: FloatArray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    #: ``X``'s rotation and translation ``(4, 4)`` of the camera's world at the reference
    #: instant (scaled by ``scale``) into the reference world:
    #: ``G_c = [R_X R_c, scale R_X t_c + t_X]``
    world_to_reference_world: FloatArray = field(default_factory=lambda: np.eye(4))
    #: ``(n,)`` bool: the instants whose ``poses_in_reference_world`` are in the reference
    #: world (a pose there, in a world tied to the reference's); empty: wherever it has one
    in_reference_world: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: the camera's own trajectory units per metre, where a metric prior let them be
    #: estimated (a rig of unknown scale), with its std; None elsewhere
    units_per_metre: float | None = None
    units_per_metre_std: float | None = None
    #: its poses' rotation noise per axis (deg) as the solve fitted it from the rotation rows
    #: of its joints (a hinge's axis, a rigid pair's rotation), else from its ball joints'
    #: point fits (as the two-camera commands do); NaN where those hit the noise floor
    sigma_rot_deg: float = float("nan")

    @property
    def rotation_std_deg(self) -> FloatArray:
        return np.degrees(np.sqrt(np.maximum(np.diag(self.covariance)[:3], 0.0)))

    @property
    def translation_std(self) -> FloatArray:
        return np.sqrt(np.maximum(np.diag(self.covariance)[3:], 0.0))


@dataclass(frozen=True)
class EdgeEstimate:
    """One edge's result; positions and axes in reference units, in each camera's frame."""

    joint: RigJoint
    position_in: dict[str, FloatArray]
    position_cov_in: dict[str, FloatArray]
    axis_in: dict[str, FloatArray]
    axis_std_deg_in: dict[str, float]
    T_q_p: FloatArray
    residual_rms: float
    frames_used: int
    frames_rejected: int
    inliers: np.ndarray
    noise: dict[str, float]
    #: the raw constraint residuals over the inlier frames, by kind (``pos``, ``rot``,
    #: ``trans``: ``(m, 3)`` each, see ``_edge_blocks``)
    residual_blocks: dict[str, FloatArray] = field(default_factory=dict)
    #: every frame of the edge (indices into the rig's timeline, the rejected ones too) and
    #: the raw residuals at each of them by kind, ``(len(frames), 3)`` each: the joint's
    #: residual over time (``inliers`` says which frames were used)
    frames: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    frame_residuals: dict[str, FloatArray] = field(default_factory=dict)
    #: ``position_in`` and ``position_cov_in`` in each camera's own trajectory units (they
    #: differ from the reference's under unknown scale): camera -> (position, covariance)
    position_own_in: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    #: ``position_cov_in`` under independent noise, before the growth for correlated errors
    #: (:mod:`acs_cli.core.correlated`): what the motion's geometry determines, for the tests
    #: of degenerate motion; empty when nothing grew
    position_cov_model_in: dict[str, FloatArray] = field(default_factory=dict)
    #: a ball's or hinge's geometry as solved, ``(o_p, o_q[, u_p, u_q])`` concatenated
    #: ((6,) or (12,), reference units; the default point, the axes with the solve's sign:
    #: ``position_in`` and ``axis_in`` may be moved or turned round after the solve), and its
    #: whole covariance: the cross-covariances a quantity of several parts needs (a hinge's
    #: point moved along its axis, :func:`acs_cli.core.rig.hinge_point_from_nearest`);
    #: empty where not known
    geometry: FloatArray = field(default_factory=lambda: np.zeros(0))
    geometry_covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))

    def motion_cov_in(self, c: str) -> FloatArray:
        """``position_cov_model_in[c]`` when the covariance grew, else ``position_cov_in[c]``."""
        return self.position_cov_model_in.get(c, self.position_cov_in[c])


@dataclass(frozen=True)
class RigEstimate:
    """The calibrated rig (see :func:`estimate_rig`)."""

    topology: RigTopology
    reference_frame: int
    cameras: dict[str, CameraEstimate]
    edges: dict[str, EdgeEstimate]
    cost: float
    iterations: int
    #: joints that fit their declared type poorly but not past refusal
    #: (:func:`check_joint_types`); the test for correlated errors speaks through
    #: ``correlated``, the stds through the verdict
    warnings: list[str] = field(default_factory=list)
    recordings: Recordings | None = None
    #: every world of every recording (see :class:`WorldEstimate`)
    worlds: list[WorldEstimate] = field(default_factory=list)
    #: the instants (indices into the timeline, sorted) whose ``poses_in_reference_world``
    #: are a bundle adjustment's per-frame fit on the corners
    #: (:func:`acs_cli.core.rig_bundle.bundle_adjust_rig`) rather than measured poses mapped
    #: into the reference world; empty for the pose-based solve
    bundle_frames: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    #: what the test for errors correlated over time found (:mod:`acs_cli.core.correlated`)
    correlated: CorrelatedErrors = NOT_TESTED


# --------------------------------------------------------------------------- layout


class _Layout:
    """Where each unknown lives in the parameter vector.

    Worlds (see :class:`Recordings`) are numbered ``0 .. W-1``; a world tied to the
    reference world's group has a rotation and translation unless it is that group's first
    world; a world of unknown scale has its own log-scale, and when the reference world's
    scale is unknown, every metric world shares one log-scale.
    """

    def __init__(
        self,
        topo: RigTopology,
        n_worlds: int,
        root: np.ndarray,
        unknown_scale: np.ndarray,
        ref_world: int,
        with_delta: list[str],
        metre: bool = False,
    ):
        ref_unknown = bool(unknown_scale[ref_world])
        k = 0
        self.rot: dict[int, slice] = {}
        self.trans: dict[int, slice] = {}
        self.logs: dict[int, int] = {}
        shared: int | None = None  # metric worlds share one scale to an unknown reference
        for w in range(n_worlds):
            if root[w] != w:
                self.rot[w], self.trans[w] = slice(k, k + 3), slice(k + 3, k + 6)
                k += 6
            if w == ref_world:
                continue
            if unknown_scale[w]:
                self.logs[w] = k
                k += 1
            elif ref_unknown:
                if shared is None:
                    shared = k
                    k += 1
                self.logs[w] = shared
        # the reference's units per metre, for a metric prior when the reference has none
        self.metre: int | None = None
        if metre and ref_unknown:
            if shared is None:
                shared = k
                k += 1
            self.metre = shared
        # each joint's unknowns, as its type's model lays them out (JointModel.geometry)
        self.edge: dict[str, slice] = {}
        for j in topo.joints:
            size = joint_model(j.type).n_params
            self.edge[j.name] = slice(k, k + size)
            k += size
        # the reference instant's poses, of the cameras that have one there
        self.delta: dict[str, slice] = {}
        for c in with_delta:
            self.delta[c] = slice(k, k + 6)
            k += 6
        self.size = k

    def world_columns(self, w: int) -> list[int]:
        cols: list[int] = []
        if w in self.rot:
            cols += list(range(self.rot[w].start, self.rot[w].stop))
            cols += list(range(self.trans[w].start, self.trans[w].stop))
        if w in self.logs:
            cols.append(self.logs[w])
        return cols

    def camera_columns(self, c: str, worlds: Iterable[int]) -> list[int]:
        """The columns of camera ``c``'s reference-instant pose and of ``worlds``."""
        cols = list(range(self.delta[c].start, self.delta[c].stop)) if c in self.delta else []
        for w in worlds:
            cols += self.world_columns(int(w))
        return sorted(set(cols))

    def edge_columns(self, name: str) -> list[int]:
        return list(range(self.size))[self.edge[name]]


@dataclass
class _State:
    """Everything the residual function needs besides ``x``."""

    topo: RigTopology
    L: _Layout
    R: dict[str, FloatArray]
    t: dict[str, FloatArray]
    widx: dict[str, np.ndarray]  # per camera: (n,) its world at each instant
    R0X: FloatArray  # (W, 3, 3) starting rotation of each world's similarity
    anchor: dict[str, Any]  # per edge: its model's fixed data (JointModel.start)
    ref_frame: int
    frames: dict[str, np.ndarray]  # per edge: frame indices where both cameras are valid
    mask: dict[str, np.ndarray]  # per edge: inlier mask over its frames
    gain: dict[str, np.ndarray]  # per edge: row gain over its frames (REFERENCE_GAIN at k)
    whiten_pos: dict[str, FloatArray]  # per edge: (m, 3, 3) inverse Cholesky factors
    w_rot: dict[str, float]  # per edge: 1 / sigma of axis or rigid-rotation rows
    w_trans: dict[str, float]  # per edge: 1 / sigma of rigid-translation rows
    w_delta: dict[str, FloatArray]  # per camera: (6,) 1 / sigma of reference-pose priors
    # prior rows W (g[at:at+3] / f - value) on a joint's geometry g = (o_p, o_q, u_p, u_q),
    # f = exp(x[col]) converting reference units to the prior's (1 where col is None)
    priors: list[tuple[str, int, FloatArray, FloatArray, int | None]]  # (joint, at, value, W, col)
    length: float = 1.0  # the rig's length scale (reference units), for noise floors
    # unknowns the estimate fits (the reference instant's corrections held apart): the
    # degrees of freedom the noise levels are corrected for
    n_free: int = 0
    # the edges' residual frames (:func:`_edge_frame`), anchored with each refit of the
    # weights: per world, its rotation unknowns, the map of their increments to the world's
    # rotation increment in the reference world (``R_X Jr(w)``), and its log-scale
    frame_w: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    frame_A: FloatArray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    frame_l: FloatArray = field(default_factory=lambda: np.zeros(0))
    # per camera: its poses' rotation noise per axis (rad) from the rotation rows of its
    # joints (a hinge's axis, a rigid pair's rotation), else its ball joints' point fits
    # above the noise floor; NaN elsewhere
    sigma_rot: dict[str, float] = field(default_factory=dict)

    def frames_of(self, c: str) -> np.ndarray:
        """``(n,)`` bool: the instants where camera ``c`` is on an edge."""
        out = np.zeros(self.widx[c].size, bool)
        for j in self.topo.edges_of(c):
            out[self.frames[j.name]] = True
        return out


@dataclass(frozen=True)
class _Worlds:
    """Every world's similarity at one ``x``: rotations ``(W, 3, 3)``, translations
    ``(W, 3)``, scales ``(W,)`` and the right Jacobians ``(W, 3, 3)`` of the rotations'
    increments (zero for a world without rotation unknowns)."""

    R: FloatArray
    t: FloatArray
    s: FloatArray
    Jw: FloatArray


def _worlds(st: _State, x: FloatArray) -> _Worlds:
    L = st.L
    W = st.R0X.shape[0]
    R = st.R0X.copy()
    t = np.zeros((W, 3))
    s = np.ones(W)
    Jw = np.zeros((W, 3, 3))
    if L.rot:
        ws = np.fromiter(L.rot, int)
        w = np.stack([x[L.rot[i]] for i in ws])
        R[ws] = np.matmul(st.R0X[ws], se3.matrix_from_rotvec(w))
        t[ws] = np.stack([x[L.trans[i]] for i in ws])
        Jw[ws] = right_jacobians(w)
    for i, col in L.logs.items():
        s[i] = np.exp(x[col])
    return _Worlds(R, t, s, Jw)


def _measured(st: _State, x: FloatArray, c: str) -> tuple[FloatArray, FloatArray]:
    """Camera ``c``'s measured rotations and translations, the reference instant's
    corrected by its unknown."""
    R, t = st.R[c], st.t[c]
    if c not in st.L.delta:
        return R, t
    d = x[st.L.delta[c]]
    k = st.ref_frame
    R = R.copy()
    t = t.copy()
    R[k] = R[k] @ se3.matrix_from_rotvec(d[:3])
    t[k] = t[k] + d[3:]
    return R, t


def _poses(
    st: _State, x: FloatArray, c: str, W: _Worlds | None = None
) -> tuple[FloatArray, FloatArray]:
    """``G_c`` for every frame: rotations ``(n, 3, 3)`` and translations ``(n, 3)``."""
    W = W if W is not None else _worlds(st, x)
    R, t = _measured(st, x, c)
    wi = st.widx[c]
    RX = W.R[wi]
    return np.matmul(RX, R), W.s[wi, None] * np.einsum("nij,nj->ni", RX, t) + W.t[wi]


def _all_poses(
    st: _State, x: FloatArray, W: _Worlds | None = None
) -> dict[str, tuple[FloatArray, FloatArray]]:
    W = W if W is not None else _worlds(st, x)
    return {c: _poses(st, x, c, W) for c in st.topo.cameras}


def joint_geometry(
    st: _State, x: FloatArray, j: RigJoint
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    """``o_p, o_q`` (reference units) and, for a type with an axis, the unit axes
    ``u_p, u_q``: :meth:`~acs_cli.core.joints.base.JointModel.geometry` of the joint's
    type at ``x``."""
    return joint_model(j.type).geometry(x[st.L.edge[j.name]], st.anchor[j.name])


def residual_geometry(
    st: _State, x: FloatArray, j: RigJoint
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    """:func:`joint_geometry` as the constraints use it
    (:meth:`~acs_cli.core.joints.base.JointModel.residual_geometry`: a hinge's point moved
    along its axis to the one nearest both cameras' centres together)."""
    return joint_model(j.type).residual_geometry(x[st.L.edge[j.name]], st.anchor[j.name])


def _edge_blocks(st: _State, x: FloatArray, j: RigJoint, G: dict) -> dict[str, FloatArray]:
    """Raw (unwhitened) residuals of one edge over its frames by kind, ``(m, 3)`` each:
    ``pos`` (a point), ``rot`` (an axis or a rigid rotation), ``trans`` (a rigid
    translation), as its type's model gives them
    (:meth:`~acs_cli.core.joints.base.JointModel.residual_blocks`)."""
    p, q = j.between
    f = st.frames[j.name]
    Rp, tp = G[p][0][f], G[p][1][f]
    Rq, tq = G[q][0][f], G[q][1][f]
    model = joint_model(j.type)
    return model.residual_blocks(x[st.L.edge[j.name]], st.anchor[j.name], Rp, tp, Rq, tq)


def _anchor_frames(st: _State, x: FloatArray) -> None:
    """Anchor the edges' residual frames (:func:`_edge_frame`) at ``x``, where the weights
    are fitted: there every edge's frame is the reference world and units."""
    W = _worlds(st, x)
    n = st.R0X.shape[0]
    st.frame_w, st.frame_A, st.frame_l = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros(n)
    for w, sl in st.L.rot.items():
        st.frame_w[w], st.frame_A[w] = x[sl], W.R[w] @ W.Jw[w]
    for w, col in st.L.logs.items():
        st.frame_l[w] = x[col]


def _frame_motion(st: _State, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Every world's rotation (a rotation vector in the reference world, ``(W, 3)``, to first
    order) and log-scale ``(W,)`` since the frames were anchored (:func:`_anchor_frames`)."""
    b, dl = np.zeros_like(st.frame_w), np.zeros_like(st.frame_l)
    for w, sl in st.L.rot.items():
        b[w] = st.frame_A[w] @ (x[sl] - st.frame_w[w])
    for w, col in st.L.logs.items():
        dl[w] = x[col] - st.frame_l[w]
    return b, dl


def _edge_frame(
    st: _State, j: RigJoint, motion: tuple[FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The frame and units edge ``j``'s point and translation rows are whitened in, per frame
    of the edge: ``f F^T`` ``(m, 3, 3)``, ``f`` ``(m,)`` and ``c`` ``(m, 3)`` with
    ``F = Exp(c)``: turned by half of each of its two cameras' worlds' rotations since the
    weights were fitted (``c``), scaled by the geometric mean of their scales' changes
    (``f``). Held in the reference world, the weights (anisotropic: the lever arms) would turn
    with the reference camera's world alone, and which camera is the reference would move the
    estimate; in this frame it does not, nor does the order of ``between``."""
    p, q = j.between
    f = st.frames[j.name]
    b, dl = motion
    wp, wq = st.widx[p][f], st.widx[q][f]
    c = 0.5 * (b[wp] + b[wq])
    s = np.exp(-0.5 * (dl[wp] + dl[wq]))
    return s[:, None, None] * se3.matrix_from_rotvec(-c), s, c


def _residuals(st: _State, x: FloatArray) -> FloatArray:
    G = _all_poses(st, x)
    motion = _frame_motion(st, x)
    parts: list[FloatArray] = []
    for j in st.topo.joints:
        m = (st.mask[j.name] * st.gain[j.name])[:, None]
        b = _edge_blocks(st, x, j, G)
        Ft, s, _ = _edge_frame(st, j, motion)
        if "pos" in b:
            w = np.matmul(st.whiten_pos[j.name] @ Ft, b["pos"][:, :, None])[:, :, 0]
            parts.append((w * m).ravel())
        if "rot" in b:
            parts.append((b["rot"] * st.w_rot[j.name] * m).ravel())
        if "trans" in b:
            parts.append((b["trans"] * (st.w_trans[j.name] * s)[:, None] * m).ravel())
    for c in st.L.delta:
        parts.append(x[st.L.delta[c]] * st.w_delta[c])
    for name, at, value, W, col in st.priors:
        g = joint_geometry(st, x, st.topo.joint(name))[at // 3]
        if g is None:  # estimate_rig refuses such priors; this guards other callers
            raise InputError(f"joints.{name}: a prior on an axis the joint does not have")
        f = 1.0 if col is None else float(np.exp(x[col]))
        parts.append(W @ (g / f - value))
    return np.concatenate(parts)


def _geometry_jacobian(
    st: _State, x: FloatArray, j: RigJoint, for_residuals: bool = False
) -> FloatArray:
    """``(12, k)``: derivatives of ``(o_p, o_q, u_p, u_q)`` by the edge's ``k`` unknowns.

    Central differences of :func:`joint_geometry` (a few vector operations, no frames).
    """
    e = x[st.L.edge[j.name]]
    return geometry_jacobian(joint_model(j.type), e, st.anchor[j.name], for_residuals)


class _EdgeJacobian:
    """One edge's part of :func:`_jacobian`, handed to its joint type's model
    (:class:`~acs_cli.core.joints.base.EdgeJacobian`): the edge's poses and weights, and
    where its rows go (3 a frame per residual kind, from ``row0``)."""

    def __init__(
        self,
        st: _State,
        x: FloatArray,
        j: RigJoint,
        W: _Worlds,
        meas: dict[str, tuple[FloatArray, FloatArray]],
        Jd: dict[str, FloatArray],
        wk: dict[str, int],
        out: tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]],
        row0: int,
        frame: tuple[FloatArray, FloatArray, FloatArray],
    ) -> None:
        L, k = st.L, st.ref_frame
        self.st, self.L, self.W, self.meas, self.Jd, self.wk, self.k = st, L, W, meas, Jd, wk, k
        self.rows_i, self.cols_i, self.vals = out
        self.row0 = row0
        p, q = self.p, self.q = j.between
        f = self.f = st.frames[j.name]
        self.m = f.size
        self.e = x[L.edge[j.name]]
        self.anchor = st.anchor[j.name]
        self.mask = (st.mask[j.name] * st.gain[j.name])[:, None, None]
        self.kk = np.flatnonzero(f == k)  # the reference instant's row in this edge, if any
        self.ecols = L.edge_columns(j.name)
        self.Rp, self.Rq = meas[p][0][f], meas[q][0][f]
        self.RGp = np.matmul(W.R[st.widx[p][f]], self.Rp)
        self.RGq = np.matmul(W.R[st.widx[q][f]], self.Rq)
        self.sp_tp = W.s[st.widx[p][f], None] * meas[p][1][f]
        self.sq_tq = W.s[st.widx[q][f], None] * meas[q][1][f]
        # the weights in the edge's frame (_edge_frame)
        self.whiten_pos: FloatArray = st.whiten_pos[j.name] @ frame[0]
        self.w_rot = st.w_rot[j.name]
        self.w_trans = st.w_trans[j.name] * frame[1][:, None, None]

    def put(
        self, block: FloatArray, cols: list[int] | None = None, at: np.ndarray | None = None
    ) -> None:
        # block (m, 3, len(cols)) for rows row0 + 3 at[i] + a (at: 0..m-1 by default)
        cols = self.ecols if cols is None else cols
        m = block.shape[0]
        at = np.arange(m) if at is None else at
        r = (self.row0 + 3 * at[:, None] + np.arange(3)).reshape(-1)
        self.rows_i.append(np.repeat(r, len(cols)))
        self.cols_i.append(np.tile(np.asarray(cols), 3 * m))
        self.vals.append(block.reshape(-1))

    def by_world(self, c: str) -> list[tuple[np.ndarray, int]]:
        """The edge's frames of camera ``c`` grouped by world: (positions, world)."""
        wi = self.st.widx[c][self.f]
        return [(np.flatnonzero(wi == w), int(w)) for w in np.unique(wi)]

    def cam_block(
        self, c: str, y: FloatArray, sign: float, with_t: bool, weight: FloatArray
    ) -> None:
        """Put the derivatives of ``sign * (R_X y + [s R_X t + t_X])`` by the similarity of
        ``c``'s world at each frame, whitened by ``weight`` ``(m, 3, 3)`` or ``(m, 1, 1)``."""
        L, W = self.L, self.W
        for at, w in self.by_world(c):
            RX = W.R[w]
            blocks, cols = [], []
            if w in L.rot:
                # d(R_X Exp(dw) y) = -R_X [y]x Jr(w) dw
                blocks.append(-sign * np.matmul(se3.left_multiply(RX, se3.skew(y[at])), W.Jw[w]))
                cols += list(range(L.rot[w].start, L.rot[w].stop))
                if with_t:
                    blocks.append(sign * np.broadcast_to(np.eye(3), (at.size, 3, 3)))
                    cols += list(range(L.trans[w].start, L.trans[w].stop))
            if w in L.logs and with_t:
                tf = self.meas[c][1][self.f[at]]
                blocks.append(sign * (W.s[w] * tf @ RX.T)[:, :, None])
                cols.append(L.logs[w])
            if blocks:
                self.put(np.matmul(weight[at], np.concatenate(blocks, axis=2)), cols, at)

    def delta_block(self, c: str, i: int, D: FloatArray, first: int, last: int) -> None:
        """Put ``D`` ``(3, last - first)`` for the reference instant's row ``i`` of ``c``."""
        if c in self.L.delta:
            cols = list(range(self.L.delta[c].start + first, self.L.delta[c].start + last))
            self.put(D[None], cols, np.array([i]))

    def next_block(self) -> None:
        self.row0 += 3 * self.m


def _frame_jacobian(
    st: _State,
    j: RigJoint,
    frame: tuple[FloatArray, FloatArray, FloatArray],
    blocks: dict[str, FloatArray],
    row0: int,
    put: Callable[..., None],
) -> None:
    """Put the derivatives of edge ``j``'s point and translation rows (from ``row0``) through
    its frame (:func:`_edge_frame`) by its worlds' unknowns: ``d(f F^T r) = f F^T [r]x Jr(-c)
    dc - f F^T r dlog(f)`` with ``dc = (A_p dw_p + A_q dw_q) / 2`` and
    ``dlog(f) = -(dl_p + dl_q) / 2``; ``blocks`` are the raw residuals (:func:`_edge_blocks`)."""
    Ft, s, c = frame
    L, f = st.L, st.frames[j.name]
    gain = (st.mask[j.name] * st.gain[j.name])[:, None, None]
    kinds = joint_model(j.type).residual_kinds
    for kind in ("pos", "trans"):
        if kind not in blocks:
            continue
        r = blocks[kind]
        first = row0 + 3 * f.size * kinds.index(kind)
        D: FloatArray | None = None
        if kind == "pos":
            Wt = gain * (st.whiten_pos[j.name] @ Ft)
            D = 0.5 * Wt @ se3.skew(r) @ right_jacobians(-c)
        else:
            Wt = gain * st.w_trans[j.name] * s[:, None, None] * np.eye(3)
        Wr = -0.5 * Wt @ r[:, :, None]
        for cam in j.between:
            wi = st.widx[cam][f]
            for w in np.unique(wi).tolist():
                at = np.flatnonzero(wi == w)
                if D is not None and w in L.rot:
                    put(D[at] @ st.frame_A[w], list(range(L.rot[w].start, L.rot[w].stop)),
                        first, at)  # fmt: skip
                if w in L.logs:
                    put(Wr[at], [L.logs[w]], first, at)


def _jacobian(st: _State, x: FloatArray) -> csr_matrix:
    """The Jacobian of :func:`_residuals` (analytic; rotations perturbed on the right).

    Each edge's rows come from its joint type's model
    (:meth:`~acs_cli.core.joints.base.JointModel.jacobian`)."""
    L, k = st.L, st.ref_frame
    W = _worlds(st, x)
    meas = {c: _measured(st, x, c) for c in st.topo.cameras}
    Jd = {c: right_jacobians(x[L.delta[c]][None, :3])[0] for c in L.delta}
    rows_i: list[np.ndarray] = []
    cols_i: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    row0 = 0

    def put(
        block: FloatArray, cols: list[int], first_row: int, at: np.ndarray | None = None
    ) -> None:
        # block (m, 3, len(cols)) for rows first_row + 3 at[i] + a (at: 0..m-1 by default)
        m = block.shape[0]
        at = np.arange(m) if at is None else at
        r = (first_row + 3 * at[:, None] + np.arange(3)).reshape(-1)
        rows_i.append(np.repeat(r, len(cols)))
        cols_i.append(np.tile(np.asarray(cols), 3 * m))
        vals.append(block.reshape(-1))

    wk = {c: int(st.widx[c][k]) for c in st.topo.cameras}
    G = _all_poses(st, x, W)
    motion = _frame_motion(st, x)
    for j in st.topo.joints:
        frame = _edge_frame(st, j, motion)
        jc = _EdgeJacobian(st, x, j, W, meas, Jd, wk, (rows_i, cols_i, vals), row0, frame)
        joint_model(j.type).jacobian(jc)
        _frame_jacobian(st, j, frame, _edge_blocks(st, x, j, G), row0, put)
        row0 = jc.row0
    for c in L.delta:
        D = np.diag(st.w_delta[c])  # the correction is its own unknown
        put(D.reshape(2, 3, 6), list(range(L.delta[c].start, L.delta[c].stop)), row0)
        row0 += 6
    for name, g_at, _value, Wp, col in st.priors:
        j = st.topo.joint(name)
        Dg = _geometry_jacobian(st, x, j)
        fp = 1.0 if col is None else float(np.exp(x[col]))
        block = Wp @ Dg[g_at : g_at + 3] / fp
        cols = L.edge_columns(name)
        if col is not None:  # d(g / f) / d log f = -g / f
            g = joint_geometry(st, x, j)[g_at // 3]
            block = np.concatenate([block, (Wp @ (-np.asarray(g) / fp))[:, None]], axis=1)
            cols = [*cols, col]
        rows = block.shape[0]
        r = row0 + np.arange(rows)
        rows_i.append(np.repeat(r, len(cols)))
        cols_i.append(np.tile(np.asarray(cols), rows))
        vals.append(block.reshape(-1))
        row0 += rows
    r = np.concatenate(rows_i)
    cidx = np.concatenate(cols_i)
    v = np.concatenate(vals)
    return csr_matrix(coo_matrix((v, (r, cidx)), shape=(row0, L.size)))


# --------------------------------------------------------------------------- init


def _initial(
    topo: RigTopology,
    tracks: dict[str, CameraTrack],
    frames: dict[str, np.ndarray],
    L: _Layout,
    widx: dict[str, np.ndarray],
    root: np.ndarray,
) -> tuple[FloatArray, FloatArray, dict[str, Any]]:
    """Starting point, in the reference world and units.

    First every world's similarity, outward from the worlds that are their group's frame:
    a world is reached through an edge whose other camera's world is known at the same
    instants, by the pairwise self-calibration (:func:`_edge_start`). Then each edge's
    geometry from every frame, by its type's model (a joint's point by the paper's Algorithm
    I, eq. (13): the worlds now agree; a hinge's axis; a rigid edge's transform); returns
    ``x``, the worlds' starting rotations and each edge's anchor
    (:meth:`~acs_cli.core.joints.base.JointModel.start`)."""
    x = np.zeros(L.size)
    n_worlds = root.size
    X: dict[int, tuple[FloatArray, FloatArray, float]] = {
        int(w): (np.eye(3), np.zeros(3), 1.0) for w in range(n_worlds) if root[w] == w
    }
    R0X = np.broadcast_to(np.eye(3), (n_worlds, 3, 3)).copy()
    anchor: dict[str, Any] = {}
    o_start: dict[str, dict[str, FloatArray]] = {}

    def in_reference(c: str, f: np.ndarray) -> FloatArray:
        T = tracks[c].T_w_c[f]
        wi = widx[c][f]
        RX = np.stack([X[int(w)][0] for w in wi])
        tX = np.stack([X[int(w)][1] for w in wi])
        sX = np.array([X[int(w)][2] for w in wi])
        return se3.transforms_from_rt(
            np.matmul(RX, T[:, :3, :3]), sX[:, None] * np.einsum("nij,nj->ni", RX, T[:, :3, 3]) + tX
        )

    for min_frames in (6, 1):  # the better-supported ties first
        progress = True
        while progress and len(X) < n_worlds:
            progress = False
            for j in topo.joints:
                p, q = j.between
                f = frames[j.name]
                pairs = np.stack([widx[p][f], widx[q][f]], axis=1)
                for wp, wq in np.unique(pairs, axis=0):
                    wp, wq = int(wp), int(wq)
                    if (wp in X) == (wq in X):
                        continue
                    sel = f[(pairs[:, 0] == wp) & (pairs[:, 1] == wq)]
                    if sel.size < min_frames:
                        continue
                    s_cam, t_cam, wt = (p, q, wq) if wp in X else (q, p, wp)
                    Gs = in_reference(s_cam, sel)
                    Tt = tracks[t_cam].T_w_c[sel]
                    # j_t = phi R j_s + t  (target units, target world)
                    R, tt, phi, o_s, o_t = _edge_start(Gs, Tt, j.type)
                    phi = max(phi, 1e-9)
                    sc = 1.0 / phi if wt in L.logs else 1.0
                    X[wt] = (R.T, -R.T @ tt / phi, sc)
                    if joint_model(j.type).pair_start and j.name not in o_start:
                        o_start[j.name] = {s_cam: o_s, t_cam: o_t * sc}
                    progress = True
    for w in range(n_worlds):
        RXw, tXw, sw = X.setdefault(w, (np.eye(3), np.zeros(3), 1.0))
        R0X[w] = RXw
        if w in L.trans:
            x[L.trans[w]] = tXw
        if w in L.logs:
            x[L.logs[w]] = np.log(sw)
    for j in topo.joints:
        p, q = j.between
        f = frames[j.name]
        Gp, Gq = in_reference(p, f), in_reference(q, f)
        Rp, tp, Rq, tq = Gp[:, :3, :3], Gp[:, :3, 3], Gq[:, :3, :3], Gq[:, :3, 3]
        o = o_start.get(j.name)
        point = None if o is None else (o[p], o[q])
        x[L.edge[j.name]], anchor[j.name] = joint_model(j.type).start(Rp, tp, Rq, tq, point)
    return x, R0X, anchor


def _edge_start(
    Gs: FloatArray, Tt: FloatArray, joint_type: str
) -> tuple[FloatArray, FloatArray, float, FloatArray, FloatArray]:
    """One edge's starting similarity and joint: for a joint whose model asks for it (a
    ball), the pairwise fit of :func:`acs_cli.core.rig_start.ball_similarity`, which
    converges from the linear lifted solution where the rig solve may not (a short, narrow
    motion leaves the linear solution far off); otherwise the linear solution."""
    if joint_model(joint_type).pair_start:
        try:
            return ball_similarity(Gs, Tt)
        except DegenerateMotionError:
            pass
    return similarity_from_lifted(Gs, Tt, None)


# --------------------------------------------------------------------------- weights


def _chol_whiteners(S: FloatArray) -> FloatArray:
    """``W_i`` ``(m, 3, 3)`` with ``W_i S_i W_i^T = I`` (inverse Cholesky factors)."""
    Lc = np.linalg.cholesky(S + 1e-300 * np.eye(3))
    return np.asarray(np.linalg.inv(Lc))


def _refit_weights(st: _State, x: FloatArray, n_params: int) -> dict[str, dict[str, float]]:
    """Per-edge noise levels from the current residuals; updates the weights in ``st``."""
    _anchor_frames(st, x)  # the weights below are fitted in the reference world at x
    G = _all_poses(st, x)
    noise: dict[str, dict[str, float]] = {}
    cam_rot: dict[str, list[float]] = {c: [] for c in st.topo.cameras}
    # what rotation rows tell (a ball's point fit trades rotation noise for translation
    # noise along the lever arms: used only where nothing else tells it)
    told_rot: dict[str, list[float]] = {c: [] for c in st.topo.cameras}
    cam_trans: dict[str, list[float]] = {c: [] for c in st.topo.cameras}
    share = n_params / max(sum(int(m.sum()) for m in st.mask.values()), 1)
    for j in st.topo.joints:
        p, q = j.between
        f = st.frames[j.name]
        # every frame alike (the reference instant's corrections are held at zero while the
        # noise is fitted: its rows are evidence like any other's)
        m = st.mask[j.name]
        model = joint_model(j.type)
        b = _edge_blocks(st, x, j, G)
        d: dict[str, float] = {}
        if "pos" in b:
            o_p, o_q, _, _ = residual_geometry(st, x, j)
            Lsh = lever_shapes(G[p][0][f], o_p) + lever_shapes(G[q][0][f], o_q)
            th = fit_variance_components(b["pos"][m], Lsh[m], int(np.ceil(share * m.sum())))
            th = np.maximum(th, [(NOISE_FLOOR_LENGTH * st.length) ** 2, NOISE_FLOOR_ROT**2])
            # rotation noise is per camera: the two lever shapes share theta_r
            S = th[1] * Lsh
            S[:, [0, 1, 2], [0, 1, 2]] += th[0]
            st.whiten_pos[j.name] = _chol_whiteners(S)
            d["sigma_trans"] = float(np.sqrt(th[0] / 2.0))
            d["sigma_rot_deg"] = float(np.degrees(np.sqrt(th[1])))
            for c in (p, q):
                if model.point_tells_rotation_noise:  # a hinge's axis rows tell it better
                    cam_rot[c].append(th[1])
                cam_trans[c].append(th[0] / 2.0)
        if "rot" in b:
            dof = model.rotation_dof
            v = max(float(np.mean(np.sum(b["rot"][m] ** 2, axis=1))) / dof, NOISE_FLOOR_ROT**2)
            st.w_rot[j.name] = 1.0 / np.sqrt(v)
            d["sigma_rot_deg"] = float(np.degrees(np.sqrt(v / 2.0)))
            for c in (p, q):
                cam_rot[c].append(v / 2.0)
                told_rot[c].append(v / 2.0)
        if "trans" in b:
            v = max(
                float(np.mean(np.sum(b["trans"][m] ** 2, axis=1))) / 3.0,
                (NOISE_FLOOR_LENGTH * st.length) ** 2,
            )
            st.w_trans[j.name] = 1.0 / np.sqrt(v)
            d["sigma_trans"] = float(np.sqrt(v / 2.0))
            for c in (p, q):
                cam_trans[c].append(v / 2.0)
        noise[j.name] = d
    scales = _worlds(st, x).s
    for c in st.L.delta:
        vr = float(np.mean(cam_rot[c])) if cam_rot[c] else 1e-6
        vt = float(np.mean(cam_trans[c])) if cam_trans[c] else 1e-6
        # translation noise of the measured pose is in the camera's own units
        s = float(scales[st.widx[c][st.ref_frame]])
        st.w_delta[c] = np.array([1 / np.sqrt(vr)] * 3 + [s / np.sqrt(vt)] * 3)
    # a camera in ball joints only: its balls' point fits, as the two-camera commands report
    # them, where above the noise floor (at the floor they tell nothing)
    st.sigma_rot = {
        c: float(np.sqrt(np.mean(told_rot[c] or cam_rot[c])))
        if told_rot[c] or (cam_rot[c] and min(cam_rot[c]) > 1.01 * NOISE_FLOOR_ROT**2)
        else float("nan")
        for c in st.topo.cameras
    }
    return noise


def _edge_rows(st: _State) -> dict[str, np.ndarray]:
    """Per edge, ``(m, d)``: the rows of :func:`_residuals` (and of its Jacobian) of each of
    its frames: 3 for each of its type's residual kinds, in order (the point's, then the
    axis's, for a hinge; the rotation's and the translation's for a rigid edge)."""
    out: dict[str, np.ndarray] = {}
    row0 = 0
    for j in st.topo.joints:
        m = st.frames[j.name].size
        kinds = len(joint_model(j.type).residual_kinds)
        blocks = [row0 + 3 * m * b + 3 * np.arange(m)[:, None] + np.arange(3) for b in range(kinds)]
        out[j.name] = np.concatenate(blocks, axis=1)
        row0 += 3 * m * kinds
    return out


def _reject(st: _State, x: FloatArray) -> int:
    """Drop the frames whose externally studentised residual is beyond the threshold of
    :func:`acs_cli.core.estimation.outlier_threshold` (the test of the two-camera
    estimators, :mod:`acs_cli.core.estimation`'s module doc), edge by edge; returns how many
    were dropped.

    For an edge's frame ``i`` with whitened residual ``e_i`` (dimension ``d``: 3 for a ball,
    5 for a hinge, 6 for a rigid edge) and hat-matrix block ``H_ii = G_i (G^T G)^-1 G_i^T``
    (``G`` the whitened Jacobian of the whole solve), ``T_i = e_i^T (I - H_ii)^-1 e_i`` is its
    leave-one-out prediction error, and ``F_i = (T_i / d) / ((S - T_i) / (nu - d))`` with
    ``S`` the edge's whitened residual power over its ``k`` kept frames and
    ``nu = d k - sum tr(H_ii) - (noise levels - 1)``: Fisher's ``F(d, nu - d)`` under
    Gaussian noise, whatever the number of frames.
    """
    r = _residuals(st, x)
    J = _jacobian(st, x)
    H = np.asarray((J.T @ J).toarray())
    Hinv = np.linalg.pinv(H, rcond=1e-14, hermitian=True)
    rows = _edge_rows(st)
    dropped = 0
    for j in st.topo.joints:
        m = st.mask[j.name]
        n = m.size
        room = int(np.floor(MAX_OUTLIER_FRACTION * n)) - int((~m).sum())
        if room <= 0:
            continue
        idx = rows[j.name]
        d_rows = idx.shape[1]
        e = r[idx]  # (n, d_rows); zero where the frame is dropped
        G = J[idx.ravel()].toarray().reshape(n, d_rows, -1)
        Hii = np.matmul(G @ Hinv, np.swapaxes(G, 1, 2))
        M = np.eye(d_rows) - Hii + 1e-9 * np.eye(d_rows)
        T = np.einsum("ni,ni->n", e, np.linalg.solve(M, e[:, :, None])[:, :, 0])
        dim = joint_model(j.type).outlier_dim
        n_noise = joint_model(j.type).noise_levels
        k = int(m.sum())
        p_eff = float(np.trace(Hii[m], axis1=1, axis2=2).sum())
        nu = dim * k - p_eff - (n_noise - 1)
        S = float(np.sum(e[m] ** 2))
        if nu - dim < estimation.MIN_TEST_DOF or not S > EXACT_POWER * dim * k:
            continue
        stat = T / dim / (np.maximum(S - T, 1e-12 * S) / (nu - dim))
        thr = estimation.outlier_threshold(n, nu - dim, dim, shape=estimation.tail_shape(T[m], dim))
        # the reference instant is never dropped: its poses are corrected to fit
        testable = m & (st.frames[j.name] != st.ref_frame)
        bad = np.flatnonzero(testable & (stat > thr))
        if bad.size:
            bad = bad[np.argsort(stat[bad])[::-1][:room]]
            m[bad] = False
            dropped += bad.size
    return dropped


def _fit_without(
    st: _State,
    x: FloatArray,
    left: dict[str, np.ndarray],
    solve: Callable[[FloatArray], FloatArray],
) -> tuple[FloatArray, dict[str, tuple[FloatArray, FloatArray, FloatArray, float, float]]]:
    """The rig solved without the frames ``left`` (per edge; noise levels refitted), and per
    edge of ``left``: the whitened residuals ``e`` ``(n, d)`` of every frame at that fit,
    their Jacobian rows ``G`` ``(n, d, p)``, the inverse information of the kept rows, the
    kept frames' residual power ``S`` and its degrees of freedom ``nu``. The frames stay
    out of the masks."""
    for name, f in left.items():
        st.mask[name][f] = False
    # a test's fit: its noise levels to 2% (the statistic's own sampling error is larger)
    x_loo, _ = _settle(st, x, solve, TEST_SETTLED_NOISE, TEST_REWEIGHT_ROUNDS)
    rows = _edge_rows(st)
    for name, f in left.items():  # their residuals (a masked row is zero)
        st.mask[name][f] = True
    r, J = _residuals(st, x_loo), _jacobian(st, x_loo)
    keep_rows = np.ones(r.size)
    for name, f in left.items():
        st.mask[name][f] = False
        keep_rows[rows[name][f].ravel()] = 0.0
    Jk = J.multiply(keep_rows[:, None]).tocsr()
    Hinv = np.linalg.pinv(np.asarray((Jk.T @ Jk).toarray()), rcond=1e-14, hermitian=True)
    out = {}
    for name in left:
        m, idx = st.mask[name], rows[name]
        e = r[idx]
        G = J[idx.ravel()].toarray().reshape(m.size, idx.shape[1], -1)
        model = joint_model(st.topo.joint(name).type)
        dim, n_noise = model.outlier_dim, model.noise_levels
        p_eff = float(np.einsum("nij,jk,nik->", G[m], Hinv, G[m]))
        out[name] = (
            e,
            G,
            Hinv,
            float(np.sum(e[m] ** 2)),
            dim * int(m.sum()) - p_eff - (n_noise - 1),
        )
    return x_loo, out


def _reject_left_out(
    st: _State, x: FloatArray, solve: Callable[[FloatArray], FloatArray]
) -> tuple[int, FloatArray]:
    """The leave-out and masking tests of :func:`acs_cli.core.estimation.solve`, with
    refits: outliers inflate the fitted noise levels and hide each other. Per edge, the
    worst ``LEAVE_OUT_SHARE`` of the kept frames (by whitened residual power) are left out,
    the rig solved without them (noise levels refitted), and each tested as a frame that
    fit predicts, ``T_i = e_i^T (I + H_ii)^-1 e_i`` against ``F(d, nu)`` with the threshold
    of a trimmed noise level. Where none is beyond, the worst ``MASKING_GROUP`` are tested
    jointly against a fit without just them. Returns how many were dropped and the
    solution: the fit without them, or ``x`` (weights as they were) when none was."""
    r = _residuals(st, x)
    rows = _edge_rows(st)
    suspects: dict[str, np.ndarray] = {}
    rooms: dict[str, int] = {}
    for j in st.topo.joints:
        m = st.mask[j.name]
        rooms[j.name] = int(np.floor(MAX_OUTLIER_FRACTION * m.size)) - int((~m).sum())
        testable = m & (st.frames[j.name] != st.ref_frame)
        k = min(rooms[j.name], int(np.ceil(estimation.LEAVE_OUT_SHARE * m.sum())))
        if min(k, int(testable.sum())) >= estimation.MASKING_GROUP:
            power = np.sum(r[rows[j.name]] ** 2, axis=1)
            cand = np.flatnonzero(testable)
            suspects[j.name] = cand[np.argsort(power[cand])[::-1][:k]]
    if not suspects:
        return 0, x
    x_loo, fits = _fit_without(st, x, suspects, solve)
    dropped = 0
    for name, f in suspects.items():
        e, G, Hinv, S, nu = fits[name]
        m = st.mask[name]
        dim = joint_model(st.topo.joint(name).type).outlier_dim
        if nu < estimation.MIN_TEST_DOF or not S > EXACT_POWER * dim * m.sum():
            m[f] = True
            continue
        Gs = G[f]
        M = np.eye(e.shape[1]) * (1 + 1e-9) + np.matmul(Gs @ Hinv, np.swapaxes(Gs, 1, 2))
        T = np.einsum("ni,ni->n", e[f], np.linalg.solve(M, e[f][:, :, None])[:, :, 0])
        Tk = np.sum(e[m] ** 2, axis=1)
        shape = estimation.tail_shape(Tk, dim)
        thr = estimation.outlier_threshold(m.size, nu, dim, (f.size - 1) / m.size, shape)
        out = f[T / dim / (S / nu) > thr]
        m[np.setdiff1d(f, out)] = True
        dropped += out.size
    if dropped:
        _refit_weights(st, x_loo, st.n_free)
        return dropped, x_loo
    groups = {
        name: f[: estimation.MASKING_GROUP]
        for name, f in suspects.items()
        if rooms[name] >= estimation.MASKING_GROUP
    }
    if groups:
        x_g, fits = _fit_without(st, x, groups, solve)
        for name, g in groups.items():
            e, G, Hinv, S, nu = fits[name]
            m = st.mask[name]
            dim = joint_model(st.topo.joint(name).type).outlier_dim
            Gg = G[g].reshape(-1, G.shape[2])
            eg = e[g].reshape(-1)
            A = np.eye(eg.size) * (1.0 + 1e-9) + Gg @ Hinv @ Gg.T
            stat = float(eg @ np.linalg.solve(A, eg)) / (g.size * dim) / (S / nu) if S > 0 else 0.0
            shape = estimation.tail_shape(np.sum(e[m] ** 2, axis=1), dim)
            limit = estimation.outlier_threshold(
                m.size, nu, dim, shape=shape, group=g.size, share=estimation.MASKING_SHARE
            )
            if nu >= estimation.MIN_TEST_DOF and stat > limit:
                dropped += g.size
            else:
                m[g] = True
        if dropped:
            _refit_weights(st, x_g, st.n_free)
            return dropped, x_g
    _refit_weights(st, x, st.n_free)
    return 0, x


# --------------------------------------------------------------------------- solve


def _check_tracks(
    topo: RigTopology, tracks: dict[str, CameraTrack], ref_frame: int, recs: Recordings
) -> int:
    for c in topo.cameras:
        if c not in tracks:
            raise InputError(f"cameras.{c}: no poses given")
        se3.check_transforms(tracks[c].T_w_c, name=f"cameras.{c} poses")
    n = tracks[topo.cameras[0]].T_w_c.shape[0]
    for c in topo.cameras:
        tr = tracks[c]
        if tr.T_w_c.shape[0] != n or tr.valid.shape != (n,):
            raise InputError(f"cameras.{c}: poses are not on the rig's common timeline")
    if recs.of_frame.shape != (n,):
        raise InputError("the recordings do not cover the rig's common timeline")
    if not -n <= ref_frame < n:
        raise InputError(f"reference.frame: {ref_frame} is outside the {n} frames")
    k = ref_frame % n
    # every camera of the reference recording has a pose at the reference instant
    in_ref = recs.of_frame == recs.of_frame[k]
    missing = [c for c in topo.cameras if tracks[c].valid[in_ref].any() and not tracks[c].valid[k]]
    if topo.reference not in missing and not tracks[topo.reference].valid[k]:
        missing.insert(0, topo.reference)
    if missing:
        raise InputError(
            f"reference.frame: camera {missing[0]} has no pose at frame {k}; choose a frame "
            "where every camera has one"
        )
    return k


@dataclass(frozen=True)
class _WorldGraph:
    """The worlds of a rig's recordings (see :class:`Recordings`)."""

    widx: dict[str, np.ndarray]  # per camera: (n,) its world at each instant
    recording: list[int]  # per world
    cameras: list[tuple[str, ...]]  # per world
    shared: list[bool]  # per world
    root: np.ndarray  # per world: the first world of its group (itself for a group's frame)
    unknown_scale: np.ndarray  # per world
    ref_world: int
    has_world: dict[str, np.ndarray]  # per camera: (n,) instants where it has a world

    def tied(self, c: str) -> np.ndarray:
        """``(n,)`` bool: the instants where camera ``c``'s pose is in the reference world
        (its world there is tied to the reference's)."""
        return self.has_world[c] & (self.root[self.widx[c]] == self.ref_world)


def _world_graph(
    topo: RigTopology,
    tracks: dict[str, CameraTrack],
    recs: Recordings,
    frames: dict[str, np.ndarray],
    k: int,
) -> _WorldGraph:
    """Number the worlds, and group those that edges tie together at some instant.

    Raises
    ------
    InputError
        The bodies of a shared world disagree on whether its scale is known.
    """
    n = recs.of_frame.size
    keys: dict[tuple[int, str], int] = {}
    recording: list[int] = []
    cams: list[list[str]] = []
    shared: list[bool] = []
    widx: dict[str, np.ndarray] = {}
    has_world: dict[str, np.ndarray] = {}
    for c in topo.cameras:
        w = np.zeros(n, int)  # 0 where it has none: masked by has_world
        on_edges = np.zeros(n, bool)  # a world only where the camera is on some edge
        for j in topo.edges_of(c):
            on_edges[frames[j.name]] = True
        has_world[c] = np.isin(recs.of_frame, recs.of_frame[on_edges]) & tracks[c].valid
        for rr in np.unique(recs.of_frame[on_edges]):
            r = int(rr)
            key = (r, "" if recs.shared_world[r] else c)
            if key not in keys:
                keys[key] = len(recording)
                recording.append(r)
                cams.append([])
                shared.append(recs.shared_world[r])
            cams[keys[key]].append(c)
            w[recs.of_frame == r] = keys[key]
        widx[c] = w
    unknown = np.zeros(len(recording), bool)
    for wn, members in enumerate(cams):
        flags = {tracks[c].unknown_scale for c in members}
        if len(flags) > 1:
            raise InputError(
                f"recordings.{recs.names[recording[wn]]}: its bodies share one world, but "
                "some have scale: unknown and others not; a shared world has one scale"
            )
        unknown[wn] = flags.pop()
    parent = list(range(len(recording)))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for j in topo.joints:
        p, q = j.between
        f = frames[j.name]
        for a, b in np.unique(np.stack([widx[p][f], widx[q][f]], axis=1), axis=0):
            ra, rb = find(int(a)), find(int(b))
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    ref_world = int(widx[topo.reference][k])
    groups = {find(w) for w in range(len(recording))}
    first = {g: (ref_world if find(ref_world) == g else g) for g in groups}
    root = np.array([first[find(w)] for w in range(len(recording))], int)
    return _WorldGraph(
        widx, recording, [tuple(m) for m in cams], shared, root, unknown, ref_world, has_world
    )


def estimate_rig(
    topology: RigTopology,
    tracks: dict[str, CameraTrack],
    *,
    reference_frame: int = 0,
    priors: dict[str, EdgePrior] | None = None,
    reject_outliers: bool = True,
    accept_weak: bool = False,
    recordings: Recordings | None = None,
    noise_tolerance: float = 0.0,
) -> RigEstimate:
    """Calibrate a rig from every camera's general motion: one maximum-likelihood solve.

    Parameters
    ----------
    topology : RigTopology
        Cameras, joints (ball, hinge, rigid) and the reference camera.
    tracks : dict of CameraTrack
        Every camera's poses on one timeline (``(n, 4, 4)`` each, with a validity mask).
    reference_frame : int
        The instant at which ``T_cam_ref`` is reported.
    priors : dict of EdgePrior, optional
        Joints known beforehand, by joint name (in the units each says, ``EdgePrior.units``).
    reject_outliers : bool
    accept_weak : bool
        Return joints whose std alone is past the refusal level instead of refusing them
        (``--accept-weak``); exact degeneracies are refused whatever it says.
    recordings : Recordings, optional
        Which recording each instant belongs to, which recordings' bodies share one world
        and which joints each holds still (default: one recording, a world per camera). A
        held joint gets its prior from that recording by Algorithm II
        (:func:`fixed_joint_prior`; ``priors`` given for the same part win).
    noise_tolerance : float
        How far (relative) the refitted noise levels may still move when the reweighting
        stops: :data:`SETTLED_NOISE` by default (the fixed point: the estimate does not
        depend on its start); :data:`TEST_SETTLED_NOISE` for a scan's many quick fits (a
        clock offset's cost at each candidate), whose residuals need not be that precise.

    Returns
    -------
    RigEstimate

    Raises
    ------
    InputError
        Missing cameras, poses that are not rigid transforms, tracks off the timeline, a
        bad reference frame (or one where the reference camera is on no joint), the bodies
        of a shared world disagreeing on their scale, a prior that does not fit its joint
        (a rigid joint, an axis on a joint that is not a hinge, a camera not on the joint,
        a covariance that is not positive definite).
    DegenerateMotionError
        An edge with too few frames in common, a joint that does not fit its declared type
        (:func:`check_joint_types`), or a motion that leaves part of the rig undetermined;
        the message names the edge and what to record (or configure) instead.
    """
    n = tracks[topology.cameras[0]].T_w_c.shape[0] if topology.cameras[0] in tracks else 0
    recs = recordings if recordings is not None else Recordings.single(n)
    k = _check_tracks(topology, tracks, reference_frame, recs)
    priors = dict(priors or {})
    for name, held in held_priors(topology, tracks, recs).items():
        priors[name] = merge_priors(priors[name], held) if name in priors else held
    frames: dict[str, np.ndarray] = {}
    for j in topology.joints:
        p, q = j.between
        f = np.flatnonzero(tracks[p].valid & tracks[q].valid)
        still = recs.holds(j.name, f)
        if still.all() and f.size:
            raise DegenerateMotionError(
                f"joint {j.name} ({p}-{q}): held still in every recording that sees both its "
                "bodies; that gives its position, not how the bodies turn: add a recording "
                "of it moving",
                details={"joint": j.name, "frames": 0},
            )
        f = f[~still]
        # in a shared world the joint is Algorithm I's (eq. (13)): a few frames determine it
        one_world = int(np.sum(np.asarray(recs.shared_world)[recs.of_frame[f]]))
        has_prior = j.name in priors and bool(priors[j.name].position_in)
        need = MIN_PRIOR_EDGE_FRAMES if has_prior else MIN_EDGE_FRAMES
        if f.size < need and one_world < MIN_SHARED_WORLD_FRAMES:
            raise DegenerateMotionError(
                f"joint {j.name} ({p}-{q}): the two cameras have poses at {f.size} common "
                f"instants; the rig needs at least {need} of general motion "
                + ("with the joint given" if has_prior else "to calibrate the joint too")
                + f" (or {MIN_SHARED_WORLD_FRAMES} in a shared world). Record more frames "
                "where both cameras track.",
                details={"joint": j.name, "frames": int(f.size)},
            )
        frames[j.name] = f
    wg = _world_graph(topology, tracks, recs, frames, k)
    # the cameras on some edge at the reference instant: their poses there are unknowns
    with_delta = [
        c for c in topology.cameras if any(k in frames[j.name] for j in topology.edges_of(c))
    ]
    if topology.reference not in with_delta:
        raise InputError(
            f"reference: camera {topology.reference} is on no joint at the reference instant "
            "(its joints' other bodies are not in that recording, or the recording holds "
            "them still): choose a recording where it moves with a neighbour"
        )
    metre = any(pr.units == "metre" for pr in priors.values())
    L = _Layout(topology, wg.root.size, wg.root, wg.unknown_scale, wg.ref_world, with_delta, metre)

    def unit_column(pr: EdgePrior, c: str) -> int | None:
        """The log-scale column converting reference units to the prior's (None: same)."""
        if pr.units == "metre":
            return L.metre
        if pr.units == "own":  # the world _own_world reports its own units in
            on = np.zeros(tracks[c].valid.size, bool)
            for j in topology.edges_of(c):
                on[frames[j.name]] = True
            w = int(wg.widx[c][k] if on[k] else wg.widx[c][int(np.argmax(on))])
            return L.logs.get(w)
        return None

    x0, R0X, anchor = _initial(topology, tracks, frames, L, wg.widx, wg.root)
    Rm = {c: np.ascontiguousarray(tracks[c].T_w_c[:, :3, :3]) for c in topology.cameras}
    tm = {c: np.ascontiguousarray(tracks[c].T_w_c[:, :3, 3]) for c in topology.cameras}
    # the rig's length scale: for noise floors and for judging what is determined
    # (the reference recording's instants: other recordings' worlds have their own origins)
    here = tracks[topology.reference].valid & (recs.of_frame == recs.of_frame[k])
    t_ref = tm[topology.reference][here]
    travel = float(np.sqrt(np.mean(np.sum((t_ref - t_ref.mean(0)) ** 2, 1))))
    if L.metre is not None:
        # the reference's units per metre from the starting joints against the metric ones
        num = den = 0.0
        for name, pr in priors.items():
            j = topology.joint(name)
            model = joint_model(j.type)
            if pr.units != "metre" or not model.has_point:
                continue
            start = model.geometry(x0[L.edge[name]], anchor[name])
            for c, pos in pr.position_in.items():
                side = j.between.index(c) if c in j.between else None
                if side is not None:
                    o = np.asarray(start[side])
                    num += float(o @ np.asarray(pos, float))
                    den += float(np.asarray(pos, float) @ np.asarray(pos, float))
        if L.metre not in L.logs.values():  # else a metric world's scale already starts it
            x0[L.metre] = np.log(max(num / den, 1e-6)) if den > 0 and num > 0 else 0.0
    prior_rows = [
        (name, at, value, W, unit_column(priors[name], c) if at < 6 else None)
        for name, at, value, W, c in edge_prior_rows(topology, priors, travel)
    ]
    for name, pr in priors.items():  # the given points start their joints
        j = topology.joint(name)
        for c, pos in pr.position_in.items():
            col = unit_column(pr, c)
            f0 = 1.0 if col is None else float(np.exp(x0[col]))
            side = j.between.index(c)
            joint_model(j.type).seed_point(x0[L.edge[name]], side, f0 * np.asarray(pos, float))
    st = _State(
        topo=topology,
        L=L,
        R=Rm,
        t=tm,
        widx=wg.widx,
        R0X=R0X,
        anchor=anchor,
        ref_frame=k,
        frames=frames,
        mask={j.name: np.ones(frames[j.name].size, bool) for j in topology.joints},
        gain={j.name: np.ones(frames[j.name].size) for j in topology.joints},
        whiten_pos={
            j.name: np.broadcast_to(np.eye(3), (frames[j.name].size, 3, 3)).copy()
            for j in topology.joints
        },
        w_rot={j.name: 1.0 for j in topology.joints},
        w_trans={j.name: 1.0 for j in topology.joints},
        w_delta={c: np.full(6, 1e3) for c in with_delta},
        priors=prior_rows,
        length=max(travel, 1e-9),
        n_free=L.size - 6 * len(L.delta),
    )
    _anchor_frames(st, x0)

    def fun(x: FloatArray) -> FloatArray:
        return _residuals(st, x)

    def jac(x: FloatArray) -> csr_matrix:
        return _jacobian(st, x)

    # the reference instant's pose corrections: held at zero while the rig is estimated from
    # every frame alike, then solved alone with the rest held (which instant is the reference
    # only picks where T_cam_ref is reported: it does not move the rig's estimate)
    delta_cols = np.zeros(L.size, bool)
    for c in L.delta:
        delta_cols[L.delta[c]] = True

    def run(x: FloatArray, free: np.ndarray | None = None) -> tuple[FloatArray, int, Any]:
        free = ~delta_cols if free is None else free
        x = x.copy()

        def f_sub(z: FloatArray) -> FloatArray:
            x[free] = z
            return fun(x)

        def j_sub(z: FloatArray) -> csr_matrix:
            x[free] = z
            return jac(x)[:, np.flatnonzero(free)]

        sol = lsq.solve(
            f_sub,
            x[free],
            jac=j_sub,
            method=RIG_METHOD,
            ftol=1e-10,
            xtol=1e-10,
            gtol=1e-10,
            max_nfev=200,
        )
        x[free] = sol.x
        return x, int(sol.nfev), sol

    nfev = 0

    def solve(x: FloatArray) -> FloatArray:
        nonlocal nfev
        x, nf, _sol = run(x)
        nfev += nf
        return x

    def settle(x: FloatArray) -> tuple[FloatArray, dict[str, dict[str, float]]]:
        return _settle(st, x, solve, noise_tolerance, REWEIGHT_ROUNDS)

    x, noise = settle(x0)
    if reject_outliers:
        for _ in range(REJECTION_ROUNDS):
            if _reject(st, x) == 0:
                # outliers that hide each other: the leave-out and masking tests, with refits
                dropped, x = _reject_left_out(st, x, solve)
                if dropped == 0:
                    break
            x, noise = settle(x)
    # last, from the converged point: the reference instant's constraints made (nearly) hard,
    # so that its poses are corrected to fit them; the rest of the solution barely moves
    # (started there at once, the trust region can stall on the stiff rows)
    for j in topology.joints:
        st.gain[j.name] = np.where(frames[j.name] == k, REFERENCE_GAIN, 1.0)
    x, nf, sol = run(x, delta_cols)
    nfev += nf
    # the covariance of everything together, the reference instant's constraints hard
    J = _jacobian(st, x)
    JtJ = J.T @ J
    H = np.asarray(JtJ.toarray() if hasattr(JtJ, "toarray") else JtJ)
    cov_model = np.linalg.pinv(H, rcond=1e-15, hermitian=True)
    # errors correlated over time (skin markers, kinematics, drift): the block sandwich
    cov, found = _correlated(st, J, sol.fun, cov_model, ~delta_cols)
    est = _assemble(st, x, cov, noise, float(sol.cost), nfev, wg, recs)
    est = dataclasses.replace(est, correlated=found)
    est.warnings.extend(check_joint_types(st, x))
    # the information from the measurements alone (the priors' rows are the last ones):
    # what the null test normalises by, so that a tight prior on one combination of unknowns
    # (a joint given in a camera's own units: its position and that camera's scale) does
    # not make the combination the data determine look null
    n_prior = sum(int(row[3].shape[0]) for row in st.priors)
    Jm = J[: J.shape[0] - n_prior]
    H_data = np.asarray((Jm.T @ Jm).toarray()) if n_prior else H
    # whether the motion determines the rig is a question of its geometry and the fitted
    # noise: asked of the model's covariance (correlated errors are a warning, not a refusal)
    judged = est if not found.detected else _assemble(st, x, cov_model, noise, 0.0, 0, wg, recs)
    _check_determined(st, x, H, cov_model, judged, travel, accept_weak, H_data)
    if found.detected:
        for name, e in est.edges.items():
            e.position_cov_model_in.update(judged.edges[name].position_cov_in)
    return est


def _correlated(
    st: _State, J: csr_matrix, r: FloatArray, cov: FloatArray, free: np.ndarray
) -> tuple[FloatArray, CorrelatedErrors]:
    """``cov`` grown for errors correlated over time (:mod:`acs_cli.core.correlated`): the
    per-instant scores of the edges' inlier rows (residuals ``r`` and Jacobian ``J`` at the
    solution; the reference instant's rows, made hard, left out), tested per joint's
    geometry and per world."""
    rows_of = _edge_rows(st)
    row_idx: list[np.ndarray] = []
    frame_idx: list[np.ndarray] = []
    for j in st.topo.joints:
        f = st.frames[j.name]
        keep = st.mask[j.name] & (f != st.ref_frame)
        rows = rows_of[j.name][keep]
        row_idx.append(rows.ravel())
        frame_idx.append(np.repeat(f[keep], rows.shape[1]))
    rr = np.concatenate(row_idx)
    if rr.size == 0:
        return cov, NOT_TESTED
    cols = np.flatnonzero(free)
    scores = frame_scores(J[rr], r[rr], np.concatenate(frame_idx), cols)
    where = {int(c): i for i, c in enumerate(cols)}
    L = st.L
    groups: dict[str, list[int]] = {
        f"joint {name}": [where[c] for c in L.edge_columns(name) if c in where] for name in L.edge
    }
    for w in sorted(set(L.rot) | set(L.logs)):
        on = [c for c in st.topo.cameras if bool(np.any(st.widx[c] == w))]
        groups[f"the world of {', '.join(on)}"] = [
            where[c] for c in L.world_columns(w) if c in where
        ]
    if L.metre is not None and L.metre in where:
        groups["units per metre"] = [where[L.metre]]
    return covariance_with_correlated_errors(cov, scores, cols, groups)


def _own_world(st: _State, c: str) -> int:
    """Camera ``c``'s world at the reference instant (else at its first pose): the one whose
    scale converts its own units (one recording: its only world)."""
    k = st.ref_frame
    on = st.frames_of(c)
    return int(st.widx[c][k] if on[k] else st.widx[c][int(np.argmax(on))])


def _settle(
    st: _State,
    x: FloatArray,
    solve: Callable[[FloatArray], FloatArray],
    tol: float,
    rounds: int,
) -> tuple[FloatArray, dict[str, dict[str, float]]]:
    """Solve and refit the noise levels in turn until they move by less than ``tol``
    (relative; 0: :data:`SETTLED_NOISE`), at most ``rounds`` refits: the solution and the
    last levels."""
    noise: dict[str, dict[str, float]] = {}
    for _ in range(rounds):
        before = noise
        noise = _refit_weights(st, x, st.n_free)
        if before and _settled(before, noise, tol):
            break
        x = solve(x)
    return x, noise


def _settled(
    a: dict[str, dict[str, float]], b: dict[str, dict[str, float]], tol: float = 0.0
) -> bool:
    """Whether refitted noise levels moved by less than ``tol`` (relative; default
    :data:`SETTLED_NOISE`)."""
    tol = tol or SETTLED_NOISE
    for name, d in b.items():
        for key, v in d.items():
            old = a.get(name, {}).get(key)
            if old is None or abs(v - old) > tol * max(abs(old), 1e-300):
                return False
    return True


def _assemble(
    st: _State,
    x: FloatArray,
    cov: FloatArray,
    noise: dict[str, dict[str, float]],
    cost: float,
    nfev: int,
    wg: _WorldGraph,
    recs: Recordings,
) -> RigEstimate:
    topo, L, k = st.topo, st.L, st.ref_frame
    ref = topo.reference
    W = _worlds(st, x)

    def pose_at_ref(xx: FloatArray, c: str) -> FloatArray:
        R, t = _poses(st, xx, c)
        return se3.transforms_from_rt(R[k], t[k])

    def scale_of(w: int) -> tuple[float, float | None]:
        if w not in L.logs:
            return 1.0, None
        s = float(W.s[w])
        return s, float(s * np.sqrt(max(cov[L.logs[w], L.logs[w]], 0.0)))

    cams: dict[str, CameraEstimate] = {}
    for c in topo.cameras:
        R, t = _poses(st, x, c, W)
        wc = int(st.widx[c][k]) if c in L.delta else int(st.widx[c][np.argmax(st.frames_of(c))])
        T0: FloatArray | None = None
        C6: FloatArray = np.zeros((6, 6))
        tied = wg.tied(c)
        if c in L.delta and c != ref and tied[k]:
            T0 = se3.invert_transforms(pose_at_ref(x, c)) @ pose_at_ref(x, ref)

            def vec(xx: FloatArray, c: str = c, T0: FloatArray = T0) -> FloatArray:
                T = se3.invert_transforms(pose_at_ref(xx, c)) @ pose_at_ref(xx, ref)
                return np.concatenate([se3.rotvec_from_matrix(T0[:3, :3].T @ T[:3, :3]), T[:3, 3]])

            cols = sorted(set(L.camera_columns(c, [wc]) + L.camera_columns(ref, [wg.ref_world])))
            _, C6 = lsq.propagate(vec, x, cols, cov[np.ix_(cols, cols)])
        elif c == ref:
            T0 = np.eye(4)
        scale, scale_std = scale_of(wc)
        upm = upm_std = None
        if L.metre is not None:  # own units per metre = (reference's per metre) / scale
            grad = np.zeros(L.size)
            grad[L.metre] += 1.0
            if wc in L.logs:
                grad[L.logs[wc]] -= 1.0
            upm = float(np.exp(grad @ x))
            upm_std = float(upm * np.sqrt(max(float(grad @ cov @ grad), 0.0)))
        cams[c] = CameraEstimate(
            T0,
            C6,
            scale,
            scale_std,
            se3.transforms_from_rt(R, t),
            se3.transforms_from_rt(W.R[wc], W.t[wc]),
            tied,
            upm,
            upm_std,
            float(np.degrees(st.sigma_rot.get(c, np.nan))),
        )
    worlds: list[WorldEstimate] = []
    for w in range(wg.root.size):
        Cw: FloatArray = np.zeros((6, 6))
        if w in L.rot:
            R_w = W.R[w]

            def wvec(xx: FloatArray, w: int = w, R_w: FloatArray = R_w) -> FloatArray:
                Wx = _worlds(st, xx)
                return np.concatenate([se3.rotvec_from_matrix(R_w.T @ Wx.R[w]), Wx.t[w]])

            cols = L.world_columns(w)
            _, Cw = lsq.propagate(wvec, x, cols, cov[np.ix_(cols, cols)])
        scale, scale_std = scale_of(w)
        worlds.append(
            WorldEstimate(
                recording=recs.names[wg.recording[w]],
                cameras=wg.cameras[w],
                shared=wg.shared[w],
                T_ref_world=se3.transforms_from_rt(W.R[w], W.t[w]),
                covariance=Cw,
                scale=scale,
                scale_std=scale_std,
                tied=bool(wg.root[w] == wg.ref_world),
            )
        )
    edges: dict[str, EdgeEstimate] = {}
    G = _all_poses(st, x)
    for j in topo.joints:
        p, q = j.between
        pos: dict[str, FloatArray] = {}
        pcov: dict[str, FloatArray] = {}
        axis: dict[str, FloatArray] = {}
        astd: dict[str, float] = {}
        own_in: dict[str, tuple[FloatArray, FloatArray]] = {}
        g: FloatArray = np.zeros(0)
        Cg: FloatArray = np.zeros((0, 0))
        model = joint_model(j.type)
        if model.has_point:
            cols = L.edge_columns(j.name)

            def geometry(xx: FloatArray, j: RigJoint = j) -> FloatArray:
                return np.concatenate([v for v in joint_geometry(st, xx, j) if v is not None])

            g, Cg = lsq.propagate(geometry, x, cols, cov[np.ix_(cols, cols)])
            for side, c in enumerate((p, q)):
                sl = slice(3 * side, 3 * side + 3)
                pos[c], pcov[c] = g[sl], Cg[sl, sl]
                wc = _own_world(st, c)
                if wc in L.logs:  # own units: divided by the camera's scale

                    def own(
                        xx: FloatArray, sl: slice = sl, wc: int = wc, j: RigJoint = j
                    ) -> FloatArray:
                        return np.asarray(geometry(xx, j)[sl]) / float(np.exp(xx[L.logs[wc]]))

                    oc = sorted({*cols, L.logs[wc]})
                    own_in[c] = lsq.propagate(own, x, oc, cov[np.ix_(oc, oc)])
                else:
                    own_in[c] = (pos[c], pcov[c])
                if model.has_axis:
                    sl = slice(6 + 3 * side, 9 + 3 * side)
                    axis[c] = g[sl]
                    astd[c] = float(np.degrees(np.sqrt(max(np.trace(Cg[sl, sl]), 0.0))))
        if axis and axis[p][int(np.argmax(np.abs(axis[p])))] < 0:
            # one convention for the axis's sign: its largest component (in p) is positive
            axis = {c: -u for c, u in axis.items()}
        Tq, Tp = cams[q].T_cam_ref, cams[p].T_cam_ref
        T_const = model.transform(x[L.edge[j.name]], st.anchor[j.name])
        if T_const is not None:  # constant: the edge's own unknowns
            T_q_p = T_const
        elif Tq is not None and Tp is not None:
            T_q_p = Tq @ se3.invert_transforms(Tp)
        else:  # no instant where both are posed: the articulation is not defined
            T_q_p = np.full((4, 4), np.nan)
        b = _edge_blocks(st, x, j, G)
        m = st.mask[j.name]
        r = b.get("pos", b.get("trans"))
        rms = float(np.sqrt(np.mean(np.sum(r[m] ** 2, axis=1)))) if r is not None else 0.0
        edges[j.name] = EdgeEstimate(
            joint=j,
            position_in=pos,
            position_cov_in=pcov,
            axis_in=axis,
            axis_std_deg_in=astd,
            T_q_p=T_q_p,
            residual_rms=rms,
            frames_used=int(m.sum()),
            frames_rejected=int((~m).sum()),
            inliers=np.asarray(st.frames[j.name][m]),
            noise=noise.get(j.name, {}),
            residual_blocks={kind: v[m] for kind, v in b.items()},
            frames=np.asarray(st.frames[j.name]),
            frame_residuals=dict(b),
            position_own_in=own_in,
            geometry=g,
            geometry_covariance=Cg,
        )
    return RigEstimate(topo, k, cams, edges, cost, nfev, recordings=recs, worlds=worlds)


# --------------------------------------------------------------------------- degeneracy


def edge_motion(est: RigEstimate, name: str) -> dict[str, MotionSummary]:
    """How ball joint ``name`` bent over the frames it used: its articulation's principal
    axes in each of its two bodies' frames (:func:`acs_cli.core.joint.articulation_motion`),
    keyed by camera; empty for other joint types (a hinge turns about one axis by design)."""
    e = est.edges[name]
    if e.joint.type != "ball" or e.inliers.size < 2:
        return {}
    p, q = e.joint.between
    G = {c: est.cameras[c].poses_in_reference_world[e.inliers, :3, :3] for c in (p, q)}
    return articulation_motion(G[p], G[q], p, q)


def near_hinge_warnings(est: RigEstimate, unit: str, known: Iterable[str] = ()) -> list[str]:
    """The near-hinge warning (:func:`acs_cli.core.joint.near_hinge_warning`) of each ball
    joint of a rig whose position was estimated from the motion (not in ``known``: joints
    given a prior, which supplies what the motion cannot), in ``unit``."""
    out, skip = [], set(known)
    for name, e in est.edges.items():
        if name in skip:
            continue
        text = near_hinge_warning(f"joint {name}", edge_motion(est, name), e.position_cov_in, unit)
        if text is not None:
            out.append(text)
    return out


#: A rigid pair whose cameras turn relative to each other by more than this (RMS, degrees),
#: or a hinge whose axis moves by more than this in one body as seen from the other, does
#: not fit its declared joint type: refused (exit 3) with the type that fits.
MODEL_REFUSE_DEG = 5.0
#: ... and above this, a warning.
MODEL_WARN_DEG = 2.0


def check_joint_types(st: _State, x: FloatArray) -> list[str]:
    """Warnings for joints that fit their declared type poorly; raises for gross misfits.

    Each type's model says what its motion must do
    (:meth:`~acs_cli.core.joints.base.JointModel.misfit`): a rigid edge's cameras must not
    turn relative to each other (``R_p^T R_q`` constant); a hinge's axis must stay one line
    in both bodies. The RMS of those rotation residuals over the frames used is compared
    with :data:`MODEL_WARN_DEG` and :data:`MODEL_REFUSE_DEG`.

    Raises
    ------
    DegenerateMotionError
        Naming each misfit joint and the type that fits its motion.
    """
    G = _all_poses(st, x)
    warnings: list[str] = []
    refused: list[str] = []
    for j in st.topo.joints:
        fit = joint_model(j.type).misfit(j, _edge_blocks(st, x, j, G), st.mask[j.name])
        if fit is None:
            continue
        rms, text = fit
        if joint_model(j.type).constant_transform:
            # a rigid mount that turns: a clock offset of whole frames does that too
            text = _timing_note(st, j) or text
        if rms > MODEL_REFUSE_DEG:
            refused.append(text)
        elif rms > MODEL_WARN_DEG:
            warnings.append(text + "; unless the poses are that noisy")
    if refused:
        raise DegenerateMotionError(
            "the joints do not fit their types: " + " | ".join(refused) + ".",
            details={"model_refuse_deg": MODEL_REFUSE_DEG},
        )
    return warnings


#: Whole-frame clock offsets the timing check of a misfit rigid joint tries, each way.
TIMING_SHIFTS = 3


def _turn_deg(R: FloatArray, a: np.ndarray, b: np.ndarray) -> FloatArray:
    """``(m,)`` deg: how far each body turned from instant ``a`` to ``b`` (``|R_a^T R_b|``)."""
    rel = np.einsum("nji,njk->nik", R[a], R[b])
    return np.degrees(np.linalg.norm(se3.rotvec_from_matrix(rel), axis=1))


def _timing_note(st: _State, j: RigJoint) -> str:
    """For a rigid joint whose bodies turn relative to each other: the words for a clock
    offset when shifting one body's poses by whole frames (at most :data:`TIMING_SHIFTS`)
    makes them turn alike, ``""`` otherwise.

    Two bodies on one rigid mount turn by the same angle between any two instants, whatever
    their worlds and the mount (the hand-eye consistency ``|A| = |B|``); the angles are
    compared over pairs of instants 1 and 5 frames apart. A shift is named when it brings
    their RMS difference under half of what it is as recorded and under
    :data:`MODEL_WARN_DEG`."""
    p, q = j.between
    f = np.sort(st.frames[j.name][st.mask[j.name]])
    on_q = st.frames_of(q)
    Rp, Rq = st.R[p], st.R[q]  # as measured (the angles are the same in any world)

    def mismatch(k: int) -> tuple[float, int]:
        pairs = [(f[:-s], f[s:]) for s in (1, 5) if f.size > s]
        if not pairs:
            return np.inf, 0
        a = np.concatenate([x for x, _ in pairs])
        b = np.concatenate([y for _, y in pairs])
        ok = (a + k >= 0) & (b + k < on_q.size) & (a + k < on_q.size) & (b + k >= 0)
        a, b = a[ok], b[ok]
        ok = on_q[a + k] & on_q[b + k]
        a, b = a[ok], b[ok]
        if a.size < 3:
            return np.inf, 0
        d = _turn_deg(Rp, a, b) - _turn_deg(Rq, a + k, b + k)
        return float(np.sqrt(np.mean(d**2))), int(a.size)

    as_given, m0 = mismatch(0)
    best = min(
        ((mismatch(k), k) for k in range(-TIMING_SHIFTS, TIMING_SHIFTS + 1) if k),
        key=lambda t: t[0][0],
    )
    (rms, used), k = best
    if not (used >= m0 // 2 and rms < 0.5 * as_given and rms < MODEL_WARN_DEG):
        return ""
    return (
        f"joint {j.name} ({p}-{q}) is declared rigid, and fits it when {p}'s pose at each "
        f"instant is paired with {q}'s {abs(k)} frame{'s' if abs(k) > 1 else ''} "
        f"{'later' if k > 0 else 'earlier'} (the two bodies then turn alike to {rms:.2f} deg "
        f"RMS, against {as_given:.2f} deg as recorded): the two clocks are offset by "
        f"{abs(k)} frame{'s' if abs(k) > 1 else ''}; correct the timestamps, or set "
        "estimate_time_offset: true"
    )


def _motion_words(R: FloatArray, what: str, hinge_ok: bool) -> str:
    """``"turns about one axis only"`` and the like for rotations ``(n, 3, 3)``, or ``""``."""
    s = np.linalg.svd((R - R.mean(axis=0)).reshape(-1, 3), compute_uv=False)
    spread = float(s[0] / np.sqrt(R.shape[0]))
    if spread < MIN_ROTATION_SPREAD:
        return f"{what} hardly turns (RMS spread {np.degrees(spread):.2f} deg)"
    if s[2] < SINGLE_AXIS_RATIO * s[0] and not hinge_ok:
        return f"{what} turns about one axis only (singular value ratio {s[2] / s[0]:.3f})"
    return ""


#: Two axes are "the same" within this angle (degrees) for the planar-motion rule.
PARALLEL_AXES_DEG = 10.0


def planar_offset(st: _State, x: FloatArray, j: RigJoint) -> str:
    """The component a planar motion hides on an edge, in words, or ``""``.

    When camera ``p`` turns about one world axis only and the joint turns about that same
    axis (a hinge along it, a ball bending about it only, or a rigid edge), nothing in the
    motion tells how far apart along that axis the two cameras' parts of the joint are: a
    truck and its trailer on flat ground. The words are the type's model's
    (:meth:`~acs_cli.core.joints.base.JointModel.planar_offset`).
    """
    p, q = j.between
    f = st.frames[j.name]
    Rp = _poses(st, x, p)[0][f]
    a = single_axis(Rp)
    if a is None:
        return ""
    cos = np.cos(np.radians(PARALLEL_AXES_DEG))
    Rq = _poses(st, x, q)[0][f]
    return joint_model(j.type).planar_offset(j, Rp, Rq, lambda: joint_geometry(st, x, j), a, cos)


def _check_determined(
    st: _State,
    x: FloatArray,
    H: FloatArray,
    cov: FloatArray,
    est: RigEstimate,
    travel: float,
    accept_weak: bool = False,
    H_data: FloatArray | None = None,
) -> None:
    """Name each edge whose part of the rig the motion leaves undetermined (exit 3).

    The information ``H`` is normalised by the diagonal of the measurements' own
    (``H_data``, without the priors' rows; ``H``'s where a column has none) before its null
    directions are sought, below :data:`NULL_EIGENVALUE` of the largest eigenvalue of the
    measurements' normalised information.

    A joint whose only fault is a std past :data:`UNDETERMINED_STD_FRACTION` is let through
    with ``accept_weak`` (the stage marks the result weak); a null direction or planar
    motion is refused whatever the flag: there is no answer to write."""
    topo, L = st.topo, st.L
    with_prior = {name for name, *_ in st.priors}
    full = np.diag(H)
    H_data = H if H_data is None else H_data
    dd = np.where(np.diag(H_data) > 1e-12 * full, np.diag(H_data), full)
    d = np.sqrt(np.maximum(dd, 1e-300))
    w, V = np.linalg.eigh(H / np.outer(d, d))
    top = float(np.linalg.eigvalsh(H_data / np.outer(d, d))[-1])
    null = V[:, w < NULL_EIGENVALUE * max(top, 1e-300)]
    parents = topo.parents()
    G = _all_poses(st, x)
    problems: list[str] = []
    details: dict[str, object] = {}
    flagged: set[str] = set()
    overridable = True  # every problem is a std past the level (not a null direction)
    for step in topo.tree_order():  # parents first: a problem upstream explains the rest
        j = step.joint
        p, q = j.between
        upstream = {s.joint.name for s in topo.path(topo.reference, step.source)}
        # a problem upstream spreads its null directions downstream: there only the planar
        # rule, which looks at this edge's own motion, names a problem of this edge's
        downstream = bool(upstream & flagged)
        if downstream and (j.name in with_prior or not planar_offset(st, x, j)):
            continue
        cols = L.edge_columns(j.name)
        # the child camera of this edge in the tree carries the edge's world transform
        child = q if parents.get(q) is not None and parents[q].joint.name == j.name else p
        cols_all = cols + L.camera_columns(child, np.unique(st.widx[child][st.frames[j.name]]))
        in_null = float(np.sum(null[cols_all, :] ** 2)) if null.size else 0.0
        scale_len = max(travel, 1e-12)
        worst = 0.0
        what = ""
        model = joint_model(j.type)
        if model.has_point:
            for c in (p, q):
                C = est.edges[j.name].position_cov_in[c]
                ev, evec = np.linalg.eigh(C)
                std = float(np.sqrt(max(ev[-1], 0.0)))
                o = est.edges[j.name].position_in[c]
                rel = std / max(float(np.linalg.norm(o)), 0.1 * scale_len, 1e-12)
                if rel > worst:
                    worst, what = rel, f"the joint's position in {c}"
                    if model.has_axis:
                        u = est.edges[j.name].axis_in[c]
                        if abs(float(evec[:, -1] @ u)) > 0.9:
                            what = (
                                f"the offset between {p} and {q} along the hinge axis "
                                f"(the joint's position along the axis in {c})"
                            )
        planar = "" if j.name in with_prior else planar_offset(st, x, j)
        if planar:
            what, in_null = planar, 1.0
            overridable = False
        elif in_null < 0.5 and (worst <= UNDETERMINED_STD_FRACTION or accept_weak):
            continue
        else:
            overridable &= in_null < 0.5
        f = st.frames[j.name]
        Rst = np.einsum("nji,njk->nik", G[p][0][f], G[q][0][f])
        bends = (
            _motion_words(Rst, f"joint {j.name}", model.single_axis_ok)
            if not model.constant_transform
            else ""
        )
        if "hardly turns" in bends:
            bends += f"; if {p} and {q} are on one body, declare it type: rigid"
        why = [_motion_words(G[p][0][f], f"body {p}", False), bends]
        why += model.motion_advice(j, Rst)
        because = "; ".join(w for w in why if w) or "the motion is too narrow for the noise"
        advice = (
            f"record the rig turning about several axes (tilting, not only turning on flat "
            f"ground) while joint {j.name} moves"
        )
        cam = model.position_hint_camera(j)
        if cam is not None:
            advice += (
                f", or give the joint in the config (joints.{j.name}.position_in.{cam}: "
                f"[x, y, z] in metres, measured on the rig)"
            )
        size = (
            "cannot be determined"
            if in_null >= 0.5
            else f"is not determined (std {100 * worst:.0f}% of its size)"
        )
        problems.append(f"joint {j.name} ({p}-{q}): {what} {size} ({because}); {advice}")
        flagged.add(j.name)
        details[j.name] = {"relative_std": worst, "null_share": in_null}
    if problems:
        raise DegenerateMotionError(
            "the motion does not determine the rig: "
            + " | ".join(problems)
            + (f"; {OVERRIDE_HINT}." if overridable else "."),
            details=details,
        )
